"""The trees' detail in the camera: stems as tapered tubes (``taper_wood``) with furrowed bark
(``bark_pattern``), and a periodic forest's tile copied over the view with its far leaves simplified
(``periodic_copies``) (docs/method.md, "Pictures without tells").
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pipeline.camera.pinhole import Camera
from pipeline.canopy.grove import Leaves, Wood
from pipeline.core.geometry import normalized

__all__ = ["BARK_FURROWS", "BARK_CONTRAST", "bark_pattern", "TIP_TAPER", "TAPER_PIECE", "taper_wood", "LEAF_PIXELS",
           "HAZE_REACH", "MAX_FOREST_REACH", "STEM_DETAIL_PIXELS", "periodic_copies"]

BARK_FURROWS = (14, 23)
"""Furrows round a trunk or branch in ``bark_pattern``: two families, so that the ridges are
uneven, not a corduroy. [count]"""

BARK_CONTRAST = 0.25
"""Bark reflectance runs from (1 - BARK_CONTRAST) to (1 + BARK_CONTRAST) times its mean
between the furrows' floors and ridges. [1]"""


def bark_pattern(normal: np.ndarray, axis: ArrayLike, height: np.ndarray, radius_px: ArrayLike) -> np.ndarray:
    """Factor on the bark's reflectance at wood fragments: vertical furrows round the stem.

    The furrows wander a little with height, mean 1 (so the stem's mean reflectance stays
    BARK_REFLECTANCE), and fade out where a furrow would be under 4 pixels wide (no moire on a far
    or thin stem).

    Parameters
    ----------
    normal : numpy.ndarray
        (n, 3) the stem's outward unit normal at the fragment [1].
    axis : numpy.ndarray
        (n, 3) the stem's direction (any length) [m].
    height : numpy.ndarray
        (n,) the height of the fragment's axis point [m].
    radius_px : numpy.ndarray
        (n,) the stem's radius in the image [pixel].

    Returns
    -------
    numpy.ndarray
        (n,) float64 factor [1].
    """
    axis = normalized(np.asarray(axis, dtype=np.float64))
    reference = normalized(np.cross(axis, np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])))
    across = np.cross(axis, reference)
    angle = np.arctan2(np.sum(normal * across, axis=1), np.sum(normal * reference, axis=1))
    wander = 0.6 * np.sin(2 * np.pi * height / 0.9) + 0.3 * np.sin(2 * np.pi * height / 0.37 + 1.3)
    coarse, fine = BARK_FURROWS
    ridge = 0.6 * np.cos(coarse * angle + wander) + 0.4 * np.cos(fine * angle + 2.1 - 1.7 * wander)
    period_px = 2 * np.pi * np.asarray(radius_px) / fine
    fade = np.clip((period_px - 4.0) / 4.0, 0.0, 1.0)
    return 1.0 + BARK_CONTRAST * fade * ridge


TIP_TAPER = 0.7
"""A stem that nothing continues (a branch's tip, a trunk's top) narrows to this share of its
radius at its end (``taper_wood``). [1]"""

TAPER_PIECE = 0.25
"""Length of the pieces a stem is cut into by ``taper_wood``. [m]"""


