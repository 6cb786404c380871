"""A wall on the ground: its sun shadow as an exact polygon and the sky it hides from each ground
point, integrated in azimuth slices (docs/method.md, "Receivers: walls and slopes", "A wall on the
ground")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.geometry import Grid
from pipeline.receivers.hemisphere import Radiance
from pipeline.receivers.plane import ReceiverPlane

__all__ = ["SLICE_NODES", "SkyTable", "wall_corners", "shadow_polygon", "polygon_coverage", "sky_table",
           "hidden_sky"]

SLICE_NODES = 12
"""Gauss-Legendre azimuth nodes in each piece of a wall's azimuth span between its corners. [count]"""

_TABLE_SIZE = (720, 256)  # (azimuth, elevation) cells of ``sky_table`` over the upper hemisphere [count]
_CHUNK = 1 << 15  # ground points per pass of ``hidden_sky`` [count]


def wall_corners(plane: ReceiverPlane) -> np.ndarray:
    """The four world corners of a wall, in order round its edge.

    Parameters
    ----------
    plane : ReceiverPlane
        A bounded receiver plane (a wall) [m].

    Returns
    -------
    numpy.ndarray
        (4, 3) the foot's two corners, then the top's [m].

    Raises
    ------
    ValueError
        For an unbounded plane.
    """
    if plane.width is None or plane.height is None:
        raise ValueError("an unbounded plane has no corners")
    half, top = plane.width / 2.0, plane.height
    return plane.world_points(np.array([[-half, 0.0, 0.0], [half, 0.0, 0.0], [half, top, 0.0], [-half, top, 0.0]]))


