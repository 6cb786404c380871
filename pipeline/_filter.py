"""Compiled loops of the frame phase's resampling: the camera's anisotropic filtering
(``camera._filtered``) and mip levels (``camera._constant_mipmap``), the stochastic tiling of the
ground albedo (``albedo.StochasticTiling.sample``), the bilinear resampling of the coarse ground
under the sun window (``shadow.resample_bilinear``), the haze over the view
(``frame._apply_haze``) and the cloud pattern's filtered reads (``clouds.CloudLayer.field``).
Each does what its array version does, float32 operation for float32 operation in the same
order (the clouds' reads: scipy's float64 ones), and the tests hold it to that version's bits.

The filtering's method is the one documented in ``camera.sample_footprint`` and ``albedo``:
these loops do it footprint by footprint, every tap of a footprint in turn, with the same float32 arithmetic
and the same order of operations as the array version (``camera._tap_mean``, ``_bilinear``), so
that no per-tap arrays are built and the footprints need not be grouped and sorted by level.
The tap counts, levels and blends come from ``camera._filter_choice`` (``filter_choice``), computed once
for all the reads that share a footprint. Imported lazily: numba costs 0.3 s to import.

Why one module: the frame phase's compiled reads share numba's lazy import and its cache on
disk, and pieces of them live once, here: the hash of a lattice vertex's offsets
(``_vertex_key``, ``_unit_hash``) serves the albedo's tiling and the cloud tile's copies alike.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["filtered", "tiling_reads", "tiling_lookup", "footprint_axes", "row_footprints", "filter_choice",
           "halve_level", "resample_separable", "haze_over", "sky_rows", "cloud_field", "lattice_read"]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _first_texel(channels, offset, rows, cols, periodic, col, row):
    """``camera._first_texel`` of one point: the flat index of channel 0 of the first of the four
    texels of a bilinear sample at texel coordinates (col, row), and the fractions (fc, fr)
    float32 beyond it."""
    if not periodic:
        col = min(max(col, -1.0), float(cols))
        row = min(max(row, -1.0), float(rows))
    c0f, r0f = np.floor(col), np.floor(row)
    fc = np.float32(col - c0f)
    fr = np.float32(row - r0f)
    c0, r0 = int(c0f), int(r0f)
    if periodic:  # a mask for a power of two, as camera._wrap: no division
        c0 = c0 & (cols - 1) if cols & (cols - 1) == 0 else c0 % cols
        r0 = r0 & (rows - 1) if rows & (rows - 1) == 0 else r0 % rows
    return ((r0 * (cols + 2) + c0) + offset + cols + 3) * channels, fc, fr


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _bilinear(flat, first, channels, step, k, fc, fr):
    """Channel ``k`` of the bilinear sample whose first texel is ``first`` (``_first_texel``),
    ``step`` the flat stride of a stored row: ``camera._bilinear``'s float32 arithmetic, each
    corner read as ``flat[o:].take(first, mode="clip")``."""
    size = flat.shape[0]
    if first >= 0 and first + step + 2 * channels <= size:  # always, but for NaN coordinates
        a = flat[first + k]
        b = flat[first + channels + k]
        c = flat[first + step + k]
        d = flat[first + step + channels + k]
    else:
        o = k
        a = flat[o + min(max(first, 0), size - o - 1)]
        o = channels + k
        b = flat[o + min(max(first, 0), size - o - 1)]
        o = step + k
        c = flat[o + min(max(first, 0), size - o - 1)]
        o = step + channels + k
        d = flat[o + min(max(first, 0), size - o - 1)]
    b -= a
    b *= fc
    a += b
    d -= c
    d *= fc
    c += d
    c -= a
    c *= fr
    a += c
    return a


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _coords(x0, y0, px, py, sx, sy, dx, dy):
    """``camera._texel_coords`` of one point and step."""
    col = (sx - x0) * (1.0 / px) - 0.5
    row = (y0 - sy) * (1.0 / py) - 0.5
    dcol = dx * (1.0 / px)
    drow = dy * (-1.0 / py)
    lim, dlim = 2.0**52, 2.0**48
    col = min(max(col, -lim), lim)
    row = min(max(row, -lim), lim)
    dcol = min(max(dcol, -dlim), dlim)
    drow = min(max(drow, -dlim), dlim)
    return col, row, dcol, drow


@njit(cache=True, nogil=True, error_model="numpy")
def filtered(flat, channels, offsets, shapes, origins, pixels, periodic, x, y, footprint, major, ex, ey, taps,
             level, blend, out):
    """``camera._filtered``: each read's mean into ``out``.

    Read r is centred on (x[r], y[r]) with the ellipse and filter of footprint j = footprint[r]
    (several reads may share one: the stochastic tiling's); read r takes taps[j] trilinear samples
    (``camera._tap_mean``, the same float32 arithmetic in the same order), in level level[j]
    blended by blend[j] towards the next when > 0. The body is written out in full for three
    channels (a helper function that returns the three means, even inlined, ran three times
    slower) and channel by channel otherwise.

    Parameters
    ----------
    flat : numpy.ndarray
        (texels x channels,) float32, every level of the mip map flat (``camera.MipMap.texels``),
        each level stored with its border of one texel (``camera._level_tables``).
    channels : int
        Channels per texel.
    offsets : numpy.ndarray
        (levels,) int64, each level's first stored texel in ``flat`` [texel].
    shapes : numpy.ndarray
        (levels, 2) int64, each level's (rows, cols) without the border.
    origins : numpy.ndarray
        (levels, 2) float64, the north-west corner (x, y) of each level's texel [0, 0] [m].
    pixels : numpy.ndarray
        (levels, 2) float64, each level's texel width (along x) and height (along y) [m].
    periodic : bool
        The raster tiles the plane (else the border holds the outside value).
    x, y : numpy.ndarray
        (m,) float64, the reads' centres on the raster's plane [m].
    footprint : numpy.ndarray
        (m,) int, the footprint of each read.
    major : numpy.ndarray
        (n,) float64, each footprint's ellipse's box width along its major axis [m].
    ex, ey : numpy.ndarray
        (n,) float64, the unit vector of each footprint's major axis [1].
    taps : numpy.ndarray
        (n,) int8, samples along the major axis (``filter_choice``).
    level : numpy.ndarray
        (n,) int16, the mip level read.
    blend : numpy.ndarray
        (n,) float32, the blend towards level + 1, in [0, 1) [1].
    out : numpy.ndarray
        (channels, m) float32, written: the reads' means, in the raster's units.
    """
    for r in range(x.shape[0]):
        j = footprint[r]
        lv, t, n = int(level[j]), blend[j], int(taps[j])
        blended = t > 0
        spacing = major[j] / n
        first = (0.5 - 0.5 * n) * spacing
        sx, sy, dx, dy = x[r] + first * ex[j], y[r] + first * ey[j], spacing * ex[j], spacing * ey[j]
        col0, row0, dcol, drow = _coords(origins[lv, 0], origins[lv, 1], pixels[lv, 0], pixels[lv, 1],
                                         sx, sy, dx, dy)
        rows, cols, off = shapes[lv, 0], shapes[lv, 1], offsets[lv]
        colb0, rowb0, dcolb, drowb = col0, row0, dcol, drow
        rowsb, colsb, offb = rows, cols, off
        if blended:
            colb0, rowb0, dcolb, drowb = _coords(origins[lv + 1, 0], origins[lv + 1, 1], pixels[lv + 1, 0],
                                                 pixels[lv + 1, 1], sx, sy, dx, dy)
            rowsb, colsb, offb = shapes[lv + 1, 0], shapes[lv + 1, 1], offsets[lv + 1]
        step, stepb = (cols + 2) * channels, (colsb + 2) * channels
        nf = np.float32(n)
        if channels == 3:
            col, row, colb, rowb = col0, row0, colb0, rowb0
            t0 = t1 = t2 = np.float32(0.0)
            for i in range(n):
                s0, s1, s2 = _bilinear3(flat, off, rows, cols, periodic, col, row, step)
                col += dcol
                row += drow
                if blended:
                    u0, u1, u2 = _bilinear3(flat, offb, rowsb, colsb, periodic, colb, rowb, stepb)
                    colb += dcolb
                    rowb += drowb
                    s0 += (u0 - s0) * t
                    s1 += (u1 - s1) * t
                    s2 += (u2 - s2) * t
                if i == 0:
                    t0, t1, t2 = s0, s1, s2
                else:
                    t0 += s0
                    t1 += s1
                    t2 += s2
            out[0, r] = t0 / nf
            out[1, r] = t1 / nf
            out[2, r] = t2 / nf
            continue
        # any other count of channels: each tap's texel found once, then every channel read
        # there (the same float32 operations per channel, in the same order, as channel by
        # channel: a stack of many rasters filtered in one pass costs little more per channel)
        col, row, colb, rowb = col0, row0, colb0, rowb0
        fb, fcb, frb = 0, np.float32(0.0), np.float32(0.0)
        for i in range(n):
            f, fc, fr = _first_texel(channels, off, rows, cols, periodic, col, row)
            col += dcol
            row += drow
            if blended:
                fb, fcb, frb = _first_texel(channels, offb, rowsb, colsb, periodic, colb, rowb)
                colb += dcolb
                rowb += drowb
            for k in range(channels):
                s = _bilinear(flat, f, channels, step, k, fc, fr)
                if blended:
                    u = _bilinear(flat, fb, channels, stepb, k, fcb, frb)
                    s += (u - s) * t
                if i == 0:
                    out[k, r] = s
                else:
                    out[k, r] += s
        for k in range(channels):
            out[k, r] /= nf


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


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _read(count, j, w, va, vb, skip, seed_key, x, y, period_x, period_y, read_x, read_y, read_pixel,
          read_weight):
    """Appends the read of vertex (va, vb) of weight w for footprint j at (x, y) [m] when
    w >= skip (``albedo.StochasticTiling.offsets``); returns the new count of reads."""
    if not w >= skip:
        return count
    key = _vertex_key(va, vb, seed_key)
    read_x[count] = x + _unit_hash(key) * period_x
    read_y[count] = y + _unit_hash(key ^ _SECOND_KEY) * period_y
    read_pixel[count] = j
    read_weight[count] = w
    return count + 1


@njit(cache=True, nogil=True, error_model="numpy")
def tiling_reads(x, y, cell, seed, skip, period_x, period_y, weight, read_x, read_y, read_pixel, read_weight):
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
        count = _read(count, j, w0, a0, b0, skip, seed_key, x[j], y[j], period_x, period_y, read_x, read_y,
                      read_pixel, read_weight)
        count = _read(count, j, w1, a1, b1, skip, seed_key, x[j], y[j], period_x, period_y, read_x, read_y,
                      read_pixel, read_weight)
        count = _read(count, j, w2, a2, b2, skip, seed_key, x[j], y[j], period_x, period_y, read_x, read_y,
                      read_pixel, read_weight)
    return count


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _component(lookups, lv, up, k, g, norm, tb):
    """Component k mapped back from the Gaussian g through the lookups of levels lv and up,
    blended by tb (``tiling_lookup``)."""
    bins = lookups.shape[2]
    position = min(max((g / norm + 4.0) * (bins / 8.0) - 0.5, 0.0), bins - 1.0)
    low = min(int(np.floor(position)), bins - 2)
    frac = position - low
    here = lookups[lv, k, low] * (1.0 - frac) + lookups[lv, k, low + 1] * frac
    there = lookups[up, k, low] * (1.0 - frac) + lookups[up, k, low + 1] * frac
    return here * (1.0 - tb) + there * tb


@njit(cache=True, nogil=True, error_model="numpy")
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
        lv = int(level[j])
        up = min(lv + 1, last)
        tb = np.float64(blend[j])
        c0 = _component(lookups, lv, up, 0, g0, norm, tb)
        c1 = _component(lookups, lv, up, 1, g1, norm, tb)
        c2 = _component(lookups, lv, up, 2, g2, norm, tb)
        for m in range(3):
            value = center[m] + (((0.0 + c0 * basis[m, 0]) + c1 * basis[m, 1]) + c2 * basis[m, 2])
            out[m, j] = np.float32(value if not value < 0.0 else 0.0)


@njit(cache=True, nogil=True, error_model="numpy")
def tiling_lookup(values, read_pixel, read_weight, weight, level, blend, lookups, center, basis, out):
    """The rest of ``albedo.StochasticTiling.sample``: the reads' means blended into the albedo.

    The reads' means, footprint by footprint (``tiling_reads``' order), are summed by weight into
    the footprint's Gaussian g, divided by the root of the sum of its squared weights, mapped back
    through the inverse lookups of its level and the next, blended by ``blend``, and out of the
    principal axes, held at 0 or more.

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
    channels, n = out.shape
    bins, last = lookups.shape[2], lookups.shape[0] - 1
    reads = values.shape[1]
    if channels == 3:
        _tiling_lookup3(values, read_pixel, read_weight, weight, level, blend, lookups, center, basis, out)
        return
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
def _bilinear3(flat, off, rows, cols, periodic, col, row, step):
    """The three channels of the bilinear sample at (col, row) of the level at ``off``."""
    f, fc, fr = _first_texel(3, off, rows, cols, periodic, col, row)
    return (_bilinear(flat, f, 3, step, 0, fc, fr), _bilinear(flat, f, 3, step, 1, fc, fr),
            _bilinear(flat, f, 3, step, 2, fc, fr))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _axes(dxdu, dxdv, dydu, dydv):
    """``camera._footprint_axes`` of one Jacobian, the same float64 operations in the same order:
    (major, minor, ex, ey)."""
    a = dxdu * dxdu + dxdv * dxdv
    b = dxdu * dydu + dxdv * dydv
    c = dydu * dydu + dydv * dydv
    bb = b * b
    half = a - c
    half *= half
    half *= 0.25
    half += bb
    half = np.sqrt(half)
    big = a + c
    big *= 0.5
    big += half
    major = np.sqrt(big)
    minor = dxdu * dydv
    minor -= dxdv * dydu
    minor = abs(minor)
    minor /= major
    if not major > 0:
        minor = 0.0
    big_c = big - c
    big_a = big - a
    if big_c * big_c + bb >= bb + big_a * big_a:
        ex, ey = big_c, b
    else:
        ex, ey = b, big_a
    norm = np.sqrt(ex * ex + ey * ey)
    if not np.isfinite(norm):
        norm = np.hypot(ex, ey)
    if norm <= 1e-12 * max(big, 1e-300):
        return major, minor, 1.0, 0.0
    return major, minor, ex / norm, ey / norm


