"""Sky models and their weighted sky-plane rasters ``e`` (Max 1991, eq. 1 and Fig. 6).

``Sky`` declares what the renderer and the camera ask of a sky; ``UniformSky``, ``EquirectSky``
(an HDRI) and ``ProceduralSky`` (clear sky, sun, moon, clouds) implement all of it.

A sky raster cell holds the integral of ``L(s) cos^4(theta) dA`` over the cell: radiance times
projected solid angle, so that the unshadowed irradiance of the ground is the plain sum of the
raster plus ``outside``, the irradiance of all the sky the raster does not cover. No hidden
normalising factor: radiance in, irradiance [radiance x sr] out.

Equirectangular skies (docs/method.md, "Conventions"): the top row touches the zenith, the centre column
looks north, east is at three quarters of the width, texel centres at
``((col + 0.5) / width, (row + 0.5) / height)``. ``rotation`` turns the sky about the zenith
towards the east: a feature at image azimuth ``phi`` is seen at azimuth ``phi + rotation``.
``cut_sun`` moves an HDRI's sun out of the image into a disc for the fine kernel (``sun_kernel``).

Why one module: the three sky models share the sky-plane raster, the sun disc and its
kernel, the moon and the ``Sky`` interface they implement; split, each would import the
others' helpers.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property, lru_cache
from typing import Protocol, runtime_checkable

import numpy as np
from scipy import ndimage

from . import clearsky, daylight, eclipse
from .camera import equirect_lookup
from .colour import REC709_LUMINANCE
from .constants import SUN_ANGULAR_RADIUS
from .vocabulary import DEFAULT_CIE_TYPE, PROCEDURAL_MODELS, TURBIDITY_RANGE
from .geometry import Grid, direction_vector, fold, projected_solid_angle, sky_grid, sky_offset, tangent_axes


@dataclass(frozen=True)
class SkyRaster:
    """The weighted sky on a sky-plane grid.

    grid : Grid -- sky-plane grid [tan]; cell (r, c) is the sky offset s = grid centre.
    weighted : ndarray (channels, rows, cols) float32 -- radiance x projected solid angle per cell.
    outside : ndarray (channels,) float64 -- irradiance of the sky outside the raster. [radiance x sr]
    """

    grid: Grid
    weighted: np.ndarray
    outside: np.ndarray

    @cached_property
    def total(self) -> np.ndarray:
        """Irradiance of the whole unshadowed sky per channel (float64). [radiance x sr]"""
        return self.weighted.sum(axis=(1, 2), dtype=np.float64) + self.outside


@runtime_checkable
class Sky(Protocol):
    """What the renderer and the camera ask of a sky model; ``UniformSky``, ``EquirectSky`` and
    ``ProceduralSky`` implement all of it. Irradiances are (3,) float64, horizontal, in the
    sky's units ([radiance x sr]; klx for ProceduralSky).

    sun : SunDisc or None -- the disc drawn by ``sun_kernel`` on the fine grid, None without one.
    sky_irradiance : the sky's irradiance without the sun disc (clouds and the moon included).
    raster(grid, *, fold_period=None) -> SkyRaster -- the weighted sky on a sky-plane grid,
        folded modulo ``fold_period`` (rows, cols) if given.
    sun_fraction() -> float -- S, the sun's power reaching the ground over the clear,
        uneclipsed sun's; 0.0 without a sun.
    total_sun_irradiance() -> the sun's before the moon and clouds dim it (an HDRI's: as
        photographed); zeros without a sun.
    view_radiance(w, s, footprint=None) -> (..., 3) -- the sky's radiance without the sun disc
        along unit vectors w (..., 3) with sky-plane points s (..., 2) [tan] (the camera holds
        wz at MIN_UPWARD or more), each standing for a sky-plane width ``footprint`` [tan]
        (None, scalar, (...) or (..., 2): along the radius and across) over which a cloud
        pattern is filtered. A model uses what it needs of w, s and footprint.
    """

    sun: SunDisc | None
    sky_irradiance: np.ndarray

    def raster(self, grid: Grid, *, fold_period=None) -> SkyRaster: ...

    def sun_fraction(self) -> float: ...

    def total_sun_irradiance(self) -> np.ndarray: ...

    def view_radiance(self, w, s, footprint=None) -> np.ndarray: ...


@dataclass(frozen=True)
class UniformSky:
    """A sky of the same radiance in every direction.

    radiance : ndarray (3,) -- linear RGB radiance. [scene-linear radiance]
    """

    radiance: np.ndarray

    @property
    def sun(self) -> None:
        """No sun disc."""
        return None

    @property
    def sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,), pi L. [radiance x sr]"""
        return np.pi * np.asarray(self.radiance, dtype=np.float64)

    def sun_fraction(self) -> float:
        """S = 0: no sun. [1]"""
        return 0.0

    def total_sun_irradiance(self) -> np.ndarray:
        """Zeros (3,): no sun. [radiance x sr]"""
        return np.zeros(3)

    def view_radiance(self, w, s, footprint=None) -> np.ndarray:
        """The radiance (..., 3) float32, the same along every unit vector w (..., 3). [radiance]"""
        radiance = np.asarray(self.radiance, dtype=np.float32)
        return np.broadcast_to(radiance, np.shape(w)[:-1] + radiance.shape).copy()

    def raster(self, grid: Grid, *, fold_period=None) -> SkyRaster:
        """Exact cell integrals of the uniform sky on ``grid``; with ``fold_period`` (rows, cols)
        folded modulo that period (see ``EquirectSky.raster``)."""
        radiance = np.asarray(self.radiance, dtype=np.float64)
        weights = projected_solid_angle(grid)
        if fold_period is not None:
            weights = fold(weights[None], sky_offset(grid), fold_period)[0]
            grid = sky_grid((0, 0), tuple(fold_period), grid.pixel)
        weighted = (radiance[:, None, None] * weights[None]).astype(np.float32)
        outside = radiance * np.pi - weighted.sum(axis=(1, 2), dtype=np.float64)
        return SkyRaster(grid, weighted, outside)


KEPT_RASTERS = 4
"""Most sky-plane rasters an ``EquirectSky`` keeps (a run asks for one or two per layer). [count]"""


