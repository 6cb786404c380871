"""Framing on a sloped ground: what a slope's config leaves out of ``ground.window``,
``ground.sun_window`` and ``camera`` placed in the slope's frame, where the slope is the level
ground and the trees stand turned, as ``framing.frame_scene`` places them on the level ground; the
exposure of the open slope; the open light below its horizon (docs/method.md, "A sloped ground").
Part of the plan stage: ``plan`` calls it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.camera.pinhole import Camera
from pipeline.config.settings import Config, GroundConfig
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.errors import ConfigError
from pipeline.core.geometry import direction_vector, pinhole_image_axes
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, world_radiance
from pipeline.receivers.layers import grove_in_frame
from pipeline.receivers.plane import ReceiverPlane
from pipeline.receivers.slope import camera_in_frame, slope_plane
from pipeline.receivers.sun import receiver_sun_irradiance, sun_lights
from pipeline.sky.base import Sky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.framing import (
    AIM_ROW,
    AUTO_SUN_PIXELS,
    CAMERA_HEIGHT,
    CAMERA_PITCH,
    DAPPLE_TRANSMITTANCE,
    SEEN_MARGIN,
    WINDOW_MARGIN,
    Box,
    Framing,
    dappled_point,
    seen_ground,
)
from pipeline.stages.inputs import albedo_mipmap, grove_of
from pipeline.stages.scene import Scene, sky_model, sun_shades

__all__ = ["STEEPEST_VIEW", "slope_occluders", "frame_slope", "below_radiance", "open_level_sun", "slope_stops"]

STEEPEST_VIEW = 80.0
"""A camera placed on a slope looks down it, towards the sun, at most this far below the world's
horizon (CAMERA_PITCH below the slope plus its tilt); steeper, it looks up the slope. [deg]"""

_LEAF_STRIDE = 16  # every 16th leaf's centre stands for the crowns' shadow (as framing.leaf_shadow_extents)


def slope_occluders(config: Config, plane: ReceiverPlane) -> np.ndarray:
    """The points whose shadows make the slope's shade, in its frame: every 16th leaf of the trees
    standing on it, turned, or the corners of its mask layers at their distances.

    Parameters
    ----------
    config : settings.Config
        A config with ``receivers.slope``.
    plane : receivers.plane.ReceiverPlane
        The slope.

    Returns
    -------
    numpy.ndarray
        (n, 3) (u, w, along n) [m].
    """
    if config.canopy.trees is None:
        return np.array([(cx + du * sx / 2, cy + dw * sy / 2, layer.height)
                         for layer in config.canopy.layers for (cx, cy), (sx, sy) in [(layer.center, layer.size)]
                         for du in (-1, 1) for dw in (-1, 1)])
    standing, _ = grove_of(config.canopy, config.receivers.slope)
    return plane.local_points(standing.leaves.center[::_LEAF_STRIDE])


def _local_sun(scene: Scene, plane: ReceiverPlane) -> np.ndarray | None:
    """The scene's sun on the slope's sky plane [tan]; None where it shades nothing or is behind the slope."""
    if not sun_shades(scene.sun):
        return None
    assert scene.sun is not None
    d = plane.local_directions(direction_vector(scene.sun.azimuth, scene.sun.elevation))
    return d[:2] / d[2] if d[2] > 1e-6 else None


def _box(points: np.ndarray, margin: float = 0.0) -> Box:
    lo, hi = points.min(axis=0) - margin, points.max(axis=0) + margin
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _cut(a: Sequence[float], b: Sequence[float]) -> Box | None:
    box = (max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3]))
    return box if box[2] > box[0] and box[3] > box[1] else None


def frame_slope(config: Config, scenes: Sequence[Scene]) -> Framing:
    """The windows and the camera of a run on a slope, each from the config where it gives them,
    else placed in the slope's frame as ``framing.frame_scene`` places them on the level ground:

    - ``ground.window``: the occluders and their shadows over every frame whose sun lights the
      slope, grown by WINDOW_MARGIN of their distance, cut to the slope the camera sees.
    - ``camera``: CAMERA_HEIGHT above the slope (vertically), looking CAMERA_PITCH down the slope
      plane at the middle frame's dappled shade (``framing.dappled_point`` on the turned grove; the
      mask layers' middle), seen AIM_ROW down the image; straight up or down the slope (no roll),
      towards the sun, unless that looks more than STEEPEST_VIEW below the horizon; the middle of a
      given ``ground.sun_window``. It stands still.
    - ``ground.sun_window``: the slope the camera sees of the shadow (with a pinhole image's length
      to spare), nearest first within AUTO_SUN_PIXELS fine pixels; the window when it is given.

    Parameters
    ----------
    config : settings.Config
        The resolved config with ``receivers.slope``.
    scenes : sequence of scene.Scene
        The scenes whose sun shades, or one scene without a sun.

    Returns
    -------
    framing.Framing
        The windows in the slope's (u, w) metres, the world camera, what was placed, the shadow's
        box on the slope and, with a placed camera and a fixed exposure, the open slope's exposure
        (``slope_stops``).

    Raises
    ------
    ConfigError
        For a camera given in part (a position or a look_at alone, a yaw and pitch without a position).
    """
    ground, c = config.ground, config.camera
    plane = slope_plane(config.receivers.slope)  # type: ignore[arg-type]
    given = (c.position is not None and (c.look_at is not None or (c.yaw is not None and c.pitch is not None)))
    if not given and (c.position is not None or c.look_at is not None or c.yaw is not None or c.pitch is not None):
        key = "camera.look_at" if c.position is not None else "camera.position"
        raise ConfigError(config.where(key), "on a slope give camera.position with camera.look_at (or yaw and "
                          "pitch), or neither: a camera placed on a slope looks along its fall line")
    auto: list[str] = []
    points = slope_occluders(config, plane)
    suns = [s for s in (_local_sun(sc, plane) for sc in scenes) if s is not None]
    shadows = [_box(points[:, :2] - points[:, 2:3] * s) for s in suns]
    shadow_box = _box(np.array([b[:2] for b in shadows] + [b[2:] for b in shadows])) if shadows else None
    reach = WINDOW_MARGIN * float(np.max(points[:, 2]))
    extent = _box(np.vstack([points[:, :2], *(np.reshape(b, (2, 2)) for b in shadows)]), reach)
    middle = _local_sun(scenes[len(scenes) // 2], plane)
    view = _given_camera(config) if given else _placed_camera(config, plane, middle, auto)
    local = _in_frame(view, plane)
    window = ground.window
    if window is None:
        auto.append("ground.window")
        window = extent
    sun_window = ground.sun_window
    if sun_window is None and suns:
        if ground.window is not None:
            sun_window = ground.window
        else:
            auto.append("ground.sun_window")
            sun_window = _seen_sun_window(config, scenes, plane, local, shadow_box, window)
    if "ground.window" in auto:  # only the slope the camera sees, and the sun window
        seen, _ = seen_ground(local)
        if len(seen):
            window = _cut(_box(seen, SEEN_MARGIN), window) or window
        if sun_window is not None:
            window = _box(np.reshape([*window, *sun_window], (4, 2)))
    placed = "camera" in auto and c.auto_exposure is None  # an auto exposure meters the slope itself
    stops = slope_stops(config, scenes[len(scenes) // 2], plane) if placed else 0.0
    fine = None if sun_window is None else _box(np.reshape(sun_window, (2, 2)))
    return Framing(_box(np.reshape(window, (2, 2))), fine, view, tuple(auto), shadow_box, None, stops)


def _given_camera(config: Config) -> Camera:
    """The config's whole camera, in world axes."""
    c = config.camera
    assert c.position is not None
    width, rows = c.resolution
    if c.look_at is not None:
        return Camera.look_at(c.position, c.look_at, vertical_fov=c.fov, width=width, height=rows)
    assert c.yaw is not None and c.pitch is not None
    return Camera((c.position[0], c.position[1], c.position[2]), c.yaw, c.pitch, c.fov, width, rows)