@njit(cache=True, nogil=True, error_model="numpy")
def footprint_axes(dxdu, dxdv, dydu, dydv):
    """``_axes`` (``camera._footprint_axes``) of every Jacobian.

    Parameters
    ----------
    dxdu, dxdv, dydu, dydv : numpy.ndarray
        (n,) float64, the Jacobian's entries [m per pixel].

    Returns
    -------
    major, minor : numpy.ndarray
        (n,) float64, the ellipse's box widths along its axes [m].
    ex, ey : numpy.ndarray
        (n,) float64, the unit vector of its major axis [1].
    """
    n = dxdu.shape[0]
    out = np.empty((4, n))
    for i in range(n):
        out[0, i], out[1, i], out[2, i], out[3, i] = _axes(dxdu[i], dxdv[i], dydu[i], dydv[i])
    return out[0], out[1], out[2], out[3]


@njit(cache=True, nogil=True, error_model="numpy")
def row_footprints(rows, part, width, height, focal, position, right, up, forward, min_downward,
                   x, y, major, minor, ex, ey, distance):
    """``camera._row_footprints`` (``_row_hits`` and ``_footprint_axes``) pixel by pixel.

    The same float64 operations in the same order as the array version.

    Parameters
    ----------
    rows : numpy.ndarray
        (r,) float64, image rows that see ground.
    part : numpy.ndarray
        (r,) float64, the fraction of each row below the horizon [1].
    width, height : int
        The image's size [pixel].
    focal : float
        The focal length [pixel].
    position : numpy.ndarray
        (3,) float64, the camera's position [m].
    right, up, forward : numpy.ndarray
        (3,) float64, the camera's unit axes [1].
    min_downward : float
        The least downward slope of a ray (``camera.MIN_DOWNWARD``) [1].
    x, y : numpy.ndarray
        (r width,) float64, written: the ground points seen [m].
    major, minor : numpy.ndarray
        (r width,) float64, written: the footprints' box widths [m].
    ex, ey : numpy.ndarray
        (r width,) float64, written: the unit vectors of their major axes [1].
    distance : numpy.ndarray
        (r width,) float32, written: the distance to the ground point [m].
    """
    height_m = position[2]
    fx0, fx1 = right[0] / focal, right[1] / focal
    fz0 = right[2] / focal
    gx0, gx1, gz0 = -up[0] / focal, -up[1] / focal, -up[2] / focal
    i = 0
    for q in range(rows.shape[0]):
        p = part[q]
        v = rows[q] + 1.0 - 0.5 * p
        down = (0.5 * height - v) / focal
        for col in range(width):
            u = col + 0.5
            across = (u - 0.5 * width) / focal
            wx = forward[0] + across * right[0] + down * up[0]
            wy = forward[1] + across * right[1] + down * up[1]
            w_z = forward[2] + across * right[2] + down * up[2]
            wz = min(w_z, -min_downward)
            t = height_m / -wz
            x[i] = position[0] + t * wx
            y[i] = position[1] + t * wy
            slope = fz0 / wz
            dxdu = t * (fx0 - wx * slope) * 1.0
            dydu = t * (fx1 - wy * slope) * 1.0
            slope = gz0 / wz
            dxdv = t * (gx0 - wx * slope) * p
            dydv = t * (gx1 - wy * slope) * p
            major[i], minor[i], ex[i], ey[i] = _axes(dxdu, dxdv, dydu, dydv)
            distance[i] = np.float32(t * np.sqrt(wx * wx + wy * wy + w_z * w_z))
            i += 1


