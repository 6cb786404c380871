"""Compiled loops that stand for whole-array expressions of the ground and frame stages, pixel by pixel: the
bilinear resampling of the coarse ground under the sun window (``shadow.resample_bilinear``), the haze over the view
(``frame._apply_haze``), the procedural sky raster's rows (``procedural.ProceduralSky.raster``) and the ground
reflectance's lattice read (``brdf_bands.sky_ratio``), a wall's irradiance read where the camera's points see it
(``view.read_taps``) and its points' sum and cover in each pixel (``view.show_points``), the walls' shade on the
ground (``walls.shade_ground``), a frame's display codes
(``composite.display_codes``, around numpy's power) and the clouds' ``np.interp`` tables
(``clouds.CloudLayer.radiance`` and ``coverage``). Each does what its array version does, float operation for
float operation (float32, or float64 where it widens) in the same order, so that no temporary arrays are built,
and the tests hold it to that version's bits. Imported lazily: numba costs 0.3 s to import.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.kernels import HELPER, LOOP

__all__ = ["resample_separable", "haze_over", "sky_rows", "lattice_read", "taps_read", "points_over", "rows_sum",
           "walls_on_ground", "exposed_display", "display_codes",
           "scattering_weights", "hermite_mean"]


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def resample_separable(raster: np.ndarray, row_at: np.ndarray, row_weight: np.ndarray, col_at: np.ndarray,
                       col_weight: np.ndarray, out: np.ndarray) -> None:
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def haze_over(background: np.ndarray, transmittance: np.ndarray, veil: np.ndarray, horizon: np.ndarray) -> None:
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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def sky_rows(along: np.ndarray, row_at: np.ndarray, row_frac: np.ndarray, first: int, count: int, clouded: bool,
             transmittance: np.ndarray, glow: np.ndarray, weights: np.ndarray, out: np.ndarray) -> None:
    """Rows ``first`` to ``first + count`` of ``procedural.ProceduralSky.raster``'s weighted raster.

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


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def lattice_read(flat: np.ndarray, corner: np.ndarray, taps: np.ndarray, lattice: int, out: np.ndarray) -> None:
    """``brdf_bands.sky_ratio``'s bilinear read of a lattice at n points (tests/reference.py's ``lattice_read_arrays``).

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



@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def taps_read(flat: np.ndarray, top_left: np.ndarray, top_right: np.ndarray, bottom_left: np.ndarray,
              bottom_right: np.ndarray, fx: np.ndarray, fy: np.ndarray, out: np.ndarray, start: int, stop: int) -> None:
    """``view.read_taps``'s bilinear read of a raster at points start to stop - 1.

    Point p takes the values at its four corners, in float64: ``top = v_tl (1 - fx) + v_tr fx``,
    ``bottom = v_bl (1 - fx) + v_br fx``, ``top (1 - fy) + bottom fy``, then float32: the operations of
    the array version, in its order.

    Parameters
    ----------
    flat : numpy.ndarray
        (cells, channels) float32, the raster's cells row by row (irradiance [klx]).
    top_left, top_right, bottom_left, bottom_right : numpy.ndarray
        (n,) int32, each point's four cells in ``flat``.
    fx, fy : numpy.ndarray
        (n,) float32, its fractions across and down from the top-left cell's centre [1].
    out : numpy.ndarray
        (n, channels) float32, rows start to stop - 1 written: the values read, in ``flat``'s units.
    start, stop : int
        The points read.
    """
    for p in range(start, stop):
        x, y = np.float64(fx[p]), np.float64(fy[p])
        gx, gy = 1.0 - x, 1.0 - y
        a, b, c, d = top_left[p], top_right[p], bottom_left[p], bottom_right[p]
        for k in range(flat.shape[1]):
            top = np.float64(flat[a, k]) * gx + np.float64(flat[b, k]) * x
            bottom = np.float64(flat[c, k]) * gx + np.float64(flat[d, k]) * x
            out[p, k] = np.float32(top * gy + bottom * y)


@njit(cache=True, nogil=True, error_model="numpy", **HELPER)
def _bilinear(flat, a, b, c, d, x, y, k):
    """Channel ``k`` of ``flat`` read bilinearly between the rows a, b (top) and c, d (bottom) at the
    fractions x, y, in float64, rounded to float32."""
    gx, gy = 1.0 - x, 1.0 - y
    top = np.float64(flat[a, k]) * gx + np.float64(flat[b, k]) * x
    bottom = np.float64(flat[c, k]) * gx + np.float64(flat[d, k]) * x
    return np.float32(top * gy + bottom * y)


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def points_over(radiance: np.ndarray, distance: np.ndarray, top: int, left: int, cols: int, hit_distance: np.ndarray,
                first: np.ndarray, sample: np.ndarray, flat: np.ndarray, top_left: np.ndarray, top_right: np.ndarray,
                bottom_left: np.ndarray, bottom_right: np.ndarray, fx: np.ndarray, fy: np.ndarray,
                albedo: np.ndarray, scale: np.float32, weight: np.float32, start: int, stop: int) -> None:
    """A wall put into the picture for the box's pixels start to stop - 1 (row by row): a pixel's
    points that meet the wall nearer than its distance are seen; each seen point's bilinear read of
    ``flat`` (``taps_read``'s float operations) times its albedo, ``scale`` and ``weight`` is summed
    from 0 in the points' order; the pixel's radiance becomes ``L (1 - cover) + sum`` with cover the
    seen points times ``weight``, and its distance the nearest seen point's where cover > 1/2.

    Parameters
    ----------
    radiance : numpy.ndarray
        (height, width, channels) float32, the picture; changed in the box [radiance].
    distance : numpy.ndarray
        (height, width) float32, what each pixel sees; changed in the box [m].
    top, left, cols : int
        The box's first row and column, and its columns [pixel].
    hit_distance : numpy.ndarray
        (samples, box pixels) float32, the points' distances to the wall [m].
    first, sample : numpy.ndarray
        ``view.WallPoints``: each box pixel's first point, and each point's sample [1].
    flat : numpy.ndarray
        (cells, channels) float32, the wall's raster [radiance x sr].
    top_left, top_right, bottom_left, bottom_right, fx, fy : numpy.ndarray
        Each point's bilinear taps (``view.BilinearTaps``) [1].
    albedo : numpy.ndarray
        (1, channels) or (points, channels) float32 [1].
    scale, weight : numpy.float32
        The factor after the albedo, and 1 / points a pixel [1].
    start, stop : int
        The box's pixels, row by row.
    """
    each = albedo.shape[0] != 1
    one, half = np.float32(1.0), np.float32(0.5)
    total = np.empty(flat.shape[1], np.float32)
    for p in range(start, stop):
        row, col = top + p // cols, left + p % cols
        behind = distance[row, col]
        count, nearest = np.float32(0.0), np.float32(np.inf)
        total[:] = 0.0
        for j in range(first[p], first[p + 1]):
            there = hit_distance[sample[j], p]
            if there < behind:
                count += one
                nearest = min(nearest, there)
                x, y = np.float64(fx[j]), np.float64(fy[j])
                a, b, c, d = top_left[j], top_right[j], bottom_left[j], bottom_right[j]
                r = j if each else 0
                for k in range(flat.shape[1]):
                    total[k] += _bilinear(flat, a, b, c, d, x, y, k) * albedo[r, k] * scale * weight
        cover = count * weight
        keep = one - cover
        for k in range(radiance.shape[2]):
            radiance[row, col, k] = radiance[row, col, k] * keep + total[k]
        if cover > half:
            distance[row, col] = nearest


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def rows_sum(values: np.ndarray) -> np.ndarray:
    """``values.sum(axis=0)`` of a C-ordered (n, channels) float32 array: row after row from 0, in
    float32, as numpy's reduction over the outer axis adds them (``stages.walls``' mean of a wall's light).

    Parameters
    ----------
    values : numpy.ndarray
        (n, channels) float32.

    Returns
    -------
    numpy.ndarray
        (channels,) float32.
    """
    total = np.zeros(values.shape[1], np.float32)
    for i in range(values.shape[0]):
        for k in range(values.shape[1]):
            total[k] += values[i, k]
    return total


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def walls_on_ground(sky_light: np.ndarray, total: np.ndarray, keep: np.ndarray, factor: np.ndarray,
                    in_front: np.ndarray, front: np.ndarray, back: np.ndarray, sun_keep: np.ndarray, lit: bool,
                    sky_out: np.ndarray, total_out: np.ndarray, start: int, stop: int) -> None:
    """``stages.walls``' ground shaded by its walls, cells start to stop - 1: in float64, the sun's
    part ``total - sky``, then wall by wall ``sky keep + (front or back) factor`` and ``sun sun_keep``
    (where ``lit``); then ``sky`` and ``sky + sun`` in float32: the array version's operations in its order.

    Parameters
    ----------
    sky_light, total : numpy.ndarray
        (rows, cols, channels) the ground's sky part and its total [radiance x sr].
    keep : numpy.ndarray
        (walls, rows, cols, channels) float64, 1 - each wall's hidden sky over the open sky's [1].
    factor : numpy.ndarray
        (walls, rows, cols) float64, each wall's view factor [1].
    in_front : numpy.ndarray
        (walls, rows, cols) bool, the cell's centre in front of the wall.
    front, back : numpy.ndarray
        (walls, channels) float64, the light each wall sends per unit view factor from its front and
        its back [radiance x sr].
    sun_keep : numpy.ndarray
        (walls, rows, cols) float64, 1 - each wall's sun shadow's cover of the cell (read where ``lit``) [1].
    lit : bool
        Whether the sun lights the ground.
    sky_out, total_out : numpy.ndarray
        (rows, cols, channels) float32, cells start to stop - 1 (row by row) written [radiance x sr].
    start, stop : int
        The cells, row by row.
    """
    cols = sky_light.shape[1]
    for n in range(start, stop):
        i, j = n // cols, n % cols
        for c in range(sky_light.shape[2]):
            sky = np.float64(sky_light[i, j, c])
            sun = np.float64(total[i, j, c]) - sky
            for w in range(keep.shape[0]):
                light = front[w, c] if in_front[w, i, j] else back[w, c]
                sky = sky * keep[w, i, j, c] + light * factor[w, i, j]
                if lit:
                    sun = sun * sun_keep[w, i, j]
            sky_out[i, j, c] = np.float32(sky)
            total_out[i, j, c] = np.float32(sky + sun)


_ACES = tuple(np.float32(c) for c in (0.0, 1.0, 2.51, 0.03, 2.43, 0.59, 0.14))
_SRGB = tuple(np.float32(c) for c in (0.0031308, 12.92, 1.055, 0.055, 255.0, 0.5))


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def exposed_display(radiance: np.ndarray, gain: np.ndarray, filmic: bool, out: np.ndarray) -> None:
    """``composite.display`` up to the sRGB power: exposed, ACES-filmic if ``filmic``, clipped.

    ``x = max(L g, 0)`` then ``x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`` clipped to [0, 1]
    (``composite.aces_filmic``), or ``L g`` clipped to [0, 1]: the float32 operations of the array
    versions, in their order, a row at a time with the gains laid along the row (so that the
    loop is vectorised).

    Parameters
    ----------
    radiance : numpy.ndarray
        (rows, cols, 3) C-contiguous float32 scene-linear radiance L [kcd/m^2].
    gain : numpy.ndarray
        (3,) float32, exposure times white balance g per channel [m^2/kcd].
    filmic : bool
        Whether the filmic roll-off is applied.
    out : numpy.ndarray
        (rows, cols, 3) C-contiguous float32, written: display-linear values in [0, 1] [1].
    """
    zero, one, a, b, c, d, e = _ACES
    rows, width = radiance.shape[0], radiance.shape[1] * 3
    source, linear = radiance.reshape(rows, width), out.reshape(rows, width)
    gains = np.empty(width, dtype=np.float32)
    for j in range(width):
        gains[j] = gain[j % 3]
    for r in range(rows):
        row, line = source[r], linear[r]
        for j in range(width):
            x = row[j] * gains[j]
            if filmic:
                x = max(x, zero)
                x = (x * a + b) * x / ((x * c + d) * x + e)
            line[j] = min(max(x, zero), one)


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def display_codes(linear: np.ndarray, powered: np.ndarray, half_dither: np.ndarray, out: np.ndarray) -> None:
    """``composite.srgb_encode`` from its power on, then ``io.write_png``'s 8-bit codes.

    ``12.92 x`` where ``x <= 0.0031308``, else ``1.055 x^(1/2.4) - 0.055``; clipped to [0, 1],
    then ``floor(v 255 + 0.5 + n)`` clipped to [0, 255], n the dither: the float32 operations of
    the array versions, in their order.

    Parameters
    ----------
    linear : numpy.ndarray
        (rows, cols, 3) C-contiguous float32 display-linear values x in [0, 1] (``exposed_display``),
        as are the other arrays [1].
    powered : numpy.ndarray
        (rows, cols, 3) float32, x^(1/2.4) as numpy's power gives it [1].
    half_dither : numpy.ndarray
        (rows, cols, 3) float32, n (``io.half_dither``) [1].
    out : numpy.ndarray
        (rows, cols, 3) uint8, written: the codes.
    """
    knee, slope, scale, offset, full, half = _SRGB
    zero, one = _ACES[0], _ACES[1]
    x, powers, noise, codes = linear.ravel(), powered.ravel(), half_dither.ravel(), out.reshape(-1)
    for n in range(x.size):
        v = x[n] * slope if x[n] <= knee else powers[n] * scale - offset
        v = min(max(v, zero), one) * full + half + noise[n]
        codes[n] = np.uint8(min(max(np.floor(v), zero), full))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _interval(points, x):
    """The index lo of the interval [points[lo], points[lo + 1]) that holds x, by bisection as
    ``np.interp`` finds it (``points`` non-decreasing, points[0] <= x < points[-1])."""
    lo, hi = 0, points.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if points[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def scattering_weights(tau: np.ndarray, nodes: np.ndarray, tables: np.ndarray, sun_weight: np.ndarray,
                       sky_weight: np.ndarray) -> None:
    """The multiple-scattering weights of ``clouds.CloudLayer.radiance``: ``np.interp`` of two tables at
    optical depths ``tau``, operation for operation (the node at or below tau by bisection, the ends
    held, the interval's slope times the distance from its first node plus its first value, and where
    that is NaN the same from the other end), so the weights are the same to the bit.

    Parameters
    ----------
    tau : numpy.ndarray
        (m,) float64 optical depths [1].
    nodes : numpy.ndarray
        (k,) float64 optical depths of the tables, strictly increasing [1].
    tables : numpy.ndarray
        (2, k) float64: the sun's and the sky's weights at the nodes [1/sr].
    sun_weight : numpy.ndarray
        (m,) float32, float32(interp(tau, nodes, tables[0])) added in place [1/sr].
    sky_weight : numpy.ndarray
        (m,) float32, set in place to float32(interp(tau, nodes, tables[1])) [1/sr].
    """
    last = nodes.shape[0] - 1
    slopes = np.empty((2, last))  # as np.interp's, per interval
    for k in range(2):
        for j in range(last):
            slopes[k, j] = (tables[k, j + 1] - tables[k, j]) / (nodes[j + 1] - nodes[j])
    values = np.empty(2)
    lo = 0
    for i in range(tau.shape[0]):
        x = tau[i]
        # the interval [nodes[lo], nodes[lo + 1]) that holds x, for both tables: the previous
        # point's (neighbours are alike), else found by bisection
        if x == x and nodes[0] <= x < nodes[last] and not nodes[lo] <= x < nodes[lo + 1]:
            lo = _interval(nodes, x)
        for k in range(2):
            if x != x:
                values[k] = x
            elif x >= nodes[last]:
                values[k] = tables[k, last]
            elif x < nodes[0]:
                values[k] = tables[k, 0]
            elif nodes[lo] == x:
                values[k] = tables[k, lo]
            else:
                value = slopes[k, lo] * (x - nodes[lo]) + tables[k, lo]
                if value != value:
                    value = slopes[k, lo] * (x - nodes[lo + 1]) + tables[k, lo + 1]
                    if value != value and tables[k, lo] == tables[k, lo + 1]:
                        value = tables[k, lo]
                values[k] = value
        sun_weight[i] += np.float32(values[0])
        sky_weight[i] = np.float32(values[1])


@njit(cache=True, nogil=True, error_model="numpy", **LOOP)
def hermite_mean(field: np.ndarray, spread: np.ndarray, nodes: np.ndarray, weights: np.ndarray, values: np.ndarray,
                 levels: np.ndarray, out: np.ndarray) -> None:
    """``clouds.CloudLayer.coverage``'s mean over a footprint: ``out`` gets ``sum_k weights[k]
    interp(field + nodes[k] spread, values, levels)``, summed from 0 in the order of the nodes, each
    interpolation that of ``np.interp`` operation for operation (as ``scattering_weights``'s), so the
    coverage is that of the array expression ``out += w * np.interp(field + z * spread, values,
    levels)`` to the bit.

    Parameters
    ----------
    field : numpy.ndarray
        (m,) float64, the cloud pattern at the footprints' centres [1].
    spread : numpy.ndarray
        (m,) float64, the pattern's standard deviation lost within each footprint [1].
    nodes, weights : numpy.ndarray
        (n,) float64 Gauss-Hermite nodes and weights, the weights summing to 1 [1].
    values : numpy.ndarray
        (k,) float64 pattern values of the coverage table, non-decreasing [1].
    levels : numpy.ndarray
        (k,) float64 coverage at ``values`` [1].
    out : numpy.ndarray
        (m,) float64, written: the mean coverage [1].
    """
    last = values.shape[0] - 1
    slopes = np.empty(last)  # as np.interp's, per interval
    for j in range(last):
        slopes[j] = (levels[j + 1] - levels[j]) / (values[j + 1] - values[j])
    lo = 0
    for i in range(field.shape[0]):
        total = 0.0
        for k in range(nodes.shape[0]):
            x = field[i] + nodes[k] * spread[i]
            if x != x:
                value = x
            elif x >= values[last]:
                value = levels[last]
            elif x < values[0]:
                value = levels[0]
            else:
                if not values[lo] <= x < values[lo + 1]:  # else the last point's interval holds it
                    lo = _interval(values, x)
                if values[lo] == x:
                    value = levels[lo]
                else:
                    value = slopes[lo] * (x - values[lo]) + levels[lo]
                    if value != value:
                        value = slopes[lo] * (x - values[lo + 1]) + levels[lo + 1]
                        if value != value and levels[lo] == levels[lo + 1]:
                            value = levels[lo]
            total += weights[k] * value
        out[i] = total
