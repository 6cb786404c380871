"""The pinhole camera: its rays, and where world points land in its image.

Image convention: pixel (row, col) covers ``[col, col + 1) x [row, row + 1)`` in continuous image
coordinates (u along columns to the right, v along rows downwards); its centre is
``(col + 0.5, row + 0.5)``. The camera looks along ``forward``; ``right`` is horizontal and
``up = right x forward``, so with no roll the horizon is level. A camera looking straight down
with yaw 0 has north at the top of its image, as the ground rasters do.

Below the rays, the perspective view of the ground and the sky (the background of the frame):
``mipmap`` and ``sample_footprint`` (anisotropic, area-averaged reading of ground rasters),
``ground_hits`` and ``ground_view`` (the Lambertian ground, its anti-aliased horizon and
distances), ``sky_view`` and ``background``.
"""

from __future__ import annotations

from dataclasses import dataclass

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
    v, u = np.mgrid[0:camera.height, 0:camera.width] + 0.5
    return image_rays(camera, u, v)


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
# (DESIGN.md section 4, frame = F_sky + S (F_sun - F_sky) + (1 - A) B).
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

    texels : ndarray (texels, channels) float32 -- every level, rows first. In "constant" mode
        each level is stored with a border of one texel of ``value`` all round.
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

    def level(self, k: int) -> np.ndarray:
        """Level ``k`` (rows, cols, channels) float32 without its border (a read-only view)."""
        rows, cols = self.shapes[k]
        border = 1 if self.outside == "constant" else 0
        stored = self.texels[self.offsets[k] : self.offsets[k] + (rows + 2 * border) * (cols + 2 * border)]
        view = stored.reshape(rows + 2 * border, cols + 2 * border, self.channels)
        view = view[border : border + rows, border : border + cols]
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
        levels = _constant_levels(a, value)
        origins = (tuple(float(v) for v in grid.origin),) * len(levels)
        pixels = tuple((grid.pixel * 2.0**k,) * 2 for k in range(len(levels)))
        border = 1
    else:
        if period is None or value is not None:
            raise ValueError('outside="periodic" takes a period and no value')
        px, py = (float(v) for v in period)
        x_min, y_min, x_max, y_max = grid.extent
        if not (px > 0 and py > 0):
            raise ValueError(f"period must be positive, got {period}")
        if px > (x_max - x_min) * (1 + 1e-9) or py > (y_max - y_min) * (1 + 1e-9):
            raise ValueError(f"the raster ({x_max - x_min} x {y_max - y_min} m) must cover one period {period}")
        levels = _periodic_levels(a, px / grid.pixel, py / grid.pixel)
        origins = ((float(x_min), float(y_min + py)),) * len(levels)
        pixels = tuple((px / lv.shape[1], py / lv.shape[0]) for lv in levels)
        value, period, border = None, (px, py), 0
    sizes = [(lv.shape[0] + 2 * border) * (lv.shape[1] + 2 * border) for lv in levels]
    offsets = tuple(int(v) for v in np.concatenate([[0], np.cumsum(sizes)[:-1]]))
    texels = np.empty((sum(sizes), channels), dtype=np.float32)
    for lv, start, size in zip(levels, offsets, sizes):
        stored = texels[start : start + size].reshape(lv.shape[0] + 2 * border, lv.shape[1] + 2 * border, channels)
        if border:
            stored[...] = value
            stored[1:-1, 1:-1] = lv
        else:
            stored[...] = lv
    shapes = tuple((lv.shape[0], lv.shape[1]) for lv in levels)
    return MipMap(texels, shapes, offsets, origins, pixels, outside, value, period)