@njit(cache=True, nogil=True, error_model="numpy")
def filter_choice(texel, lod_bias, count, max_taps, major, minor, taps, level, blend):
    """``camera._filter_choice`` footprint by footprint, the same float64 operations.

    Parameters
    ----------
    texel : float
        The mip map's finest texel, sqrt(px py) [m].
    lod_bias : float
        Added to the level of detail, log2 of the footprint's width over ``texel`` [1].
    count : int
        The mip map's levels.
    max_taps : int
        The most taps a footprint takes (``camera.MAX_TAPS``).
    major, minor : numpy.ndarray
        (n,) float64, the footprints' box widths [m].
    taps : numpy.ndarray
        (n,) int8, written: the tap count.
    level : numpy.ndarray
        (n,) int16, written: the level.
    blend : numpy.ndarray
        (n,) float32, written: the blend towards the next level, in [0, 1) [1].
    """
    big = np.finfo(np.float64).max
    top = float(count - 1)
    for j in range(major.shape[0]):
        a, b = major[j], minor[j]
        ratio = a / (b if b >= texel or b != b else texel)  # np.maximum: NaN wins
        if ratio != ratio:
            ratio = 1.0
        elif ratio == np.inf:
            ratio = float(max_taps)
        elif ratio == -np.inf:
            ratio = -big
        ratio -= 1e-3
        ratio = np.ceil(ratio)
        n = min(max(ratio, 1.0), float(max_taps))
        lod = a / np.float64(np.int8(n))
        if b != b or lod != lod:
            lod = np.nan
        elif b > lod:
            lod = b
        lod /= texel
        lod = np.log2(lod)
        lod += lod_bias
        if lod != lod:
            lod = 0.0
        lod = min(max(lod, 0.0), top)
        floor = np.floor(lod)
        k = np.int16(floor)
        t = lod - floor
        if t > 1.0 - 1e-6:
            k += np.int16(1)
            t = 0.0
        elif t < 1e-6:
            t = 0.0
        taps[j] = np.int8(n)
        level[j] = k
        blend[j] = np.float32(t)