def shadow_polygon(plane: ReceiverPlane, sun: ArrayLike) -> np.ndarray:
    """The wall's sun shadow on the ground z = 0: its corners projected along the sun, their convex hull.

    Parameters
    ----------
    plane : ReceiverPlane
        The wall (its corners at z >= 0).
    sun : array_like
        (3,) unit world direction towards the sun, z > 0 [1].

    Returns
    -------
    numpy.ndarray
        (k, 2) the hull's corners counter-clockwise (x east, y north) [m].
    """
    s = np.asarray(sun, dtype=np.float64)
    c = wall_corners(plane)
    points = c[:, :2] - (c[:, 2:] / s[2]) * s[:2]
    return _hull(points)


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull (k, 2) of points (n, 2), counter-clockwise (Andrew's monotone chain)."""
    pts = sorted({(float(x), float(y)) for x, y in points})
    if len(pts) < 3:
        return np.array(pts)

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _clamp_integral(t: np.ndarray, h: float) -> np.ndarray:
    """The antiderivative of clamp(t, 0, h) in t."""
    return np.where(t <= 0.0, 0.0, np.where(t >= h, h * t - h * h / 2.0, t * t / 2.0))


def polygon_coverage(polygon: np.ndarray, grid: Grid) -> np.ndarray:
    """The share of each grid cell that a simple polygon covers, exactly.

    Each edge adds, cell by cell, the signed area between it and the cell's bottom, clamped to the
    cell (the shoelace formula cut to the cell), so the result is exact for any simple polygon.

    Parameters
    ----------
    polygon : numpy.ndarray
        (k, 2) corners in order (x east, y north) [m].
    grid : Grid
        The ground grid [m].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float64 in [0, 1] [1].
    """
    rows, cols = grid.shape
    p = grid.pixel
    x_edges = grid.origin[0] + p * np.arange(cols + 1)
    y_bottom = grid.origin[1] - p * (np.arange(rows) + 1.0)
    area = np.zeros((rows, cols))
    for (xa, ya), (xb, yb) in zip(polygon, np.roll(polygon, -1, axis=0)):
        if xa == xb:
            continue
        lo, hi = (xa, xb) if xa < xb else (xb, xa)
        c0 = max(int(np.floor((lo - x_edges[0]) / p)), 0)
        c1 = min(int(np.ceil((hi - x_edges[0]) / p)), cols)
        if c1 <= c0:
            continue
        x0 = np.clip(x_edges[c0:c1], lo, hi)
        x1 = np.clip(x_edges[c0 + 1:c1 + 1], lo, hi)
        slope = (yb - ya) / (xb - xa)
        f0 = ya + slope * (x0 - xa) - y_bottom[:, None]
        f1 = ya + slope * (x1 - xa) - y_bottom[:, None]
        if abs(slope) * p > 1e-9:
            part = (_clamp_integral(f1, p) - _clamp_integral(f0, p)) / slope
        else:
            part = np.clip((f0 + f1) / 2.0, 0.0, p) * (x1 - x0)
        area[:, c0:c1] += part if xb < xa else -part
    x, y = polygon[:, 0], polygon[:, 1]
    signed = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return np.clip(area * np.sign(signed) / (p * p), 0.0, 1.0)


@dataclass(frozen=True)
class SkyTable:
    """The upper hemisphere's light cumulated up from the horizon, by azimuth.

    Attributes
    ----------
    cumulative : numpy.ndarray
        (azimuths + 1, elevations + 1, 3): at azimuth a_i = 2 pi i / azimuths (from north towards
        east) and elevation e_j = (pi / 2) j / elevations, the integral of L sin(e) cos(e) de from
        the horizon to e_j [radiance].
    """

    cumulative: np.ndarray

    def at(self, azimuth: np.ndarray, elevation: np.ndarray) -> np.ndarray:
        """The table read bilinearly at (azimuth [rad], elevation [rad]) (...) -> (..., 3) [radiance]."""
        na, ne = self.cumulative.shape[0] - 1, self.cumulative.shape[1] - 1
        a = np.mod(azimuth, 2.0 * np.pi) * (na / (2.0 * np.pi))
        e = np.clip(elevation, 0.0, np.pi / 2.0) * (ne / (np.pi / 2.0))
        i = np.minimum(a.astype(np.int64), na - 1)
        j = np.minimum(e.astype(np.int64), ne - 1)
        fa, fe = (a - i)[..., None], (e - j)[..., None]
        t = self.cumulative
        return ((1 - fa) * ((1 - fe) * t[i, j] + fe * t[i, j + 1])
                + fa * ((1 - fe) * t[i + 1, j] + fe * t[i + 1, j + 1]))


def sky_table(radiance: Radiance, size: tuple[int, int] = _TABLE_SIZE) -> SkyTable:
    """``SkyTable`` of the light around the ground: the radiance at each cell's middle, integrated
    exactly in elevation against sin(e) cos(e) over the cell.

    Parameters
    ----------
    radiance : Radiance
        The light by world direction (``hemisphere.world_radiance``).
    size : tuple of int
        (azimuth, elevation) cells.

    Returns
    -------
    SkyTable
        Its cumulative table [radiance].
    """
    na, ne = size
    a = 2.0 * np.pi * np.arange(na + 1) / na
    e_edges = (np.pi / 2.0) * np.arange(ne + 1) / ne
    e_mid = (e_edges[:-1] + e_edges[1:]) / 2.0
    d = np.stack(np.broadcast_arrays(np.sin(a)[:, None] * np.cos(e_mid), np.cos(a)[:, None] * np.cos(e_mid),
                                     np.sin(e_mid)[None, :]), axis=-1)
    weight = np.diff(np.sin(e_edges) ** 2) / 2.0  # the integral of sin cos over each cell
    cells = radiance(d) * weight[None, :, None]
    cumulative = np.concatenate([np.zeros((na + 1, 1, 3)), np.cumsum(cells, axis=1)], axis=1)
    return SkyTable(cumulative)


def hidden_sky(plane: ReceiverPlane, points: np.ndarray, table: SkyTable | None,
               nodes: int = SLICE_NODES) -> tuple[np.ndarray, np.ndarray]:
    """The light a wall hides from points on the ground z = 0, and its view factor from them.

    In each vertical half-plane through a point, at azimuth phi, the wall is a segment (the plane
    cut by its four edges); the elevations it spans above the horizon hide the sky's
    ``G(phi, e_hi) - G(phi, e_lo)`` (``SkyTable``), and ``(sin^2 e_hi - sin^2 e_lo) / 2`` of a
    uniform light. The azimuth span between the wall's corners is cut at each corner and each
    piece integrated by Gauss-Legendre nodes.

    Parameters
    ----------
    plane : ReceiverPlane
        The wall.
    points : numpy.ndarray
        (n, 2) ground points (x east, y north) [m].
    table : SkyTable or None
        The sky's table; None: the hidden light is not computed (zeros).
    nodes : int
        Gauss-Legendre nodes per piece of the span.

    Returns
    -------
    hidden : numpy.ndarray
        (n, 3) the irradiance the sky behind the wall gave each point [radiance x sr].
    view_factor : numpy.ndarray
        (n,) the wall's view factor from each point, its projected solid angle over pi [1].
    """
    hidden = np.zeros((len(points), 3))
    factor = np.zeros(len(points))
    for start in range(0, len(points), _CHUNK):
        part = slice(start, start + _CHUNK)
        hidden[part], factor[part] = _hidden_chunk(plane, np.asarray(points[part], dtype=np.float64), table, nodes)
    return hidden, factor


def _hidden_chunk(plane: ReceiverPlane, p: np.ndarray, table: SkyTable | None,
                  nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """``hidden_sky`` on one chunk of points (n, 2)."""
    corners = wall_corners(plane)
    rel = corners[None, :, :2] - p[:, None, :]  # (n, 4, 2)
    centre = np.arctan2(rel[..., 0].mean(axis=1), rel[..., 1].mean(axis=1))
    corner_az = np.arctan2(rel[..., 0], rel[..., 1]) - centre[:, None]
    corner_az = np.sort(np.mod(corner_az + np.pi, 2.0 * np.pi) - np.pi, axis=1)  # (n, 4) about the centre
    x, w = np.polynomial.legendre.leggauss(nodes)
    # three pieces between the corners; one for an upright wall, whose corners pair up in azimuth
    cuts = corner_az[:, ::3] if abs(plane.normal[2]) < 1e-12 else corner_az
    lo, hi = cuts[:, :-1, None], cuts[:, 1:, None]
    phi = (centre[:, None, None] + (lo + hi) / 2.0 + (hi - lo) / 2.0 * x).reshape(len(p), -1)
    dphi = np.broadcast_to((hi - lo) / 2.0 * w, (len(p), lo.shape[1], nodes)).reshape(len(p), -1)
    if abs(plane.normal[2]) < 1e-12 and plane.origin[2] == 0.0:  # upright on the ground: from the horizon up
        n = plane.normal[:2]
        distance = (np.asarray(plane.origin[:2]) - p) @ n  # along n to the wall's line
        r = distance[:, None] / (np.sin(phi) * n[0] + np.cos(phi) * n[1])
        e_hi = np.arctan2(plane.height or 0.0, np.maximum(r, 1e-12))
        factor = np.sum(dphi * np.sin(e_hi) ** 2 / 2.0, axis=1) / np.pi
        if table is None:
            return np.zeros((len(p), 3)), factor
        return np.sum(dphi[..., None] * table.at(phi, e_hi), axis=1), factor
    e_lo, e_hi = _slice_elevations(corners, p, phi)
    factor = np.sum(dphi * (np.sin(e_hi) ** 2 - np.sin(e_lo) ** 2) / 2.0, axis=1) / np.pi
    if table is None:
        return np.zeros((len(p), 3)), factor
    hidden = np.sum(dphi[..., None] * (table.at(phi, e_hi) - table.at(phi, e_lo)), axis=1)
    return hidden, factor


def _slice_elevations(corners: np.ndarray, p: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The elevations (n, k) [rad] between which the wall lies above the horizon in the vertical
    half-plane at azimuth phi (n, k) through each point p (n, 2); equal where it does not."""
    h = np.stack([np.sin(phi), np.cos(phi)], axis=-1)  # (n, k, 2)
    m = np.stack([h[..., 1], -h[..., 0]], axis=-1)
    rel = corners[None, :, :2] - p[:, None, :]  # (n, 4, 2)
    side = np.einsum("nkc,nic->nki", m, rel)  # (n, k, 4) signed distance of each corner from the plane
    r_along = np.einsum("nkc,nic->nki", h, rel)
    elevations = []
    found = []
    for i in range(4):
        j = (i + 1) % 4
        a, b = side[..., i], side[..., j]
        crosses = (a * b <= 0.0) & (a != b)
        t = np.where(crosses, a / np.where(a != b, a - b, 1.0), 0.0)
        r = r_along[..., i] + t * (r_along[..., j] - r_along[..., i])
        z = corners[i, 2] + t * (corners[j, 2] - corners[i, 2])
        ok = crosses & (r > 0.0)
        elevations.append(np.where(ok, np.arctan2(np.maximum(z, 0.0), np.maximum(r, 1e-12)), np.nan))
        found.append(ok)
    e = np.stack(elevations, axis=-1)
    any_found = np.any(np.stack(found, axis=-1), axis=-1)
    e_lo = np.where(any_found, np.nanmin(np.where(np.isnan(e), np.inf, e), axis=-1), 0.0)
    e_hi = np.where(any_found, np.nanmax(np.where(np.isnan(e), -np.inf, e), axis=-1), 0.0)
    return e_lo, e_hi
