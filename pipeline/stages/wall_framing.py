"""Framing at walls: where the leaves' shadow falls on a wall and where it reaches the ground past
them, the camera placed to look at a wall's flecks, the exposure of the brightest receiver in view,
each receiver's open light, and whether a camera stands in or behind a wall (docs/method.md,
"Receivers: walls and slopes"). Part of the plan stage: ``framing`` and ``plan`` call it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.camera import pinhole
from pipeline.camera.pinhole import Camera
from pipeline.config.settings import Config
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import direction_vector
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, world_radiance
from pipeline.receivers.plane import ReceiverPlane, level_ground, wall_distance
from pipeline.receivers.sun import receiver_sun_irradiance, sun_incidence, sun_lights
from pipeline.receivers.view import wall_hits
from pipeline.receivers.walls import wall_plane
from pipeline.sky.base import Sky
from pipeline.sky.sun_disc import SunDisc
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.inputs import albedo_mipmap, isolated_grove

__all__ = ["WALL_TURNS", "HIDDEN_MOST", "WALL_FILL", "FLECK_SHARE", "EXPOSURE_SHARE", "CLEAR_STEP", "WALL_CLEARANCE",
           "wall_planes", "shadow_points", "first_walls", "fleck_wall", "wall_camera", "sees_wall_flecks",
           "camera_wall_problem", "clear_of_walls", "ground_shadow_boxes", "OpenLight", "open_receivers",
           "receiver_shares", "exposure_stops"]

WALL_TURNS = (35.0, 45.0, 55.0, 65.0)
"""A camera placed at a wall looks at its flecks from one of these angles round from the wall's
normal, the first from which the crown (towards the sun) hides little of them. [deg]"""
HIDDEN_MOST = 0.05
"""The most of the shadow on the wall that the crown may hide from a placed camera. [1]"""
WALL_FILL = 0.5
"""The leaves' shadow on the wall (its points' extent) spans this share of the placed camera's
image, across or up, whichever is tighter: the rest is sunlit wall. [1]"""
FLECK_SHARE = 0.25
"""A wall takes the camera when at least this share of the leaves' shadows falls on it. [1]"""
EXPOSURE_SHARE = 0.1
"""A receiver sets the exposure when it fills at least this share of the picture. [1]"""
CLEAR_STEP = 15.0
"""A camera placed for the ground that stands in or behind a wall is turned about its target in
steps of this. [deg]"""
WALL_CLEARANCE = 1e-3
"""How far a camera must stand from a wall, and two walls must reach past each other's edges to
cross (walls that meet at an edge do not). [m]"""
_LEAF_STRIDE = 16  # every 16th leaf's centre stands for the crown's shadow (as framing.leaf_shadow_extents)
_VIEW_SAMPLES = 48  # rays per image side for a picture's shares


def wall_planes(config: Config) -> list[ReceiverPlane]:
    """The config's walls as receiver planes.

    Parameters
    ----------
    config : settings.Config
        The resolved config.

    Returns
    -------
    list of receivers.plane.ReceiverPlane
        One per ``receivers.walls``, in order.
    """
    return [wall_plane(w, f"receivers.walls[{i}]") for i, w in enumerate(config.receivers.walls)]


def shadow_points(config: Config) -> np.ndarray:
    """Points that stand for the canopy's shade: every 16th leaf's centre of the grove, or a 9 x 9
    grid over each mask image's area at its height.

    Parameters
    ----------
    config : settings.Config
        The resolved config.

    Returns
    -------
    numpy.ndarray
        (n, 3) world points [m].
    """
    isolated = isolated_grove(config.canopy)
    if isolated is not None:
        return np.asarray(isolated[0].leaves.center[::_LEAF_STRIDE], dtype=np.float64)
    grids = []
    for layer in config.canopy.layers:
        (cx, cy), (w, h) = layer.center, layer.size
        x, y = np.meshgrid(cx + w * np.linspace(-0.5, 0.5, 9), cy + h * np.linspace(-0.5, 0.5, 9))
        grids.append(np.column_stack([x.ravel(), y.ravel(), np.full(x.size, layer.height)]))
    return np.concatenate(grids)