def _in_frame(view: Camera, plane: ReceiverPlane) -> Camera:
    """``receivers.slope.camera_in_frame``, or for a camera it refuses (the plan names the key) the
    camera at the same place in the slope's axes looking the same way, for the windows."""
    try:
        return camera_in_frame(view, plane)
    except ValueError:
        position = plane.local_points(view.position)
        return Camera.look_at(position, position + plane.local_directions(view.basis[2]),
                              vertical_fov=view.vertical_fov, width=view.width, height=view.height)


def _placed_camera(config: Config, plane: ReceiverPlane, s: np.ndarray | None, auto: list[str]) -> Camera:
    """The world camera placed on the slope (``frame_slope``), looking at the dappled shade under
    the sun at the slope's sky-plane point ``s`` [tan] (None: the crowns' foot, up the slope)."""
    c, ground = config.camera, config.ground
    auto.append("camera")
    tilt = float(config.receivers.slope.tilt)  # type: ignore[union-attr]
    sun = np.zeros(2) if s is None else s
    if ground.sun_window is not None:
        sw = ground.sun_window
        target, aim = np.array([(sw[0] + sw[2]) / 2, (sw[1] + sw[3]) / 2]), 0.5
    elif config.canopy.trees is None:
        centre = np.mean([(*layer.center, layer.height) for layer in config.canopy.layers], axis=0)
        target, aim = centre[:2] - centre[2] * sun, AIM_ROW
    else:
        turned = grove_in_frame(grove_of(config.canopy, config.receivers.slope)[0], plane)
        target, aim = dappled_point(config, sun, DAPPLE_TRANSMITTANCE, grove=turned), AIM_ROW
    pitch = np.radians(CAMERA_PITCH)
    uphill = s is None or s[1] >= 0.0 or np.degrees(tilt) + CAMERA_PITCH > STEEPEST_VIEW
    along = 1.0 if uphill else -1.0  # +w: up the slope
    eye = CAMERA_HEIGHT * np.cos(tilt)  # along the normal: CAMERA_HEIGHT straight above the slope
    down = pitch + np.arctan((2.0 * aim - 1.0) * np.tan(c.fov / 2.0))
    position = np.array([target[0], target[1] - along * eye / np.tan(down), eye])
    forward = np.array([0.0, along * np.cos(pitch), -np.sin(pitch)])
    width, rows = c.resolution
    world = plane.world_points(position)
    return Camera.look_at(world, world + plane.world_directions(forward), vertical_fov=c.fov, width=width, height=rows)