def taper_wood(wood: Wood) -> tuple[Wood, np.ndarray]:
    """The stems as smooth, tapering tubes, drawn as pieces about TAPER_PIECE [m] long.

    Capsules are chained where one starts at the other's end (a trunk's segments, a branch's
    two halves); each chain's axis becomes the Catmull-Rom spline through its joints (Catmull
    & Rom, "A class of local interpolating splines", 1974; uniform, with mirrored end points),
    so the axis, and with it the normal that shades the stem, turns gradually instead of at a
    joint at the same height on every trunk; the radius runs linearly from each capsule's own
    at its start to the next one's (or to TIP_TAPER of its own at a chain's end), so the width
    changes by millimetres from piece to piece instead of by centimetres at a joint. Each piece
    also gets its own sun visibility (``stem_visibility``), so the light on a trunk fades where
    the crown's shade begins.

    Parameters
    ----------
    wood : grove.Wood
        The capsules: ends (M, 3) and radii (M,) [m].

    Returns
    -------
    pieces : grove.Wood
        The pieces: ends (k, 3) and radii (k,) [m].
    owner : numpy.ndarray
        (k,) int64, the capsule each piece comes from.
    """
    start, end = np.asarray(wood.start, dtype=np.float64), np.asarray(wood.end, dtype=np.float64)
    radius = np.asarray(wood.radius, dtype=np.float64)
    starts = {tuple(np.round(p, 9)): i for i, p in enumerate(start)}
    follower = [starts.get(tuple(np.round(p, 9)), -1) for p in end]
    follower = [f if f != i else -1 for i, f in enumerate(follower)]
    has_predecessor = np.zeros(len(radius), bool)
    for f in follower:
        if f >= 0:
            has_predecessor[f] = True
    pieces_start, pieces_end, pieces_radius, owner = [], [], [], []
    seen = np.zeros(len(radius), bool)
    heads = [i for i in range(len(radius)) if not has_predecessor[i]] + list(range(len(radius)))
    for head in heads:  # chains from their heads; then any capsule left (a closed loop)
        chain, i = [], head
        while i >= 0 and not seen[i]:
            seen[i] = True
            chain.append(i)
            i = follower[i]
        if not chain:
            continue
        knots = np.vstack([start[chain[0]], end[chain]])
        radii = np.append(radius[chain], TIP_TAPER * radius[chain[-1]])
        padded = np.vstack([2 * knots[0] - knots[1], knots, 2 * knots[-1] - knots[-2]])
        for k, capsule in enumerate(chain):
            p0, p1, p2, p3 = padded[k : k + 4]
            count = max(1, int(np.ceil(np.linalg.norm(p2 - p1) / TAPER_PIECE)))
            u = np.linspace(0.0, 1.0, count + 1)[:, None]
            curve = 0.5 * ((2 * p1) + (p2 - p0) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u**2
                           + (3 * p1 - p0 - 3 * p2 + p3) * u**3)
            middle = 0.5 * (u[:-1, 0] + u[1:, 0])
            pieces_start.append(curve[:-1])
            pieces_end.append(curve[1:])
            pieces_radius.append(radii[k] + middle * (radii[k + 1] - radii[k]))
            owner.append(np.full(count, capsule))
    if not owner:
        return Wood(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)), np.zeros(0, np.int64)
    return (Wood(np.concatenate(pieces_start), np.concatenate(pieces_end), np.concatenate(pieces_radius)),
            np.concatenate(owner).astype(np.int64))


# ---------------------------------------------------------------------------------------------
# A periodic forest in the camera: the tile's trees copied over every tile in view
# ---------------------------------------------------------------------------------------------

LEAF_PIXELS = 6.0
"""A periodic forest's copied leaves are drawn at least this long in the image: within the
distance D = focal x (median leaf length) / LEAF_PIXELS of the camera every leaf is drawn
(10 m for configs/forest.yaml at 1280 x 720, 2.5 m in its preview); beyond it a leaf is kept
with probability (D / d)^2 and, kept, grown by d / D in both axes, so its expected area, and the
crown's coverage, is unchanged (stochastic simplification, Cook, Halstead, Planck & Ryu,
"Stochastic Simplification of Aggregate Detail", ACM TOG 26(3), 2007): a far crown costs as
many leaves as it has pixels, not as it has leaves. [pixel]"""

HAZE_REACH = 3.0
"""Copies of a periodic forest are drawn out to this many haze extinction lengths, where the
haze lets 1.8 % of their light through, and to no more than MAX_FOREST_REACH. [1]"""

MAX_FOREST_REACH = 600.0
"""Farthest copies drawn of a periodic forest, whatever the haze. [m]"""


STEM_DETAIL_PIXELS = 2.0
"""Copies of a periodic forest whose stems are all under this radius in the image are drawn
with the straight capsules (``coarse_wood``) instead of the tapered pieces: a joint's step in
width is then under half a pixel, and 40 pieces a trunk would cost more than the leaves. [pixel]"""


