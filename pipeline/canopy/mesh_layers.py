"""Mesh trees in the canopy's layers: read once per process, fluttered, drawn into each plane's masks, summed up.

``mesh_tree`` reads a tree (``mesh.read_mesh``) with its leaves' motion (``mesh_flutter``) and coverage
tables, once per process; ``layer_transmittance`` draws the trees' share of one plane at one cycle frame
(``mesh_coverage.mesh_mask``); ``shadow_bounds`` is where a tree's shadow can fall over the whole cycle,
``mesh_bytes`` the memory a worker needs for it and ``mesh_summary`` what ``sunshade check`` prints
(docs/method.md, "Trees from mesh files").
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy import mesh_coverage, mesh_flutter
from pipeline.canopy.grove import FlutterParams
from pipeline.canopy.mesh import MeshParams, TreeMesh, read_mesh
from pipeline.core.geometry import Grid
from pipeline.core.mesh_files import mesh_files

__all__ = ["MAX_MESH_BYTES", "MeshTree", "MeshSummary", "mesh_tree", "layer_transmittance", "shadow_bounds",
           "mesh_bytes", "mesh_summary"]

MAX_MESH_BYTES = 4e9
"""Most memory one worker may take for the mesh trees: their triangles (at rest and fluttered), coverage
tables and one plane's masks (``mesh_bytes``) [B]."""

_TRIANGLE_BYTES = 3 * 3 * 8 * 3 + 3 * 2 * 8 + 4 * 8 + 3 * 2 * 8 * 2
"""Bytes per triangle: its corners at rest, fluttered and projected, its uv, material, group, layer, and
the kernel's pixel and texel corners (float64 and int64) [B]."""


@dataclass(frozen=True, eq=False)
class MeshTree:
    """A mesh tree read once: the tree at rest, its leaves' motion and its coverage tables (hashed by identity).

    Attributes
    ----------
    mesh : TreeMesh
        The tree at rest [m].
    motion : mesh_flutter.LeafMotion
        Each leaf's pivot, axes and phases.
    tables : mesh_coverage.CoverageTables
        Its materials' coverage tables.
    """

    mesh: TreeMesh
    motion: mesh_flutter.LeafMotion
    tables: mesh_coverage.CoverageTables


@dataclass(frozen=True)
class MeshSummary:
    """What ``sunshade check`` says about a mesh tree.

    Attributes
    ----------
    triangles : int
        Triangles drawn [count].
    skipped : int
        Zero-area triangles left out [count].
    leaves : int
        Leaves found (groups of leaf triangles) [count].
    leaf_triangles : int
        Triangles of the leaves [count].
    leaf_area : float
        The leaves' alpha-weighted area, one side [m^2].
    box : tuple of 6 float
        (x_min, y_min, z_min, x_max, y_max, z_max) at rest [m].
    layers : tuple of int
        Triangles in each canopy plane [count].
    """

    triangles: int
    skipped: int
    leaves: int
    leaf_triangles: int
    leaf_area: float
    box: tuple[float, float, float, float, float, float]
    layers: tuple[int, ...]


def mesh_tree(params: MeshParams, *, seed: int, index: int = 0) -> MeshTree:
    """A mesh tree read, its leaves' motion found and its tables made, once per process while its files
    (``core.mesh_files.mesh_files``) keep their sizes and times.

    Parameters
    ----------
    params : MeshParams
        The file and where it stands.
    seed, index
        As in ``mesh_flutter.leaf_motion``.

    Returns
    -------
    MeshTree
        The tree.

    Raises
    ------
    ImageError
        One line naming the file (``mesh.read_mesh``).
    """
    stamps = tuple((str(file), file.stat().st_size, file.stat().st_mtime_ns) for file in mesh_files(params.path))
    return _read_tree(params, stamps, seed, index)


@functools.lru_cache(maxsize=4)
def _read_tree(params: MeshParams, stamps: tuple, seed: int, index: int) -> MeshTree:
    """``mesh_tree``'s tree, kept under its files' ``stamps`` (a file rewritten is read again)."""
    mesh = read_mesh(params)
    return MeshTree(mesh, mesh_flutter.leaf_motion(mesh, seed=seed, index=index), mesh_coverage.coverage_tables(mesh))


@functools.lru_cache(maxsize=16)
def _layer_of(tree: MeshTree, heights: tuple[float, ...]) -> np.ndarray:
    """Each triangle's canopy plane, by the tree at rest."""
    return mesh_coverage.mesh_layer_index(tree.mesh, heights)


