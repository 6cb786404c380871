"""Procedural ground albedo: a seamlessly tileable texture of grass and soil.

Periodic noise is white noise from ``numpy.random.default_rng(seed)`` low-pass filtered in the
Fourier domain (a Gaussian of the spatial frequency), so every field tiles exactly with the
texture's period. Albedo is the fraction of light reflected (Lambertian), per linear Rec.709
channel. [1]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.fft as sfft
from numpy.typing import ArrayLike

from pipeline.core.geometry import Grid

if TYPE_CHECKING:
    from pipeline.texture.mipmap import Footprints, MipMap

__all__ = [
    "GRASS_DARK", "GRASS_LIGHT", "SOIL", "periodic_noise", "grass_albedo", "TILING_CELLS_PER_PERIOD",
    "BLEND_SHARPNESS", "SKIP_WEIGHT", "LOOKUP_BINS", "StochasticTiling", "vertex_keys", "SECOND_KEY", "unit_hash",
    "stochastic_tiling",
]

GRASS_DARK = (0.08, 0.16, 0.05)
GRASS_LIGHT = (0.15, 0.25, 0.08)
SOIL = (0.20, 0.15, 0.10)
"""Albedos of shaded and sunny blades of grass and of bare dry soil (linear Rec.709). [1]"""


def periodic_noise(rng: np.random.Generator, size_px: int, *, period: float, wavelength: float) -> np.ndarray:
    """Zero-mean, unit-variance noise that tiles with ``period`` (Gaussian low-pass of white noise).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the white noise.
    size_px : int
        Texels a side [pixel].
    period : float
        Side of the square it tiles with [m].
    wavelength : float
        Features about this wide [m].

    Returns
    -------
    numpy.ndarray
        (size_px, size_px) float64 [1].
    """
    white = rng.standard_normal((size_px, size_px))
    fy = sfft.fftfreq(size_px, d=period / size_px)[:, None]  # [cycles / m]
    fx = sfft.rfftfreq(size_px, d=period / size_px)[None, :]
    gain = np.exp(-0.5 * (fx * fx + fy * fy) * wavelength**2 * (2.0 * np.pi) ** 2 / 4.0)
    field = sfft.irfft2(sfft.rfft2(white) * gain, s=white.shape)
    field -= field.mean()
    return field / max(field.std(), 1e-12)


def grass_albedo(*, size_px: int = 1024, period: float = 4.0, seed: int = 0) -> tuple[np.ndarray, Grid]:
    """A tileable grass-and-soil albedo texture.

    Patches of soil (about a fifth of the area, some tens of centimetres across) in grass whose shade
    varies in tufts and blades; the mean albedo is about 0.15.

    Parameters
    ----------
    size_px : int, optional
        Texels a side, at least 8 [pixel].
    period : float, optional
        Side of the square texture; it tiles the plane with this period [m].
    seed : int, optional
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    image : numpy.ndarray
        (size_px, size_px, 3) float32 albedo in (0, 1) [1].
    grid : Grid
        The texture's grid, its north-west corner at (0, period) [m].

    Raises
    ------
    ValueError
        If ``size_px`` is under 8 or ``period`` not positive.
    """
    if size_px < 8:
        raise ValueError(f"size_px must be at least 8, got {size_px}")
    if not period > 0:
        raise ValueError(f"period must be positive [m], got {period}")
    rng = np.random.default_rng(seed)
    patches = periodic_noise(rng, size_px, period=period, wavelength=0.6)
    tufts = periodic_noise(rng, size_px, period=period, wavelength=0.08)
    blades = periodic_noise(rng, size_px, period=period, wavelength=min(0.012, 4 * period / size_px))
    soil = np.clip((patches + 0.3 * tufts - 0.8) / 0.4, 0.0, 1.0)
    soil = soil * soil * (3.0 - 2.0 * soil)  # smoothstep: soft edges
    shade = np.clip(0.5 + 0.2 * tufts + 0.25 * blades, 0.0, 1.0)[..., None]
    grass = np.asarray(GRASS_DARK) + shade * (np.asarray(GRASS_LIGHT) - np.asarray(GRASS_DARK))
    dirt = np.asarray(SOIL) * (1.0 + 0.15 * np.clip(tufts + 0.5 * blades, -2.0, 2.0))[..., None]
    image = grass + soil[..., None] * (dirt - grass)
    image = np.clip(image, 0.01, 0.99).astype(np.float32)
    return image, Grid((0.0, float(period)), float(period) / size_px, (size_px, size_px))


# ---------------------------------------------------------------------------------------------
# Stochastic tiling: the albedo tile laid without visible repetition
#
# Heitz & Neyret, "High-Performance By-Example Noise using a Histogram-Preserving Blending
# Operator", Proc. ACM Comput. Graph. Interact. Tech. 1(2), 2018 (HPG): the plane is cut into
# equilateral triangles; each lattice vertex reads the tile at its own random offset, and a
# point blends the reads of its triangle's three vertices (barycentric weights w_i) by the
# variance-preserving operator G = sum_i w_i G_i / sqrt(sum_i w_i^2) (section 3). Done on the
# albedo itself that operator shifts colours (soil blended into grass turns pink), so, as in the
# paper (section 4), the tile's colours are first decorrelated (PCA) and each component mapped
# to a standard Gaussian through its histogram (G = Phi^-1(rank)); the blend is done on those
# and mapped back through the inverse transformation, which gives every point the tile's own
# histogram. Filtering (the paper's section 4.3, prefiltering the inverse lookup): the tile's
# Gaussian form is mip-mapped and read with each pixel's footprint as the plain tile is; the
# inverse lookup of mip level k is the regression of the tile's level k on the Gaussian form's
# level k, E[albedo_k | G_k], so a far pixel, whose reads are all means, gets the tile's mean.
# The tile's period no longer shows: two points a period apart lie in different triangles whose
# vertices read unrelated parts of the tile.
# ---------------------------------------------------------------------------------------------

TILING_CELLS_PER_PERIOD = 2.0 * np.sqrt(3.0)
"""Triangle sides per tile period, as in Heitz & Neyret's code (uv x 2 sqrt(3)): each vertex's
read shows about a third of the tile. [1]"""

BLEND_SHARPNESS = 4.0
"""Exponent on the barycentric weights, renormalised (Mikkelsen, "Practical Real-Time
Hex-Tiling", JCGT 11(2), 2022): most of a triangle takes one vertex's read, and only narrow
bands blend three, where the blend would mix soil into grass. The compiled reads
(``kernels.tiling.tiling_reads``) take it as two squarings: 4 only. [1]"""

SKIP_WEIGHT = 1e-2
"""Sharpened weights under which a vertex's read is left out (``StochasticTiling.sample``):
about 1.95 reads a pixel instead of 3. [1]"""

LOOKUP_BINS = 256
"""Bins of the inverse lookups over the Gaussian range [-4, 4]. [1]"""


@dataclass(frozen=True, eq=False)
class StochasticTiling:
    """A periodic albedo MipMap laid on the ground by Heitz & Neyret's stochastic tiling.

    Built by ``stochastic_tiling``.

    Attributes
    ----------
    texture : mipmap.MipMap
        The tile, with outside "periodic" [1].
    gaussian : mipmap.MipMap
        The tile's Gaussian form (same levels) [1].
    center : numpy.ndarray
        (channels,) the tile's mean [1].
    basis : numpy.ndarray
        (channels, channels): its principal axes (columns) [1].
    lookups : numpy.ndarray
        (levels, channels, LOOKUP_BINS): per level and component, the component's mean value at the
        bins' centres of the Gaussian form [1].
    cell : float
        Side of the lattice's triangles [m].
    seed : int
        Seed of the vertices' offsets (a hash of the vertex and the seed: the same on every worker
        and in every frame).
    """

    texture: MipMap
    gaussian: MipMap
    center: np.ndarray
    basis: np.ndarray
    lookups: np.ndarray
    cell: float
    seed: int = 0

    @property
    def mean(self) -> np.ndarray:
        """The tile's mean, which the tiling keeps.

        Returns
        -------
        numpy.ndarray
            (channels,) [1].
        """
        return self.texture.mean

    @property
    def channels(self) -> int:
        """The tile's number of channels.

        Returns
        -------
        int
            [count].
        """
        return self.texture.channels

    def level(self, k: int) -> np.ndarray:
        """Level ``k`` of the tile (``MipMap.level``).

        Parameters
        ----------
        k : int
            The mip level.

        Returns
        -------
        numpy.ndarray
            (rows, cols, channels) albedo [1].
        """
        return self.texture.level(k)

    def weights(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The triangles' vertices and barycentric weights at ground points.

        Parameters
        ----------
        x, y : numpy.ndarray
            (n,) ground points [m].

        Returns
        -------
        vertices : numpy.ndarray
            (3, n, 2) int64 vertex ids on the skewed lattice.
        weights : numpy.ndarray
            (3, n) float64, summing to 1 [1].
        """
        # skew the plane so that the triangles become half squares (the paper's TriangleGrid)
        a = np.asarray(x, dtype=np.float64) / self.cell
        b = np.asarray(y, dtype=np.float64) / self.cell
        sa, sb = a - b / np.sqrt(3.0), 2.0 * b / np.sqrt(3.0)
        ia, ib = np.floor(sa), np.floor(sb)
        fa, fb = sa - ia, sb - ib
        ia, ib = ia.astype(np.int64), ib.astype(np.int64)
        lower = fa + fb < 1.0
        one = np.ones_like(ia)
        corners_low = np.stack([np.stack([ia, ib], -1), np.stack([ia, ib + one], -1), np.stack([ia + one, ib], -1)])
        corners_high = np.stack([np.stack([ia + one, ib + one], -1), np.stack([ia + one, ib], -1),
                                 np.stack([ia, ib + one], -1)])
        vertices = np.where(lower[None, :, None], corners_low, corners_high)
        weights = np.where(lower[None], np.stack([1.0 - fa - fb, fb, fa]),
                           np.stack([fa + fb - 1.0, 1.0 - fb, 1.0 - fa]))
        return vertices, weights

    def offsets(self, vertices: ArrayLike) -> np.ndarray:
        """Each lattice vertex's offset into the tile, uniform in [0, period).

        Parameters
        ----------
        vertices : numpy.ndarray
            (..., 2) int64 vertex ids (``weights``).

        Returns
        -------
        numpy.ndarray
            (..., 2) float64 offsets [m].
        """
        v = np.asarray(vertices, dtype=np.int64)
        key = vertex_keys(v[..., 0], v[..., 1], self.seed)
        px, py = _period(self.texture)
        return np.stack([unit_hash(key) * px, unit_hash(key ^ SECOND_KEY) * py], -1)

    def sample(self, fp: Footprints, *, lod_bias: float) -> np.ndarray:
        """The tiled albedo averaged over ground footprints.

        Compiled (``kernels.tiling``, ``kernels.filter``): the lattice weights and offsets of every footprint, its reads
        of weight SKIP_WEIGHT or more (the others left out: their Gaussian term taken as its
        mean, 0; about 1.95 reads a pixel instead of 3), filtered with the footprint's tap
        count and levels, chosen once for its reads, then the blend and the inverse lookups.
        tests/reference.py's ``tiling_sample_arrays(tiling, fp, lod_bias=, skip=SKIP_WEIGHT)`` is
        the reference (numpy).

        Parameters
        ----------
        fp : mipmap.Footprints
            n ground footprints [m].
        lod_bias : float
            Bias of the mip level [1].

        Returns
        -------
        numpy.ndarray
            (channels, n) float32 albedo [1].
        """
        from pipeline.kernels import filter as _filter
        from pipeline.kernels import tiling
        from pipeline.texture import mipmap as texture

        n = len(fp)
        out = np.empty((self.channels, n), dtype=np.float32)
        if n == 0:
            return out
        x, y, major, ex, ey = texture.as_float64(fp.x, fp.y, fp.major, fp.ex, fp.ey)
        weight = np.empty((3, n))
        read_x, read_y, read_weight = (np.empty(3 * n) for _ in range(3))
        read_pixel = np.empty(3 * n, dtype=np.intp)
        px, py = _period(self.gaussian)
        m = tiling.tiling_reads(x, y, float(self.cell), int(self.seed), float(SKIP_WEIGHT), float(px), float(py),
                                 weight, read_x, read_y, read_pixel, read_weight)
        taps, level, blend = texture.filter_choice(self.gaussian, lod_bias, major, fp.minor)
        values = np.empty((self.channels, m), dtype=np.float32)
        _filter.filtered(*texture.level_tables(self.gaussian), True, read_x[:m], read_y[:m], read_pixel[:m],
                         major, ex, ey, taps, level, blend, values)
        tiling.tiling_lookup(values, read_pixel[:m], read_weight[:m], weight, level, blend,
                              np.ascontiguousarray(self.lookups, dtype=np.float64),
                              np.ascontiguousarray(self.center, dtype=np.float64),
                              np.ascontiguousarray(self.basis, dtype=np.float64), out)
        return out


