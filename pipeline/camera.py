"""The pinhole camera: its rays, and where world points land in its image.

Image convention: pixel (row, col) covers ``[col, col + 1) x [row, row + 1)`` in continuous image
coordinates (u along columns to the right, v along rows downwards); its centre is
``(col + 0.5, row + 0.5)``. The camera looks along ``forward``; ``right`` is horizontal and
``up = right x forward``, so with no roll the horizon is level. A camera looking straight down
with yaw 0 has north at the top of its image, as the ground rasters do.

Below the rays, the perspective view of the ground and the sky (the background of the frame):
``mipmap``, ``footprints`` and ``sample_footprint(s)`` (anisotropic, area-averaged reading of
ground rasters), ``ground_hits`` and ``ground_view`` (the Lambertian ground, its anti-aliased
horizon and distances), ``sky_view`` and ``background``.

Why one module: the camera's rays, its ground footprints and the filtered reads of the
ground, albedo and sky share the footprint and mip-map conventions; the compiled loops are in
``_filter.py``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    position : (x, y, z) of the pinhole. [m]
    yaw : azimuth of the view direction, from north towards east. [rad]
    pitch : elevation of the view direction, in [-pi/2, pi/2], negative looking down. [rad]
    vertical_fov : full vertical field of view, in (0, pi). [rad]
    width, height : image size. [pixel]
    """

    position: tuple[float, float, float]
    yaw: float
    pitch: float
    vertical_fov: float
    width: int
    height: int

    def __post_init__(self):
        if not (0.0 < self.vertical_fov < np.pi):
            raise ValueError(f"vertical_fov must lie in (0, pi) rad, got {self.vertical_fov}")
        if not (-np.pi / 2 <= self.pitch <= np.pi / 2):
            raise ValueError(f"pitch must lie in [-pi/2, pi/2] rad, got {self.pitch}")
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width} x {self.height}")

    @classmethod
    def look_at(cls, position, target, *, vertical_fov: float, width: int, height: int) -> "Camera":
        """The camera at ``position`` [m] looking at ``target`` [m] (level, no roll)."""
        d = np.asarray(target, dtype=np.float64) - np.asarray(position, dtype=np.float64)
        if not np.any(d):
            raise ValueError("target and position coincide")
        yaw = float(np.arctan2(d[0], d[1]) % (2 * np.pi))
        pitch = float(np.arctan2(d[2], np.hypot(d[0], d[1])))
        return cls(tuple(float(v) for v in position), yaw, pitch, vertical_fov, width, height)

    @property
    def focal(self) -> float:
        """Focal length in pixels: pixels per unit of tan(angle) off the axis. [pixel]"""
        return 0.5 * self.height / np.tan(0.5 * self.vertical_fov)

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit (right, up, forward) vectors in world coordinates. A straight-down view takes
        its right from the yaw, so yaw 0 puts east on the right and north at the top."""
        cy, sy = np.cos(self.yaw), np.sin(self.yaw)
        cp, sp = np.cos(self.pitch), np.sin(self.pitch)
        forward = np.array([cp * sy, cp * cy, sp])
        right = np.array([cy, -sy, 0.0])
        return right, np.cross(right, forward), forward


def image_rays(camera: Camera, u, v) -> np.ndarray:
    """World directions (..., 3), not normalised, through image points (u, v) [pixel]: the
    point on the image plane at distance 1 along ``forward``. [m per m of depth]"""
    right, up, forward = camera.basis
    x = (np.asarray(u, dtype=np.float64) - 0.5 * camera.width) / camera.focal
    y = (0.5 * camera.height - np.asarray(v, dtype=np.float64)) / camera.focal
    return forward + x[..., None] * right + y[..., None] * up


def pixel_rays(camera: Camera) -> np.ndarray:
    """Directions (height, width, 3) through every pixel centre, as ``image_rays``."""
    right, up, forward = camera.basis
    x = (np.arange(camera.width, dtype=np.float64) + 0.5 - 0.5 * camera.width) / camera.focal
    y = (0.5 * camera.height - (np.arange(camera.height, dtype=np.float64) + 0.5)) / camera.focal
    out = np.empty((camera.height, camera.width, 3))
    for k in range(3):  # image_rays' (forward + x right) + y up, one component at a time
        np.add((forward[k] + x * right[k])[None, :], (y * up[k])[:, None], out=out[..., k])
    return out


def project_points(camera: Camera, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image coordinates (u, v) [pixel] and depth along ``forward`` [m] of world points
    (..., 3) [m]. Points at depth <= 0 are behind the pinhole; their (u, v) are meaningless."""
    right, up, forward = camera.basis
    d = np.asarray(points, dtype=np.float64) - np.asarray(camera.position)
    depth = d @ forward
    safe = np.where(np.abs(depth) > 1e-12, depth, 1e-12)
    u = 0.5 * camera.width + camera.focal * (d @ right) / safe
    v = 0.5 * camera.height - camera.focal * (d @ up) / safe
    return u, v, depth


