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

from pipeline.kernels import HELPER, LOOP

__all__ = [
    "box_pixels", "shapes", "flutter", "onto", "ellipse_params", "leaf_fragments",
    "scatter_light", "leaf_heights",
]


@njit(cache=True, nogil=True, **LOOP)
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


_OPAQUE = np.float32(1.0 - 2.0**-20)

# inline="always" (numba inlines before typing, which costs compile time) only on ``_box``,
# ``_row_tables`` (run when a box's width or k changes) and ``_pixel_cover`` (called, the fine
# mask's sums took a fifth more); LLVM inlines the small arithmetic helpers (_square_cdf, _cover,
# _turn) as fast. The helpers that each box runs on whole arrays are called: numba's inlining
# reference-counts their arrays, atomic increments and decrements at each box (docs/accuracy.md,
# "The leaf rasteriser").


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
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


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
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
def _row_tables(w, k, qx, qy):
    """One pixel row's sub-samples over a box w pixels wide, k x k per pixel, sub-sample by
    sub-sample: the (sy, sx)-th of every pixel, then the next. Their x from the box's left edge
    into qx (float32, as the array version computes them before it subtracts the centre: k is a
    power of two, so multiplying by 1 / k gives the bits of dividing by k) and their sub-row sy
    into qy (float32), then copies of the last up to a multiple of 8 (the vector loops then run no
    scalar remainder); returns that multiple, the row's stride in the coverage buffer."""
    step = np.float32(1.0) / np.float32(k)
    t = 0
    for sy in range(k):
        for sx in range(k):
            for c in range(w):
                qx[t] = (np.float32(c * k + sx) + np.float32(0.5)) * step
                qy[t] = np.float32(sy)
                t += 1
    stride = (t + 7) // 8 * 8
    for j in range(t, stride):
        qx[j], qy[j] = qx[t - 1], qy[t - 1]
    return stride


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _pixel_cover(buf, base, w, k):
    """The coverage of the pixel whose first sub-sample is buf[base] (``_row_tables``' order): its
    k x k sub-samples summed in the order (sy, sx) of the array version, divided by k k (a power of
    two: the bits of dividing). k is spelled out so that each sum has a fixed length."""
    total = buf[base]
    if k == 4:
        for s in range(1, 16):
            total += buf[base + s * w]
        return total * np.float32(1.0 / 16.0)
    if k == 2:
        for s in range(1, 4):
            total += buf[base + s * w]
        return total * np.float32(0.25)
    return total


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _multiply(buf, w, h, k, stride, x0, y0, transmittance):
    """transmittance[row, col] of the w x h box at (x0, y0) multiplied by 1 - cover, cover each
    pixel's ``_pixel_cover`` (row r's sub-samples from buf[r stride]) clipped just below 1, where
    cover > 0 (elsewhere by 1.0, which keeps every value's bits: no branch in the loop)."""
    for r in range(h):
        for c in range(w):
            cover = _pixel_cover(buf, r * stride + c, w, k)
            transmittance[y0 + r, x0 + c] *= 1.0 - float(min(cover, _OPAQUE)) if cover > 0 else 1.0


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _emit(buf, w, h, k, stride, x0, y0, cols, pixel, coverage, source, shape, count):
    """The coverages of ``_multiply``'s pixels where cover > 0 as fragments (flat pixel, coverage
    clipped just below 1, ``shape``) appended at ``count``, row by row; returns the new count."""
    for r in range(h):
        for c in range(w):
            cover = _pixel_cover(buf, r * stride + c, w, k)
            if cover > 0:
                pixel[count] = (y0 + r) * cols + x0 + c
                coverage[count] = min(cover, _OPAQUE)
                source[count] = shape
                count += 1
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
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
    rows, cols = transmittance.shape
    qx, qy = np.empty(16 * cols + 8, np.float32), np.empty(16 * cols + 8, np.float32)
    buf = np.empty(1024, np.float32)
    pixel, coverage, source = fragments
    stride, table_k, table_w = 0, 0, 0
    for ii in range(index.shape[0]):
        i, cx, cy = index[ii], center[ii, 0], center[ii, 1]
        bx, by, w, h, k, thick = _box(cx, cy, half[i, 0], half[i, 1], feature[i], thickness[i], rows, cols, most)
        if w == 0:
            continue
        if k != table_k or w != table_w:  # the tables depend on k and w alone
            stride, table_k, table_w = _row_tables(w, k, qx, qy), k, w
        if stride * h > buf.shape[0]:
            buf = np.empty(2 * stride * h, np.float32)
        rx, ry = np.float32(cx - bx), np.float32(cy - by)
        if capsule:
            _capsule_box(prm, i, h, k, thick, qx, qy, stride, rx, ry, buf)
            _clear_outside_stretch(prm, i, w, h, k, stride, rx, ry, buf)
        else:
            _ellipse_box(prm, i, h, k, thick, qx, qy, stride, rx, ry, buf)
        if pixel.shape[0]:
            count = _emit(buf, w, h, k, stride, bx, by, cols, pixel, coverage, source, owner[i], count)
        else:
            _multiply(buf, w, h, k, stride, bx, by, transmittance)
    return count


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _ellipse_box(prm, i, h, k, thick, qx, qy, stride, rx, ry, buf):
    """The coverage by the ellipse prm[i] (the major unit vector, A, B) of the sub-samples of a box's
    h pixel rows, row r's (``_row_tables``' qx, qy, offsets from the centre (rx, ry) [pixel]) into
    buf[r stride:]."""
    ex, ey, major, minor = prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3]
    ab, bb, aa = major * minor, minor * minor, major * major
    eps, eps2 = np.float32(1e-3) * minor, np.float32(1e-3) * bb
    kf, step = np.float32(k), np.float32(1.0) / np.float32(k)
    for r in range(h):
        row = np.float32(r * k)  # + sy: the sub-row's index, exactly
        for j in range(stride):
            dx, dy = qx[j] - rx, ((row + qy[j]) + np.float32(0.5)) * step - ry
            p = dx * ex + dy * ey
            q = dy * ex - dx * ey
            bp = bb * p
            aq = aa * q
            mp = minor * p
            mq = major * q
            gauge = np.sqrt(mp * mp + mq * mq)
            inv = np.float32(1.0) / (np.sqrt(bp * bp + aq * aq) + eps2)
            d = (gauge - ab) * (gauge + eps) * inv
            buf[r * stride + j] = _cover(d, (bp * ex - aq * ey) * inv, (bp * ey + aq * ex) * inv, kf, thick)


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _capsule_box(prm, i, h, k, thick, qx, qy, stride, rx, ry, buf):
    """The coverage by the capsule piece prm[i] of the sub-samples of a box's h pixel rows, as
    ``_ellipse_box``."""
    x0, y0, ex, ey, inverse, radius = prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3], prm[i, 4], prm[i, 5]
    kf, step = np.float32(k), np.float32(1.0) / np.float32(k)
    for r in range(h):
        row = np.float32(r * k)
        for j in range(stride):
            px, py = (qx[j] - rx) - x0, (((row + qy[j]) + np.float32(0.5)) * step - ry) - y0
            t = min(max((px * ex + py * ey) * inverse, np.float32(0.0)), np.float32(1.0))
            nx, ny = px - t * ex, py - t * ey
            length = np.sqrt(nx * nx + ny * ny) + np.float32(1e-6)
            inv = np.float32(1.0) / length
            buf[r * stride + j] = _cover(length - radius, nx * inv, ny * inv, kf, thick)


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _clear_outside_stretch(prm, i, w, h, k, stride, rx, ry, buf):
    """Clears the sub-samples of the box's pixels outside the capsule piece's stretch [t_lo, t_hi) of its
    axis, judged at the pixels' centres in float64 (the pieces of one capsule tile its axis): their
    sum is then 0, as the array version's."""
    x0, y0, ex, ey, inverse, t_lo, t_hi = prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3], prm[i, 4], prm[i, 6], prm[i, 7]
    for r in range(h):
        cy = float(r) + 0.5 - float(ry) - float(y0)
        for c in range(w):
            cx = float(c) + 0.5 - float(rx) - float(x0)
            t = (cx * float(ex) + cy * float(ey)) * float(inverse)
            if not (t >= float(t_lo) and t < float(t_hi)):
                for s in range(k * k):
                    buf[r * stride + s * w + c] = 0.0


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _turn(v0, v1, v2, k0, k1, k2, c, s):
    """Rodrigues: (v0, v1, v2) turned about the unit axis (k0, k1, k2) by the angle of cosine c and
    sine s."""
    dot = (k0 * v0 + k1 * v1 + k2 * v2) * (1 - c)
    return (v0 * c + (k1 * v2 - k2 * v1) * s + k0 * dot, v1 * c + (k2 * v0 - k0 * v2) * s + k1 * dot,
            v2 * c + (k0 * v1 - k1 * v0) * s + k2 * dot)


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
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
    for i in range(n):
        u0, u1, u2 = axis_u[i, 0], axis_u[i, 1], axis_u[i, 2]
        norm = math.sqrt(u0 ** 2 + u1 ** 2 + u2 ** 2)
        angle = twist * math.sin(omega + twist_phase[i])
        t0, t1, t2 = _turn(axis_v[i, 0], axis_v[i, 1], axis_v[i, 2], u0 / norm, u1 / norm, u2 / norm,
                           math.cos(angle), math.sin(angle))
        angle = swing * math.sin(omega + swing_phase[i])
        c, s = math.cos(angle), math.sin(angle)
        a0, a1, a2 = swing_axis[i, 0], swing_axis[i, 1], swing_axis[i, 2]
        p0, p1, p2 = pivot[i, 0], pivot[i, 1], pivot[i, 2]
        x, y, z = _turn(center[i, 0] - p0, center[i, 1] - p1, center[i, 2] - p2, a0, a1, a2, c, s)
        c_out[i, 0], c_out[i, 1], c_out[i, 2] = x + p0, y + p1, z + p2
        u_out[i, 0], u_out[i, 1], u_out[i, 2] = _turn(u0, u1, u2, a0, a1, a2, c, s)
        v_out[i, 0], v_out[i, 1], v_out[i, 2] = _turn(t0, t1, t2, a0, a1, a2, c, s)
    return c_out, u_out, v_out


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def ellipse_params(order: np.ndarray, center: np.ndarray, axis_a: np.ndarray, axis_b: np.ndarray, origin_x: float,
                   origin_y: float, pixel: float, rows: float, cols: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """rasteriser._ellipses in one pass: ellipses in the pixel units of a grid, in the order ``order``.

    Parameters
    ----------
    order : numpy.ndarray
        (m,) the ellipses to take, in their order (each read at random once, its outputs written one
        after another).
    center : numpy.ndarray
        (n, 2) centres [m].
    axis_a, axis_b : numpy.ndarray
        (n, 2) conjugate semi-axes [m].
    origin_x, origin_y : float
        The grid's north-west corner [m].
    pixel : float
        The grid's pixel [m].
    rows, cols : float
        The raster drawn [pixel]: an ellipse whose box lies wholly outside it (the box that ``shapes``
        then skips) gets its centre and half-size only, the rest 0; rows 0 for every ellipse whole.

    Returns
    -------
    tuple of numpy.ndarray
        (centre (m, 2), box half-size (m, 2), (major unit vector, A, max(B, 1e-4)) (m, 4), B (m,),
        2 B (m,)) [pixel], the ii-th of ellipse order[ii].
    """
    n = order.shape[0]
    c_px, half, prm = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 4))
    minor_out, thick = np.empty(n), np.empty(n)
    read = np.empty((256, 6))  # a block's inputs, read first in a tight loop: its misses then overlap
    for ii in range(n):
        j = ii % 256
        if j == 0:
            for jj in range(min(256, n - ii)):
                i = order[ii + jj]
                read[jj, 0], read[jj, 1], read[jj, 2] = center[i, 0], center[i, 1], axis_a[i, 0]
                read[jj, 3], read[jj, 4], read[jj, 5] = axis_a[i, 1], axis_b[i, 0], axis_b[i, 1]
        a0, a1 = read[j, 2] / pixel, -read[j, 3] / pixel
        b0, b1 = read[j, 4] / pixel, -read[j, 5] / pixel
        p, s = a0 * a0 + b0 * b0, a1 * a1 + b1 * b1
        cx, cy, hx, hy = (read[j, 0] - origin_x) / pixel, (origin_y - read[j, 1]) / pixel, math.sqrt(p), math.sqrt(s)
        c_px[ii, 0], c_px[ii, 1], half[ii, 0], half[ii, 1] = cx, cy, hx, hy
        if rows > 0 and (cx + hx <= 0 or cx - hx >= cols or cy + hy <= 0 or cy - hy >= rows):  # _box: w or h 0
            prm[ii, 0], prm[ii, 1], prm[ii, 2], prm[ii, 3], minor_out[ii], thick[ii] = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            continue
        q = a0 * a1 + b0 * b1
        major = math.sqrt(0.5 * (p + s) + math.hypot(0.5 * (p - s), q))
        minor = abs(a0 * b1 - a1 * b0) / max(major, 1e-30)
        angle = 0.5 * math.atan2(2 * q, p - s)
        prm[ii, 0], prm[ii, 1], prm[ii, 2], prm[ii, 3] = math.cos(angle), math.sin(angle), major, max(minor, 1e-4)
        minor_out[ii], thick[ii] = minor, 2 * minor
    return c_px, half, prm, minor_out, thick


@njit(cache=True, nogil=True, **LOOP)
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


@njit(cache=True, nogil=True, **LOOP)
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


@njit(cache=True, nogil=True, **LOOP)
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
