"""Compiled loops of the mesh coverage (``canopy.mesh_coverage``): triangles drawn exactly into a transmittance mask.

Each triangle, projected onto the canopy plane in pixel units, is clipped against every pixel square
it touches (Sutherland-Hodgman: a row's strip, then each pixel of it); the clipped polygon's area
times the mean of its material's coverage table over the polygon's image in texture space is its
coverage. The mean is exact for the table taken as constant over each of its texels: by Green's
theorem the integral over the polygon is the line integral of the table's row prefix sums along its
boundary, walked texel by texel (docs/method.md, "Trees from mesh files"). Triangles of one group (a
leaf, a piece of wood) add their coverages in a pixel; groups combine as ``prod (1 - c)``, the
procedural leaves' contract. Imported lazily: numba costs 0.3 s to import.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["mesh_transmittance", "triangle_alpha"]

_OPAQUE = 1.0 - 2.0**-20  # a group's coverage clipped just below 1, as kernels/raster.py clips a leaf's
_MAX_VERTICES = 16  # a triangle clipped by four lines has at most 7 corners


@njit(cache=True, nogil=True, error_model="numpy")
def _clip(xs, ys, n, axis, value, keep_above, out_x, out_y):
    """The polygon (xs, ys)[:n] clipped to the half-plane coordinate ``axis`` (0: x, 1: y) >= value
    (``keep_above``) or <= value; written to out_x, out_y; returns its corner count."""
    m = 0
    for i in range(n):
        j = (i + 1) % n
        a = (xs[i] if axis == 0 else ys[i]) - value
        b = (xs[j] if axis == 0 else ys[j]) - value
        if not keep_above:
            a, b = -a, -b
        if a >= 0:
            out_x[m], out_y[m] = xs[i], ys[i]
            m += 1
        if (a >= 0) != (b >= 0):
            t = a / (a - b)
            out_x[m], out_y[m] = xs[i] + t * (xs[j] - xs[i]), ys[i] + t * (ys[j] - ys[i])
            m += 1
    return m


@njit(cache=True, nogil=True, error_model="numpy")
def _signed_area(xs, ys, n):
    """The shoelace area of the polygon (xs, ys)[:n], positive anticlockwise in (x, y)."""
    total = 0.0
    for i in range(n):
        j = (i + 1) % n
        total += xs[i] * ys[j] - xs[j] * ys[i]
    return 0.5 * total


@njit(cache=True, nogil=True, error_model="numpy")
def _prefix(prefix, base, width, height, row, u):
    """The integral of the table's row ``row`` from 0 to u, the table repeating (rows and columns) [texel]:
    its prefix sums (row-major, width + 1 a row, from ``base``) read linearly."""
    start = base + (row % height) * (width + 1)
    periods = math.floor(u / width)
    rest = u - periods * width
    i = min(int(rest), width - 1)
    return (periods * prefix[start + width] + prefix[start + i]
            + (rest - i) * (prefix[start + i + 1] - prefix[start + i]))


@njit(cache=True, nogil=True, error_model="numpy")
def _prefix_within(prefix, base, width, row, u):
    """``_prefix`` for 0 <= u <= width and 0 <= row < height: no period to take off."""
    start = base + row * (width + 1)
    i = min(int(u), width - 1)
    return prefix[start + i] + (u - i) * (prefix[start + i + 1] - prefix[start + i])


@njit(cache=True, nogil=True, error_model="numpy")
def _edge_integral(u0, r0, u1, r1, within, prefix, base, width, height):
    """The line integral of G(u, r) dr along the edge (u0, r0) -> (u1, r1), G the row prefix integral,
    the edge walked piece by piece between texel lines (exact: G is linear in u within a texel and
    constant in r within a row); ``within``: the edge lies in the table's first period."""
    dr = r1 - r0
    if dr == 0.0:
        return 0.0
    du = u1 - u0
    inf = np.inf
    if du > 0:
        step_u = 1.0 / du
        next_u = (math.floor(u0) + 1.0 - u0) * step_u
    elif du < 0:
        step_u = -1.0 / du
        next_u = (u0 - (math.ceil(u0) - 1.0)) * step_u
    else:
        step_u, next_u = inf, inf
    step_r = 1.0 / abs(dr)
    next_r = ((math.floor(r0) + 1.0 - r0) if dr > 0 else (r0 - (math.ceil(r0) - 1.0))) * step_r
    total, t = 0.0, 0.0
    while True:
        t_next = min(next_u, next_r, 1.0)
        if t_next > t:
            mid = 0.5 * (t + t_next)
            u, row = u0 + du * mid, int(math.floor(r0 + dr * mid))
            if within:
                total += (t_next - t) * _prefix_within(prefix, base, width, row, u)
            else:
                total += (t_next - t) * _prefix(prefix, base, width, height, row, u)
        if t_next >= 1.0:
            break
        t = t_next
        if next_u <= t_next:
            next_u += step_u
        if next_r <= t_next:
            next_r += step_r
    return total * dr


