"""Compiled loops of the mesh coverage (``canopy.mesh_coverage``): triangles drawn exactly into a transmittance mask.

A triangle's coverage of a pixel is the integral, over their overlap, of its material's coverage
table (constant over each texel) mapped affinely onto the canopy plane. By Green's theorem it is the
line integral of the table's row prefix F (dF/du = the table) d(row) around the overlap's boundary,
and that boundary is made of two kinds of piece: the triangle's edges cut at the pixel lines, and the
pixel lines cut by the triangle (each shared by two pixels, counted once for each with opposite
signs). Each piece's integral is exact in closed form within a texel row (F is linear in u within a
texel; its own prefix H, quadratic, integrates it across texels), so a piece costs the texel rows it
crosses (docs/method.md, "Trees from mesh files"); a triangle whose pixel lines cross fewer texel columns
than rows walks the transposed table's rows, and an edge two triangles of a group share, where their
pieces on it cancel, is left out of both. Triangles of one group (a leaf, a piece of wood)
add their coverages in a pixel; groups combine as ``prod (1 - c)``, the procedural leaves' contract.
The pieces of a group's triangles are listed first, then integrated in one loop: arrays handed to a
compiled function per piece cost two atomic reference counts each, more than the piece's arithmetic.
Imported lazily: numba costs 0.3 s to import.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["mesh_transmittance", "triangle_alpha"]

_OPAQUE = 1.0 - 2.0**-20  # a group's coverage clipped just below 1, as kernels/raster.py clips a leaf's


_PARAMS = 14  # a triangle's parameters: affine map (6), weight, base, width, height, flags, period, outline loops
_PIECE = 7  # a piece's row: x0, y0, x1, y1 [pixel], the pixel it bounds positively, negatively (-1: none), triangle


@njit(cache=True, nogil=True, error_model="numpy")
def _integrate(pieces, count, params, prefix, double, acc):
    """Each listed piece's line integral times its triangle's weight, added to the pixel it bounds positively
    and taken from the one it bounds negatively: x dy for a constant triangle, else F dr along the piece's image
    in the texture, walked texel row by row (rows and columns repeating unless the triangle stays in the
    first period). Within a row F is linear in u on each texel: a shallow piece (|du| > |dr|) integrates by
    the difference of H (F's integral) times dr / du; a steep one crosses at most one texel line in a row,
    and F at the middle of each part is exact. One loop: arrays handed to a compiled function cost two
    atomic reference counts each, more than a piece's arithmetic."""
    for n in range(count):
        x0, y0, x1, y1, t = pieces[n, 0], pieces[n, 1], pieces[n, 2], pieces[n, 3], int(pieces[n, 6])
        flags, value = int(params[t, 10]), 0.0
        if flags & 1:
            value = 0.5 * (x0 + x1) * (y1 - y0)
        else:
            c0, c1, c2, c3, c4, c5 = params[t, 0], params[t, 1], params[t, 2], params[t, 3], params[t, 4], params[t, 5]
            u0, r0 = c0 + c1 * x0 + c2 * y0, c3 + c4 * x0 + c5 * y0
            u1, r1 = c0 + c1 * x1 + c2 * y1, c3 + c4 * x1 + c5 * y1
            base, width, height, within = int(params[t, 7]), int(params[t, 8]), int(params[t, 9]), flags & 2 != 0
            sign = 1.0
            if r1 < r0:
                u0, r0, u1, r1, sign = u1, r1, u0, r0, -1.0
            du, dr = u1 - u0, r1 - r0
            row, last = np.floor(r0), (np.ceil(r1) - 1.0 if r1 > r0 else np.floor(r0) - 1.0)
            shallow = abs(du) > dr
            run = du / dr if dr > 0.0 else 0.0
            ra, ua = r0, u0
            while row <= last:
                rb = r1 if row == last else row + 1.0
                ub = u1 if row == last else u0 + run * (rb - r0)
                k = min(max(int(row), 0), height - 1) if within else int(row) % height
                start = base + k * (width + 1)
                lo, hi = min(ua, ub), max(ua, ub)
                cut = min(np.floor(lo) + 1.0, hi)
                for part in range(2):  # shallow: H(ub), H(ua); steep: F over [lo, cut], [cut, hi]
                    a, b = (lo, cut) if part == 0 else (cut, hi)
                    if not shallow and b <= a and not (part == 0 and hi == lo):
                        continue
                    u = (ub if part == 0 else ua) if shallow else 0.5 * (a + b)
                    periods = 0.0 if within else np.floor(u / width)
                    rest = u - periods * width
                    i = min(max(int(rest), 0), width - 1)
                    x, low = rest - i, prefix[start + i]
                    slope = prefix[start + i + 1] - low
                    if shallow:
                        h = double[start + i] + x * (low + 0.5 * x * slope) + periods * (
                            double[start + width] + prefix[start + width] * (width * 0.5 * (periods - 1.0) + rest))
                        value += sign * (dr / du) * (h if part == 0 else -h)
                    else:
                        f = low + x * slope + periods * prefix[start + width]
                        value += sign * (rb - ra) * f * ((b - a) / (hi - lo) if hi > lo else 1.0)
                ra, ua = rb, ub
                row += 1.0
        value *= params[t, 6]
        plus, minus = int(pieces[n, 4]), int(pieces[n, 5])
        if plus >= 0:
            acc[plus] += value
        if minus >= 0:
            acc[minus] -= value


@njit(cache=True, nogil=True, error_model="numpy")
def _edge_pieces(x, y, t, skip, pieces, count, rows, cols):
    """The triangle's edges (anticlockwise) cut at the pixel lines, listed, but for those whose bit is set in
    ``skip`` (shared with a triangle of the group that cancels them); returns the count."""
    for e in range(3):
        ax, ay, bx, by = x[e], y[e], x[(e + 1) % 3], y[(e + 1) % 3]
        dx, dy = bx - ax, by - ay
        if skip & (1 << e) and not (dx == 0.0 and ax == np.floor(ax)) and not (dy == 0.0 and ay == np.floor(ay)):
            continue  # (along a pixel line each triangle's piece bounds the pixel on its own side)
        t_lo, t_hi = 0.0, 1.0  # the edge clipped to the raster
        for axis in range(2):
            a, d, n = (ax, dx, cols) if axis == 0 else (ay, dy, rows)
            if d == 0.0:
                if a < 0.0 or a > n:
                    t_hi = -1.0
            else:
                ta, tb = (0.0 - a) / d, (n - a) / d
                t_lo, t_hi = max(t_lo, min(ta, tb)), min(t_hi, max(ta, tb))
        if t_lo >= t_hi:
            continue
        px, py = ax + dx * t_lo, ay + dy * t_lo
        line_x = (np.floor(px) + 1.0 if dx > 0 else np.ceil(px) - 1.0) if dx != 0 else 0.0
        line_y = (np.floor(py) + 1.0 if dy > 0 else np.ceil(py) - 1.0) if dy != 0 else 0.0
        inv_x, inv_y = (1.0 / dx if dx != 0 else 0.0), (1.0 / dy if dy != 0 else 0.0)
        step_x, step_y = (1.0 if dx > 0 else -1.0), (1.0 if dy > 0 else -1.0)
        s = t_lo
        while s < t_hi:
            tx = (line_x - ax) * inv_x if dx != 0 else np.inf
            ty = (line_y - ay) * inv_y if dy != 0 else np.inf
            s_next = min(tx, ty, t_hi)
            if s_next > s:
                qx, qy = ax + dx * s_next, ay + dy * s_next
                mx, my = 0.5 * (px + qx), 0.5 * (py + qy)
                col, row = np.floor(mx), np.floor(my)
                if col == mx and dy > 0:  # along a pixel line: the pixel on the triangle's side (its left)
                    col -= 1.0
                if row == my and dx < 0:
                    row -= 1.0
                if 0 <= col < cols and 0 <= row < rows:
                    pieces[count, 0], pieces[count, 1], pieces[count, 2], pieces[count, 3] = px, py, qx, qy
                    pieces[count, 4], pieces[count, 5], pieces[count, 6] = row * cols + col, -1.0, t
                    count += 1
                px, py, s = qx, qy, s_next
            if tx <= s_next:
                line_x += step_x
            if ty <= s_next:
                line_y += step_y
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def _span(x, y, at, along_x):
    """The triangle's extent on the line x = at (``along_x`` False: its y range) or y = at (its x range)."""
    lo, hi = np.inf, -np.inf
    for e in range(3):
        a0, a1 = (y[e], y[(e + 1) % 3]) if along_x else (x[e], x[(e + 1) % 3])
        b0, b1 = (x[e], x[(e + 1) % 3]) if along_x else (y[e], y[(e + 1) % 3])
        if a0 != a1 and (a0 - at) * (a1 - at) <= 0.0:
            b = b0 + (b1 - b0) * ((at - a0) / (a1 - a0))
            lo, hi = min(lo, b), max(hi, b)
    return lo, hi


@njit(cache=True, nogil=True, error_model="numpy")
def _inner_pieces(x, y, t, constant, pieces, count, rows, cols):
    """The pixel lines through the triangle cut at the pixel lines across them, listed with the pixels on
    either side (x = line upwards: the left one's boundary, the right one's reversed; y = line towards +x:
    the one below's, the one above's reversed); returns the count. A constant triangle's horizontal
    pieces are left out (x dy is 0 along them)."""
    for vertical in (True, False):
        if constant and not vertical:
            break
        a0, a1, a2 = (x[0], x[1], x[2]) if vertical else (y[0], y[1], y[2])
        n_a, n_b = (cols, rows) if vertical else (rows, cols)
        first = max(int(np.floor(min(a0, a1, a2))) + 1, 0)
        last = min(int(np.ceil(max(a0, a1, a2))) - 1, n_a)
        for line in range(first, last + 1):
            lo, hi = _span(x, y, float(line), not vertical)
            for k in range(max(int(np.floor(lo)), 0), min(int(np.ceil(hi)) - 1, n_b - 1) + 1):
                s0, s1 = max(lo, float(k)), min(hi, k + 1.0)
                if s1 <= s0:
                    continue
                if vertical:
                    pieces[count, 0], pieces[count, 1], pieces[count, 2], pieces[count, 3] = line, s0, line, s1
                    pieces[count, 4] = k * cols + line - 1 if line > 0 else -1
                    pieces[count, 5] = k * cols + line if line < cols else -1
                else:
                    pieces[count, 0], pieces[count, 1], pieces[count, 2], pieces[count, 3] = s0, line, s1, line
                    pieces[count, 4] = line * cols + k if line < rows else -1
                    pieces[count, 5] = (line - 1) * cols + k if line > 0 else -1
                pieces[count, 6] = t
                count += 1
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def _setup(x, y, tu, tr, width, height, params, t):
    """Triangle t's map from the plane [pixel] to the texture [texel] written to params[t, :7] (u = c0 + c1 x +
    c2 y, r = c3 + c4 x + c5 y, the texture moved by whole periods to start in the first; 1 / Jacobian) and
    its period flag (2: it stays in the first period) to params[t, 10]; returns its texture area [texel^2]."""
    det = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
    shift_u = width * np.floor(min(tu[0], tu[1], tu[2]) / width)
    shift_r = height * np.floor(min(tr[0], tr[1], tr[2]) / height)
    ex1, ey1, ex2, ey2 = x[1] - x[0], y[1] - y[0], x[2] - x[0], y[2] - y[0]
    eu1, eu2, er1, er2 = tu[1] - tu[0], tu[2] - tu[0], tr[1] - tr[0], tr[2] - tr[0]
    a_u, b_u = (eu1 * ey2 - eu2 * ey1) / det, (eu2 * ex1 - eu1 * ex2) / det
    a_r, b_r = (er1 * ey2 - er2 * ey1) / det, (er2 * ex1 - er1 * ex2) / det
    params[t, 0], params[t, 1], params[t, 2] = tu[0] - shift_u - a_u * x[0] - b_u * y[0], a_u, b_u
    params[t, 3], params[t, 4], params[t, 5] = tr[0] - shift_r - a_r * x[0] - b_r * y[0], a_r, b_r
    within = max(tu[0], tu[1], tu[2]) - shift_u <= width and max(tr[0], tr[1], tr[2]) - shift_r <= height
    params[t, 10] = 2.0 if within else 0.0
    jacobian = a_u * b_r - b_u * a_r
    params[t, 6] = 1.0 / jacobian if jacobian != 0.0 else 0.0
    params[t, 11] = shift_u * 65536.0 + shift_r  # which period: shared edges cancel only within one
    return abs(jacobian * det)


@njit(cache=True, nogil=True, error_model="numpy")
def _parameters(corners, texels, material, prefix, level_base, level_size, levels, texels_per_pixel, outline_range,
                outline_levels, outline_texels, params, placed):
    """Every triangle's parameters (``_PARAMS``; flags 1: constant, 2: in the first period, 4: drawn, 8: drawn
    by its table's outline, loops params[12] .. params[13] - 1) and its corners made anticlockwise
    (``placed``, (m, 3, 2)) [pixel]."""
    for t in range(corners.shape[0]):
        m = material[t]
        x = (corners[t, 0, 0], corners[t, 1, 0], corners[t, 2, 0])
        y = (corners[t, 0, 1], corners[t, 1, 1], corners[t, 2, 1])
        tu = (texels[t, 0, 0], texels[t, 1, 0], texels[t, 2, 0])
        tr = (texels[t, 0, 1], texels[t, 1, 1], texels[t, 2, 1])
        det = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
        if det < 0.0:  # anticlockwise in (x, y)
            x, y, tu, tr = (x[0], x[2], x[1]), (y[0], y[2], y[1]), (tu[0], tu[2], tu[1]), (tr[0], tr[2], tr[1])
        for k in range(3):
            placed[t, k, 0], placed[t, k, 1] = x[k], y[k]
        params[t, 10] = 0.0
        if abs(det) < 1e-12:
            continue
        width0, height0 = level_size[m, 0, 0], level_size[m, 0, 1]
        texture = abs((tu[1] - tu[0]) * (tr[2] - tr[0]) - (tu[2] - tu[0]) * (tr[1] - tr[0])) * width0 * height0
        if outline_levels[m] > 0 and texture > 0.0 and max(tu) - np.floor(min(tu)) <= 1.0 and \
                max(tr) - np.floor(min(tr)) <= 1.0:  # a 0 / 1 table, the triangle in one period: its outline
            step = np.sqrt(texture / abs(det)) / outline_texels
            k = 0 if step <= 1.0 else min(int(np.floor(np.log2(step))), outline_levels[m] - 1)
            params[t, 7], params[t, 10] = -2.0, 14.0
            params[t, 12], params[t, 13] = outline_range[m, k, 0], outline_range[m, k, 1]
            continue
        ratio = np.sqrt(texture / abs(det)) / texels_per_pixel  # the level whose texels are ~1 / tpp of a pixel
        level = 0 if ratio <= 1.0 else min(int(np.floor(np.log2(ratio))), levels[m] - 1)
        base, width, height = level_base[m, level, 0], level_size[m, level, 0], level_size[m, level, 1]
        tu = (tu[0] * width, tu[1] * width, tu[2] * width)
        tr = (tr[0] * height, tr[1] * height, tr[2] * height)
        texture_area = _setup(x, y, tu, tr, width, height, params, t)
        params[t, 7], params[t, 8], params[t, 9] = base, width, height
        one_texel = np.floor(tu[0]) == np.floor(tu[1]) == np.floor(tu[2]) and \
            np.floor(tr[0]) == np.floor(tr[1]) == np.floor(tr[2])
        if (width == 1 and height == 1) or one_texel or texture_area < 1e-12:
            # the table's value over the whole triangle (where it has no area: its centroid's texel)
            u, r = (tu[0] + tu[1] + tu[2]) / 3.0, (tr[0] + tr[1] + tr[2]) / 3.0
            start = base + (int(np.floor(r)) % height) * (width + 1)
            i = int(np.floor(u)) % width
            params[t, 6], params[t, 7], params[t, 10] = prefix[start + i + 1] - prefix[start + i], -1.0, 1.0
            params[t, 11] = 0.0
        elif abs(params[t, 1]) + abs(params[t, 2]) < abs(params[t, 4]) + abs(params[t, 5]):
            # the pixel lines cross fewer texel columns than rows: walk the transposed table's rows instead
            # (u and r swapped, the Jacobian's sign with them: the same integral)
            _setup(x, y, tr, tu, height, width, params, t)
            params[t, 7], params[t, 8], params[t, 9] = level_base[m, level, 1], height, width
        if params[t, 6] != 0.0:
            params[t, 10] += 4.0


@njit(cache=True, nogil=True, error_model="numpy")
def _shared_edges(placed, partner, params):
    """Each drawn triangle's edges (as ``placed``, bit e from corner e to e + 1) that a partner's cancels: the
    partner across it (``partner`` (m, 3), -1 for none) runs it the other way, with the same table, level and
    period (or the same constant), so their pieces on it are equal and opposite."""
    skip = np.zeros(placed.shape[0], np.int64)
    for t in range(placed.shape[0]):
        if int(params[t, 10]) & 13 != 4:
            continue
        for e in range(3):
            p = partner[t, e]
            if p < 0 or int(params[p, 10]) & 13 != 4 or params[t, 7] != params[p, 7] or \
                    params[t, 11] != params[p, 11] or (params[t, 7] < 0.0 and params[t, 6] != params[p, 6]) or \
                    abs(params[t, 6] - params[p, 6]) > 1e-9 * abs(params[t, 6]):
                continue  # the pieces scale by 1 / Jacobian: unequal maps (a fold, a crease) do not cancel
            for j in range(3):  # the placed edge A -> B of t that the partner runs B -> A
                ax, ay = placed[t, j, 0], placed[t, j, 1]
                bx, by = placed[t, (j + 1) % 3, 0], placed[t, (j + 1) % 3, 1]
                for k in range(3):
                    if placed[p, k, 0] == bx and placed[p, k, 1] == by and \
                            placed[p, (k + 1) % 3, 0] == ax and placed[p, (k + 1) % 3, 1] == ay:
                        skip[t] |= 1 << j
    return skip


@njit(cache=True, nogil=True, error_model="numpy")
def _accumulate(x0, y0, x1, y1, weight, cells, rows, cols):
    """The segment's exact signed area added to the accumulation raster ``cells`` ((rows, cols + 1), flat),
    split at the pixel lines: a part in pixel (row, col) adds dy (col + 1 - x_mid) to cell (row, col) and
    dy (x_mid - col) to (row, col + 1), so that a row's running sum is the area a closed outline covers in
    each pixel (left of the raster: all of dy to column 0; right of it: nothing)."""
    if y0 == y1:
        return
    top, left = np.floor(min(y0, y1)), np.floor(min(x0, x1))
    if 0.0 <= top and top + 1.0 >= max(y0, y1) and top < rows and 0.0 <= left and left + 1.0 >= max(x0, x1) and \
            left < cols:  # within one pixel
        cell, mid = int(top) * (cols + 1) + int(left), 0.5 * (x0 + x1) - left
        cells[cell] += (y1 - y0) * weight * (1.0 - mid)
        cells[cell + 1] += (y1 - y0) * weight * mid
        return
    lo_y, hi_y = max(min(y0, y1), 0.0), min(max(y0, y1), float(rows))
    slope = (x1 - x0) / (y1 - y0)
    for row in range(int(np.floor(lo_y)), int(np.ceil(hi_y))):
        ya, yb = max(lo_y, float(row)), min(hi_y, row + 1.0)
        if yb <= ya:
            continue
        dy = (yb - ya) * weight if y1 > y0 else (ya - yb) * weight
        xa, xb = x0 + slope * (ya - y0), x0 + slope * (yb - y0)
        left, right = min(xa, xb), max(xa, xb)
        line = row * (cols + 1)
        first, last = max(int(np.floor(left)), -1), min(int(np.floor(right)), cols)
        if first == last or right == left:  # within one column
            mid = 0.5 * (left + right)
            if first < 0 or mid <= 0.0:
                cells[line] += dy
            elif first < cols:
                c = min(int(np.floor(mid)), cols - 1)
                cells[line + c] += dy * (c + 1.0 - mid)
                cells[line + c + 1] += dy * (mid - c)
            continue
        per = dy / (right - left)
        for c in range(first, last + 1):
            a, b = max(left, float(c)) if c >= 0 else left, min(right, c + 1.0) if c >= 0 else min(right, 0.0)
            if b <= a or c >= cols:
                continue
            part = per * (b - a)
            if c < 0:
                cells[line] += part
            else:
                mid = 0.5 * (a + b)
                cells[line + c] += part * (c + 1.0 - mid)
                cells[line + c + 1] += part * (mid - c)


@njit(cache=True, nogil=True, error_model="numpy")
def _clip(src_u, src_r, n, au, ar, bu, br, side, dst_u, dst_r):
    """The polygon (src, n corners) clipped to the half-plane left of A -> B (``side`` 1) or right of it
    (-1), written to dst (Sutherland-Hodgman); returns its corners' count."""
    out = 0
    eu, er = bu - au, br - ar
    pu, pr = src_u[n - 1], src_r[n - 1]
    pd = side * (eu * (pr - ar) - er * (pu - au))
    for k in range(n):
        qu, qr = src_u[k], src_r[k]
        qd = side * (eu * (qr - ar) - er * (qu - au))
        if (pd >= 0.0) != (qd >= 0.0):
            f = pd / (pd - qd)
            dst_u[out], dst_r[out] = pu + f * (qu - pu), pr + f * (qr - pr)
            out += 1
        if qd >= 0.0:
            dst_u[out], dst_r[out] = qu, qr
            out += 1
        pu, pr, pd = qu, qr, qd
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _outline_draw(p, tex, clip, count, outline, loop_start, loop_box, first, end, weight, cells, rows, cols, buf):
    """The table's outline (loops ``first`` .. ``end`` - 1, anticlockwise around what covers, in the
    texture [fraction]) clipped to the convex polygon ``clip`` ((count, 2), its corners in turn) in the
    texture, mapped onto the raster by the affine map that takes ``tex`` (3, 2) [fraction] to ``p`` (3, 2)
    [pixel], and accumulated into ``cells`` times ``weight``; ``buf`` (4, n) scratch."""
    fu1, fu2, fr1, fr2 = tex[1, 0] - tex[0, 0], tex[2, 0] - tex[0, 0], tex[1, 1] - tex[0, 1], tex[2, 1] - tex[0, 1]
    det = fu1 * fr2 - fu2 * fr1
    if det == 0.0:
        return
    ex1, ex2, ey1, ey2 = p[1, 0] - p[0, 0], p[2, 0] - p[0, 0], p[1, 1] - p[0, 1], p[2, 1] - p[0, 1]
    # pixel = p0 + A (t - t0), A = E F^-1
    a00, a01 = (ex1 * fr2 - ex2 * fr1) / det, (ex2 * fu1 - ex1 * fu2) / det
    a10, a11 = (ey1 * fr2 - ey2 * fr1) / det, (ey2 * fu1 - ey1 * fu2) / det
    w = weight if a00 * a11 - a01 * a10 < 0.0 else -weight  # the raster's rows run down
    side = 1.0 if det > 0.0 else -1.0
    lo_u, hi_u, lo_r, hi_r = np.inf, -np.inf, np.inf, -np.inf
    for k in range(count):
        lo_u, hi_u = min(lo_u, clip[k, 0]), max(hi_u, clip[k, 0])
        lo_r, hi_r = min(lo_r, clip[k, 1]), max(hi_r, clip[k, 1])
    for loop in range(first, end):
        if loop_box[loop, 0] >= hi_u or loop_box[loop, 2] <= lo_u or loop_box[loop, 1] >= hi_r or \
                loop_box[loop, 3] <= lo_r:
            continue
        a, n = loop_start[loop], loop_start[loop + 1] - loop_start[loop]
        src_u, src_r = outline[a:a + n, 0], outline[a:a + n, 1]
        into = 0
        for e in range(count):  # the loop clipped to each edge's inner side in turn, unless its box is inside it
            j = (e + 1) % count
            eu, er = clip[j, 0] - clip[e, 0], clip[j, 1] - clip[e, 1]
            inside = True
            for corner in range(4):
                cu, cr = loop_box[loop, 0 if corner < 2 else 2], loop_box[loop, 1 + 2 * (corner % 2)]
                inside = inside and side * (eu * (cr - clip[e, 1]) - er * (cu - clip[e, 0])) >= 0.0
            if inside:
                continue
            n = _clip(src_u, src_r, n, clip[e, 0], clip[e, 1], clip[j, 0], clip[j, 1], side, buf[into],
                      buf[into + 1])
            src_u, src_r, into = buf[into], buf[into + 1], 2 - into
            if n == 0:
                break
        if n < 3:
            continue
        u0, r0 = tex[0, 0], tex[0, 1]
        px = p[0, 0] + a00 * (src_u[n - 1] - u0) + a01 * (src_r[n - 1] - r0)
        py = p[0, 1] + a10 * (src_u[n - 1] - u0) + a11 * (src_r[n - 1] - r0)
        for k in range(n):
            qx = p[0, 0] + a00 * (src_u[k] - u0) + a01 * (src_r[k] - r0)
            qy = p[0, 1] + a10 * (src_u[k] - u0) + a11 * (src_r[k] - r0)
            _accumulate(px, py, qx, qy, w, cells, rows, cols)
            px, py = qx, qy


@njit(cache=True, nogil=True, error_model="numpy")
def _card(corners, texels, params, t, end, tex, clip):
    """Triangle t's texture coordinates moved into the first period (``tex``) and the polygon its outline is
    clipped to (``clip``); returns its corners' count: 4 where t and the next triangle (of its group, which
    ends before ``end``) are two halves of a card (across an edge whose corners they share; the same outline
    level; one affine map; a convex quadrilateral in the texture), so that their shared edge is not drawn;
    else 3 (the triangle)."""
    shift_u = np.floor(min(texels[t, 0, 0], texels[t, 1, 0], texels[t, 2, 0]))
    shift_r = np.floor(min(texels[t, 0, 1], texels[t, 1, 1], texels[t, 2, 1]))
    for k in range(3):
        tex[k, 0], tex[k, 1] = texels[t, k, 0] - shift_u, texels[t, k, 1] - shift_r
        clip[k, 0], clip[k, 1] = tex[k, 0], tex[k, 1]
    o = t + 1
    if o >= end or not int(params[o, 10]) & 8 or params[o, 12] != params[t, 12] or \
            params[o, 13] != params[t, 13]:
        return 3
    e, d = -1, -1  # the edge t shares with o (the same corners and texture coordinates), o's corner off it
    for k in range(3):
        for j in range(3):
            a, b = (k + 1) % 3, (j + 1) % 3
            if corners[o, j, 0] == corners[t, a, 0] and corners[o, j, 1] == corners[t, a, 1] and \
                    corners[o, b, 0] == corners[t, k, 0] and corners[o, b, 1] == corners[t, k, 1] and \
                    texels[o, j, 0] == texels[t, a, 0] and texels[o, j, 1] == texels[t, a, 1] and \
                    texels[o, b, 0] == texels[t, k, 0] and texels[o, b, 1] == texels[t, k, 1]:
                e, d = k, (j + 2) % 3
    if e < 0:
        return 3
    du, dr = texels[o, d, 0] - shift_u, texels[o, d, 1] - shift_r
    fu1, fu2, fr1, fr2 = tex[1, 0] - tex[0, 0], tex[2, 0] - tex[0, 0], tex[1, 1] - tex[0, 1], tex[2, 1] - tex[0, 1]
    det = fu1 * fr2 - fu2 * fr1
    if det == 0.0 or not (0.0 <= du <= 1.0 and 0.0 <= dr <= 1.0):
        return 3
    b1 = ((du - tex[0, 0]) * fr2 - fu2 * (dr - tex[0, 1])) / det
    b2 = (fu1 * (dr - tex[0, 1]) - (du - tex[0, 0]) * fr1) / det
    scale = 1e-9 * (1.0 + abs(corners[t, 1, 0] - corners[t, 0, 0]) + abs(corners[t, 1, 1] - corners[t, 0, 1]))
    for axis in range(2):  # the other half's corner where t's map takes its texture coordinates
        at = corners[t, 0, axis] + b1 * (corners[t, 1, axis] - corners[t, 0, axis]) + \
            b2 * (corners[t, 2, axis] - corners[t, 0, axis])
        if abs(at - corners[o, d, axis]) > scale:
            return 3
    order = (e, -1, (e + 1) % 3, (e + 2) % 3)
    for k in range(4):
        if order[k] < 0:
            clip[k, 0], clip[k, 1] = du, dr
        else:
            clip[k, 0], clip[k, 1] = tex[order[k], 0], tex[order[k], 1]
    side = 1.0 if det > 0.0 else -1.0
    for k in range(4):  # convex: every corner turns the triangle's way
        a, b, c = clip[k], clip[(k + 1) % 4], clip[(k + 2) % 4]
        if side * ((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])) <= 0.0:
            for j in range(3):
                clip[j, 0], clip[j, 1] = tex[j, 0], tex[j, 1]
            return 3
    return 4


