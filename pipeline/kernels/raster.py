"""Compiled loops of the anti-aliased rasteriser (``rasteriser.rasterize_transmittance``).

The method is the one documented in ``rasteriser.py`` (and docs/method.md): the coverage of a pixel
is the mean over k x k sub-samples of the exact area fraction of the sub-sample's square that
lies inside the shape's local strip. These loops compute it shape by shape straight into the
transmittance-depth raster, with the same float32 arithmetic as the array version they replace, so
that no per-pixel fragment arrays are built. Imported lazily: numba costs 0.3 s to import.

Why one module: every numba kernel of the canopy and foreground passes sits behind that one lazy
import and one on-disk compile cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "box_pixels", "in_order", "shapes", "flutter", "onto", "ellipse_params", "leaf_fragments",
    "scatter_light", "leaf_heights",
]


@njit(cache=True, nogil=True)
def box_pixels(center: np.ndarray, half: np.ndarray, index: np.ndarray, rows: int, cols: int) -> int:
    """How many pixels the boxes hold within the raster.

    Parameters
    ----------
    center : numpy.ndarray
        (m, 2) centres of the boxes [pixel].
    half : numpy.ndarray
        (n, 2) half-sizes, read as half[index] [pixel].
    index : numpy.ndarray
        (m,) the half-size of each box.
    rows, cols : int
        The raster's size [pixel].

    Returns
    -------
    int
        The pixels [count].
    """
    total = 0
    for ii in range(index.shape[0]):
        i = index[ii]
        w = min(max(math.ceil(center[ii, 0] + half[i, 0]), 0.0), float(cols)) - \
            min(max(math.floor(center[ii, 0] - half[i, 0]), 0.0), float(cols))
        h = min(max(math.ceil(center[ii, 1] + half[i, 1]), 0.0), float(rows)) - \
            min(max(math.floor(center[ii, 1] - half[i, 1]), 0.0), float(rows))
        if w > 0 and h > 0:
            total += int(w) * int(h)
    return total


@njit(cache=True, nogil=True)
def in_order(order: np.ndarray, center: np.ndarray, half: np.ndarray, prm: np.ndarray, feature: np.ndarray,
             thickness: np.ndarray, owner: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The shapes' arrays taken in the order ``order`` (prm as float32).

    The kernels then read them one after another, not at random (docs/accuracy.md, "The leaf
    rasteriser").

    Parameters
    ----------
    order : numpy.ndarray
        (n,) indices.
    center, half : numpy.ndarray
        (n, 2) [pixel].
    prm : numpy.ndarray
        (n, k) shape parameters.
    feature, thickness : numpy.ndarray
        (n,) [pixel].
    owner : numpy.ndarray
        (n,) shape numbers.

    Returns
    -------
    tuple of numpy.ndarray
        (center, half, prm, feature, thickness, owner) reordered; ``prm`` float32.
    """
    n = order.shape[0]
    center_out, half_out, prm_out = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, prm.shape[1]), np.float32)
    feature_out, thickness_out, owner_out = np.empty(n), np.empty(n), np.empty(n, owner.dtype)
    for ii in range(n):
        i = order[ii]
        center_out[ii, 0], center_out[ii, 1], half_out[ii, 0], half_out[ii, 1] = \
            center[i, 0], center[i, 1], half[i, 0], half[i, 1]
        for j in range(prm.shape[1]):
            prm_out[ii, j] = prm[i, j]
        feature_out[ii], thickness_out[ii], owner_out[ii] = feature[i], thickness[i], owner[i]
    return center_out, half_out, prm_out, feature_out, thickness_out, owner_out


_OPAQUE = np.float32(1.0 - 2.0**-20)

# inline="always" (numba inlines before typing, which costs compile time) only where it was
# measured to matter, the box loop's helpers that take the sample buffers; LLVM inlines the
# small arithmetic ones (_square_cdf, _cover, _turn) as fast
# (docs/accuracy.md, "The leaf rasteriser").


