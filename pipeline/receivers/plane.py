"""A receiver plane and its frame: a wall, a sloped ground or the level ground turned so that the
receiver is the xy-plane of Max's method (docs/method.md, "Receivers: walls and slopes").

The frame (u, w, n) is right-handed, n the receiver's outward normal, u horizontal and to the right
as one faces the receiver, w = n x u (up a wall, up a slope towards its back). Receiver rasters
use the ground's layout with (u, w) for (x, y): ``col`` grows with +u, ``row`` with -w. A world
direction d maps to the receiver's sky plane at s = (d.u / d.n, d.w / d.n).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.errors import ConfigError

__all__ = ["ReceiverPlane", "wall", "slope", "level_ground", "wall_distance", "wall_crossings", "walls_cross"]


@dataclass(frozen=True)
class ReceiverPlane:
    """A plane that receives light, with its frame and (for a wall) its extent.

    Parameters
    ----------
    origin : tuple of 3 float
        World point (x east, y north, z up) of the plane's (u, w) = (0, 0): a wall's foot centre,
        a slope's fixed point [m].
    facing : float
        Azimuth of the normal's horizontal part, from north towards east [rad].
    zenith : float
        Zenith angle of the normal: 0 level, a slope's tilt, pi/2 a vertical wall [rad].
    width, height : float or None
        A wall's extent along u (centred on the origin) and along w (from the origin up); None
        for an unbounded plane [m].
    """

    origin: tuple[float, float, float]
    facing: float
    zenith: float
    width: float | None = None
    height: float | None = None

    @cached_property
    def normal(self) -> np.ndarray:
        """n (3,), the outward unit normal in world axes. [1]"""
        a, z = self.facing, self.zenith
        return _clean(np.array([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)]))

    @cached_property
    def across(self) -> np.ndarray:
        """u (3,), horizontal, to the right as one faces the receiver (east for a south-facing or the
        level one). [1]"""
        return _clean(np.array([-np.cos(self.facing), np.sin(self.facing), 0.0]))

    @cached_property
    def along(self) -> np.ndarray:
        """w (3,) = n x u: up a wall, up a slope. [1]"""
        return np.cross(self.normal, self.across)

    @cached_property
    def rotation(self) -> np.ndarray:
        """(3, 3) with columns u, w, n: world = rotation @ local, local = rotation.T @ world. [1]"""
        return np.column_stack([self.across, self.along, self.normal])

    def local_directions(self, d: ArrayLike) -> np.ndarray:
        """World directions (..., 3) in the receiver's axes (d.u, d.w, d.n). [1]"""
        return np.asarray(d, dtype=np.float64) @ self.rotation

    def world_directions(self, v: ArrayLike) -> np.ndarray:
        """Receiver-frame directions (..., 3) in world axes. [1]"""
        return np.asarray(v, dtype=np.float64) @ self.rotation.T

    def local_points(self, p: ArrayLike) -> np.ndarray:
        """World points (..., 3) [m] as (u, w, distance along n) from the origin [m]."""
        return (np.asarray(p, dtype=np.float64) - np.asarray(self.origin)) @ self.rotation

    def world_points(self, v: ArrayLike) -> np.ndarray:
        """Receiver-frame points (u, w, along n) (..., 3) [m] in world axes [m]."""
        return np.asarray(self.origin) + np.asarray(v, dtype=np.float64) @ self.rotation.T

    def sky_plane(self, d: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """World directions d (..., 3) on the receiver's sky plane.

        Returns
        -------
        s : numpy.ndarray
            (..., 2) (d.u / d.n, d.w / d.n) [tan]; meaningful where d.n > 0.
        cos_incidence : numpy.ndarray
            (...) d.n [1].
        """
        v = self.local_directions(d)
        dn = v[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            return v[..., :2] / dn[..., None], dn

    def direction(self, s: ArrayLike) -> np.ndarray:
        """World unit directions (..., 3) of receiver sky-plane points s (..., 2) [tan]; inverse of ``sky_plane``."""
        s = np.asarray(s, dtype=np.float64)
        cos_t = 1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
        v = np.stack([s[..., 0] * cos_t, s[..., 1] * cos_t, cos_t], axis=-1)
        return self.world_directions(v)

    @property
    def ground_view_factor(self) -> float:
        """The share of the receiver's hemisphere, by projected solid angle, below the world horizon:
        (1 - cos(zenith)) / 2 (0 level, 1/2 a vertical wall). [1]"""
        return float((1.0 - np.cos(self.zenith)) / 2.0)


def _clean(v: np.ndarray) -> np.ndarray:
    """``v`` with the rounding of sin(pi) and cos(pi / 2) (below 1e-15) set to 0: the level ground's
    frame is the world's exactly."""
    return np.where(np.abs(v) < 1e-15, 0.0, v)


def _finite(value: float, where: str) -> float:
    value = float(value)
    if not np.isfinite(value):
        raise ConfigError(where, f"must be a finite number, got {value}")
    return value


def wall(foot: ArrayLike, *, facing: float, width: float, height: float, tilt: float = 0.0,
         where: str = "wall") -> ReceiverPlane:
    """A wall: a rectangle standing on its foot, facing an azimuth.

    Parameters
    ----------
    foot : sequence of 3 float
        World point of the middle of its bottom edge [m].
    facing : float
        Azimuth its outward normal looks towards, from north towards east [rad].
    width, height : float
        Its extent along u and up along w; positive [m].
    tilt : float, optional
        Its lean back from vertical, the normal raised by ``tilt`` above the horizon; |tilt| < pi/2 [rad].
    where : str, optional
        The config key the values come from, for the errors.

    Returns
    -------
    ReceiverPlane
        The wall.

    Raises
    ------
    ConfigError
        Naming the key of a size that is not positive, a tilt of 90 degrees or more, or a value not finite.
    """
    values = [_finite(v, f"{where}.foot") for v in np.ravel(foot)]
    if len(values) != 3:
        raise ConfigError(f"{where}.foot", f"must be three numbers (x, y, z) [m], got {len(values)}")
    for key, size in (("width", width), ("height", height)):
        if not _finite(size, f"{where}.{key}") > 0:
            raise ConfigError(f"{where}.{key}", f"must be positive [m], got {size:g}")
    if not abs(_finite(tilt, f"{where}.tilt")) < np.pi / 2:
        raise ConfigError(f"{where}.tilt", f"must be less than 90 degrees, got {np.degrees(tilt):g}")
    return ReceiverPlane((values[0], values[1], values[2]), _finite(facing, f"{where}.facing"),
                         np.pi / 2 - float(tilt), float(width), float(height))


def slope(*, tilt: float, facing: float, through: ArrayLike = (0.0, 0.0, 0.0), where: str = "slope") -> ReceiverPlane:
    """A sloped ground: the level ground tilted by ``tilt`` so that it faces ``facing`` (a hillside).

    Parameters
    ----------
    tilt : float
        The slope, in [0, pi/2) [rad].
    facing : float
        Azimuth it falls towards (its normal's horizontal part) [rad].
    through : sequence of 3 float, optional
        A world point on it [m].
    where : str, optional
        The config key, for the errors.

    Returns
    -------
    ReceiverPlane
        The unbounded plane.

    Raises
    ------
    ConfigError
        Naming the key of a slope of 90 degrees or more, or negative, or a value not finite.
    """
    t = _finite(tilt, f"{where}.tilt")
    if not 0.0 <= t < np.pi / 2:
        raise ConfigError(f"{where}.tilt", f"must be at least 0 and less than 90 degrees, got {np.degrees(t):g}")
    x, y, z = (_finite(v, f"{where}.through") for v in np.ravel(through))
    return ReceiverPlane((x, y, z), _finite(facing, f"{where}.facing"), t)


def level_ground() -> ReceiverPlane:
    """The level ground as a receiver: its frame is the world's (u east, w north, n up).

    Returns
    -------
    ReceiverPlane
        The plane z = 0.
    """
    return ReceiverPlane((0.0, 0.0, 0.0), np.pi, 0.0)


def wall_distance(plane: ReceiverPlane, start: ArrayLike, end: ArrayLike) -> np.ndarray:
    """The least distance of each segment to a wall's rectangle.

    The distance to a convex set is convex along a segment: a golden-section search finds its
    least to 1e-12 of the segment's length.

    Parameters
    ----------
    plane : ReceiverPlane
        A wall (with its width and height).
    start, end : numpy.ndarray
        (..., 3) the segments' world ends; equal ends for points [m].

    Returns
    -------
    numpy.ndarray
        (...) float64 [m].
    """
    assert plane.width is not None and plane.height is not None
    a, b = plane.local_points(start), plane.local_points(end)
    low, high = np.array([-plane.width / 2, 0.0]), np.array([plane.width / 2, plane.height])

    def distance(t: np.ndarray) -> np.ndarray:
        p = a + t[..., None] * (b - a)
        return np.hypot(np.linalg.norm(p[..., :2] - np.clip(p[..., :2], low, high), axis=-1), p[..., 2])

    lo, hi = np.zeros(a.shape[:-1]), np.ones(a.shape[:-1])
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    for _ in range(60):
        t1, t2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        nearer = distance(t1) < distance(t2)
        hi, lo = np.where(nearer, t2, hi), np.where(nearer, lo, t1)
    return np.minimum(distance((lo + hi) / 2), np.minimum(distance(0 * lo), distance(0 * lo + 1)))


def wall_crossings(plane: ReceiverPlane, start: ArrayLike, end: ArrayLike, *, margin: float = 0.0) -> np.ndarray:
    """Whether each segment passes through a wall's rectangle, shrunk by ``margin`` from its edges.

    Parameters
    ----------
    plane : ReceiverPlane
        A wall (with its width and height).
    start, end : numpy.ndarray
        (..., 3) the segments' world ends [m].
    margin : float, optional
        How far inside the wall's edges the crossing must be [m].

    Returns
    -------
    numpy.ndarray
        (...) bool: the segment's ends lie on the two sides of the wall's plane and it meets the
        plane inside the shrunk rectangle.
    """
    assert plane.width is not None and plane.height is not None
    a, b = plane.local_points(start), plane.local_points(end)
    sides = (a[..., 2] * b[..., 2] <= 0) & (a[..., 2] != b[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = a[..., 2] / (a[..., 2] - b[..., 2])
    p = a + np.where(sides, t, 0.0)[..., None] * (b - a)
    return (sides & (np.abs(p[..., 0]) < plane.width / 2 - margin) & (p[..., 1] > margin)
            & (p[..., 1] < plane.height - margin))


def walls_cross(first: ReceiverPlane, second: ReceiverPlane, *, margin: float) -> bool:
    """Whether two walls pass through each other, more than ``margin`` inside both: walls that meet
    at an edge (a corner, a wall's end against another's face) do not cross.

    Each wall shrunk by ``margin`` is tested against the other's edges shrunk by twice that: two
    rectangles in planes that are not parallel cross where an edge of one pierces the other (walls
    in one plane are not tested).

    Parameters
    ----------
    first, second : ReceiverPlane
        Two walls (with their widths and heights).
    margin : float
        How far inside both the crossing must be [m].

    Returns
    -------
    bool
        True where they cross.
    """
    def edges(plane: ReceiverPlane, inset: float) -> tuple[np.ndarray, np.ndarray]:
        assert plane.width is not None and plane.height is not None
        u, w = plane.width / 2 - inset, (inset, plane.height - inset)
        corners = plane.world_points([(-u, w[0], 0.0), (u, w[0], 0.0), (u, w[1], 0.0), (-u, w[1], 0.0)])
        return corners, np.roll(corners, -1, axis=0)

    return any(bool(np.any(wall_crossings(b, *edges(a, 2 * margin), margin=margin)))
               for a, b in ((first, second), (second, first)))