@njit(cache=True, nogil=True, error_model="numpy")
def _scratch(loop_start):
    """Scratch for the clipped loops (4, n), a triangle's texture coordinates (3, 2), a clip polygon (4, 2)
    and the pieces."""
    longest = 3
    for loop in range(loop_start.shape[0] - 1):
        longest = max(longest, loop_start[loop + 1] - loop_start[loop])
    return np.empty((4, 8 * longest + 16)), np.empty((3, 2)), np.empty((4, 2)), np.empty((4096, _PIECE))


@njit(cache=True, nogil=True, error_model="numpy")
def _outlined(t, flags, x, y, corners, texels, params, end, tex, clip, outline, loop_start, loop_box, cells, rows,
              cols, buf):
    """Triangle t accumulated into ``cells``: a constant one as itself (anticlockwise, ``x``, ``y``) times its
    value, else its table's outline clipped by it, or by its card with the next triangle; returns the card's
    second half (drawn with it), or -1."""
    if flags & 1:
        for k in range(3):
            j = (k + 1) % 3
            _accumulate(x[k], y[k], x[j], y[j], -params[t, 6], cells, rows, cols)
        return -1
    sides = _card(corners, texels, params, t, end, tex, clip)
    _outline_draw(corners[t], tex, clip, sides, outline, loop_start, loop_box, int(params[t, 12]), int(params[t, 13]),
                  1.0, cells, rows, cols, buf)
    return t + 1 if sides == 4 else -1


