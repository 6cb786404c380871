"""A tree mesh's shadow on a canopy plane: its triangles projected along the sun and drawn by exact coverage.

``mesh_mask`` draws a ``mesh.TreeMesh`` into a layer's transmittance mask (each triangle's overlap
with each pixel times its leaf texture's alpha over the overlap; ``kernels/triangles.py`` holds the
compiled loops), ``mesh_layer_index`` splits it into layers as the grove is split, and
``alpha_weighted_area`` is its leaves' own area (docs/method.md, "Trees from mesh files").
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy.mesh import TreeMesh
from pipeline.core.geometry import Grid

__all__ = ["TEXELS_PER_PIXEL", "OUTLINE_TEXELS_PER_PIXEL", "CoverageTables", "coverage_tables", "project_mesh",
           "sun_facing", "mesh_layer_index", "mesh_mask", "alpha_weighted_area"]

_BAND_ROWS = 8  # groups are drawn in bands of this many raster rows (for the cache) [pixel]
_ORDERS_KEPT = 16  # rasters whose order of the groups a tree's tables keep

TEXELS_PER_PIXEL = 4.0
"""A leaf texture is read at the finest of its box-filtered levels whose texel spans at most
1 / TEXELS_PER_PIXEL of a mask pixel (docs/accuracy.md, "Trees from mesh files") [1]."""

OUTLINE_TEXELS_PER_PIXEL = 2.0
"""A table of 0 and 1 (an alpha-masked leaf) is drawn by its outline, the contour at 1/2 of the coarsest of its
box-filtered levels whose texel spans at most 1 / OUTLINE_TEXELS_PER_PIXEL of a mask pixel
(docs/accuracy.md, "Trees from mesh files") [1]."""


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
    outline : numpy.ndarray
        (n, 2) float64 the outlines' corners, loop after loop, (u, 1 - v) [fraction of the table].
    loop_start : numpy.ndarray
        (loops + 1,) int64 where each loop starts in ``outline``.
    loop_box : numpy.ndarray
        (loops, 4) float64 each loop's (u_min, r_min, u_max, r_max) [fraction].
    outline_range : numpy.ndarray
        (materials, L, 2) int64 the loops of each material's outline at each level.
    outline_levels : numpy.ndarray
        (materials,) int64 the levels with an outline: 0 where the table is not all 0 and 1.
    by_group : numpy.ndarray
        (m,) int64 the triangles by group (stable).
    orders : dict
        For each raster drawn (sun, plane, grid), the triangles with their groups in the bands of the first
        mesh drawn there: made on first use, so that the groups are read nearly in the order drawn (speed
        alone: the order drawn is by band and group whatever this order).
    """

    prefix: np.ndarray
    level_base: np.ndarray
    level_size: np.ndarray
    levels: np.ndarray
    double: np.ndarray
    partner: np.ndarray
    outline: np.ndarray
    loop_start: np.ndarray
    loop_box: np.ndarray
    outline_range: np.ndarray
    outline_levels: np.ndarray
    by_group: np.ndarray
    orders: dict[tuple[float, ...], np.ndarray] = field(default_factory=dict, compare=False, repr=False)


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
    loops: list[np.ndarray] = []
    outline_range = np.zeros((len(pyramids), depth, 2), dtype=np.int64)
    outline_levels = np.zeros(len(pyramids), dtype=np.int64)
    for m, pyramid in enumerate(pyramids):
        if pyramid[0].size > 1 and np.all((pyramid[0] == 0) | (pyramid[0] == 1)):
            for level, table in enumerate(pyramid):
                if min(table.shape) < 2:
                    break
                first = len(loops)
                loops += _fitted(_outline(table), float(pyramid[0].mean()))
                outline_range[m, level] = (first, len(loops))
                outline_levels[m] = level + 1
    loop_start = np.r_[0, np.cumsum([len(loop) for loop in loops])].astype(np.int64)
    outline = np.concatenate(loops) if loops else np.zeros((0, 2))
    loop_box = np.array([[*loop.min(axis=0), *loop.max(axis=0)] for loop in loops]).reshape(-1, 4)
    return CoverageTables(np.concatenate(parts), base, size, levels, np.concatenate(doubles), _partners(mesh),
                          np.ascontiguousarray(outline), loop_start, loop_box, outline_range, outline_levels,
                          np.argsort(mesh.group, kind="stable"))


def _fitted(loops: list[np.ndarray], area: float) -> list[np.ndarray]:
    """The loops moved out along their normals by one distance (and kept within the table), so that they
    enclose ``area`` [fraction^2]: a contour at 1/2 of a box-filtered table cuts into convex parts."""
    moved = loops
    for _ in range(3):
        enclosed = sum(_area(loop) for loop in moved)
        perimeter = sum(float(np.sum(np.linalg.norm(np.roll(loop, -1, axis=0) - loop, axis=1))) for loop in moved)
        if perimeter == 0.0 or abs(enclosed - area) < 1e-9:
            break
        distance = (area - enclosed) / perimeter
        moved = [np.clip(loop + distance * _miters(loop), 0.0, 1.0) for loop in moved]
    return moved


