"""Compiled loops of the camera's anisotropic filtering: the filtered reads of a mip map (``mipmap.filtered_read``),
the footprints of the ground's pixels (``pinhole._row_footprints``, ``mipmap.footprint_axes``), the choice of taps
and level (``mipmap.filter_choice``) and the mip levels halved in place (``mipmap._constant_mipmap``). Each does
what its array version does, float32 operation for float32 operation in the same order, and the tests hold it to
that version's bits.

The filtering's method is the one documented in ``mipmap.sample_footprint`` and ``albedo``:
these loops do it footprint by footprint, every tap of a footprint in turn, with the same float32 arithmetic
and the same order of operations as the array version (tests/reference.py's ``_tap_mean``, ``_bilinear``), so
that the footprints need not be grouped and sorted by level.
The tap counts, levels and blends come from ``mipmap.filter_choice`` (here ``filter_choice``), computed once
for all the reads that share a footprint. Three channels: ``tap_table`` finds where the taps fall and
``filtered3_at`` reads there; a still camera reads each frame's raster at the same places, so that it finds
them once (the same bits; docs/accuracy.md, "A still camera's taps"). Imported lazily: numba costs 0.3 s to
import.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.core.cores import in_shares
from pipeline.kernels import HELPER, LOOP

__all__ = ["filtered", "tap_table", "filtered3_at", "footprint_axes", "row_footprints", "filter_choice",
           "halve_level"]

_FLOAT64_MAX = float(np.finfo(np.float64).max)
"""The largest float64, ``filter_choice``'s stand-in for -inf (a constant: ``np.finfo`` in a loop compiles two
functions more)."""


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _first_texel(channels, offset, rows, cols, periodic, col, row):
    """tests/reference.py's ``_first_texel`` of one point: the flat index of channel 0 of the first of the four
    texels of a bilinear sample at texel coordinates (col, row), and the fractions (fc, fr)
    float32 beyond it."""
    if not periodic:
        col = min(max(col, -1.0), float(cols))
        row = min(max(row, -1.0), float(rows))
    c0f, r0f = np.floor(col), np.floor(row)
    fc = np.float32(col - c0f)
    fr = np.float32(row - r0f)
    c0, r0 = np.int64(c0f), np.int64(r0f)
    if periodic:  # a mask for a power of two, as tests/reference.py's _wrap: no division
        c0 = c0 & (cols - 1) if cols & (cols - 1) == 0 else c0 % cols
        r0 = r0 & (rows - 1) if rows & (rows - 1) == 0 else r0 % rows
    return ((r0 * (cols + 2) + c0) + offset + cols + 3) * channels, fc, fr


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _bilinear(flat, first, channels, step, k, fc, fr):
    """Channel ``k`` of the bilinear sample whose first texel is ``first`` (``_first_texel``),
    ``step`` the flat stride of a stored row: tests/reference.py's ``_bilinear`` float32 arithmetic, each
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
    """tests/reference.py's ``_texel_coords`` of one point and step."""
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


def filtered(flat: np.ndarray, channels: int, offsets: np.ndarray, shapes: np.ndarray, origins: np.ndarray,
             pixels: np.ndarray, periodic: bool, x: np.ndarray, y: np.ndarray, footprint: np.ndarray,
             major: np.ndarray, ex: np.ndarray, ey: np.ndarray, taps: np.ndarray, level: np.ndarray,
             blend: np.ndarray, out: np.ndarray) -> None:
    """``mipmap.filtered_read``: each read's mean into ``out``.

    Read r is centred on (x[r], y[r]) with the ellipse and filter of footprint j = footprint[r]
    (several reads may share one: the stochastic tiling's); read r takes taps[j] trilinear samples
    (tests/reference.py's ``_tap_mean``, the same float32 arithmetic in the same order), in level level[j]
    blended by blend[j] towards the next when > 0. Three channels: where the taps fall first
    (``tap_table``), then read there (``filtered3_at``), the same bits as reading each tap as it is
    found; the loops that a still camera's later frames run anyway, so that a run compiles no loop
    of its own for its first frame (docs/accuracy.md, "Compiling after an install"). Other counts
    of channels: channel by channel (``_filtered_channels``). The reads are shared among the
    threads of ``cores.loop_threads``.

    Parameters
    ----------
    flat : numpy.ndarray
        (texels x channels,) float32, every level of the mip map flat (``mipmap.MipMap.texels``),
        each level stored with its border of one texel (``mipmap.level_tables``).
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
    if channels == 3:  # each read's footprint's values gathered: read r is footprint r, as tap_table takes them
        read_taps, read_level, read_blend = taps[footprint], level[footprint], blend[footprint]
        kept = tap_table(channels, offsets, shapes, origins, pixels, periodic, x, y, major[footprint], ex[footprint],
                         ey[footprint], read_taps, read_level, read_blend)
        in_shares(x.shape[0], lambda start, stop: filtered3_at(flat, shapes, read_taps, read_level, read_blend, *kept,
                                                               out, start, stop))
        return
    in_shares(x.shape[0], lambda start, stop: _filtered_channels(
        flat, channels, offsets, shapes, origins, pixels, periodic, x, y, footprint, major, ex, ey, taps, level, blend,
        out, start, stop))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _read(r, channels, offsets, shapes, origins, pixels, x, y, footprint, major, ex, ey, taps, level, blend):
    """Read r's taps as ``filtered`` lays them out: (blend t, taps n, blended, the first tap's (col, row) and the
    step between taps (dcol, drow) in level ``level[j]``, its rows, cols and first texel, the same in the next
    level (the same level when not blended), the two levels' row strides in ``flat``, n as float32)."""
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
    return (t, n, blended, col0, row0, dcol, drow, rows, cols, off, colb0, rowb0, dcolb, drowb, rowsb, colsb, offb,
            step, stepb, nf)


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def _filtered_channels(flat, channels, offsets, shapes, origins, pixels, periodic, x, y, footprint, major, ex, ey,
                       taps, level, blend, out, start, stop):
    """``filtered`` of any count of channels, reads start to stop - 1."""
    for r in range(start, stop):
        (t, n, blended, col0, row0, dcol, drow, rows, cols, off, colb0, rowb0, dcolb, drowb, rowsb, colsb, offb,
         step, stepb, nf) = _read(r, channels, offsets, shapes, origins, pixels, x, y, footprint, major, ex, ey, taps,
                                  level, blend)
        # each tap's texel found once, then every channel read
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