@njit(cache=True, nogil=True, error_model="numpy")
def mesh_transmittance(corners: np.ndarray, texels: np.ndarray, material: np.ndarray, group_start: np.ndarray,
                       prefix: np.ndarray, level_base: np.ndarray, level_size: np.ndarray, levels: np.ndarray,
                       texels_per_pixel: float, transmittance: np.ndarray, double: np.ndarray,
                       partner: np.ndarray, outline: np.ndarray, loop_start: np.ndarray, loop_box: np.ndarray,
                       outline_range: np.ndarray, outline_levels: np.ndarray, outline_texels: float) -> None:
    """Triangles drawn into a transmittance raster by their exact coverage, group by group: a constant one,
    and one whose table is 0 or 1 within one period of it, accumulated as polygons (the triangle; the outline
    clipped by it) of exact signed area into a raster summed along its rows; any other piece by piece.

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
    level_base, level_size, levels : numpy.ndarray
        (materials, L, 2) int64 where each level's prefix sums start, and its transposed table's; each level's
        (width, height) [texel]; (materials,) int64 the levels each material has.
    texels_per_pixel : float
        The finest level whose texel spans at most 1 / texels_per_pixel of a pixel is read [1].
    transmittance : numpy.ndarray
        (rows, cols) float64, multiplied in place by 1 - each group's coverage [1].
    double : numpy.ndarray
        As ``prefix``: each row's prefix sums of the integral of its prefix F [texel^2].
    partner : numpy.ndarray
        (m, 3) int64: the triangle of the same group across each edge (corner k to k + 1) with the same
        vertices and texture coordinates at both ends, or -1; their shared edge is not drawn where the two
        cancel on it.
    outline, loop_start, loop_box, outline_range, outline_levels : numpy.ndarray
        The tables' outlines, as ``canopy.mesh_coverage.CoverageTables`` holds them: their corners (n, 2), loop
        after loop [fraction of the table]; where each loop starts; each loop's box; each material's loops at
        each level; the levels with an outline (0: the table is not all 0 and 1).
    outline_texels : float
        The coarsest outline whose texel spans at most 1 / outline_texels of a pixel is drawn [1].
    """
    rows, cols = transmittance.shape
    flat = transmittance.reshape(-1)
    acc, cells = np.zeros(rows * cols), np.zeros(rows * (cols + 1))
    params, placed = np.empty((corners.shape[0], _PARAMS)), np.empty_like(corners)
    _parameters(corners, texels, material, prefix, level_base, level_size, levels, texels_per_pixel, outline_range,
                outline_levels, outline_texels, params, placed)
    skip = _shared_edges(placed, partner, params)
    buf, tex, clip, pieces = _scratch(loop_start)
    for g in range(group_start.shape[0] - 1):
        count, r_lo, r_hi, c_lo, c_hi, card, pieced = 0, rows, 0, cols, 0, -1, False
        for t in range(group_start[g], group_start[g + 1]):
            x = (placed[t, 0, 0], placed[t, 1, 0], placed[t, 2, 0])
            y = (placed[t, 0, 1], placed[t, 1, 1], placed[t, 2, 1])
            c0, c1 = max(int(np.floor(min(x))), 0), min(int(np.ceil(max(x))), cols)
            r0, r1 = max(int(np.floor(min(y))), 0), min(int(np.ceil(max(y))), rows)
            flags = int(params[t, 10])
            if c1 <= c0 or r1 <= r0 or not flags & 4:
                continue
            r_lo, r_hi, c_lo, c_hi = min(r_lo, r0), max(r_hi, r1), min(c_lo, c0), max(c_hi, c1)
            if flags & 9:
                if t != card:  # (a card's second half is drawn with its first)
                    card = _outlined(t, flags, x, y, corners, texels, params, group_start[g + 1], tex, clip, outline,
                                     loop_start, loop_box, cells, rows, cols, buf)
                continue
            pieced = True
            most = 3 * (c1 - c0 + r1 - r0 + 3) + 2 * (c1 - c0 + 1) * (r1 - r0 + 1)
            if count + most > pieces.shape[0]:
                _integrate(pieces, count, params, prefix, double, acc)
                count = 0
                if most > pieces.shape[0]:
                    pieces = np.empty((most, _PIECE))
            count = _inner_pieces(x, y, t, False, pieces, _edge_pieces(x, y, t, skip[t], pieces, count, rows, cols),
                                  rows, cols)
        _integrate(pieces, count, params, prefix, double, acc)
        _deposit(flat, acc, cells, r_lo, r_hi, c_lo, c_hi, cols, pieced)