@dataclass(frozen=True)
class EquirectSky:
    """A sky from an equirectangular image (HDRI), texels taken as piecewise constant.

    image : ndarray (height, width, 3) float32 -- linear RGB radiance, finite, not negative.
    rotation : float -- turn about the zenith towards the east. [rad]
    sun : SunDisc or None -- the sun cut out of the image (``cut_sun``), drawn by ``sun_kernel``
        on the fine grid of the two-scale method; the image then holds the sky without it.
    sun_normal_irradiance : ndarray (3,) or None -- the cut sun's normal irradiance, given with
        ``sun``. [radiance x sr]
    """

    image: np.ndarray
    rotation: float = 0.0
    sun: SunDisc | None = None
    sun_normal_irradiance: np.ndarray | None = None

    def __post_init__(self):
        if (self.sun is None) != (self.sun_normal_irradiance is None):
            raise ValueError("sun and sun_normal_irradiance come together, or neither")
        if self.sun is not None and np.shape(self.sun_normal_irradiance) != (3,):
            raise ValueError(f"sun_normal_irradiance must be (3,), got {np.shape(self.sun_normal_irradiance)}")

    @cached_property
    def sun_direction(self) -> np.ndarray:
        """Unit vector towards the cut sun's centre (with a sun only). [1]"""
        return direction_vector(self.sun.azimuth, self.sun.elevation)

    def sun_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the cut sun (3,), E_n cos(zenith): the sun kernel's sum; 0
        without a sun. ``total_irradiance() + sun_irradiance()`` is the uncut image's. [radiance x sr]"""
        if self.sun is None:
            return np.zeros(3)
        return np.asarray(self.sun_normal_irradiance, dtype=np.float64) * self.sun_direction[2]

    def sun_fraction(self) -> float:
        """S = 1 with a sun: a photographed sun is what it is (clouds and moon are already in the
        image); 0 without one. [1]"""
        return 0.0 if self.sun is None else 1.0

    def total_sun_irradiance(self) -> np.ndarray:
        """The cut sun's horizontal irradiance (3,), ``sun_irradiance()``: as photographed. [radiance x sr]"""
        return self.sun_irradiance()

    @cached_property
    def sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,) of the image, without the cut sun: ``total_irradiance()``. [radiance x sr]"""
        return self.total_irradiance()

    def view_radiance(self, w, s, footprint=None) -> np.ndarray:
        """Bilinear samples (..., 3) float32 of the image along unit vectors w (..., 3), ``rotation``
        included, rows held to the upper half (``camera.equirect_lookup``). [radiance]"""
        return equirect_lookup(self.image, w, rotation=self.rotation, sky_only=True)

    def _sun_samples(self, w, footprint):
        """Radiance (..., 3) of the cut sun at unit vectors w (..., 3) (see ``_disc_samples``). [radiance]"""
        return _disc_samples(w, footprint, self.sun, self.sun_direction, self.sun_normal_irradiance)

    def total_irradiance(self) -> np.ndarray:
        """Exact irradiance of the upper hemisphere of the piecewise-constant image. [radiance x sr]"""
        height, width, _ = self.image.shape
        theta0, theta1 = _row_bounds(height)
        weight = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
        rows = len(weight)
        return np.einsum("r,rcn->n", weight, self.image[:rows].astype(np.float64))

    def raster(self, grid: Grid, *, fold_period=None) -> SkyRaster:
        """``_raster``, kept on this sky for the next call with the same grid and fold (read-only:
        a still image gives every frame of a run the same raster; it cost seconds a frame)."""
        key = (grid, None if fold_period is None else tuple(int(n) for n in fold_period))
        try:
            kept = self._rasters.get(key)
        except TypeError:  # a grid given with lists: not kept
            return self._raster(grid, fold_period=fold_period)
        if kept is None:
            kept = self._raster(grid, fold_period=fold_period)
            for array in (kept.weighted, kept.outside):
                array.flags.writeable = False
            if len(self._rasters) >= KEPT_RASTERS:
                self._rasters.pop(next(iter(self._rasters)))
            self._rasters[key] = kept
        return kept

    @cached_property
    def _rasters(self) -> dict:
        """``raster``'s results by (grid, fold period), oldest first."""
        return {}

    def _raster(self, grid: Grid, *, fold_period=None) -> SkyRaster:
        """Area-averaged resampling onto ``grid`` that keeps every texel's energy.

        Each texel is cut into sub-texels no larger than half a cell on the sky plane; each
        sub-texel's energy (radiance x its exact projected solid angle) is spread bilinearly
        over the four nearest cells. A small bright sun keeps its energy exactly; what lands
        off the grid is counted in ``outside``.

        fold_period : (rows, cols) or None -- deposit each cell at its offset modulo this period
            (a periodic canopy tile): the raster returned is the folded one, on the grid of
            offsets 0..period-1, and the full ``grid`` never exists in memory.
        """
        height, width, channels = self.image.shape
        wrap = None
        if fold_period is not None:
            wrap = (sky_offset(grid), tuple(fold_period))
        rows, cols = grid.shape if wrap is None else wrap[1]
        step = 0.5 * grid.pixel
        near, reach, keep_phi = _grid_footprint(grid)
        accum = np.zeros((channels, rows * cols), dtype=np.float64)
        pending: list = []
        theta0, theta1 = _row_bounds(height)
        for row in range(len(theta0)):
            # only the band of the row that can land on the grid (one cell of bilinear reach)
            t0 = max(np.tan(theta0[row]), near - 2 * step)
            t1 = min(np.tan(theta1[row]) if theta1[row] < np.pi / 2 else np.inf, reach)
            if t1 <= t0:
                continue
            n_theta = max(1, int(np.ceil((t1 - t0) / step)))
            n_phi = max(1, int(np.ceil(t1 * (2.0 * np.pi / width) / step)))
            edges = np.arctan(np.linspace(t0, t1, n_theta + 1))
            centres = 0.5 * (np.tan(edges[:-1]) + np.tan(edges[1:]))
            weight = 0.5 * (np.sin(edges[1:]) ** 2 - np.sin(edges[:-1]) ** 2) * (
                2.0 * np.pi / (width * n_phi)
            )
            sub_cols = np.arange(width * n_phi)
            phi = ((sub_cols + 0.5) / (width * n_phi) - 0.5) * 2.0 * np.pi + self.rotation
            kept = keep_phi(phi, 2.0 * np.pi / (width * n_phi))
            sub_cols, phi = sub_cols[kept], phi[kept]
            chunk = max(1, (1 << 21) // max(1, len(phi)))  # bounded memory per pass
            for lo in range(0, n_theta, chunk):
                sx = centres[lo : lo + chunk, None] * np.sin(phi)[None, :]
                sy = centres[lo : lo + chunk, None] * np.cos(phi)[None, :]
                index, share, sub_row, sub_col = _bilinear_shares(grid, sx, sy, wrap)
                texel = self.image[row, sub_cols[sub_col] // n_phi].astype(np.float64)
                pending.append((index, texel * (share * weight[lo + sub_row])[:, None]))
                if sum(len(i) for i, _ in pending) > 1 << 22:
                    _flush(accum, pending)
        _flush(accum, pending)
        weighted = accum.reshape(channels, rows, cols).astype(np.float32)
        outside = self.total_irradiance() - weighted.sum(axis=(1, 2), dtype=np.float64)
        if wrap is not None:
            grid = sky_grid((0, 0), wrap[1], grid.pixel)
        return SkyRaster(grid, weighted, outside)


def _grid_footprint(grid: Grid):
    """Where a sky-plane grid lies as seen from the zenith, with one cell of margin.

    Returns (near, reach, keep_phi): the nearest and farthest distances [tan] of the grid from
    the origin, and keep_phi(phi, dphi) -> bool mask of the azimuths [rad] (each of width dphi)
    whose rays can cross the grid.
    """
    x_min, y_min, x_max, y_max = grid.extent
    margin = grid.pixel
    x_min, y_min, x_max, y_max = x_min - margin, y_min - margin, x_max + margin, y_max + margin
    reach = np.hypot(max(abs(x_min), abs(x_max)), max(abs(y_min), abs(y_max)))
    near = np.hypot(max(0.0, x_min, -x_max), max(0.0, y_min, -y_max))
    if near == 0.0:
        return near, reach, lambda phi, dphi: np.ones(len(phi), dtype=bool)
    corners = np.arctan2([x_min, x_min, x_max, x_max], [y_min, y_max, y_min, y_max])
    middle = np.arctan2((x_min + x_max) / 2, (y_min + y_max) / 2)
    spread = np.angle(np.exp(1j * (corners - middle)))  # within (-pi/2, pi/2): the grid is off the origin
    lo, hi = spread.min(), spread.max()

    def keep_phi(phi, dphi):
        off = np.angle(np.exp(1j * (phi - middle)))
        return (off >= lo - dphi) & (off <= hi + dphi)

    return near, reach, keep_phi


def _row_bounds(height: int):
    """Zenith-angle bounds [rad] of the equirectangular rows that reach above the horizon."""
    edges = np.arange(height + 1) * (np.pi / height)
    upper = edges[:-1] < np.pi / 2
    return edges[:-1][upper], np.minimum(edges[1:][upper], np.pi / 2)


def _bilinear_shares(grid: Grid, sx, sy, wrap=None):
    """Bilinear deposits of sky-plane points (sx, sy) (2-D arrays) on the cells of ``grid``.

    Returns the flat cell index, the share (the four shares of a point sum to 1), and the row and
    column of the point each deposit came from; shares falling off the grid are left out. With
    ``wrap`` = (offset of grid cell [0, 0], period), the index is that of the offset modulo
    the period, on a (period rows, period cols) raster.
    """
    rows, cols = grid.shape
    rowf, colf = grid.raster_from_ground(sx, sy)
    r0 = np.floor(rowf)
    c0 = np.floor(colf)
    fr, fc = rowf - r0, colf - c0
    r0, c0 = r0.astype(np.int64), c0.astype(np.int64)
    point_row, point_col = np.indices(sx.shape)
    parts = []
    for dr, dc, share in (
        (0, 0, (1 - fr) * (1 - fc)),
        (0, 1, (1 - fr) * fc),
        (1, 0, fr * (1 - fc)),
        (1, 1, fr * fc),
    ):
        r, c = r0 + dr, c0 + dc
        inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        r, c = r[inside], c[inside]
        if wrap is not None:
            (r_start, c_start), (r_period, c_period) = wrap
            r, c, cols_out = (r + r_start) % r_period, (c + c_start) % c_period, c_period
        else:
            cols_out = cols
        parts.append((r * cols_out + c, share[inside], point_row[inside], point_col[inside]))
    return tuple(np.concatenate(arrays) for arrays in zip(*parts))


def _flush(accum, pending: list) -> None:
    """Add the pending (flat index, values (n, channels)) deposits to ``accum`` and empty the list."""
    if not pending:
        return
    index = np.concatenate([i for i, _ in pending])
    values = np.concatenate([v for _, v in pending])
    for ch in range(accum.shape[0]):
        accum[ch] += np.bincount(index, weights=values[:, ch], minlength=accum.shape[1])
    pending.clear()


# ---------------------------------------------------------------------------------------------
# Procedural sky: a clear sky at the absolute levels of ``daylight`` (Ineichen & Perez 2002 with
# the Perez et al. 1990 efficacies) shaped by ``clearsky`` (CIE standard general sky or Preetham
# et al. 1999), an attenuated limb-darkened sun, a dark moon and duck-typed clouds.
#
# Units: radiance in kcd/m^2 per linear Rec.709 channel (the channels' Rec.709 luminance is the
# photometric luminance), so irradiances [radiance x sr] come out in klx. Directions: azimuth from
# north towards east, zenith angle from +z [rad]; sky-plane points s = (wx/wz, wy/wz) [tan].
#
# Clouds protocol (implemented in ``pipeline/clouds.py``, used here by duck typing):
#   clouds.transmittance(s (..., 2), time, footprint=None) -> (...) in [0, 1], direct transmittance along s;
#   clouds.radiance(s (..., 2), time, *, sun_s (2,), sun_irradiance (3,), sky_irradiance (3,), footprint=None)
#       -> (..., 3) light scattered towards the observer [kcd/m^2], given the sun's sky-plane
#       point, its normal irradiance above the clouds after the atmosphere and the moon [klx], and
#       the clear sky's horizontal irradiance [klx].
#   clouds.shade(s, time, *, sun_s, sun_irradiance, sky_irradiance, footprint=None), optional ->
#       (transmittance, radiance) as the two above return them, the pattern sampled once.
#   Sky behind cloud: L_clear(s) T(s) + clouds.radiance(s); the sun is dimmed by T(s_sun).
# ---------------------------------------------------------------------------------------------

RGB_WAVELENGTHS = eclipse.RGB_WAVELENGTHS
"""Representative wavelengths of the R, G, B channels for the colour of the sun's attenuation
(``eclipse.RGB_WAVELENGTHS``, which the eclipse sky's channels share). [um]"""

LIMB_DARKENING = (0.52, 0.59, 0.68)
"""Linear limb-darkening coefficients u of I(mu) / I(1) = 1 - u (1 - mu) for R, G, B. G: the
linear law with the disc-mean of Allen's quadratic law at 550 nm, I/I(1) = 0.30 + 0.93 mu -
0.23 mu^2 (Cox 2000, Allen's Astrophysical Quantities, 4th ed., sec. 14.7), i.e. 1 - u/3 = 0.805;
R and B follow the stronger darkening at shorter wavelengths (Hestroffer & Magnan 1998, A&A 333,
338); approximate. [1]"""

CLEAR_SKY_NODE_SPACING = 0.02
"""Largest spacing of the nodes on which ``ProceduralSky.raster`` evaluates the clear sky. [tan]"""

MAX_KERNEL_CELLS = 4_000_000
"""Largest sun kernel block, in cells: a low sun on a fine grid is refused rather than ground out."""


def sun_colour(zenith: float, turbidity: float) -> np.ndarray:
    """Colour of the sun's direct light after the atmosphere, scaled to Rec.709 luminance 1: the
    direct transmittance for R, G, B of Preetham et al. (1999, appendix A.1), Rayleigh
    tau_R = exp(-0.008735 lambda^-4.08 m) times Angstrom aerosol tau_a = exp(-beta lambda^-1.3 m),
    beta = 0.04608 T - 0.04586, at RGB_WAVELENGTHS [um] (``eclipse.vertical_optical_depths``), m
    the Kasten & Young (1989) relative air mass of pvlib. Only the ratios between the channels are kept: the level is ``daylight``'s.

    zenith : sun zenith angle, in [0, pi/2). [rad]   turbidity : T. [1]
    Returns (3,) float64. [1]
    """
    from pvlib import atmosphere

    m = float(atmosphere.get_relative_airmass(float(np.degrees(zenith)), "kastenyoung1989"))
    rayleigh, aerosol = eclipse.vertical_optical_depths(turbidity)
    transmittance = np.exp(-m * (rayleigh + aerosol))
    return transmittance / (transmittance @ np.asarray(REC709_LUMINANCE, dtype=np.float64))


def sun_disc_radiance(angular_distance, *, angular_radius: float, normal_irradiance, limb_darkening):
    """Radiance of a limb-darkened disc, linear law I(mu) = I(1) (1 - u (1 - mu)),
    mu = sqrt(1 - (rho / r)^2) (e.g. Cox 2000, Allen's Astrophysical Quantities, sec. 14.7).

    angular_distance : rho, from the disc centre; 0 beyond the limb. [rad]
    angular_radius : r. [rad]
    normal_irradiance : (3,) integral of the radiance over the flat disc, pi r^2 I(1) (1 - u/3). [klx]
    limb_darkening : (3,) u, 0 for a uniform disc. [1]
    Returns (..., 3) float64. [kcd/m^2]
    """
    rho = np.asarray(angular_distance, dtype=np.float64)[..., None]
    u = np.asarray(limb_darkening, dtype=np.float64)
    centre = np.asarray(normal_irradiance, dtype=np.float64) / (np.pi * angular_radius**2 * (1.0 - u / 3.0))
    mu = np.sqrt(np.clip(1.0 - (rho / angular_radius) ** 2, 0.0, 1.0))
    return np.where(rho <= angular_radius, centre * (1.0 - u * (1.0 - mu)), 0.0)


@dataclass(frozen=True)
class SunDisc:
    """The sun as seen from the ground.

    azimuth : from north towards east. [rad]
    elevation : above the horizon (geometric). [rad]
    angular_radius : radius of the disc; its normal irradiance scales as its square. [rad]
    limb_darkening : (3,) linear-law coefficients u for R, G, B; (0, 0, 0) for a uniform disc. [1]
    """

    azimuth: float
    elevation: float
    angular_radius: float = SUN_ANGULAR_RADIUS
    limb_darkening: tuple = LIMB_DARKENING

    def __post_init__(self):
        _check_disc(self, "sun")
        u = np.asarray(self.limb_darkening, dtype=np.float64)
        if u.shape != (3,) or np.any(~((u >= 0) & (u <= 1))):
            raise ValueError(f"sun limb_darkening must be three numbers in [0, 1], got {self.limb_darkening}")


@dataclass(frozen=True)
class MoonDisc:
    """The new moon: a dark disc that cuts the sun (it does not hide the sky, which is lit in front of it).

    azimuth, elevation, angular_radius : as for SunDisc. [rad]
    """

    azimuth: float
    elevation: float
    angular_radius: float

    def __post_init__(self):
        _check_disc(self, "moon")


def _check_disc(disc, name):
    if not (np.isfinite(disc.azimuth) and np.isfinite(disc.elevation) and abs(disc.elevation) <= np.pi / 2):
        raise ValueError(f"{name} azimuth and elevation must be finite, |elevation| <= pi/2 [rad]")
    if not (0.0 < disc.angular_radius < 0.1):
        raise ValueError(f"{name} angular_radius must be in (0, 0.1) [rad], got {disc.angular_radius}")


def _unit(s) -> np.ndarray:
    """Unit vectors (..., 3) of sky-plane points s (..., 2). [tan] -> [1]"""
    s = np.asarray(s, dtype=np.float64)
    cos_zenith = 1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
    return np.stack([s[..., 0] * cos_zenith, s[..., 1] * cos_zenith, cos_zenith], axis=-1)


def _angle(w, c):
    """Angle [rad] between unit vectors w (..., 3) and c (3,), stable for small angles."""
    return 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(w - c, axis=-1), 0.0, 1.0))