def tap_table(channels: int, offsets: np.ndarray, shapes: np.ndarray, origins: np.ndarray, pixels: np.ndarray,
              periodic: bool, x: np.ndarray, y: np.ndarray, major: np.ndarray, ex: np.ndarray, ey: np.ndarray,
              taps: np.ndarray, level: np.ndarray,
              blend: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where ``filtered``'s taps fall for read r = footprint r, for ``filtered3_at``: each tap's first
    texel and fractions (``_first_texel``), the same float64 steps along the major axis in the same
    order, and after each tap its sample in the next level when blended.

    Parameters
    ----------
    channels, offsets, shapes, origins, pixels, periodic, x, y, major, ex, ey, taps, level, blend
        As for ``filtered``.

    Returns
    -------
    start : numpy.ndarray
        (m + 1,) int64: read r's samples are ``start[r]`` to ``start[r + 1]``.
    first : numpy.ndarray
        (samples,) int64: each sample's first texel in the flat texels (``_first_texel``).
    fc, fr : numpy.ndarray
        (samples,) float32: its fractions beyond that texel along a row and a column [1].
    """
    samples = int(np.sum(taps.astype(np.int64) * np.where(blend > 0, 2, 1)))
    start, first = np.empty(len(x) + 1, dtype=np.int64), np.empty(samples, dtype=np.int64)
    fc, fr = np.empty(samples, dtype=np.float32), np.empty(samples, dtype=np.float32)
    _tap_table(channels, offsets, shapes, origins, pixels, periodic, x, y, major, ex, ey, taps, level, blend, start,
               first, fc, fr)
    return start, first, fc, fr


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def _tap_table(channels, offsets, shapes, origins, pixels, periodic, x, y, major, ex, ey, taps, level, blend, start,
               first, fc, fr):
    """``tap_table``'s loop, into its arrays: read r's taps where ``_read`` puts them, level by level (a
    blended read's samples alternate between its two levels; each level's steps are the same float64 sums in
    the same order), so that ``_coords`` and ``_first_texel`` are inlined once each (docs/accuracy.md,
    "Compiling after an install")."""
    k = np.int64(0)
    for r in range(x.shape[0]):
        lv, n = np.int64(level[r]), np.int64(taps[r])
        stride = np.int64(2) if blend[r] > 0 else np.int64(1)
        spacing = major[r] / n
        offset = (0.5 - 0.5 * n) * spacing
        sx, sy, dx, dy = x[r] + offset * ex[r], y[r] + offset * ey[r], spacing * ex[r], spacing * ey[r]
        start[r] = k
        for b in range(stride):
            m = lv + b
            col, row, dcol, drow = _coords(origins[m, 0], origins[m, 1], pixels[m, 0], pixels[m, 1], sx, sy, dx, dy)
            rows, cols, off = shapes[m, 0], shapes[m, 1], offsets[m]
            for i in range(k + b, k + n * stride, stride):
                first[i], fc[i], fr[i] = _first_texel(channels, off, rows, cols, periodic, col, row)
                col += dcol
                row += drow
        k += n * stride
    start[x.shape[0]] = k


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def filtered3_at(flat: np.ndarray, shapes: np.ndarray, taps: np.ndarray, level: np.ndarray, blend: np.ndarray,
                 start: np.ndarray, first: np.ndarray, fc: np.ndarray, fr: np.ndarray, out: np.ndarray, begin: int,
                 end: int) -> None:
    """``filtered`` of three channels, read r = footprint r, its samples where ``tap_table`` found
    them: tests/reference.py's ``_tap_mean`` float32 arithmetic in the same order, each tap's
    bilinear sample (``_bilinear``) blended towards the next level's (a still camera reads the
    same places of each frame's raster, so the places are found once). The blend, the sum and the
    mean are written here, not in helpers: each helper is one more function for numba to compile.

    Parameters
    ----------
    flat, shapes, taps, level, blend
        As for ``filtered`` (three channels).
    start, first, fc, fr : numpy.ndarray
        ``tap_table``'s, for these footprints and a mip map of this geometry.
    out : numpy.ndarray
        (3, m) float32, written: the reads' means, in the raster's units.
    begin, end : int
        The reads done: begin to end - 1 (``cores.in_shares``'s share).
    """
    for r in range(begin, end):
        lv, t, n = np.int64(level[r]), blend[r], np.int64(taps[r])
        blended = t > 0
        step = (shapes[lv, 1] + 2) * 3
        stepb = (shapes[lv + 1, 1] + 2) * 3 if blended else step
        k = start[r]
        t0 = t1 = t2 = np.float32(0.0)
        # the channels as int64, not literals: numba compiles a helper once per literal argument
        c0, c1, c2 = np.int64(0), np.int64(1), np.int64(2)
        for i in range(n):
            f, c, w = first[k], fc[k], fr[k]
            s0, s1, s2 = (_bilinear(flat, f, 3, step, c0, c, w), _bilinear(flat, f, 3, step, c1, c, w),
                          _bilinear(flat, f, 3, step, c2, c, w))
            k += 1
            if blended:
                f, c, w = first[k], fc[k], fr[k]
                u0, u1, u2 = (_bilinear(flat, f, 3, stepb, c0, c, w), _bilinear(flat, f, 3, stepb, c1, c, w),
                              _bilinear(flat, f, 3, stepb, c2, c, w))
                k += 1
                s0 += (u0 - s0) * t
                s1 += (u1 - s1) * t
                s2 += (u2 - s2) * t
            if i == 0:  # the first tap starts the sum
                t0, t1, t2 = s0, s1, s2
            else:
                t0, t1, t2 = t0 + s0, t1 + s1, t2 + s2
        nf = np.float32(n)
        out[0, r] = t0 / nf
        out[1, r] = t1 / nf
        out[2, r] = t2 / nf


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _axes(dxdu, dxdv, dydu, dydv):
    """``mipmap.footprint_axes`` of one Jacobian, the same float64 operations in the same order:
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def footprint_axes(dxdu: np.ndarray, dxdv: np.ndarray, dydu: np.ndarray,
                   dydv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``_axes`` (``mipmap.footprint_axes``) of every Jacobian.

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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def row_footprints(rows: np.ndarray, part: np.ndarray, width: int, height: int, focal: float, position: np.ndarray,
                   right: np.ndarray, up: np.ndarray, forward: np.ndarray, min_downward: float, x: np.ndarray,
                   y: np.ndarray, major: np.ndarray, minor: np.ndarray, ex: np.ndarray, ey: np.ndarray,
                   distance: np.ndarray) -> None:
    """``pinhole._row_footprints`` (``row_hits`` and ``mipmap.footprint_axes``) pixel by pixel.

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
        The least downward slope of a ray (``pinhole.MIN_DOWNWARD``) [1].
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def filter_choice(texel: float, lod_bias: float, count: int, max_taps: int, major: np.ndarray, minor: np.ndarray,
                  taps: np.ndarray, level: np.ndarray, blend: np.ndarray) -> None:
    """``mipmap.filter_choice`` footprint by footprint, the same float64 operations.

    Parameters
    ----------
    texel : float
        The mip map's finest texel, sqrt(px py) [m].
    lod_bias : float
        Added to the level of detail, log2 of the footprint's width over ``texel`` [1].
    count : int
        The mip map's levels.
    max_taps : int
        The most taps a footprint takes (``mipmap.MAX_TAPS``).
    major, minor : numpy.ndarray
        (n,) float64, the footprints' box widths [m].
    taps : numpy.ndarray
        (n,) int8, written: the tap count.
    level : numpy.ndarray
        (n,) int16, written: the level.
    blend : numpy.ndarray
        (n,) float32, written: the blend towards the next level, in [0, 1) [1].
    """
    big = _FLOAT64_MAX
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def halve_level(texels: np.ndarray, source: int, rows: int, cols: int, target: int) -> None:
    """One step of the constant mip map's levels (``mipmap._constant_mipmap``; its numpy reference
    tests/reference.py, ``constant_levels``): one level averaged 2 x 2 into the next, in place.

    Pairs of rows first, then pairs of columns, each sum halved in float32. An odd size's missing row
    or column is the border's value, as the padding of the array version.

    Parameters
    ----------
    texels : numpy.ndarray
        (texels, channels) float32, a mip map's texels (``mipmap.MipMap.texels``); the level at
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