def _constant_levels(a: np.ndarray, value: np.ndarray) -> list:
    """Levels of a raster on a plane of ``value``: pad to even sizes with the value, average 2 x 2."""
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
    return (0.5 * (even + odd)).astype(np.float32)


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
    rule, blurrier. Points are grouped by level and sorted by tap count, so the work is about
    8 gathers per tap, vectorised.

    lod_bias : added to the level. [level]
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    jac = np.asarray(jacobian, dtype=np.float64).reshape(-1, 2, 2)
    if not (len(x) == len(y) == len(jac)):
        raise ValueError(f"x, y and jacobian disagree in length: {len(x)}, {len(y)}, {len(jac)}")
    out = np.zeros((len(x), mip.channels), dtype=np.float32)
    if len(x) == 0:
        return out
    texel = float(np.sqrt(mip.pixels[0][0] * mip.pixels[0][1]))
    major, minor, ex, ey = _footprint_axes(jac)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.nan_to_num(major / np.maximum(minor, texel), nan=1.0, posinf=MAX_TAPS)
        taps = np.clip(np.ceil(ratio - 1e-3), 1, MAX_TAPS).astype(np.int64)
        lod = np.log2(np.maximum(minor, major / taps) / texel) + lod_bias
    lod = np.clip(np.nan_to_num(lod, nan=0.0), 0.0, mip.count - 1)
    k = np.minimum(np.floor(lod).astype(np.int64), mip.count - 1)
    t = lod - k
    done = t > 1.0 - 1e-6  # all in the next level
    k[done] += 1
    t[done | (t < 1e-6)] = 0.0
    group = 2 * k + (t > 0)
    order = np.argsort(group * (MAX_TAPS + 1) + (MAX_TAPS - taps), kind="stable")
    group, taps, major = group[order], taps[order], major[order]
    x, y, ex, ey, t = x[order], y[order], ex[order], ey[order], t[order].astype(np.float32)[:, None]
    accumulated = np.zeros_like(out)
    starts = np.flatnonzero(np.diff(group, prepend=-1))
    for a, b in zip(starts, np.append(starts[1:], len(group))):
        level, blended = divmod(int(group[a]), 2)
        descending = -taps[a:b]
        for i in range(int(taps[a])):
            s = slice(a, a + int(np.searchsorted(descending, -i, side="left")))
            step = ((i + 0.5) / taps[s] - 0.5) * major[s]
            px, py = x[s] + step * ex[s], y[s] + step * ey[s]
            sample = _bilinear(mip, level, px, py)
            if blended:
                sample += t[s] * (_bilinear(mip, level + 1, px, py) - sample)
            accumulated[s] += sample
    out[order] = accumulated / taps[:, None].astype(np.float32)
    return out