@njit(cache=True, nogil=True, error_model="numpy")
def halve_level(texels, source, rows, cols, target):
    """``camera._constant_levels``'s step: one level averaged 2 x 2 into the next, in place.

    Pairs of rows first, then pairs of columns, each sum halved in float32. An odd size's missing row
    or column is the border's value, as the padding of the array version.

    Parameters
    ----------
    texels : numpy.ndarray
        (texels, channels) float32, a mip map's texels (``camera.MipMap.texels``); the level at
        ``target`` is written.
    source : int
        The stored level's first texel (with its border of the outside value) [texel].
    rows, cols : int
        The stored level's size, without the border.
    target : int
        The next level's first texel; it is (ceil(rows / 2), ceil(cols / 2)) [texel].
    """
    channels = texels.shape[1]
    step, out_rows, out_cols = cols + 2, (rows + 1) // 2, (cols + 1) // 2
    half = np.float32(0.5)
    for i in range(out_rows):
        top = source + (2 * i + 1) * step + 1
        bottom = top + step
        out = target + (i + 1) * (out_cols + 2) + 1
        for j in range(out_cols):
            for k in range(channels):
                left = (texels[top + 2 * j, k] + texels[bottom + 2 * j, k]) * half
                right = (texels[top + 2 * j + 1, k] + texels[bottom + 2 * j + 1, k]) * half
                texels[out + j, k] = (left + right) * half



