"""Compiled loops that make a mesh tree's triangles ready to draw (``canopy.mesh_flutter``, ``canopy.mesh_coverage``).

``turn_corners`` turns each leaf of a mesh tree about its pivot, one rotation a leaf; ``arrange`` projects
the triangles drawn onto a mask's raster, their groups in bands of rows, as ``kernels/triangles.py``
draws them (docs/method.md, "Trees from mesh files"). Imported lazily: numba costs 0.3 s to import.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["arrange", "turn_corners"]


@njit(cache=True, nogil=True, error_model="numpy")
def _rodrigues(axis, angle, out):
    """out (3, 3): the turn about the unit axis (3,) by angle [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis[0], axis[1], axis[2]
    k = 1.0 - c
    out[0, 0], out[0, 1], out[0, 2] = c + k * x * x, k * x * y - s * z, k * x * z + s * y
    out[1, 0], out[1, 1], out[1, 2] = k * y * x + s * z, c + k * y * y, k * y * z - s * x
    out[2, 0], out[2, 1], out[2, 2] = k * z * x - s * y, k * z * y + s * x, c + k * z * z


@njit(cache=True, nogil=True, error_model="numpy")
def turn_corners(rest: np.ndarray, leaf_triangles: np.ndarray, owner: np.ndarray, arm: np.ndarray,
                 pivot: np.ndarray, twist_axis: np.ndarray, twist: np.ndarray, swing_axis: np.ndarray,
                 swing: np.ndarray) -> np.ndarray:
    """Every triangle's corners, each leaf triangle's turned about its leaf's pivot: twisted about the leaf's
    twist axis, then swung about its swing axis, the two made one rotation a leaf.

    Parameters
    ----------
    rest : numpy.ndarray
        (m, 3, 3) every triangle's corners at rest [m].
    leaf_triangles : numpy.ndarray
        (k,) int64 the leaf triangles, in ``rest``.
    owner : numpy.ndarray
        (k,) int64 the leaf of each.
    arm : numpy.ndarray
        (k, 3, 3) each leaf triangle's corners less its leaf's pivot [m].
    pivot : numpy.ndarray
        (L, 3) each leaf's pivot [m].
    twist_axis, swing_axis : numpy.ndarray
        (L, 3) unit axes of each leaf's two turns [1].
    twist, swing : numpy.ndarray
        (L,) their angles [rad].

    Returns
    -------
    numpy.ndarray
        (m, 3, 3) the corners [m]: ``pivot + swing twist arm`` for the leaf triangles, ``rest`` for the others.
    """
    leaves = pivot.shape[0]
    turn = np.empty((leaves, 3, 3))
    a, b = np.empty((3, 3)), np.empty((3, 3))
    for g in range(leaves):
        _rodrigues(swing_axis[g], swing[g], a)
        _rodrigues(twist_axis[g], twist[g], b)
        for i in range(3):
            for j in range(3):
                turn[g, i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
    out = rest.copy()
    for n in range(leaf_triangles.shape[0]):
        t, g = leaf_triangles[n], owner[n]
        for c in range(3):
            a0, a1, a2 = arm[n, c, 0], arm[n, c, 1], arm[n, c, 2]
            for i in range(3):
                out[t, c, i] = pivot[g, i] + (turn[g, i, 0] * a0 + turn[g, i, 1] * a1 + turn[g, i, 2] * a2)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def arrange(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray, material: np.ndarray, group: np.ndarray,
            partner: np.ndarray, chosen: np.ndarray, sun: np.ndarray, plane_height: float, origin: np.ndarray,
            pixel: float, band_rows: int, partners: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """The chosen triangles projected along the sun onto the raster, their groups in bands of ``band_rows``
    raster rows (by their first corner; by group within a band), as ``mesh_transmittance`` takes them.

    Parameters
    ----------
    vertices : numpy.ndarray
        (n, 3) float64 [m].
    triangles : numpy.ndarray
        (m, 3) int64 corners in ``vertices``.
    uv : numpy.ndarray
        (m, 3, 2) float64 texture coordinates [1].
    material, group : numpy.ndarray
        (m,) int64 each triangle's material and group.
    partner : numpy.ndarray
        (m, 3) int64 the triangle of the same group across each edge, or -1.
    chosen : numpy.ndarray
        (k,) int64 the triangles drawn, each group's together (in any order of the groups: the nearer
        the bands', the fewer the cache misses).
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    plane_height : float
        Height of the plane [m].
    origin : numpy.ndarray
        (2,) the raster's north-west corner [m].
    pixel : float
        Pixel size [m].
    band_rows : int
        Rows of a band [pixel].
    partners : bool
        Whether the partners are wanted (else all -1): some triangle is integrated piece by piece.

    Returns
    -------
    tuple of numpy.ndarray
        (corners (k, 3, 2) [pixel], texels (k, 3, 2) as (u, 1 - v) [1], material (k,), group_start (g + 1,),
        partner (k, 3) in the new order).
    """
    k = chosen.shape[0]
    starts = np.empty(k + 1, np.int64)
    groups = 0
    for n in range(k):
        if n == 0 or group[chosen[n]] != group[chosen[n - 1]]:
            starts[groups] = n
            groups += 1
    starts[groups] = k
    order = _band_order(vertices, triangles, group, chosen, starts[:groups + 1], sun, plane_height, origin, pixel,
                        band_rows)
    corners, texels = np.empty((k, 3, 2)), np.empty((k, 3, 2))
    chosen_material, local = np.empty(k, np.int64), np.full(triangles.shape[0] if partners else 0, -1, np.int64)
    group_start = np.empty(groups + 1, np.int64)
    group_start[0], at = 0, 0
    for i in range(groups):
        g = order[i]
        for n in range(starts[g], starts[g + 1]):
            t = chosen[n]
            for c in range(3):
                v = triangles[t, c]
                height = vertices[v, 2] - plane_height
                corners[at, c, 0] = ((vertices[v, 0] - height * sun[0]) - origin[0]) / pixel
                corners[at, c, 1] = (origin[1] - (vertices[v, 1] - height * sun[1])) / pixel
                texels[at, c, 0], texels[at, c, 1] = uv[t, c, 0], 1.0 - uv[t, c, 1]
            chosen_material[at] = material[t]
            if partners:
                local[t] = at
            at += 1
        group_start[i + 1] = at
    return corners, texels, chosen_material, group_start, _renumbered(partner, chosen, local, partners)


@njit(cache=True, nogil=True, error_model="numpy")
def _band_order(vertices, triangles, group, chosen, starts, sun, plane_height, origin, pixel, band_rows):
    """The groups (``starts`` into ``chosen``) by the band of rows their first corner falls in, then by group:
    the same order whatever order the groups were chosen in."""
    groups = starts.shape[0] - 1
    key = np.empty(groups, np.int64)
    for g in range(groups):
        v = triangles[chosen[starts[g]], 0]
        y = (origin[1] - (vertices[v, 1] - (vertices[v, 2] - plane_height) * sun[1])) / pixel
        key[g] = int(np.floor(y / band_rows))
    if groups:
        low, ids = key.min(), group.max() + 1
        for g in range(groups):
            key[g] = (key[g] - low) * ids + group[chosen[starts[g]]]
    return np.argsort(key, kind="mergesort")


@njit(cache=True, nogil=True, error_model="numpy")
def _renumbered(partner, chosen, local, partners):
    """(k, 3) the partners of the chosen triangles as their new places (``local``), or all -1."""
    moved = np.full((chosen.shape[0], 3), -1, np.int64)
    for n in range(chosen.shape[0] if partners else 0):
        t = chosen[n]
        for e in range(3):
            moved[local[t], e] = local[partner[t, e]] if partner[t, e] >= 0 else -1
    return moved