def _seen_sun_window(config: Config, scenes: Sequence[Scene], plane: ReceiverPlane, view: Camera,
                     shadow_box: Box | None, window: Box) -> Box:
    """The slope the camera (in the slope's frame) sees of the shadow, grown by a pinhole image's
    length, within the window, nearest first while AUTO_SUN_PIXELS fine pixels hold it; if it sees
    none of the shadow, what it sees of the window; if none of that, 2 m about its foot. [m]"""
    distance = float(np.max(slope_occluders(config, plane)[:, 2]))
    suns = [sc.sun for sc in scenes if sc.sun is not None and _local_sun(sc, plane) is not None]
    radius = min(sun.angular_radius for sun in suns)
    lowest = min(float(np.arcsin(np.clip(plane.local_directions(direction_vector(sun.azimuth, sun.elevation))[2],
                                         -1.0, 1.0))) for sun in suns)  # above the slope
    pixel = config.ground.sun_pixel or distance * 2 * np.tan(radius) / config.render.sun_cells
    image = pinhole_image_axes(distance, max(lowest, 2.0 * radius), radius)[0]
    points, along = seen_ground(view)
    for area in ([] if shadow_box is None else [_cut(_box(np.reshape(shadow_box, (2, 2)), image), window)]) + [window]:
        if area is None:
            continue
        inside = ((points[:, 0] >= area[0]) & (points[:, 0] <= area[2])
                  & (points[:, 1] >= area[1]) & (points[:, 1] <= area[3]))
        if inside.any():
            break
    else:
        return _box(np.array([view.position[:2]]), 2.0)
    near = points[inside][np.argsort(along[inside])]
    lo, hi = np.minimum.accumulate(near, axis=0), np.maximum.accumulate(near, axis=0)
    grow = 2 * pixel + image / 4
    cells = np.prod(np.clip(np.minimum(hi + grow, area[2:]) - np.maximum(lo - grow, area[:2]), 0.0, None),
                    axis=1) / pixel**2
    k = max(1, int(np.searchsorted(cells, AUTO_SUN_PIXELS, side="right")))  # cells grow with k
    return _cut(_box(near[:k], grow), area) or area


