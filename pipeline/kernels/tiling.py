"""Compiled loops of the hashed tilings: the stochastic tiling of the ground albedo
(``albedo.StochasticTiling.sample``: its reads, then their blend through the inverse lookups) and the cloud
pattern's filtered reads over the tile's shifted copies (``clouds.CloudLayer.field``). Both shift a lattice's
vertices by the same hash of the vertex's offsets (``_vertex_key``, ``_unit_hash``). Each does what its array
version does, operation for operation in the same order (the clouds' reads: scipy's float64 ones), and the tests
hold it to that version's bits. The clouds' reads are spelled out per order (``_cubic_read``, ``_linear_read``:
a third less time than one loop over both orders' weights). Imported lazily: numba costs 0.3 s to import.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.kernels import HELPER, LOOP

__all__ = ["tiling_reads", "tiling_lookup", "cloud_field", "cloud_grid"]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _unit_hash(key):
    """``albedo.unit_hash`` of one uint64 key."""
    z = key + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return np.float64(z >> np.uint64(11)) / 9007199254740992.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _seed_key(seed):
    """``albedo.vertex_keys``'s share of the seed."""
    return np.uint64(seed) * np.uint64(0x165667B19E3779F9)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _vertex_key(va, vb, seed_key):
    """``albedo.vertex_keys`` of one lattice vertex (va, vb), ``seed_key`` from ``_seed_key``."""
    return ((np.uint64(va) * np.uint64(0x9E3779B97F4A7C15)) ^ (np.uint64(vb) * np.uint64(0xC2B2AE3D27D4EB4F))) ^ seed_key  # noqa: E501