def first_walls(points: np.ndarray, sun: np.ndarray, planes: Sequence[ReceiverPlane]) -> tuple[np.ndarray, np.ndarray]:
    """Where each point's shadow falls: the first wall that its ray away from the sun meets on the
    wall's lit side, or the ground.

    Parameters
    ----------
    points : numpy.ndarray
        (n, 3) world points above the ground [m].
    sun : numpy.ndarray
        (3,) unit vector towards the sun, above the horizon [1].
    planes : sequence of receivers.plane.ReceiverPlane
        The walls.

    Returns
    -------
    index : numpy.ndarray
        (n,) int, the wall each shadow falls on, -1 for the ground.
    uw : numpy.ndarray
        (n, 2) the shadow's (u, w) on that wall (its world (x, y) on the ground for -1) [m].
    """
    points = np.asarray(points, dtype=np.float64)
    reach = points[:, 2] / sun[2]  # along -sun to the ground
    index, nearest = np.full(len(points), -1), reach.copy()
    uw = points[:, :2] - reach[:, None] * sun[:2]
    for i, plane in enumerate(planes):
        assert plane.width is not None and plane.height is not None
        cos_n = float(sun @ plane.normal)
        if cos_n <= 0.0:  # the sun behind it: no shadow on its face
            continue
        local = plane.local_points(points)
        t = local[:, 2] / cos_n
        a, b = (local[:, :2] - t[:, None] * plane.local_directions(sun)[:2]).T
        hit = (local[:, 2] > 0) & (t < nearest) & (np.abs(a) <= plane.width / 2) & (b >= 0) & (b <= plane.height)
        index[hit], nearest[hit] = i, t[hit]
        uw[hit] = np.column_stack([a, b])[hit]
    return index, uw


def fleck_wall(config: Config, sun: SunDisc, planes: Sequence[ReceiverPlane]) -> tuple[int, np.ndarray] | None:
    """The wall that takes the most of the leaves' shadow under ``sun``, if it takes FLECK_SHARE of it.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    sun : sky.sun_disc.SunDisc
        The sun, above the horizon.
    planes : sequence of receivers.plane.ReceiverPlane
        The walls.

    Returns
    -------
    tuple or None
        The wall's index and its shadow points' (u, w) (n, 2) [m]; None: the ground takes the shade.
    """
    if not planes:
        return None
    index, uw = first_walls(shadow_points(config), direction_vector(sun.azimuth, sun.elevation), planes)
    counts = np.bincount(index[index >= 0], minlength=len(planes))
    best = int(np.argmax(counts))
    if counts[best] < FLECK_SHARE * len(index):
        return None
    return best, uw[index == best]