# ---------------------------------------------------------------------------------------------
# The perspective view of the ground and the sky: the background B of the frame composite
# (docs/method.md, "The camera, the foreground and the finished frame": frame = F_sky + S (F_sun - F_sky) + (1 - A) B).
#
# Ground rasters are minified far from the camera (a 1 cm texel may be metres of a far pixel), so
# they are read through a mip map with anisotropic footprints, as GPU anisotropic filtering does:
# each pixel's footprint on the ground (the parallelogram spanned by the columns of the Jacobian
# d(x, y)/d(u, v) of its ray's hit point) is replaced by its ellipse of inertia; the mip level is
# chosen from the minor axis and up to MAX_TAPS trilinear taps are spread along the major axis.
# ---------------------------------------------------------------------------------------------

MAX_TAPS = 16
"""Most trilinear taps along a footprint's major axis; longer footprints use coarser levels."""

MIN_DOWNWARD = 1e-9
"""Least downward slope |wz| of a ray (unnormalised, |w| >= 1) that is taken to hit the ground:
caps the hit distance at height / MIN_DOWNWARD. [1]"""

MIN_UPWARD = 1e-3
"""Least upward slope wz / |w| used to look up a sky model on the sky plane, whose points run to
infinity at the horizon: |s| <= 1 / MIN_UPWARD. [1]"""

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

    texels : ndarray (texels, channels) float32 -- every level, rows first, each stored with a
        border of one texel all round: ``value`` ("constant"), or the texels of the opposite
        edge ("periodic"), so that a bilinear sample's four texels are always stored at the
        same offsets from the first.
    shapes : ((rows, cols), ...) -- each level's size, without the border.
    offsets : (int, ...) -- index in ``texels`` of each level's first stored texel.
    origins : ((x, y), ...) -- north-west corner of each level's texel [0, 0]. [m]
    pixels : ((px, py), ...) -- each level's texel width (along x) and height (along y). [m]
    outside : "constant" or "periodic".
    value : ndarray (channels,) float32 or None -- the value beyond the raster ("constant").
    period : (Px, Py) or None -- the tiling period ("periodic"). [m]
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
        return self.texels.shape[1]

    @property
    def count(self) -> int:
        """Number of levels."""
        return len(self.shapes)

    @property
    def mean(self) -> np.ndarray:
        """The mean (channels,) of the raster: its coarsest level's, for a periodic map. [units of the raster]"""
        return self.level(self.count - 1).reshape(-1, self.channels).mean(axis=0, dtype=np.float64)

    def level(self, k: int) -> np.ndarray:
        """Level ``k`` (rows, cols, channels) float32 without its border (a read-only view)."""
        rows, cols = self.shapes[k]
        stored = self.texels[self.offsets[k] : self.offsets[k] + (rows + 2) * (cols + 2)]
        view = stored.reshape(rows + 2, cols + 2, self.channels)[1 : rows + 1, 1 : cols + 1]
        view.flags.writeable = False
        return view