@njit(cache=True, nogil=True, error_model="numpy")
def _mean_over(us, rs, n, prefix, base, width, height):
    """The mean of the table over the polygon (us, rs)[:n] in its texel units: the polygon moved by whole
    periods to start in the first; where it has no area, its centroid's texel; where the texels of its
    bounding box are all 0 or all 1, that; else the line integral over its area."""
    u_lo, u_hi, r_lo, r_hi = us[0], us[0], rs[0], rs[0]
    for i in range(1, n):
        u_lo, u_hi, r_lo, r_hi = min(u_lo, us[i]), max(u_hi, us[i]), min(r_lo, rs[i]), max(r_hi, rs[i])
    shift_u, shift_r = width * math.floor(u_lo / width), height * math.floor(r_lo / height)
    for i in range(n):
        us[i] -= shift_u
        rs[i] -= shift_r
    u_lo, u_hi, r_lo, r_hi = u_lo - shift_u, u_hi - shift_u, r_lo - shift_r, r_hi - shift_r
    area = _signed_area(us, rs, n)
    if abs(area) < 1e-12:
        u, r = 0.0, 0.0
        for i in range(n):
            u += us[i] / n
            r += rs[i] / n
        row = int(math.floor(r))
        return _prefix(prefix, base, width, height, row, math.floor(u) + 1.0) - \
            _prefix(prefix, base, width, height, row, math.floor(u))
    within = u_hi <= width and r_hi <= height
    if within:  # the texels of the bounding box all 0 or all 1: no walk
        first, last = int(u_lo), min(int(math.ceil(u_hi)), width)
        total = 0.0
        for row in range(int(r_lo), min(int(math.ceil(r_hi)), height)):
            start = base + row * (width + 1)
            total += prefix[start + last] - prefix[start + first]
        if total == 0.0:
            return 0.0
        if total == (last - first) * (min(int(math.ceil(r_hi)), height) - int(r_lo)):
            return 1.0
    total = 0.0
    for i in range(n):
        j = (i + 1) % n
        total += _edge_integral(us[i], rs[i], us[j], rs[j], within, prefix, base, width, height)
    return min(max(total / area, 0.0), 1.0)


@njit(cache=True, nogil=True, error_model="numpy")
def _level(corners, texels, t, levels, width0, height0, texels_per_pixel):
    """The table level whose texels are about 1 / texels_per_pixel of a pixel under triangle t."""
    x, y, u, r = corners[t, :, 0], corners[t, :, 1], texels[t, :, 0] * width0, texels[t, :, 1] * height0
    plane = abs((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]))
    texture = abs((u[1] - u[0]) * (r[2] - r[0]) - (u[2] - u[0]) * (r[1] - r[0]))
    ratio = math.sqrt(texture / max(plane, 1e-300)) / texels_per_pixel
    return 0 if ratio <= 1.0 else min(int(math.floor(math.log2(ratio))), levels - 1)