@njit(cache=True, nogil=True, error_model="numpy")
def resample_separable(raster, row_at, row_weight, col_at, col_weight, out):
    """``shadow.resample_bilinear``'s ``R @ image @ C.T`` per channel.

    R and C are given by the columns they read and their weights, k per row: each output value is
    the float32 sum, from 0 and in that order, of weights times values, as scipy's sparse products;
    rows first, then columns.

    Parameters
    ----------
    raster : numpy.ndarray
        (channels, rows, cols) float32, the coarse raster (irradiance [klx]).
    row_at : numpy.ndarray
        (R rows, k) int64, the raster rows each output row reads.
    row_weight : numpy.ndarray
        (R rows, k) float32, their weights [1].
    col_at : numpy.ndarray
        (C rows, k) int64, the raster columns each output column reads.
    col_weight : numpy.ndarray
        (C rows, k) float32, their weights [1].
    out : numpy.ndarray
        (channels, R rows, C rows) float32, written: the resampled raster, in ``raster``'s units.
    """
    along = np.empty(raster.shape[2], dtype=np.float32)
    for ch in range(raster.shape[0]):
        for i in range(out.shape[1]):
            along[:] = 0.0
            for p in range(row_at.shape[1]):
                weight, row = row_weight[i, p], row_at[i, p]
                for c in range(raster.shape[2]):
                    along[c] += weight * raster[ch, row, c]
            if col_at.shape[1] == 2:  # bilinear: two reads a value, unrolled
                for j in range(out.shape[2]):
                    total = np.float32(0.0) + col_weight[j, 0] * along[col_at[j, 0]]
                    out[ch, i, j] = total + col_weight[j, 1] * along[col_at[j, 1]]
            else:
                for j in range(out.shape[2]):
                    total = np.float32(0.0)
                    for p in range(col_at.shape[1]):
                        total += col_weight[j, p] * along[col_at[j, p]]
                    out[ch, i, j] = total


