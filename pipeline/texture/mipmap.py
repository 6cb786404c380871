"""Texture filtering of planar rasters: the mip map and the anisotropic footprint filter.

A raster on the ground plane (irradiance, albedo, a sky's relative light) is read through a
``mipmap`` (box-filtered levels, and the rule for the plane beyond the raster: a constant value
or the raster's periodic tiling); image pixels' ground ``footprints`` are reduced to ellipses and
averaged over by ``sample_footprint(s)``, as GPU anisotropic filtering does. The compiled loops
are in ``_filter.py``; each ``_..._arrays`` function here is the numpy reference a test holds them
to, bit for bit.

Why one module: the mip map's stored layout (every level flat, one texel of border all round)
and the filter that reads it (tap and level choice, trilinear taps, the outside rule) are one
convention, and each compiled loop sits beside its numpy reference.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from pipeline.core.cores import in_shares
from pipeline.core.kept import kept_at

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
    shapes: tuple
    offsets: tuple
    origins: tuple
    pixels: tuple
    outside: str
    value: np.ndarray | None = None
    period: tuple | None = None

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


def mipmap(raster, grid, *, outside: str = "constant", value=None, period=None) -> MipMap:
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


def _stored_levels(shapes, channels: int) -> tuple[np.ndarray, tuple]:
    """An empty ``MipMap.texels`` for levels of ``shapes`` (rows, cols) stored with their
    borders, one after another, and the offset of each level's first stored texel."""
    sizes = [(rows + 2) * (cols + 2) for rows, cols in shapes]
    offsets = tuple(int(v) for v in np.concatenate([[0], np.cumsum(sizes)[:-1]]))
    return np.empty((sum(sizes), channels), dtype=np.float32), offsets