def mipmap(raster, grid, *, outside: str = "constant", value=None, period=None) -> MipMap:
    """The mip map of a north-up raster on the ground plane, and the rule for the plane beyond it.

    raster : (rows, cols, channels) -- e.g. irradiance [radiance x sr] or albedo [1]; not changed.
    grid : Grid of the raster (``grid.shape == (rows, cols)``). [m]
    outside : "constant" -- beyond the raster the plane holds ``value`` (an isolated grove: the
        ground beyond the shadow window gets the unshadowed irradiance); odd sizes are padded
        with ``value`` before each 2 x 2 average, which is then exact for that infinite plane.
        "periodic" -- the raster tiles the plane with period ``period``: a point is moved by
        whole periods into the fundamental cell [x_min, x_min + Px) x [y_min, y_min + Py) (the
        raster's south-west corner), and only that cell of the raster is used, so a raster larger
        than one period must itself be periodic. When a period is a whole number of pixels
        (within 1e-6 pixel) the cell is taken as it is; otherwise it is resampled, by exact
        area averages of the texels taken as piecewise constant, onto ceil(P / pixel) texels a
        little narrower than the raster's (a blur of under one pixel). Odd sizes of the periodic
        levels are averaged the same way, so every level has exactly the raster's mean.
    value : (channels,) or scalar -- the value beyond the raster ("constant" only).
    period : (Px, Py) -- the tiling period, positive and at most the raster's extent
        ("periodic" only). [m]
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
        stored.reshape(lv.shape[0] + 2, lv.shape[1] + 2, channels)[...] = np.pad(lv, ((1, 1), (1, 1), (0, 0)), mode="wrap")
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
    from . import _filter

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
    integral = np.concatenate([np.zeros((1,) + moved.shape[1:]), np.cumsum(moved, axis=0)])
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

    x, y : (n,) float64 -- the centres. [m]
    major, minor : (n,) float64 -- box widths along the ellipse's axes, major >= minor. [m]
    ex, ey : (n,) float64 -- unit vector along the major axis. [1]
    """

    x: np.ndarray
    y: np.ndarray
    major: np.ndarray
    minor: np.ndarray
    ex: np.ndarray
    ey: np.ndarray

    def __len__(self) -> int:
        return len(self.x)