def _footprint_axes(jac: np.ndarray):
    """Box widths (major, minor) [m] and the major axis's unit vector (ex, ey) of the ellipse
    with the second moments of the parallelogram spanned by the columns of ``jac`` (n, 2, 2)."""
    a = jac[:, 0, 0] ** 2 + jac[:, 0, 1] ** 2
    b = jac[:, 0, 0] * jac[:, 1, 0] + jac[:, 0, 1] * jac[:, 1, 1]
    c = jac[:, 1, 0] ** 2 + jac[:, 1, 1] ** 2
    half = np.sqrt(0.25 * (a - c) ** 2 + b * b)
    big = 0.5 * (a + c) + half
    major = np.sqrt(big)
    area = np.abs(jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        minor = np.where(major > 0, area / major, 0.0)
    # eigenvector of the larger eigenvalue: the better conditioned of two equivalent forms
    v1x, v1y = big - c, b
    v2x, v2y = b, big - a
    first = v1x * v1x + v1y * v1y >= v2x * v2x + v2y * v2y
    ex, ey = np.where(first, v1x, v2x), np.where(first, v1y, v2y)
    norm = np.hypot(ex, ey)
    round_ = norm <= 1e-12 * np.maximum(big, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        ex = np.where(round_, 1.0, ex / norm)
        ey = np.where(round_, 0.0, ey / norm)
    return major, minor, ex, ey


def _bilinear(mip: MipMap, level: int, x, y) -> np.ndarray:
    """Bilinear samples (m, C) float32 of one level at ground points (x, y) (m,) [m], the plane
    beyond the raster as ``mip.outside`` says."""
    (x0, y0), (px, py) = mip.origins[level], mip.pixels[level]
    rows, cols = mip.shapes[level]
    limit = 2.0**52  # beyond this a float holds no fraction, and int64 must not overflow
    col = (x - x0) * (1.0 / px) - 0.5
    row = (y0 - y) * (1.0 / py) - 0.5
    for u in (col, row):
        np.minimum(u, limit, out=u)
        np.maximum(u, -limit, out=u)
    c0, r0 = np.floor(col), np.floor(row)
    fc = (col - c0).astype(np.float32)[:, None]
    fr = (row - r0).astype(np.float32)[:, None]
    c0, r0 = c0.astype(np.int64), r0.astype(np.int64)
    if mip.outside == "periodic":
        c0 %= cols
        r0 %= rows
        c1 = c0 + 1
        c1[c1 == cols] = 0
        r1 = r0 + 1
        r1[r1 == rows] = 0
        stride = cols
    else:  # a border of the outside value all round: clip into it
        c1 = np.clip(c0 + 1, -1, cols) + 1
        r1 = np.clip(r0 + 1, -1, rows) + 1
        c0 = np.clip(c0, -1, cols) + 1
        r0 = np.clip(r0, -1, rows) + 1
        stride = cols + 2
    top = r0 * stride + mip.offsets[level]
    bottom = r1 * stride + mip.offsets[level]
    texels = mip.texels
    a, b = np.take(texels, top + c0, axis=0), np.take(texels, top + c1, axis=0)
    upper = a + fc * (b - a)
    a, b = np.take(texels, bottom + c0, axis=0), np.take(texels, bottom + c1, axis=0)
    lower = a + fc * (b - a)
    return upper + fr * (lower - upper)


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
    height_m = float(camera.position[2])
    if not height_m > 0:
        raise ValueError(f"the camera must be above the ground, got z = {height_m} [m]")
    rows_total, cols_total = camera.height, camera.width
    fraction = ground_fraction_rows(camera)
    x = np.full((rows_total, cols_total), np.nan)
    y = np.full((rows_total, cols_total), np.nan)
    jacobian = np.full((rows_total, cols_total, 2, 2), np.nan)
    distance = np.full((rows_total, cols_total), np.inf)
    coverage = np.broadcast_to(fraction[:, None], (rows_total, cols_total)).copy()
    rows = np.flatnonzero(fraction > 0)
    if len(rows) == 0:
        return x, y, jacobian, distance, coverage
    part = fraction[rows][:, None]
    v = rows[:, None] + 1.0 - 0.5 * part
    u = np.arange(cols_total, dtype=np.float64)[None, :] + 0.5
    w = image_rays(camera, u, v)
    wz = np.minimum(w[..., 2], -MIN_DOWNWARD)
    t = height_m / -wz
    x[rows] = camera.position[0] + t * w[..., 0]
    y[rows] = camera.position[1] + t * w[..., 1]
    right, up, _ = camera.basis
    f = camera.focal
    for j, (dw, scale) in enumerate(((right / f, 1.0), (-up / f, part))):
        slope = dw[2] / wz  # d(wz)/d(image) over wz
        jacobian[rows, :, 0, j] = t * (dw[0] - w[..., 0] * slope) * scale
        jacobian[rows, :, 1, j] = t * (dw[1] - w[..., 1] * slope) * scale
    distance[rows] = t * np.linalg.norm(w, axis=-1)
    return x, y, jacobian, distance, coverage


def ground_view(camera: Camera, *, irradiance: MipMap, albedo: MipMap):
    """The Lambertian ground z = 0 in the camera's image: radiance = albedo E / pi.

    camera : Camera above the ground (position z > 0). [m]
    irradiance : MipMap of the ground irradiance E (channels 3, or 1 for grey). [radiance x sr]
    albedo : MipMap of the ground's albedo (channels 3 or 1). [1]
    Returns
        radiance : (height, width, 3) float32 -- albedo E / pi over the pixel's ground part, with
            albedo and E each averaged over its ground footprint (``ground_hits``,
            ``sample_footprint``); 0 where no ground is seen. [radiance]
        ground_fraction : (height, width) float32 -- the fraction of the pixel below the horizon:
            the anti-aliased horizon. [1]
        distance : (height, width) float32 -- from the pinhole to the ground point seen, along
            the ray (for aerial perspective); inf where no ground is seen. [m]

    Near the horizon the footprints grow without bound and the samples reach the rasters'
    coarsest levels: their means for periodic rasters, the outside value otherwise.
    """
    x, y, jacobian, distance, fraction = ground_hits(camera)
    radiance = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    seen = np.flatnonzero(np.isfinite(distance).ravel())
    if len(seen):
        xs, ys = x.ravel()[seen], y.ravel()[seen]
        jac = jacobian.reshape(-1, 2, 2)[seen]
        e = sample_footprint(irradiance, xs, ys, jac)
        rho = sample_footprint(albedo, xs, ys, jac)
        radiance.reshape(-1, 3)[seen] = e * rho * np.float32(1.0 / np.pi)
    return radiance, fraction.astype(np.float32), distance.astype(np.float32)


def sky_view(camera: Camera, sky) -> np.ndarray:
    """The sky's radiance (height, width, 3) float32 in the camera's image, without the sun disc.

    sky : UniformSky (its constant radiance), EquirectSky (bilinear in its image, ``rotation``
        included, DESIGN.md section 3) or any model with ``radiance(s)`` at sky-plane points
        s = (wx / wz, wy / wz) [tan] (ProceduralSky), with wz / |w| held at MIN_UPWARD or more.
    Each pixel cut by the horizon is sampled at the centre of its sky part; pixels wholly below
    the horizon are 0. [radiance]
    """
    from .sky import EquirectSky, UniformSky

    fraction = ground_fraction_rows(camera)
    out = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    rows = np.flatnonzero(fraction < 1)
    if len(rows) == 0:
        return out
    v = (rows + 0.5 * (1.0 - fraction[rows]))[:, None]
    u = np.arange(camera.width, dtype=np.float64)[None, :] + 0.5
    w = image_rays(camera, u, v)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    if isinstance(sky, UniformSky):
        out[rows] = np.asarray(sky.radiance, dtype=np.float32)
    elif isinstance(sky, EquirectSky):
        out[rows] = equirect_lookup(sky.image, w, rotation=sky.rotation)
    else:
        wz = np.maximum(w[..., 2], MIN_UPWARD)
        s = np.stack([w[..., 0] / wz, w[..., 1] / wz], axis=-1)
        out[rows] = sky.radiance(s)
    return out


def equirect_lookup(image, w, *, rotation: float = 0.0) -> np.ndarray:
    """Bilinear samples (..., 3) float32 of an equirectangular image (height, width, 3) in the
    directions of unit vectors w (..., 3), in DESIGN.md's convention (top row at the zenith,
    centre column north, east at three quarters of the width, texel centres at
    ((col + 0.5) / width, (row + 0.5) / height)); ``rotation`` [rad] turns the image about the
    zenith towards the east. Columns wrap round; rows are held at the poles."""
    image = np.asarray(image)
    height, width = image.shape[:2]
    w = np.asarray(w, dtype=np.float64)
    azimuth = np.arctan2(w[..., 0], w[..., 1]) - rotation
    zenith = np.arccos(np.clip(w[..., 2], -1.0, 1.0))
    col = (azimuth / (2.0 * np.pi) + 0.5) * width - 0.5
    row = np.clip(zenith / np.pi * height - 0.5, 0.0, height - 1.0)
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


def background(camera: Camera, *, irradiance: MipMap, albedo: MipMap, sky):
    """The background B of the composite: ground and sky blended by the horizon's coverage.

    Returns radiance (height, width, 3) float32 = f ground + (1 - f) sky [radiance], with f the
    pixel's ground fraction, and distance (height, width) float32, the ground's (inf where
    there is no ground) [m]; see ``ground_view`` and ``sky_view``.
    """
    ground, fraction, distance = ground_view(camera, irradiance=irradiance, albedo=albedo)
    sky_radiance = sky_view(camera, sky)
    f = fraction[..., None]
    return (f * ground + (1.0 - f) * sky_radiance).astype(np.float32), distance