def _disc_samples(w, footprint, sun: SunDisc, direction, normal_irradiance, moon: MoonDisc | None = None):
    """Radiance (..., 3) of the limb-darkened sun disc at unit vectors w (..., 3), optionally cut
    by a dark moon, the disc edges (sun limb, moon limb) anti-aliased by a linear ramp over
    ``footprint(centre, rho)`` [rad]: the sample spacing measured along the angular distance rho
    from ``centre``.

    sun : SunDisc (its radius and limb darkening); direction : (3,) unit vector of its centre. [1]
    normal_irradiance : (3,) of the whole disc. [radiance x sr]
    Returns (..., 3) float64. [radiance]
    """
    r = sun.angular_radius
    rho = _angle(w, direction)
    value = sun_disc_radiance(np.minimum(rho, r), angular_radius=r, normal_irradiance=normal_irradiance,
                              limb_darkening=sun.limb_darkening)
    cover = np.clip(0.5 - (rho - r) / footprint(direction, rho), 0.0, 1.0)
    if moon is not None:
        centre = direction_vector(moon.azimuth, moon.elevation)
        rho_m = _angle(w, centre)
        cover *= np.clip(0.5 + (rho_m - moon.angular_radius) / footprint(centre, rho_m), 0.0, 1.0)
    return value * cover[..., None]


