"""Drifting layers of fractal cloud: their transmittance and the light they scatter
(docs/method.md, "The cloud layer": the pattern, the single- and multiple-scattering model and
its energy bounds). The pattern is ``cloud_noise``'s, the slab's fluxes ``cloud_transfer``'s."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.cores import in_shares
from pipeline.core.kept import kept_at
from pipeline.sky.cloud_noise import coverage_knots, lost_variance, packed_levels
from pipeline.sky.cloud_transfer import (
    delta_eddington_transmittance,
    diffuse_direct_transmittance,
    single_scattering_flux_transmittance,
    slab_path,
    two_stream_diffuse_transmittance,
)
from pipeline.sky.scattering import henyey_greenstein

__all__ = ["CloudLayer", "MAX_TAPS", "TILE_BLEND"]

_TAU_NODES = 48  # optical-depth nodes of the per-call multiple-scattering table
_kept_taps: dict = {}  # CloudLayer._footprint_taps's at a still camera's points (kept.kept_at), not written
_kept_spreads: dict = {}  # CloudLayer._spread's, the same

# numpy's Gauss-Hermite nodes and weights, cached: numpy finds them as the eigenvalues of a
# matrix at each call. Callers must not write to them.
_hermegauss = lru_cache(maxsize=4)(np.polynomial.hermite_e.hermegauss)

MAX_TAPS = 16
"""Most trilinear taps along a footprint's longer axis (``CloudLayer.field``)."""

_HERMITE_NODES = 8  # Gauss-Hermite nodes of a footprint's mean coverage

TILE_BLEND = 0.125
"""Width of the band about each edge of a copy of the tile, as a fraction of the tile's side, over
which the copies on both sides blend (``kernels.tiling.cloud_field``). [1]"""