def periodic_copies(leaves: Leaves, wood: Wood, camera: Camera, *, period: float, center: ArrayLike, haze: float,
                    seed: int = 0, coarse_wood: Wood | None = None) -> tuple[Leaves, Wood, np.ndarray, np.ndarray]:
    """The shapes of one tile of a periodic forest copied over every tile the camera sees.

    Every shape is wrapped into the tile, as ``grove.grow_grove`` makes them; the copies are those
    whose bounds (the tile and its crowns) lie within reach (HAZE_REACH haze lengths, at most
    MAX_FOREST_REACH) and inside the view's cone, far leaves simplified as LEAF_PIXELS says.

    Parameters
    ----------
    leaves : grove.Leaves
        The tile's leaves [m].
    wood : grove.Wood
        The tile's wood [m].
    camera : pinhole.Camera
        The pinhole camera.
    period : float
        The tile's side [m].
    center : array_like
        (x, y) of the tile's centre [m].
    haze : float
        Extinction length of the air (0: none, MAX_FOREST_REACH) [m].
    seed : int, optional
        Seed of the leaves' choice (default_rng([seed, 3])).
    coarse_wood : grove.Wood, optional
        The stems as fewer, straight capsules, drawn instead of ``wood`` in the copies that
        STEM_DETAIL_PIXELS allows (None: ``wood`` everywhere) [m].

    Returns
    -------
    leaves : grove.Leaves
        The copied leaves [m].
    wood : grove.Wood
        The copied stems [m].
    leaf_index : numpy.ndarray
        (N',) int64, the leaf of the tile that each is a copy of (for its per-shape values: sun
        visibility).
    wood_index : numpy.ndarray
        (M',) int64, the same for the stems, those of ``coarse_wood`` numbered after those of
        ``wood``.
    """
    reach = min(HAZE_REACH * haze if haze > 0 else MAX_FOREST_REACH, MAX_FOREST_REACH)
    shift, nearest = _tiles_in_view(leaves, wood, camera, float(period), np.asarray(center, dtype=np.float64), reach)
    copied_leaves, leaf_index = _copied_leaves(leaves, camera, shift, nearest, seed)
    copied_wood, wood_index = _copied_wood(wood, coarse_wood, camera, shift, nearest)
    return copied_leaves, copied_wood, leaf_index, wood_index


def _tiles_in_view(leaves: Leaves, wood: Wood, camera: Camera, period: float, center: np.ndarray,
                   reach: float) -> tuple[np.ndarray, np.ndarray]:
    """The copies of the tile centred at ``center`` (2,) [m] whose bounds come within ``reach`` [m] of
    the camera inside the view's cone: the shift (k, 2) [m] of each from the tile, and the distance
    (k,) from the camera to its bounds (at least 1e-9) [m]."""
    position = np.asarray(camera.position, dtype=np.float64)
    everything = np.concatenate([leaves.center, wood.start, wood.end])
    low, high = everything.min(axis=0), everything.max(axis=0)
    # half-width of the tile's shapes
    margin = float(np.max(np.maximum(np.abs(low[:2] - center), np.abs(high[:2] - center))))
    radius = np.sqrt(2.0) * margin + float(np.max(wood.radius, initial=0.0))
    forward = camera.basis[2]
    half_diagonal = np.arctan(0.5 * np.hypot(camera.width, camera.height) / camera.focal)
    count = int(np.ceil((reach + radius) / period))
    i, j = np.meshgrid(np.arange(-count, count + 1), np.arange(-count, count + 1), indexing="ij")
    shift = np.column_stack([i.ravel(), j.ravel()]) * period
    centres = center + shift
    middle = np.column_stack([centres, np.full(len(centres), 0.5 * (low[2] + high[2]))])
    bound = np.hypot(radius, 0.5 * (high[2] - low[2]))
    to = middle - position
    distance = np.linalg.norm(to, axis=1)
    # the cone of the view (the image's half-diagonal about ``forward``), widened by each copy's bounds
    angle = np.arccos(np.clip(to @ forward / np.maximum(distance, 1e-12), -1.0, 1.0))
    inside = distance <= bound
    widen = np.arcsin(np.clip(bound / np.maximum(distance, 1e-12), 0.0, 1.0))
    seen = inside | ((distance - bound <= reach) & (angle - widen <= half_diagonal))
    return shift[seen], np.maximum(distance[seen] - bound, 1e-9)