# numpy's Gauss-Legendre nodes and weights, cached: numpy finds them as the eigenvalues of a
# matrix at each call, several times a frame. Callers must not write to them.
_leggauss = lru_cache(maxsize=4)(np.polynomial.legendre.leggauss)


def _gauss_legendre(a, b, n):
    """Nodes and weights of n-point Gauss-Legendre on [a, b] (arrays broadcast, nodes on the last axis)."""
    x, w = _leggauss(n)
    a, b = np.asarray(a, dtype=np.float64)[..., None], np.asarray(b, dtype=np.float64)[..., None]
    return a + (b - a) * (x + 1.0) / 2.0, (b - a) / 2.0 * w


@dataclass(frozen=True)
class ProceduralSky:
    """Clear sky in absolute units with the sun, an optional moon and optional clouds.

    turbidity : Linke turbidity factor TL, in vocabulary.TURBIDITY_RANGE: the levels of sun and
        sky (``daylight.clear_daylight``) and the colours of both. [1]
    sun : SunDisc -- elevation at least ``daylight.TWILIGHT_END`` (-6 degrees, the end of civil
        twilight; lower: ValueError). Below 10 degrees the levels follow the USNO twilight curve
        (``daylight.sky_daylight``); with its disc not wholly above the horizon the sun gives no
        direct light. Its angular radius gives its distance, so the extraterrestrial irradiance. [rad]
    moon : MoonDisc or None.
    clouds : an object with the clouds protocol (module comment above), or None.
    time : passed to the clouds. [s]
    skylight : factor on the clear sky's radiance; 0 leaves the sun alone, as in the paper's
        Fig. 11. [1]
    shape : the clear sky's angular distribution, a name in ``vocabulary.PROCEDURAL_MODELS``; cie_type : the
        CIE standard general sky type with shape 'cie', 1..15.
    altitude : of the site above sea level. [m]
    eclipse_table : (elevations, azimuths, path nodes) of a deep eclipse's line-of-sight table
        (``eclipse.EclipseField``); ``eclipse.METER_TABLE`` for an exposure meter. [count]

    Radiance in kcd/m^2, irradiance in klx (linear Rec.709 channels). The clear sky (no moon, no
    clouds, skylight 1) gives the diffuse horizontal illuminance of ``daylight`` and the sun its
    direct normal illuminance. The moon cuts the sun and dims the clear sky and the clouds' glow
    by the same (limb-weighted) factor, since skylight is scattered sunlight; below the horizon
    there is no light (0).
    """

    turbidity: float
    sun: SunDisc
    moon: MoonDisc | None = None
    clouds: object | None = None
    time: float = 0.0
    skylight: float = 1.0
    shape: str = "cie"
    cie_type: int = DEFAULT_CIE_TYPE
    altitude: float = 0.0
    eclipse_table: tuple = (eclipse.TABLE_ELEVATIONS, eclipse.TABLE_AZIMUTHS, eclipse.PATH_NODES)

    def __post_init__(self):
        lo, hi = TURBIDITY_RANGE
        if not (lo <= self.turbidity <= hi):
            raise ValueError(f"turbidity must be in [{lo}, {hi}], got {self.turbidity}")
        if not self.sun.elevation >= daylight.TWILIGHT_END:
            raise ValueError(f"sun elevation must be at least {np.degrees(daylight.TWILIGHT_END):g} degrees (the end "
                             f"of civil twilight) for the sky, got {np.degrees(self.sun.elevation):.2f} degrees")
        if self.shape not in PROCEDURAL_MODELS:
            raise ValueError(f"unknown sky shape {self.shape!r} (valid: {', '.join(PROCEDURAL_MODELS)})")
        if self.cie_type not in clearsky.CIE_TYPES:
            raise ValueError(f"cie_type must be 1..15, got {self.cie_type}")

    # --- the sun ------------------------------------------------------------------------------
    @cached_property
    def sun_direction(self) -> np.ndarray:
        """Unit vector towards the sun's centre. [1]"""
        return direction_vector(self.sun.azimuth, self.sun.elevation)

    @cached_property
    def sun_point(self) -> np.ndarray:
        """Sky-plane point of the sun's centre (2,). [tan]"""
        return self.sun_direction[:2] / self.sun_direction[2]

    @cached_property
    def daylight(self) -> daylight.ClearDaylight:
        """The clear sky's direct and diffuse light at this sun, turbidity, altitude and distance."""
        return daylight.sky_daylight(self.sun.elevation, self.turbidity, altitude=self.altitude,
                                     distance_factor=(self.sun.angular_radius / SUN_ANGULAR_RADIUS) ** 2,
                                     sun_radius=self.sun.angular_radius)

    @cached_property
    def sun_normal_irradiance(self) -> np.ndarray:
        """Clear, uneclipsed normal irradiance of the sun after the atmosphere (3,): the direct
        normal illuminance of ``daylight`` in the colour of ``sun_colour`` (zeros with the disc
        not wholly up). [klx]"""
        zenith = min(np.pi / 2 - self.sun.elevation, np.pi / 2)
        return self.daylight.direct_normal_illuminance * sun_colour(zenith, self.turbidity)

    def total_sun_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the clear, uneclipsed sun (3,): the sun kernel's sum without moon
        or cloud, E_n cos(zenith) (to O(r^2)). [klx]"""
        return self.sun_normal_irradiance * self.sun_direction[2]

    @cached_property
    def moon_visible(self) -> np.ndarray:
        """Fraction of the limb-darkened sun's power the moon leaves visible, per channel (3,). [1]

        Ring by ring: the ring of radius rho about the sun's centre is covered by the moon (centre d
        away, radius R) over arccos((rho^2 + d^2 - R^2) / (2 rho d)) / pi of its length; the rings
        are summed with Gauss-Legendre between the radii where that fraction has kinks. The discs
        are flat circles of their angular radii (error O(r^2)).
        """
        if self.moon is None:
            return np.ones(3)
        r, big_r = self.sun.angular_radius, self.moon.angular_radius
        d = float(_angle(direction_vector(self.moon.azimuth, self.moon.elevation), self.sun_direction))
        if d >= r + big_r:
            return np.ones(3)
        cuts = np.unique(np.clip([0.0, abs(d - big_r), d + big_r, r], 0.0, r))
        rho, w = _gauss_legendre(cuts[:-1], cuts[1:], 48)
        rho, w = rho.ravel(), w.ravel()
        k = (rho**2 + d**2 - big_r**2) / (2.0 * rho * max(d, 1e-300))
        covered = np.arccos(np.clip(k, -1.0, 1.0)) / np.pi
        ring = sun_disc_radiance(rho, angular_radius=r, normal_irradiance=np.ones(3),
                                 limb_darkening=self.sun.limb_darkening) * (w * rho)[:, None]
        return 1.0 - (ring * covered[:, None]).sum(axis=0) / ring.sum(axis=0)

    @cached_property
    def sun_cloud_transmittance(self) -> float:
        """Cloud transmittance towards the sun's centre, 1 without clouds. [1]"""
        if self.clouds is None:
            return 1.0
        return float(np.clip(self.clouds.transmittance(self.sun_point[None], self.time)[0], 0.0, 1.0))

    def sun_fraction(self) -> float:
        """S: direct sun power reaching the ground after moon and clouds over that of the clear,
        uneclipsed sun (docs/method.md, "The procedural sky"), weighted by Rec.709 luminance. [1]"""
        e = self.sun_normal_irradiance * REC709_LUMINANCE
        if not e.sum() > 0:  # a set sun (twilight)
            return 0.0
        return float(self.sun_cloud_transmittance * (e @ self.moon_visible) / e.sum())

    def sun_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the sun after moon and clouds (3,): the sum of its kernel
        with 16 cells across the disc, which weights each part of a moon-cut disc by its own
        cos(theta) (its error is measured in docs/accuracy.md); zeros when the disc is not
        wholly above the horizon (``daylight.sky_daylight`` gives it no light then). Below
        KERNEL_FLOOR, where the kernel stretches past its limit: E_n cos(zenith) times the
        moon's ``moon_visible`` and the clouds' transmittance (the centre's cos(theta)). [klx]"""
        if self.sun.elevation - self.sun.angular_radius <= 1e-3:
            return np.zeros(3)
        if self.sun.elevation < KERNEL_FLOOR:
            return self.total_sun_irradiance() * self.moon_visible * self.sun_cloud_transmittance
        return sun_kernel(self, self.sun.angular_radius / 8).weighted.sum(axis=(1, 2), dtype=np.float64)

    def _sun_samples(self, w, footprint):
        """Visible sun radiance (..., 3) [kcd/m^2] at unit vectors w (..., 3), cut by the moon and
        dimmed by the clouds' transmittance towards the sun's centre (see ``_disc_samples``)."""
        return _disc_samples(w, footprint, self.sun, self.sun_direction, self.sun_normal_irradiance,
                             self.moon) * self.sun_cloud_transmittance

    # --- the sky ------------------------------------------------------------------------------
    @cached_property
    def _sky_dimming(self) -> np.ndarray:
        """Factor on the clear sky (3,): the sun's visible fraction (eclipse), times skylight. [1]"""
        return self.moon_visible * self.skylight

    def _relative_sky(self, s) -> np.ndarray:
        """The clear sky's shape and colour at sky-plane points s (..., 2) [tan]: zenith luminance 1. [1]"""
        w = _unit(s)
        return clearsky.relative_sky(w[..., 2], _angle(w, self.sun_direction), sun_zenith=np.pi / 2 - self.sun.elevation,
                                     turbidity=self.turbidity, shape=self.shape, cie_type=self.cie_type)

    @cached_property
    def _relative_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,) of the sky of zenith luminance 1 (``_relative_sky``). [sr]"""
        weight = _outside_nodes(None)[1]
        return (_relative_nodes(self._clear_key, _outside_nodes, None) * weight[..., None]).sum(axis=(0, 1, 2))

    @cached_property
    def _clear_key(self) -> ProceduralSky:
        """This sky without what does not shape the clear sky (the sun's size and limb, moon,
        clouds, time, skylight): the key of the caches of its shape."""
        return replace(self, sun=SunDisc(self.sun.azimuth, self.sun.elevation), moon=None, clouds=None,
                       time=0.0, skylight=1.0)

    @cached_property
    def zenith_luminance(self) -> float:
        """Luminance of the clear, uneclipsed sky at the zenith: the one that gives the diffuse
        horizontal illuminance of ``daylight`` (skylight and the moon not applied). [kcd/m^2]"""
        luminance = self._relative_irradiance @ np.asarray(REC709_LUMINANCE, dtype=np.float64)
        return self.daylight.diffuse_horizontal_illuminance / luminance

    def clear_radiance(self, s) -> np.ndarray:
        """Clear-sky radiance at sky-plane points s (..., 2) [tan], eclipse-dimmed, no sun disc. [kcd/m^2]"""
        return self._clear(s)

    def _clear(self, s, corona: bool = True) -> np.ndarray:
        """``clear_radiance``; ``corona`` False leaves the corona out (``equirect`` deposits it). [kcd/m^2]"""
        L = self._relative_sky(s) * (self.zenith_luminance * self._dimming_at(s))
        if corona and self._deep:
            L = L + self.corona_radiance(_unit(s))
        return L

    # --- the deep eclipse (docs/method.md, "The eclipse sky") ---------------------------------
    @cached_property
    def _deep(self) -> float:
        """b: the weight of the deep-eclipse sky (``eclipse.deep_weight``), 0 without a moon or
        above 99.8% obscuration, where the sky is the clear sky times S. [1]"""
        if self.moon is None:
            return 0.0
        return eclipse.deep_weight(float(self.moon_visible @ np.asarray(REC709_LUMINANCE, dtype=np.float64)))

    @cached_property
    def moon_direction(self) -> np.ndarray:
        """Unit vector towards the moon's centre (with a moon). [1]"""
        return direction_vector(self.moon.azimuth, self.moon.elevation)

    @cached_property
    def _eclipse_field(self) -> eclipse.EclipseField:
        """F and M of every sky direction at this sun and moon (``eclipse.line_of_sight``)."""
        return eclipse.EclipseField.compute(
            table=self.eclipse_table, sun_direction=self.sun_direction, moon_direction=self.moon_direction,
            sun_radius=self.sun.angular_radius, moon_radius=self.moon.angular_radius, turbidity=self.turbidity)

    def _dimming_at(self, s) -> np.ndarray:
        """Factor on the clear sky at sky-plane points s (..., 2) [tan]: ``_sky_dimming`` (3,)
        above 99.8% obscuration; deeper, (..., 3)
        (1 - b) S + b (F(w) + k c M(w) G(w)) times skylight (``eclipse``), G the clear sky's
        shape 90 degrees from the sun over its shape at w (no circumsolar glow in the multiply
        scattered light). [1]"""
        b = self._deep
        if not b:
            return self._sky_dimming
        w = _unit(s)
        f, m = self._eclipse_field(w)
        # the multiply scattered light has no circumsolar glow: the clear sky's shape at 90
        # degrees from the sun (its gradation with zenith angle kept), over its shape here
        glowless = clearsky.relative_sky(w[..., 2], np.full(w.shape[:-1], np.pi / 2),
                                         sun_zenith=np.pi / 2 - self.sun.elevation, turbidity=self.turbidity,
                                         shape=self.shape, cie_type=self.cie_type) / self._relative_sky(s)
        deep = f + eclipse.MULTIPLE_SCATTERING * eclipse.floor_colour(self.turbidity) * m * glowless
        return ((1.0 - b) * self.moon_visible + b * deep) * self.skylight

    def corona_radiance(self, w) -> np.ndarray:
        """The corona as drawn (``eclipse.corona_drawn``: Baumbach's profile, ending with no edge
        at ``eclipse.CORONA_REACH`` solar radii) at unit vectors w (..., 3) times b, 0 behind
        the moon: B(r) / B_sun of the sun's clear mean disc radiance E_n / (pi r^2). [kcd/m^2]"""
        w = np.asarray(w, dtype=np.float64)
        r = self.sun.angular_radius
        mean_disc = self.sun_normal_irradiance / (np.pi * r * r)
        profile = eclipse.corona_drawn(_angle(w, self.sun_direction) / r)
        profile = np.where(_angle(w, self.moon_direction) >= self.moon.angular_radius, profile, 0.0)
        return (self._deep * profile)[..., None] * mean_disc

    @cached_property
    def corona_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,) of ``corona_radiance`` (the moon taken as concentric with the
        sun, ``eclipse.corona_drawn_beyond``), dimmed by the cloud towards the sun. [klx]"""
        if not self._deep:
            return np.zeros(3)
        beyond = eclipse.corona_drawn_beyond(self.moon.angular_radius / self.sun.angular_radius)
        return (self._deep * beyond * self.sun_cloud_transmittance) * self.total_sun_irradiance()

    def _corona_cells(self, grid: Grid):
        """(flat cell indices, (3, n) cell integrals of corona L cos^4(theta) dA) of ``grid``'s cells
        within ``eclipse.CORONA_REACH`` solar radii of the sun, 8 x 8 sub-samples a cell. [klx]"""
        reach = eclipse.CORONA_REACH * self.sun.angular_radius
        rows, cols = grid.shape
        x, y = grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
        near = _angle(_unit(np.stack(np.broadcast_arrays(x, y), axis=-1)), self.sun_direction) <= reach + grid.pixel
        idx = np.flatnonzero(near)
        if idx.size == 0:
            return idx, np.zeros((3, 0))
        n = 8
        offsets = ((np.arange(n) + 0.5) / n - 0.5) * grid.pixel
        ox, oy = np.meshgrid(offsets, -offsets)
        sx = np.broadcast_to(x, (rows, cols)).ravel()[idx, None, None] + ox
        sy = np.broadcast_to(y, (rows, cols)).ravel()[idx, None, None] + oy
        cos4 = 1.0 / (1.0 + sx * sx + sy * sy) ** 2
        L = self.corona_radiance(_unit(np.stack([sx, sy], axis=-1))) * self.sun_cloud_transmittance
        return idx, np.einsum("kijc,kij->ck", L, cos4) * (grid.pixel / n) ** 2

    def radiance(self, s, footprint=None) -> np.ndarray:
        """Sky radiance without the sun disc at sky-plane points s (..., 2) [tan]:
        L_clear T + cloud glow. ``footprint``: None, or the sky-plane width each point stands
        for (scalar or (...)) [tan], over which the cloud pattern is filtered (a camera's
        pixel near the horizon spans kilometres of cloud deck). [kcd/m^2]"""
        return self._with_clouds(self.clear_radiance(s), s, footprint)

    def _with_clouds(self, L, s, footprint=None) -> np.ndarray:
        """The clear-sky radiance L (..., 3) [kcd/m^2] at sky-plane points s behind the clouds:
        L T + cloud glow (L itself, scaled in place, without clouds). [kcd/m^2]"""
        if self.clouds is None:
            return L
        transmittance, glow = self._cloud_shade(s, footprint)
        L *= np.clip(transmittance, 0.0, 1.0)[..., None]
        return L + glow

    def _cloud_shade(self, s, footprint=None):
        """The clouds' (transmittance (...), radiance (..., 3) [kcd/m^2]) at sky-plane points s
        (..., 2) [tan]: by their ``shade`` where they have one (the pattern sampled once)."""
        shade = getattr(self.clouds, "shade", None)
        if shade is not None:
            return shade(s, self.time, footprint=footprint, **self._cloud_light)
        return (self.clouds.transmittance(s, self.time, footprint),
                self.clouds.radiance(s, self.time, footprint=footprint, **self._cloud_light))

    def view_radiance(self, w, s, footprint=None) -> np.ndarray:
        """``radiance(s, footprint)`` (..., 3) at the sky-plane points s (..., 2) of the unit
        vectors w. [kcd/m^2]"""
        return self.radiance(s, footprint=footprint)

    @cached_property
    def _cloud_light(self) -> dict:
        return dict(sun_s=self.sun_point.copy(), sun_irradiance=self.sun_normal_irradiance * self.moon_visible,
                    sky_irradiance=self.clear_sky_irradiance)

    @cached_property
    def clear_sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the clear sky (3,), no sun disc, eclipse-dimmed. [klx]"""
        if self._deep:
            s, weight = _outside_nodes(None)
            L = _relative_nodes(self._clear_key, _outside_nodes, None) * (self.zenith_luminance * self._dimming_at(s))
            return (L * weight[..., None]).sum(axis=(0, 1, 2))
        return self._relative_irradiance * (self.zenith_luminance * self._sky_dimming)

    @cached_property
    def sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the sky with clouds (3,), no sun disc (the corona in a deep
        eclipse included). [klx]"""
        if self._deep:
            return self._outside(None) + self.corona_irradiance
        return self._outside(None)

    def unshadowed(self) -> np.ndarray:
        """Horizontal irradiance of the open sky and sun (3,): any raster's total plus the sun kernel's sum. [klx]"""
        return self.sky_irradiance + self.sun_irradiance()

    def _outside(self, extent) -> np.ndarray:
        """Irradiance [klx] of the sky (``radiance``) outside the sky-plane rectangle ``extent``
        (x_min, y_min, x_max, y_max) [tan] (None: the whole hemisphere), by the quadrature of
        ``_outside_nodes``; the clear sky's shape at its nodes is computed once for all frames
        with this clear sky (``_relative_nodes``)."""
        s, weight = _outside_nodes(extent)
        L = _relative_nodes(self._clear_key, _outside_nodes, extent) * (self.zenith_luminance * self._dimming_at(s))
        return (self._with_clouds(L, s) * weight[..., None]).sum(axis=(0, 1, 2))

    def raster(self, grid: Grid, *, fold_period=None) -> SkyRaster:
        """The sky without the sun disc on a sky-plane grid: radiance at cell centres times the
        exact projected solid angles (Max 1991, eq. 2); ``outside`` by quadrature of the rest of the
        hemisphere (``_outside``). With ``fold_period`` (rows, cols), folded as in
        ``EquirectSky.raster``. Units: [klx].

        The smooth clear sky is evaluated on every k-th cell centre, nodes at most
        ``CLEAR_SKY_NODE_SPACING`` apart, and interpolated bilinearly (least accurate in the few
        cells at the sun where the Perez circumsolar term has a cusp; measured in
        docs/accuracy.md); clouds are evaluated at every cell centre.
        """
        from . import _array_loops

        rows, cols = grid.shape
        k = max(1, int(CLEAR_SKY_NODE_SPACING // grid.pixel))
        _, row_at, row_frac = _lerp_nodes(rows, k)
        _, col_at, col_frac = _lerp_nodes(cols, k)
        # clear_radiance at the nodes, the shape computed once for all frames (_relative_nodes)
        relative = _relative_nodes(self._clear_key, _raster_nodes, grid, k)
        dimming = self._dimming_at(_raster_nodes(grid, k)[0]) if self._deep else self._sky_dimming
        nodes = np.moveaxis(relative * (self.zenith_luminance * dimming), -1, 0)
        nodes = nodes.astype(np.float32)
        along = nodes[:, :, col_at] * (1 - col_frac) + nodes[:, :, col_at + 1] * col_frac  # (3, nodes, cols)
        weights = _solid_angles32(grid)
        weighted = np.empty((3, rows, cols), dtype=np.float32)
        x, y = grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
        step = max(1, (1 << 20) // cols)
        transmittance, glow = np.empty((0, 0)), np.empty((0, 0, 3), dtype=np.float32)  # no clouds
        for lo in range(0, rows, step):  # bounded memory
            part = slice(lo, lo + step)
            if self.clouds is not None:
                transmittance, glow = self._cloud_shade(np.stack(np.broadcast_arrays(x, y[part]), axis=-1))
            # compiled: the clear sky between node rows, the clouds' transmittance and glow,
            # the solid angles, as L = lerp; L *= clip(T, 0, 1); L += glow; L * weights
            _array_loops.sky_rows(along, row_at, row_frac, lo, len(row_at[part]), self.clouds is not None,
                                  np.ascontiguousarray(transmittance, dtype=np.float64),
                                  np.ascontiguousarray(glow, dtype=np.float32), weights, weighted)
        outside = self._outside(grid.extent)
        if self._deep:  # the corona, cell by cell (its light beyond the grid is left out)
            idx, corona = self._corona_cells(grid)
            weighted.reshape(3, -1)[:, idx] += corona.astype(np.float32)
        if fold_period is not None:
            weighted = fold(weighted, sky_offset(grid), fold_period)
            grid = sky_grid((0, 0), tuple(fold_period), grid.pixel)
        return SkyRaster(grid, weighted, outside)

    def equirect(self, width: int, *, parts: bool = False):
        """Equirectangular radiance image (width / 2, width, 3) float32 [kcd/m^2] in the module's
        convention (top row at the zenith, centre column north, east at three quarters), with the
        sun disc deposited area-correctly: each of many small samples of the disc carries
        L cos(theta) d_omega into the texel it falls in, divided by that texel's exact projected
        solid angle, so the image's irradiance equals ``unshadowed()``. Below the horizon: 0.
        ``parts``: (the image, {"sun": the sun disc alone, "sky": the rest}), each float32 as
        rounded from the float64 parts the image is the sum of (the light passes)."""
        if width < 4 or width % 2:
            raise ValueError(f"width must be even and at least 4, got {width}")
        height = width // 2
        upper = height // 2
        theta = (np.arange(upper) + 0.5) * (np.pi / height)
        phi = ((np.arange(width) + 0.5) / width - 0.5) * 2.0 * np.pi
        tan = np.tan(theta)[:, None]
        s = np.stack([tan * np.sin(phi), tan * np.cos(phi)], axis=-1)
        image = np.zeros((height, width, 3), dtype=np.float64)
        image[:upper] = self._with_clouds(self._clear(s, corona=False), s)
        # the sun: samples on a square grid of the plane tangent at the sun (gnomonic)
        r = self.sun.angular_radius
        spacing = min(r / 64.0, np.pi / height / 4.0)
        sky = image.copy() if parts else None
        self._deposit(image, lambda w: self._sun_samples(w, lambda centre, rho: spacing), r, spacing)
        if self._deep:  # the corona, more coarsely: it is smooth beyond the limb; not S's light,
            # so in the sky's part
            spacing = min(r / 16.0, np.pi / height / 4.0)
            for target in (image, sky) if parts else (image,):
                self._deposit(target, lambda w: self.corona_radiance(w) * self.sun_cloud_transmittance,
                              eclipse.CORONA_REACH * r, spacing)
        if parts:
            return image.astype(np.float32), {"sun": (image - sky).astype(np.float32), "sky": sky.astype(np.float32)}
        return image.astype(np.float32)

    def _deposit(self, image, radiance, reach: float, spacing: float) -> None:
        """Add to the equirectangular ``image`` (height, width, 3) [kcd/m^2] the light
        ``radiance(w)`` (..., 3) [kcd/m^2] within ``reach`` [rad] of the sun, sampled every
        ``spacing`` [rad] on the plane tangent at the sun, each sample's L cos(theta) d_omega
        put into its texel over the texel's projected solid angle."""
        height, width = image.shape[:2]
        upper = height // 2
        n = int(np.ceil((reach + 2 * spacing) / spacing))
        g = (np.arange(-n, n + 1)) * spacing
        gx, gy = np.meshgrid(g, g)
        _, e1, e2 = tangent_axes(self.sun.azimuth, self.sun.elevation)
        p = self.sun_direction + gx[..., None] * e1 + gy[..., None] * e2
        norm = np.linalg.norm(p, axis=-1)
        w = p / norm[..., None]
        d_omega = spacing**2 / norm**3
        energy = radiance(w) * (d_omega * np.maximum(w[..., 2], 0.0))[..., None]
        row = np.minimum((np.arccos(np.clip(w[..., 2], -1, 1)) / np.pi * height).astype(np.int64), height - 1)
        col = np.floor((np.arctan2(w[..., 0], w[..., 1]) / (2 * np.pi) + 0.5) * width).astype(np.int64) % width
        keep = (row < upper) & (energy.sum(axis=-1) > 0)
        row, col, energy = row[keep], col[keep], energy[keep]
        theta0, theta1 = row * np.pi / height, (row + 1) * np.pi / height
        texel = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
        np.add.at(image, (row, col), energy / texel[:, None])


