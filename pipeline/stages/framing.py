"""Framing: the ground windows and the camera placed from the canopy and the sun's path, so that
any place and time frames the canopy's dappled shadow, the camera following it over a time span
where one place would lose it (docs/method.md, "Framing"). Part of the plan stage."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from pipeline.camera import pinhole
from pipeline.camera.pinhole import Camera
from pipeline.canopy import grove as grove_geometry
from pipeline.config.settings import Config
from pipeline.core.geometry import direction_vector, pinhole_image_axes, sky_plane_from_direction
from pipeline.receivers.plane import ReceiverPlane
from pipeline.sky.sun_disc import SunDisc
from pipeline.stages.inputs import grove_of
from pipeline.stages.scene import Scene, shading_scenes, sky_model, sun_of, sun_shades
from pipeline.stages.wall_framing import (
    clear_of_walls,
    exposure_stops,
    ground_shadow_boxes,
    sees_wall_flecks,
    wall_camera,
    wall_planes,
)

if TYPE_CHECKING:
    from pipeline.stages.plan import RunPlan

Box = tuple[float, float, float, float]
"""(x_min, y_min, x_max, y_max) of a box on the ground [m]."""

__all__ = ["CAMERA_HEIGHT", "CAMERA_PITCH", "ECLIPSE_PITCH", "CAMERA_TURN", "WINDOW_MARGIN", "AUTO_SUN_PIXELS",
           "AUTO_SUN_MASK", "AUTO_VIEW_SAMPLES", "Framing", "canopy_extent", "crown_centre", "DAPPLE_TRANSMITTANCE",
           "ECLIPSE_TRANSMITTANCE", "LOW_SUN", "DAPPLE_CELL", "dappled_point", "shadow_extents", "leaf_shadow_extents",
           "frame_scene", "AIM_ROW", "seen_ground", "framing_warnings", "FOLLOW_SLACK",
           "follow_targets", "follow_cameras", "SEEN_MARGIN",
           "frame_ranges"]

CAMERA_HEIGHT = 1.7
"""Eye height of a camera placed by default. [m]"""
CAMERA_PITCH = 35.0
"""How far a camera placed by default looks down at the shadow. [deg]"""
ECLIPSE_PITCH = 50.0
"""How far it looks down when the moon cuts the sun in some frame and the sun stands above
LOW_SUN: nearer, so that the pinhole images are large enough to show their crescents. [deg]"""
CAMERA_TURN = 35.0
"""A camera placed by default looks this far round from the sun's azimuth, towards the west
of it. [deg]"""
WINDOW_MARGIN = 0.5
"""An automatic ground.window reaches this many canopy heights beyond the canopy and its shadow:
the soft shade of the sky light. [1]"""
AUTO_SUN_PIXELS = 1_500_000
"""Most pixels of an automatic ground.sun_window at its natural pixel: the far ground the
camera sees beyond it reads the coarse raster. [1]"""
AUTO_SUN_MASK = 6_000_000
"""Most cells of the fine mask behind an automatic sun window (the window moved along the sun's
path over the animation): past it the fine pixel grows. [1]"""
AUTO_VIEW_SAMPLES = 48
"""Rays per side of the image with which the ground the camera sees is found. [1]"""


@dataclass(frozen=True)
class Framing:
    """The resolved ground windows, the camera, which were placed, and where the shadow falls.

    Attributes
    ----------
    window : tuple of float
        The ground window (x_min, y_min, x_max, y_max) [m].
    sun_window : tuple of float or None
        The sun window, the same way [m]; None: the window.
    camera : pinhole.Camera
        The camera.
    auto : tuple of str
        Which of ``ground.window``, ``ground.sun_window`` and ``camera`` were placed automatically.
    shadow : tuple of float or None
        (x_min, y_min, x_max, y_max) of where the shadow falls [m]; None: a periodic forest, shadow
        everywhere.
    follow : tuple of (int, pinhole.Camera) or None
        With a camera that follows the shadow (``camera.follow``), per shading scene its frame and
        its camera (``camera`` is the middle one's); None: one camera for every frame.
    exposure_stops : float
        With walls, the stops that expose the brightest receiver in view (``wall_framing.exposure_stops``);
        0 without [stops].
    """

    window: Box
    sun_window: Box | None
    camera: Camera
    auto: tuple[str, ...]
    shadow: Box | None
    follow: tuple[tuple[int, Camera], ...] | None = None
    exposure_stops: float = 0.0


def canopy_extent(config: Config, projection: tuple[float, float]) -> Box:
    """The box of every canopy plane.

    The grove's leaves projected along the sun onto each plane over the flutter cycle, or the mask
    images' areas.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    projection : tuple of float
        The sky-plane point of the sun the leaves are projected along [tan].

    Returns
    -------
    tuple of float
        (x_min, y_min, x_max, y_max) [m].
    """
    boxes: list[tuple[float, ...]] = []
    for layer in config.canopy.layers:
        if config.canopy.trees is None or config.canopy.layout == "periodic":
            (cx, cy), (w, h) = layer.center, layer.size
            boxes.append((cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2))
        else:
            grove, flutter = grove_of(config.canopy)
            boxes.append(tuple(float(v) for v in grove_geometry.grove_bounds(
                grove, flutter, sun=np.array(projection), plane_height=layer.height)))
    return _union(boxes)


def crown_centre(config: Config) -> np.ndarray:
    """The mean of the grove's leaf stems, or of the mask planes' centres at their heights.

    Its shadow, not the canopy's bounding box's, is where the leaves' shade is: a low sun throws
    the trunks' shadows far longer than the crowns'.

    Parameters
    ----------
    config : settings.Config
        The resolved config.

    Returns
    -------
    ndarray, shape (3,)
        (x, y, z) [m].
    """
    if config.canopy.trees is None or config.canopy.layout == "periodic":
        return np.mean([(*layer.center, layer.height) for layer in config.canopy.layers], axis=0)
    grove, _ = grove_of(config.canopy)
    return grove.pivot.mean(axis=0)


DAPPLE_TRANSMITTANCE = 0.3
"""The camera placed by default looks where this share of the sun gets through the leaves:
near the shadow's rim, sun flecks on shade (a low sun's flecks are large and faint, so the
contrast comes from the rim). [1]"""
ECLIPSE_TRANSMITTANCE = 0.1
"""The same when the moon cuts the sun in some frame and the sun stands above LOW_SUN: deeper in
the shade, where the pinhole images stand apart and show their crescents. [1]"""
LOW_SUN = 30.0
"""Below this elevation the pinhole images are over twice as long as wide (1 / sin(elevation))
and overlap in deep shade: an eclipse is framed at the rim too. [deg]"""
DAPPLE_CELL = 0.25
"""Cell of the leaf-shadow density map that finds it (averaged over 1 m). [m]"""


def dappled_point(config: Config, s: ArrayLike, transmittance: float = DAPPLE_TRANSMITTANCE,
                  grove: grove_geometry.Grove | None = None) -> np.ndarray:
    """The point on the ground where the sun gets through the grove's leaves in about ``transmittance``.

    Each leaf's shadow (its ellipse's area pi |u| |v| times |n . w| / w_z along the sun w) is summed
    on a map of DAPPLE_CELL cells, averaged over 1 m, and taken as the optical depth of leaves
    placed at random, T = exp(-area per area); of the points nearest that T, the one nearest the
    shadow of the leaves' centre. A dense crown under a low sun lets light through only near its
    rim. Mask images and periodic forests: the shadow of the planes' centre.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    s : array_like, shape (2,)
        The sun's sky-plane point [tan].
    transmittance : float
        The share of the sun sought [1].
    grove : canopy.grove.Grove or None
        The grove in a receiver's axes, z along its normal (a slope's, ``slope_framing``) [m];
        None: the config's on the level ground.

    Returns
    -------
    ndarray, shape (2,)
        (x, y) [m].
    """
    centre = crown_centre(config) if grove is None else grove.pivot.mean(axis=0)
    middle = centre[:2] - centre[2] * np.asarray(s)
    if grove is None and (config.canopy.trees is None or config.canopy.layout == "periodic"):
        return middle
    from scipy.ndimage import uniform_filter

    leaves = (grove_of(config.canopy)[0] if grove is None else grove).leaves
    w = np.append(s, 1.0) / np.linalg.norm(np.append(s, 1.0))
    normal = np.cross(leaves.axis_u, leaves.axis_v)
    area = np.pi * np.abs(normal @ w) / w[2]  # |u x v| |n . w| = |(u x v) . w|
    shade = leaves.center[:, :2] - leaves.center[:, 2:3] * np.asarray(s)
    lo = shade.min(axis=0) - 1.0
    cells = np.ceil((shade.max(axis=0) + 1.0 - lo) / DAPPLE_CELL).astype(int)
    col, row = ((shade - lo) / DAPPLE_CELL).astype(int).T
    depth = np.zeros(cells[::-1])
    np.add.at(depth, (row, col), area / DAPPLE_CELL**2)
    depth = uniform_filter(depth, size=max(1, int(round(1.0 / DAPPLE_CELL))), mode="constant")
    miss = np.abs(np.log(np.maximum(np.exp(-depth), 1e-30) / transmittance))
    rows, cols = np.nonzero(miss <= miss.min() + 0.1)
    points = lo + (np.column_stack([cols, rows]) + 0.5) * DAPPLE_CELL
    return points[np.argmin(np.linalg.norm(points - middle, axis=1))]


def _union(boxes: Iterable[Sequence[float | np.ndarray]]) -> Box:
    corners = np.array(boxes, dtype=np.float64)
    return (*corners[:, :2].min(axis=0), *corners[:, 2:].max(axis=0))


def _grow(box: Sequence[float], margin: float) -> Box:
    return (box[0] - margin, box[1] - margin, box[2] + margin, box[3] + margin)


def _intersect(a: Sequence[float], b: Sequence[float]) -> Box | None:
    box = (max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3]))
    return box if box[2] > box[0] and box[3] > box[1] else None


def shadow_extents(config: Config, scenes: Iterable[Scene], projection: tuple[float, float],
                   extent: Box | None = None) -> list[Box]:
    """Per frame, the box of the ground the canopy's shadow falls on.

    A plane point c at height h shades c - h s along the sun's sky-plane point s [tan], so the
    shadow lies h cot(elevation) from the canopy, towards the anti-solar azimuth.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    scenes : iterable of scene.Scene
        The frames' scenes; one without a sun gets the canopy's box.
    projection : tuple of float
        The sun's sky-plane point the canopy's extent is projected along [tan].
    extent : tuple of float, optional
        ``canopy_extent(config, projection)``, where the caller has it already (a grove's takes
        0.2 s) [m].

    Returns
    -------
    list of tuple of float
        Per scene, (x_min, y_min, x_max, y_max) [m].
    """
    if extent is None:
        extent = canopy_extent(config, projection)
    boxes = []
    for scene in scenes:
        if scene.sun is None:
            boxes.append(extent)
            continue
        sx, sy = sky_plane_from_direction(scene.sun.azimuth, np.pi / 2 - scene.sun.elevation)
        boxes.append(_union([(extent[0] - h * sx, extent[1] - h * sy, extent[2] - h * sx, extent[3] - h * sy)
                             for h in (layer.height for layer in config.canopy.layers)]))
    return boxes


def leaf_shadow_extents(config: Config, scenes: Iterable[Scene], projection: tuple[float, float]) -> list[Box]:
    """Per frame, the box of the leaves' shadows alone.

    Every 16th leaf's centre, at its own height, along the frame's sun: a low sun's trunk shadow
    reaches far beyond them. Mask images: ``shadow_extents``.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    scenes : iterable of scene.Scene
        The frames' scenes, each with a sun.
    projection : tuple of float
        The sun's sky-plane point [tan] (for ``shadow_extents``).

    Returns
    -------
    list of tuple of float
        Per scene, (x_min, y_min, x_max, y_max) [m].
    """
    if config.canopy.trees is None or config.canopy.layout == "periodic":
        return shadow_extents(config, scenes, projection)
    grove, _ = grove_of(config.canopy)
    centres = grove.leaves.center[::16]
    boxes = []
    for sun in map(sun_of, scenes):
        s = np.array(sky_plane_from_direction(sun.azimuth, np.pi / 2 - sun.elevation))
        shade = centres[:, :2] - centres[:, 2:3] * s
        boxes.append((*shade.min(axis=0), *shade.max(axis=0)))
    return boxes


def frame_scene(config: Config, scenes: Sequence[Scene], projection: tuple[float, float]) -> Framing:
    """The windows and the camera of a run, each from the config where it gives them, else
    placed (docs/method.md, "Framing"):

    - ``ground.window``: the canopy and its shadow over every frame, grown by WINDOW_MARGIN
      canopy heights (an isolated canopy); one tile (a periodic forest).
    - ``camera``: at eye height, looking CAMERA_PITCH (ECLIPSE_PITCH when the moon cuts the
      sun above LOW_SUN) down at the middle frame's dappled shade (``dappled_point``), seen
      AIM_ROW down the image, facing CAMERA_TURN round from the sun's azimuth; a given
      position looks there, a given look_at is seen from there.
    - ``ground.sun_window``: the ground the camera sees of the shadow (with a pinhole image's
      length to spare), cut at the distance where it would pass AUTO_SUN_PIXELS fine pixels;
      the window when a window is given but no sun window.
    - ``camera.follow``: a placed camera (no position, look_at or sun window given) that would
      lose the shadow over the span (``auto``), or any (``shadow``), walks with it frame by
      frame (``follow_targets``, ``follow_cameras``); the plan moves the sun window with it.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    scenes : sequence of scene.Scene
        The scenes whose sun shades (``scene.shading_scenes``), or one scene without a sun.
    projection : tuple of float
        The sky-plane point of the sun the leaves are projected along [tan].

    Returns
    -------
    Framing
        The windows [m], the camera, what was placed and where the shadow falls.
    """
    ground, c = config.ground, config.camera
    heights = [layer.height for layer in config.canopy.layers]
    periodic = config.canopy.layout == "periodic"
    auto = []
    extent = canopy_extent(config, projection)
    shadows = shadow_extents(config, scenes, projection, extent)
    shadow_box = None if periodic else _union(shadows)
    window = ground.window
    if window is None:
        auto.append("ground.window")
        window = extent if periodic or shadow_box is None else _grow(_union([extent, shadow_box]),
                                                                     WINDOW_MARGIN * max(heights))
    # the camera's target: where the middle frame's shade is dappled
    sun = scenes[len(scenes) // 2].sun
    s = np.array(sky_plane_from_direction(sun.azimuth, np.pi / 2 - sun.elevation)) if sun else np.zeros(2)
    deep = sun is not None and _eclipsed(scenes) and sun.elevation >= np.radians(LOW_SUN)
    target = dappled_point(config, s, ECLIPSE_TRANSMITTANCE if deep else DAPPLE_TRANSMITTANCE)
    aim = AIM_ROW
    if ground.sun_window is not None and c.position is None and c.look_at is None:
        sw = ground.sun_window  # a given sun window: the camera looks at its middle
        target, aim = np.array([(sw[0] + sw[2]) / 2, (sw[1] + sw[3]) / 2]), 0.5
    pitch = ECLIPSE_PITCH if deep else CAMERA_PITCH
    planes = wall_planes(config)
    view, at_wall = _view_at_walls(config, planes, sun, auto) if planes else (None, False)
    if view is None:
        view = _place_camera(config, target, s, auto, pitch, aim)
        if planes and "camera" in auto and c.position is None and c.look_at is None:  # clear of the walls
            view = clear_of_walls(view, target, planes)
    follow = None
    movable = (not at_wall and sun is not None and c.position is None and c.look_at is None
               and ground.sun_window is None and ground.window is None  # a given window: the camera stays
               and not periodic  # an endless forest has no shadow to follow
               and config.foreground.model != "passes")  # imported passes hold one camera's view
    if movable and c.follow != "fixed" and len(scenes) > 1:
        targets = follow_targets(config, scenes, target)
        if c.follow == "shadow" or _strays(view, target, targets):
            follow = tuple(zip((sc.frame for sc in scenes), follow_cameras(view, target, targets)))
    sun_window = ground.sun_window
    if sun_window is None and sun is not None:
        if ground.window is not None:
            sun_window = ground.window
        else:
            auto.append("ground.sun_window")
            sun_window = _seen_sun_window(config, scenes, view, shadow_box, window)
    if "ground.window" in auto and not periodic:  # only the ground some frame's camera sees
        window = _seen_window([view] if follow is None else [v for _, v in follow], view, sun_window, window)
    stops = exposure_stops(config, sky_model(config.sky).at(scenes[len(scenes) // 2]), view) if planes else 0.0
    return Framing(_floats(window), None if sun_window is None else _floats(sun_window),
                   view, tuple(auto), shadow_box, follow, stops)


def _view_at_walls(config: Config, planes: list[ReceiverPlane], sun: SunDisc | None,
                   auto: list[str]) -> tuple[Camera | None, bool]:
    """Where a wall takes the leaves' shadow, a camera not given (no position, look_at, yaw or pitch)
    looks at it there (``wall_framing.wall_camera``) and stays: a wall's shadow moves little."""
    c = config.camera
    if sun is None or c.position is not None or c.look_at is not None or c.yaw is not None or c.pitch is not None:
        return None, False
    view = wall_camera(config, sun, planes, CAMERA_HEIGHT)
    if view is None:
        return None, False
    auto.append("camera")
    return view, True


