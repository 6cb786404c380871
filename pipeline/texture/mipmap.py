"""Texture filtering of planar rasters: the mip map and the anisotropic footprint filter.

A raster on the ground plane (irradiance, albedo, a sky's relative light) is read through a
``mipmap`` (box-filtered levels, and the rule for the plane beyond the raster: a constant value
or the raster's periodic tiling); image pixels' ground ``footprints`` are reduced to ellipses and
averaged over by ``sample_footprint(s)``, as GPU anisotropic filtering does. The compiled loops
are in ``kernels/filter.py``; their numpy references, which the tests hold them to bit for bit,
are in tests/reference.py (``filtered_arrays``, ``filter_choice_arrays``).

Why one module: the mip map's stored layout (every level flat, one texel of border all round)
and the filter that reads it (tap and level choice, trilinear taps, the outside rule) are one
convention.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.cores import in_shares
from pipeline.core.kept import kept_at

if TYPE_CHECKING:
    from pipeline.core.geometry import Grid

__all__ = ["LOD_BIAS", "MAX_TAPS", "Footprints", "MipMap", "footprints", "mipmap", "sample_footprint",
           "sample_footprints"]

# ---------------------------------------------------------------------------------------------
# Ground rasters are minified far from the camera (a 1 cm texel may be metres of a far pixel), so
# they are read through a mip map with anisotropic footprints, as GPU anisotropic filtering does:
# each pixel's footprint on the ground (the parallelogram spanned by the columns of the Jacobian
# d(x, y)/d(u, v) of its ray's hit point) is replaced by its ellipse of inertia; the mip level is
# chosen from the minor axis and up to MAX_TAPS trilinear taps are spread along the major axis.
# ---------------------------------------------------------------------------------------------

MAX_TAPS = 16
"""Most trilinear taps along a footprint's major axis; longer footprints use coarser levels."""

LOD_BIAS = -0.5
"""Added to the mip level chosen from the footprint: a level's box followed by bilinear
interpolation is about sqrt(3) wider (in its second moment) than the footprint's box, so half a
level finer brings the filter's width close to the footprint's while it still passes less than
the footprint's own box above the image's sampling frequency. [level]"""

_OUTSIDE_MODES = ("constant", "periodic")


@dataclass(frozen=True, eq=False)
class MipMap:
    """A pyramid of box-filtered levels of a planar raster, and what lies outside it.

    Built by ``mipmap``. Level k+1 is the 2 x 2 box average of level k (odd sizes padded with
    the outside value, or area-averaged when periodic), down to a single texel; all levels are
    stored flat, one after another, in ``texels``.

    Parameters
    ----------
    texels : numpy.ndarray
        (texels, channels) float32: every level, rows first, each stored with a border of one
        texel all round: ``value`` ("constant"), or the texels of the opposite edge
        ("periodic"), so that a bilinear sample's four texels are always stored at the same
        offsets from the first. [units of the raster]
    shapes : tuple of (int, int)
        Each level's (rows, cols), without the border. [texel]
    offsets : tuple of int
        Index in ``texels`` of each level's first stored texel.
    origins : tuple of (float, float)
        North-west corner (x, y) of each level's texel [0, 0]. [m]
    pixels : tuple of (float, float)
        Each level's texel width (along x) and height (along y). [m]
    outside : {"constant", "periodic"}
        The rule for the plane beyond the raster.
    value : numpy.ndarray or None
        (channels,) float32: the value beyond the raster ("constant"). [units of the raster]
    period : (float, float) or None
        The tiling period (Px, Py) ("periodic"). [m]
    """

    texels: np.ndarray
    shapes: tuple[tuple[int, int], ...]
    offsets: tuple[int, ...]
    origins: tuple[tuple[float, float], ...]
    pixels: tuple[tuple[float, float], ...]
    outside: str
    value: np.ndarray | None = None
    period: tuple[float, float] | None = None

    @property
    def channels(self) -> int:
        """Number of channels of the raster."""
        return self.texels.shape[1]

    @property
    def count(self) -> int:
        """Number of levels."""
        return len(self.shapes)

    @property
    def mean(self) -> np.ndarray:
        """The raster's mean (channels,) float64: its coarsest level's, for a periodic map.
        [units of the raster]"""
        return self.level(self.count - 1).reshape(-1, self.channels).mean(axis=0, dtype=np.float64)

    def level(self, k: int) -> np.ndarray:
        """One level of the pyramid, without its border.

        Parameters
        ----------
        k : int
            The level, 0 (the raster) to ``count - 1`` (one texel).

        Returns
        -------
        numpy.ndarray
            (rows, cols, channels) float32, a read-only view. [units of the raster]
        """
        rows, cols = self.shapes[k]
        stored = self.texels[self.offsets[k] : self.offsets[k] + (rows + 2) * (cols + 2)]
        view = stored.reshape(rows + 2, cols + 2, self.channels)[1 : rows + 1, 1 : cols + 1]
        view.flags.writeable = False
        return view