def _copied_leaves(leaves: Leaves, camera: Camera, shift: np.ndarray, nearest: np.ndarray,
                   seed: int) -> tuple[Leaves, np.ndarray]:
    """The tile's leaves in the copies shifted by ``shift`` (k, 2) [m], whose bounds are ``nearest``
    (k,) [m] from the camera, simplified as LEAF_PIXELS says; and the (N',) int64 leaf of the tile
    each is a copy of. Each leaf draws a number in [0, 1), each copy a turn of them."""
    position = np.asarray(camera.position, dtype=np.float64)
    rng = np.random.default_rng([seed, 3])
    draw = rng.random(len(leaves.center))
    tile_draw = rng.random(len(shift))
    length = 2.0 * np.median(np.linalg.norm(leaves.axis_u, axis=1)) if len(draw) else 0.0
    full_detail = camera.focal * length / LEAF_PIXELS  # [m]
    by_draw = np.argsort(draw)
    sorted_draw = draw[by_draw]
    centers, axes_u, axes_v, leaf_index = [], [], [], []
    for offset, turn, near in zip(shift, tile_draw, nearest):
        candidates = _leaf_candidates(by_draw, sorted_draw, turn, min(1.0, (full_detail / near) ** 2))
        c = leaves.center[candidates] + np.array([offset[0], offset[1], 0.0])
        d = np.linalg.norm(c - position, axis=1)
        keep_share = np.minimum(1.0, (full_detail / np.maximum(d, 1e-9)) ** 2)
        chosen = np.mod(draw[candidates] + turn, 1.0) < keep_share
        kept = candidates[chosen]
        c, keep_share = c[chosen], keep_share[chosen]
        grow = 1.0 / np.sqrt(keep_share)[:, None]
        centers.append(c)
        axes_u.append(leaves.axis_u[kept] * grow)
        axes_v.append(leaves.axis_v[kept] * grow)
        leaf_index.append(kept)
    return Leaves(np.concatenate(centers), np.concatenate(axes_u), np.concatenate(axes_v)), np.concatenate(leaf_index)


def _leaf_candidates(by_draw: np.ndarray, sorted_draw: np.ndarray, turn: float, most: float) -> np.ndarray:
    """The leaves a copy could keep: those whose (draw + turn) mod 1 lies below ``most``, the share
    kept at the copy's nearest point [1]; ``by_draw`` the leaves in the order of their draws,
    ``sorted_draw`` the draws in that order."""
    if most >= 1.0:
        return by_draw
    lo, hi = 1.0 - turn, 1.0 - turn + most
    return np.concatenate([by_draw[np.searchsorted(sorted_draw, lo):np.searchsorted(sorted_draw, hi)],
                           by_draw[:np.searchsorted(sorted_draw, hi - 1.0)]])


def _copied_wood(wood: Wood, coarse_wood: Wood | None, camera: Camera, shift: np.ndarray,
                 nearest: np.ndarray) -> tuple[Wood, np.ndarray]:
    """The tile's stems in the copies shifted by ``shift`` (k, 2) [m], those of ``coarse_wood`` where
    STEM_DETAIL_PIXELS allows at ``nearest`` (k,) [m]; and the (M',) int64 stem each is a copy of,
    those of ``coarse_wood`` numbered after those of ``wood``."""
    sources = [wood] if coarse_wood is None else [wood, coarse_wood]
    every = Wood(*(np.concatenate([getattr(w, f) for w in sources]) for f in ("start", "end", "radius")))
    fine = np.arange(len(wood.radius))
    coarse = fine if coarse_wood is None else len(wood.radius) + np.arange(len(coarse_wood.radius))
    thin = camera.focal * float(np.max(wood.radius, initial=0.0)) / nearest < STEM_DETAIL_PIXELS
    wood_index = np.concatenate([coarse if far else fine for far in thin] or [np.zeros(0, np.int64)])
    moved = np.repeat(np.column_stack([shift, np.zeros(len(shift))]),
                      [len(coarse) if far else len(fine) for far in thin], axis=0)
    return Wood(every.start[wood_index] + moved, every.end[wood_index] + moved, every.radius[wood_index]), wood_index