@njit(cache=True, nogil=True, error_model="numpy")
def _square_cdf(t, a, b):
    """Fraction of a unit square (centred on 0) where n . u <= t, |n| = 1, a = max(|nx|, |ny|),
    b = min(|nx|, |ny|): the CDF of a trapezoid (tests/test_canopy.py's _square_cdf, branch-free). One division:
    the branch's denominator, a or 2 a b + 1e-12, is chosen first (the same bits as 1 / a and
    1 / (2 a b + 1e-12) computed apart)."""
    s = abs(t)
    edge = max(np.float32(0.5) * (a + b) - s, np.float32(0.0))
    slope = s <= np.float32(0.5) * (a - b)
    inv = np.float32(1.0) / (a if slope else np.float32(2.0) * a * b + np.float32(1e-12))
    tail = np.float32(0.5) - s * inv if slope else edge * edge * inv
    return tail if t < 0 else np.float32(1.0) - tail


@njit(cache=True, nogil=True, error_model="numpy")
def _cover(d, nx, ny, kf, thick):
    """Coverage of one sub-sample from its signed distance d and normal (nx, ny) [pixel]; thick
    >= 0 (thin shapes) subtracts the parallel half-plane ``thick`` sub-sample widths further in.
    It is exactly 0 where d k >= _CLEAR and exactly 1 where d k <= -_CLEAR and thick < 0 (the
    trapezoid, |n| <= 1, is at most sqrt(2) / 2 wide on either side of its centre)."""
    nx, ny = abs(nx), abs(ny)
    a = max(max(nx, ny), np.float32(0.7071))
    b = min(nx, ny)
    t = d * -kf
    cover = _square_cdf(t, a, b)
    if thick >= 0:
        cover -= _square_cdf(t - thick, a, b)
    return cover


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _samples(rx, ry, w, h, k, dxs, dys):
    """Sub-sample offsets from the shape's centre [pixel] over its w x h box, k x k per pixel,
    sub-sample by sub-sample: the (sy, sx)-th of every pixel, row by row, then the next
    (float32, as the array version computes them: k is a power of two, so multiplying by 1 / k
    gives the bits of dividing by k); returns their count."""
    step = np.float32(1.0) / np.float32(k)
    n = w * h
    # x of the planes (0, sx): their first row, then copies of it; y of the planes (sy, 0)
    for c in range(w * k):
        dxs[(c % k) * n + c // k] = (np.float32(c) + np.float32(0.5)) * step - rx
    for sx in range(k):
        for p in range(w, n):
            dxs[sx * n + p] = dxs[sx * n + p - w]
    for sy in range(k):
        for r in range(h):
            dy = (np.float32(r * k + sy) + np.float32(0.5)) * step - ry
            for c in range(w):
                dys[sy * k * n + r * w + c] = dy
    for sy in range(k):  # every other plane copies them
        for sx in range(k):
            plane = (sy * k + sx) * n
            for p in range(n):
                if sy > 0:
                    dxs[plane + p] = dxs[sx * n + p]
                if sx > 0:
                    dys[plane + p] = dys[sy * k * n + p]
    m = k * k * n
    return m


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sum_samples(buf, n, k):
    """Each of the n pixels' k x k sub-sample coverages (as ``_samples`` orders them) summed
    into buf[:n], in the order (sy, sx) of the array version, all pixels at once."""
    for s in range(1, k * k):
        for p in range(n):
            buf[p] += buf[s * n + p]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _deposit(buf, w, h, k, x0, y0, transmittance, fragments, shape, count):
    """The coverages of a w x h box at (x0, y0), buf[:w h] (the sums of ``_sum_samples``)
    divided by k k, clipped just below 1: transmittance[row, col] multiplied by 1 - cover, or,
    where ``fragments`` (pixel, coverage, shape) has room, fragments appended at ``count``.
    Returns the new count."""
    pixel, coverage, source = fragments
    mean = np.float32(1.0) / np.float32(k * k)  # a power of two: the bits of dividing
    if pixel.shape[0]:
        for r in range(h):
            for c in range(w):
                cover = buf[r * w + c] * mean
                if cover > 0:
                    pixel[count] = (y0 + r) * transmittance.shape[1] + x0 + c
                    coverage[count] = min(cover, _OPAQUE)
                    source[count] = shape
                    count += 1
    else:
        for r in range(h):
            for c in range(w):
                cover = buf[r * w + c] * mean
                if cover > 0:
                    transmittance[y0 + r, x0 + c] *= 1.0 - float(min(cover, _OPAQUE))
    return count


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _box(cx, cy, hx, hy, feature, thickness, rows, cols, most):
    """The box of a shape centred at (cx, cy) with half-size (hx, hy) [pixel], clipped to the
    raster, as tests/test_canopy.py's _reference_scatter chooses it: (col, row, width, height, k sub-samples per axis,
    thin, thickness in sub-samples or -1 when not thin); width 0 when it misses the raster."""
    x0 = min(max(math.floor(cx - hx), 0.0), float(cols))
    y0 = min(max(math.floor(cy - hy), 0.0), float(rows))
    x1 = min(max(math.ceil(cx + hx), 0.0), float(cols))
    y1 = min(max(math.ceil(cy + hy), 0.0), float(rows))
    w, h = int(x1) - int(x0), int(y1) - int(y0)
    if w <= 0 or h <= 0:
        return int(x0), int(y0), 0, 0, 1, np.float32(-1.0)
    k = 1 if feature >= 2.5 else (2 if feature >= 0.8 else 4)
    if w * h * k * k > most:  # fewer sub-samples for huge boxes, as before
        k = 1 if w * h * 4 > most else 2
    thick = np.float32(thickness * k) if thickness * k < 1.5 else np.float32(-1.0)
    return int(x0), int(y0), w, h, k, thick


@njit(cache=True, nogil=True)
def _grown(buffer, size):
    return buffer if buffer.shape[0] >= size else np.empty(2 * size, np.float32)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _next_box(ii, center, half, index, feature, thickness, most, transmittance, samples):
    """The ii-th box to draw, as ``_box`` gives it: (shape index i, col, row, width, height, k,
    thick, its centre relative to (col, row) (float32) [pixel], the sample buffers ``samples``
    (x, y, coverage) grown to hold its sub-samples)."""
    i, cx, cy = index[ii], center[ii, 0], center[ii, 1]
    rows, cols = transmittance.shape
    x0, y0, w, h, k, thick = _box(cx, cy, half[i, 0], half[i, 1], feature[i], thickness[i], rows, cols, most)
    n = w * h * k * k
    return i, x0, y0, w, h, k, thick, np.float32(cx - x0), np.float32(cy - y0), \
        (_grown(samples[0], n), _grown(samples[1], n), _grown(samples[2], n))


@njit(cache=True, nogil=True, error_model="numpy")
def shapes(capsule: bool, center: np.ndarray, half: np.ndarray, index: np.ndarray, prm: np.ndarray,
           feature: np.ndarray, thickness: np.ndarray, most: int, transmittance: np.ndarray,
           fragments: tuple[np.ndarray, np.ndarray, np.ndarray], owner: np.ndarray, count: int) -> int:
    """Every ellipse's or capsule piece's coverage c of every pixel of its box, into the transmittance or
    as fragments.

    ``transmittance`` (rows, cols) is multiplied by 1 - c, or, if the arrays ``fragments`` are not
    empty, fragments are appended from ``count`` (``transmittance`` then only gives the raster's
    shape).

    Parameters
    ----------
    capsule : bool
        Capsule pieces (the wood), else ellipses (the leaves).
    center : numpy.ndarray
        (m, 2) float64: the boxes' centres (u, v), in the order drawn (translates of a periodic
        canopy included) [pixel].
    half : numpy.ndarray
        (n, 2) box half-sizes of the shapes [pixel].
    index : numpy.ndarray
        (m,) the shape of each box, into the per-shape arrays.
    prm : numpy.ndarray
        Float32 shape parameters. Ellipses: (n, 4), the major unit vector, semi-axes A, B. Capsule
        pieces: (n, 8), the axis start relative to the piece's centre (x0, y0), the axis (ex, ey),
        1 / |axis|^2, the radius, and the stretch [t_lo, t_hi) of the axis whose pixels (judged at
        their centres) the piece draws.
    feature : numpy.ndarray
        (n,) feature size (B, or the radius) [pixel].
    thickness : numpy.ndarray
        (n,) thickness (2 B, or twice the radius) [pixel].
    most : int
        The most sub-samples of one box before k is lowered [count].
    transmittance : numpy.ndarray
        (rows, cols) float64, multiplied by 1 - c in place; only its shape is read when
        ``fragments`` has room [1].
    fragments : tuple of numpy.ndarray
        (flat pixel int64, coverage float32, shape int64), each (size,); empty for the
        transmittance.
    owner : numpy.ndarray
        (n,) the shape number a fragment carries.
    count : int
        Fragments already written [count].

    Returns
    -------
    int
        The new count of fragments [count].
    """
    samples = (np.empty(1024, np.float32), np.empty(1024, np.float32), np.empty(1024, np.float32))
    for ii in range(index.shape[0]):
        i, bx, by, w, h, k, thick, rx, ry, samples = _next_box(ii, center, half, index, feature, thickness,
                                                               most, transmittance, samples)
        if w == 0:
            continue
        dxs, dys, buf = samples
        kf = np.float32(k)
        m = _samples(rx, ry, w, h, k, dxs, dys)
        if capsule:
            _capsule_cover(prm[i], m, dxs, dys, kf, thick, buf)
        else:
            _ellipse_cover(prm[i], m, dxs, dys, kf, thick, buf)
        _sum_samples(buf, w * h, k)
        if capsule:
            _clear_outside_stretch(prm[i], w, h, rx, ry, buf)
        count = _deposit(buf, w, h, k, bx, by, transmittance, fragments, owner[i], count)
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def _ellipse_cover(prm, m, dxs, dys, kf, thick, buf):
    """The coverage of the first ``m`` sub-samples (dxs, dys) by the ellipse ``prm`` (4,), into ``buf``."""
    ex, ey, major, minor = prm[0], prm[1], prm[2], prm[3]
    ab, bb, aa = major * minor, minor * minor, major * major
    eps, eps2 = np.float32(1e-3) * minor, np.float32(1e-3) * bb
    for j in range(m):
        dx, dy = dxs[j], dys[j]
        p = dx * ex + dy * ey
        q = dy * ex - dx * ey
        bp = bb * p
        aq = aa * q
        mp = minor * p
        mq = major * q
        gauge = np.sqrt(mp * mp + mq * mq)
        inv = np.float32(1.0) / (np.sqrt(bp * bp + aq * aq) + eps2)
        d = (gauge - ab) * (gauge + eps) * inv
        buf[j] = _cover(d, (bp * ex - aq * ey) * inv, (bp * ey + aq * ex) * inv, kf, thick)


@njit(cache=True, nogil=True, error_model="numpy")
def _capsule_cover(prm, m, dxs, dys, kf, thick, buf):
    """The coverage of the first ``m`` sub-samples (dxs, dys) by the capsule piece ``prm`` (8,), into ``buf``."""
    x0, y0, ex, ey, inverse, radius = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5]
    for j in range(m):
        px, py = dxs[j] - x0, dys[j] - y0
        t = min(max((px * ex + py * ey) * inverse, np.float32(0.0)), np.float32(1.0))
        qx, qy = px - t * ex, py - t * ey
        length = np.sqrt(qx * qx + qy * qy) + np.float32(1e-6)
        inv = np.float32(1.0) / length
        buf[j] = _cover(length - radius, qx * inv, qy * inv, kf, thick)