_SECOND_KEY = np.uint64(0xD6E8FEB86659FD93)
"""``albedo.SECOND_KEY``."""


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def tiling_reads(x: np.ndarray, y: np.ndarray, cell: float, seed: int, skip: float, period_x: float, period_y: float,
                 weight: np.ndarray, read_x: np.ndarray, read_y: np.ndarray, read_pixel: np.ndarray,
                 read_weight: np.ndarray) -> int:
    """The reads of ``albedo.StochasticTiling.sample``, footprint by footprint in vertex order.

    Per footprint j the lattice triangle's three vertices and weights (``weights``) raised to the
    fourth power (BLEND_SHARPNESS, as two squarings) and renormalised go into ``weight``; each read
    of weight ``skip`` or more gets its point, (x, y) moved by the vertex's offset (``offsets``),
    its footprint and its weight.

    Parameters
    ----------
    x, y : numpy.ndarray
        (n,) float64, the footprints' centres on the ground [m].
    cell : float
        The triangle lattice's cell [m].
    seed : int
        The tiling's seed.
    skip : float
        Reads of a lower weight are left out (``albedo.SKIP_WEIGHT``) [1].
    period_x, period_y : float
        The exemplar's period along x and y: a vertex's offset is uniform in [0, period) [m].
    weight : numpy.ndarray
        (3, n) float64, written: each footprint's three vertex weights [1].
    read_x, read_y : numpy.ndarray
        (3 n,) float64, written from the start: the reads' points [m].
    read_pixel : numpy.ndarray
        (3 n,) int, written from the start: each read's footprint.
    read_weight : numpy.ndarray
        (3 n,) float64, written from the start: each read's weight [1].

    Returns
    -------
    int
        The count of reads written.
    """
    root3 = np.sqrt(3.0)
    seed_key = _seed_key(seed)
    count = 0
    for j in range(x.shape[0]):
        a = x[j] / cell
        b = y[j] / cell
        sa, sb = a - b / root3, 2.0 * b / root3
        ia, ib = np.floor(sa), np.floor(sb)
        fa, fb = sa - ia, sb - ib
        ja, jb = np.int64(ia), np.int64(ib)
        if fa + fb < 1.0:
            a0, b0, w0 = ja, jb, 1.0 - fa - fb
            a1, b1, w1 = ja, jb + 1, fb
            a2, b2, w2 = ja + 1, jb, fa
        else:
            a0, b0, w0 = ja + 1, jb + 1, fa + fb - 1.0
            a1, b1, w1 = ja + 1, jb, 1.0 - fb
            a2, b2, w2 = ja, jb + 1, 1.0 - fa
        w0 *= w0
        w0 *= w0
        w1 *= w1
        w1 *= w1
        w2 *= w2
        w2 *= w2
        total = w0 + w1 + w2
        w0 /= total
        w1 /= total
        w2 /= total
        weight[0, j], weight[1, j], weight[2, j] = w0, w1, w2
        # the three vertices' reads in one loop: numba types and lowers its body once
        for vertex in range(3):
            va, vb, w = (a0, b0, w0) if vertex == 0 else ((a1, b1, w1) if vertex == 1 else (a2, b2, w2))
            if w >= skip:  # else left out (``albedo.StochasticTiling.offsets``)
                key = _vertex_key(va, vb, seed_key)
                read_x[count] = x[j] + _unit_hash(key) * period_x
                read_y[count] = y[j] + _unit_hash(key ^ _SECOND_KEY) * period_y
                read_pixel[count] = j
                read_weight[count] = w
                count += 1
    return count


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _component(lookups, lv, up, k, g, norm, tb):
    """Component k mapped back from the Gaussian g through the lookups of levels lv and up,
    blended by tb (``tiling_lookup``)."""
    bins = lookups.shape[2]
    position = min(max((g / norm + 4.0) * (bins / 8.0) - 0.5, 0.0), bins - 1.0)
    low = min(np.int64(np.floor(position)), bins - 2)
    frac = position - low
    here = lookups[lv, k, low] * (1.0 - frac) + lookups[lv, k, low + 1] * frac
    there = lookups[up, k, low] * (1.0 - frac) + lookups[up, k, low + 1] * frac
    return here * (1.0 - tb) + there * tb


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def _tiling_lookup3(values, read_pixel, read_weight, weight, level, blend, lookups, center, basis, out):
    """``tiling_lookup`` for three channels, in scalars."""
    n = out.shape[1]
    last = lookups.shape[0] - 1
    reads = values.shape[1]
    r = 0
    for j in range(n):
        g0 = g1 = g2 = 0.0
        while r < reads and read_pixel[r] == j:
            w = read_weight[r]
            g0 += w * np.float64(values[0, r])
            g1 += w * np.float64(values[1, r])
            g2 += w * np.float64(values[2, r])
            r += 1
        norm = np.sqrt(weight[0, j] * weight[0, j] + weight[1, j] * weight[1, j] + weight[2, j] * weight[2, j])
        lv = np.int64(level[j])
        up = min(lv + 1, last)
        tb = np.float64(blend[j])
        # the components as int64, not literals: numba compiles a helper once per literal argument
        c0 = _component(lookups, lv, up, np.int64(0), g0, norm, tb)
        c1 = _component(lookups, lv, up, np.int64(1), g1, norm, tb)
        c2 = _component(lookups, lv, up, np.int64(2), g2, norm, tb)
        for m in range(3):
            value = center[m] + (((0.0 + c0 * basis[m, 0]) + c1 * basis[m, 1]) + c2 * basis[m, 2])
            out[m, j] = np.float32(value if not value < 0.0 else 0.0)


