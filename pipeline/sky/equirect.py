"""The sky of an equirectangular image (HDRI), resampled onto sky-plane rasters keeping every
texel's energy, and its sun cut out into a disc for the fine kernel.

Equirectangular skies (docs/method.md, "Conventions"): the top row touches the zenith, the centre column
looks north, east is at three quarters of the width, texel centres at
``((col + 0.5) / width, (row + 0.5) / height)``. ``rotation`` turns the sky about the zenith
towards the east: a feature at image azimuth ``phi`` is seen at azimuth ``phi + rotation``.
``cut_sun`` moves an HDRI's sun out of the image into a disc for the fine kernel (``sun_kernel``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.constants import SUN_ANGULAR_RADIUS
from pipeline.core.geometry import Grid, direction_vector, sky_grid, sky_offset
from pipeline.core.kept import kept_at
from pipeline.sky.raster import SkyRaster, bilinear_shares, flush, grid_footprint, kept_raster
from pipeline.sky.sun_disc import LIMB_DARKENING, SunDisc, angle_to

__all__ = ["EquirectSky", "cut_sun", "equirect_lookup"]


@dataclass(frozen=True)
class EquirectSky:
    """A sky from an equirectangular image (HDRI), texels taken as piecewise constant; a ``base.Sky``.

    Parameters
    ----------
    image : numpy.ndarray
        (height, width, 3) float32 linear RGB radiance, finite, not negative [radiance].
    rotation : float
        Turn about the zenith towards the east [rad].
    sun : sun_disc.SunDisc or None
        The sun cut out of the image (``cut_sun``), drawn by ``sun_kernel.sun_kernel`` on the fine
        grid of the two-scale method; the image then holds the sky without it.
    sun_normal_irradiance : numpy.ndarray or None
        (3,) the cut sun's normal irradiance, given with ``sun`` [radiance x sr].

    Raises
    ------
    ValueError
        When ``sun`` and ``sun_normal_irradiance`` do not come together, or the latter is not (3,).
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
        if self.sun is None:
            raise AttributeError("EquirectSky.sun_direction: the sky has no cut sun (cut_sun)")
        return direction_vector(self.sun.azimuth, self.sun.elevation)

    def sun_irradiance(self) -> np.ndarray:
        """The cut sun's horizontal irradiance on the open ground.

        Returns
        -------
        numpy.ndarray
            (3,) E_n cos(zenith), the sun kernel's sum; zeros without a sun [radiance x sr].
            ``image_irradiance() + sun_irradiance()`` is the uncut image's.
        """
        if self.sun is None:
            return np.zeros(3)
        return np.asarray(self.sun_normal_irradiance, dtype=np.float64) * self.sun_direction[2]

    def sun_fraction(self) -> float:
        """S, the sun's power reaching the ground over the clear, uneclipsed sun's.

        Returns
        -------
        float
            1 with a sun: a photographed sun is what it is (clouds and moon are already in the
            image); 0 without one [1].
        """
        return 0.0 if self.sun is None else 1.0

    def undimmed_sun_irradiance(self) -> np.ndarray:
        """The sun's horizontal irradiance before the moon and clouds dim it: as photographed.

        Returns
        -------
        numpy.ndarray
            (3,) ``sun_irradiance()``: a photographed sun is already dimmed [radiance x sr].
        """
        return self.sun_irradiance()

    @cached_property
    def sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,) of the image, without the cut sun: ``image_irradiance()``. [radiance x sr]"""
        return self.image_irradiance()

    def view_radiance(self, w: np.ndarray, s: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """The image's radiance without the cut sun along view directions.

        Parameters
        ----------
        w : numpy.ndarray
            (..., 3) unit vectors [1]; ``rotation`` is applied, rows held to the upper half
            (``equirect_lookup``).
        s, footprint :
            Unused (the ``base.Sky`` interface).

        Returns
        -------
        numpy.ndarray
            (..., 3) float32 bilinear samples of the image [radiance]; at a still camera's read-only
            w, kept for the next frames (``kept.kept_at``: 53 ms of a frame of hdri.yaml).
        """
        if isinstance(w, np.ndarray) and not w.flags.writeable:
            return kept_at(self._views, None, w, lambda: equirect_lookup(self.image, w, rotation=self.rotation,
                                                                         sky_only=True))
        return equirect_lookup(self.image, w, rotation=self.rotation, sky_only=True)

    @cached_property
    def _views(self) -> dict:
        """``view_radiance``'s results at read-only directions (``kept.kept_at``)."""
        return {}

    def image_irradiance(self) -> np.ndarray:
        """The image's irradiance on the open ground: its upper hemisphere, texels piecewise constant.

        Returns
        -------
        numpy.ndarray
            (3,) float64 exact irradiance of the image as it is (without a cut sun) [radiance x sr].
        """
        height, width, _ = self.image.shape
        theta0, theta1 = _row_bounds(height)
        weight = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
        rows = len(weight)
        return np.einsum("r,rcn->n", weight, self.image[:rows].astype(np.float64))

    def raster(self, grid: Grid, *, fold_period: tuple[int, int] | None = None) -> SkyRaster:
        """The image on a sky-plane grid, area-averaged so that every texel keeps its energy (``_raster``).

        Kept on this sky for the next call with the same grid and fold (read-only: a still image
        gives every frame of a run the same raster; it cost seconds a frame).

        Parameters
        ----------
        grid : geometry.Grid
            The sky-plane grid [tan].
        fold_period : tuple of int or None
            (rows, cols): the raster folded modulo this period, on the grid of offsets 0..period-1.

        Returns
        -------
        sky.raster.SkyRaster
            The weighted sky, ``outside`` the image's light off the grid [radiance x sr].
        """
        key = (grid, None if fold_period is None else tuple(int(n) for n in fold_period))
        return kept_raster(self._rasters, key, lambda: self._raster(grid, fold_period=fold_period))

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
        near, reach, keep_phi = grid_footprint(grid)
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
                index, share, sub_row, sub_col = bilinear_shares(grid, sx, sy, wrap)
                texel = self.image[row, sub_cols[sub_col] // n_phi].astype(np.float64)
                pending.append((index, texel * (share * weight[lo + sub_row])[:, None]))
                if sum(len(i) for i, _ in pending) > 1 << 22:
                    flush(accum, pending)
        flush(accum, pending)
        weighted = accum.reshape(channels, rows, cols).astype(np.float32)
        outside = self.image_irradiance() - weighted.sum(axis=(1, 2), dtype=np.float64)
        if wrap is not None:
            grid = sky_grid((0, 0), wrap[1], grid.pixel)
        return SkyRaster(grid, weighted, outside)


def _row_bounds(height: int):
    """Zenith-angle bounds [rad] of the equirectangular rows that reach above the horizon."""
    edges = np.arange(height + 1) * (np.pi / height)
    upper = edges[:-1] < np.pi / 2
    return edges[:-1][upper], np.minimum(edges[1:][upper], np.pi / 2)


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
    background away, and the region's texels are set to the background: image_irradiance() +
    sun_irradiance() of the result is the input's image_irradiance() (to rounding), and the sun
    kernel's sum is sun_irradiance() (measured in docs/accuracy.md). Direction: the unit-vector mean of the
    texel centres weighted by the excess luminance times solid angle, ``rotation`` included. The
    disc takes ``angular_radius`` and ``limb_darkening``, not the image's (a photographed sun is
    blurred); its normal irradiance is the excess horizontal irradiance over cos(zenith).

    The sky comes back as it is when it already has a sun, when no texel stands out (overcast,
    a bare gradient), when the core reaches farther than max(``max_radius``, two texel heights)
    from the peak (not compact), when the excess is not positive in every channel, or when the
    sun is lower than ``min_elevation`` (its sky-plane kernel would be huge: it stays in the
    coarse raster).

    Parameters
    ----------
    sky : EquirectSky
        The HDRI sky.
    contrast : float
        Peak over median luminance needed [1].
    margin, ring : int
        Widths of the blurred edge and of the background ring [texels].
    max_radius, min_elevation : float
        Largest reach of the core from the peak, lowest sun cut [rad].
    angular_radius : float
        The disc's radius [rad].
    limb_darkening : tuple
        (3,) the disc's linear-law coefficients u [1].

    Returns
    -------
    EquirectSky
        With the sun cut out (a new image; the input is not changed), or ``sky`` as it is.
    """
    if sky.sun is not None:
        return sky
    height, width, _ = sky.image.shape
    theta0, theta1 = _row_bounds(height)
    luminance = sky.image[: len(theta0)].astype(np.float64) @ np.asarray(REC709_LUMINANCE, dtype=np.float64)
    peak_row, peak_col = np.unravel_index(np.argmax(luminance), luminance.shape)
    peak, level = luminance[peak_row, peak_col], np.median(luminance)
    if not peak > 0 or peak < contrast * level:
        return sky
    texels = _sun_texels(luminance, int(peak_row), int(peak_col), max(np.sqrt(peak * level), 1e-3 * peak), margin,
                         ring)
    core = _texel_directions(texels.core_rows, texels.core_cols, sky.image.shape, sky.rotation)
    peak_direction = _texel_directions(peak_row, peak_col, sky.image.shape, sky.rotation)
    if angle_to(core, peak_direction).max() > max(max_radius, 2.0 * np.pi / height):
        return sky
    background = np.median(sky.image[texels.ring_rows, texels.ring_cols], axis=0).astype(sky.image.dtype)
    excess = sky.image[texels.rows, texels.cols].astype(np.float64) - background  # what the image loses, exactly
    horizontal = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
    energy = np.einsum("k,kn->n", horizontal[texels.rows], excess)
    if not np.all(energy > 0):
        return sky
    solid = (np.cos(theta0) - np.cos(theta1)) * (2.0 * np.pi / width)
    direction = _excess_direction(sky, texels, excess, solid)
    elevation = float(np.arcsin(np.clip(direction[2], -1.0, 1.0)))
    if elevation < max(min_elevation, 2.0 * angular_radius):
        return sky
    image = sky.image.copy()
    image[texels.rows, texels.cols] = background
    sun = SunDisc(float(np.arctan2(direction[0], direction[1]) % (2.0 * np.pi)), elevation,
                  angular_radius, tuple(limb_darkening))
    return EquirectSky(image, sky.rotation, sun, energy / direction[2])


@dataclass(frozen=True)
class _SunTexels:
    """The texels of an HDRI's sun (``cut_sun``), as row and column indices into the image.

    Attributes
    ----------
    core_rows, core_cols : numpy.ndarray
        (n,) the core: the bright texels connected to the peak.
    rows, cols : numpy.ndarray
        (m,) the region: the core grown by the margin, the texels the sun is taken from.
    ring_rows, ring_cols : numpy.ndarray
        (k,) the ring around the region, whose median is the background.
    """

    core_rows: np.ndarray
    core_cols: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    ring_rows: np.ndarray
    ring_cols: np.ndarray


def _sun_texels(luminance: np.ndarray, peak_row: int, peak_col: int, threshold: float, margin: int,
                ring: int) -> _SunTexels:
    """``cut_sun``'s texels of the sun about the peak (peak_row, peak_col) of ``luminance`` (the
    rows above the horizon) [1]: the core, those brighter than ``threshold`` connected to the peak
    (8-neighbours, the image turned so that the peak lies mid-width), grown by ``margin`` into the
    region, and the ``ring`` texels around it [texels]."""
    width = luminance.shape[1]
    shift = width // 2 - peak_col  # the peak mid-image, the seam opposite: no region crosses it
    bright = np.roll(luminance, shift, axis=1) > threshold
    square = np.ones((3, 3), dtype=bool)
    labels, _ = ndimage.label(bright, structure=square)
    core = labels == labels[peak_row, width // 2]
    region = ndimage.binary_dilation(core, square, iterations=margin) if margin > 0 else core
    around = ndimage.binary_dilation(region, square, iterations=ring) & ~region
    r_core, c_core = np.nonzero(core)
    r_idx, c_idx = np.nonzero(region)
    r_ring, c_ring = np.nonzero(around)
    c_core, c_idx, c_ring = ((c - shift) % width for c in (c_core, c_idx, c_ring))
    return _SunTexels(r_core, c_core, r_idx, c_idx, r_ring, c_ring)


def _texel_directions(rows: ArrayLike, cols: ArrayLike, shape: tuple[int, ...], rotation: float) -> np.ndarray:
    """Unit vectors (..., 3) [1] towards the centres of texels (rows, cols) of an equirectangular
    image of ``shape`` (height, width, ...) turned by ``rotation`` [rad] (``cut_sun``)."""
    height, width = shape[0], shape[1]
    theta = (np.asarray(rows) + 0.5) * (np.pi / height)
    phi = ((np.asarray(cols) + 0.5) / width - 0.5) * 2.0 * np.pi + rotation
    return np.stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)], axis=-1)


def _excess_direction(sky: EquirectSky, texels: _SunTexels, excess: np.ndarray, solid: np.ndarray) -> np.ndarray:
    """The unit vector (3,) [1] towards the cut sun (``cut_sun``): the mean of the region's texel
    centres weighted by their excess luminance (``excess`` (m, 3) [radiance]) times their solid
    angle (``solid`` per row [sr]), ``rotation`` included."""
    weight = np.maximum(excess @ np.asarray(REC709_LUMINANCE, dtype=np.float64), 0.0) * solid[texels.rows]
    direction = weight @ _texel_directions(texels.rows, texels.cols, sky.image.shape, sky.rotation)
    direction /= np.linalg.norm(direction)
    return direction


def equirect_lookup(image: ArrayLike, w: ArrayLike, *, rotation: float = 0.0, sky_only: bool = False) -> np.ndarray:
    """Bilinear samples of an equirectangular image in given directions.

    The image's convention is that of docs/method.md, "Conventions": top row at the zenith, centre
    column north, east at three quarters of the width, texel centres at
    ((col + 0.5) / width, (row + 0.5) / height). Columns wrap round; rows are held at the poles.

    Parameters
    ----------
    image : array_like
        (height, width, 3) equirectangular image. [radiance]
    w : array_like
        (..., 3) unit vectors. [1]
    rotation : float, optional
        Turns the image about the zenith towards the east. [rad]
    sky_only : bool, optional
        Rows are held to the upper half too, so that a direction just above the horizon never
        blends in the image's ground below it (the ground plane stands for that: blended, it
        drew a dark band over the horizon).

    Returns
    -------
    numpy.ndarray
        (..., 3) float32 samples. [radiance]
    """
    image = np.asarray(image)
    height, width = image.shape[:2]
    w = np.asarray(w, dtype=np.float64)
    azimuth = np.arctan2(w[..., 0], w[..., 1]) - rotation
    zenith = np.arccos(np.clip(w[..., 2], -1.0, 1.0))
    col = (azimuth / (2.0 * np.pi) + 0.5) * width - 0.5
    row = np.clip(zenith / np.pi * height - 0.5, 0.0, (np.ceil(0.5 * height) - 1.0 if sky_only else height - 1.0))
    c0, r0 = np.floor(col), np.floor(row)
    fc = (col - c0).astype(np.float32)[..., None]
    fr = (row - r0).astype(np.float32)[..., None]
    c0 = c0.astype(np.int64) % width
    c1 = (c0 + 1) % width
    r0 = r0.astype(np.int64)
    r1 = np.minimum(r0 + 1, height - 1)
    upper = image[r0, c0] * (1.0 - fc) + image[r0, c1] * fc
    lower = image[r1, c0] * (1.0 - fc) + image[r1, c1] * fc
    return (upper * (1.0 - fr) + lower * fr).astype(np.float32)