@njit(cache=True, nogil=True, error_model="numpy")
def _clear_outside_stretch(prm, w, h, rx, ry, buf):
    """Clears the coverage of the box's pixels outside the capsule piece's stretch [t_lo, t_hi) of its axis,
    judged at the pixels' centres in float64 (the pieces of one capsule tile its axis)."""
    x0, y0, ex, ey, inverse, t_lo, t_hi = prm[0], prm[1], prm[2], prm[3], prm[4], prm[6], prm[7]
    for r in range(h):
        cy = float(r) + 0.5 - float(ry) - float(y0)
        for c in range(w):
            cx = float(c) + 0.5 - float(rx) - float(x0)
            t = (cx * float(ex) + cy * float(ey)) * float(inverse)
            if not (t >= float(t_lo) and t < float(t_hi)):
                buf[r * w + c] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def _turn(v, k, c, s, out):
    """Rodrigues: ``v`` (3,) turned about the unit axis ``k`` (3,) by the angle of cosine c and
    sine s, into ``out`` (3,)."""
    dot = (k[0] * v[0] + k[1] * v[1] + k[2] * v[2]) * (1 - c)
    x = v[0] * c + (k[1] * v[2] - k[2] * v[1]) * s + k[0] * dot
    y = v[1] * c + (k[2] * v[0] - k[0] * v[2]) * s + k[1] * dot
    z = v[2] * c + (k[0] * v[1] - k[1] * v[0]) * s + k[2] * dot
    out[0], out[1], out[2] = x, y, z