def _constant_mipmap(a: np.ndarray, grid, value: np.ndarray) -> MipMap:
    """``mipmap`` with ``outside="constant"``: the levels of ``_constant_levels``, each made in
    place in the stored texels from the one before (``_filter.halve_level``, the same float32
    operations in the same order: the border holds the padding's value)."""
    from pipeline.kernels import filter as _filter

    shapes = [tuple(a.shape[:2])]
    while max(shapes[-1]) > 1:
        shapes.append(tuple((n + 1) // 2 for n in shapes[-1]))
    channels = a.shape[2]
    texels, offsets = _stored_levels(shapes, channels)
    for k, ((rows, cols), start) in enumerate(zip(shapes, offsets)):
        stored = texels[start : start + (rows + 2) * (cols + 2)].reshape(rows + 2, cols + 2, channels)
        stored[0], stored[-1], stored[1:-1, 0], stored[1:-1, -1] = value, value, value, value
        if k == 0:
            stored[1:-1, 1:-1] = a
        else:
            _filter.halve_level(texels, offsets[k - 1], *shapes[k - 1], start)
    origins = (tuple(float(v) for v in grid.origin),) * len(shapes)
    pixels = tuple((grid.pixel * 2.0**k,) * 2 for k in range(len(shapes)))
    return MipMap(texels, tuple(shapes), offsets, origins, pixels, "constant", value, None)


def _constant_levels(a: np.ndarray, value: np.ndarray) -> list:
    """Levels of a raster on a plane of ``value``: pad to even sizes with the value, average 2 x 2
    (the reference of ``_constant_mipmap``, which tests/test_camera.py holds to the same bits)."""
    levels = [a]
    while max(a.shape[:2]) > 1:
        rows, cols = a.shape[:2]
        if rows % 2 or cols % 2:
            padded = np.empty((rows + rows % 2, cols + cols % 2, a.shape[2]), dtype=np.float32)
            padded[...] = value
            padded[:rows, :cols] = a
            a = padded
        a = _pair_mean(_pair_mean(a, 0), 1)
        levels.append(a)
    return levels


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
                a = _pair_mean(a, axis) if n % 2 == 0 else _box_resample(a, axis, 0.0, float(n), (n + 1) // 2)
        levels.append(a)
    return levels


def _pair_mean(a: np.ndarray, axis: int) -> np.ndarray:
    """Mean of neighbouring pairs along ``axis`` (even length)."""
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


_CHUNK = 16384
"""Footprints filtered together: the working arrays of one tap stay in the processor's cache."""

_BLOCK = 32768
"""Footprints a block in the per-footprint steps (``_in_blocks``)."""


def _in_blocks(function, *arrays, size: int):
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


def footprints(x, y, jacobian) -> Footprints:
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
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    jac = np.asarray(jacobian, dtype=np.float64).reshape(-1, 2, 2)
    if not (len(x) == len(y) == len(jac)):
        raise ValueError(f"x, y and jacobian disagree in length: {len(x)}, {len(y)}, {len(jac)}")
    entries = np.ascontiguousarray(jac.reshape(-1, 4).T)  # dx/du, dx/dv, dy/du, dy/dv
    return Footprints(x, y, *_in_blocks(footprint_axes, *entries, size=_BLOCK))


def sample_footprint(mip: MipMap, x, y, jacobian, *, lod_bias: float = LOD_BIAS) -> np.ndarray:
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
    (``_filter.filtered``), footprint by footprint, with the arithmetic of ``filtered_arrays``."""
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


def as_float64(*arrays) -> tuple:
    """The arrays as contiguous float64 (no copy when they are)."""
    return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in arrays)


def level_tables(mip: MipMap) -> tuple:
    """What the compiled loops need of a MipMap: the flat texels, the channels, and per level
    the offset (int64), shape (rows, cols) int64, origin (x, y) and texel size (px, py) float64."""
    return (mip.texels.reshape(-1), mip.channels, np.asarray(mip.offsets, dtype=np.int64),
            np.asarray(mip.shapes, dtype=np.int64).reshape(-1, 2),
            np.asarray(mip.origins, dtype=np.float64).reshape(-1, 2),
            np.asarray(mip.pixels, dtype=np.float64).reshape(-1, 2))


def filtered_arrays(mip: MipMap, fp: Footprints, lod_bias: float) -> np.ndarray:
    """``filtered_read`` with whole arrays (numpy), the reference of the compiled loops.

    The footprints are grouped by level (and whether they blend two) and sorted by tap count
    within a group; each run of up to _CHUNK footprints of a group is filtered at once, tap by
    tap (``_tap_mean``). Footprints that read only the outside value ("constant") form a group
    of their own, which needs no samples.
    """
    n = len(fp)
    if n == 0:
        return np.zeros((mip.channels, 0), dtype=np.float32)
    taps, level, blend = _in_blocks(functools.partial(filter_choice_arrays, mip, lod_bias), fp.major, fp.minor,
                                    size=_BLOCK)
    group = 2 * level + (blend > 0)
    if mip.outside == "constant":
        beyond, = _in_blocks(lambda *arrays: (_beyond(mip, *arrays),), fp.x, fp.y, fp.major, fp.ex, fp.ey,
                             taps, level + (blend > 0), size=_BLOCK)
        group[beyond] = _BEYOND
    key = group * (MAX_TAPS + 1) + (MAX_TAPS - taps)  # int16: under 64 levels of 17 tap counts
    order = np.argsort(key, kind="stable")  # a radix sort
    group, taps = group.take(order), taps.take(order)
    starts = np.flatnonzero(np.diff(group, prepend=group[0] - 1))
    mean = np.empty((mip.channels, n), dtype=np.float32)
    for a, b in zip(starts, np.append(starts[1:], n)):
        if group[a] == _BEYOND:
            mean[:, a:b] = _outside_means(mip).take(taps[a:b], axis=1)
            continue
        k, blended = divmod(int(group[a]), 2)
        for c in range(a, b, _CHUNK):
            s = slice(c, min(c + _CHUNK, b))
            chosen = order[s]
            t = blend.take(chosen) if blended else None
            x, y, major, ex, ey = (u.take(chosen) for u in (fp.x, fp.y, fp.major, fp.ex, fp.ey))
            mean[:, s] = _tap_mean(mip, k, t, x, y, major, ex, ey, taps[s])
    inverse = np.empty_like(order)
    inverse[order] = np.arange(n)
    return mean.take(inverse, axis=1)


_BEYOND = -1
"""The group of the footprints that read only the outside value (``_beyond``)."""


def _beyond(mip: MipMap, x, y, major, ex, ey, taps, level) -> np.ndarray:
    """Whether each footprint (n,) bool (``Footprints``' fields x, y, major, ex, ey) of ``taps``
    taps has them all beyond one edge of the raster in its coarsest level read, ``level`` (n,)
    int, by half a texel more than the border: every trilinear sample of it reads the outside
    value alone (in the finer level too, whose texels are smaller and whose border is nearer).
    Mode "constant"."""
    (x0, y0), (rows, cols) = mip.origins[0], np.asarray(mip.shapes, dtype=np.float64).T
    px, py = np.asarray(mip.pixels, dtype=np.float64).T
    # the edges [m] a tap must lie beyond, level by level: a texel out from the raster
    west, east = (x0 - px).take(level), (x0 + (cols + 1) * px).take(level)
    north, south = (y0 + py).take(level), (y0 - (rows + 1) * py).take(level)
    reach = (0.5 - 0.5 / taps) * major  # from the centre to the farthest tap [m]
    across, along = np.abs(reach * ex), np.abs(reach * ey)
    with np.errstate(invalid="ignore"):
        return (x + across <= west) | (x - across >= east) | (y - along >= north) | (y + along <= south)


def _outside_means(mip: MipMap) -> np.ndarray:
    """(channels, MAX_TAPS + 1) float32: column n is what ``_tap_mean`` makes of n samples of
    the outside value: their float32 sum, in order, over n (column 0 unused)."""
    table = np.zeros((mip.channels, MAX_TAPS + 1), dtype=np.float32)
    total = np.zeros(mip.channels, dtype=np.float32)
    for n in range(1, MAX_TAPS + 1):
        total += mip.value
        table[:, n] = total / np.float32(n)
    return table


def filter_choice(mip: MipMap, lod_bias: float, major, minor):
    """Each footprint's tap count (n,) int8, level k (n,) int16 and blend t (n,) float32 in
    [0, 1) towards level k + 1 (0: level k alone), as ``sample_footprint`` says, from its
    ellipse's box widths ``major`` and ``minor`` (n,) [m]: compiled (``_filter.filter_choice``),
    the operations of ``filter_choice_arrays``. The choice depends on the footprints and the
    mip map's finest texel and level count alone, so the frames of a run, whose camera and
    rasters' grids stand still, make it once for the same footprint arrays
    (``_view_footprints``): the last few choices are kept with those arrays (not to be written
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


def _new_filter_choice(texel: float, count: int, lod_bias: float, major, minor):
    from pipeline.kernels import filter as _filter

    major, minor = as_float64(major, minor)
    n = len(major)
    taps, level, blend = np.empty(n, dtype=np.int8), np.empty(n, dtype=np.int16), np.empty(n, dtype=np.float32)
    _filter.filter_choice(texel, float(lod_bias), count, MAX_TAPS, major, minor, taps, level, blend)
    return taps, level, blend


def filter_choice_arrays(mip: MipMap, lod_bias: float, major, minor):
    """``filter_choice`` with whole arrays (numpy), the reference of the compiled loop."""
    texel = float(np.sqrt(mip.pixels[0][0] * mip.pixels[0][1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.nan_to_num(major / np.maximum(minor, texel), nan=1.0, posinf=MAX_TAPS, copy=False)
        ratio -= 1e-3
        np.ceil(ratio, out=ratio)
        taps = np.clip(ratio, 1, MAX_TAPS, out=ratio).astype(np.int8)
        lod = major / taps
        np.maximum(minor, lod, out=lod)
        lod /= texel
        np.log2(lod, out=lod)
        lod += lod_bias
    lod = np.clip(np.nan_to_num(lod, nan=0.0, copy=False), 0.0, mip.count - 1, out=lod)
    floor = np.floor(lod)
    k = floor.astype(np.int16)
    t = np.subtract(lod, floor, out=lod)
    done = t > 1.0 - 1e-6  # all in the next level
    k[done] += 1
    t[done | (t < 1e-6)] = 0.0
    return taps, k, t.astype(np.float32)


def _tap_mean(mip: MipMap, level: int, t, x, y, major, ex, ey, taps) -> np.ndarray:
    """Means (channels, m) float32 over each footprint's taps of its trilinear samples.

    level : the finer level read; t : (m,) float32 blend towards level + 1, or None for level
        alone. [level, 1]
    x, y, major, ex, ey : (m,) the footprints' ellipses (``Footprints``). [m, m, 1]
    taps : (m,) tap counts, in decreasing order.
    The taps of footprint j lie at (x, y) + ((i + 0.5) / taps - 0.5) major (ex, ey), i < taps[j].
    """
    spacing = major / taps  # [m]
    first = (0.5 - 0.5 * taps) * spacing  # the first tap's offset along the major axis [m]
    start = (x + first * ex, y + first * ey, spacing * ex, spacing * ey)  # the first tap, the step [m]
    finer = _texel_coords(mip, level, *start)
    coarser = None if t is None else _texel_coords(mip, level + 1, *start)
    descending = -taps
    for i in range(int(taps[0])):
        m = int(np.searchsorted(descending, -i, side="left"))  # footprints with more than i taps
        col, row, dcol, drow = (u[:m] for u in finer)
        sample = _bilinear(mip, level, col, row)
        col += dcol
        row += drow
        if coarser is not None:
            col, row, dcol, drow = (u[:m] for u in coarser)
            upper = _bilinear(mip, level + 1, col, row)
            col += dcol
            row += drow
            upper -= sample
            upper *= t[:m]
            sample += upper
        if i == 0:
            total = sample
        else:
            total[:, :m] += sample
    total /= taps.astype(np.float32)
    return total


def _texel_coords(mip: MipMap, level: int, x, y, dx, dy):
    """(col, row) [texel] in level ``level`` of ground points (x, y) [m], texel centres at whole
    numbers, and (dcol, drow) [texel] of ground steps (dx, dy) [m]; new arrays."""
    (x0, y0), (px, py) = mip.origins[level], mip.pixels[level]
    col = (x - x0) * (1.0 / px) - 0.5
    row = (y0 - y) * (1.0 / py) - 0.5
    dcol, drow = dx * (1.0 / px), dy * (-1.0 / py)
    # held where a float has no fraction left, so that no tap's texel overflows an integer
    for u, limit in ((col, 2.0**52), (row, 2.0**52), (dcol, 2.0**48), (drow, 2.0**48)):
        np.clip(u, -limit, limit, out=u)
    return col, row, dcol, drow


def footprint_axes(dxdu, dxdv, dydu, dydv):
    """Box widths (major, minor) [m] and the major axis's unit vector (ex, ey) [1], each (n,)
    float64, of the ellipse with the second moments of the parallelogram spanned by the columns
    (dxdu, dydu) and (dxdv, dydv) [m per pixel] (each (n,)) of the footprint's Jacobian: J J^T =
    [[a, b], [b, c]], its larger eigenvalue and eigenvector (``_filter.footprint_axes``)."""
    from pipeline.kernels import filter as _filter

    return _filter.footprint_axes(*(np.ascontiguousarray(v, dtype=np.float64) for v in (dxdu, dxdv, dydu, dydv)))


def _bilinear(mip: MipMap, level: int, col, row) -> np.ndarray:
    """Bilinear samples (channels, m) float32 of one level at texel coordinates (col, row) (m,)
    [texel] (``_texel_coords``), the plane beyond the raster as ``mip.outside`` says. The four
    texels of a sample lie at fixed offsets from the first (``_first_texel``) and are gathered
    in one ``take``."""
    first, fc, fr = _first_texel(mip, level, col, row)
    flat = mip.texels.reshape(-1)
    gathered = np.empty((4, mip.channels, len(first)), dtype=np.float32)
    offsets = _corner_offsets(mip.shapes[level][1] + 2, mip.channels)
    for offset, out in zip(offsets, gathered.reshape(-1, len(first))):
        flat[offset:].take(first, out=out, mode="clip")  # no index array of all the corners
    a, b, c, d = gathered  # each (channels, m)
    b -= a  # the upper row, along the columns
    b *= fc
    a += b
    d -= c  # the lower row
    d *= fc
    c += d
    c -= a  # along the rows
    c *= fr
    a += c
    return a


def _first_texel(mip: MipMap, level: int, col, row):
    """The first of the four texels of bilinear samples at texel coordinates (col, row) (m,)
    [texel], the one at (floor(row), floor(col)): the index (m,) intp of its channel 0 in the
    flat texel array, and the fractions (fc, fr) (m,) float32 of (col, row) beyond it [texel].

    The texel is brought into the stored level, border included: held at the border of the
    outside value ("constant"), or moved by whole periods ("periodic")."""
    rows, cols = mip.shapes[level]
    if mip.outside == "constant":
        col, row = np.clip(col, -1.0, cols), np.clip(row, -1.0, rows)
    c0, r0 = np.floor(col), np.floor(row)
    fc = np.empty(len(col), dtype=np.float32)
    fr = np.empty(len(row), dtype=np.float32)
    np.subtract(col, c0, out=fc)
    np.subtract(row, r0, out=fr)
    c0, r0 = c0.astype(np.intp), r0.astype(np.intp)
    if mip.outside == "periodic":
        _wrap(c0, cols)
        _wrap(r0, rows)
    r0 *= cols + 2  # stored rows, one texel of border all round
    r0 += c0
    r0 += mip.offsets[level] + cols + 3
    r0 *= mip.channels
    return r0, fc, fr


@functools.lru_cache(maxsize=256)
def _corner_offsets(stride: int, channels: int) -> tuple:
    """Offsets in the flat texel array of the four texels of a bilinear sample, (r0, c0),
    (r0, c0 + 1), (r0 + 1, c0), (r0 + 1, c0 + 1), channel by channel, from channel 0 of the
    first: 4 channels ints; ``stride`` the stored texels a row."""
    return tuple(texel * channels + k for texel in (0, 1, stride, stride + 1) for k in range(channels))


def _wrap(i: np.ndarray, n: int) -> None:
    """i modulo n, in place (n > 0); a mask when n is a power of two."""
    if n & (n - 1):
        np.remainder(i, n, out=i)
    else:
        np.bitwise_and(i, n - 1, out=i)