def mipmap(raster: ArrayLike, grid: Grid, *, outside: str = "constant", value: ArrayLike | None = None,
           period: tuple[float, float] | None = None) -> MipMap:
    """The mip map of a north-up raster on the ground plane, and the rule for the plane beyond it.

    Parameters
    ----------
    raster : array_like
        (rows, cols, channels): e.g. irradiance [radiance x sr] or albedo [1]; not changed.
    grid : geometry.Grid
        The raster's grid (``grid.shape == (rows, cols)``). [m]
    outside : {"constant", "periodic"}
        "constant": beyond the raster the plane holds ``value`` (an isolated grove: the ground
        beyond the shadow window gets the unshadowed irradiance); odd sizes are padded with
        ``value`` before each 2 x 2 average, which is then exact for that infinite plane.
        "periodic": the raster tiles the plane with period ``period``: a point is moved by
        whole periods into the fundamental cell [x_min, x_min + Px) x [y_min, y_min + Py) (the
        raster's south-west corner), and only that cell of the raster is used, so a raster larger
        than one period must itself be periodic. When a period is a whole number of pixels
        (within 1e-6 pixel) the cell is taken as it is; otherwise it is resampled, by exact
        area averages of the texels taken as piecewise constant, onto ceil(P / pixel) texels a
        little narrower than the raster's (a blur of under one pixel). Odd sizes of the periodic
        levels are averaged the same way, so every level has exactly the raster's mean.
    value : array_like or float, optional
        (channels,) or a scalar: the value beyond the raster ("constant" only). [units of the raster]
    period : (float, float), optional
        The tiling period (Px, Py), positive and at most the raster's extent ("periodic" only). [m]

    Returns
    -------
    MipMap
        The levels, down to one texel, and the outside rule.
    """
    a = np.asarray(raster, dtype=np.float32)
    if a.ndim != 3:
        raise ValueError(f"raster must be (rows, cols, channels), got shape {a.shape}")
    if tuple(a.shape[:2]) != tuple(grid.shape):
        raise ValueError(f"raster shape {a.shape[:2]} does not match grid shape {grid.shape}")
    if outside not in _OUTSIDE_MODES:
        raise ValueError(f"outside must be one of {_OUTSIDE_MODES}, got {outside!r}")
    channels = a.shape[2]
    if outside == "constant":
        if value is None or period is not None:
            raise ValueError('outside="constant" takes a value and no period')
        value = np.broadcast_to(np.asarray(value, dtype=np.float32), (channels,)).copy()
        return _constant_mipmap(a, grid, value)
    if period is None or value is not None:
        raise ValueError('outside="periodic" takes a period and no value')
    px, py = (float(v) for v in period)
    x_min, y_min, x_max, y_max = grid.extent
    if not (px > 0 and py > 0):
        raise ValueError(f"period must be positive, got {period}")
    if px > (x_max - x_min) * (1 + 1e-9) or py > (y_max - y_min) * (1 + 1e-9):
        raise ValueError(f"the raster ({x_max - x_min} x {y_max - y_min} m) must cover one period {period}")
    levels = _periodic_levels(a, px / grid.pixel, py / grid.pixel)
    shapes = tuple((lv.shape[0], lv.shape[1]) for lv in levels)
    texels, offsets = _stored_levels(shapes, channels)
    for lv, start in zip(levels, offsets):
        stored = texels[start : start + (lv.shape[0] + 2) * (lv.shape[1] + 2)]
        wrapped = np.pad(lv, ((1, 1), (1, 1), (0, 0)), mode="wrap")  # the border: the opposite edges
        stored.reshape(lv.shape[0] + 2, lv.shape[1] + 2, channels)[...] = wrapped
    origins = ((float(x_min), float(y_min + py)),) * len(levels)
    pixels = tuple((px / lv.shape[1], py / lv.shape[0]) for lv in levels)
    return MipMap(texels, shapes, offsets, origins, pixels, "periodic", None, (px, py))