@lru_cache(maxsize=8)
def _outside_nodes(extent, n_azimuth=1024, n_zenith=32) -> tuple:
    """(sky-plane points s (n_azimuth, 2, n_zenith, 2) [tan], weights (n_azimuth, 2, n_zenith)
    [sr]) of the irradiance outside the rectangle ``extent`` (x_min, y_min, x_max, y_max) [tan]
    (None: the whole hemisphere): for each azimuth (midpoint rule) the ray from the zenith leaves
    the rectangle at exact zenith angles; the outside parts of the ray are integrated with
    Gauss-Legendre in theta of L cos(theta) sin(theta). Read-only, cached."""
    phi = (np.arange(n_azimuth) + 0.5) * (2.0 * np.pi / n_azimuth)
    d = np.stack([np.sin(phi), np.cos(phi)], axis=-1)
    t_in = np.zeros(n_azimuth)
    t_out = np.zeros(n_azimuth)
    if extent is not None:
        lo = np.array(extent[:2])
        hi = np.array(extent[2:])
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = lo / d, hi / d
        near, far = np.minimum(a, b), np.maximum(a, b)
        parallel = d == 0.0
        inside = (lo <= 0.0) & (hi >= 0.0)
        near = np.where(parallel, np.where(inside, -np.inf, np.inf), near)
        far = np.where(parallel, np.where(inside, np.inf, -np.inf), far)
        t_in = np.maximum(near.max(axis=1), 0.0)
        t_out = far.min(axis=1)
        hit = t_out > t_in
        t_in, t_out = np.where(hit, t_in, 0.0), np.where(hit, t_out, 0.0)
    a = np.stack([np.zeros(n_azimuth), np.arctan(t_out)], axis=1)
    b = np.stack([np.arctan(t_in), np.full(n_azimuth, np.pi / 2)], axis=1)
    theta, w = _gauss_legendre(a, b, n_zenith)  # (n_azimuth, 2, n_zenith)
    tan = np.tan(theta)
    s = np.stack([tan * d[:, None, None, 0], tan * d[:, None, None, 1]], axis=-1)
    weight = w * np.cos(theta) * np.sin(theta) * (2.0 * np.pi / n_azimuth)
    s.setflags(write=False)
    weight.setflags(write=False)
    return s, weight