@njit(cache=True, nogil=True, error_model="numpy")
def haze_over(background, transmittance, veil, horizon):
    """``frame.render_frame``'s haze, in place: the background becomes ``T B + (1 - T) L_horizon + 0``.

    In the float32 operations and order of the array version (``B *= T; B += veil * L; B + 0``, the
    last turning -0 into +0).

    Parameters
    ----------
    background : numpy.ndarray
        (rows, cols, 3) float32 radiance B, overwritten [kcd/m^2].
    transmittance : numpy.ndarray
        (rows, cols, 1) float32, T [1].
    veil : numpy.ndarray
        (rows, cols, 1) float32, 1 - T [1].
    horizon : numpy.ndarray
        (cols, 3) float32, the sky's radiance at the horizon L_horizon per column [kcd/m^2].
    """
    zero = np.float32(0.0)
    for i in range(background.shape[0]):
        for j in range(background.shape[1]):
            t, v = transmittance[i, j, 0], veil[i, j, 0]
            for k in range(background.shape[2]):
                background[i, j, k] = (background[i, j, k] * t + v * horizon[j, k]) + zero


@njit(cache=True, nogil=True, error_model="numpy")
def sky_rows(along, row_at, row_frac, first, count, clouded, transmittance, glow, weights, out):
    """Rows ``first`` to ``first + count`` of ``sky.ProceduralSky.raster``'s weighted raster.

    The clear sky interpolated between node rows ``row_at`` and ``row_at + 1`` by ``row_frac``,
    where ``clouded`` times the clouds' transmittance clipped to [0, 1] and plus their ``glow``,
    times the cells' solid angles: the float32 operations of the array version, in its order.

    Parameters
    ----------
    along : numpy.ndarray
        (3, nodes, cols) float32, the clear sky's radiance at the node rows [kcd/m^2].
    row_at : numpy.ndarray
        (rows,) int, each raster row's node row.
    row_frac : numpy.ndarray
        (rows,) float32, its fraction towards the next node row [1].
    first, count : int
        The raster rows written.
    clouded : bool
        Whether there are clouds (else ``transmittance`` and ``glow`` are not read).
    transmittance : numpy.ndarray
        (count, cols) float64, the clouds' transmittance [1].
    glow : numpy.ndarray
        (count, cols, 3) float32, the clouds' scattered light [kcd/m^2].
    weights : numpy.ndarray
        (rows, cols) float32, the cells' solid angles [sr].
    out : numpy.ndarray
        (3, rows, cols) float32, written: the weighted raster [klx].
    """
    one = np.float32(1.0)
    for r in range(count):
        row = first + r
        f = row_frac[row]
        g = one - f
        a = row_at[row]
        for c in range(3):
            for j in range(out.shape[2]):
                value = along[c, a, j] * g + along[c, a + 1, j] * f
                if clouded:
                    value *= np.float32(min(max(transmittance[r, j], 0.0), 1.0))
                    value += glow[r, j, c]
                out[c, row, j] = value * weights[row, j]


