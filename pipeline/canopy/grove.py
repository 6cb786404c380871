"""The procedural grove: trees of wood and leaves grown from a seed, their flutter, their projection along the sun.

``grow_grove`` grows a seeded grove (trunks and branches as capsules, elliptical leaves),
``leaves_at`` makes its leaves flutter periodically and ``project`` casts leaves and wood along
the sun onto a canopy plane as ``Shapes``, which ``rasteriser.py`` draws (docs/method.md, "The
grove and its masks").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.geometry import normalized

__all__ = ["GroveParams", "FlutterParams", "Leaves", "Wood", "Grove", "Shapes", "grow_grove", "leaves_at", "project",
           "swing_axes", "layer_index", "shapes_bounds", "grove_bounds", "trunks"]


# ---------------------------------------------------------------------------------------------
# Procedural grove: trees with wood (capsules) and fluttering elliptical leaves, projected along
# the sun onto the canopy plane and rasterized with anti-aliasing into a transmittance mask.
#
# The projection (Max 1991, Fig. 1): a ray from ground point x towards the sun crosses height z
# at x + z s, s = (wx / wz, wy / wz) the sun's sky-plane point, so a point P lands on the canopy
# plane z = h at P_xy - (P_z - h) s. The map is affine: a flat elliptical leaf (centre C,
# semi-axes U, V) becomes the ellipse of centre proj(C) and conjugate semi-axes
# U_xy - U_z s, V_xy - V_z s.
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GroveParams:
    """A seeded procedural grove.

    Attributes
    ----------
    count : int
        Number of trees.
    seed : int
        Random seed (every tree draws from default_rng([seed, 1, i])).
    crown_radius : float
        Horizontal half-axis of each crown ellipsoid [m].
    leaves_per_tree : int
        Leaves of each tree.
    leaf_length : float
        Mean leaf length; lengths vary by +-30 %, width/length 0.4 to 0.7 [m].
    leaves_per_cluster : int
        Mean leaves per cluster (Gaussian, sigma 0.06 crown_radius); 1 scatters the leaves evenly
        over the crown's shell.
    height : float
        Height of the crowns' centres, the canopy plane [m].
    layout : str
        "isolated" (a clump around ``center``) or "periodic" (trees in a square ``tile``, every
        shape wrapped into it).
    tile : float or None
        Period of the periodic layout, required for it [m].
    center : tuple of (float, float)
        (x, y) of the clump or of the tile's centre [m].
    spread : float or None
        Radius of the disc the trunks stand in; default 0.8 crown_radius sqrt(count - 1), which
        makes neighbouring crowns overlap a little [m].
    """

    count: int = 3
    seed: int = 7
    crown_radius: float = 4.0
    leaves_per_tree: int = 12000
    leaf_length: float = 0.08
    leaves_per_cluster: int = 40
    height: float = 8.0
    layout: str = "isolated"
    tile: float | None = None
    center: tuple[float, float] = (0.0, 0.0)
    spread: float | None = None


@dataclass(frozen=True)
class FlutterParams:
    """Leaf flutter: every leaf swings and twists, each by amplitude sin(2 pi frame / cycle + its own phase).

    The swing is about a horizontal axis through its stem, the twist about its own length axis.

    Attributes
    ----------
    cycle : int
        Frames of one exactly periodic cycle [frames].
    swing : float
        Amplitude of the swing [rad].
    twist : float
        Amplitude of the twist [rad].
    """

    cycle: int = 48
    swing: float = float(np.radians(12.0))
    twist: float = float(np.radians(20.0))

    def angle(self, frame: int) -> float:
        """The cycle's angle at ``frame`` (any int), reduced modulo ``cycle``: 2 pi (frame mod cycle) / cycle.

        Parameters
        ----------
        frame : int
            The frame [frames].

        Returns
        -------
        float
            The angle the phases are added to [rad].
        """
        return 2 * np.pi * np.mod(frame, self.cycle) / self.cycle


@dataclass(frozen=True)
class Leaves:
    """Flat elliptical leaves.

    Attributes
    ----------
    center : numpy.ndarray
        (N, 3) centres [m].
    axis_u : numpy.ndarray
        (N, 3) semi-axis along the length [m].
    axis_v : numpy.ndarray
        (N, 3) semi-axis across, perpendicular to ``axis_u`` [m].
    """

    center: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray


@dataclass(frozen=True)
class Grove:
    """A grove at rest.

    Attributes
    ----------
    leaves : Leaves
        Rest pose [m].
    pivot : numpy.ndarray
        (N, 3) the stem end of each leaf [m].
    swing_axis : numpy.ndarray
        (N, 3) horizontal unit vectors [1].
    swing_phase, twist_phase : numpy.ndarray
        (N,) [rad].
    wood : Wood
        Trunks and branches [m].
    bases : numpy.ndarray
        (count, 3) trunk feet [m].
    params : GroveParams
        The parameters it grew from.
    """

    leaves: Leaves
    pivot: np.ndarray
    swing_axis: np.ndarray
    swing_phase: np.ndarray
    twist_phase: np.ndarray
    wood: Wood
    bases: np.ndarray
    params: GroveParams


@dataclass(frozen=True)
class Shapes:
    """Opaque shapes on the canopy plane: ellipses and capsules.

    Attributes
    ----------
    center : numpy.ndarray
        (N, 2) centres of the ellipses [m].
    axis_a, axis_b : numpy.ndarray
        (N, 2) conjugate semi-axes of the ellipses [m].
    start, end : numpy.ndarray
        (M, 2) segment ends of the capsules [m].
    radius : numpy.ndarray
        (M,) radii of the capsules [m].
    """

    center: np.ndarray
    axis_a: np.ndarray
    axis_b: np.ndarray
    start: np.ndarray
    end: np.ndarray
    radius: np.ndarray

    def subset(self, leaves: np.ndarray | slice = slice(None), wood: np.ndarray | slice = slice(None)) -> Shapes:
        """The ellipses selected by ``leaves`` and capsules selected by ``wood``.

        A boolean mask that selects everything keeps the arrays themselves (a single canopy plane's layer
        selects every shape).

        Parameters
        ----------
        leaves : numpy.ndarray or slice, optional
            Boolean mask (N,), index array or slice of the ellipses.
        wood : numpy.ndarray or slice, optional
            Boolean mask (M,), index array or slice of the capsules.

        Returns
        -------
        Shapes
            The selected shapes [m].
        """
        leaves, wood = _every(leaves, len(self.center)), _every(wood, len(self.radius))
        return Shapes(self.center[leaves], self.axis_a[leaves], self.axis_b[leaves],
                      self.start[wood], self.end[wood], self.radius[wood])


@dataclass(frozen=True)
class Wood:
    """Trunks and branches as capsules.

    Attributes
    ----------
    start, end : numpy.ndarray
        (M, 3) segment ends [m].
    radius : numpy.ndarray
        (M,) radii [m].
    """

    start: np.ndarray
    end: np.ndarray
    radius: np.ndarray


def _every(select: np.ndarray | slice, n: int) -> np.ndarray | slice:
    """``select``, or slice(None) where it is a boolean mask (n,) that is true everywhere."""
    if isinstance(select, np.ndarray) and select.dtype == bool and select.shape == (n,) and select.all():
        return slice(None)
    return select


def grow_grove(params: GroveParams = GroveParams()) -> Grove:
    """Grow the grove of ``params``, deterministic from its seed.

    Each tree: a tapering trunk (radius 0.15 to 0.25 m) from the ground up to its crown centre,
    seven two-segment branches out into the crown, and leaf clusters in a flattened crown
    ellipsoid (half-axes about crown_radius, crown_radius, 0.35 crown_radius around ``height``).

    Parameters
    ----------
    params : GroveParams, optional
        The grove's parameters.

    Returns
    -------
    Grove
        The grove at rest; lengths in [m].

    Raises
    ------
    ValueError
        For an unknown layout, or a periodic one without a tile.
    """
    p = params
    if p.layout not in ("isolated", "periodic"):
        raise ValueError(f"layout must be 'isolated' or 'periodic', not {p.layout!r}")
    if p.layout == "periodic":
        _tile(p)
    bases = _tree_bases(p)
    trees = [_grow_tree(np.random.default_rng([p.seed, 1, i]), base, p) for i, base in enumerate(bases)]
    cat = lambda k: np.concatenate([t[k] for t in trees])  # noqa: E731
    center, axis_u, pivot, start, end = cat("center"), cat("axis_u"), cat("pivot"), cat("start"), cat("end")
    if p.layout == "periodic":  # wrap every shape into the tile, whole periods at a time
        center, shift = _wrap(center, p)
        pivot = pivot + shift
        start, shift = _wrap(start, p)
        end = end + shift
    return Grove(
        leaves=Leaves(center, axis_u, cat("axis_v")),
        pivot=pivot, swing_axis=cat("swing_axis"),
        swing_phase=cat("swing_phase"), twist_phase=cat("twist_phase"),
        wood=Wood(start, end, cat("radius")),
        bases=np.column_stack([bases, np.zeros(len(bases))]), params=p,
    )


def _tile(p: GroveParams) -> float:
    """The tile period of a periodic grove [m]; ValueError without one."""
    if not p.tile:
        raise ValueError("a periodic grove needs a tile period [m]")
    return p.tile


def _tree_bases(p: GroveParams) -> np.ndarray:
    """Trunk feet (count, 2) [m], at least a crown radius apart where space allows."""
    rng = np.random.default_rng([p.seed, 0])
    spread = 0.8 * p.crown_radius * np.sqrt(max(p.count - 1, 0)) if p.spread is None else p.spread
    bases = np.empty((p.count, 2))
    for i in range(p.count):
        for _attempt in range(100):
            if p.layout == "periodic":
                tile = _tile(p)
                xy = np.asarray(p.center) + (rng.random(2) - 0.5) * tile
                near = np.abs((xy - bases[:i] + tile / 2) % tile - tile / 2)
            else:
                radius, angle = spread * np.sqrt(rng.random()), 2 * np.pi * rng.random()
                xy = np.asarray(p.center) + radius * np.array([np.cos(angle), np.sin(angle)])
                near = xy - bases[:i]
            if np.all(np.hypot(near[:, 0], near[:, 1]) >= p.crown_radius):
                break
        bases[i] = xy
    return bases


def _grow_tree(rng: np.random.Generator, base: np.ndarray, p: GroveParams) -> dict[str, np.ndarray]:
    """Wood and leaves of one tree standing at ``base`` (x, y) [m], as a dict of arrays."""
    R, h = p.crown_radius, p.height
    half = R * rng.uniform(0.9, 1.1, 2)
    half_z = R * rng.uniform(0.3, 0.4)
    crown = np.array([*(base + rng.normal(0, 0.05 * R, 2)), h])
    # trunk: three tapering segments from the foot to the crown centre
    r0 = rng.uniform(0.15, 0.25)
    knots = np.linspace([*base, 0.0], crown, 4)
    knots[1:-1, :2] += rng.normal(0, 0.03 * R, (2, 2))
    start, end, radius = [knots[:-1]], [knots[1:]], [r0 * np.linspace(1.0, 0.6, 3)]
    # branches: two segments each from the upper trunk out into the crown
    n_branch = 7
    z = rng.uniform(h - 1.2 * half_z, h - 0.2 * half_z, n_branch)
    foot = crown + (z - h)[:, None] * (crown - knots[0]) / h
    azimuth = 2 * np.pi * (np.arange(n_branch) + rng.random(n_branch)) / n_branch
    reach = rng.uniform(0.55, 0.85, n_branch)
    tip = crown + np.column_stack([reach * half[0] * np.cos(azimuth), reach * half[1] * np.sin(azimuth),
                                   rng.uniform(-0.2, 0.6, n_branch) * half_z])
    mid = 0.5 * (foot + tip) + rng.normal(0, 0.08 * R, (n_branch, 3))
    start += [foot, mid]
    end += [mid, tip]
    radius += [np.full(n_branch, 0.4 * r0), np.full(n_branch, 0.2 * r0)]
    # leaf clusters in a shell of the crown ellipsoid, leaves scattered around each
    n = p.leaves_per_tree
    n_cluster = max(1, n // p.leaves_per_cluster)
    direction = normalized(rng.normal(size=(n_cluster, 3)))
    cluster = crown + direction * rng.uniform(0.35, 1.0, (n_cluster, 1)) ** (1 / 3) * [*half, half_z]
    spread = 0.06 * R * (p.leaves_per_cluster > 1)
    center = cluster[rng.permutation(n) % n_cluster] + rng.normal(0, spread, (n, 3)) * [1, 1, 0.5]
    length = p.leaf_length * rng.uniform(0.7, 1.3, n)
    u = normalized(rng.normal(size=(n, 3)))
    v = normalized(np.cross(u, rng.normal(size=(n, 3))))
    axis_u = 0.5 * length[:, None] * u
    axis_v = 0.5 * (length * rng.uniform(0.4, 0.7, n))[:, None] * v
    swing_axis = swing_axes(u)
    return dict(center=center, axis_u=axis_u, axis_v=axis_v, pivot=center - axis_u,
                swing_axis=swing_axis, swing_phase=rng.uniform(0, 2 * np.pi, n),
                twist_phase=rng.uniform(0, 2 * np.pi, n), start=np.concatenate(start),
                end=np.concatenate(end), radius=np.concatenate(radius))


def _wrap(points: np.ndarray, p: GroveParams) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) [m] moved by whole tiles into the tile around p.center; returns them and the shift."""
    tile = _tile(p)
    low = np.asarray(p.center) - tile / 2
    shift = np.zeros_like(points)
    shift[:, :2] = -np.floor((points[:, :2] - low) / tile) * tile
    return points + shift, shift