@lru_cache(maxsize=8)
def _raster_nodes(grid: Grid, k: int) -> tuple:
    """(sky-plane points (nodes, nodes, 2) [tan],) of the clear sky's nodes in ``raster``: every
    k-th cell centre of ``grid`` and the last (``_lerp_nodes``). Read-only, cached."""
    rows, cols = grid.shape
    x, y = grid.ground_from_raster(_lerp_nodes(rows, k)[0][:, None], _lerp_nodes(cols, k)[0][None, :])
    s = np.stack(np.broadcast_arrays(x, y), axis=-1)
    s.setflags(write=False)
    return (s,)


@lru_cache(maxsize=16)
def _relative_nodes(clear: ProceduralSky, nodes, *where) -> np.ndarray:
    """``clear._relative_sky`` (..., 3) at the points ``nodes(*where)[0]`` (``_outside_nodes``,
    ``_raster_nodes``), read-only, cached: the clear sky's shape is the same in every frame while
    the sun stands still. [1]"""
    relative = clear._relative_sky(nodes(*where)[0])
    relative.setflags(write=False)
    return relative


@lru_cache(maxsize=8)
def _solid_angles32(grid: Grid) -> np.ndarray:
    """``projected_solid_angle(grid)`` as float32, made once per grid (read-only). [sr]"""
    weights = projected_solid_angle(grid).astype(np.float32)
    weights.flags.writeable = False
    return weights