@njit(cache=True, nogil=True, error_model="numpy")
def flutter(center: np.ndarray, axis_u: np.ndarray, axis_v: np.ndarray, pivot: np.ndarray, swing_axis: np.ndarray,
            swing_phase: np.ndarray, twist_phase: np.ndarray, omega: float, swing: float,
            twist: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """grove.leaves_at in one pass over the leaves.

    Parameters
    ----------
    center, axis_u, axis_v : numpy.ndarray
        (n, 3) float64 rest pose of the leaves [m].
    pivot : numpy.ndarray
        (n, 3) stem ends [m].
    swing_axis : numpy.ndarray
        (n, 3) horizontal unit vectors [1].
    swing_phase, twist_phase : numpy.ndarray
        (n,) [rad].
    omega : float
        2 pi frame / cycle, the frame reduced modulo the cycle [rad].
    swing, twist : float
        Amplitudes [rad].

    Returns
    -------
    center, axis_u, axis_v : numpy.ndarray
        (n, 3) float64 [m].
    """
    n = center.shape[0]
    c_out, u_out, v_out = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    length, turned, rel = np.empty(3), np.empty(3), np.empty(3)
    for i in range(n):
        norm = math.sqrt(axis_u[i, 0] ** 2 + axis_u[i, 1] ** 2 + axis_u[i, 2] ** 2)
        for d in range(3):
            length[d] = axis_u[i, d] / norm
        angle = twist * math.sin(omega + twist_phase[i])
        _turn(axis_v[i], length, math.cos(angle), math.sin(angle), turned)
        angle = swing * math.sin(omega + swing_phase[i])
        c, s = math.cos(angle), math.sin(angle)
        for d in range(3):
            rel[d] = center[i, d] - pivot[i, d]
        _turn(rel, swing_axis[i], c, s, c_out[i])
        for d in range(3):
            c_out[i, d] += pivot[i, d]
        _turn(axis_u[i], swing_axis[i], c, s, u_out[i])
        _turn(turned, swing_axis[i], c, s, v_out[i])
    return c_out, u_out, v_out


@njit(cache=True, nogil=True, error_model="numpy")
def onto(points: np.ndarray, sx: float, sy: float, offset: float) -> np.ndarray:
    """grove.project's map of ``points`` along the sun onto the plane z = offset, in one pass.

    numpy's operations, in order.

    Parameters
    ----------
    points : numpy.ndarray
        (n, 3) float64 [m].
    sx, sy : float
        The sun's sky-plane point [tan].
    offset : float
        Height of the plane [m].

    Returns
    -------
    numpy.ndarray
        (n, 2) float64 [m].
    """
    out = np.empty((points.shape[0], 2))
    for i in range(points.shape[0]):
        z = points[i, 2] - offset
        out[i, 0] = points[i, 0] - z * sx
        out[i, 1] = points[i, 1] - z * sy
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def ellipse_params(center: np.ndarray, axis_a: np.ndarray, axis_b: np.ndarray, origin_x: float, origin_y: float,
                   pixel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """rasteriser._ellipses in one pass: ellipses in the pixel units of a grid.

    Parameters
    ----------
    center : numpy.ndarray
        (n, 2) centres [m].
    axis_a, axis_b : numpy.ndarray
        (n, 2) conjugate semi-axes [m].
    origin_x, origin_y : float
        The grid's north-west corner [m].
    pixel : float
        The grid's pixel [m].

    Returns
    -------
    tuple of numpy.ndarray
        (centre (n, 2), box half-size (n, 2), (major unit vector, A, max(B, 1e-4)) (n, 4), B (n,),
        2 B (n,)) [pixel].
    """
    n = center.shape[0]
    c_px, half, prm = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 4))
    minor_out, thick = np.empty(n), np.empty(n)
    for i in range(n):
        a0, a1 = axis_a[i, 0] / pixel, -axis_a[i, 1] / pixel
        b0, b1 = axis_b[i, 0] / pixel, -axis_b[i, 1] / pixel
        p, s = a0 * a0 + b0 * b0, a1 * a1 + b1 * b1
        q = a0 * a1 + b0 * b1
        major = math.sqrt(0.5 * (p + s) + math.hypot(0.5 * (p - s), q))
        minor = abs(a0 * b1 - a1 * b0) / max(major, 1e-30)
        angle = 0.5 * math.atan2(2 * q, p - s)
        c_px[i, 0] = (center[i, 0] - origin_x) / pixel
        c_px[i, 1] = (origin_y - center[i, 1]) / pixel
        half[i, 0], half[i, 1] = math.sqrt(p), math.sqrt(s)
        prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3] = math.cos(angle), math.sin(angle), major, max(minor, 1e-4)
        minor_out[i], thick[i] = minor, 2 * minor
    return c_px, half, prm, minor_out, thick