@dataclass(frozen=True)
class CloudLayer:
    """A horizontal layer of drifting fractal cloud (see the module docstring for the model).

    Attributes
    ----------
    cover : float
        Fraction of the sky plane covered, in [0, 1] [1].
    scale : float
        Feature size of the pattern: clouds and gaps are about this wide [m].
    altitude : float
        Height of the layer above the observer, > 0 [m].
    wind : tuple of (float, float)
        (2,) velocity of the pattern, x east, y north: the density at x at time t is that at
        ``x - wind t`` at time 0 [m/s].
    thickness : float
        Vertical optical depth of a full cloud, >= 0 [1].
    seed : int
        Seed of the noise.
    albedo : float, optional
        Single-scattering albedo; water droplets absorb almost nothing in the visible [1].
    asymmetry : float, optional
        g of the Henyey-Greenstein phase; 0.85 for water clouds in the visible
        (Hansen & Travis 1974, Space Sci. Rev. 16, 527) [1].
    softness : float, optional
        Width of the soft edge, as a fraction of the smaller of cover and 1 - cover, in
        [0, 1]; 0 gives hard edges [1].
    spectral_slope : float, optional
        Slope of the 1-D power spectrum of a transect (5/3: Cahalan & Snider 1989) [1].
    period : float, optional
        Side of the noise tile (laid as shifted copies) in units of ``scale`` [1].
    texels : int, optional
        Lattice side of the noise tile [count].

    Raises
    ------
    ValueError
        If a field is out of its range.
    """

    cover: float
    scale: float
    altitude: float
    wind: tuple[float, float]
    thickness: float
    seed: int
    albedo: float = 1.0
    asymmetry: float = 0.85
    softness: float = 0.5
    spectral_slope: float = 5.0 / 3.0
    period: float = 16.0
    texels: int = 1024

    def __post_init__(self):
        wind = np.asarray(self.wind, dtype=np.float64).reshape(-1)
        if wind.shape != (2,):
            raise ValueError(f"wind must have 2 components, got {wind.shape}")
        object.__setattr__(self, "wind", (float(wind[0]), float(wind[1])))
        for name in ("cover", "scale", "altitude", "thickness", "albedo", "asymmetry",
                     "softness", "spectral_slope", "period"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "texels", int(self.texels))
        if not 0.0 <= self.cover <= 1.0:
            raise ValueError(f"cover must be in [0, 1], got {self.cover}")
        if self.scale <= 0.0 or self.altitude <= 0.0:
            raise ValueError("scale and altitude must be positive")
        if self.thickness < 0.0:
            raise ValueError("thickness must be >= 0")
        if not 0.0 <= self.albedo <= 1.0:
            raise ValueError("albedo must be in [0, 1]")
        if not -1.0 < self.asymmetry < 1.0:
            raise ValueError("asymmetry must be in (-1, 1)")
        if not 0.0 <= self.softness <= 1.0:
            raise ValueError("softness must be in [0, 1]")
        if self.texels < 4 or self.period <= 0.0:
            raise ValueError("texels must be >= 4 and period positive")

    @property
    def texel(self) -> float:
        """Lattice spacing of the noise on the layer.

        Returns
        -------
        float
            period x scale / texels [m].
        """
        return self.period * self.scale / self.texels

    def _noise_key(self):
        return (self.seed, self.texels, self.period, self.spectral_slope)

    def field(self, s: ArrayLike, time: float, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """The noise where directions ``s`` meet the layer at ``time`` (zero mean, unit variance on the lattice).

        The lattice is read by cubic B-spline interpolation (Unser, Aldroubi & Eden, "Fast
        B-spline transforms for continuous image representation and interpolation", IEEE PAMI
        13(3), 1991: the lattice's spline coefficients, cached), so the field and its gradient
        are continuous and a cloud's edge (a level line of the field) stays a smooth curve
        however much a camera magnifies it; bilinear reading left a kink at every texel, the
        blocky, camouflage-like edges.

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points of the directions [tan]. A raster's grid, (rows, cols, 2) with x
            the same down each column and y along each row, is read without a footprint row by row
            (``kernels.tiling.cloud_grid``), to the same bits.
        time : float
            [s].
        footprint : None, float or numpy.ndarray, optional
            The width each sample stands for on the sky plane [tan]: a scalar or (...) (a round
            footprint), or (..., 2) (the same shape as ``s``): its width along the radius s / |s| and
            across it. The noise is then filtered over it on the layer, as GPUs filter textures
            anisotropically: the mip level is chosen from the narrower width and up to MAX_TAPS
            trilinear taps are spread along the wider one (a camera's pixel near the horizon is
            1 / cos(theta) times longer along the radius than across it on the sky plane: filtered
            round, the far cloud deck was smeared sideways into stepped bands).

        Returns
        -------
        numpy.ndarray
            (...) float64 noise [1].
        """
        flat, offsets, sides = packed_levels(*self._noise_key())
        copies = (TILE_BLEND, self.seed, *self._drifted_copies(time))
        s = np.asarray(s, dtype=np.float64)
        if footprint is None and _on_grid(s):  # a raster's: each row's and column's weights once
            from pipeline.kernels.tiling import cloud_grid  # numba, imported on first use

            rows, cols = self._lattice(s[:, 0], time)[0], self._lattice(s[0], time)[1]
            out = np.empty(s.shape[:2])
            in_shares(out.size, lambda a, b: cloud_grid(flat, offsets, sides, rows, cols, a, b, out.reshape(-1),
                                                        *copies))
            return out
        shape, coords, taps = self._taps(s, time, footprint)
        out = np.empty(coords.shape[1])
        from pipeline.kernels.tiling import cloud_field  # numba, imported on first use

        rows, cols = coords[0], coords[1]  # contiguous, as each sample's taps: a share is their slices
        if taps is None:
            unused, none = np.empty(0), np.empty(0, dtype=np.intp)
            in_shares(len(out), lambda a, b: cloud_field(
                flat, offsets, sides, rows[a:b], cols[a:b], True, none, none, unused, unused, unused, unused,
                out[a:b], *copies))
        else:
            count, k0, blend, major, ex, ey = taps
            in_shares(len(out), lambda a, b: cloud_field(
                flat, offsets, sides, rows[a:b], cols[a:b], False, count[a:b], k0[a:b], blend[a:b], major[a:b],
                ex[a:b], ey[a:b], out[a:b], *copies))
        return out.reshape(shape)

    def _drift(self, time) -> tuple[float, float]:
        """How far the pattern has drifted at ``time`` [s], (rows, cols) [texel]."""
        return -self.wind[1] * float(time) / self.texel, self.wind[0] * float(time) / self.texel

    def _drifted_copies(self, time) -> tuple[int, int]:
        """The copy of the tile (row, col) that ``_taps``'s lattice coordinates (0, 0) are the
        centre of at ``time`` [s]: the drift's whole tiles, negated (``kernels.tiling.cloud_field``)."""
        drift_row, drift_col = self._drift(time)
        return -int(math.floor(drift_row / self.texels)), -int(math.floor(drift_col / self.texels))

    def _taps(self, s, time, footprint=None) -> tuple:
        """Where ``field`` reads the lattice: (the shape of ``s`` (..., 2) [tan] less its last
        axis; the lattice coordinates (row, col) of the samples (2, m) at ``time`` [s] [texel];
        None without a footprint, else the taps as ``kernels.tiling.cloud_field`` takes them: (count (m,), finer
        level k0 (m,), blend towards level k0 + 1 (m,), spread major (m,) [texel], the major
        axis ex, ey (m,) on the lattice))."""
        s = original = np.asarray(s, dtype=np.float64)
        shape = s.shape[:-1]
        s = s.reshape(-1, 2)  # at least one axis
        coords = self._lattice(s, time)
        if footprint is None:
            return shape, coords, None
        if isinstance(footprint, np.ndarray) and not (original.flags.writeable or footprint.flags.writeable):
            return shape, coords, kept_at(_kept_taps, self, (original, footprint),  # to numba: left writable
                                          lambda: self._footprint_taps(s, shape, footprint), read_only=False)
        return shape, coords, self._footprint_taps(s, shape, footprint)

    def _lattice(self, s, time) -> np.ndarray:
        """The lattice coordinates (row, col) (2, m) [texel of level 0] of sky-plane points s (m, 2)
        [tan] at ``time`` [s] (``_taps``)."""
        per_texel = self.altitude / self.texel
        # Drift reduced modulo the tile first, so that late frames keep full precision.
        drift_row, drift_col = self._drift(time)
        shift_col, shift_row = np.mod(drift_col, self.texels), np.mod(drift_row, self.texels)
        coords = np.empty((2, s.shape[0]))
        np.multiply(s[:, 1], -per_texel, out=coords[0])
        coords[0] -= shift_row
        np.multiply(s[:, 0], per_texel, out=coords[1])
        coords[1] -= shift_col
        return coords

    def _footprint_taps(self, s, shape, footprint) -> tuple:
        """``_taps``'s taps at sky-plane points s (m, 2) [tan] of a footprint [tan] (``field``), which
        do not move with time: a still camera's are kept (``kept.kept_at``: 30 ms of a frame of
        sun-and-shade.yaml)."""
        levels = len(packed_levels(*self._noise_key())[2])
        along, across = self._widths(shape, footprint)
        major, minor = np.maximum(along, across), np.minimum(along, across)
        taps = np.clip(np.ceil(major / np.maximum(minor, 1.0) - 1e-9), 1, MAX_TAPS).astype(np.intp)
        level = np.clip(np.log2(np.maximum(np.maximum(minor, major / taps), 1e-300)), 0.0, levels - 1.0)
        # the major axis on the lattice (row grows with -y): the radius, or across it
        radius = np.hypot(s[:, 0], s[:, 1])
        ex = np.where(radius > 0, s[:, 0] / np.maximum(radius, 1e-300), 1.0)
        ey = np.where(radius > 0, s[:, 1] / np.maximum(radius, 1e-300), 0.0)
        ex, ey = np.where(along >= across, ex, -ey), np.where(along >= across, ey, ex)
        k0 = np.minimum(np.floor(level).astype(np.intp), levels - 1)
        return taps, k0, level - k0, major, ex, ey

    def _widths(self, shape, footprint):
        """A footprint (``field``) as its widths along the radius and across it, each
        (prod(shape),) [texel of the lattice]."""
        per_texel = self.altitude / self.texel
        width = np.asarray(footprint, dtype=np.float64)
        if width.ndim == len(shape) + 1 and width.shape[-1] == 2:
            along = np.broadcast_to(width[..., 0], shape).reshape(-1) * per_texel
            across = np.broadcast_to(width[..., 1], shape).reshape(-1) * per_texel
        else:
            along = across = np.broadcast_to(width, shape).reshape(-1) * per_texel
        return along, across

    def coverage(self, s: ArrayLike, time: float, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """Cloud coverage c in [0, 1] at directions ``s`` at ``time``.

        1 in cloud cores, 0 in clear sky; ``c >= 1/2`` on a fraction ``cover`` of the plane. With a
        ``footprint`` the coverage is the footprint's mean coverage, not the coverage of its mean field
        (which cuts a hard edge through the pixel, the stair steps of an aliased edge): the field within
        the footprint is taken as Gaussian about its filtered value with the variance that the filter
        took out (``lost_variance``), and c averaged over it by Gauss-Hermite quadrature, as Heitz &
        Neyret (2018, section 4.3) prefilter a lookup applied to a filtered Gaussian texture.

        Parameters
        ----------
        s, time, footprint
            The directions' sky-plane points (..., 2) [tan], the time [s] and the footprint [tan],
            as ``field`` takes them.

        Returns
        -------
        numpy.ndarray
            (...) float64 coverage [1].
        """
        s = np.asarray(s, dtype=np.float64)
        if self.cover <= 0.0:
            return np.zeros(s.shape[:-1])
        if self.cover >= 1.0:
            return np.ones(s.shape[:-1])
        values, levels = coverage_knots(*self._noise_key(), self.cover, self.softness)
        field = self.field(s, time, footprint)
        if footprint is None:
            return np.interp(field, values, levels)
        spread: np.ndarray = self._spread(s, footprint).reshape(field.shape)
        nodes, weights = _hermegauss(_HERMITE_NODES)
        out = np.empty(field.shape)
        from pipeline.kernels.arrays import hermite_mean  # numba, imported on first use

        field, spread, flat = field.reshape(-1), spread.reshape(-1), out.reshape(-1)
        weights = weights / weights.sum()
        values, levels = (np.ascontiguousarray(t, dtype=np.float64) for t in (values, levels))
        in_shares(len(flat), lambda a, b: hermite_mean(field[a:b], spread[a:b], nodes, weights, values, levels,
                                                      flat[a:b]))
        return out

    def _spread(self, s, footprint) -> np.ndarray:
        """The standard deviation of the field that a footprint filters out at sky-plane points s (..., 2)
        [tan] (``coverage``), flat [1]: a still camera's is kept (``kept.kept_at``)."""
        def compute():
            along, across = self._widths(s.shape[:-1], footprint)
            return np.sqrt(lost_variance(self._noise_key(), along, across))

        if isinstance(footprint, np.ndarray) and not (s.flags.writeable or footprint.flags.writeable):
            return kept_at(_kept_spreads, self, (s, footprint), compute, read_only=False)  # to numba
        return compute()

    def optical_depth(self, s: ArrayLike, time: float, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """Vertical optical depth tau = thickness x coverage where ``s`` meets the layer at ``time``.

        Parameters
        ----------
        s, time, footprint
            As in ``coverage``: the directions' sky-plane points (..., 2) [tan], the time [s], the
            footprint [tan].

        Returns
        -------
        numpy.ndarray
            (...) float64 tau [1].
        """
        return self.thickness * self.coverage(s, time, footprint)

    def transmittance(self, s: ArrayLike, time: float, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """Direct transmittance exp(-tau / cos(theta)) along directions ``s`` at ``time``.

        cos(theta) = 1 / sqrt(1 + |s|^2).

        Parameters
        ----------
        s, time, footprint
            As ``optical_depth`` takes them (``coverage``'s).

        Returns
        -------
        numpy.ndarray
            (...) float64 transmittance [1].
        """
        s = np.asarray(s, dtype=np.float64)
        tau = self.optical_depth(s, time, footprint)
        return np.exp(-tau * np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2))

    def _multiple_tables(self, sun_cosine):
        """(tau nodes, m_sun, m_sky) of the multiple-scattering term for this sun (cached: a
        frame asks for them several times with the same sun)."""
        return _multiple_tables(self, float(sun_cosine))

    def _tables(self, sun_cosine):
        """``_multiple_tables`` computed."""
        t = np.linspace(0.0, 1.0, _TAU_NODES)
        tau = self.thickness * t * t  # denser near 0, where S1 bends most
        g, w = self.asymmetry, self.albedo
        s1_conservative = single_scattering_flux_transmittance(
            tau, sun_cosine, asymmetry=g, albedo=1.0)
        m_sun = np.maximum(0.0, delta_eddington_transmittance(tau, sun_cosine, asymmetry=g)
                           - np.exp(-tau / sun_cosine) - s1_conservative)
        direct = diffuse_direct_transmittance(tau)
        diffuse = two_stream_diffuse_transmittance(tau, albedo=1.0, asymmetry=g) - direct
        m_sky = np.maximum(0.0, diffuse)
        if w < 1.0:
            absorbing = two_stream_diffuse_transmittance(tau, albedo=w, asymmetry=g) - direct
            ratio = np.where(diffuse > 1e-300, np.clip(absorbing, 0.0, None)
                             / np.where(diffuse > 1e-300, diffuse, 1.0), w)
            ratio = np.minimum(ratio, 1.0)
            m_sun = m_sun * ratio
            m_sky = m_sky * ratio
        return tau, m_sun, m_sky

    def radiance(self, s: ArrayLike, time: float, *, sun_s: ArrayLike, sun_irradiance: ArrayLike,
                 sky_irradiance: ArrayLike, multiple_scattering: bool = True, tau: np.ndarray | None = None,
                 footprint: float | np.ndarray | None = None) -> np.ndarray:
        """Light the layer scatters towards the observer along directions ``s``.

        Parameters
        ----------
        s, time
            The directions' sky-plane points (..., 2) [tan] and the time [s], as ``field`` takes them.
        sun_s : numpy.ndarray
            (2,) sky-plane point of the sun (above the horizon) [tan].
        sun_irradiance : numpy.ndarray
            (3,) RGB normal irradiance of the sun above the cloud [klx].
        sky_irradiance : numpy.ndarray
            (3,) RGB horizontal irradiance of the clear sky [klx].
        multiple_scattering : bool, optional
            False keeps Blinn's single scattering alone.
        tau : numpy.ndarray, optional
            (...) optical depth already sampled at ``s`` and ``time`` (as by ``optical_depth``), to
            save sampling the pattern twice [1].
        footprint : None, float or numpy.ndarray, optional
            The pattern's filter width, as in ``field`` (when ``tau`` is not given) [tan].

        Returns
        -------
        numpy.ndarray
            (..., 3) float32 RGB radiance, 0 where there is no cloud [kcd/m^2].
        """
        s = np.asarray(s, dtype=np.float64)
        sun_s = np.asarray(sun_s, dtype=np.float64).reshape(2)
        sun_rgb = np.asarray(sun_irradiance, dtype=np.float64).reshape(3)
        sky_rgb = np.asarray(sky_irradiance, dtype=np.float64).reshape(3)
        if tau is None:
            tau = self.optical_depth(s, time, footprint)
        if self.cover <= 0.0 or self.thickness <= 0.0:
            return np.zeros((*s.shape[:-1], 3), dtype=np.float32)
        # float32 from here on: twice as fast, and far finer than any image needs.
        f32 = np.float32
        sx, sy = s[..., 0].astype(f32), s[..., 1].astype(f32)
        tau32 = np.asarray(tau, dtype=f32)
        inv_mu = sx * sx
        inv_mu += sy * sy
        inv_mu += f32(1.0)
        np.sqrt(inv_mu, out=inv_mu)  # 1 / cos(theta_view)
        inv_mu0 = float(np.sqrt(1.0 + sun_s @ sun_s))
        mu0 = 1.0 / inv_mu0
        cos_scatter = sx * f32(sun_s[0])
        cos_scatter += sy * f32(sun_s[1])
        cos_scatter += f32(1.0)
        cos_scatter /= inv_mu
        cos_scatter *= f32(mu0)
        np.clip(cos_scatter, f32(-1.0), f32(1.0), out=cos_scatter)
        sun_weight = henyey_greenstein(cos_scatter, self.asymmetry).astype(f32, copy=False)
        sun_weight *= f32(self.albedo)
        sun_weight *= inv_mu
        sun_weight *= slab_path(tau32, inv_mu, f32(inv_mu0))  # Blinn single scattering / F [1/sr]
        out = np.empty((*s.shape[:-1], 3), dtype=f32)
        if multiple_scattering:
            nodes, m_sun, m_sky = self._multiple_tables(mu0)
            sky_weight = np.empty_like(sun_weight)  # the np.interp of tables [1/sr], compiled
            from pipeline.kernels.arrays import scattering_weights  # numba, imported on first use

            taus, tables = np.ascontiguousarray(tau, dtype=np.float64).reshape(-1), np.stack(
                [m_sun * (mu0 / np.pi), m_sky / np.pi])
            suns, skies = sun_weight.reshape(-1), sky_weight.reshape(-1)
            in_shares(len(taus), lambda a, b: scattering_weights(taus[a:b], nodes, tables, suns[a:b], skies[a:b]))
            for c in range(3):
                np.multiply(sun_weight, f32(sun_rgb[c]), out=out[..., c])
                out[..., c] += sky_weight * f32(sky_rgb[c])
        else:
            np.multiply(sun_weight[..., None], sun_rgb.astype(f32), out=out)
        return out

    def shade(self, s: ArrayLike, time: float, *, sun_s: ArrayLike, sun_irradiance: ArrayLike,
              sky_irradiance: ArrayLike, multiple_scattering: bool = True,
              footprint: float | np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The transmittance and the radiance along ``s``, sampling the pattern once.

        ``(transmittance(s, time, footprint), radiance(s, time, ..., footprint=footprint))``.

        Parameters
        ----------
        s, time, sun_s, sun_irradiance, sky_irradiance, multiple_scattering, footprint
            As in ``radiance``.

        Returns
        -------
        transmittance : numpy.ndarray
            (...) float64 [1].
        radiance : numpy.ndarray
            (..., 3) float32 RGB [kcd/m^2].
        """
        s = np.asarray(s, dtype=np.float64)
        tau = self.optical_depth(s, time, footprint)
        transmittance = np.exp(-tau * np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2))
        radiance = self.radiance(s, time, sun_s=sun_s, sun_irradiance=sun_irradiance,
                                 sky_irradiance=sky_irradiance,
                                 multiple_scattering=multiple_scattering, tau=tau)
        return transmittance, radiance


def _on_grid(s: np.ndarray) -> bool:
    """Whether sky-plane points s (..., 2) [tan] are a grid: (rows, cols, 2), x the same down each
    column and y the same along each row (a raster's points, ``CloudLayer.field``)."""
    return (s.ndim == 3 and s.shape[0] > 1 and s.shape[1] > 1 and bool((s[:, :, 0] == s[:1, :, 0]).all())
            and bool((s[:, :, 1] == s[:, :1, 1]).all()))


@lru_cache(maxsize=16)
def _multiple_tables(layer: CloudLayer, sun_cosine: float) -> tuple:
    """``CloudLayer._multiple_tables``, cached per layer and sun; read-only arrays."""
    tables = layer._tables(sun_cosine)
    for table in tables:
        table.setflags(write=False)
    return tables