def _lerp_nodes(n: int, k: int):
    """Nodes every k of n indices (the last one included) and, for each index, the node interval it
    falls in (``at``, ``at + 1`` valid) and its fraction along it (float32)."""
    nodes = np.arange(0, n, k)
    if nodes[-1] != n - 1:
        nodes = np.append(nodes, n - 1)
    if len(nodes) == 1:
        nodes = np.array([0, 0])
    index = np.arange(n)
    at = np.minimum(np.searchsorted(nodes, index, side="right") - 1, len(nodes) - 2)
    span = np.maximum(nodes[at + 1] - nodes[at], 1)
    return nodes, at, ((index - nodes[at]) / span).astype(np.float32)


def sun_kernel(sky: ProceduralSky | EquirectSky, q: float) -> SkyRaster:
    """The sun disc for the two-scale method (docs/method.md, "Two scales for the sun") on a fine sky-plane grid of cell q.

    Limb-darkened, cut by the moon, dimmed by the clouds' transmittance towards the sun's centre,
    rasterized directly on the sky plane (a low sun is an ellipse stretched radially by about
    1 / cos^2(theta)). Each cell holds the integral of L_sun(s) cos^4(theta) dA over it: n x n
    sub-samples per cell (n >= 8, more when the disc spans few cells), the sun and moon limbs
    anti-aliased by a linear ramp one sub-sample wide measured along the gradient of the angular
    distance (|grad_s rho| = cos(theta) |u_xy|, u the unit tangent away from the disc centre),
    which keeps the disc's energy with no renormalisation (measured in docs/accuracy.md; the
    worst case comes from the limb-darkening law's square root at the limb).

    sky : ProceduralSky, or EquirectSky with a sun (``cut_sun``; no moon, no cloud dimming) --
        the whole sun disc must be above the horizon.
    q : sky-plane cell. [tan]
    Returns a SkyRaster (outside = 0) on ``geometry.sky_grid(start, shape, q)``: the block covers
    the disc with a margin of one cell; ``geometry.sky_offset(kernel.grid)`` is its offset ``start``.
    Units: the sky's irradiance ([klx] for ProceduralSky); its sum is ``sky.sun_irradiance()``.
    """
    sun = sky.sun
    if sun is None:
        raise ValueError("the sky has no sun to draw a kernel of (cut_sun finds an HDRI's)")
    r = sun.angular_radius
    if not q > 0:
        raise ValueError(f"q must be positive [tan], got {q}")
    if sun.elevation - r <= 1e-3:
        raise ValueError("the sun disc must lie wholly above the horizon for its sky-plane kernel")
    grid, h_sub, samples = _kernel_samples(sky, q)
    dimming = sky.sun_cloud_transmittance if isinstance(sky, ProceduralSky) else None
    out = np.zeros((3, grid.shape[0] * grid.shape[1]))
    for idx, disc, cos4 in samples:
        L = disc if dimming is None else disc * dimming  # as ProceduralSky._sun_samples dims it
        out[:, idx] = np.einsum("kijc,kij->ck", L, cos4) * h_sub**2
    weighted = out.reshape(3, *grid.shape).astype(np.float32)
    return SkyRaster(grid, weighted, np.zeros(3))


KERNEL_FLOOR = float(np.radians(2.0))
"""Below this sun elevation ``ProceduralSky.sun_irradiance`` does without the kernel: stretched
1 / cos^2(theta) > 800 times on the sky plane, it would pass MAX_KERNEL_CELLS; the renderer
takes such a sun's light as unshadowed (``framing.SHADOW_FLOOR``). [rad]"""

KERNEL_CACHE_SAMPLES = 1 << 20
"""Most sub-samples of a sun kernel whose undimmed samples (``_kernel_samples``) are kept for the
next frame: 32 MB of them, to a kernel of 64 x 64 cells at 8 x 8 sub-samples. [count]"""


def _kernel_samples(sky, q: float) -> tuple:
    """(grid, sub-sample side h_sub [tan], ((cells, undimmed sun radiance (k, n, n, 3), cos^4(theta)
    (k, n, n)), ...)) of ``sun_kernel``: its sub-samples by chunks of cells, before the clouds
    dim the sun. Kept
    (``_kept_kernel_samples``) for a procedural sky, whose sun changes far more slowly than its
    clouds, where there are at most KERNEL_CACHE_SAMPLES of them. [kcd/m^2 for a procedural sky]"""
    if isinstance(sky, ProceduralSky):
        key = replace(sky, clouds=None, time=0.0)
        try:
            hash(key)
        except TypeError:
            pass
        else:
            grid, cells, n = _kernel_layout(sky, q)
            if len(cells) * n * n <= KERNEL_CACHE_SAMPLES:
                return _kept_kernel_samples(key, q)
    return _kept_kernel_samples.__wrapped__(sky, q)