def layer_transmittance(trees: Sequence[MeshTree], flutter: FlutterParams, frame: int, *, heights: Sequence[float],
                        layer: int, sun: ArrayLike, grid: Grid) -> np.ndarray:
    """The mesh trees' transmittance on one canopy plane at one cycle frame.

    Each tree's leaves flutter (``mesh_flutter.mesh_at``); its triangles whose plane (at rest) is ``layer``
    are drawn by exact coverage; trees combine as products.

    Parameters
    ----------
    trees : sequence of MeshTree
        The trees.
    flutter : FlutterParams
        Cycle [frames] and amplitudes [rad].
    frame : int
        The cycle frame [frames].
    heights : sequence of float
        Heights of all the canopy planes [m].
    layer : int
        The plane drawn, an index of ``heights``.
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    grid : Grid
        The raster [m].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 transmittance [1].
    """
    result: np.ndarray | None = None
    for tree in trees:
        moved = mesh_flutter.mesh_at(tree.mesh, tree.motion, flutter, frame)
        select = _layer_of(tree, tuple(float(h) for h in heights)) == layer
        mask = mesh_coverage.mesh_mask(moved, sun=sun, plane_height=float(heights[layer]), grid=grid, select=select,
                                       tables=tree.tables)
        result = mask if result is None else (result * mask).astype(np.float32)
    return np.ones(grid.shape, np.float32) if result is None else result


def shadow_bounds(tree: MeshTree, *, sun: ArrayLike, plane_height: float) -> tuple[float, float, float, float]:
    """The rectangle the tree's shadow on the plane z = plane_height can reach over the whole flutter cycle.

    A leaf's points stay within their farthest distance r from its pivot however it turns, and a
    displacement d projects to length at most |d| sqrt(1 + |s|^2); the wood stays.

    Parameters
    ----------
    tree : MeshTree
        The tree.
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    plane_height : float
        Height of the plane [m].

    Returns
    -------
    tuple of 4 float
        (x_min, y_min, x_max, y_max) [m].
    """
    s = np.asarray(sun, dtype=np.float64)
    mesh = tree.mesh
    onto = lambda p: p[:, :2] - (p[:, 2:3] - plane_height) * s  # noqa: E731
    leaf = mesh.leaf
    corners = mesh.vertices[mesh.triangles]
    owner = np.repeat(mesh.group[leaf], 3)
    leaf_corners = corners[leaf].reshape(-1, 3)
    reach = np.zeros(len(tree.motion.pivot))
    np.maximum.at(reach, owner, np.linalg.norm(leaf_corners - tree.motion.pivot[owner], axis=1))
    reach *= np.hypot(1.0, np.hypot(*s))
    pivots = onto(tree.motion.pivot)
    wood = onto(corners[~leaf].reshape(-1, 3))
    low = np.concatenate([pivots - reach[:, None], wood])
    high = np.concatenate([pivots + reach[:, None], wood])
    return (*low.min(axis=0), *high.max(axis=0))


def mesh_bytes(tree: MeshTree, grid_cells: int) -> float:
    """The memory one worker takes for a mesh tree drawing one plane's masks.

    Parameters
    ----------
    tree : MeshTree
        The tree.
    grid_cells : int
        The cells of the largest mask drawn at once [count].

    Returns
    -------
    float
        [B]
    """
    return float(len(tree.mesh.triangles) * _TRIANGLE_BYTES + tree.tables.prefix.nbytes + 12 * grid_cells)


def mesh_summary(tree: MeshTree, heights: Sequence[float]) -> MeshSummary:
    """The tree's triangles, leaves, leaf area, bounding box and triangles per plane.

    Parameters
    ----------
    tree : MeshTree
        The tree.
    heights : sequence of float
        Heights of the canopy planes [m].

    Returns
    -------
    MeshSummary
        The figures.
    """
    mesh = tree.mesh
    leaf = mesh.leaf
    used = mesh.vertices[np.unique(mesh.triangles)]
    layer = _layer_of(tree, tuple(float(h) for h in heights))
    return MeshSummary(
        triangles=len(mesh.triangles), skipped=mesh.skipped, leaves=len(tree.motion.pivot),
        leaf_triangles=int(np.count_nonzero(leaf)), leaf_area=mesh_coverage.alpha_weighted_area(mesh, tree.tables),
        box=(*(float(v) for v in used.min(axis=0)), *(float(v) for v in used.max(axis=0))),  # type: ignore[arg-type]
        layers=tuple(int(n) for n in np.bincount(layer, minlength=len(heights))))