def wall_camera(config: Config, sun: SunDisc, planes: Sequence[ReceiverPlane], eye: float) -> Camera | None:
    """A camera that looks at the leaves' flecks on a wall, where a wall takes them (``fleck_wall``).

    It stands at eye height in front of the wall and looks at the middle of the leaves' shadow on
    it, far enough for the shadow to span WALL_FILL of the image (the rest sunlit wall); round from
    the wall's normal by the first of WALL_TURNS, on the side away from the sun and then the other,
    from which the crown hides less than HIDDEN_MOST of the shadow (else the one that hides least),
    clear of every wall (``camera_wall_problem``).

    Parameters
    ----------
    config : settings.Config
        The resolved config; its camera's fov and resolution.
    sun : sky.sun_disc.SunDisc
        The middle frame's sun.
    planes : sequence of receivers.plane.ReceiverPlane
        The walls.
    eye : float
        The camera's height [m].

    Returns
    -------
    camera.pinhole.Camera or None
        None where no wall takes the flecks, or no place in front of it is clear.
    """
    found = fleck_wall(config, sun, planes)
    if found is None:
        return None
    index, uw = found
    plane = planes[index]
    lo, hi = uw.min(axis=0), uw.max(axis=0)
    target = plane.world_points([*(lo + hi) / 2, 0.0])
    flecks = plane.world_points(np.column_stack([uw, np.zeros(len(uw))]))
    leaves = shadow_points(config)
    c = config.camera
    width, rows = c.resolution
    tan_v = np.tan(c.fov / 2)
    tan_h = tan_v * width / rows
    side = -1.0 if direction_vector(sun.azimuth, sun.elevation) @ plane.across >= 0 else 1.0
    facing = plane.normal[:2] / np.linalg.norm(plane.normal[:2])
    best: tuple[float, Camera] | None = None
    for angle in (np.radians(sign * side * turn) for turn in WALL_TURNS for sign in (1.0, -1.0)):
        span = max((hi[0] - lo[0]) * np.cos(angle) / 2 / tan_h, (hi[1] - lo[1]) / 2 / tan_v) / WALL_FILL
        away = np.cos(angle) * facing + np.sin(angle) * plane.across[:2]
        position = (*(target[:2] + max(span, 1.0) * away), eye)
        view = Camera.look_at(position, target, vertical_fov=c.fov, width=width, height=rows)
        if any(camera_wall_problem(view, p) is not None for p in planes):
            continue
        hidden = _hidden(view, flecks, leaves)
        if hidden <= HIDDEN_MOST:
            return view
        if best is None or hidden < best[0]:
            best = (hidden, view)
    return None if best is None else best[1]


def clear_of_walls(view: Camera, target: np.ndarray, planes: Sequence[ReceiverPlane]) -> Camera:
    """A placed camera turned about the vertical through its ground target, by the least of steps of
    ``CLEAR_STEP``, until it stands clear of every wall (``camera_wall_problem``).

    Parameters
    ----------
    view : camera.pinhole.Camera
        The camera the ground's framing placed.
    target : numpy.ndarray
        (2,) the ground point it looks at (x, y) [m].
    planes : sequence of receivers.plane.ReceiverPlane
        The walls.

    Returns
    -------
    camera.pinhole.Camera
        The first clear one, or ``view`` itself where none is (the plan then refuses it).
    """
    offset = np.subtract(view.position[:2], target)
    for step in range(int(round(180.0 / CLEAR_STEP)) + 1):
        for sign in ((1.0,) if step in (0, round(180.0 / CLEAR_STEP)) else (1.0, -1.0)):
            turn = np.radians(sign * step * CLEAR_STEP)
            c, s = np.cos(turn), np.sin(turn)
            x, y = target + np.array([c * offset[0] + s * offset[1], -s * offset[0] + c * offset[1]])
            moved = Camera((float(x), float(y), view.position[2]), float((view.yaw + turn) % (2 * np.pi)),
                           view.pitch, view.vertical_fov, view.width, view.height)
            if all(camera_wall_problem(moved, p) is None for p in planes):
                return moved
    return view


