"""Drifting layers of fractal cloud: their transmittance and the light they scatter
(docs/method.md, "The cloud layer": the pattern, the single- and multiple-scattering model and
its energy bounds).

Why one module: the noise texture, the cover, the transmittance and the scattered light are one
physical model of a layer, each part tuned against the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import ndimage, special

from .composite import henyey_greenstein

__all__ = [
    "CloudLayer", "single_scattering_transmission", "single_scattering_flux_transmittance",
    "delta_eddington_transmittance", "two_stream_diffuse_transmittance", "diffuse_direct_transmittance",
    "fractal_noise", "MAX_TAPS", "TILE_BLEND",
]

_TAU_NODES = 48  # optical-depth nodes of the per-call multiple-scattering table
_QUAD_NODES = 192  # Gauss-Legendre nodes per angle in the single-scattering flux quadrature


# --------------------------------------------------------------------------- physics functions


# numpy's Gauss-Legendre and Gauss-Hermite nodes and weights, cached: numpy finds them as the
# eigenvalues of a matrix at each call (50 ms for 192 nodes on a busy machine, several times a
# frame). Callers must not write to them.
_leggauss = lru_cache(maxsize=4)(np.polynomial.legendre.leggauss)
_hermegauss = lru_cache(maxsize=4)(np.polynomial.hermite_e.hermegauss)


def _phi(x):
    """(1 - exp(-x)) / x for x >= 0, with phi(0) = 1. [dimensionless]"""
    x = np.asarray(x)
    if x.dtype != np.float32:
        x = x.astype(np.float64)
    x = np.maximum(x, np.finfo(x.dtype).tiny)  # expm1 is exact there: phi = 1
    return -np.expm1(-x) / x


def single_scattering_transmission(optical_depth, view_cosine, sun_cosine, phase, *, albedo):
    """Singly scattered radiance below a slab lit from above, per unit sun normal irradiance.

    Blinn 1982 ("Light reflection functions for simulation of clouds and dusty surfaces",
    SIGGRAPH 82), transmitted light of a low-albedo layer:
    ``L / F = w p mu0 / (mu - mu0) (exp(-tau/mu) - exp(-tau/mu0))``, evaluated in the form
    ``w p (tau / mu) exp(-tau min(1/mu, 1/mu0)) phi(tau |1/mu0 - 1/mu|)``, which is exact and
    stable at ``mu = mu0``.

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau, vertical optical depth of the slab, >= 0 [1].
    view_cosine : float or numpy.ndarray
        mu, cosine of the zenith angle of the viewing direction, in (0, 1] [1].
    sun_cosine : float or numpy.ndarray
        mu0, cosine of the sun's zenith angle, in (0, 1] [1].
    phase : float or numpy.ndarray
        p, phase function at the scattering angle, normalised to 1 over the sphere [1/sr].
    albedo : float
        w, single-scattering albedo in [0, 1] [1].

    Arrays broadcast.

    Returns
    -------
    numpy.ndarray
        L / F, float64 of the broadcast shape [1/sr].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    inv_mu = 1.0 / np.asarray(view_cosine, dtype=np.float64)
    inv_mu0 = 1.0 / np.asarray(sun_cosine, dtype=np.float64)
    return albedo * np.asarray(phase, dtype=np.float64) * inv_mu * _slab_path(tau, inv_mu, inv_mu0)


def _slab_path(tau, inv_mu, inv_mu0):
    """tau exp(-tau m) phi(tau d), m = min(1/mu, 1/mu0), d = |1/mu0 - 1/mu|: the integral over
    the depth t in [0, tau] of exp(-t / mu0 - (tau - t) / mu). [dimensionless]"""
    near = np.minimum(inv_mu, inv_mu0)
    x = np.abs(inv_mu0 - inv_mu)
    x = x * tau
    result = np.exp(-tau * near)
    result *= tau
    result *= _phi(x)
    return result