def footprints(x, y, jacobian) -> Footprints:
    """The ellipses of the footprints of image pixels on the ground.

    x, y : (n,) ground points, the footprints' centres. [m]
    jacobian : (n, 2, 2) d(x, y)/d(u, v): column 0 is the ground step of one image pixel along
        u, column 1 along v; the footprint is the parallelogram they span. [m per pixel]
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    jac = np.asarray(jacobian, dtype=np.float64).reshape(-1, 2, 2)
    if not (len(x) == len(y) == len(jac)):
        raise ValueError(f"x, y and jacobian disagree in length: {len(x)}, {len(y)}, {len(jac)}")
    entries = np.ascontiguousarray(jac.reshape(-1, 4).T)  # dx/du, dx/dv, dy/du, dy/dv
    return Footprints(x, y, *_in_blocks(_footprint_axes, *entries, size=_BLOCK))


def sample_footprint(mip: MipMap, x, y, jacobian, *, lod_bias: float = LOD_BIAS) -> np.ndarray:
    """Averages of a mip-mapped raster over the ground footprints of image pixels.

    mip : MipMap of the raster.
    x, y : (n,) ground points, the footprints' centres. [m]
    jacobian : (n, 2, 2) d(x, y)/d(u, v): column 0 is the ground step of one image pixel along
        u, column 1 along v; the footprint is the parallelogram they span. [m per pixel]
    Returns (n, channels) float32 in the raster's units.

    Anisotropic filtering, as GPUs do it: the footprint is replaced by the ellipse of the same
    second moments (eigen-decomposition of J J^T; for a rectangle its axes are the sides), of
    box widths w_major >= w_minor. n_taps = min(ceil(w_major / max(w_minor, texel)), MAX_TAPS)
    taps equally spaced along the major axis each take a trilinear sample (bilinear in two
    levels, blended) at level log2(max(w_minor, w_major / n_taps) / texel) + ``lod_bias``, never
    finer than level 0: a magnified footprint is a single bilinear sample of the raster. With
    the default bias (LOD_BIAS) the filter's width is close to the footprint's; 0 is the GPU
    rule, blurrier. ``sample_footprints`` does the work; it reads several rasters through one
    set of ``footprints``.

    lod_bias : added to the level. [level]
    """
    return sample_footprints(mip, footprints(x, y, jacobian), lod_bias=lod_bias)


def sample_footprints(mip: MipMap, fp: Footprints, *, lod_bias: float = LOD_BIAS) -> np.ndarray:
    """``sample_footprint`` of footprints already reduced to ellipses: (n, channels) float32."""
    return np.ascontiguousarray(_filtered(mip, fp, lod_bias).T)


def _filtered(mip: MipMap, fp: Footprints, lod_bias: float) -> np.ndarray:
    """``sample_footprints``, channels first: (channels, n) float32: compiled
    (``_filter.filtered``), footprint by footprint, with the arithmetic of ``_filtered_arrays``."""
    n = len(fp)
    if n == 0:
        return np.zeros((mip.channels, 0), dtype=np.float32)
    from . import _filter

    taps, level, blend = _filter_choice(mip, lod_bias, fp.major, fp.minor)
    out = np.empty((mip.channels, n), dtype=np.float32)
    x, y, major, ex, ey = _float64(fp.x, fp.y, fp.major, fp.ex, fp.ey)
    _filter.filtered(*_level_tables(mip), mip.outside == "periodic", x, y, np.arange(n), major, ex, ey,
                     taps, level, blend, out)
    return out


def _float64(*arrays) -> tuple:
    """The arrays as contiguous float64 (no copy when they are)."""
    return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in arrays)


def _level_tables(mip: MipMap) -> tuple:
    """What the compiled loops need of a MipMap: the flat texels, the channels, and per level
    the offset (int64), shape (rows, cols) int64, origin (x, y) and texel size (px, py) float64."""
    return (mip.texels.reshape(-1), mip.channels, np.asarray(mip.offsets, dtype=np.int64),
            np.asarray(mip.shapes, dtype=np.int64).reshape(-1, 2),
            np.asarray(mip.origins, dtype=np.float64).reshape(-1, 2),
            np.asarray(mip.pixels, dtype=np.float64).reshape(-1, 2))


def _filtered_arrays(mip: MipMap, fp: Footprints, lod_bias: float) -> np.ndarray:
    """``_filtered`` with whole arrays (numpy), the reference of the compiled loops.

    The footprints are grouped by level (and whether they blend two) and sorted by tap count
    within a group; each run of up to _CHUNK footprints of a group is filtered at once, tap by
    tap (``_tap_mean``). Footprints that read only the outside value ("constant") form a group
    of their own, which needs no samples.
    """
    n = len(fp)
    if n == 0:
        return np.zeros((mip.channels, 0), dtype=np.float32)
    taps, level, blend = _in_blocks(functools.partial(_filter_choice_arrays, mip, lod_bias), fp.major, fp.minor,
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


def _filter_choice(mip: MipMap, lod_bias: float, major, minor):
    """Each footprint's tap count (n,) int8, level k (n,) int16 and blend t (n,) float32 in
    [0, 1) towards level k + 1 (0: level k alone), as ``sample_footprint`` says, from its
    ellipse's box widths ``major`` and ``minor`` (n,) [m]: compiled (``_filter.filter_choice``),
    the operations of ``_filter_choice_arrays``. The choice depends on the footprints and the
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
"""``_filter_choice``'s last choices: (id major, id minor, texel, lod bias, levels) -> (major,
minor, (taps, level, blend))."""


def _new_filter_choice(texel: float, count: int, lod_bias: float, major, minor):
    from . import _filter

    major, minor = _float64(major, minor)
    n = len(major)
    taps, level, blend = np.empty(n, dtype=np.int8), np.empty(n, dtype=np.int16), np.empty(n, dtype=np.float32)
    _filter.filter_choice(texel, float(lod_bias), count, MAX_TAPS, major, minor, taps, level, blend)
    return taps, level, blend


def _filter_choice_arrays(mip: MipMap, lod_bias: float, major, minor):
    """``_filter_choice`` with whole arrays (numpy), the reference of the compiled loop."""
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


def _footprint_axes(dxdu, dxdv, dydu, dydv):
    """Box widths (major, minor) [m] and the major axis's unit vector (ex, ey) [1], each (n,)
    float64, of the ellipse with the second moments of the parallelogram spanned by the columns
    (dxdu, dydu) and (dxdv, dydv) [m per pixel] (each (n,)) of the footprint's Jacobian: J J^T =
    [[a, b], [b, c]], its larger eigenvalue and eigenvector (``_filter.footprint_axes``)."""
    from . import _filter

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