def swing_axes(length: np.ndarray) -> np.ndarray:
    """Each leaf's swing axis: horizontal, across its length.

    Parameters
    ----------
    length : numpy.ndarray
        (n, 3) each leaf's direction along its length (any length).

    Returns
    -------
    numpy.ndarray
        (n, 3) unit vectors [1].
    """
    return normalized(np.column_stack([-length[:, 1], length[:, 0], np.zeros(len(length))]) + [1e-12, 0, 0])


def leaves_at(grove: Grove, flutter: FlutterParams, frame: int) -> Leaves:
    """The leaves at ``frame`` (any int), exactly periodic: each twists about its length axis, then
    swings about its horizontal axis (``swing_axes``) through its stem, as ``FlutterParams`` says.
    (Compiled: pipeline/kernels/raster.py, ``flutter``.)

    Parameters
    ----------
    grove : Grove
        The grove at rest.
    flutter : FlutterParams
        Cycle [frames] and amplitudes [rad].
    frame : int
        The frame [frames].

    Returns
    -------
    Leaves
        The leaves at ``frame`` [m].
    """
    from pipeline.kernels import raster

    omega = flutter.angle(frame)
    leaves = grove.leaves
    center, axis_u, axis_v, pivot, swing_axis, swing_phase, twist_phase = (
        np.ascontiguousarray(a, dtype=np.float64) for a in (leaves.center, leaves.axis_u, leaves.axis_v, grove.pivot,
                                                             grove.swing_axis, grove.swing_phase, grove.twist_phase))
    return Leaves(*raster.flutter(center, axis_u, axis_v, pivot, swing_axis, swing_phase, twist_phase,
                                   float(omega), float(flutter.swing), float(flutter.twist)))