@njit(cache=True, nogil=True)
def leaf_fragments(flat: np.ndarray, shape: np.ndarray, leaves: int, cols: int, rows: int, focal: float,
                   n_forward: np.ndarray, n_right: np.ndarray, n_up: np.ndarray, n_rel: np.ndarray,
                   nearest: np.ndarray, farthest: np.ndarray, leaf_sky: np.ndarray, leaf_sun: np.ndarray,
                   frag_depth: np.ndarray, frag_sun: np.ndarray, frag_sky: np.ndarray) -> None:
    """``trees.tree_passes``'s leaf fragments (those whose ``shape`` is under ``leaves``).

    Fragment by fragment with the float64 operations of its array version in their order: the depth
    where the pixel's ray meets the leaf's plane, ``n_rel / (n . ray)`` with n . ray kept from 0
    (1e-12), clamped to [nearest, farthest] of the leaf; the leaf's sun and sky light.

    Parameters
    ----------
    flat : numpy.ndarray
        (n,) pixel index (row cols + col).
    shape : numpy.ndarray
        (n,) shape number of each fragment.
    leaves : int
        Shapes under this are leaves [count].
    cols, rows : int
        The image's size [pixel].
    focal : float
        Focal length [pixel].
    n_forward, n_right, n_up : numpy.ndarray
        Per shape, the leaf normal's components along the camera's forward, right and up [1].
    n_rel : numpy.ndarray
        Per shape, the leaf normal's component along the leaf from the pinhole [m].
    nearest, farthest : numpy.ndarray
        Per shape, the depth range of the leaf [m].
    leaf_sky, leaf_sun : numpy.ndarray
        Per shape, (shapes, 3) the leaf's sky and sun light.
    frag_depth : numpy.ndarray
        (n,) output depth [m].
    frag_sun, frag_sky : numpy.ndarray
        (n, 3) output light (sun: sky plus sun), in the units of ``leaf_sky``.
    """
    half_cols, half_rows = 0.5 * cols, 0.5 * rows
    for f in range(flat.shape[0]):
        s = shape[f]
        if s >= leaves:
            continue
        pu = flat[f] % cols + 0.5
        pv = flat[f] // cols + 0.5
        across = (n_forward[s] + ((pu - half_cols) / focal) * n_right[s]) + ((half_rows - pv) / focal) * n_up[s]
        hit = n_rel[s] / (across if abs(across) > 1e-12 else 1e-12)
        if hit == hit:  # np.clip: NaN stays
            hit = hit if hit > nearest[s] else nearest[s]
            hit = hit if hit < farthest[s] else farthest[s]
        frag_depth[f] = hit
        for c in range(3):
            frag_sun[f, c] = leaf_sky[s, c] + leaf_sun[s, c]
            frag_sky[f, c] = leaf_sky[s, c]