@njit(cache=True, nogil=True, error_model="numpy")
def cloud_field(flat, offsets, sides, rows, cols, direct, taps, k0, blend, major, ex, ey, out,
                tile_blend, seed, base_row, base_col):
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
        Every level of the noise in one flat float64 array (``cloud_noise._packed``) [1].
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
    n_levels = sides.shape[0]
    side0 = sides[0]
    band = tile_blend * side0
    seed_key = _seed_key(seed)
    weights = np.empty((2, 4))
    index = np.empty((2, 4), dtype=np.intp)
    copies = np.empty((2, 2), dtype=np.int64)  # per axis: the copies read, lower first
    shares = np.empty((2, 2))  # per axis: their smoothstep weights
    last_row = last_col = 0  # the last copy hashed, and its shift
    last_shift_row = last_shift_col = 0.0
    for i in range(rows.shape[0]):
        n_taps = 1 if direct else taps[i]
        total = 0.0
        for t in range(n_taps):
            if direct:
                tap_row, tap_col = rows[i], cols[i]
            else:
                step = ((t + 0.5) / n_taps - 0.5) * major[i]  # [texel] from the centre
                tap_row = rows[i] + -ey[i] * step
                tap_col = cols[i] + ex[i] * step
            count_row = count_col = 1
            for axis in range(2):
                x = tap_row if axis == 0 else tap_col
                copy = math.floor(x / side0 + 0.5)
                edge = x - (copy - 0.5) * side0  # [texel] from the copy's lower edge
                copies[axis, 0] = copy + (base_row if axis == 0 else base_col)
                shares[axis, 0] = 1.0
                if edge < 0.5 * band or edge > side0 - 0.5 * band:
                    u = edge / band + 0.5 if edge < 0.5 * band else (edge - side0) / band + 0.5
                    u = min(max(u, 0.0), 1.0)
                    upper_share = u * u * (3.0 - 2.0 * u)
                    if edge < 0.5 * band:
                        copies[axis, 1] = copies[axis, 0]
                        copies[axis, 0] -= 1
                    else:
                        copies[axis, 1] = copies[axis, 0] + 1
                    shares[axis, 0] = 1.0 - upper_share
                    shares[axis, 1] = upper_share
                    if axis == 0:
                        count_row = 2
                    else:
                        count_col = 2
            weighted = 0.0
            squares = 0.0
            for cr in range(count_row):
                for cc in range(count_col):
                    shift_row = shift_col = 0.0
                    if copies[0, cr] == last_row and copies[1, cc] == last_col:  # as the last read's
                        shift_row, shift_col = last_shift_row, last_shift_col
                    elif copies[0, cr] != 0 or copies[1, cc] != 0:  # the copy's shift, hashed
                        key = _vertex_key(copies[0, cr], copies[1, cc], seed_key)
                        shift_row = _unit_hash(key) * side0
                        shift_col = _unit_hash(key ^ _SECOND_KEY) * side0
                        last_row, last_col = copies[0, cr], copies[1, cc]
                        last_shift_row, last_shift_col = shift_row, shift_col
                    w = shares[0, cr] * shares[1, cc]
                    at_row = tap_row + shift_row
                    at_col = tap_col + shift_col
                    k = 0 if direct else k0[i]
                    upper = (not direct) and blend[i] > 0 and k + 1 < n_levels
                    finer = 0.0
                    for level in range(k, k + 2 if upper else k + 1):
                        side = sides[level]
                        order = 3 if level == 0 else 1
                        for axis in range(2):
                            x = at_row if axis == 0 else at_col
                            if not direct:
                                x = (x + 0.5) / 2.0**level - 0.5  # texel centres of the level
                            if x < 0:  # scipy's grid-wrap of a coordinate
                                x = 0.0 if side <= 1 else x + side * (int((-1.0 - x) / side) + 1)
                            elif x > side - 1:
                                x = 0.0 if side <= 1 else x - side * int(x / side)
                            if not x > -1.0:  # NaN: scipy's constant 0
                                break
                            start = int(math.floor(x)) - order // 2
                            f = x - math.floor(x)
                            if order == 3:
                                z = 1.0 - f
                                weights[axis, 1] = (f * f * (f - 2.0) * 3.0 + 4.0) / 6.0
                                weights[axis, 2] = (z * z * (z - 2.0) * 3.0 + 4.0) / 6.0
                                weights[axis, 0] = z * z * z / 6.0
                            else:
                                weights[axis, 0] = 1.0 - f
                            last = 1.0
                            for j in range(order):
                                last -= weights[axis, j]
                            weights[axis, order] = last
                            wraps = start < 0 or start + order >= side
                            for j in range(order + 1):
                                index[axis, j] = (start + j) % side if wraps else start + j
                        value = 0.0
                        if x > -1.0:
                            base = offsets[level]
                            for a in range(order + 1):
                                row = base + index[0, a] * side
                                for b in range(order + 1):
                                    value += flat[row + index[1, b]] * weights[0, a] * weights[1, b]
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
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def lattice_read(flat, corner, taps, lattice, out):
    """``brdf_bands.sky_ratio``'s bilinear read of a lattice at n points (``brdf_bands._lattice_read_arrays``).

    Point p takes the four values from flat index corner[p] (its first corner), + 1, + lattice,
    + lattice + 1 with weights taps[:, p], summed in that order in float32.

    Parameters
    ----------
    flat : numpy.ndarray
        (channels, lattice * lattice) float32, the lattice's values [1].
    corner : numpy.ndarray
        (n,) intp, each point's first corner.
    taps : numpy.ndarray
        (4, n) float32, the bilinear weights of the four corners [1].
    lattice : int
        The lattice's side [count].
    out : numpy.ndarray
        (channels, n) float32, written: the values read [1].
    """
    for p in range(corner.shape[0]):
        k = corner[p]
        for c in range(flat.shape[0]):
            v = flat[c, k] * taps[0, p]
            v += flat[c, k + 1] * taps[1, p]
            v += flat[c, k + lattice] * taps[2, p]
            v += flat[c, k + lattice + 1] * taps[3, p]
            out[c, p] = v