def tiling_lookup(values: np.ndarray, read_pixel: np.ndarray, read_weight: np.ndarray, weight: np.ndarray,
                  level: np.ndarray, blend: np.ndarray, lookups: np.ndarray, center: np.ndarray, basis: np.ndarray,
                  out: np.ndarray) -> None:
    """The rest of ``albedo.StochasticTiling.sample``: the reads' means blended into the albedo.

    The reads' means, footprint by footprint (``tiling_reads``' order), are summed by weight into
    the footprint's Gaussian g, divided by the root of the sum of its squared weights, mapped back
    through the inverse lookups of its level and the next, blended by ``blend``, and out of the
    principal axes, held at 0 or more. Three channels in scalars (``_tiling_lookup3``), others in
    ``_tiling_lookup_channels``: a run compiles the one it uses (docs/accuracy.md, "Compiling after an
    install").

    Parameters
    ----------
    values : numpy.ndarray
        (channels, m) float32, the reads' means (``filtered``) in the Gaussian space [1].
    read_pixel : numpy.ndarray
        (m,) int, each read's footprint (``tiling_reads``).
    read_weight : numpy.ndarray
        (m,) float64, each read's weight [1].
    weight : numpy.ndarray
        (3, n) float64, each footprint's vertex weights [1].
    level : numpy.ndarray
        (n,) int16, each footprint's mip level.
    blend : numpy.ndarray
        (n,) float32, its blend towards the next level [1].
    lookups : numpy.ndarray
        (levels, channels, bins) float64, the inverse lookup tables per level and component [1].
    center : numpy.ndarray
        (channels,) float64, the exemplar's mean albedo [1].
    basis : numpy.ndarray
        (channels, channels) float64, the principal axes [1].
    out : numpy.ndarray
        (channels, n) float32, written: the albedo [1].
    """
    loop = _tiling_lookup3 if out.shape[0] == 3 else _tiling_lookup_channels
    loop(values, read_pixel, read_weight, weight, level, blend, lookups, center, basis, out)


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def _tiling_lookup_channels(values, read_pixel, read_weight, weight, level, blend, lookups, center, basis, out):
    """``tiling_lookup`` of any count of channels."""
    channels, n = out.shape
    bins, last = lookups.shape[2], lookups.shape[0] - 1
    reads = values.shape[1]
    g = np.empty(channels, dtype=np.float64)
    comp = np.empty(channels, dtype=np.float64)
    r = 0
    for j in range(n):
        for k in range(channels):
            g[k] = 0.0
        while r < reads and read_pixel[r] == j:
            for k in range(channels):
                g[k] += read_weight[r] * np.float64(values[k, r])
            r += 1
        norm = np.sqrt(weight[0, j] * weight[0, j] + weight[1, j] * weight[1, j] + weight[2, j] * weight[2, j])
        lv = int(level[j])
        up = min(lv + 1, last)
        tb = np.float64(blend[j])
        for k in range(channels):
            position = min(max((g[k] / norm + 4.0) * (bins / 8.0) - 0.5, 0.0), bins - 1.0)
            low = min(int(np.floor(position)), bins - 2)
            frac = position - low
            here = lookups[lv, k, low] * (1.0 - frac) + lookups[lv, k, low + 1] * frac
            there = lookups[up, k, low] * (1.0 - frac) + lookups[up, k, low + 1] * frac
            comp[k] = here * (1.0 - tb) + there * tb
        for m in range(channels):
            acc = 0.0
            for i in range(channels):
                acc += comp[i] * basis[m, i]
            value = center[m] + acc
            out[m, j] = np.float32(value if not value < 0.0 else 0.0)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _grid_wrap(x, side):
    """scipy's grid-wrap of a coordinate [texel] on a level of ``side`` texels."""
    if x < 0:
        return 0.0 if side <= 1 else x + side * (int((-1.0 - x) / side) + 1)
    if x > side - 1:
        return 0.0 if side <= 1 else x - side * int(x / side)
    return x


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cubic_weights(f):
    """The cubic B-spline's four weights at fraction f of a texel, as scipy's ``map_coordinates``
    (order 3) computes them."""
    z = 1.0 - f
    w1 = (f * f * (f - 2.0) * 3.0 + 4.0) / 6.0
    w2 = (z * z * (z - 2.0) * 3.0 + 4.0) / 6.0
    w0 = z * z * z / 6.0
    return w0, w1, w2, 1.0 - w0 - w1 - w2


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cubic_axis(x, side):
    """One axis of ``_cubic_read`` at x [texel] on a level of ``side`` texels: (False, ...) where x
    is NaN, else (True, the four texels read, their weights), as scipy wraps and weighs them."""
    x = _grid_wrap(x, side)
    if not x > -1.0:  # NaN: scipy's constant 0
        return False, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0
    w0, w1, w2, w3 = _cubic_weights(x - math.floor(x))
    r = int(math.floor(x)) - 1
    if r < 0 or r + 3 >= side:
        return True, r % side, (r + 1) % side, (r + 2) % side, (r + 3) % side, w0, w1, w2, w3
    return True, r, r + 1, r + 2, r + 3, w0, w1, w2, w3


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cubic_sum(flat, base, side, i0, i1, i2, i3, r0, r1, r2, r3, j0, j1, j2, j3, c0, c1, c2, c3):
    """The cubic read of texels (i, j) of the level at ``base`` in ``flat`` by weights r (rows) and c
    (columns): value x row weight x column weight summed over rows, then columns, as scipy sums."""
    value = 0.0
    for i, wr in ((i0, r0), (i1, r1), (i2, r2), (i3, r3)):
        at = base + i * side
        value += flat[at + j0] * wr * c0
        value += flat[at + j1] * wr * c1
        value += flat[at + j2] * wr * c2
        value += flat[at + j3] * wr * c3
    return value


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cubic_read(flat, base, side, row, col):
    """scipy's cubic B-spline read (``map_coordinates``, order 3, ``prefilter=False``, grid-wrap)
    of the level at ``base`` in ``flat`` at (row, col) [texel]: 0 where either is NaN."""
    row_ok, i0, i1, i2, i3, r0, r1, r2, r3 = _cubic_axis(row, side)
    col_ok, j0, j1, j2, j3, c0, c1, c2, c3 = _cubic_axis(col, side)
    if not (row_ok and col_ok):
        return 0.0
    return _cubic_sum(flat, base, side, i0, i1, i2, i3, r0, r1, r2, r3, j0, j1, j2, j3, c0, c1, c2, c3)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _linear_read(flat, base, side, row, col):
    """scipy's bilinear read (order 1, grid-wrap) of the level at ``base`` in ``flat`` at (row,
    col) [texel]: 0 where either is NaN."""
    row, col = _grid_wrap(row, side), _grid_wrap(col, side)
    if not (row > -1.0 and col > -1.0):  # NaN: scipy's constant 0
        return 0.0
    r0 = 1.0 - (row - math.floor(row))
    r1 = 1.0 - r0
    c0 = 1.0 - (col - math.floor(col))
    c1 = 1.0 - c0
    r, c = int(math.floor(row)), int(math.floor(col))
    if r < 0 or r + 1 >= side or c < 0 or c + 1 >= side:
        i0, i1, j0, j1 = r % side, (r + 1) % side, c % side, (c + 1) % side
    else:
        i0, i1, j0, j1 = r, r + 1, c, c + 1
    value = 0.0
    value += flat[base + i0 * side + j0] * r0 * c0
    value += flat[base + i0 * side + j1] * r0 * c1
    value += flat[base + i1 * side + j0] * r1 * c0
    value += flat[base + i1 * side + j1] * r1 * c1
    return value


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _copies_at(x, side0, band, base):
    """The copies of the tile read at lattice coordinate x [texel of level 0] along one axis
    (``cloud_field``): (how many, 1 or 2; the lower copy; the upper; their smoothstep shares [1]),
    ``base`` added to the copies' indices. Within ``band`` [texel] of a copy's edge, both copies."""
    copy = math.floor(x / side0 + 0.5)
    edge = x - (copy - 0.5) * side0  # [texel] from the copy's lower edge
    lower = copy + base
    if edge < 0.5 * band or edge > side0 - 0.5 * band:
        u = edge / band + 0.5 if edge < 0.5 * band else (edge - side0) / band + 0.5
        u = min(max(u, 0.0), 1.0)
        upper_share = u * u * (3.0 - 2.0 * u)
        if edge < 0.5 * band:
            return 2, lower - 1, lower, 1.0 - upper_share, upper_share
        return 2, lower, lower + 1, 1.0 - upper_share, upper_share
    return 1, lower, lower, 1.0, 0.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _copy_shift(copy_row, copy_col, seed_key, side0):
    """The shift (rows, cols) [texel of level 0] of copy (copy_row, copy_col) of the tile: none for
    copy (0, 0), else hashed as the ground albedo's lattice vertices (``cloud_field``)."""
    if copy_row == 0 and copy_col == 0:
        return 0.0, 0.0
    key = _vertex_key(copy_row, copy_col, seed_key)
    return _unit_hash(key) * side0, _unit_hash(key ^ _SECOND_KEY) * side0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _remembered_shift(copy_row, copy_col, seed_key, side0, last_row, last_col, last_shift_row, last_shift_col):
    """The copy (copy_row, copy_col) of the tile and its shift (rows, cols) [texel of level 0]
    (``_copy_shift``), as (copy_row, copy_col, shift_row, shift_col): the last copy hashed and its
    shift (last_row, last_col, last_shift_row, last_shift_col) when it is that copy, not hashed again."""
    if copy_row == last_row and copy_col == last_col:  # as the last read's
        return last_row, last_col, last_shift_row, last_shift_col
    shift_row, shift_col = _copy_shift(copy_row, copy_col, seed_key, side0)
    return copy_row, copy_col, shift_row, shift_col


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _tap_point(rows, cols, major, ex, ey, i, t, n_taps, direct):
    """Tap t of n_taps of sample i (``cloud_field``): (row, col) [texel of level 0], the sample's
    point itself when ``direct``, else spaced along (ex[i], ey[i]) over major[i] about it."""
    if direct:
        return rows[i], cols[i]
    step = ((t + 0.5) / n_taps - 0.5) * major[i]  # [texel] from the centre
    return rows[i] + -ey[i] * step, cols[i] + ex[i] * step


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _field_samples(flat, offsets, sides, rows, cols, direct, taps, k0, blend, major, ex, ey, out, tile_blend, seed,
                   base_row, base_col):
    """``cloud_field``'s loop over samples and taps. The levels are read here, not in a helper:
    numba inlining the reads one call deeper made the loop 1.5 to 2 times slower."""
    n_levels = sides.shape[0]
    side0 = sides[0]
    band = tile_blend * side0
    seed_key = _seed_key(seed)
    copies = np.empty((2, 2), dtype=np.int64)  # per axis: the copies read, lower first
    shares = np.empty((2, 2))  # per axis: their smoothstep weights
    last_row = last_col = 0  # the last copy hashed, and its shift
    last_shift_row = last_shift_col = 0.0
    scales = np.empty(n_levels)  # 2^level, exactly
    for level in range(n_levels):
        scales[level] = 2.0**level
    for i in range(rows.shape[0]):
        n_taps = 1 if direct else taps[i]
        k = 0 if direct else k0[i]
        upper = (not direct) and blend[i] > 0 and k + 1 < n_levels
        total = 0.0
        for t in range(n_taps):
            tap_row, tap_col = _tap_point(rows, cols, major, ex, ey, i, t, n_taps, direct)
            count_row, copies[0, 0], copies[0, 1], shares[0, 0], shares[0, 1] = _copies_at(
                tap_row, side0, band, base_row)
            count_col, copies[1, 0], copies[1, 1], shares[1, 0], shares[1, 1] = _copies_at(
                tap_col, side0, band, base_col)
            weighted = 0.0
            squares = 0.0
            for cr in range(count_row):
                for cc in range(count_col):
                    last_row, last_col, last_shift_row, last_shift_col = _remembered_shift(
                        copies[0, cr], copies[1, cc], seed_key, side0, last_row, last_col, last_shift_row,
                        last_shift_col)
                    w = shares[0, cr] * shares[1, cc]
                    at_row = tap_row + last_shift_row
                    at_col = tap_col + last_shift_col
                    finer = 0.0
                    for level in range(k, k + 2 if upper else k + 1):
                        row_at, col_at = at_row, at_col
                        if not direct:  # texel centres of the level
                            row_at = (row_at + 0.5) / scales[level] - 0.5
                            col_at = (col_at + 0.5) / scales[level] - 0.5
                        if level == 0:
                            value = _cubic_read(flat, offsets[0], sides[0], row_at, col_at)
                        else:
                            value = _linear_read(flat, offsets[level], sides[level], row_at, col_at)
                        if level == k:
                            finer = value
                        else:
                            value = finer + blend[i] * (value - finer)
                    weighted += w * value
                    squares += w * w
            if count_row * count_col > 1:
                value = weighted / math.sqrt(squares)
            total += value / n_taps if not direct else value
        out[i] = total


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def cloud_field(flat: np.ndarray, offsets: np.ndarray, sides: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                direct: bool, taps: np.ndarray, k0: np.ndarray, blend: np.ndarray, major: np.ndarray,
                ex: np.ndarray, ey: np.ndarray, out: np.ndarray, tile_blend: float, seed: int, base_row: int,
                base_col: int) -> np.ndarray:
    """The reads of ``clouds.CloudLayer.field`` in one loop over samples and taps.

    The plane is laid with copies of the tile, each but copy (0, 0) shifted by (rows, cols),
    uniform in [0, side) texels of level 0, as the ground albedo's stochastic tiling shifts its
    lattice vertices (``_vertex_key``, ``_unit_hash``), so that the pattern does not repeat (a
    repeating tile lines its copies up towards the horizon, docs/method.md, "The cloud
    pattern"); in a band ``tile_blend`` of the side wide about each edge a read blends the
    copies on both sides, ``sum w v / sqrt(sum w^2)`` (variance preserving, Heitz & Neyret
    2018) with smoothstep weights. A read inside one copy is that copy's read alone, bit for bit.
    Each read is that of ``scipy.ndimage.map_coordinates`` with mode ``grid-wrap`` (cubic
    B-spline with ``prefilter=False`` at level 0, bilinear above), operation for operation, so
    the result is the same to the bit: the coordinate wrapped into the tile as scipy wraps it,
    scipy's spline weights (the last one 1 minus the others), the sum over rows then columns of
    value x row weight x column weight.

    Parameters
    ----------
    flat : numpy.ndarray
        Every level of the noise in one flat float64 array (``cloud_noise.packed_levels``) [1].
    offsets : numpy.ndarray
        (levels,) intp, each level's first value in ``flat``.
    sides : numpy.ndarray
        (levels,) intp, each (square) level's side [texel].
    rows, cols : numpy.ndarray
        (m,) lattice coordinates of the samples [texel of level 0].
    direct : bool
        True reads level 0 at (rows, cols) alone (no footprint; the arrays below unused); else
        sample i averages taps[i] taps spaced along (ex[i], ey[i]) over major[i], each read at level
        k0[i] and, where blend[i] > 0, blended towards level k0[i] + 1.
    taps : numpy.ndarray
        (m,) int, taps per sample.
    k0 : numpy.ndarray
        (m,) int, each sample's level.
    blend : numpy.ndarray
        (m,) float, its blend towards the next level [1].
    major : numpy.ndarray
        (m,) float64, the footprint's length along its major axis [texel of level 0].
    ex, ey : numpy.ndarray
        (m,) float64, the unit vector of the major axis [1].
    out : numpy.ndarray
        (m,) float64, written: the field [1].
    tile_blend : float
        ``clouds.TILE_BLEND``, the blend band's width over the side [1].
    seed : int
        The layer's seed.
    base_row, base_col : int
        The index of the copy of the tile whose centre is at lattice coordinates (0, 0)
        (``CloudLayer._drifted_copies``).

    Returns
    -------
    numpy.ndarray
        ``out``.
    """
    _field_samples(flat, offsets, sides, rows, cols, direct, taps, k0, blend, major, ex, ey, out, tile_blend, seed,
                   base_row, base_col)
    return out


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _column_copies(cols, side0, band, base_col):
    """Per column of ``cloud_grid``: (how many copies of the tile it reads, 1 or 2 (n_cols,); the
    copies, lower first (n_cols, 2); their smoothstep shares (n_cols, 2) [1]) (``_copies_at``)."""
    n_cols = cols.shape[0]
    col_count = np.empty(n_cols, dtype=np.int64)
    col_copy = np.empty((n_cols, 2), dtype=np.int64)
    col_share = np.empty((n_cols, 2))
    for j in range(n_cols):
        col_count[j], col_copy[j, 0], col_copy[j, 1], col_share[j, 0], col_share[j, 1] = _copies_at(
            cols[j], side0, band, base_col)
    return col_count, col_copy, col_share


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _column_taps(copy_row, cr, first_copy, cols, col_count, col_copy, seed_key, side0, shift_rows, col_ok, col_at,
                 col_w):
    """For row copy ``copy_row`` (the row's cr-th, 0 or 1) of ``cloud_grid``: the shift's row part
    [texel of level 0] per column copy from ``first_copy`` into shift_rows[cr], and each column's
    taps (``_cubic_axis``) per column copy into col_ok[cr], col_at[cr], col_w[cr]."""
    for cc in range(shift_rows.shape[1]):
        shift_rows[cr, cc] = _copy_shift(copy_row, first_copy + cc, seed_key, side0)[0]
    for j in range(cols.shape[0]):
        for cc in range(col_count[j]):
            shift_col = _copy_shift(copy_row, col_copy[j, cc], seed_key, side0)[1]
            (col_ok[cr, j, cc], col_at[cr, j, cc, 0], col_at[cr, j, cc, 1], col_at[cr, j, cc, 2],
             col_at[cr, j, cc, 3], col_w[cr, j, cc, 0], col_w[cr, j, cc, 1], col_w[cr, j, cc, 2],
             col_w[cr, j, cc, 3]) = _cubic_axis(cols[j] + shift_col, side0)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _row_taps(row, count_row, shift_rows, side0, row_ok, row_at, row_w):
    """The taps (``_cubic_axis``) of a row of ``cloud_grid`` at lattice row ``row`` [texel of level
    0], per row copy (``count_row`` of them) and column copy, into row_ok, row_at, row_w."""
    for cr in range(count_row):
        for cc in range(shift_rows.shape[1]):
            (row_ok[cr, cc], row_at[cr, cc, 0], row_at[cr, cc, 1], row_at[cr, cc, 2], row_at[cr, cc, 3],
             row_w[cr, cc, 0], row_w[cr, cc, 1], row_w[cr, cc, 2], row_w[cr, cc, 3]) = _cubic_axis(
                row + shift_rows[cr, cc], side0)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _grid_row(flat, base, side0, count_row, share_lower, share_upper, col_count, col_copy, col_share, first_copy,
              row_ok, row_at, row_w, col_ok, col_at, col_w, out, at, j_start, j_stop):
    """Columns j_start to j_stop - 1 of one row of ``cloud_grid`` into out[at + j]: per sample the
    read of the copy of the tile it lies in, or the variance-preserving blend of the copies about it
    [1], from the row's taps (``_row_taps``) and the columns' (``_column_taps``)."""
    for j in range(j_start, j_stop):
        weighted = 0.0
        squares = 0.0
        value = 0.0
        for cr in range(count_row):
            for cc in range(col_count[j]):
                w = (share_lower if cr == 0 else share_upper) * col_share[j, cc]
                k = col_copy[j, cc] - first_copy
                value = 0.0
                if row_ok[cr, k] and col_ok[cr, j, cc]:
                    value = _cubic_sum(flat, base, side0, row_at[cr, k, 0], row_at[cr, k, 1], row_at[cr, k, 2],
                                       row_at[cr, k, 3], row_w[cr, k, 0], row_w[cr, k, 1], row_w[cr, k, 2],
                                       row_w[cr, k, 3], col_at[cr, j, cc, 0], col_at[cr, j, cc, 1],
                                       col_at[cr, j, cc, 2], col_at[cr, j, cc, 3], col_w[cr, j, cc, 0],
                                       col_w[cr, j, cc, 1], col_w[cr, j, cc, 2], col_w[cr, j, cc, 3])
                weighted += w * value
                squares += w * w
        if count_row * col_count[j] > 1:
            value = weighted / math.sqrt(squares)
        total = 0.0
        total += value
        out[at + j] = total


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def cloud_grid(flat: np.ndarray, offsets: np.ndarray, sides: np.ndarray, rows: np.ndarray, cols: np.ndarray,
               start: int, stop: int, out: np.ndarray, tile_blend: float, seed: int, base_row: int,
               base_col: int) -> np.ndarray:
    """``cloud_field``'s direct reads (level 0, no footprint) of a grid: the sample of row i and
    column j at lattice coordinates (rows[i], cols[j]), written to ``out[i x len(cols) + j]`` for
    start <= i x len(cols) + j < stop, bit for bit as ``cloud_field`` reads it. A row's copies of
    the tile, their shifts and its reads' row weights are found once for the row, and a column's
    weights once for each run of rows in the same copies, not once per sample (a grove frame's
    sky raster: 4.2 M samples, docs/accuracy.md, "The clouds on a grid").

    Parameters
    ----------
    flat, offsets, sides
        The noise's levels, as ``cloud_field`` takes them (only level 0 is read).
    rows : numpy.ndarray
        (n_rows,) float64 lattice row of each row of samples [texel of level 0].
    cols : numpy.ndarray
        (n_cols,) float64 lattice column of each column of samples [texel of level 0].
    start, stop : int
        The samples written, in row-major order.
    out : numpy.ndarray
        (n_rows x n_cols,) float64, written from start to stop: the field [1].
    tile_blend, seed, base_row, base_col
        As ``cloud_field`` takes them.

    Returns
    -------
    numpy.ndarray
        ``out``.
    """
    n_cols = cols.shape[0]
    if stop <= start:
        return out
    side0, base = sides[0], offsets[0]
    band = tile_blend * side0
    seed_key = _seed_key(seed)
    col_count, col_copy, col_share = _column_copies(cols, side0, band, base_col)
    first_copy = col_copy[:, 0].min()
    spread = col_copy[:, 1].max() - first_copy + 1  # the column copies met
    # per row copy (of the row's two) and column copy: the shift's row part and the row's taps
    row_ok = np.empty((2, spread), dtype=np.bool_)
    row_at = np.empty((2, spread, 4), dtype=np.int64)
    row_w = np.empty((2, spread, 4))
    # per row copy, column and column copy: the column's taps, for the row copies of ``made``
    col_ok = np.empty((2, n_cols, 2), dtype=np.bool_)
    col_at = np.empty((2, n_cols, 2, 4), dtype=np.int64)
    col_w = np.empty((2, n_cols, 2, 4))
    shift_rows = np.empty((2, spread))
    made = np.array([-1, 0, 0], dtype=np.int64)  # the row copies the column taps are for: count, lower, upper
    for i in range(start // n_cols, (stop - 1) // n_cols + 1):
        count_row, lower, upper, share_lower, share_upper = _copies_at(rows[i], side0, band, base_row)
        if count_row != made[0] or lower != made[1] or (count_row == 2 and upper != made[2]):
            for cr in range(count_row):
                _column_taps(lower if cr == 0 else upper, cr, first_copy, cols, col_count, col_copy, seed_key, side0,
                             shift_rows, col_ok, col_at, col_w)
            made[0], made[1], made[2] = count_row, lower, upper
        _row_taps(rows[i], count_row, shift_rows, side0, row_ok, row_at, row_w)
        _grid_row(flat, base, side0, count_row, share_lower, share_upper, col_count, col_copy, col_share, first_copy,
                  row_ok, row_at, row_w, col_ok, col_at, col_w, out, i * n_cols, max(start - i * n_cols, 0),
                  min(stop - i * n_cols, n_cols))
    return out