def ground_fraction_rows(camera: Camera) -> np.ndarray:
    """Fraction (height,) float64 of each image row's pixels that lies below the horizon. [1]

    The camera has no roll, so the horizon (rays with wz = 0) is the image line
    v = height / 2 + focal tan(pitch), the same for every column, and a ray's wz falls linearly
    with v: the fraction is the analytic coverage clip(row + 1 - v_horizon, 0, 1).
    """
    _, up, forward = camera.basis
    v = np.arange(camera.height + 1, dtype=np.float64)
    wz = forward[2] + (0.5 * camera.height - v) / camera.focal * up[2]  # at the row edges
    top, bottom = wz[:-1], wz[1:]
    crossing = (top > 0) & (bottom < 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        partial = np.where(crossing, -bottom / (top - bottom), 0.0)
    return np.where(top <= 0, np.where(bottom < 0, 1.0, 0.0), np.where(bottom < 0, partial, 0.0))


def ground_hits(camera: Camera):
    """Where each pixel's ground part meets the ground plane z = 0, and its footprint there.

    camera : Camera above the ground (position z > 0). [m]
    Returns
        x, y : (height, width) float64 -- the ground point seen at the centre of the pixel's
            ground part (the whole pixel, or the part below the horizon); NaN where no ground is
            seen. [m]
        jacobian : (height, width, 2, 2) float64 -- d(x, y)/d(u, v), the ground steps of one
            image pixel along u (column 0) and along v (column 1, times the ground part's
            height): the footprint parallelogram; NaN where no ground is seen. [m per pixel]
        distance : (height, width) float64 -- from the pinhole to that point, along the ray;
            inf where no ground is seen. [m]
        ground_fraction : (height, width) float64 -- the fraction of the pixel below the horizon,
            analytic (``ground_fraction_rows``). [1]

    The Jacobian is the analytic derivative of the ray-plane hit P = C + t w, t = -z_C / wz:
    dP/du = t (dw/du - w (dwz/du) / wz), and the same along v. Near the horizon the hit runs to
    infinity; wz is held at -MIN_DOWNWARD or below, so every number stays finite.
    """
    rows_total, cols_total = camera.height, camera.width
    rows, part = _ground_rows(camera)
    x_rows, y_rows, *jac_rows, distance_rows = _row_hits(camera, rows, part)
    x = np.full((rows_total, cols_total), np.nan)
    y = np.full((rows_total, cols_total), np.nan)
    jacobian = np.full((rows_total, cols_total, 2, 2), np.nan)
    distance = np.full((rows_total, cols_total), np.inf)
    coverage = np.broadcast_to(ground_fraction_rows(camera)[:, None], (rows_total, cols_total)).copy()
    x[rows], y[rows], distance[rows] = x_rows, y_rows, distance_rows
    for (i, j), entry in zip(((0, 0), (0, 1), (1, 0), (1, 1)), jac_rows):
        jacobian[rows, :, i, j] = entry
    return x, y, jacobian, distance, coverage


def _ground_rows(camera: Camera):
    """The image rows that see ground, (r,) int, every pixel of which sees it, and their
    fractions below the horizon (r,) float64 [1]; checks that the camera is above the ground."""
    height_m = float(camera.position[2])
    if not height_m > 0:
        raise ValueError(f"the camera must be above the ground, got z = {height_m} [m]")
    fraction = ground_fraction_rows(camera)
    rows = np.flatnonzero(fraction > 0)
    return rows, fraction[rows]


def _row_hits(camera: Camera, rows, part):
    """``ground_hits`` for some image rows (r,) int that see ground, of fractions ``part`` (r,)
    below the horizon [1], without the full-image arrays: x, y [m], the Jacobian's entries
    dx/du, dx/dv, dy/du, dy/dv [m per pixel] and distance [m], each (r, width) float64."""
    height_m = float(camera.position[2])
    part = part[:, None]
    v = rows[:, None] + 1.0 - 0.5 * part
    u = np.arange(camera.width, dtype=np.float64)[None, :] + 0.5
    right, up, forward = camera.basis
    f = camera.focal
    # image_rays, one component at a time: (r, width) arrays
    across, down = (u - 0.5 * camera.width) / f, (0.5 * camera.height - v) / f
    wx, wy, w_z = (forward[k] + across * right[k] + down * up[k] for k in range(3))
    wz = np.minimum(w_z, -MIN_DOWNWARD)
    t = height_m / -wz
    x = camera.position[0] + t * wx
    y = camera.position[1] + t * wy
    jacobian = {}
    for j, (dw, scale) in enumerate(((right / f, 1.0), (-up / f, part))):
        slope = dw[2] / wz  # d(wz)/d(image) over wz
        jacobian[0, j] = t * (dw[0] - wx * slope) * scale
        jacobian[1, j] = t * (dw[1] - wy * slope) * scale
    distance = t * np.sqrt(wx * wx + wy * wy + w_z * w_z)
    return x, y, jacobian[0, 0], jacobian[0, 1], jacobian[1, 0], jacobian[1, 1], distance


def ground_view(camera: Camera, *, irradiance, albedo: MipMap):
    """The Lambertian ground z = 0 in the camera's image: radiance = albedo E / pi.

    camera : Camera above the ground (position z > 0). [m]
    irradiance : MipMap of the ground irradiance E (channels 3, or 1 for grey), or a sequence
        of them, finest first: each but the last holds NaN beyond its raster ("constant" with
        value NaN), and a footprint that reaches NaN is read from the next. [radiance x sr]
    albedo : MipMap of the ground's albedo (channels 3 or 1), or a laying of one with a
        ``sample(footprints, lod_bias=)`` method (``albedo.StochasticTiling``). [1]
    Returns
        radiance : (height, width, 3) float32 -- albedo E / pi over the pixel's ground part, with
            albedo and E each averaged over its ground footprint (``ground_hits``,
            ``sample_footprint``); 0 where no ground is seen. [radiance]
        ground_fraction : (height, width) float32 -- the fraction of the pixel below the horizon:
            the anti-aliased horizon; read-only, made once per camera. [1]
        distance : (height, width) float32 -- from the pinhole to the ground point seen, along
            the ray (for aerial perspective); inf where no ground is seen; read-only, made
            once per camera. [m]

    Near the horizon the footprints grow without bound and the samples reach the rasters'
    coarsest levels: their means for periodic rasters, the outside value otherwise.
    """
    rows, e = _seen_irradiance(camera, irradiance)
    radiance = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    if len(rows):
        rho = _albedo_in_view(camera, albedo)
        e = np.multiply(e, rho, out=e if len(e) >= len(rho) else None)  # (e rho) / pi in float32
        e *= np.float32(1.0 / np.pi)
        radiance[rows] = e.T.reshape(len(rows), camera.width, -1)
    return radiance, _ground_fractions(camera)[0], ground_distance(camera)


def ground_irradiance(camera: Camera, *, irradiance) -> np.ndarray:
    """The ground's horizontal irradiance E (height, width, 3) float32 that each pixel sees,
    averaged over its ground footprint as ``ground_view`` averages it (the same filtered
    chain), without the albedo; 0 where no ground is seen. [radiance x sr]"""
    rows, e = _seen_irradiance(camera, irradiance)
    out = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    if len(rows):
        out[rows] = e.T.reshape(len(rows), camera.width, -1)
    return out


def _seen_irradiance(camera: Camera, irradiance):
    """(the image rows that see ground, E (channels, pixels) float32 over their footprints or
    None without such rows): ``ground_view``'s and ``ground_irradiance``'s read of the
    irradiance MipMaps (a MipMap or a sequence, finest first). [radiance x sr]"""
    rows, _ = _ground_rows(camera)
    if not len(rows):
        return rows, None
    fp, _ = _view_footprints(camera)
    return rows, _filtered_chain(irradiance if isinstance(irradiance, (tuple, list)) else (irradiance,), fp)


@functools.lru_cache(maxsize=1)
def _ground_fractions(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """``ground_view``'s ground fraction f (height, width) float32 and 1 - f (height, width, 1):
    they depend on the camera alone. Read-only."""
    fraction = np.broadcast_to(ground_fraction_rows(camera).astype(np.float32)[:, None],
                               (camera.height, camera.width)).copy()
    rest = 1.0 - fraction[..., None]
    for array in (fraction, rest):
        array.flags.writeable = False
    return fraction, rest


@functools.lru_cache(maxsize=1)
def ground_distance(camera: Camera) -> np.ndarray:
    """(height, width) float32 distance from the pinhole to the ground point each pixel sees,
    along the ray (``ground_view``'s), inf where no ground is seen: made once for the frames of
    a run, whose camera stands still. Read-only. [m]"""
    rows, _ = _ground_rows(camera)
    distance = np.full((camera.height, camera.width), np.inf, dtype=np.float32)
    if len(rows):
        distance[rows] = _view_footprints(camera)[1].reshape(len(rows), camera.width)
    distance.flags.writeable = False
    return distance


@functools.lru_cache(maxsize=1)
def _view_footprints(camera: Camera):
    """``ground_view``'s Footprints of the pixels of the image rows that see ground, rows
    first, and their distances (n,) float32 [m] (``_row_footprints``): made once for the
    frames of a run, whose camera stands still. Not to be written to (left writable: numba
    compiles read-only arrays as another type)."""
    rows, part = _ground_rows(camera)
    *ellipses, distance = _row_footprints(camera, rows, part)
    return Footprints(*ellipses), distance


@functools.lru_cache(maxsize=2)
def _albedo_in_view(camera: Camera, albedo) -> np.ndarray:
    """The albedo (channels, n) float32 (read-only) of the ground pixels of ``camera``'s view
    (``_view_footprints``), for a MipMap or a laying with ``sample``. It depends on the view
    and the albedo alone, so the frames of a run, whose camera stands still, read it once (the
    lru_cache holds the albedo, so its id is not reused)."""
    fp, _ = _view_footprints(camera)
    rho = _filtered(albedo, fp, LOD_BIAS) if isinstance(albedo, MipMap) else albedo.sample(fp, lod_bias=LOD_BIAS)
    rho.flags.writeable = False
    return rho


def _filtered_chain(maps, fp: Footprints) -> np.ndarray:
    """(channels, n) samples of the first of ``maps`` whose footprint stays finite."""
    values = _filtered(maps[0], fp, LOD_BIAS)
    for mip in maps[1:]:
        missing = np.flatnonzero(~np.isfinite(values).all(axis=0))
        if not len(missing):
            break
        subset = Footprints(*(getattr(fp, f.name)[missing] for f in fields(Footprints)))
        values[:, missing] = _filtered(mip, subset, LOD_BIAS)
    return values


def _row_footprints(camera: Camera, rows, part):
    """The ``Footprints`` fields and the distances of the pixels of some image rows that see
    ground (``_row_hits``), each (r width,) float64 (the distances float32): compiled
    (``_filter.row_footprints``), the operations of ``_row_footprints_arrays``."""
    from . import _filter

    n = len(rows) * camera.width
    x, y, major, minor, ex, ey = (np.empty(n) for _ in range(6))
    distance = np.empty(n, dtype=np.float32)
    right, up, forward = camera.basis
    _filter.row_footprints(np.asarray(rows, dtype=np.float64), np.asarray(part, dtype=np.float64),
                           camera.width, camera.height, float(camera.focal),
                           np.asarray(camera.position, dtype=np.float64), right, up, forward, MIN_DOWNWARD,
                           x, y, major, minor, ex, ey, distance)
    return x, y, major, minor, ex, ey, distance


def _row_footprints_arrays(camera: Camera, rows, part):
    """``_row_footprints`` with whole arrays (numpy), the reference of the compiled loop."""
    x, y, *jacobian, distance = (u.ravel() for u in _row_hits(camera, rows, part))
    return (x, y, *_footprint_axes(*jacobian), distance.astype(np.float32))


def sky_view(camera: Camera, sky) -> np.ndarray:
    """The sky's radiance (height, width, 3) float32 in the camera's image, without the sun disc.

    sky : a ``sky.Sky``, asked for its ``view_radiance`` along each pixel's unit vector w, at
        sky-plane points s = (wx / wz, wy / wz) [tan] with wz / |w| held at MIN_UPWARD or more,
        with a pixel's width on the sky plane along the radius and across as the footprint.
    Each pixel cut by the horizon is sampled at the centre of its sky part; pixels wholly below
    the horizon are 0. [radiance]
    """
    out = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    rows, w, s, footprint = _sky_rays(camera)
    if len(rows):
        out[rows] = sky.view_radiance(w, s, footprint)
    return out


@functools.lru_cache(maxsize=1)
def _sky_rays(camera: Camera):
    """``sky_view``'s image rows that see sky, and their pixels' unit vectors w, sky-plane
    points s and footprints: made once for the frames of a run, whose camera stands still.
    Read-only."""
    fraction = ground_fraction_rows(camera)
    rows = np.flatnonzero(fraction < 1)
    v = (rows + 0.5 * (1.0 - fraction[rows]))[:, None]
    u = np.arange(camera.width, dtype=np.float64)[None, :] + 0.5
    w = image_rays(camera, u, v)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    wz = np.maximum(w[..., 2], MIN_UPWARD)
    s = np.stack([w[..., 0] / wz, w[..., 1] / wz], axis=-1)
    footprint = np.stack(np.broadcast_arrays(1.0 / (camera.focal * wz * wz), 1.0 / (camera.focal * wz)), axis=-1)
    for array in (rows, w, s, footprint):
        array.flags.writeable = False
    return rows, w, s, footprint


def horizon_sky(camera: Camera, sky) -> np.ndarray:
    """The sky's radiance (width, 3) float32 just above the horizon in each image column: the
    radiance of an endless column of haze seen level (the sky model holds its haze), which
    the ground tends to with distance (Koschmieder 1924, ``render.render_frame``).

    Each column is sampled in its direction at the horizon, raised to wz / |w| = MIN_UPWARD,
    with the footprint of ``sky_view`` there (the cloud pattern filtered to its mean so far
    out). sky : as ``sky_view``. [radiance]
    """
    right, up, forward = camera.basis
    u = np.arange(camera.width, dtype=np.float64) + 0.5
    # the level ray of column u is forward + x right + y up with wz = 0: y = -tan(pitch), and its
    # horizontal part (sin yaw, cos yaw) / cos(pitch) + x right
    ahead = np.array([np.sin(camera.yaw), np.cos(camera.yaw), 0.0]) / max(np.cos(camera.pitch), 1e-6)
    x = (u - 0.5 * camera.width) / camera.focal
    w = ahead[None, :] + x[:, None] * np.array([right[0], right[1], 0.0])[None, :]
    w[:, :2] /= np.hypot(w[:, 0], w[:, 1])[:, None]
    w[:, 2] = MIN_UPWARD / np.sqrt(1.0 - MIN_UPWARD**2)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    s = w[:, :2] / w[:, 2:3]
    return np.asarray(sky.view_radiance(w, s, 1.0 / (camera.focal * MIN_UPWARD**2)), dtype=np.float32)


def equirect_lookup(image, w, *, rotation: float = 0.0, sky_only: bool = False) -> np.ndarray:
    """Bilinear samples (..., 3) float32 of an equirectangular image (height, width, 3) in the
    directions of unit vectors w (..., 3), in the convention of docs/method.md (top row at the zenith,
    centre column north, east at three quarters of the width, texel centres at
    ((col + 0.5) / width, (row + 0.5) / height)); ``rotation`` [rad] turns the image about the
    zenith towards the east. Columns wrap round; rows are held at the poles. ``sky_only``: rows
    are held to the upper half too, so that a direction just above the horizon never blends in
    the image's ground below it (the ground plane stands for that: blended, it drew a dark band
    over the horizon)."""
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


def background(camera: Camera, *, irradiance, albedo: MipMap, sky, seen_sky=None):
    """The background B of the composite: ground and sky blended by the horizon's coverage.

    Returns radiance (height, width, 3) float32 = f ground + (1 - f) sky [radiance], with f the
    pixel's ground fraction, and distance (height, width) float32, the ground's (inf where
    there is no ground) [m]; see ``ground_view`` and ``sky_view``. ``seen_sky``: the sky's
    ``sky_view`` made before (not changed), so that a frame's light passes read the sky once.
    """
    ground, fraction, distance = ground_view(camera, irradiance=irradiance, albedo=albedo)
    sky_radiance = sky_view(camera, sky) if seen_sky is None else seen_sky.copy()
    ground *= fraction[..., None]  # f ground + (1 - f) sky in float32, in place
    sky_radiance *= _ground_fractions(camera)[1]
    ground += sky_radiance
    return ground, distance