def _miters(loop: np.ndarray) -> np.ndarray:
    """(n, 2) each corner's offset for a unit move of both its edges outwards (right of the way round) [1]."""
    edge = np.roll(loop, -1, axis=0) - loop
    normal = np.column_stack([edge[:, 1], -edge[:, 0]]) / np.maximum(np.linalg.norm(edge, axis=1), 1e-300)[:, None]
    before = np.roll(normal, 1, axis=0)
    return (before + normal) / np.maximum(1.0 + np.sum(before * normal, axis=1), 0.2)[:, None]


def _area(loop: np.ndarray) -> float:
    """The loop's signed area (the shoelace) [fraction^2]."""
    x, y = loop[:, 0], loop[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _outline(table: np.ndarray) -> list[np.ndarray]:
    """The table's contour at 1/2 (linear between texel centres), as loops anticlockwise around what
    covers in (u, r) and clockwise around holes [fraction of the table]; where it runs from one side of the
    table to the next it is taken through their corner (a table covering up to its corner keeps it)."""
    import contourpy

    rows, cols = table.shape
    generator = contourpy.contour_generator(z=np.pad(table, 1), name="serial",
                                            fill_type=contourpy.FillType.OuterOffset)
    filled = generator.filled(0.5, 2.0)
    loops = []
    for polygon, starts in zip(filled[0], filled[1]):
        points = np.asarray(polygon, dtype=np.float64)
        for a, b in itertools.pairwise(np.asarray(starts, dtype=np.int64).tolist()):
            loop = np.clip(points[a:b - 1] - 0.5, 0.0, [cols, rows]) / [cols, rows]  # the last repeats the first
            on_side = np.column_stack([loop[:, 0] == 0.0, loop[:, 1] == 0.0, loop[:, 0] == 1.0, loop[:, 1] == 1.0])
            after = np.roll(on_side, -1, axis=0)
            corners = []  # from one side to the one beside it: through their corner
            for k in np.flatnonzero((on_side[:, :, None] & after[:, None, :]).reshape(-1, 16).any(axis=1)):
                side, then = np.argwhere(on_side[k][:, None] & after[k][None, :])[0]
                if side % 2 != then % 2:
                    point = loop[k].copy()
                    point[side % 2] = loop[k, side % 2]
                    point[then % 2] = loop[(k + 1) % len(loop), then % 2]
                    corners.append((k + 1, point))
            for k, point in reversed(corners):
                loop = np.insert(loop, k, point, axis=0)
            if len(loop) >= 3:
                loops.append(np.ascontiguousarray(loop))
    return loops


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
    from pipeline.kernels import mesh_arrange, triangles

    tables = coverage_tables(mesh) if tables is None else tables
    leaf = mesh.leaf
    drawn = leaf.copy()
    if not leaf.all():
        drawn[~leaf] = sun_facing(mesh, sun=sun, select=~leaf)
    if select is not None:
        drawn &= select
    key = (*np.asarray(sun, dtype=np.float64).tolist(), float(plane_height), *grid.origin, grid.pixel, *grid.shape)
    if key not in tables.orders:
        if len(tables.orders) >= _ORDERS_KEPT:
            tables.orders.clear()
        tables.orders[key] = _in_bands(mesh, tables.by_group, sun, plane_height, grid)
    near = tables.orders[key]
    chosen = near[drawn[near]]  # each group's triangles together
    corners, texels, material, group_start, partner = mesh_arrange.arrange(
        mesh.vertices, mesh.triangles, mesh.uv, mesh.material, mesh.group, tables.partner, chosen,
        np.asarray(sun, dtype=np.float64), float(plane_height), np.asarray(grid.origin, dtype=np.float64),
        float(grid.pixel), _BAND_ROWS, not np.all(tables.outline_levels[mesh.material[chosen]] > 0))
    transmittance = np.ones(grid.shape)
    triangles.mesh_transmittance(corners, texels, material, group_start, tables.prefix, tables.level_base,
                                 tables.level_size, tables.levels, TEXELS_PER_PIXEL, transmittance, tables.double,
                                 partner, tables.outline, tables.loop_start, tables.loop_box, tables.outline_range,
                                 tables.outline_levels, OUTLINE_TEXELS_PER_PIXEL)
    return transmittance.astype(np.float32)


def _in_bands(mesh: TreeMesh, by_group: np.ndarray, sun: ArrayLike, plane_height: float, grid: Grid) -> np.ndarray:
    """The triangles, each group's together, the groups by the band of rows their first corner falls in."""
    group = mesh.group[by_group]
    start = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    first = mesh.vertices[mesh.triangles[by_group[start], 0]]
    y = (grid.origin[1] - (first[:, 1] - (first[:, 2] - plane_height) * np.asarray(sun, dtype=np.float64)[1]))
    order = np.argsort(np.floor(y / grid.pixel / _BAND_ROWS), kind="stable")
    sizes = np.diff(np.r_[start, len(by_group)])[order]
    moved = np.repeat(start[order] - np.cumsum(sizes) + sizes, sizes) + np.arange(len(by_group))
    return by_group[moved]


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