def project(leaves: Leaves, wood: Wood | None = None, *, sun: ArrayLike, plane_height: float) -> Shapes:
    """Leaves and wood projected along the sun onto the canopy plane z = plane_height.

    A point P lands at P_xy - (P_z - plane_height) s. Leaves stay exact ellipses. A wood capsule
    projects to a capsule whose radius is the half-width of the cylinder's shadow,
    r / |n_xy| with n the unit normal to both the sun and the segment (r for an upright trunk,
    r / cos(theta) for a branch across the sun); its end caps are approximated as round.

    Parameters
    ----------
    leaves : Leaves
        The leaves [m].
    wood : Wood or None, optional
        The wood; None for none [m].
    sun : numpy.ndarray
        (2,) the sun's sky-plane point s = (wx / wz, wy / wz) [tan].
    plane_height : float
        Height of the canopy plane [m].

    Returns
    -------
    Shapes
        The shapes on the canopy plane [m].
    """
    from pipeline.kernels import raster

    s = np.asarray(sun, dtype=np.float64)

    def onto(points: np.ndarray, offset: float = plane_height) -> np.ndarray:
        # P_xy - (P_z - offset) s, compiled, the same bits
        return raster.onto(np.ascontiguousarray(points, dtype=np.float64), float(s[0]), float(s[1]), float(offset))

    if wood is None:
        wood = Wood(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    normal = np.cross(np.append(s, 1.0), wood.end - wood.start)
    norm = np.linalg.norm(normal, axis=1)
    stretch = np.where(norm > 1e-12, norm / np.maximum(np.hypot(normal[:, 0], normal[:, 1]), 1e-300), 1.0)
    return Shapes(onto(leaves.center), onto(leaves.axis_u, 0.0), onto(leaves.axis_v, 0.0),
                  onto(wood.start), onto(wood.end), wood.radius * stretch)


def layer_index(grove: Grove, heights: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest canopy plane for every leaf (by its rest centre) and wood segment (by its midpoint).

    Parameters
    ----------
    grove : Grove
        The grove.
    heights : sequence of float
        Heights of the canopy planes [m].

    Returns
    -------
    leaf_layer : numpy.ndarray
        (N,) int.
    wood_layer : numpy.ndarray
        (M,) int.
    """
    planes = np.asarray(heights, dtype=np.float64)
    nearest = lambda z: np.argmin(np.abs(z[:, None] - planes[None, :]), axis=1)  # noqa: E731
    wood_z = 0.5 * (grove.wood.start[:, 2] + grove.wood.end[:, 2])
    return nearest(grove.leaves.center[:, 2]), nearest(wood_z)


def shapes_bounds(shapes: Shapes) -> tuple[float, float, float, float]:
    """The rectangle enclosing every shape.

    Parameters
    ----------
    shapes : Shapes
        The shapes [m].

    Returns
    -------
    tuple of 4 float
        (x_min, y_min, x_max, y_max); NaNs when there are none [m].
    """
    half = np.sqrt(shapes.axis_a**2 + shapes.axis_b**2)
    low = np.concatenate([shapes.center - half, np.minimum(shapes.start, shapes.end) - shapes.radius[:, None]])
    high = np.concatenate([shapes.center + half, np.maximum(shapes.start, shapes.end) + shapes.radius[:, None]])
    if len(low) == 0:
        return (np.nan,) * 4
    return (*low.min(axis=0), *high.max(axis=0))


def grove_bounds(grove: Grove, flutter: FlutterParams | None = None, *, sun: ArrayLike,
                 plane_height: float) -> tuple[float, float, float, float]:
    """The rectangle of the projected grove for every flutter frame.

    A leaf's points stay within |U| + sqrt(|U|^2 + |V|^2) of its stem however it turns, and a
    displacement d projects to length at most |d| sqrt(1 + |s|^2); ``flutter`` is not needed.

    Parameters
    ----------
    grove : Grove
        The grove.
    flutter : FlutterParams or None, optional
        Unused.
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    plane_height : float
        Height of the canopy plane [m].

    Returns
    -------
    tuple of 4 float
        (x_min, y_min, x_max, y_max) [m].
    """
    s = np.asarray(sun, dtype=np.float64)
    leaves = grove.leaves
    u, v = np.linalg.norm(leaves.axis_u, axis=1), np.linalg.norm(leaves.axis_v, axis=1)
    reach = (u + np.hypot(u, v)) * np.hypot(1.0, np.hypot(*s))
    stems = project(Leaves(grove.pivot, 0 * grove.pivot, 0 * grove.pivot), grove.wood,
                    sun=s, plane_height=plane_height)
    disc = np.column_stack([reach, np.zeros_like(reach)])
    return shapes_bounds(Shapes(stems.center, disc, disc[:, ::-1], stems.start, stems.end, stems.radius))


def trunks(grove: Grove) -> Wood:
    """The trunks of a grove at rest: the chain of wood segments that runs up from each foot.

    Each trunk's segments join end to start exactly (``grow_grove``); a branch starts between
    the trunk's knots, so the chain from a foot holds the trunk alone.

    Parameters
    ----------
    grove : Grove
        The grove.

    Returns
    -------
    Wood
        The trunks' segments, foot first, tree by tree [m].
    """
    wood, chosen = grove.wood, []
    for base in grove.bases:
        at = np.flatnonzero(np.all(wood.start == base, axis=1))
        while len(at):
            chosen.append(at[0])
            at = np.flatnonzero(np.all(wood.start == wood.end[at[0]], axis=1))
    index = np.array(chosen, dtype=np.intp)
    return Wood(wood.start[index], wood.end[index], wood.radius[index])