def _floats(box: Sequence[float]) -> Box:
    """A box's four numbers as floats [m]."""
    x_min, y_min, x_max, y_max = (float(v) for v in box)
    return x_min, y_min, x_max, y_max


FOLLOW_SLACK = 0.15
"""With ``camera.follow: auto`` a placed camera follows the shadow when, seen from the middle
frame's camera, some frame's target lies further than this share of the image's width from
where that camera sees its own (or outside the image). [1]"""


def follow_targets(config: Config, scenes: Sequence[Scene], target: ArrayLike) -> np.ndarray:
    """Per scene, the ground point a camera that follows the shadow aims at.

    The shadow of the crown's centre along the scene's sun, ``c - h s``, plus the middle scene's
    ``target``'s offset from it, taken in the sun's own axes and stretched along the sun by
    ``1 / sin(elevation)`` as the shadow of a round crown is: the target keeps its place in the
    shadow (its rim, its dappled part) as the shadow moves and lengthens, smoothly, where the
    dappled point found anew in each frame would jump from one side of the shadow to the other
    (docs/method.md, "Framing").

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    scenes : sequence of scene.Scene
        The scenes whose sun shades, in frame order.
    target : array_like, shape (2,)
        The middle scene's target (``dappled_point``) (x, y) [m].

    Returns
    -------
    ndarray, shape (len(scenes), 2)
        (x, y) [m].
    """
    centre = crown_centre(config)
    suns = [sun_of(sc) for sc in scenes]
    sky = np.array([sky_plane_from_direction(sun.azimuth, np.pi / 2 - sun.elevation) for sun in suns])
    middles = centre[:2] - centre[2] * sky
    azimuth = np.array([sun.azimuth for sun in suns])
    elevation = np.array([sun.elevation for sun in suns])
    along = np.column_stack([np.sin(azimuth), np.cos(azimuth)])
    across = np.column_stack([np.cos(azimuth), -np.sin(azimuth)])
    m = len(scenes) // 2
    offset = np.asarray(target, dtype=np.float64) - middles[m]
    stretch = (offset @ along[m]) * np.sin(elevation[m])  # the offset along the sun times sin(h)
    return middles + (stretch / np.sin(elevation))[:, None] * along + (offset @ across[m]) * across