@njit(cache=True, nogil=True, error_model="numpy")
def _deposit(flat, acc, cells, r_lo, r_hi, c_lo, c_hi, cols, pieced):
    """A group's coverage (the running row sums of ``cells``, plus the pieces' sums ``acc`` where it has
    pieces) taken into the transmittance, clipped just below 1, and the buffers cleared over the group's box."""
    for r in range(r_lo, r_hi):
        line, running = r * (cols + 1), 0.0
        for c in range(c_lo, c_hi):
            running += cells[line + c]
            cells[line + c] = 0.0
            cover = running
            if pieced:
                cover += acc[r * cols + c]
                acc[r * cols + c] = 0.0
            if cover > 0.0:
                flat[r * cols + c] *= 1.0 - min(cover, _OPAQUE)
        cells[line + c_hi] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def triangle_alpha(texels: np.ndarray, material: np.ndarray, prefix: np.ndarray, level_base: np.ndarray,
                   level_size: np.ndarray, double: np.ndarray) -> np.ndarray:
    """The mean of each triangle's coverage table over the triangle in texture space (level 0).

    Parameters
    ----------
    texels, material, prefix, level_base, level_size, double
        As for ``mesh_transmittance``.

    Returns
    -------
    numpy.ndarray
        (m,) float64 in [0, 1] [1].
    """
    m = texels.shape[0]
    out, params, pieces = np.zeros(m), np.zeros((m, _PARAMS)), np.empty((3 * m, _PIECE))
    for t in range(m):  # F dr around the triangle in the texture over its area: the pieces of _integrate
        material_t = material[t]
        base, width, height = level_base[material_t, 0, 0], level_size[material_t, 0, 0], level_size[material_t, 0, 1]
        tu = (texels[t, 0, 0] * width, texels[t, 1, 0] * width, texels[t, 2, 0] * width)
        tr = (texels[t, 0, 1] * height, texels[t, 1, 1] * height, texels[t, 2, 1] * height)
        area = 0.5 * ((tu[1] - tu[0]) * (tr[2] - tr[0]) - (tu[2] - tu[0]) * (tr[1] - tr[0]))
        shift_u, shift_r = width * np.floor(min(tu) / width), height * np.floor(min(tr) / height)
        within = max(tu) - shift_u <= width and max(tr) - shift_r <= height
        params[t, 1], params[t, 5], params[t, 6] = 1.0, 1.0, 1.0 / area if abs(area) >= 1e-12 else 0.0
        params[t, 7], params[t, 8], params[t, 9], params[t, 10] = base, width, height, 2.0 if within else 0.0
        for k in range(3):
            j = (k + 1) % 3
            pieces[3 * t + k, 0], pieces[3 * t + k, 1] = tu[k] - shift_u, tr[k] - shift_r
            pieces[3 * t + k, 2], pieces[3 * t + k, 3] = tu[j] - shift_u, tr[j] - shift_r
            pieces[3 * t + k, 4], pieces[3 * t + k, 5], pieces[3 * t + k, 6] = t, -1.0, t
        if abs(area) < 1e-12:  # no area: its centroid's texel
            start = base + (int(np.floor((tr[0] + tr[1] + tr[2]) / 3.0)) % height) * (width + 1)
            i = int(np.floor((tu[0] + tu[1] + tu[2]) / 3.0)) % width
            out[t] = prefix[start + i + 1] - prefix[start + i]
    _integrate(pieces, 3 * m, params, prefix, double, out)
    return np.minimum(np.maximum(out, 0.0), 1.0)