def _stored_levels(shapes: tuple[tuple[int, int], ...], channels: int) -> tuple[np.ndarray, tuple[int, ...]]:
    """An empty ``MipMap.texels`` for levels of ``shapes`` (rows, cols) stored with their
    borders, one after another, and the offset of each level's first stored texel."""
    sizes = [(rows + 2) * (cols + 2) for rows, cols in shapes]
    offsets = tuple(int(v) for v in np.concatenate([[0], np.cumsum(sizes)[:-1]]))
    return np.empty((sum(sizes), channels), dtype=np.float32), offsets


def _constant_mipmap(a: np.ndarray, grid: Grid, value: np.ndarray) -> MipMap:
    """``mipmap`` with ``outside="constant"``: levels of the raster on a plane of ``value``, each
    made in place in the stored texels from the one before (``kernels.filter.halve_level``): the
    bits of the numpy reference (tests/reference.py, ``constant_levels``: pad to even sizes with
    the value, ``pair_mean`` along rows then columns), the border holding the padding's value."""
    from pipeline.kernels import filter as _filter

    shapes: list[tuple[int, int]] = [(a.shape[0], a.shape[1])]
    while max(shapes[-1]) > 1:
        shapes.append(((shapes[-1][0] + 1) // 2, (shapes[-1][1] + 1) // 2))
    channels = a.shape[2]
    texels, offsets = _stored_levels(tuple(shapes), channels)
    for k, ((rows, cols), start) in enumerate(zip(shapes, offsets)):
        stored = texels[start : start + (rows + 2) * (cols + 2)].reshape(rows + 2, cols + 2, channels)
        stored[0], stored[-1], stored[1:-1, 0], stored[1:-1, -1] = value, value, value, value
        if k == 0 and a.strides[2] > a.strides[1]:  # channels first in memory (a ground raster's moved
            for c in range(channels):  # axes): channel by channel, twice as fast as one transposing copy
                stored[1:-1, 1:-1, c] = a[..., c]
        elif k == 0:
            stored[1:-1, 1:-1] = a
        else:
            _filter.halve_level(texels, offsets[k - 1], *shapes[k - 1], start)
    origins = ((float(grid.origin[0]), float(grid.origin[1])),) * len(shapes)
    pixels = tuple((grid.pixel * 2.0**k,) * 2 for k in range(len(shapes)))
    return MipMap(texels, tuple(shapes), offsets, origins, pixels, "constant", value, None)


def _periodic_levels(a: np.ndarray, lx: float, ly: float) -> list:
    """Levels of one period of a raster: the fundamental cell (south-west corner) on whole
    texels, then halvings; odd sizes are area-averaged onto ceil(n / 2) texels per period.
    lx, ly : the period along x (columns) and y (rows). [pixel]"""
    rows = a.shape[0]
    if abs(lx - round(lx)) < 1e-6:
        a = a[:, : int(round(lx))]
    else:
        a = _box_resample(a, 1, 0.0, lx, int(np.ceil(lx)))
    if abs(ly - round(ly)) < 1e-6:
        a = a[rows - int(round(ly)) :]
    else:
        a = _box_resample(a, 0, rows - ly, ly, int(np.ceil(ly)))
    a = np.ascontiguousarray(a, dtype=np.float32)
    levels = [a]
    while max(a.shape[:2]) > 1:
        for axis in (0, 1):
            n = a.shape[axis]
            if n > 1:
                a = pair_mean(a, axis) if n % 2 == 0 else _box_resample(a, axis, 0.0, float(n), (n + 1) // 2)
        levels.append(a)
    return levels


def pair_mean(a: np.ndarray, axis: int) -> np.ndarray:
    """Mean of neighbouring pairs along an axis: one halving step of the mip map's levels.

    Parameters
    ----------
    a : numpy.ndarray
        A raster (rows, cols, channels), of even length along ``axis`` [any unit].
    axis : int
        The axis halved.

    Returns
    -------
    numpy.ndarray
        float32, half as long along ``axis``: each pair summed in float32, then halved [as ``a``].
    """
    even = a[(slice(None),) * axis + (slice(0, None, 2),)]
    odd = a[(slice(None),) * axis + (slice(1, None, 2),)]
    out = np.add(even, odd, dtype=np.float32)
    out *= np.float32(0.5)
    return out


def _box_resample(a: np.ndarray, axis: int, start: float, length: float, count: int) -> np.ndarray:
    """Exact averages of ``a``, taken as piecewise constant on unit cells along ``axis``, over
    ``count`` equal cells spanning [start, start + length) (in cells of ``a``, inside it)."""
    n = a.shape[axis]
    moved = np.moveaxis(a, axis, 0).astype(np.float64)
    integral = np.concatenate([np.zeros((1, *moved.shape[1:])), np.cumsum(moved, axis=0)])
    edges = np.clip(start + length * np.arange(count + 1) / count, 0.0, n)
    at = np.minimum(np.floor(edges).astype(np.intp), n - 1)
    frac = (edges - at).reshape((-1,) + (1,) * (moved.ndim - 1))
    cumulative = integral[at] + frac * moved[at]
    out = np.diff(cumulative, axis=0) / (length / count)
    return np.moveaxis(out, 0, axis).astype(np.float32)


_BLOCK = 32768
"""Footprints a block in the per-footprint steps (``_in_blocks``)."""


def _in_blocks(function: Callable[..., tuple[np.ndarray, ...]], *arrays: np.ndarray,
               size: int) -> tuple[np.ndarray, ...]:
    """``function(*arrays)`` for a function that works item by item along the arrays' first
    axis and returns a tuple of arrays: applied to blocks of ``size`` items and the results
    joined, so that its temporaries stay small (in the processor's cache, and no fresh pages)."""
    starts = range(0, max(len(arrays[0]), 1), size)  # one empty block for empty arrays
    parts = [function(*(a[i : i + size] for a in arrays)) for i in starts]
    return tuple(np.concatenate(results) for results in zip(*parts))


@dataclass(frozen=True, eq=False)
class Footprints:
    """Ground footprints of image pixels, each replaced by its ellipse of inertia (``footprints``).
    They depend on the view only: one set serves every raster read through it.

    Parameters
    ----------
    x, y : numpy.ndarray
        (n,) float64: the centres. [m]
    major, minor : numpy.ndarray
        (n,) float64: box widths along the ellipse's axes, major >= minor. [m]
    ex, ey : numpy.ndarray
        (n,) float64: unit vector along the major axis. [1]
    """

    x: np.ndarray
    y: np.ndarray
    major: np.ndarray
    minor: np.ndarray
    ex: np.ndarray
    ey: np.ndarray

    def __len__(self) -> int:
        """Number of footprints."""
        return len(self.x)


def footprints(x: ArrayLike, y: ArrayLike, jacobian: ArrayLike) -> Footprints:
    """The ellipses of the footprints of image pixels on the ground.

    Parameters
    ----------
    x, y : array_like
        (n,) ground points, the footprints' centres. [m]
    jacobian : array_like
        (n, 2, 2) d(x, y)/d(u, v): column 0 is the ground step of one image pixel along u,
        column 1 along v; the footprint is the parallelogram they span. [m per pixel]

    Returns
    -------
    Footprints
        Each footprint's ellipse of the same second moments (``sample_footprint``).
    """
    xs = np.asarray(x, dtype=np.float64).ravel()
    ys = np.asarray(y, dtype=np.float64).ravel()
    jac = np.asarray(jacobian, dtype=np.float64).reshape(-1, 2, 2)
    if not (len(xs) == len(ys) == len(jac)):
        raise ValueError(f"x, y and jacobian disagree in length: {len(xs)}, {len(ys)}, {len(jac)}")
    entries = np.ascontiguousarray(jac.reshape(-1, 4).T)  # dx/du, dx/dv, dy/du, dy/dv
    return Footprints(xs, ys, *_in_blocks(footprint_axes, *entries, size=_BLOCK))


def sample_footprint(mip: MipMap, x: ArrayLike, y: ArrayLike, jacobian: ArrayLike, *,
                     lod_bias: float = LOD_BIAS) -> np.ndarray:
    """Averages of a mip-mapped raster over the ground footprints of image pixels.

    Parameters
    ----------
    mip : MipMap
        The raster's mip map.
    x, y : array_like
        (n,) ground points, the footprints' centres. [m]
    jacobian : array_like
        (n, 2, 2) d(x, y)/d(u, v): column 0 is the ground step of one image pixel along u,
        column 1 along v; the footprint is the parallelogram they span. [m per pixel]
    lod_bias : float, optional
        Added to the mip level chosen from the footprint. [level]

    Returns
    -------
    numpy.ndarray
        (n, channels) float32: each footprint's average. [units of the raster]

    Notes
    -----
    Anisotropic filtering, as GPUs do it: the footprint is replaced by the ellipse of the same
    second moments (eigen-decomposition of J J^T; for a rectangle its axes are the sides), of
    box widths w_major >= w_minor. n_taps = min(ceil(w_major / max(w_minor, texel)), MAX_TAPS)
    taps equally spaced along the major axis each take a trilinear sample (bilinear in two
    levels, blended) at level log2(max(w_minor, w_major / n_taps) / texel) + ``lod_bias``, never
    finer than level 0: a magnified footprint is a single bilinear sample of the raster. With
    the default bias (LOD_BIAS) the filter's width is close to the footprint's; 0 is the GPU
    rule, blurrier. ``sample_footprints`` does the work; it reads several rasters through one
    set of ``footprints``.
    """
    return sample_footprints(mip, footprints(x, y, jacobian), lod_bias=lod_bias)


def sample_footprints(mip: MipMap, fp: Footprints, *, lod_bias: float = LOD_BIAS) -> np.ndarray:
    """``sample_footprint`` of footprints already reduced to ellipses.

    Parameters
    ----------
    mip : MipMap
        The raster's mip map.
    fp : Footprints
        The footprints' ellipses (``footprints``).
    lod_bias : float, optional
        As for ``sample_footprint``. [level]

    Returns
    -------
    numpy.ndarray
        (n, channels) float32: each footprint's average. [units of the raster]
    """
    return np.ascontiguousarray(filtered_read(mip, fp, lod_bias).T)


def filtered_read(mip: MipMap, fp: Footprints, lod_bias: float) -> np.ndarray:
    """``sample_footprints``, channels first: (channels, n) float32: compiled
    (``kernels.filter.filtered``), footprint by footprint, with the arithmetic of tests/reference.py's
    ``filtered_arrays``."""
    n = len(fp)
    if n == 0:
        return np.zeros((mip.channels, 0), dtype=np.float32)
    from pipeline.kernels import filter as _filter

    taps, level, blend = filter_choice(mip, lod_bias, fp.major, fp.minor)
    out = np.empty((mip.channels, n), dtype=np.float32)
    tables = level_tables(mip)
    x, y, major, ex, ey = as_float64(fp.x, fp.y, fp.major, fp.ex, fp.ey)
    periodic = mip.outside == "periodic"
    if mip.channels == 3:  # where the taps fall depends on the footprints and the levels' geometry alone
        geometry = (lod_bias, periodic, mip.texels.shape, mip.shapes, mip.offsets, mip.origins, mip.pixels)
        kept = kept_at(_TAPS, geometry, (fp.x, fp.y, fp.major, fp.ex, fp.ey), lambda: _filter.tap_table(
            *tables[1:], periodic, x, y, major, ex, ey, taps, level, blend), read_only=False, first=lambda: None)
        if kept is not None:
            in_shares(n, lambda a, b: _filter.filtered3_at(tables[0], tables[3], taps, level, blend, *kept, out, a, b))
            return out
    _filter.filtered(*tables, periodic, x, y, np.arange(n), major, ex, ey, taps, level, blend, out)
    return out


_TAPS: dict = {}  # filtered_read's tap tables: a still camera reads each frame's irradiance at the same places


def as_float64(*arrays: ArrayLike) -> tuple[np.ndarray, ...]:
    """The arrays as contiguous float64 (no copy when they are)."""
    return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in arrays)


def level_tables(mip: MipMap) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What the compiled loops need of a MipMap: the flat texels, the channels, and per level
    the offset (int64), shape (rows, cols) int64, origin (x, y) and texel size (px, py) float64."""
    return (mip.texels.reshape(-1), mip.channels, np.asarray(mip.offsets, dtype=np.int64),
            np.asarray(mip.shapes, dtype=np.int64).reshape(-1, 2),
            np.asarray(mip.origins, dtype=np.float64).reshape(-1, 2),
            np.asarray(mip.pixels, dtype=np.float64).reshape(-1, 2))


def filter_choice(mip: MipMap, lod_bias: float, major: np.ndarray,
                  minor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each footprint's tap count (n,) int8, level k (n,) int16 and blend t (n,) float32 in
    [0, 1) towards level k + 1 (0: level k alone), as ``sample_footprint`` says, from its
    ellipse's box widths ``major`` and ``minor`` (n,) [m]: compiled (``kernels.filter.filter_choice``),
    the operations of tests/reference.py's ``filter_choice_arrays``. The choice depends on the footprints and the
    mip map's finest texel and level count alone, so the frames of a run, whose camera and
    rasters' grids stand still, make it once for the same footprint arrays
    (``pinhole.view_footprints``): the last few choices are kept with those arrays (not to be written
    to; left writable, as numba compiles read-only arrays as another type)."""
    texel = float(np.sqrt(mip.pixels[0][0] * mip.pixels[0][1]))
    key = (id(major), id(minor), texel, float(lod_bias), mip.count)
    kept = _CHOICES.get(key)
    if kept is not None and kept[0] is major and kept[1] is minor:
        return kept[2]
    choice = _new_filter_choice(texel, mip.count, lod_bias, major, minor)
    _CHOICES[key] = (major, minor, choice)  # the arrays kept too: their ids are not reused
    while len(_CHOICES) > 4:
        del _CHOICES[next(iter(_CHOICES))]
    return choice


_CHOICES: dict = {}
"""``filter_choice``'s last choices: (id major, id minor, texel, lod bias, levels) -> (major,
minor, (taps, level, blend))."""


def _new_filter_choice(texel: float, count: int, lod_bias: float, major: np.ndarray,
                       minor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from pipeline.kernels import filter as _filter

    major, minor = as_float64(major, minor)
    n = len(major)
    taps, level, blend = np.empty(n, dtype=np.int8), np.empty(n, dtype=np.int16), np.empty(n, dtype=np.float32)
    _filter.filter_choice(texel, float(lod_bias), count, MAX_TAPS, major, minor, taps, level, blend)
    return taps, level, blend


def footprint_axes(dxdu: ArrayLike, dxdv: ArrayLike, dydu: ArrayLike,
                   dydv: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Box widths (major, minor) [m] and the major axis's unit vector (ex, ey) [1], each (n,)
    float64, of the ellipse with the second moments of the parallelogram spanned by the columns
    (dxdu, dydu) and (dxdv, dydv) [m per pixel] (each (n,)) of the footprint's Jacobian: J J^T =
    [[a, b], [b, c]], its larger eigenvalue and eigenvector (``kernels.filter.footprint_axes``)."""
    from pipeline.kernels import filter as _filter

    return _filter.footprint_axes(*(np.ascontiguousarray(v, dtype=np.float64) for v in (dxdu, dxdv, dydu, dydv)))