def follow_cameras(view: Camera, target: ArrayLike, targets: ArrayLike) -> list[Camera]:
    """``view`` moved over the ground, its yaw and pitch kept, so that it sees each target where it
    sees ``target``.

    Parameters
    ----------
    view : pinhole.Camera
        The camera that looks at ``target``.
    target : array_like, shape (2,)
        Its ground point (x, y) [m].
    targets : array_like, shape (n, 2)
        The ground points to look at (x, y) [m].

    Returns
    -------
    list of pinhole.Camera
        One per target.
    """
    moves = np.asarray(targets, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    x, y, z = view.position
    return [pinhole.Camera((float(x + dx), float(y + dy), z), view.yaw, view.pitch, view.vertical_fov,
                          view.width, view.height) for dx, dy in moves]


def _strays(view: Camera, target: ArrayLike, targets: np.ndarray) -> bool:
    """Whether some target lies further than FOLLOW_SLACK of the image's width from where
    ``view`` sees ``target``, or outside the image."""
    points = np.column_stack([np.vstack([target, targets]), np.zeros(len(targets) + 1)])
    u, v, depth = pinhole.project_points(view, points)
    inside = (depth[1:] > 0) & (u[1:] >= 0) & (u[1:] <= view.width) & (v[1:] >= 0) & (v[1:] <= view.height)
    drift = np.hypot(u[1:] - u[0], v[1:] - v[0]) / view.width
    return bool(np.any(~inside) or np.any(drift > FOLLOW_SLACK))


def _eclipsed(scenes: Iterable[Scene]) -> bool:
    """Whether the moon cuts the sun in some frame."""
    for scene in scenes:
        if scene.sun is None or scene.moon is None:
            continue
        a = direction_vector(scene.sun.azimuth, scene.sun.elevation)
        b = direction_vector(scene.moon.azimuth, scene.moon.elevation)
        if np.arccos(np.clip(a @ b, -1, 1)) < scene.sun.angular_radius + scene.moon.angular_radius:
            return True
    return False


def _place_camera(config: Config, target: np.ndarray, s: np.ndarray, auto: list[str], pitch_down: float,
                  aim: float = 0.5) -> Camera:
    """The config's camera with what it leaves out placed to look at ``target`` [m], by default
    ``pitch_down`` [deg] below the horizon, with the target ``aim`` [1] down the image (0 top,
    1 bottom; AIM_ROW for a target of its own)."""
    c = config.camera
    width, rows = c.resolution
    if c.position is not None and c.yaw is not None and c.pitch is not None:  # yaw and pitch come together
        return pinhole.Camera((c.position[0], c.position[1], c.position[2]), c.yaw, c.pitch, c.fov, width, rows)
    if c.position is not None and c.look_at is not None:
        return pinhole.Camera.look_at(c.position, c.look_at, vertical_fov=c.fov, width=width, height=rows)
    auto.append("camera")
    if c.position is not None:
        return pinhole.Camera.look_at(c.position, (*target, 0.0), vertical_fov=c.fov, width=width, height=rows)
    if c.look_at is not None:
        target = np.array(c.look_at[:2])
    yaw = c.yaw
    if yaw is None:
        sun_azimuth = float(np.arctan2(s[0], s[1])) if np.any(s) else np.pi
        yaw = (sun_azimuth - np.radians(CAMERA_TURN)) % (2 * np.pi)
    pitch = c.pitch if c.pitch is not None else -np.radians(pitch_down)
    # the target at the middle of the image's bottom third, AIM_ROW down: the near ground
    below = np.arctan((2.0 * aim - 1.0) * np.tan(c.fov / 2.0))
    down = -pitch + below
    back = CAMERA_HEIGHT / np.tan(min(down, np.pi / 2)) if pitch < -np.radians(1.0) else 2.0 * max(
        layer.height for layer in config.canopy.layers)
    position = (*(np.asarray(target) - back * np.array([np.sin(yaw), np.cos(yaw)])), CAMERA_HEIGHT)
    if c.look_at is not None:
        return pinhole.Camera.look_at(position, c.look_at, vertical_fov=c.fov, width=width, height=rows)
    return pinhole.Camera((float(position[0]), float(position[1]), float(position[2])), float(yaw), float(pitch),
                         c.fov, width, rows)


AIM_ROW = 5.0 / 6.0
"""A camera placed by default sees its target this far down the image (0 top, 1 bottom): the
middle of the bottom third, the nearest ground, sharpest and least foreshortened. [1]"""


def seen_ground(view: Camera, samples: int = AUTO_VIEW_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """The ground points of a grid of rays over the image that meet the ground.

    Parameters
    ----------
    view : pinhole.Camera
        The camera.
    samples : int
        Rays per side of the image [1].

    Returns
    -------
    points : ndarray, shape (n, 2)
        Where the rays meet the ground (x, y) [m].
    distance : ndarray, shape (n,)
        Their distances from the camera [m].
    """
    u, v = np.meshgrid(np.linspace(0, view.width, samples), np.linspace(0, view.height, samples))
    rays = pinhole.image_rays(view, u, v).reshape(-1, 3)
    down = rays[:, 2] < -1e-9
    t = -view.position[2] / rays[down, 2]
    points = np.asarray(view.position[:2]) + t[:, None] * rays[down, :2]
    return points, t * np.linalg.norm(rays[down], axis=1)


def _seen_sun_window(config: Config, scenes: Sequence[Scene], view: Camera, shadow_box: Box | None,
                     window: Box) -> Box | None:
    """The ground the camera sees of the shadow (grown by a pinhole image's length), within the
    window, as near as AUTO_SUN_PIXELS fine pixels allow; if it sees none of the shadow, what
    it sees of the window. [m]"""
    heights = [layer.height for layer in config.canopy.layers]
    radius = min(sun_of(sc).angular_radius for sc in scenes)
    lowest = min(sun_of(sc).elevation for sc in scenes)
    pixel = config.ground.sun_pixel or min(heights) * 2 * np.tan(radius) / config.render.sun_cells
    # a pinhole image's length [m]: 1 / sin(h) times its width (geometry.pinhole_image_axes)
    image = pinhole_image_axes(max(heights), max(lowest, 2.0 * radius), radius)[0]
    area = window if shadow_box is None else _intersect(_grow(shadow_box, image), window) or window
    points, distance = seen_ground(view)
    inside = ((points[:, 0] >= area[0]) & (points[:, 0] <= area[2])
              & (points[:, 1] >= area[1]) & (points[:, 1] <= area[3]))
    if not inside.any():  # the camera misses the shadow: the ground it sees in the window
        area = window
        inside = ((points[:, 0] >= area[0]) & (points[:, 0] <= area[2])
                  & (points[:, 1] >= area[1]) & (points[:, 1] <= area[3]))
    if not inside.any():  # nor the window (it looks up, or away): 2 m about its foot
        return _grow((*view.position[:2], *view.position[:2]), 2.0)
    points, distance = points[inside], distance[inside]
    order = np.argsort(distance)
    best = None
    for k in range(1, len(order) + 1):  # the nearest points first, while they fit
        near = points[order[:k]]
        box = _intersect(_grow((*near.min(axis=0), *near.max(axis=0)), 2 * pixel + image / 4), area)
        if box is None:
            continue
        if _pixels(box, pixel) > AUTO_SUN_PIXELS and best is not None:
            break
        best = box
    return best


SEEN_MARGIN = 2.0
"""A placed ground.window reaches this far beyond the ground the cameras see (the texture
filter's reach at the image's far edge). [m]"""


def _seen_window(views: Sequence[Camera], middle: Camera, sun_window: Box | None, window: Box) -> Box:
    """The ground the cameras see over the frames with SEEN_MARGIN to spare, within ``window``,
    and the sun window moved with each camera [m]: the shadow's union over a long span (264 x 86
    m at a 3.7 degree sun) holds far more ground than a camera at eye height sees."""
    points, _ = seen_ground(middle)
    if not len(points):
        return window
    seen, fine = [], []
    for view in views:  # a following camera only walks: its ground walks with it
        dx, dy = np.subtract(view.position[:2], middle.position[:2])
        moved = points + (dx, dy)
        seen.append((*moved.min(axis=0), *moved.max(axis=0)))
        if sun_window is not None:
            fine.append((sun_window[0] + dx, sun_window[1] + dy, sun_window[2] + dx, sun_window[3] + dy))
    return _union([_intersect(_grow(_union(seen), SEEN_MARGIN), window) or window, *fine])


def _pixels(box: Box, pixel: float) -> float:
    return (box[2] - box[0]) * (box[3] - box[1]) / pixel**2


def framing_warnings(config: Config, plan: RunPlan) -> list[str]:
    """One-line warnings of a plan whose picture would show no dappled shadow, or a false one.

    The camera sees none of the sun window; the sun is below the canopy's reach, the sky square
    (``sky.alpha``), in some frames, so that beyond the sun window nothing shades it; the
    leaves' shadow falls outside the sun window in some frames.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    plan : plan.RunPlan
        Its plan.

    Returns
    -------
    list of str
        The warnings, none for a good framing.
    """
    if config.receivers.slope is not None:  # its windows are in its frame (slope_framing)
        return []
    scenes = list(plan.scenes)
    warnings = []
    fine = plan.sun_window or plan.window
    x0, y0, x1, y1 = fine.extent
    key = "ground.sun_window" if plan.sun_window is not None else "ground.window"
    points, _ = seen_ground(plan.camera)
    seen = ((points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1))
    middle = scenes[len(scenes) // 2].sun
    if not seen.any() and not (middle is not None and sees_wall_flecks(config, plan.camera, middle)):
        warnings.append(f"the camera sees none of {key} [{x0:.2f}, {y0:.2f}, {x1:.2f}, {y1:.2f}]: "
                        f"its frames will show no sun flecks (leave camera out to place it)")
    reach = np.pi / 2 - config.sky.alpha  # the lowest sun the sky square holds [rad]
    low = [f for f, scene in enumerate(scenes) if sun_shades(scene.sun) and sun_of(scene).elevation < reach]
    beyond = 1.0 - float(seen.mean())  # the share of the ground seen where that sun is unshadowed
    if low and plan.sun_window is not None and beyond > 0:
        warnings.append(f"the sun is below the sky square (sky.alpha {np.degrees(config.sky.alpha):g} "
                        f"degrees reaches down to {np.degrees(reach):g} degrees elevation) in "
                        f"{len(low)} of {len(scenes)} frames ({frame_ranges(low)}): beyond {key}, "
                        f"{100 * beyond:.0f}% of the ground the camera sees, its light is taken as "
                        f"unshadowed there; raise sky.alpha")
    if config.canopy.layout == "isolated" and plan.sun_window is not None:
        shading = shading_scenes(scenes)
        boxes: Sequence[Box | None] = (  # the shadows a wall takes lie in its own fine raster
            ground_shadow_boxes(config, [sun_of(sc) for sc in shading]) if config.receivers.walls
            else leaf_shadow_extents(config, shading, plan.projection))
        missed = []
        for sc, box in zip(shading, boxes):
            moved = plan.at(sc.frame).sun_window  # the frame's own, with a following camera
            if box is not None and moved is not None and _intersect(box, moved.extent) is None:
                missed.append(sc.frame)
        if missed:
            elevations = [np.degrees(sun_of(scenes[f]).elevation) for f in missed]
            warnings.append(f"the leaves' shadow falls outside {key} in {len(missed)} of "
                            f"{len(scenes)} frames ({frame_ranges(missed)}; the sun at "
                            f"{min(elevations):.1f} to {max(elevations):.1f} degrees): the canopy "
                            f"does not reach the window along the sun there")
    return warnings


def frame_ranges(frames: Sequence[int]) -> str:
    """Frame numbers as ranges, for a message: ``[0, 1, 2, 5]`` -> ``"0-2,5"``.

    Parameters
    ----------
    frames : list of int
        Increasing frame numbers, at least one.

    Returns
    -------
    str
        The runs of consecutive frames, comma-separated.
    """
    parts: list[str] = []
    start: int | None = frames[0]
    for a, b in zip(frames, [*frames[1:], None]):
        if b != a + 1:
            parts.append(f"{start}" if start == a else f"{start}-{a}")
            start = b
    return ",".join(parts)