def below_radiance(ground: GroundConfig, sky: Sky) -> np.ndarray:
    """The radiance (3,) below the world's horizon around a slope: the open level ground's, its mean
    albedo x its light / pi (``hemisphere.ground_radiance``).

    Parameters
    ----------
    ground : settings.GroundConfig
        The ground (its albedo).
    sky : sky.base.Sky
        The frame's sky.

    Returns
    -------
    numpy.ndarray
        (3,) float64 [radiance].
    """
    return ground_radiance(albedo_mipmap(ground).mean, np.asarray(sky.sky_irradiance, dtype=np.float64)
                           + open_level_sun(sky))


def open_level_sun(sky: Sky) -> np.ndarray:
    """The sun's light (3,) on the open level ground for the light below a slope's horizon: a
    procedural sky's sun as a point, E_n cos(zenith) dimmed by the moon and the clouds (the kernel's
    sum to O(r^2); at a low sun the kernel stretched over the level sky plane costs seconds), any
    other sky's ``sun_kernel.sun_irradiance``.

    Parameters
    ----------
    sky : sky.base.Sky
        The frame's sky.

    Returns
    -------
    numpy.ndarray
        (3,) float64 [radiance x sr].
    """
    if isinstance(sky, ProceduralSky):
        if sky.sun is None or sky.sun.elevation - sky.sun.angular_radius <= 1e-3:
            return np.zeros(3)
        return np.asarray(sky.undimmed_sun_irradiance() * sky.moon_visible * sky.sun_cloud_transmittance,
                          dtype=np.float64)
    return sun_irradiance(sky)  # type: ignore[arg-type]


def slope_stops(config: Config, scene: Scene, plane: ReceiverPlane) -> float:
    """Stops that move the default exposure (a white level ground under its open sun and sky at 1)
    to put a white slope under its own open light at 1: a slope facing the sun darkens the picture.

    Parameters
    ----------
    config : settings.Config
        The resolved config with ``receivers.slope``.
    scene : scene.Scene
        The middle frame's scene.
    plane : receivers.plane.ReceiverPlane
        The slope.

    Returns
    -------
    float
        -log2(slope / level), luminance [stops]; 0 without light.
    """
    sky = sky_model(config.sky).at(scene)
    level = float((np.asarray(sky.sky_irradiance, dtype=np.float64) + open_level_sun(sky)) @ REC709_LUMINANCE)
    slope = hemisphere_irradiance(world_radiance(sky, below_radiance(config.ground, sky)), plane)
    if sky.sun is not None and sun_lights(sky, plane):
        slope = slope + receiver_sun_irradiance(sky, plane)
    lit = float(slope @ REC709_LUMINANCE)
    return 0.0 if level <= 0 or lit <= 0 else float(-np.log2(lit / level))