def single_scattering_flux_transmittance(optical_depth, sun_cosine, *, asymmetry, albedo,
                                         nodes=_QUAD_NODES):
    """S1: the singly scattered flux leaving the base of a slab over the sun's flux F mu0.

    The hemispheric integral of ``single_scattering_transmission`` times ``mu`` over the lower
    hemisphere, by Gauss-Legendre quadrature in zenith (``nodes``) and azimuth (``nodes``);
    the azimuth integral of the Henyey-Greenstein phase is done once for all depths.

    Parameters
    ----------
    optical_depth : numpy.ndarray
        tau, vertical optical depths >= 0, any shape [1].
    sun_cosine : float
        mu0 in (0, 1] [1].
    asymmetry : float
        g of the Henyey-Greenstein phase [1].
    albedo : float
        Single-scattering albedo [1].
    nodes : int, optional
        Gauss-Legendre nodes per angle.

    Returns
    -------
    numpy.ndarray
        S1, float64 with the shape of ``optical_depth``, in [0, albedo] [1].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    mu0 = float(sun_cosine)
    x, w = _leggauss(int(nodes))
    theta = 0.25 * np.pi * (x + 1.0)  # zenith of the view, (0, pi/2)
    w_theta = 0.25 * np.pi * w
    phi = 0.5 * np.pi * (x + 1.0)  # azimuth from the sun, (0, pi); the integrand is even
    w_phi = np.pi * w  # twice 0.5 pi w: both halves of the circle
    sin0 = np.sqrt(max(0.0, 1.0 - mu0 * mu0))
    cos_scatter = (np.cos(theta)[:, None] * mu0
                   + np.sin(theta)[:, None] * sin0 * np.cos(phi)[None, :])
    phase_ring = henyey_greenstein(cos_scatter, asymmetry) @ w_phi  # (nodes,) [1/sr x rad]
    mu = np.cos(theta)
    inv_mu, inv_mu0 = 1.0 / mu, 1.0 / mu0
    t = tau.reshape(-1, 1)
    path = _slab_path(t, inv_mu[None, :], inv_mu0)
    # integral of L mu d_omega = F w  int p path sin(theta) d_theta d_phi
    s1 = albedo * (path @ (w_theta * np.sin(theta) * phase_ring)) / mu0
    return s1.reshape(tau.shape)


def delta_eddington_transmittance(optical_depth, sun_cosine, *, asymmetry):
    """Total (direct + diffuse) flux transmittance of a non-absorbing slab under a collimated sun.

    Delta-Eddington (Joseph, Wiscombe & Weinman 1976, J. Atmos. Sci. 33, 2452-2459): the forward
    peak ``f = g^2`` is folded into the direct beam, ``tau' = (1 - g^2) tau``, ``g' = g / (1 + g)``;
    then the conservative Eddington two-stream solution (Meador & Weaver 1980, J. Atmos. Sci. 37,
    630-643; ``gamma1 = 3 (1 - g') / 4``, ``gamma3 = (2 - 3 g' mu0) / 4``):
    ``R = (gamma1 tau' + (gamma3 - gamma1 mu0)(1 - exp(-tau'/mu0))) / (1 + gamma1 tau')``,
    ``T = 1 - R``.

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau, vertical optical depth >= 0 [1].
    sun_cosine : float or numpy.ndarray
        mu0 in (0, 1], broadcastable with ``optical_depth`` [1].
    asymmetry : float
        g in [0, 1) [1].

    Returns
    -------
    numpy.ndarray
        T, the transmitted flux over the incident ``F mu0``, float64 of the broadcast shape [1].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    mu0 = np.asarray(sun_cosine, dtype=np.float64)
    g = float(asymmetry)
    tau_s = (1.0 - g * g) * tau
    g_s = g / (1.0 + g)
    gamma1 = 0.75 * (1.0 - g_s)
    gamma3 = 0.25 * (2.0 - 3.0 * g_s * mu0)
    reflectance = ((gamma1 * tau_s + (gamma3 - gamma1 * mu0) * -np.expm1(-tau_s / mu0))
                   / (1.0 + gamma1 * tau_s))
    return 1.0 - reflectance


def two_stream_diffuse_transmittance(optical_depth, *, albedo, asymmetry):
    """Flux transmittance of a slab under uniform diffuse light, two-stream (hemispheric mean).

    ``dF+/dtau = g1 F+ - g2 F-``, ``dF-/dtau = g2 F+ - g1 F-``, ``g1 = 2 - w (1 + g)``,
    ``g2 = w (1 - g)`` (Meador & Weaver 1980, Table 1); with ``k = sqrt(g1^2 - g2^2)`` and
    ``r = g2 / (g1 + k)``, ``T = (1 - r^2) exp(-k tau) / (1 - r^2 exp(-2 k tau))``, written to
    stay finite as ``k -> 0`` (conservative limit ``T = 1 / (1 + (1 - g) tau)``, Bohren 1987,
    Am. J. Phys. 55, 524).

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau >= 0 [1].
    albedo : float
        w in [0, 1] [1].
    asymmetry : float
        g in (-1, 1) [1].

    Returns
    -------
    numpy.ndarray
        T, direct and diffuse together, float64 of the shape of ``optical_depth`` [1].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    g1 = 2.0 - albedo * (1.0 + asymmetry)
    g2 = albedo * (1.0 - asymmetry)
    k = np.sqrt(max(0.0, g1 * g1 - g2 * g2))
    r = g2 / (g1 + k)
    # (1 - r^2) = 2k / (g1 + k); divide numerator and denominator by 2k.
    return np.exp(-k * tau) / (1.0 + (g1 + k) * r * r * tau * _phi(2.0 * k * tau))


def diffuse_direct_transmittance(optical_depth):
    """Unscattered fraction of uniform diffuse light through a slab: 2 E3(tau).

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau >= 0 [1].

    Returns
    -------
    numpy.ndarray
        float64 of the shape of ``optical_depth`` [1].
    """
    return 2.0 * special.expn(3, np.asarray(optical_depth, dtype=np.float64))


# --------------------------------------------------------------------------- noise texture


@lru_cache(maxsize=16)
def _noise(seed: int, texels: int, period: float, spectral_slope: float):
    """(texture, sorted values), both read-only float64 (texels, texels); see ``fractal_noise``."""
    n = int(texels)
    white = np.random.default_rng(seed).standard_normal((n, n))
    ky = np.fft.fftfreq(n, d=1.0 / n)[:, None]  # cycles per tile
    kx = np.fft.rfftfreq(n, d=1.0 / n)[None, :]
    k0 = 0.5 * float(period)  # 1 / (2 scale) in cycles per tile of period * scale
    amplitude = (kx * kx + ky * ky + k0 * k0) ** (-(spectral_slope + 1.0) / 4.0)
    amplitude[0, 0] = 0.0
    field = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(n, n))
    field -= field.mean()
    field /= field.std()
    ordered = np.sort(field, axis=None)
    field.setflags(write=False)
    ordered.setflags(write=False)
    return field, ordered


def fractal_noise(seed, texels=1024, *, period=16.0, spectral_slope=5.0 / 3.0):
    """The periodic fractal noise lattice of a cloud layer (zero mean, unit variance).

    Cached: the same arguments return the same array.

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng`` for the white noise.
    texels : int, optional
        Lattice side; one tile is ``texels x texels`` [count].
    period : float, optional
        Tile side in units of the feature size ``scale`` [1].
    spectral_slope : float, optional
        beta, slope of the 1-D transect power spectrum ``k^-beta`` [1].

    Returns
    -------
    numpy.ndarray
        Read-only float64 (texels, texels), indexed [row, col] with col along +x and row along -y [1].
    """
    return _noise(int(seed), int(texels), float(period), float(spectral_slope))[0]


@lru_cache(maxsize=8)
def _noise_levels(seed: int, texels: int, period: float, spectral_slope: float) -> tuple:
    """The noise lattice and its 2 x 2 box-filtered levels down to one texel (a mip pyramid of
    a periodic texture: every level keeps the mean and tiles). Read-only float64."""
    levels = [_noise(seed, texels, period, spectral_slope)[0]]
    while min(levels[-1].shape) > 1 and all(n % 2 == 0 for n in levels[-1].shape):
        a = levels[-1]
        coarser = 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])
        coarser.setflags(write=False)
        levels.append(coarser)
    return tuple(levels)


MAX_TAPS = 16
"""Most trilinear taps along a footprint's longer axis (``CloudLayer.field``)."""

_HERMITE_NODES = 8  # Gauss-Hermite nodes of a footprint's mean coverage


@lru_cache(maxsize=8)
def _level_variances(seed: int, texels: int, period: float, spectral_slope: float) -> np.ndarray:
    """Variance of each mip level of the noise (level 0: 1): (levels,) float64, entry k that of
    the lattice's means over boxes of 2^k texels. [dimensionless]"""
    return np.array([level.var() for level in _noise_levels(seed, texels, period, spectral_slope)])


def _lost_variance(key, along, across) -> np.ndarray:
    """The variance of the noise within a footprint of widths ``along`` x ``across`` (m,)
    [texel] about its mean: 1 - var(box mean) for a box of the footprint's area, from the mip
    levels' variances (log-linear between them); below 2 texels, the lost variance of a
    2-texel box times (width / 2)^2 (a smooth field varies linearly within a small box).
    [dimensionless]"""
    variances = _level_variances(*key)
    lost = 1.0 - variances
    width = np.sqrt(np.maximum(along * across, 1e-300))  # the box of the same area [texel]
    level = np.log2(np.maximum(width, 1e-300))
    big = np.interp(level, np.arange(len(lost)), lost)
    small = lost[1] * (width / 2.0) ** 2 if len(lost) > 1 else np.zeros_like(width)
    return np.clip(np.where(width >= 2.0, big, np.minimum(small, big)), 0.0, 1.0)


@lru_cache(maxsize=8)
def _spline(seed: int, texels: int, period: float, spectral_slope: float) -> np.ndarray:
    """Cubic B-spline coefficients of the noise lattice (periodic), read-only float64."""
    coefficients = ndimage.spline_filter(_noise(seed, texels, period, spectral_slope)[0], order=3,
                                         mode="grid-wrap")
    coefficients.setflags(write=False)
    return coefficients


@lru_cache(maxsize=8)
def _packed(seed: int, texels: int, period: float, spectral_slope: float) -> tuple:
    """What ``_tiling.cloud_field`` reads: (every level in one flat float64 array, each level's offset
    in it, each level's side [texel]). Level 0 is the lattice's cubic B-spline coefficients
    (``_spline``), the coarser levels the box-filtered lattice (``_noise_levels``)."""
    levels = (_spline(seed, texels, period, spectral_slope),) + _noise_levels(seed, texels, period, spectral_slope)[1:]
    sides = np.array([level.shape[0] for level in levels], dtype=np.intp)
    offsets = np.concatenate([[0], np.cumsum([level.size for level in levels])[:-1]]).astype(np.intp)
    flat = np.concatenate([level.reshape(-1) for level in levels])
    flat.setflags(write=False)
    return flat, offsets, sides


TILE_BLEND = 0.125
"""Width of the band about each edge of a copy of the tile, as a fraction of the tile's side, over
which the copies on both sides blend (``_tiling.cloud_field``). [1]"""


def _scattering_loop(tau, nodes, tables, sun_weight, sky_weight):
    """The multiple-scattering weights of ``CloudLayer.radiance`` at optical depths ``tau`` (m,)
    (compiled by ``_compiled``): ``sun_weight`` (m,) float32 gets float32(interp(tau, nodes,
    tables[0])) added, ``sky_weight`` (m,) float32 is set to float32(interp(tau, nodes,
    tables[1])), each interpolation that of ``np.interp`` operation for operation (the node at
    or below tau by binary search, the ends held, the slope of the interval times the distance
    from its first node plus its first value, and where that is NaN the same from the other
    end), so the weights are the same to the bit. ``nodes`` strictly increasing."""
    last = nodes.shape[0] - 1
    slopes = np.empty((2, last))  # as np.interp's, per interval
    for k in range(2):
        for j in range(last):
            slopes[k, j] = (tables[k, j + 1] - tables[k, j]) / (nodes[j + 1] - nodes[j])
    values = np.empty(2)
    lo = 0
    for i in range(tau.shape[0]):
        x = tau[i]
        # the interval [nodes[lo], nodes[lo + 1]) that holds x, for both tables: the previous
        # point's (neighbours are alike), else found by bisection
        if x == x and nodes[0] <= x < nodes[last] and not nodes[lo] <= x < nodes[lo + 1]:
            lo, hi = 0, last
            while hi - lo > 1:
                mid = (lo + hi) >> 1
                if nodes[mid] <= x:
                    lo = mid
                else:
                    hi = mid
        for k in range(2):
            if x != x:
                values[k] = x
            elif x >= nodes[last]:
                values[k] = tables[k, last]
            elif x < nodes[0]:
                values[k] = tables[k, 0]
            elif nodes[lo] == x:
                values[k] = tables[k, lo]
            else:
                value = slopes[k, lo] * (x - nodes[lo]) + tables[k, lo]
                if value != value:
                    value = slopes[k, lo] * (x - nodes[lo + 1]) + tables[k, lo + 1]
                    if value != value and tables[k, lo] == tables[k, lo + 1]:
                        value = tables[k, lo]
                values[k] = value
        sun_weight[i] += np.float32(values[0])
        sky_weight[i] = np.float32(values[1])


@lru_cache(maxsize=4)
def _compiled(loop):
    """``loop`` (``_scattering_loop``) compiled by numba (imported here, on
    first use: it costs 0.3 s to import; the compiled code is cached on disk)."""
    from numba import njit

    return njit(cache=True, nogil=True, error_model="numpy")(loop)


@lru_cache(maxsize=64)
def _knots(seed, texels, period, spectral_slope, cover, softness):
    """Field values and coverages of the rank-space smoothstep (see the module docstring)."""
    ordered = _noise(seed, texels, period, spectral_slope)[1]
    u0 = 1.0 - cover
    h = softness * min(cover, 1.0 - cover)
    t = np.linspace(0.0, 1.0, 33)
    ranks = u0 - h + 2.0 * h * t
    values = np.interp(ranks * (ordered.size - 1), np.arange(ordered.size), ordered)
    if h <= 0.0 or not np.all(np.diff(values) > 0.0):
        values = np.array([values[16], values[16] + 1e-12])
        return values, np.array([0.0, 1.0])
    return values, t * t * (3.0 - 2.0 * t)


# --------------------------------------------------------------------------- the layer


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

    def field(self, s, time, footprint=None) -> np.ndarray:
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
            (..., 2) sky-plane points of the directions [tan].
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
        shape, coords, taps = self._taps(s, time, footprint)
        flat, offsets, sides = _packed(*self._noise_key())
        out = np.empty(coords.shape[1])
        from ._tiling import cloud_field  # numba, imported on first use

        copies = (TILE_BLEND, self.seed, *self._drifted_copies(time))
        if taps is None:
            unused, none = np.empty(0), np.empty(0, dtype=np.intp)
            cloud_field(flat, offsets, sides, coords[0], coords[1], True, none, none, unused, unused, unused,
                        unused, out, *copies)
        else:
            cloud_field(flat, offsets, sides, coords[0], coords[1], False, *taps, out, *copies)
        return out.reshape(shape)

    def _drift(self, time) -> tuple[float, float]:
        """How far the pattern has drifted at ``time`` [s], (rows, cols) [texel]."""
        return -self.wind[1] * float(time) / self.texel, self.wind[0] * float(time) / self.texel

    def _drifted_copies(self, time) -> tuple[int, int]:
        """The copy of the tile (row, col) that ``_taps``'s lattice coordinates (0, 0) are the
        centre of at ``time`` [s]: the drift's whole tiles, negated (``_tiling.cloud_field``)."""
        return tuple(-int(math.floor(drift / self.texels)) for drift in self._drift(time))

    def _taps(self, s, time, footprint=None) -> tuple:
        """Where ``field`` reads the lattice: (the shape of ``s`` (..., 2) [tan] less its last
        axis; the lattice coordinates (row, col) of the samples (2, m) at ``time`` [s] [texel];
        None without a footprint, else the taps as ``_tiling.cloud_field`` takes them: (count (m,), finer
        level k0 (m,), blend towards level k0 + 1 (m,), spread major (m,) [texel], the major
        axis ex, ey (m,) on the lattice))."""
        s = np.asarray(s, dtype=np.float64)
        n = self.texels
        per_texel = self.altitude / self.texel
        # Drift reduced modulo the tile first, so that late frames keep full precision.
        drift_row, drift_col = self._drift(time)
        shift_col, shift_row = np.mod(drift_col, n), np.mod(drift_row, n)
        shape = s.shape[:-1]
        s = s.reshape(-1, 2)  # at least one axis
        coords = np.empty((2, s.shape[0]))
        np.multiply(s[:, 1], -per_texel, out=coords[0])
        coords[0] -= shift_row
        np.multiply(s[:, 0], per_texel, out=coords[1])
        coords[1] -= shift_col
        if footprint is None:
            return shape, coords, None
        levels = len(_packed(*self._noise_key())[2])
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
        return shape, coords, (taps, k0, level - k0, major, ex, ey)

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

    def coverage(self, s, time, footprint=None) -> np.ndarray:
        """Cloud coverage c in [0, 1] at directions ``s`` at ``time``.

        1 in cloud cores, 0 in clear sky; ``c >= 1/2`` on a fraction ``cover`` of the plane. With a
        ``footprint`` the coverage is the footprint's mean coverage, not the coverage of its mean field
        (which cuts a hard edge through the pixel, the stair steps of an aliased edge): the field within
        the footprint is taken as Gaussian about its filtered value with the variance that the filter
        took out (``_lost_variance``), and c averaged over it by Gauss-Hermite quadrature, as Heitz &
        Neyret (2018, section 4.3) prefilter a lookup applied to a filtered Gaussian texture.

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points of the directions [tan].
        time : float
            [s].
        footprint : None, float or numpy.ndarray, optional
            As in ``field`` [tan].

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
        values, levels = _knots(*self._noise_key(), self.cover, self.softness)
        field = self.field(s, time, footprint)
        if footprint is None:
            return np.interp(field, values, levels)
        along, across = self._widths(s.shape[:-1], footprint)
        spread = np.sqrt(_lost_variance(self._noise_key(), along, across)).reshape(field.shape)
        nodes, weights = _hermegauss(_HERMITE_NODES)
        out = np.zeros(field.shape)
        for z, w in zip(nodes, weights / weights.sum()):
            out += w * np.interp(field + z * spread, values, levels)
        return out

    def optical_depth(self, s, time, footprint=None) -> np.ndarray:
        """Vertical optical depth tau = thickness x coverage where ``s`` meets the layer at ``time``.

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points of the directions [tan].
        time : float
            [s].
        footprint : None, float or numpy.ndarray, optional
            As in ``field`` [tan].

        Returns
        -------
        numpy.ndarray
            (...) float64 tau [1].
        """
        return self.thickness * self.coverage(s, time, footprint)

    def transmittance(self, s, time, footprint=None) -> np.ndarray:
        """Direct transmittance exp(-tau / cos(theta)) along directions ``s`` at ``time``.

        cos(theta) = 1 / sqrt(1 + |s|^2).

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points of the directions [tan].
        time : float
            [s].
        footprint : None, float or numpy.ndarray, optional
            As in ``field`` [tan].

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

    def radiance(self, s, time, *, sun_s, sun_irradiance, sky_irradiance,
                 multiple_scattering=True, tau=None, footprint=None) -> np.ndarray:
        """Light the layer scatters towards the observer along directions ``s``.

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points of the directions [tan].
        time : float
            [s].
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
            return np.zeros(s.shape[:-1] + (3,), dtype=np.float32)
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
        sun_weight *= _slab_path(tau32, inv_mu, f32(inv_mu0))  # Blinn single scattering / F [1/sr]
        out = np.empty(s.shape[:-1] + (3,), dtype=f32)
        if multiple_scattering:
            nodes, m_sun, m_sky = self._multiple_tables(mu0)
            sky_weight = np.empty_like(sun_weight)  # the np.interp of tables [1/sr], compiled
            _compiled(_scattering_loop)(np.ascontiguousarray(tau, dtype=np.float64).reshape(-1), nodes,
                                        np.stack([m_sun * (mu0 / np.pi), m_sky / np.pi]),
                                        sun_weight.reshape(-1), sky_weight.reshape(-1))
            for c in range(3):
                np.multiply(sun_weight, f32(sun_rgb[c]), out=out[..., c])
                out[..., c] += sky_weight * f32(sky_rgb[c])
        else:
            np.multiply(sun_weight[..., None], sun_rgb.astype(f32), out=out)
        return out

    def shade(self, s, time, *, sun_s, sun_irradiance, sky_irradiance, multiple_scattering=True,
              footprint=None):
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


@lru_cache(maxsize=16)
def _multiple_tables(layer: CloudLayer, sun_cosine: float) -> tuple:
    """``CloudLayer._multiple_tables``, cached per layer and sun; read-only arrays."""
    tables = layer._tables(sun_cosine)
    for table in tables:
        table.setflags(write=False)
    return tables