def vertex_keys(va: ArrayLike, vb: ArrayLike, seed: int) -> np.ndarray:
    """uint64 hash keys of lattice vertices under ``seed``.

    A vertex's offsets are ``unit_hash(key)`` and ``unit_hash(key ^ SECOND_KEY)`` times the period
    (the stochastic tiling's, and the cloud tile's copies, ``kernels.tiling.cloud_field``).

    Parameters
    ----------
    va, vb : numpy.ndarray
        int64 vertex ids, broadcastable.
    seed : int
        The seed.

    Returns
    -------
    numpy.ndarray
        uint64 keys of the broadcast shape.
    """
    a = np.asarray(va, dtype=np.int64).astype(np.uint64)
    b = np.asarray(vb, dtype=np.int64).astype(np.uint64)
    key = a * np.uint64(0x9E3779B97F4A7C15) ^ b * np.uint64(0xC2B2AE3D27D4EB4F)
    key ^= np.uint64(seed) * np.uint64(0x165667B19E3779F9)
    return key


SECOND_KEY = np.uint64(0xD6E8FEB86659FD93)
"""Xored into a vertex's key for its second offset (``vertex_keys``)."""


def unit_hash(key: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser (Steele, Lea & Flood 2014) of uint64 keys, as floats in [0, 1).

    Parameters
    ----------
    key : numpy.ndarray
        uint64 keys.

    Returns
    -------
    numpy.ndarray
        float64 of the shape of ``key`` [1].
    """
    z = key + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) / float(2**53)


def stochastic_tiling(texture: MipMap, *, seed: int = 0) -> StochasticTiling:
    """The Heitz & Neyret tiling of a periodic albedo MipMap.

    Its triangles are period / TILING_CELLS_PER_PERIOD a side (the longer period).

    Parameters
    ----------
    texture : mipmap.MipMap
        From ``texture.mipmap``, outside "periodic" [1].
    seed : int, optional
        Seed of the vertices' offsets.

    Returns
    -------
    StochasticTiling
        The tiling.

    Raises
    ------
    ValueError
        If the texture is not periodic.
    """
    from scipy.special import ndtri

    from pipeline.texture.mipmap import mipmap

    if texture.outside != "periodic":
        raise ValueError("stochastic tiling needs a periodic texture")
    tile = np.asarray(texture.level(0), dtype=np.float64)
    rows, cols, channels = tile.shape
    flat = tile.reshape(-1, channels)
    center = flat.mean(axis=0)
    if len(flat) < 2:  # one texel: no spread to decorrelate (its covariance is undefined)
        basis = np.eye(channels)
    else:
        _, basis = np.linalg.eigh(np.cov(flat - center, rowvar=False).reshape(channels, channels))
    components = _times(flat - center, basis)
    gaussian = np.empty((len(flat), channels), dtype=np.float32)
    quantiles = ndtri((np.arange(len(flat)) + 0.5) / len(flat)).astype(np.float32)
    for c in range(channels):  # Phi^-1 of the rank: a standard Gaussian histogram (ties kept apart)
        gaussian[np.argsort(components[:, c].astype(np.float32)), c] = quantiles
    px, py = _period(texture)
    grid = Grid((0.0, py), px / cols, (rows, cols))
    gauss_map = mipmap(gaussian.reshape(rows, cols, channels), grid,
                       outside="periodic", period=(px, py))
    centres = -4.0 + 8.0 * (np.arange(LOOKUP_BINS) + 0.5) / LOOKUP_BINS
    lookups = np.empty((gauss_map.count, channels, LOOKUP_BINS))
    for k in range(gauss_map.count):
        g_k = gauss_map.level(k).reshape(-1, channels).astype(np.float64)
        y_k = _times(texture.level(k).reshape(-1, channels).astype(np.float64) - center, basis)
        for c in range(channels):
            lookups[k, c] = _regression(g_k[:, c], y_k[:, c], centres)
    return StochasticTiling(texture, gauss_map, center, basis, lookups,
                            max(px, py) / TILING_CELLS_PER_PERIOD, seed)


def _times(rows: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """rows (n, c) @ matrix (c, c), summed column by column (a small matrix product that BLAS,
    for an inner size of 3, does many times slower)."""
    out = np.zeros((rows.shape[0], matrix.shape[1]))
    for i in range(matrix.shape[0]):
        out += rows[:, i : i + 1] * matrix[i]
    return out


def _regression(g: np.ndarray, y: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """E[y | g] at ``centres``: y's mean in each bin of g, joined linearly across empty bins and
    held beyond the outermost full ones. [units of y]"""
    width = centres[1] - centres[0]
    index = np.clip(np.floor((g - centres[0] + 0.5 * width) / width).astype(np.intp), 0, len(centres) - 1)
    count = np.bincount(index, minlength=len(centres))
    total = np.bincount(index, weights=y, minlength=len(centres))
    full = count > 0
    return np.interp(centres, centres[full], total[full] / count[full])


def _period(texture: MipMap) -> tuple[float, float]:
    """The tiling period (Px, Py) [m] of a periodic MipMap; ValueError for another."""
    if texture.period is None:
        raise ValueError("stochastic tiling needs a periodic texture")
    return texture.period