@njit(cache=True, nogil=True, error_model="numpy")
def _triangle(corners, texels, t, m, level, prefix, level_base, level_size, acc, touched, count, rows, cols, buf):
    """Triangle t's coverage of each pixel, added to acc (flat), new pixels appended to touched; returns
    the count."""
    x, y = corners[t, :, 0], corners[t, :, 1]
    ex1, ey1, ex2, ey2 = x[1] - x[0], y[1] - y[0], x[2] - x[0], y[2] - y[0]
    det = ex1 * ey2 - ex2 * ey1
    if abs(det) < 1e-12:
        return count
    base, width, height = level_base[m, level], level_size[m, level, 0], level_size[m, level, 1]
    constant = width == 1 and height == 1
    # texture coordinates [texel of the level] as an affine function of the plane's [pixel]
    tu, tr = texels[t, :, 0] * width, texels[t, :, 1] * height
    a_u = ((tu[1] - tu[0]) * ey2 - (tu[2] - tu[0]) * ey1) / det
    b_u = ((tu[2] - tu[0]) * ex1 - (tu[1] - tu[0]) * ex2) / det
    a_r = ((tr[1] - tr[0]) * ey2 - (tr[2] - tr[0]) * ey1) / det
    b_r = ((tr[2] - tr[0]) * ex1 - (tr[1] - tr[0]) * ex2) / det
    sx, sy, px, py, qx, qy, us, rs = buf
    for k in range(3):
        px[k], py[k] = x[k], y[k]
    r_lo, r_hi = max(int(math.floor(min(y[0], y[1], y[2]))), 0), min(int(math.ceil(max(y[0], y[1], y[2]))), rows)
    for row in range(r_lo, r_hi):
        n = _clip(px, py, 3, 1, float(row), True, qx, qy)
        n = _clip(qx, qy, n, 1, float(row + 1), False, sx, sy)
        if n < 3:
            continue
        x_lo, x_hi = sx[0], sx[0]
        for i in range(1, n):
            x_lo, x_hi = min(x_lo, sx[i]), max(x_hi, sx[i])
        for col in range(max(int(math.floor(x_lo)), 0), min(int(math.ceil(x_hi)), cols)):
            k = _clip(sx, sy, n, 0, float(col), True, qx, qy)
            k = _clip(qx, qy, k, 0, float(col + 1), False, us, rs)
            if k < 3:
                continue
            area = abs(_signed_area(us, rs, k))
            if area <= 0.0:
                continue
            if constant:
                mean = prefix[base + 1]
            else:
                for i in range(k):
                    dx, dy = us[i] - x[0], rs[i] - y[0]
                    us[i], rs[i] = tu[0] + a_u * dx + b_u * dy, tr[0] + a_r * dx + b_r * dy
                mean = _mean_over(us, rs, k, prefix, base, width, height)
            cover = area * mean
            if cover > 0.0:
                p = row * cols + col
                if acc[p] == 0.0:
                    touched[count] = p
                    count += 1
                acc[p] += cover
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def mesh_transmittance(corners: np.ndarray, texels: np.ndarray, material: np.ndarray, group_start: np.ndarray,
                       prefix: np.ndarray, level_base: np.ndarray, level_size: np.ndarray, levels: np.ndarray,
                       texels_per_pixel: float, transmittance: np.ndarray) -> None:
    """Triangles drawn into a transmittance raster by their exact coverage, group by group.

    Parameters
    ----------
    corners : numpy.ndarray
        (m, 3, 2) float64 corners on the raster: x along columns, y along rows; pixel (row, col) is
        [col, col + 1) x [row, row + 1) [pixel].
    texels : numpy.ndarray
        (m, 3, 2) float64 texture coordinates as fractions of the table: (u, 1 - v) [1].
    material : numpy.ndarray
        (m,) int64 material of each triangle.
    group_start : numpy.ndarray
        (g + 1,) int64: group i is triangles group_start[i] .. group_start[i + 1] - 1.
    prefix : numpy.ndarray
        Flat float64 row prefix sums of every material's tables, (height, width + 1) each [texel].
    level_base : numpy.ndarray
        (materials, L) int64: where each level's prefix sums start.
    level_size : numpy.ndarray
        (materials, L, 2) int64: each level's (width, height) [texel].
    levels : numpy.ndarray
        (materials,) int64: the levels each material has.
    texels_per_pixel : float
        The finest level whose texel spans at most 1 / texels_per_pixel of a pixel is read [1].
    transmittance : numpy.ndarray
        (rows, cols) float64, multiplied in place by 1 - each group's coverage [1].
    """
    rows, cols = transmittance.shape
    flat = transmittance.reshape(-1)
    acc = np.zeros(rows * cols)
    touched = np.empty(rows * cols, np.int64)
    buf = (np.empty(_MAX_VERTICES), np.empty(_MAX_VERTICES), np.empty(_MAX_VERTICES), np.empty(_MAX_VERTICES),
           np.empty(_MAX_VERTICES), np.empty(_MAX_VERTICES), np.empty(_MAX_VERTICES), np.empty(_MAX_VERTICES))
    for g in range(group_start.shape[0] - 1):
        count = 0
        for t in range(group_start[g], group_start[g + 1]):
            m = material[t]
            level = _level(corners, texels, t, levels[m], level_size[m, 0, 0], level_size[m, 0, 1], texels_per_pixel)
            count = _triangle(corners, texels, t, m, level, prefix, level_base, level_size, acc, touched, count,
                              rows, cols, buf)
        for i in range(count):
            p = touched[i]
            flat[p] *= 1.0 - min(acc[p], _OPAQUE)
            acc[p] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def triangle_alpha(texels: np.ndarray, material: np.ndarray, prefix: np.ndarray, level_base: np.ndarray,
                   level_size: np.ndarray) -> np.ndarray:
    """The mean of each triangle's coverage table over the triangle in texture space (level 0).

    Parameters
    ----------
    texels, material, prefix, level_base, level_size
        As for ``mesh_transmittance``.

    Returns
    -------
    numpy.ndarray
        (m,) float64 in [0, 1] [1].
    """
    out = np.empty(texels.shape[0])
    us, rs = np.empty(3), np.empty(3)
    for t in range(texels.shape[0]):
        m = material[t]
        width, height = level_size[m, 0, 0], level_size[m, 0, 1]
        for k in range(3):
            us[k], rs[k] = texels[t, k, 0] * width, texels[t, k, 1] * height
        out[t] = _mean_over(us, rs, 3, prefix, level_base[m, 0], width, height)
    return out