def _kernel_layout(sky, q: float) -> tuple:
    """(grid, flat indices of the cells that can hold any of the disc, sub-samples n per cell
    side) of ``sun_kernel``."""
    sun = sky.sun
    r = sun.angular_radius
    # the disc's bounding box on the sky plane, from points on its limb
    _, e1, e2 = tangent_axes(sun.azimuth, sun.elevation)
    psi = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
    limb = np.cos(r) * sky.sun_direction + np.sin(r) * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    limb = limb[:, :2] / limb[:, 2:]
    (x_min, y_min), (x_max, y_max) = limb.min(axis=0), limb.max(axis=0)
    c0, c1 = int(np.floor(x_min / q + 0.5)) - 1, int(np.floor(x_max / q + 0.5)) + 1
    r0, r1 = int(np.floor(-y_max / q + 0.5)) - 1, int(np.floor(-y_min / q + 0.5)) + 1
    shape = (r1 - r0 + 1, c1 - c0 + 1)
    if shape[0] * shape[1] > MAX_KERNEL_CELLS:
        raise ValueError(f"the sun kernel would be {shape[0]} x {shape[1]} cells: raise q or the sun")
    grid = sky_grid((r0, c0), shape, q)
    minor = min(x_max - x_min, y_max - y_min) / q
    n = int(min(128, max(8, np.ceil(128.0 / minor))))
    # cells that can hold any of the disc: centre within r + half a cell diagonal (in angle)
    rr, cc = np.indices(shape)
    cx, cy = grid.ground_from_raster(rr, cc)
    centres = np.stack([cx, cy, np.ones_like(cx)], axis=-1)
    centres /= np.linalg.norm(centres, axis=-1, keepdims=True)
    reach = r + q * 0.75 * centres[..., 2]  # a cell spans at most q cos(theta) x sqrt(2)/2 in angle
    near = _angle(centres, sky.sun_direction) <= reach
    cells = np.flatnonzero(near.ravel())
    return grid, cells, n


@lru_cache(maxsize=4)
def _kept_kernel_samples(sky, q: float) -> tuple:
    """``_kernel_samples`` computed (cached for the keys ``_kernel_samples`` gives it)."""
    grid, cells, n = _kernel_layout(sky, q)
    h_sub = q / n
    cx, cy = grid.ground_from_raster(*np.indices(grid.shape))
    offsets = (np.arange(n) + 0.5) / n - 0.5
    ox, oy = np.meshgrid(offsets * q, -offsets * q)

    def footprint(centre, rho):
        # sky-plane sub-sample spacing h_sub expressed in angle along the gradient of rho
        away = w * np.cos(rho)[..., None] - centre
        norm = np.maximum(np.linalg.norm(away, axis=-1), 1e-300)
        return h_sub * cos_t * np.maximum(np.hypot(away[..., 0], away[..., 1]) / norm, 1e-9)

    chunks = []
    chunk = max(1, (1 << 20) // (n * n))
    for lo in range(0, len(cells), chunk):
        idx = cells[lo : lo + chunk]
        sx = cx.ravel()[idx, None, None] + ox
        sy = cy.ravel()[idx, None, None] + oy
        cos_t = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
        w = np.stack([sx * cos_t, sy * cos_t, cos_t], axis=-1)
        disc = _disc_samples(w, footprint, sky.sun, sky.sun_direction, sky.sun_normal_irradiance,
                             getattr(sky, "moon", None))
        cos4 = cos_t**4
        for a in (idx, disc, cos4):
            a.setflags(write=False)
        chunks.append((idx, disc, cos4))
    return grid, h_sub, tuple(chunks)


def cut_sun(sky: EquirectSky, *, contrast: float = 50.0, margin: int = 1, ring: int = 3,
            max_radius: float = float(np.radians(3.0)), min_elevation: float = float(np.radians(2.0)),
            angular_radius: float = SUN_ANGULAR_RADIUS, limb_darkening: tuple = LIMB_DARKENING) -> EquirectSky:
    """The HDRI's sun cut out into the fine kernel of the two-scale method (docs/method.md, "Two scales for the sun").

    Detection, on the Rec.709 luminance Y of the texels above the horizon: the peak texel must
    stand out, Y_max >= ``contrast`` x the median Y; the core is the texels brighter than
    max(sqrt(Y_max median), 1e-3 Y_max) (the log-midpoint) connected to the peak (8-neighbours,
    the image turned so that the peak lies mid-width); the region is the core grown by ``margin``
    texels (the partly covered, blurred edge); the background is the per-channel median of the
    ``ring`` texels around the region. The sun carries the region's radiance above the
    background away, and the region's texels are set to the background: total_irradiance() +
    sun_irradiance() of the result is the input's total_irradiance() (to rounding), and the sun
    kernel's sum is sun_irradiance() (measured in docs/accuracy.md). Direction: the unit-vector mean of the
    texel centres weighted by the excess luminance times solid angle, ``rotation`` included. The
    disc takes ``angular_radius`` and ``limb_darkening``, not the image's (a photographed sun is
    blurred); its normal irradiance is the excess horizontal irradiance over cos(zenith).

    The sky comes back as it is when it already has a sun, when no texel stands out (overcast,
    a bare gradient), when the core reaches farther than max(``max_radius``, two texel heights)
    from the peak (not compact), when the excess is not positive in every channel, or when the
    sun is lower than ``min_elevation`` (its sky-plane kernel would be huge: it stays in the
    coarse raster).

    contrast : peak over median luminance needed. [1]   margin, ring : widths. [texels]
    max_radius, min_elevation, angular_radius : [rad]   limb_darkening : (3,) u. [1]
    Returns an EquirectSky (a new image; the input is not changed).
    """
    if sky.sun is not None:
        return sky
    height, width, _ = sky.image.shape
    theta0, theta1 = _row_bounds(height)
    rows = len(theta0)
    luminance = sky.image[:rows].astype(np.float64) @ np.asarray(REC709_LUMINANCE, dtype=np.float64)
    peak_row, peak_col = np.unravel_index(np.argmax(luminance), luminance.shape)
    peak, level = luminance[peak_row, peak_col], np.median(luminance)
    if not peak > 0 or peak < contrast * level:
        return sky
    shift = width // 2 - peak_col  # the peak mid-image, the seam opposite: no region crosses it
    bright = np.roll(luminance, shift, axis=1) > max(np.sqrt(peak * level), 1e-3 * peak)
    square = np.ones((3, 3), dtype=bool)
    labels, _ = ndimage.label(bright, structure=square)
    core = labels == labels[peak_row, width // 2]
    region = ndimage.binary_dilation(core, square, iterations=margin) if margin > 0 else core
    around = ndimage.binary_dilation(region, square, iterations=ring) & ~region
    r_core, c_core = np.nonzero(core)
    r_idx, c_idx = np.nonzero(region)
    r_ring, c_ring = np.nonzero(around)
    c_core, c_idx, c_ring = ((c - shift) % width for c in (c_core, c_idx, c_ring))

    def unit(r, c):
        theta = (r + 0.5) * (np.pi / height)
        phi = ((c + 0.5) / width - 0.5) * 2.0 * np.pi + sky.rotation
        return np.stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)], axis=-1)

    if _angle(unit(r_core, c_core), unit(peak_row, peak_col)).max() > max(max_radius, 2.0 * np.pi / height):
        return sky
    background = np.median(sky.image[r_ring, c_ring], axis=0).astype(sky.image.dtype)
    excess = sky.image[r_idx, c_idx].astype(np.float64) - background  # what the image loses, exactly
    horizontal = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
    solid = (np.cos(theta0) - np.cos(theta1)) * (2.0 * np.pi / width)
    energy = np.einsum("k,kn->n", horizontal[r_idx], excess)
    if not np.all(energy > 0):
        return sky
    weight = np.maximum(excess @ np.asarray(REC709_LUMINANCE, dtype=np.float64), 0.0) * solid[r_idx]
    direction = weight @ unit(r_idx, c_idx)
    direction /= np.linalg.norm(direction)
    elevation = float(np.arcsin(np.clip(direction[2], -1.0, 1.0)))
    if elevation < max(min_elevation, 2.0 * angular_radius):
        return sky
    image = sky.image.copy()
    image[r_idx, c_idx] = background
    sun = SunDisc(float(np.arctan2(direction[0], direction[1]) % (2.0 * np.pi)), elevation,
                  angular_radius, tuple(limb_darkening))
    return EquirectSky(image, sky.rotation, sun, energy / direction[2])
