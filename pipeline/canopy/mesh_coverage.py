"""A tree mesh's shadow on a canopy plane: its triangles projected along the sun and drawn by exact coverage.

``mesh_mask`` draws a ``mesh.TreeMesh`` into a layer's transmittance mask (each triangle's overlap
with each pixel times its leaf texture's alpha over the overlap; ``kernels/triangles.py`` holds the
compiled loops), ``mesh_layer_index`` splits it into layers as the grove is split, and
``alpha_weighted_area`` is its leaves' own area (docs/method.md, "Trees from mesh files").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy.mesh import TreeMesh
from pipeline.core.geometry import Grid

__all__ = ["TEXELS_PER_PIXEL", "CoverageTables", "coverage_tables", "project_mesh", "sun_facing", "mesh_layer_index",
           "mesh_mask", "alpha_weighted_area"]

_BAND_ROWS = 8  # groups are drawn in bands of this many raster rows (for the cache) [pixel]

TEXELS_PER_PIXEL = 4.0
"""A leaf texture is read at the finest of its box-filtered levels whose texel spans at most
1 / TEXELS_PER_PIXEL of a mask pixel (docs/accuracy.md, "Trees from mesh files") [1]."""


@dataclass(frozen=True)
class CoverageTables:
    """Every material's coverage table and its box-filtered levels, as row prefix sums for the compiled loops.

    Attributes
    ----------
    prefix : numpy.ndarray
        Flat float64: each level's (height, width + 1) row prefix sums, then its transposed table's [texel].
    level_base : numpy.ndarray
        (materials, L, 2) int64 where each level and its transposed table start in ``prefix``.
    level_size : numpy.ndarray
        (materials, L, 2) int64 each level's (width, height) [texel].
    levels : numpy.ndarray
        (materials,) int64 the levels of each material.
    double : numpy.ndarray
        Flat float64 laid out as ``prefix``: the prefix sums of each row's prefix integral [texel^2].
    partner : numpy.ndarray
        (m, 3) int64: the mesh's triangle of the same group across each edge (corner k to k + 1) with the
        same vertices and texture coordinates at both ends, or -1 (none, or more than one).
    """

    prefix: np.ndarray
    level_base: np.ndarray
    level_size: np.ndarray
    levels: np.ndarray
    double: np.ndarray
    partner: np.ndarray


def coverage_tables(mesh: TreeMesh) -> CoverageTables:
    """The mesh's coverage tables (level 0 each material's own, each next one 2 x 2 texels averaged) and
    which triangles share an edge.

    Parameters
    ----------
    mesh : TreeMesh
        The mesh.

    Returns
    -------
    CoverageTables
        The tables as the compiled loops read them.
    """
    pyramids = [_pyramid(np.asarray(m.coverage, dtype=np.float64)) for m in mesh.materials]
    depth = max(len(p) for p in pyramids)
    base = np.zeros((len(pyramids), depth, 2), dtype=np.int64)
    size = np.ones((len(pyramids), depth, 2), dtype=np.int64)
    parts, doubles, offset = [], [], 0
    for m, pyramid in enumerate(pyramids):
        for level, table in enumerate(pyramid):
            size[m, level] = (table.shape[1], table.shape[0])
            for turned, oriented in enumerate((table, table.T)):
                rows = np.zeros((oriented.shape[0], oriented.shape[1] + 1))
                np.cumsum(oriented, axis=1, out=rows[:, 1:])
                double = np.zeros_like(rows)  # F is linear on each texel: its integral by the trapezoid
                np.cumsum(0.5 * (rows[:, :-1] + rows[:, 1:]), axis=1, out=double[:, 1:])
                base[m, level, turned] = offset
                parts.append(rows.reshape(-1))
                doubles.append(double.reshape(-1))
                offset += rows.size
    levels = np.array([len(p) for p in pyramids], dtype=np.int64)
    return CoverageTables(np.concatenate(parts), base, size, levels, np.concatenate(doubles), _partners(mesh))


def _partners(mesh: TreeMesh) -> np.ndarray:
    """(m, 3) int64: the triangle across each edge of the same group with the same two vertices and texture
    coordinates at them, or -1 (no such triangle, or more than one)."""
    m = len(mesh.triangles)
    start, end = mesh.triangles, np.roll(mesh.triangles, -1, axis=1)
    uv_start, uv_end = mesh.uv, np.roll(mesh.uv, -1, axis=1)
    low, high = np.minimum(start, end).reshape(-1), np.maximum(start, end).reshape(-1)
    forward = (start <= end).reshape(-1, 1)
    uv_low = np.where(forward, uv_start.reshape(-1, 2), uv_end.reshape(-1, 2))
    uv_high = np.where(forward, uv_end.reshape(-1, 2), uv_start.reshape(-1, 2))
    group = np.repeat(mesh.group, 3)
    order = np.lexsort((high, low, group))
    same = (group[order][1:] == group[order][:-1]) & (low[order][1:] == low[order][:-1]) & \
        (high[order][1:] == high[order][:-1])
    alone = np.r_[True, ~same[:-1]] & np.r_[~same[1:], True]  # exactly two edges with this key
    first = np.flatnonzero(same & alone)
    a, b = order[first], order[first + 1]
    keep = np.all(uv_low[a] == uv_low[b], axis=1) & np.all(uv_high[a] == uv_high[b], axis=1)
    partner = np.full(3 * m, -1, dtype=np.int64)
    partner[a[keep]], partner[b[keep]] = b[keep] // 3, a[keep] // 3
    return partner.reshape(m, 3)


def _pyramid(table: np.ndarray) -> list[np.ndarray]:
    """The table and its levels down to one texel, each the 2 x 2 mean of the one before (an odd side
    repeats its last texel)."""
    levels = [table]
    while max(table.shape) > 1:
        padded = np.pad(table, ((0, table.shape[0] % 2), (0, table.shape[1] % 2)), mode="edge")
        rows, cols = max(padded.shape[0] // 2, 1), max(padded.shape[1] // 2, 1)
        table = padded.reshape(rows, padded.shape[0] // rows, cols, padded.shape[1] // cols).mean(axis=(1, 3))
        levels.append(table)
    return levels


def project_mesh(mesh: TreeMesh, *, sun: ArrayLike, plane_height: float,
                 select: np.ndarray | slice = slice(None)) -> np.ndarray:
    """Every triangle's corners projected along the sun onto the canopy plane z = plane_height.

    A point P lands at P_xy - (P_z - plane_height) s, as the grove's leaves do.

    Parameters
    ----------
    mesh : TreeMesh
        The mesh [m].
    sun : numpy.ndarray
        (2,) the sun's sky-plane point s = (wx / wz, wy / wz) [tan].
    plane_height : float
        Height of the canopy plane [m].
    select : numpy.ndarray or slice, optional
        The triangles projected (a boolean mask or indices, in that order); all by default.

    Returns
    -------
    numpy.ndarray
        (k, 3, 2) float64 [m].
    """
    s = np.asarray(sun, dtype=np.float64)
    points = mesh.vertices[:, :2] - (mesh.vertices[:, 2:3] - plane_height) * s
    return points[mesh.triangles[select]]


def sun_facing(mesh: TreeMesh, *, sun: ArrayLike, select: np.ndarray | slice = slice(None)) -> np.ndarray:
    """Which triangles face the sun by their winding (normal . (s, 1) > 0).

    Parameters
    ----------
    mesh : TreeMesh
        The mesh [m].
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    select : numpy.ndarray or slice, optional
        The triangles asked about (a boolean mask or indices); all by default.

    Returns
    -------
    numpy.ndarray
        (k,) bool, one for each triangle selected.
    """
    corners = mesh.vertices[mesh.triangles[select]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return normal @ np.append(np.asarray(sun, dtype=np.float64), 1.0) > 0


def mesh_layer_index(mesh: TreeMesh, heights: Sequence[float]) -> np.ndarray:
    """The nearest canopy plane of every triangle: a leaf's by its group's area-weighted centre (a leaf stays
    whole), wood's by its own centre, as ``grove.layer_index`` places leaves and wood segments.

    Parameters
    ----------
    mesh : TreeMesh
        The mesh [m].
    heights : sequence of float
        Heights of the canopy planes [m].

    Returns
    -------
    numpy.ndarray
        (m,) int64.
    """
    planes = np.asarray(heights, dtype=np.float64)
    corners = mesh.vertices[mesh.triangles]
    z = corners[:, :, 2].mean(axis=1)
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    leaf = mesh.leaf
    groups = int(mesh.group.max()) + 1 if len(mesh.group) else 0
    weight = np.bincount(mesh.group[leaf], area[leaf], minlength=groups)
    centre = np.bincount(mesh.group[leaf], area[leaf] * z[leaf], minlength=groups) / np.maximum(weight, 1e-300)
    z = np.where(leaf, centre[mesh.group], z)
    return np.argmin(np.abs(z[:, None] - planes[None, :]), axis=1).astype(np.int64)


def mesh_mask(mesh: TreeMesh, *, sun: ArrayLike, plane_height: float, grid: Grid, select: np.ndarray | None = None,
              tables: CoverageTables | None = None) -> np.ndarray:
    """Transmittance of the mesh on the canopy plane z = plane_height, each pixel's coverage exact.

    Leaf triangles count on both sides; wood only where it faces the sun (a closed solid's near side,
    once). Within a group (a leaf, a piece of wood) triangles add their coverage of a pixel; groups
    combine as prod (1 - c), each c clipped just below 1.

    Parameters
    ----------
    mesh : TreeMesh
        The mesh [m].
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    plane_height : float
        Height of the canopy plane [m].
    grid : Grid
        The raster [m].
    select : numpy.ndarray or None, optional
        (m,) bool: the triangles drawn (e.g. ``mesh_layer_index(...) == layer``); None for all.
    tables : CoverageTables or None, optional
        ``coverage_tables(mesh)``, made here when None.

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 transmittance [1].
    """
    from pipeline.kernels import triangles

    tables = coverage_tables(mesh) if tables is None else tables
    leaf = mesh.leaf
    drawn = leaf.copy()
    drawn[~leaf] = sun_facing(mesh, sun=sun, select=~leaf)
    if select is not None:
        drawn &= select
    chosen = np.flatnonzero(drawn)
    chosen = chosen[np.argsort(mesh.group[chosen], kind="stable")]
    plane = project_mesh(mesh, sun=sun, plane_height=plane_height, select=chosen)
    corners = np.stack([plane[..., 0] - grid.origin[0], grid.origin[1] - plane[..., 1]], axis=-1) / grid.pixel
    group = mesh.group[chosen]
    group_start = np.flatnonzero(np.r_[True, group[1:] != group[:-1], True]).astype(np.int64)
    # groups in bands of raster rows, so that neighbours share the cache (the result is the same product)
    band = np.floor(corners[group_start[:-1], 0, 1] / _BAND_ROWS).astype(np.int64)
    order = np.argsort(band, kind="stable")
    sizes = np.diff(group_start)[order]
    moved = np.repeat(group_start[:-1][order] - np.cumsum(sizes) + sizes, sizes) + np.arange(len(chosen))
    chosen, corners = chosen[moved], corners[moved]
    texels = np.stack([mesh.uv[chosen, :, 0], 1.0 - mesh.uv[chosen, :, 1]], axis=-1)
    group_start = np.r_[0, np.cumsum(sizes)].astype(np.int64)
    local = np.full(len(mesh.triangles), -1, dtype=np.int64)
    local[chosen] = np.arange(len(chosen))
    partner = np.where(tables.partner[chosen] >= 0, local[np.maximum(tables.partner[chosen], 0)], -1)
    transmittance = np.ones(grid.shape)
    triangles.mesh_transmittance(np.ascontiguousarray(corners), np.ascontiguousarray(texels),
                                 np.ascontiguousarray(mesh.material[chosen]), group_start, tables.prefix,
                                 tables.level_base, tables.level_size, tables.levels, TEXELS_PER_PIXEL,
                                 transmittance, tables.double, np.ascontiguousarray(partner))
    return transmittance.astype(np.float32)


def alpha_weighted_area(mesh: TreeMesh, tables: CoverageTables | None = None) -> float:
    """The leaves' area, one side, each triangle's weighted by its coverage table's mean over it.

    Parameters
    ----------
    mesh : TreeMesh
        The mesh [m].
    tables : CoverageTables or None, optional
        ``coverage_tables(mesh)``, made here when None.

    Returns
    -------
    float
        [m^2].
    """
    from pipeline.kernels import triangles

    tables = coverage_tables(mesh) if tables is None else tables
    leaf = np.flatnonzero(mesh.leaf)
    corners = mesh.vertices[mesh.triangles[leaf]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    texels = np.stack([mesh.uv[leaf, :, 0], 1.0 - mesh.uv[leaf, :, 1]], axis=-1)
    alpha = triangles.triangle_alpha(np.ascontiguousarray(texels), np.ascontiguousarray(mesh.material[leaf]),
                                     tables.prefix, tables.level_base, tables.level_size, tables.double)
    return float(np.sum(area * alpha))