@njit(cache=True, nogil=True)
def scatter_light(flat: np.ndarray, weight: np.ndarray, frag_sun: np.ndarray, frag_sky: np.ndarray,
                  pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """``trees.tree_passes``'s sun and sky images: each fragment's light times its weight added to its pixel.

    Fragment after fragment from 0: the sums, in the order, of
    ``np.bincount(flat, weights=weight * light[:, c])`` per channel.

    Parameters
    ----------
    flat : numpy.ndarray
        (n,) pixel of each fragment.
    weight : numpy.ndarray
        (n,) weights [1].
    frag_sun, frag_sky : numpy.ndarray
        (n, 3) light of each fragment.
    pixels : int
        Pixels of the image [count].

    Returns
    -------
    sun, sky : numpy.ndarray
        (pixels, 3) float64, in the units of the fragments' light.
    """
    sun = np.zeros((pixels, 3))
    sky = np.zeros((pixels, 3))
    for f in range(flat.shape[0]):
        p, w = flat[f], weight[f]
        for c in range(3):
            sun[p, c] += w * frag_sun[f, c]
            sky[p, c] += w * frag_sky[f, c]
    return sun, sky


@njit(cache=True, nogil=True)
def leaf_heights(shape: np.ndarray, leaves: int, px: np.ndarray, py: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                 slope_x: np.ndarray, slope_y: np.ndarray, h_center: np.ndarray, reach: np.ndarray,
                 height: np.ndarray) -> None:
    """``trees._visibility``'s leaf fragments (those whose ``shape`` is under ``leaves``).

    The height towards the light of the leaf's plane over the fragment's point, its rise from the
    centre along the plane's slopes clamped to [-reach, reach] of the leaf, with the float64
    operations of the array version in their order, into ``height``.

    Parameters
    ----------
    shape : numpy.ndarray
        (n,) shape number of each fragment.
    leaves : int
        Shapes under this are leaves [count].
    px, py : numpy.ndarray
        (n,) the fragments' points [m].
    cx, cy : numpy.ndarray
        Per shape, the leaf's centre [m].
    slope_x, slope_y : numpy.ndarray
        Per shape, the slopes of the leaf's plane [1].
    h_center : numpy.ndarray
        Per shape, the height at the centre [m].
    reach : numpy.ndarray
        Per shape, the largest rise [m].
    height : numpy.ndarray
        (n,) output [m].
    """
    for f in range(shape.shape[0]):
        s = shape[f]
        if s >= leaves:
            continue
        rise = (px[f] - cx[s]) * slope_x[s] + (py[f] - cy[s]) * slope_y[s]
        if rise == rise:  # np.clip: NaN stays
            rise = rise if rise > -reach[s] else -reach[s]
            rise = rise if rise < reach[s] else reach[s]
        height[f] = h_center[s] + rise