def _hidden(view: Camera, flecks: np.ndarray, leaves: np.ndarray, cells: int = 24) -> float:
    """The share of the shadow's points on the wall that fall in an image cell (of ``cells`` across)
    where a leaf nearer the camera is seen: the crown in front of its own shadow. [1]"""
    u, v, depth = pinhole.project_points(view, flecks)
    lu, lv, ldepth = pinhole.project_points(view, leaves)
    cell = view.width / cells
    near = np.full((int(np.ceil(view.height / cell)) + 1, cells + 1), -np.inf)
    seen = (ldepth > 0) & (lu >= 0) & (lu < view.width) & (lv >= 0) & (lv < view.height)
    np.maximum.at(near, ((lv[seen] // cell).astype(int), (lu[seen] // cell).astype(int)), -ldepth[seen])
    inside = (depth > 0) & (u >= 0) & (u < view.width) & (v >= 0) & (v < view.height)
    if not inside.any():
        return 1.0
    r, k = (v[inside] // cell).astype(int), (u[inside] // cell).astype(int)
    return float(np.mean(-near[r, k] < depth[inside]))


def sees_wall_flecks(config: Config, camera: Camera, sun: SunDisc) -> bool:
    """Whether the camera sees some of the leaves' shadow on a wall (``fleck_wall``).

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    camera : camera.pinhole.Camera
        The camera.
    sun : sky.sun_disc.SunDisc
        The sun.

    Returns
    -------
    bool
        True where a shadow point on that wall projects into the image in front of the camera.
    """
    planes = wall_planes(config)
    found = fleck_wall(config, sun, planes) if sun.elevation > 0 else None
    if found is None:
        return False
    index, uw = found
    u, v, depth = pinhole.project_points(camera, planes[index].world_points(np.column_stack([uw, np.zeros(len(uw))])))
    return bool(np.any((depth > 0) & (u >= 0) & (u <= camera.width) & (v >= 0) & (v <= camera.height)))


def camera_wall_problem(camera: Camera, plane: ReceiverPlane) -> str | None:
    """Whether a camera stands within WALL_CLEARANCE of a wall, or behind it seeing its back.

    Parameters
    ----------
    camera : camera.pinhole.Camera
        The camera.
    plane : receivers.plane.ReceiverPlane
        A wall.

    Returns
    -------
    str or None
        ``"in"``, ``"behind"``, or None for a camera clear of it.
    """
    if wall_distance(plane, camera.position, camera.position) < WALL_CLEARANCE:
        return "in"
    if plane.local_points(camera.position)[2] < 0 and wall_hits(camera, plane, samples=1).hit.any():
        return "behind"
    return None


def ground_shadow_boxes(config: Config, suns: Sequence[SunDisc]) -> list[tuple[float, float, float, float] | None]:
    """Per sun, the box of the leaves' shadows that reach the ground past the walls (the rest fall on
    a wall, in its own fine raster).

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    suns : sequence of sky.sun_disc.SunDisc
        The frames' suns, above the horizon.

    Returns
    -------
    list
        Per sun, (x_min, y_min, x_max, y_max) [m], or None where every shadow falls on a wall.
    """
    points, planes = shadow_points(config), wall_planes(config)
    boxes: list[tuple[float, float, float, float] | None] = []
    for sun in suns:
        index, xy = first_walls(points, direction_vector(sun.azimuth, sun.elevation), planes)
        ground = xy[index < 0]
        if not len(ground):
            boxes.append(None)
            continue
        (x0, y0), (x1, y1) = ground.min(axis=0), ground.max(axis=0)
        boxes.append((float(x0), float(y0), float(x1), float(y1)))
    return boxes


@dataclass(frozen=True)
class OpenLight:
    """A receiver's light before any shade.

    Attributes
    ----------
    name : str
        ``ground`` or the wall's name.
    incidence : float
        cos of the sun's angle from its normal (negative: behind it; 0 without a sun) [1].
    sun, sky : float
        The luminance of the sun's light on it (0 where it does not light it) and of its hemisphere's
        (the sky, and below the horizon the open ground) [radiance x sr; klx for a procedural sky].
    """

    name: str
    incidence: float
    sun: float
    sky: float

    @property
    def most(self) -> float:
        """The most a fleck can stand above the shade, (sun + sky) / sky; inf without sky. [1]"""
        return (self.sun + self.sky) / self.sky if self.sky > 0 else float("inf")


def open_receivers(config: Config, sky: Sky, *, exact: bool = True) -> list[OpenLight]:
    """The level ground's and each wall's open light under a frame's sky.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    sky : sky.base.Sky
        The frame's sky.
    exact : bool
        The sun as the renderer's kernel sums it (``sun_kernel.sun_irradiance``, about a second);
        False: its normal irradiance times the share of the disc uncovered and s.n (within 1e-4 of
        it under a clear sky; no cloud's dimming), for the exposure.

    Returns
    -------
    list of OpenLight
        The ground first, then the walls in order.
    """
    planes = wall_planes(config)
    if exact:
        level_sun = np.asarray(sun_irradiance(sky), dtype=np.float64)  # type: ignore[arg-type]
        wall_suns = [receiver_sun_irradiance(sky, plane) for plane in planes]
    else:
        up = float(np.asarray(sky.sun_direction)[2]) if sky.sun is not None else 0.0  # type: ignore[attr-defined]
        normal = (float(sky.sun_fraction()) * np.asarray(sky.undimmed_sun_irradiance(), dtype=np.float64) / up
                  if up > 0 else np.zeros(3))
        level_sun = normal * max(up, 0.0)
        wall_suns = [normal * sun_incidence(sky, plane) if sun_lights(sky, plane) else np.zeros(3) for plane in planes]
    ground = np.asarray(sky.sky_irradiance, dtype=np.float64) + level_sun
    radiance = world_radiance(sky, ground_radiance(albedo_mipmap(config.ground).mean, ground))
    found = [OpenLight("ground", sun_incidence(sky, level_ground()), _luminance(level_sun),
                       _luminance(sky.sky_irradiance))]
    for wall, plane, sun in zip(config.receivers.walls, planes, wall_suns):
        found.append(OpenLight(wall.name, sun_incidence(sky, plane), _luminance(sun),
                               _luminance(hemisphere_irradiance(radiance, plane))))
    return found


def _luminance(rgb: object) -> float:
    return float(np.asarray(rgb, dtype=np.float64) @ REC709_LUMINANCE)


def receiver_shares(camera: Camera, planes: Sequence[ReceiverPlane], samples: int = _VIEW_SAMPLES) -> np.ndarray:
    """The share of a picture each receiver fills, by the nearest receiver each of a grid of rays meets.

    Parameters
    ----------
    camera : camera.pinhole.Camera
        The camera.
    planes : sequence of receivers.plane.ReceiverPlane
        The walls.
    samples : int
        Rays per image side [1].

    Returns
    -------
    numpy.ndarray
        (1 + len(planes),) the ground's share, then each wall's [1].
    """
    u, v = np.meshgrid((np.arange(samples) + 0.5) / samples * camera.width,
                       (np.arange(samples) + 0.5) / samples * camera.height)
    rays = pinhole.image_rays(camera, u, v).reshape(-1, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(rays[:, 2] < 0, -camera.position[2] / rays[:, 2], np.inf)
    which = np.where(np.isfinite(t), 0, -1)
    for i, plane in enumerate(planes):
        assert plane.width is not None and plane.height is not None
        origin, local = plane.local_points(camera.position), plane.local_directions(rays)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -origin[2] / local[:, 2]
            a, b = origin[0] + s * local[:, 0], origin[1] + s * local[:, 1]
        hit = (s > 0) & (s < t) & (np.abs(a) <= plane.width / 2) & (b >= 0) & (b <= plane.height)
        which[hit], t[hit] = i + 1, s[hit]
    return np.bincount(which[which >= 0], minlength=1 + len(planes)) / len(rays)


def exposure_stops(config: Config, sky: Sky, camera: Camera) -> float:
    """Stops that move the default exposure (a white ground under the open ground's sun and sky at 1)
    to put a white surface under the brightest receiver's open light at 1, of the receivers that fill
    at least EXPOSURE_SHARE of the picture: a sunlit wall brighter than the ground darkens the picture.

    Parameters
    ----------
    config : settings.Config
        The resolved config with walls.
    sky : sky.base.Sky
        The middle frame's sky.
    camera : camera.pinhole.Camera
        The camera.

    Returns
    -------
    float
        -log2(brightest / ground) [stops]; 0 where the ground is the brightest or nothing fills enough.
    """
    lights = open_receivers(config, sky, exact=False)
    shares = receiver_shares(camera, wall_planes(config))
    seen = [light.sun + light.sky for light, share in zip(lights, shares) if share >= EXPOSURE_SHARE]
    ground = lights[0].sun + lights[0].sky
    if not seen or ground <= 0 or max(seen) <= 0:
        return 0.0
    return float(-np.log2(max(seen) / ground))
