"""A mesh tree's leaves fluttering: each leaf (a group of leaf triangles) swings and twists about where it attaches.

``leaf_motion`` finds each leaf's attachment point (its corner nearest the wood, or without wood its end
along its long axis nearer the tree's middle), its long axis and its phases; ``mesh_at`` turns every leaf
rigidly on the flutter cycle as ``grove.leaves_at`` turns the procedural leaves, the wood still
(docs/method.md, "Trees from mesh files").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.canopy.grove import FlutterParams, swing_axes
from pipeline.canopy.mesh import TreeMesh

__all__ = ["LeafMotion", "leaf_motion", "mesh_at"]


@dataclass(frozen=True)
class LeafMotion:
    """Each leaf of a mesh tree at rest, as its flutter needs it.

    Attributes
    ----------
    pivot : numpy.ndarray
        (L, 3) where each leaf attaches: the point it turns about [m].
    length_axis : numpy.ndarray
        (L, 3) unit vectors along each leaf's long axis, pointing away from the pivot: the twist's axis [1].
    swing_axis : numpy.ndarray
        (L, 3) horizontal unit vectors across each leaf: the swing's axis [1].
    swing_phase, twist_phase : numpy.ndarray
        (L,) [rad].
    rest : numpy.ndarray
        (m, 3, 3) every triangle's corners at rest [m].
    leaf_triangles : numpy.ndarray
        (k,) int64 the leaf triangles, in ``rest``.
    owner : numpy.ndarray
        (k,) int64 the leaf of each.
    arm : numpy.ndarray
        (k, 3, 3) each leaf triangle's corners' offsets from its leaf's pivot [m].
    """

    pivot: np.ndarray
    length_axis: np.ndarray
    swing_axis: np.ndarray
    swing_phase: np.ndarray
    twist_phase: np.ndarray
    rest: np.ndarray
    leaf_triangles: np.ndarray
    owner: np.ndarray
    arm: np.ndarray


def leaf_motion(mesh: TreeMesh, *, seed: int, index: int = 0) -> LeafMotion:
    """Each leaf's pivot, axes and phases, deterministic from the seed.

    The pivot is the leaf's corner nearest the wood: nearest the point of the wood (its corners, edge
    midpoints and centroids) nearest the mean of the leaf's corners. A tree without wood pivots each
    leaf at the end of its long axis (the corners' principal axis) nearer the leaves' horizontal middle.
    The phases are uniform on [0, 2 pi) from default_rng([seed, 3, index]).

    Parameters
    ----------
    mesh : TreeMesh
        The tree at rest [m].
    seed : int
        The flutter's seed.
    index : int, optional
        The tree's place among the config's mesh trees.

    Returns
    -------
    LeafMotion
        One row per leaf group (``TreeMesh.group`` 0 .. L - 1).
    """
    leaf = mesh.leaf
    group = mesh.group[leaf]
    count = int(group.max()) + 1 if len(group) else 0
    n = max(len(mesh.vertices), 1)
    pairs = np.unique(np.repeat(group, 3) * n + mesh.triangles[leaf].reshape(-1))
    owner, corners = pairs // n, mesh.vertices[pairs % n]  # each leaf's corners, once each
    weight = np.maximum(np.bincount(owner, minlength=count), 1).astype(np.float64)
    mean = np.stack([np.bincount(owner, corners[:, k], minlength=count) for k in range(3)], axis=1) / weight[:, None]
    offset = corners - mean[owner]
    moment = np.zeros((count, 3, 3))
    for j in range(3):
        for k in range(3):
            moment[:, j, k] = np.bincount(owner, offset[:, j] * offset[:, k], minlength=count)
    axis = np.linalg.eigh(moment)[1][:, :, -1] if count else np.zeros((0, 3))
    wood = ~leaf
    if wood.any():
        from scipy.spatial import cKDTree

        pieces = mesh.vertices[mesh.triangles[wood]]
        targets = np.unique(np.concatenate([pieces.reshape(-1, 3),
                                            0.5 * (pieces + np.roll(pieces, 1, axis=1)).reshape(-1, 3),
                                            pieces.mean(axis=1)]), axis=0)
        anchor = targets[cKDTree(targets, leafsize=64).query(mean)[1]]  # the wood nearest each leaf's middle
        distance = np.linalg.norm(corners - anchor[owner], axis=1)
    else:
        along = np.einsum("ij,ij->i", offset, axis[owner])
        middle = mean.mean(axis=0) if count else np.zeros(3)
        ends = np.where(np.einsum("ij,ij->i", (middle - mean)[:, :2], axis[:, :2]) >= 0, 1.0, -1.0)
        distance = -along * ends[owner]  # the end of the long axis towards the middle comes first
    order = np.lexsort((distance, owner))
    first = order[np.flatnonzero(np.r_[True, owner[order][1:] != owner[order][:-1]])]
    pivot = corners[first]
    outward = np.where(np.einsum("ij,ij->i", mean - pivot, axis) >= 0, 1.0, -1.0)
    length_axis = axis * outward[:, None]
    swing_axis = swing_axes(length_axis)
    rng = np.random.default_rng([seed, 3, index])
    rest = mesh.vertices[mesh.triangles]
    leaf_triangles = np.flatnonzero(leaf)
    arm = rest[leaf_triangles] - pivot[group][:, None, :]
    return LeafMotion(pivot, length_axis, swing_axis, rng.uniform(0, 2 * np.pi, count),
                      rng.uniform(0, 2 * np.pi, count), rest, leaf_triangles, group, np.ascontiguousarray(arm))


def mesh_at(mesh: TreeMesh, motion: LeafMotion, flutter: FlutterParams, frame: int) -> TreeMesh:
    """The tree at ``frame`` (any int), exactly periodic: every leaf turned rigidly about its pivot.

    Each leaf twists about its long axis, then swings about its horizontal axis, both through its pivot,
    as ``grove.FlutterParams`` says; the wood stays. The two turns are made one rotation a leaf, which
    then turns the leaf's corners (compiled: ``kernels/mesh_arrange.py``, ``turn_corners``). Every triangle
    gets corners of its own (none shared), its texture coordinates, material and group kept.

    Parameters
    ----------
    mesh : TreeMesh
        The tree at rest [m].
    motion : LeafMotion
        ``leaf_motion(mesh, ...)``.
    flutter, frame
        As in ``grove.leaves_at``.

    Returns
    -------
    TreeMesh
        The tree at ``frame`` [m].
    """
    from pipeline.kernels.mesh_arrange import turn_corners

    omega = flutter.angle(frame)
    corners = turn_corners(motion.rest, motion.leaf_triangles, motion.owner, motion.arm, motion.pivot,
                           motion.length_axis, flutter.twist * np.sin(omega + motion.twist_phase),
                           motion.swing_axis, flutter.swing * np.sin(omega + motion.swing_phase))
    return replace(mesh, vertices=corners.reshape(-1, 3), triangles=np.arange(3 * len(corners)).reshape(-1, 3))
