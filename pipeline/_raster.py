"""Compiled loops of the anti-aliased rasteriser (``canopy.rasterize_transmittance``).

The method is the one documented in ``canopy.py`` (and docs/method.md): the coverage of a pixel
is the mean over k x k sub-samples of the exact area fraction of the sub-sample's square that
lies inside the shape's local strip. These loops compute it shape by shape straight into the
optical-depth raster, with the same float32 arithmetic as the array version they replace, so
that no per-pixel fragment arrays are built. Imported lazily: numba costs 0.3 s to import.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_OPAQUE = np.float32(1.0 - 2.0**-20)
_OPAQUE_DEPTH = -math.log1p(-float(_OPAQUE))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _square_cdf(t, a, b):
    """Fraction of a unit square (centred on 0) where n . u <= t, |n| = 1, a = max(|nx|, |ny|),
    b = min(|nx|, |ny|): the CDF of a trapezoid (canopy._square_cdf, branch-free)."""
    s = abs(t)
    edge = np.float32(0.5) * (a + b) - s
    edge = max(edge, np.float32(0.0))
    quad = edge * edge / (np.float32(2.0) * a * b + np.float32(1e-12))
    lin = np.float32(0.5) - s / a
    tail = lin if s <= np.float32(0.5) * (a - b) else quad
    return tail if t < 0 else np.float32(1.0) - tail


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cover(d, nx, ny, kf, thick):
    """Coverage of one sub-sample from its signed distance d and normal (nx, ny) [pixel]; thick
    >= 0 (thin shapes) subtracts the parallel half-plane ``thick`` sub-sample widths further in."""
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
    row by row (float32, as the array version computes them); returns their count."""
    kf = np.float32(k)
    m = 0
    for r in range(h):
        for sy in range(k):
            dy = (np.float32(r * k + sy) + np.float32(0.5)) / kf - ry
            for j in range(w * k):
                dxs[m] = (np.float32(j) + np.float32(0.5)) / kf - rx
                dys[m] = dy
                m += 1
    return m


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _pixel_cover(buf, w, k, r, c):
    """Mean of the k x k sub-sample coverages of box pixel (r, c)."""
    acc = np.float32(0.0)
    for sy in range(k):
        base = (r * k + sy) * w * k + c * k
        for sx in range(k):
            acc += buf[base + sx]
    return acc / np.float32(k * k)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _deposit(optical, row, col, cover):
    """Add -log(1 - cover) to optical[row, col], cover clipped just below 1 (a covered pixel's
    constant is kept aside: log1p is the dearest step)."""
    if cover >= _OPAQUE:
        optical[row, col] += _OPAQUE_DEPTH
    elif cover > 0:
        optical[row, col] -= math.log1p(-cover)


def _scratch(size, sub):
    most = 1
    for i in range(size.shape[0]):
        most = max(most, size[i, 0] * size[i, 1] * sub[i] * sub[i])
    return np.empty(most, np.float32), np.empty(most, np.float32), np.empty(most, np.float32)


_scratch = njit(cache=True, nogil=True)(_scratch)


@njit(cache=True, nogil=True, error_model="numpy")
def ellipses(rel, lo, size, sub, thin, thickness, prm, optical):
    """Add -log(1 - c) of every ellipse's coverage c to ``optical`` (rows, cols) float64.

    rel (n, 2) float32: centre minus the box corner [pixel]; lo (n, 2), size (n, 2) int64: box
    corner and size (u, v) within the raster; sub (n,) sub-samples per axis; thin (n,) bool;
    thickness (n,) float32 [pixel]; prm (n, 4) float32: major unit vector, semi-axes A, B."""
    dxs, dys, buf = _scratch(size, sub)
    for i in range(rel.shape[0]):
        k = sub[i]
        kf = np.float32(k)
        w, h = size[i, 0], size[i, 1]
        ex, ey, major, minor = prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3]
        thick = thickness[i] * kf if thin[i] else np.float32(-1.0)
        ab, bb, aa = major * minor, minor * minor, major * major
        eps, eps2 = np.float32(1e-3) * minor, np.float32(1e-3) * bb
        m = _samples(rel[i, 0], rel[i, 1], w, h, k, dxs, dys)
        for j in range(m):
            dx, dy = dxs[j], dys[j]
            p = dx * ex + dy * ey
            q = dy * ex - dx * ey
            bp = bb * p
            aq = aa * q
            mp = minor * p
            mq = major * q
            gauge = np.sqrt(mp * mp + mq * mq)
            grad = np.sqrt(bp * bp + aq * aq) + eps2
            d = (gauge - ab) * (gauge + eps) / grad
            buf[j] = _cover(d, (bp * ex - aq * ey) / grad, (bp * ey + aq * ex) / grad, kf, thick)
        for r in range(h):
            for c in range(w):
                _deposit(optical, lo[i, 1] + r, lo[i, 0] + c, _pixel_cover(buf, w, k, r, c))


@njit(cache=True, nogil=True, error_model="numpy")
def capsules(rel, lo, size, sub, thin, thickness, prm, optical):
    """As ``ellipses`` for capsule pieces; prm (n, 8) float32: axis start relative to the
    piece's centre (x0, y0), axis (ex, ey), 1 / |axis|^2, radius, and the stretch [t_lo, t_hi)
    of the axis whose pixels (judged at their centres) the piece draws."""
    dxs, dys, buf = _scratch(size, sub)
    for i in range(rel.shape[0]):
        k = sub[i]
        kf = np.float32(k)
        w, h = size[i, 0], size[i, 1]
        rx, ry = rel[i, 0], rel[i, 1]
        x0, y0, ex, ey, inverse, radius, t_lo, t_hi = (prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3],
                                                      prm[i, 4], prm[i, 5], prm[i, 6], prm[i, 7])
        thick = thickness[i] * kf if thin[i] else np.float32(-1.0)
        m = _samples(rx, ry, w, h, k, dxs, dys)
        for j in range(m):
            px, py = dxs[j] - x0, dys[j] - y0
            t = min(max((px * ex + py * ey) * inverse, np.float32(0.0)), np.float32(1.0))
            qx, qy = px - t * ex, py - t * ey
            length = np.sqrt(qx * qx + qy * qy) + np.float32(1e-6)
            buf[j] = _cover(length - radius, qx / length, qy / length, kf, thick)
        for r in range(h):
            # the piece's stretch of the axis, judged at pixel centres in float64 as before
            cy = float(r) + 0.5 - float(ry) - float(y0)
            for c in range(w):
                cx = float(c) + 0.5 - float(rx) - float(x0)
                t = (cx * float(ex) + cy * float(ey)) * float(inverse)
                if t >= float(t_lo) and t < float(t_hi):
                    _deposit(optical, lo[i, 1] + r, lo[i, 0] + c, _pixel_cover(buf, w, k, r, c))
