"""The orchestrator: reads a config's inputs and runs the stages in order.

The cycle phase makes the products of every cycle frame (mask spectra, foreground passes) and
caches them; the frame phase makes a frame: the ground raster (Max 1991, Fig. 7) under that
frame's sky, resampled in the camera with the sky, the foreground blended by S over it.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import time
from dataclasses import asdict, dataclass, replace
from datetime import datetime
from pathlib import Path

import joblib
import numpy as np

from . import albedo as albedos
from . import cache, camera, canopy, composite, ephemeris, foreground, io, shadow
from . import sky as sky_models
from .composite import REC709_LUMINANCE
from .errors import ConfigError, portable
from .config import (BYTES_PER_CELL, MAX_FFT_CELLS, MAX_GROUND_PIXELS, MAX_RADIANCE, MAX_SUN_PIXELS,
                     CanopyConfig, CanopyLayer, Config, GroundConfig, SkyConfig, size_text)
from .clouds import CloudLayer
from .geometry import Grid, sky_plane_from_direction
from .sky import EquirectSky, UniformSky


@dataclass(frozen=True)
class GroundResult:
    """irradiance : (rows, cols, 3) float32 [radiance x sr]; grid : its ground Grid [m];
    unshadowed : (3,) irradiance of the open sky; exact : whether every ray that meets the
    canopy lies inside the sky square (else light from beyond it was taken as unshadowed)."""

    irradiance: np.ndarray
    grid: Grid
    unshadowed: np.ndarray
    exact: bool
    outer: tuple[np.ndarray, Grid] | None = None


def default_workers() -> int:
    """FFT threads: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def load_sky(sky: SkyConfig, scene: Scene | None = None):
    """The sky model of a config at a scene (procedural skies), its image read and checked
    (negative radiance is taken as 0). Raises io.ImageError."""
    if sky.model == "uniform":
        return UniformSky(np.asarray(sky.radiance, dtype=np.float64))
    if sky.model in sky_models.PROCEDURAL_MODELS:
        clouds = None
        if sky.clouds is not None:
            c = sky.clouds
            clouds = CloudLayer(cover=c.cover, scale=c.scale, altitude=c.altitude,
                                wind=np.asarray(c.wind), thickness=c.thickness, seed=c.seed)
        return _clear_sky(sky, scene.sun, moon=scene.moon, clouds=clouds, time=scene.time)
    return _load_hdri(sky)


def _clear_sky(sky: SkyConfig, sun: sky_models.SunDisc, **state) -> sky_models.ProceduralSky:
    """The procedural sky of a config with ``sun``; ``state``: moon, clouds, time."""
    return sky_models.ProceduralSky(turbidity=sky.turbidity, sun=sun, skylight=sky.skylight, shape=sky.model,
                                    cie_type=sky.cie_type, altitude=sky.site.elevation if sky.site else 0.0,
                                    **state)


@functools.lru_cache(maxsize=4)
def _load_hdri(sky: SkyConfig) -> EquirectSky:
    """An HDRI sky read, checked and its sun cut out once per process (the plan needs its sun,
    every frame its image)."""
    image = io.read_image(sky.hdri)
    if image.shape[2] < 3:
        image = np.repeat(image[..., :1], 3, axis=2)
    image = image[..., :3]
    if not np.all(np.isfinite(image)):
        raise io.ImageError(sky.hdri, "the sky image holds NaN or infinite values")
    if image.max() > MAX_RADIANCE:
        raise io.ImageError(sky.hdri, f"radiance {image.max():.3g} is above the most, {MAX_RADIANCE:g}")
    return sky_models.cut_sun(EquirectSky(np.maximum(image, 0.0), sky.rotation))


def load_mask(layer: CanopyLayer, frame: int = 0) -> np.ndarray:
    """Transmittance (rows, cols) of a layer's mask image at ``frame`` of its sequence.
    Raises io.ImageError."""
    path = layer.mask[frame % len(layer.mask)]
    image = io.read_image(path)
    try:
        return canopy.transmittance_from_image(image)
    except ValueError as exc:
        raise io.ImageError(path, str(exc)) from None


@dataclass(frozen=True)
class Scene:
    """The sky's state at one output frame.

    frame : output frame index; time : film time frame / fps [s]; when : UTC time (site and
    time configs) or None; sun, moon : their discs (procedural skies) or None.
    """

    frame: int
    time: float
    when: datetime | None
    sun: sky_models.SunDisc | None
    moon: sky_models.MoonDisc | None


def scene_at(config: Config, frame: int) -> Scene:
    """Where the sun and moon are at output ``frame``: from the ephemeris for a site and time
    span (spread evenly over the frames), or from the explicit angles, the moon sliding from
    ``offset_start`` to ``offset_end``."""
    sky, frames = config.sky, config.animation.frames
    fraction = frame / (frames - 1) if frames > 1 else 0.0
    time = frame / config.animation.fps
    if sky.model == "hdri":
        return Scene(frame, time, None, _load_hdri(sky).sun, None)
    if sky.model not in sky_models.PROCEDURAL_MODELS:
        return Scene(frame, time, None, None, None)
    if sky.site is not None:
        site = sky.site
        when = site.start + (site.end - site.start) * fraction
        sun, moon = ephemeris.sun_and_moon(
            ephemeris.Site(site.latitude, site.longitude, site.elevation), when)
        return Scene(frame, time, when,
                     sky_models.SunDisc(sun.azimuth, sun.elevation, sun.angular_radius),
                     sky_models.MoonDisc(moon.azimuth, moon.elevation, moon.angular_radius))
    s = sky.sun
    sun = sky_models.SunDisc(s.azimuth, s.elevation, s.radius)
    moon = None
    if sky.moon is not None:
        m = sky.moon
        dx, dy = (a + (b - a) * fraction for a, b in zip(m.offset_start, m.offset_end))
        azimuth, elevation = _offset_direction(s.azimuth, s.elevation, dx, dy)
        moon = sky_models.MoonDisc(azimuth, elevation, m.radius)
    return Scene(frame, time, None, sun, moon)


def _offset_direction(azimuth, elevation, dx, dy):
    """The direction at gnomonic offset (dx to the right, dy up) [rad] from (azimuth,
    elevation) [rad]: the inverse of ``ephemeris.moon_offset_from_sun``."""
    a, h = azimuth, elevation
    s = np.array([np.cos(h) * np.sin(a), np.cos(h) * np.cos(a), np.sin(h)])
    e_az = np.array([np.cos(a), -np.sin(a), 0.0])
    e_el = np.array([-np.sin(h) * np.sin(a), -np.sin(h) * np.cos(a), np.cos(h)])
    w = s + dx * e_az + dy * e_el
    w /= np.linalg.norm(w)
    return float(np.arctan2(w[0], w[1]) % (2 * np.pi)), float(np.arcsin(np.clip(w[2], -1, 1)))


@dataclass(frozen=True)
class LayerPlan:
    """One canopy plane's correlation plans, fixed for a whole run.

    height [m]; canopy : its coarse mask Grid on the window's lattice [m]; coarse : the
    IsolatedPlan or PeriodicPlan; sun : the SunPlan of the fine sun window, or None.
    """

    height: float
    canopy: Grid
    coarse: shadow.IsolatedPlan | shadow.PeriodicPlan
    sun: shadow.SunPlan | None


@dataclass(frozen=True)
class RunPlan:
    """Everything about the rasters that does not change from frame to frame.

    window : the coarse ground Grid (sky light) [m]; sun_window : the fine ground Grid of the
    sun, or None without a sun kernel [m]; projection : the sky-plane point of the sun the
    leaves are projected along (Max 1991, Fig. 1) [tan]; layers : per canopy plane;
    camera : the resolved camera; auto : the config keys the plan placed itself (of
    ``ground.window``, ``ground.sun_window``, ``camera``); shadow : (x_min, y_min, x_max, y_max)
    of where the canopy's shadow falls over the animation [m], None for a periodic forest;
    exposures : per frame, its exposure with ``camera.exposure: auto`` (``with_exposures``), or
    None: a frame then meters the frames its exposure remembers [m^2/kcd].
    """

    window: Grid
    sun_window: Grid | None
    projection: tuple[float, float]
    layers: tuple[LayerPlan, ...]
    camera: camera.Camera | None = None
    auto: tuple[str, ...] = ()
    shadow: tuple[float, float, float, float] | None = None
    exposures: tuple[float | None, ...] | None = None


def check_inputs(config: Config) -> RunPlan:
    """Read every input file of a config and check it (masks, HDRI, albedo image, foreground
    passes and their size), then plan the run: what a run would stumble on, found before any
    work starts. Raises io.ImageError naming the file."""
    for layer in config.canopy.layers:
        for frame in range(len(layer.mask)):
            load_mask(layer, frame)
    if config.sky.model == "hdri":
        _load_hdri(config.sky)
    if isinstance(config.ground.albedo, Path):
        image = albedo_mipmap(config.ground).level(0)
        if not np.all(np.isfinite(image)) or image.min() < 0:
            raise io.ImageError(config.ground.albedo, "albedo must be finite and not negative")
    plan = plan_run(config)
    if config.foreground.model == "passes":
        for cycle_frame in range(config.canopy.cycle):
            _imported_passes(config, plan, cycle_frame)
    return plan


def plan_run(config: Config) -> RunPlan:
    """The grids and correlation plans of a run, from the config alone (an HDRI sky is read
    for its sun; no mask image is read). What the config leaves out of ``ground.window``,
    ``ground.sun_window`` and ``camera`` is placed from the canopy and the sun's path over the
    animation (``frame_scene``)."""
    scenes = [scene_at(config, f) for f in range(config.animation.frames)]
    has_sun = scenes[0].sun is not None
    projection = (0.0, 0.0)
    if has_sun:
        middle = scenes[len(scenes) // 2].sun
        projection = tuple(float(v) for v in sky_plane_from_direction(
            middle.azimuth, np.pi / 2 - middle.elevation))
    heights = [layer.height for layer in config.canopy.layers]
    framing = frame_scene(config, scenes, projection)
    window = Grid.from_window(framing.window, config.ground.pixel)
    sun_window = (_sun_window(config, scenes, min(heights), framing.sun_window or framing.window)
                  if has_sun else None)
    layers = _plan_layers(config, scenes, window, sun_window, projection)
    if "ground.sun_window" in framing.auto and config.ground.sun_pixel is None:
        # the sun's path over the animation widens the fine mask: keep it within AUTO_SUN_MASK
        cells = max(np.prod(lp.sun.mask.shape) for lp in layers)
        if cells > AUTO_SUN_MASK:
            sun_window = Grid.from_window(framing.sun_window, sun_window.pixel * np.sqrt(cells / AUTO_SUN_MASK))
            layers = _plan_layers(config, scenes, window, sun_window, projection)
    plan = RunPlan(window, sun_window, projection, tuple(layers), framing.camera, framing.auto,
                   framing.shadow)
    _check_sizes(config, plan)
    return plan


def _plan_layers(config: Config, scenes, window: Grid, sun_window: Grid | None, projection):
    """Each canopy plane's LayerPlan: its mask grid, coarse plan and fine sun plan."""
    has_sun = sun_window is not None
    layers = []
    for layer in config.canopy.layers:
        grid = _canopy_grid(config, layer, window, projection)
        if config.canopy.layout == "isolated":
            coarse = shadow.plan_isolated(window, grid, height=layer.height, alpha=config.sky.alpha)
        else:
            coarse = shadow.plan_periodic(window, grid, height=layer.height, alpha=config.sky.alpha)
        sun = None
        if has_sun:
            q = sun_window.pixel / layer.height
            centres = [sky_plane_from_direction(sc.sun.azimuth, np.pi / 2 - sc.sun.elevation)
                       for sc in scenes]
            reach = max(_sun_reach(sc.sun) for sc in scenes)
            lo, hi = shadow.sun_offset_range(np.array(centres), reach=reach, q=q)
            sun = shadow.plan_sun(sun_window, offset_lo=lo, offset_hi=hi)
        layers.append(LayerPlan(layer.height, grid, coarse, sun))
    return layers


# ---------------------------------------------------------------------------------------------
# Framing: the ground windows and the camera placed from the canopy and the sun's path, so that
# any place and time frames the canopy's dappled shadow (docs/method.md, "Framing").
# ---------------------------------------------------------------------------------------------

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
    """The resolved ground windows [m] (x_min, y_min, x_max, y_max; sun_window None: the
    window), the camera, which of them were placed automatically, and where the shadow falls
    [m] (None: a periodic forest, shadow everywhere)."""

    window: tuple[float, float, float, float]
    sun_window: tuple[float, float, float, float] | None
    camera: camera.Camera
    auto: tuple[str, ...]
    shadow: tuple[float, float, float, float] | None


def canopy_extent(config: Config, projection) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) [m] of every canopy plane: the grove's leaves projected
    along the sun (``projection`` [tan]) onto each plane over the flutter cycle, or the mask
    images' areas."""
    boxes = []
    for layer in config.canopy.layers:
        if config.canopy.trees is None or config.canopy.layout == "periodic":
            (cx, cy), (w, h) = layer.center, layer.size
            boxes.append((cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2))
        else:
            grove, flutter = _grove(config.canopy)
            boxes.append(tuple(float(v) for v in canopy.grove_bounds(
                grove, flutter, sun=np.array(projection), plane_height=layer.height)))
    return _union(boxes)


def crown_centre(config: Config) -> np.ndarray:
    """(x, y, z) [m]: the mean of the grove's leaf stems, or of the mask planes' centres at
    their heights. Its shadow, not the canopy's bounding box's, is where the leaves' shade is:
    a low sun throws the trunks' shadows far longer than the crowns'."""
    if config.canopy.trees is None or config.canopy.layout == "periodic":
        return np.mean([(*layer.center, layer.height) for layer in config.canopy.layers], axis=0)
    grove, _ = _grove(config.canopy)
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


def dappled_point(config: Config, s, transmittance: float = DAPPLE_TRANSMITTANCE) -> np.ndarray:
    """(x, y) [m] on the ground where the sun, at sky-plane point ``s`` [tan], gets through the
    grove's leaves in about ``transmittance`` [1]: each leaf's shadow (its ellipse's area
    pi |u| |v| times |n . w| / w_z along the sun w) is summed on a map of DAPPLE_CELL cells,
    averaged over 1 m, and taken as the optical depth of leaves placed at random,
    T = exp(-area per area); of the points nearest that T, the one nearest the shadow of the
    leaves' centre. A dense crown under a low sun lets light through only near its rim. Mask
    images and periodic forests: the shadow of the planes' centre."""
    centre = crown_centre(config)
    middle = centre[:2] - centre[2] * np.asarray(s)
    if config.canopy.trees is None or config.canopy.layout == "periodic":
        return middle
    from scipy.ndimage import uniform_filter

    grove, _ = _grove(config.canopy)
    leaves = grove.leaves
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


def _union(boxes):
    boxes = np.array(boxes, dtype=np.float64)
    return (*boxes[:, :2].min(axis=0), *boxes[:, 2:].max(axis=0))


def _grow(box, margin):
    return (box[0] - margin, box[1] - margin, box[2] + margin, box[3] + margin)


def _intersect(a, b):
    box = (max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3]))
    return box if box[2] > box[0] and box[3] > box[1] else None


def shadow_extents(config: Config, scenes, projection) -> list:
    """Per frame, (x_min, y_min, x_max, y_max) [m] of the ground the canopy's shadow falls on: a
    plane point c at height h shades c - h s along the sun's sky-plane point s [tan], so the
    shadow lies h cot(elevation) from the canopy, towards the anti-solar azimuth."""
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


def leaf_shadow_extents(config: Config, scenes, projection) -> list:
    """Per frame, (x_min, y_min, x_max, y_max) [m] of the leaves' shadows alone (every 16th
    leaf's centre, at its own height, along the frame's sun): a low sun's trunk shadow reaches
    far beyond them. Mask images: ``shadow_extents``."""
    if config.canopy.trees is None or config.canopy.layout == "periodic":
        return shadow_extents(config, scenes, projection)
    grove, _ = _grove(config.canopy)
    centres = grove.leaves.center[::16]
    boxes = []
    for scene in scenes:
        s = np.array(sky_plane_from_direction(scene.sun.azimuth, np.pi / 2 - scene.sun.elevation))
        shade = centres[:, :2] - centres[:, 2:3] * s
        boxes.append((*shade.min(axis=0), *shade.max(axis=0)))
    return boxes


def frame_scene(config: Config, scenes, projection) -> Framing:
    """The windows and the camera of a run, each from the config where it gives them, else
    placed (docs/method.md, "Framing"):

    - ``ground.window``: the canopy and its shadow over every frame, grown by WINDOW_MARGIN
      canopy heights (an isolated canopy); one tile (a periodic forest).
    - ``camera``: at eye height, looking CAMERA_PITCH (ECLIPSE_PITCH when the moon cuts the
      sun above LOW_SUN) down at the middle frame's shadow of the leaves' centre (``crown_centre``), facing CAMERA_TURN round
      from the sun's azimuth; a given position looks there, a given look_at is seen from there.
    - ``ground.sun_window``: the ground the camera sees of the shadow (with a pinhole image's
      length to spare), cut at the distance where it would pass AUTO_SUN_PIXELS fine pixels;
      the window when a window is given but no sun window.
    """
    ground, c = config.ground, config.camera
    heights = [layer.height for layer in config.canopy.layers]
    periodic = config.canopy.layout == "periodic"
    auto = []
    extent = canopy_extent(config, projection)
    shadows = shadow_extents(config, scenes, projection)
    shadow_box = None if periodic else _union(shadows)
    window = ground.window
    if window is None:
        auto.append("ground.window")
        window = extent if periodic else _grow(_union([extent, shadow_box]), WINDOW_MARGIN * max(heights))
        if not periodic:
            _check_auto_pixels(config, "ground.window", window, ground.pixel, MAX_GROUND_PIXELS, "ground.pixel")
            if config.canopy.trees is None:  # an image canopy's transform: window and canopy
                grown = _grow(window, max(max(layer.size) for layer in config.canopy.layers) / 2)
                _check_auto_pixels(config, "ground.window", grown, ground.pixel, MAX_FFT_CELLS, "ground.pixel")
    # the camera's target: where the middle frame's shade is dappled
    sun = scenes[len(scenes) // 2].sun
    s = np.array(sky_plane_from_direction(sun.azimuth, np.pi / 2 - sun.elevation)) if sun else np.zeros(2)
    deep = sun is not None and _eclipsed(scenes) and sun.elevation >= np.radians(LOW_SUN)
    target = dappled_point(config, s, ECLIPSE_TRANSMITTANCE if deep else DAPPLE_TRANSMITTANCE)
    if ground.sun_window is not None and c.position is None and c.look_at is None:
        sw = ground.sun_window
        target = np.array([(sw[0] + sw[2]) / 2, (sw[1] + sw[3]) / 2])
    view = _place_camera(config, target, s, auto, ECLIPSE_PITCH if deep else CAMERA_PITCH)
    sun_window = ground.sun_window
    if sun_window is None and sun is not None:
        if ground.window is not None:
            sun_window = ground.window
        else:
            auto.append("ground.sun_window")
            sun_window = _seen_sun_window(config, scenes, view, shadow_box, window)
    return Framing(tuple(float(v) for v in window),
                   None if sun_window is None else tuple(float(v) for v in sun_window),
                   view, tuple(auto), shadow_box)


def _check_auto_pixels(config, key, window, pixel, most, knob):
    cells = ((window[2] - window[0]) / pixel) * ((window[3] - window[1]) / pixel)
    if cells > most:
        raise ConfigError(f"{config.path}: {key}", f"the automatic window {[round(v, 2) for v in window]} would be "
                          f"{cells:.3g} pixels; the most is {most:.3g}: give {key} or raise {knob}")


def _eclipsed(scenes) -> bool:
    """Whether the moon cuts the sun in some frame."""
    for scene in scenes:
        if scene.sun is None or scene.moon is None:
            continue
        a = sky_models._unit(scene.sun.azimuth, scene.sun.elevation)
        b = sky_models._unit(scene.moon.azimuth, scene.moon.elevation)
        if np.arccos(np.clip(a @ b, -1, 1)) < scene.sun.angular_radius + scene.moon.angular_radius:
            return True
    return False


def _place_camera(config: Config, target, s, auto, pitch_down: float) -> camera.Camera:
    """The config's camera with what it leaves out placed to look at ``target`` [m], by default
    ``pitch_down`` [deg] below the horizon."""
    c = config.camera
    width, rows = c.resolution
    if c.position is not None and (c.yaw is not None or c.look_at is not None):
        if c.yaw is not None:
            return camera.Camera(tuple(c.position), c.yaw, c.pitch, c.fov, width, rows)
        return camera.Camera.look_at(c.position, c.look_at, vertical_fov=c.fov, width=width, height=rows)
    auto.append("camera")
    if c.position is not None:
        return camera.Camera.look_at(c.position, (*target, 0.0), vertical_fov=c.fov, width=width, height=rows)
    if c.look_at is not None:
        target = np.array(c.look_at[:2])
    yaw = c.yaw
    if yaw is None:
        sun_azimuth = float(np.arctan2(s[0], s[1])) if np.any(s) else np.pi
        yaw = (sun_azimuth - np.radians(CAMERA_TURN)) % (2 * np.pi)
    pitch = c.pitch if c.pitch is not None else -np.radians(pitch_down)
    back = CAMERA_HEIGHT / np.tan(-pitch) if pitch < -np.radians(1.0) else 2.0 * max(
        layer.height for layer in config.canopy.layers)
    position = (*(np.asarray(target) - back * np.array([np.sin(yaw), np.cos(yaw)])), CAMERA_HEIGHT)
    if c.look_at is not None:
        return camera.Camera.look_at(position, c.look_at, vertical_fov=c.fov, width=width, height=rows)
    return camera.Camera(tuple(float(v) for v in position), float(yaw), float(pitch), c.fov, width, rows)


def seen_ground(view: camera.Camera, samples: int = AUTO_VIEW_SAMPLES):
    """Ground points (n, 2) [m] and their distances (n,) [m] of a grid of rays over the image
    that meet the ground."""
    u, v = np.meshgrid(np.linspace(0, view.width, samples), np.linspace(0, view.height, samples))
    rays = camera.image_rays(view, u, v).reshape(-1, 3)
    down = rays[:, 2] < -1e-9
    t = -view.position[2] / rays[down, 2]
    points = np.asarray(view.position[:2]) + t[:, None] * rays[down, :2]
    return points, t * np.linalg.norm(rays[down], axis=1)


def _seen_sun_window(config: Config, scenes, view, shadow_box, window):
    """The ground the camera sees of the shadow (grown by a pinhole image's length), within the
    window, as near as AUTO_SUN_PIXELS fine pixels allow; if it sees none of the shadow, what
    it sees of the window. [m]"""
    heights = [layer.height for layer in config.canopy.layers]
    radius = min(sc.sun.angular_radius for sc in scenes)
    lowest = min(sc.sun.elevation for sc in scenes)
    pixel = config.ground.sun_pixel or min(heights) * 2 * np.tan(radius) / config.render.sun_cells
    image = 2 * max(heights) * np.tan(radius) / np.sin(lowest)  # a pinhole image's length [m]
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


def _pixels(box, pixel) -> float:
    return (box[2] - box[0]) * (box[3] - box[1]) / pixel**2


def framing_warnings(config: Config, plan: RunPlan) -> list[str]:
    """One-line warnings of a plan whose picture would show no dappled shadow, or a false one:
    the camera sees none of the sun window; the sun is below the canopy's reach, the sky square
    (``sky.alpha``), in some frames, so that beyond the sun window nothing shades it; the
    leaves' shadow falls outside the sun window in some frames."""
    warnings = []
    fine = plan.sun_window or plan.window
    x0, y0, x1, y1 = fine.extent
    key = "ground.sun_window" if plan.sun_window is not None else "ground.window"
    points, _ = seen_ground(plan.camera)
    seen = ((points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1))
    if not seen.any():
        warnings.append(f"the camera sees none of {key} [{x0:.2f}, {y0:.2f}, {x1:.2f}, {y1:.2f}]: "
                        f"its frames will show no sun flecks (leave camera out to place it)")
    scenes = [scene_at(config, f) for f in range(config.animation.frames)]
    reach = np.pi / 2 - config.sky.alpha  # the lowest sun the sky square holds [rad]
    low = [f for f, scene in enumerate(scenes) if scene.sun is not None and scene.sun.elevation < reach]
    if low and plan.sun_window is not None:
        warnings.append(f"the sun is below the sky square (sky.alpha {np.degrees(config.sky.alpha):g} "
                        f"degrees reaches down to {np.degrees(reach):g} degrees elevation) in "
                        f"{len(low)} of {len(scenes)} frames ({_ranges(low)}): beyond {key} its "
                        f"light is taken as unshadowed there; raise sky.alpha")
    if config.canopy.layout == "isolated" and plan.sun_window is not None:
        boxes = leaf_shadow_extents(config, scenes, plan.projection)
        missed = [f for f, box in enumerate(boxes) if _intersect(box, fine.extent) is None]
        if missed:
            elevations = [np.degrees(scenes[f].sun.elevation) for f in missed]
            warnings.append(f"the leaves' shadow falls outside {key} in {len(missed)} of "
                            f"{len(boxes)} frames ({_ranges(missed)}; the sun at "
                            f"{min(elevations):.1f} to {max(elevations):.1f} degrees): the canopy "
                            f"does not reach the window along the sun there")
    return warnings


def _ranges(frames) -> str:
    parts, start = [], frames[0]
    for a, b in zip(frames, frames[1:] + [None]):
        if b != a + 1:
            parts.append(f"{start}" if start == a else f"{start}-{a}")
            start = b
    return ",".join(parts)


EXPOSURE_MEMORY = 14.0
"""Auto exposure forgets the light of frames more than this many time constants back (their
weight is exp(-14) < 1e-6): a frame meters only the frames just before it. [1]"""


def exposure_frames(config: Config, frame: int) -> range:
    """The frames whose light the auto exposure of ``frame`` remembers."""
    a = config.camera.auto_exposure
    memory = int(np.ceil(EXPOSURE_MEMORY * a.time_constant * config.animation.fps))
    return range(max(0, frame - memory), frame + 1)


def auto_exposures(config: Config, plan: RunPlan, frames=None) -> dict[int, float]:
    """The exposure of ``frames`` (default: all) with ``camera.exposure: auto`` [m^2/kcd]: each
    frame's meter reading is the open ground's light (``meter``), followed through
    ``composite.auto_exposure``'s first-order lag and limits from the first frame it remembers
    (``exposure_frames``), so a frame's exposure is the same whichever frames are rendered."""
    light = reference_lighting(config, plan)
    frames = range(config.animation.frames) if frames is None else frames
    windows = {frame: exposure_frames(config, frame) for frame in frames}
    readings = {f: meter(config, scene_at(config, f), light) for f in sorted(set().union(*windows.values()))}
    a = config.camera.auto_exposure
    return {frame: float(composite.auto_exposure(
                [readings[f] for f in window], reference=light.unshadowed,
                frame_time=1.0 / config.animation.fps, time_constant=a.time_constant,
                limits=a.limits, stops=config.camera.exposure)[-1])
            for frame, window in windows.items()}


def with_exposures(config: Config, plan: RunPlan, frames=None) -> RunPlan:
    """The plan with the auto exposure of ``frames`` (default: all; the others None), metered
    once for a whole run."""
    if config.camera.auto_exposure is None:
        return plan
    exposures = auto_exposures(config, plan, frames)
    return replace(plan, exposures=tuple(exposures.get(f) for f in range(config.animation.frames)))


def meter(config: Config, scene: Scene, light: Lighting) -> np.ndarray:
    """What an incident-light meter on the open ground reads at a frame (3,): the sky's
    horizontal irradiance now (clouds and the moon dim it) plus the clear sun's times S.
    [klx]"""
    sky = load_sky(config.sky, scene)
    if light.sun_direction is None or not hasattr(sky, "sky_irradiance"):
        return light.unshadowed
    sun = sky.total_sun_irradiance() if hasattr(sky, "total_sun_irradiance") else (
        light.sun_irradiance * light.sun_direction[2])
    return np.asarray(sky.sky_irradiance) + float(sky.sun_fraction()) * np.asarray(sun)


def _check_sizes(config: Config, plan: RunPlan) -> None:
    """Refuse a plan whose rasters would pass the stated limits (config.MAX_SUN_PIXELS and
    MAX_FFT_CELLS), before any is made, with the memory they would take. Raises ConfigError."""
    def refuse(key, what, cells, most, advice):
        raise ConfigError(f"{config.path}: {key}", f"{what} would be {cells:.3g} cells, about "
                          f"{size_text(cells * BYTES_PER_CELL)}; the most is {most:.3g}: {advice}")

    if plan.sun_window is not None and np.prod(plan.sun_window.shape) > MAX_SUN_PIXELS:
        refuse("ground.sun_window", "the sun's fine raster", np.prod(plan.sun_window.shape),
               MAX_SUN_PIXELS, "shrink ground.sun_window (or ground.window) or raise ground.pixel")
    for layer in plan.layers:
        if np.prod(getattr(layer.coarse, "fft_shape", (0, 0))) > MAX_FFT_CELLS:
            refuse("ground.window", "the sky light's transform", np.prod(layer.coarse.fft_shape),
                   MAX_FFT_CELLS, "shrink ground.window or the canopy, or raise ground.pixel")
        if layer.sun is not None and np.prod(layer.sun.fft_shape) > MAX_FFT_CELLS:
            refuse("ground.sun_window", "the sun's transform (its window and the sun's path)",
                   np.prod(layer.sun.fft_shape), MAX_FFT_CELLS,
                   "shrink ground.sun_window or the time span, or raise ground.sun_pixel")


def _sun_reach(sun) -> float:
    """How far the sun disc reaches from its centre on the sky plane, with 10% to spare. [tan]"""
    zenith = np.pi / 2 - sun.elevation
    return 1.1 * sun.angular_radius / np.cos(min(zenith + sun.angular_radius, np.radians(89.0))) ** 2


def _sun_window(config: Config, scenes, lowest: float, window) -> Grid:
    """The fine ground grid of the sun: ``ground.sun_pixel`` or a pixel small enough for the
    sun disc to span render.sun_cells cells under the lowest canopy plane, unless the window would then
    pass MAX_SUN_PIXELS (the pixel grows) or the pixel would pass ground.pixel."""
    ground = config.ground
    pixel = ground.sun_pixel
    if pixel is None:
        radius = min(sc.sun.angular_radius for sc in scenes)
        pixel = lowest * 2 * np.tan(radius) / config.render.sun_cells
        area = (window[2] - window[0]) * (window[3] - window[1])
        pixel = min(max(pixel, np.sqrt(area / MAX_SUN_PIXELS)), ground.pixel)
    return Grid.from_window(window, pixel)


def _canopy_grid(config: Config, layer: CanopyLayer, window: Grid, projection) -> Grid:
    """The coarse mask grid of a layer on the window's lattice: the image's area, or the
    grove's bounds over the whole flutter cycle, or one periodic tile."""
    periodic = config.canopy.layout == "periodic"
    if config.canopy.trees is None or periodic:
        return canopy.lattice_grid(layer.center, layer.size, window, periodic=periodic)
    grove, flutter = _grove(config.canopy)
    bounds = canopy.grove_bounds(grove, flutter, sun=np.array(projection), plane_height=layer.height)
    size = (bounds[2] - bounds[0], bounds[3] - bounds[1])
    center = ((bounds[0] + bounds[2]) / 2, (bounds[1] + bounds[3]) / 2)
    return canopy.lattice_grid(center, size, window, periodic=False)


@functools.lru_cache(maxsize=4)
def _grove(canopy_config: CanopyConfig):
    """The grove of a canopy config and its flutter, grown once per process."""
    trees, layer0 = canopy_config.trees, canopy_config.layers[0]
    params = canopy.GroveParams(
        count=trees.count, seed=trees.seed, crown_radius=trees.crown_radius,
        leaves_per_tree=trees.leaves_per_tree, leaf_length=trees.leaf_length,
        height=max(layer.height for layer in canopy_config.layers),
        layout=canopy_config.layout,
        tile=layer0.size[0] if canopy_config.layout == "periodic" else None,
        center=layer0.center, spread=trees.spread)
    f = canopy_config.flutter
    return canopy.grow_grove(params), canopy.FlutterParams(cycle=f.cycle, swing=f.swing, twist=f.twist)


def layer_masks(config: Config, plan: RunPlan, layer_index: int, cycle_frame: int):
    """Transmittance masks (coarse, fine or None) of one canopy plane at one cycle frame."""
    layer, lp = config.canopy.layers[layer_index], plan.layers[layer_index]
    periodic = config.canopy.layout == "periodic"
    grids = [lp.canopy] + ([lp.sun.mask] if lp.sun else [])
    if config.canopy.trees is None:
        image = load_mask(layer, cycle_frame)
        masks = [canopy.transmittance_on_grid(image, center=layer.center, size=layer.size,
                                              grid=g, periodic=periodic) for g in grids]
    else:
        grove, flutter = _grove(config.canopy)
        heights = tuple(l.height for l in config.canopy.layers)
        leaf_layer, wood_layer = canopy.layer_index(grove, heights)
        shapes = canopy.project(
            canopy.leaves_at(grove, flutter, cycle_frame), grove.wood,
            sun=np.array(plan.projection), plane_height=layer.height,
        ).subset(leaves=leaf_layer == layer_index, wood=wood_layer == layer_index)
        period = layer.size if periodic else None
        masks = [canopy.rasterize_transmittance(shapes, g, period=period) for g in grids]
    return masks[0], (masks[1] if lp.sun else None)


def cycle_params(config: Config, plan: RunPlan, layer_index: int, cycle_frame: int) -> dict:
    """Everything a layer's cycle products at ``cycle_frame`` depend on (docs/runs.md, "Resume"; docs/method.md, "Cycle products and the cache")."""
    c = config.canopy
    lp = plan.layers[layer_index]
    if c.trees is None:
        source = {"mask": _file_digest(c.layers[layer_index].mask[cycle_frame])}
    else:
        source = {"trees": asdict(c.trees), "flutter": asdict(c.flutter),
                  "heights": [l.height for l in c.layers]}
    layer = c.layers[layer_index]
    return {
        "source": source, "layout": c.layout, "layer": layer_index, "height": layer.height,
        "center": layer.center, "size": layer.size, "frame": cycle_frame,
        "projection": plan.projection, "canopy": asdict(lp.canopy),
        "fft": getattr(lp.coarse, "fft_shape", None),
        "sun": None if lp.sun is None else {"mask": asdict(lp.sun.mask), "fft": lp.sun.fft_shape},
    }


@functools.lru_cache(maxsize=64)
def _file_digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def cycle_item(config: Config, plan: RunPlan, layer_index: int, cycle_frame: int, store: cache.Cache,
               *, workers: int = 1) -> dict:
    """A layer's cached cycle products at ``cycle_frame``, computed on a miss: ``coarse`` (the
    occlusion or tile spectrum), ``mean`` (mean transmittance of a tile), ``fine`` (the fine
    mask spectrum, when there is a sun kernel). Memory-mapped, read-only."""
    lp = plan.layers[layer_index]

    def compute():
        coarse, fine = layer_masks(config, plan, layer_index, cycle_frame)
        if isinstance(lp.coarse, shadow.IsolatedPlan):
            spectrum = shadow.occlusion_spectrum(1.0 - coarse, lp.coarse, workers=workers)
        else:
            spectrum = shadow.transmittance_spectrum(coarse, workers=workers)
        item = {"coarse": spectrum.astype(np.complex64),
                "mean": np.array([coarse.mean(dtype=np.float64)])}
        if fine is not None:
            item["fine"] = shadow.fine_mask_spectrum(fine, lp.sun, workers=workers).astype(np.complex64)
        return item

    return store.get_or_compute("spectra", cycle_params(config, plan, layer_index, cycle_frame), compute)


def cycle_phase(config: Config, plan: RunPlan, store: cache.Cache, *, jobs: int = 1,
                workers: int = 1, progress=None, cycle_frames=None) -> int:
    """Every cycle product for every cycle frame (each layer's spectra, the foreground passes of
    built-in trees), or for ``cycle_frames`` only: those already stored are checked here, the
    missing ones computed in parallel over cycle frames by joblib processes (each with
    ``workers`` FFT threads; the backend is joblib's current one, Dask included).
    ``progress(done, total)`` is called as items finish. Returns the number of items computed."""
    frames = range(config.canopy.cycle) if cycle_frames is None else sorted(set(cycle_frames))
    tasks = [(layer, frame) for frame in frames for layer in range(len(config.canopy.layers))]
    if config.foreground.model == "trees":
        tasks += [(None, frame) for frame in frames]
    missing = [(layer, frame) for layer, frame in tasks if store.get(*_product_key(config, plan, layer, frame)) is None]
    done = len(tasks) - len(missing)
    if progress:
        progress(done, len(tasks))
    if not missing:
        return 0
    computed = 0
    results = joblib.Parallel(n_jobs=min(jobs, len(missing)), return_as="generator")(
        joblib.delayed(_cycle_task)(config, plan, layer, frame, str(store.root), workers)
        for layer, frame in missing)
    for misses in results:
        computed += misses
        done += 1
        if progress:
            progress(done, len(tasks))
    return computed


def _product_key(config, plan, layer, frame):
    """(kind, params) of a cycle product: a layer's spectra, or the foreground (layer None)."""
    if layer is None:
        return "foreground", foreground_params(config, plan, frame)
    return "spectra", cycle_params(config, plan, layer, frame)


FRAME_BYTES_PER_PIXEL = {True: 4.2, False: 7.4}
"""Disk a finished frame takes per pixel, its EXR (half floats: True; float32: False, PIZ) and
its PNG together: 3.9 MB for a 1280 x 720 frame of configs/eclipse.yaml in half floats (its 240
frames took 933 MB, docs/accuracy.md); float32 adds 2 bytes a pixel. About: the compression
follows the picture. [B]"""


def disk_needed(config: Config, plan: RunPlan) -> tuple[float, float]:
    """(frames, cache) [B] a whole run writes: the frames at FRAME_BYTES_PER_PIXEL, and every
    cycle product at its exact size: per layer and cycle frame the coarse spectrum (complex64
    half spectrum of its FFT, or of one tile) and the fine one, per cycle frame the built-in
    trees' passes (sun, sky: 3 float32, alpha and haze: 1)."""
    width, height = config.camera.resolution
    frames = config.animation.frames * width * height * FRAME_BYTES_PER_PIXEL[config.output.half]
    per_frame = 0
    for lp in plan.layers:
        rows, cols = getattr(lp.coarse, "fft_shape", None) or lp.coarse.tile_shape
        per_frame += rows * (cols // 2 + 1) * 8
        if lp.sun is not None:
            rows, cols = lp.sun.fft_shape
            per_frame += rows * (cols // 2 + 1) * 8
    if config.foreground.model == "trees":
        per_frame += 8 * 4 * width * height  # float32 sun and sky (3 each), alpha, haze depth
    return float(frames), float(per_frame * config.canopy.cycle)


CONFIG_INDEX = ".configs"
"""Folder in the cache root where each config that rendered records the keys of its cycle
products (``record_config_items``), so that ``sunshade cache list`` can name them."""


def config_item_keys(config: Config, plan: RunPlan) -> dict[str, tuple[str, int]]:
    """Every cycle product a config's run needs: cache key -> (kind, cycle frame)."""
    keys = {}
    for frame in range(config.canopy.cycle):
        for layer in [*range(len(config.canopy.layers)), *([None] if config.foreground.model == "trees" else [])]:
            kind, params = _product_key(config, plan, layer, frame)
            keys[cache.key_of(kind, params)] = (kind, frame)
    return keys


def record_config_items(config: Config, plan: RunPlan, store: cache.Cache) -> None:
    """Record in the cache which items are this config's (``CONFIG_INDEX``/<hash of its path>
    .json: its name, path and keys, those of earlier versions of it kept), written atomically."""
    folder = store.root / CONFIG_INDEX
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{hashlib.sha256(str(config.path).encode()).hexdigest()[:16]}.json"
    try:
        keys = set(json.loads(path.read_text()).get("keys", []))
    except (OSError, ValueError, AttributeError):
        keys = set()
    keys |= set(config_item_keys(config, plan))
    temporary = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    temporary.write_text(json.dumps({"name": config.output.name, "config": str(config.path),
                                     "cycle": config.canopy.cycle, "keys": sorted(keys)}))
    temporary.replace(path)


def recorded_configs(store: cache.Cache) -> list[dict]:
    """The configs recorded in a cache (``record_config_items``), each {name, config, cycle,
    keys}, by name."""
    found = []
    for path in sorted((store.root / CONFIG_INDEX).glob("*.json")):
        try:
            entry = json.loads(path.read_text())
            found.append({"name": str(entry["name"]), "config": str(entry["config"]),
                          "cycle": int(entry.get("cycle", 0)), "keys": set(entry["keys"])})
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return sorted(found, key=lambda entry: (entry["name"], entry["config"]))


@portable
def _cycle_task(config, plan, layer, frame, root, workers) -> int:
    store = cache.Cache(root)
    if layer is None:
        foreground_item(config, plan, frame, store)
    else:
        cycle_item(config, plan, layer, frame, store, workers=workers)
    return store.misses


def render_ground(config: Config, *, frame: int = 0, store: cache.Cache | None = None,
                  plan: RunPlan | None = None, workers: int | None = None, sky=None,
                  outer: bool = False) -> GroundResult:
    """Ground irradiance at output ``frame``: every canopy layer under the sky (the coarse sky
    raster, and the fine sun kernel where the sky has a sun), layers combined by the paper's
    product rule. Cycle products come from ``store`` (computed on a miss); ``sky`` is the
    frame's sky model, loaded when not given. ``outer``: also the coarse raster of the whole
    window with the sun at the coarse cell (the paper's single scale), where the sun window
    does not cover it: what a camera sees beyond the sun window."""
    workers = workers or default_workers()
    plan = plan or plan_run(config)
    store = store or cache.Cache(cache.cache_dir(None))
    sky = sky or load_sky(config.sky, scene_at(config, frame))
    cycle_frame = frame % config.canopy.cycle
    outer = outer and plan.sun_window is not None and not _covers(plan.sun_window, plan.window)
    grounds, outers, totals, exact = [], [], [], True
    for index, layer_plan in enumerate(plan.layers):
        item = cycle_item(config, plan, index, cycle_frame, store, workers=workers)
        g, total, layer_exact, g_outer = _ground_of_layer(sky, layer_plan, item, plan, workers, outer)
        grounds.append(g)
        outers.append(g_outer)
        totals.append(total)
        exact &= layer_exact
    combined = shadow.combine_layers(grounds, totals[0])
    grid = plan.sun_window or plan.window
    around = None
    if outer:
        around = (np.moveaxis(shadow.combine_layers(outers, totals[0]), 0, -1), plan.window)
    return GroundResult(np.moveaxis(combined, 0, -1), grid, totals[0], exact, around)


def _covers(inner: Grid, outer: Grid) -> bool:
    """Whether ``inner`` reaches over all of ``outer`` (to a hundredth of a pixel)."""
    a, b = inner.extent, outer.extent
    tol = 0.01 * outer.pixel
    return a[0] <= b[0] + tol and a[1] <= b[1] + tol and a[2] >= b[2] - tol and a[3] >= b[3] - tol


def _ground_of_layer(sky, lp: LayerPlan, item, plan: RunPlan, workers, outer=False):
    """(ground raster, unshadowed total, exact, outer raster or None) of one layer: the coarse
    sky light, plus the fine sun kernel on the sun window; with ``outer`` also the coarse
    raster with the sun kernel at the coarse cell."""
    coarse = lp.coarse
    if isinstance(coarse, shadow.IsolatedPlan):
        grid = coarse.sky or shadow.sky_grid((0, 0), (1, 1), plan.window.pixel / lp.height)
        raster = sky.raster(grid)  # a 1 x 1 stand-in when no ray reaches the canopy
        g = shadow.ground_isolated(raster, item["coarse"], coarse, workers=workers)
        exact = coarse.exact
    else:
        raster = sky.raster(coarse.sky, fold_period=coarse.tile_shape)
        g = shadow.ground_periodic(raster, item["coarse"], coarse, float(item["mean"][0]),
                                   workers=workers)
        exact = True
    total = raster.total
    g_outer = None
    if lp.sun is not None:
        if outer:
            g_outer = g + _coarse_sun(sky, lp, item, plan, workers)
        kernel = sky_models.sun_kernel(sky, plan.sun_window.pixel / lp.height)
        g = shadow.resample_bilinear(g, plan.window, plan.sun_window)
        g += shadow.ground_sun(kernel, item["fine"], lp.sun, workers=workers)
        total = total + kernel.weighted.sum(axis=(1, 2), dtype=np.float64)
    return g, total, exact, g_outer


def _coarse_sun(sky, lp: LayerPlan, item, plan: RunPlan, workers):
    """The sun's light through one layer on the coarse window (channels, rows, cols): its
    kernel at the coarse sky cell, correlated like the sky. [klx]"""
    kernel = sky_models.sun_kernel(sky, plan.window.pixel / lp.height)
    coarse = lp.coarse
    if isinstance(coarse, shadow.PeriodicPlan):
        return shadow.ground_periodic(sky_models.SkyRaster(kernel.grid, kernel.weighted, np.zeros(3)),
                                      item["coarse"], coarse, float(item["mean"][0]), workers=workers)
    weighted = np.zeros((3, *coarse.sky.shape), dtype=np.float32) if coarse.sky else np.zeros((3, 1, 1), np.float32)
    if coarse.sky is not None:  # the kernel's cells inside the sky square; the rest reach the ground
        dr, dc = np.subtract(shadow.sky_offset(kernel.grid), shadow.sky_offset(coarse.sky))
        rows, cols = kernel.weighted.shape[1:]
        r0, c0 = max(dr, 0), max(dc, 0)
        r1, c1 = min(dr + rows, coarse.sky.shape[0]), min(dc + cols, coarse.sky.shape[1])
        if r1 > r0 and c1 > c0:
            weighted[:, r0:r1, c0:c1] = kernel.weighted[:, r0 - dr:r1 - dr, c0 - dc:c1 - dc]
    outside = kernel.weighted.sum(axis=(1, 2), dtype=np.float64) - weighted.sum(axis=(1, 2), dtype=np.float64)
    raster = sky_models.SkyRaster(coarse.sky or shadow.sky_grid((0, 0), (1, 1), kernel.grid.pixel),
                                  weighted, outside)
    return shadow.ground_isolated(raster, item["coarse"], coarse, workers=workers)


# ---------------------------------------------------------------------------------------------
# The finished frame: camera, foreground, compositing (Max 1991, Figs. 10 and 13)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Lighting:
    """The clear, uneclipsed light of a run, fixed for all its frames: what the foreground
    passes are lit by and the exposure is set from.

    sun_direction : (3,) unit vector towards the sun, or None; sun_irradiance : (3,) its normal
    irradiance [klx]; sky_irradiance : (3,) horizontal irradiance of the sky alone [klx].
    """

    sun_direction: np.ndarray | None
    sun_irradiance: np.ndarray
    sky_irradiance: np.ndarray

    @property
    def unshadowed(self) -> np.ndarray:
        """Horizontal irradiance of sun and sky together (3,). [klx]"""
        if self.sun_direction is None:
            return self.sky_irradiance
        return self.sky_irradiance + self.sun_irradiance * self.sun_direction[2]


def reference_lighting(config: Config, plan: RunPlan) -> Lighting:
    """The run's Lighting: the clear sky of the config with its sun at the projection
    direction (the middle frame's), no clouds and no moon."""
    s = np.append(plan.projection, 1.0)
    direction = s / np.linalg.norm(s)
    sky = config.sky
    if sky.model == "uniform":
        return Lighting(None, np.zeros(3), np.pi * np.asarray(sky.radiance, dtype=np.float64))
    if sky.model == "hdri":
        hdri = _load_hdri(sky)
        if hdri.sun is None:
            return Lighting(None, np.zeros(3), hdri.total_irradiance())
        return Lighting(direction, np.asarray(hdri.sun_normal_irradiance, dtype=np.float64),
                        hdri.total_irradiance())
    middle = scene_at(config, config.animation.frames // 2).sun
    clear = _clear_sky(sky, middle)
    return Lighting(direction, clear.sun_normal_irradiance, clear.clear_sky_irradiance)


def camera_of(config: Config, plan: RunPlan) -> camera.Camera:
    """The run's camera: the config's, with what it leaves out placed by ``frame_scene``."""
    return plan.camera


def foreground_params(config: Config, plan: RunPlan, cycle_frame: int) -> dict:
    """Everything the built-in trees' passes at ``cycle_frame`` depend on: not the light's
    strength or colour, since they are stored per unit irradiance."""
    c = config.canopy
    return {"trees": asdict(c.trees), "flutter": asdict(c.flutter),
            "heights": [layer.height for layer in c.layers], "layout": c.layout,
            "center": c.layers[0].center, "size": c.layers[0].size,
            "camera": asdict(camera_of(config, plan)),
            "frame": cycle_frame, "sun": None if plan.sun_window is None else plan.projection,
            "haze": config.sky.haze,
            "wood": {"tip": foreground.TIP_TAPER, "piece": foreground.TAPER_PIECE,  # the stems' cones and bark
                     "furrows": foreground.BARK_FURROWS, "contrast": foreground.BARK_CONTRAST,
                     "probe": foreground.STEM_PROBE},
            "copies": None if c.layout != "periodic" else {  # how a periodic forest's tile is copied
                "detail": foreground.LEAF_PIXELS, "reach": foreground.HAZE_REACH,
                "most": foreground.MAX_FOREST_REACH, "stems": foreground.STEM_DETAIL_PIXELS}}


def foreground_item(config: Config, plan: RunPlan, cycle_frame: int, store: cache.Cache) -> dict:
    """The built-in trees' foreground passes at ``cycle_frame``, cached, per unit irradiance:
    ``sun`` the sun's term for a normal irradiance of 1 in each channel, ``sky`` the sky's for
    a horizontal irradiance of 1 (rows, cols, 3) [1/sr], ``alpha`` (rows, cols). The shading is
    linear in each channel's light, so a frame scales them by the run's Lighting.
    Memory-mapped, read-only."""

    def compute():
        grove, flutter = _grove(config.canopy)
        leaves = canopy.leaves_at(grove, flutter, cycle_frame)
        wood, owner = foreground.taper_wood(grove.wood)
        has_sun = plan.sun_window is not None
        sun_point = np.asarray(plan.projection)
        leaf_visibility = wood_visibility = None
        if has_sun:
            leaf_visibility, wood_visibility = foreground.stem_visibility(leaves, wood, sun_point=sun_point)
        view = camera_of(config, plan)
        if config.canopy.layout == "periodic":  # the tile's trees on every tile in view
            layer = config.canopy.layers[0]
            leaves, wood, leaf_index, wood_index = foreground.periodic_copies(
                leaves, wood, view, period=layer.size[0], center=layer.center, haze=config.sky.haze,
                seed=config.canopy.trees.seed, coarse_wood=grove.wood)
            if has_sun:  # a straight capsule gets the mean visibility of its pieces
                pieces = np.bincount(owner, minlength=len(grove.wood.radius))
                capsule = np.bincount(owner, weights=wood_visibility, minlength=len(pieces)) / np.maximum(pieces, 1)
                leaf_visibility = leaf_visibility[leaf_index]
                wood_visibility = np.concatenate([wood_visibility, capsule])[wood_index]
        direction = np.append(sun_point, 1.0) / np.linalg.norm(np.append(sun_point, 1.0))
        passes = foreground.tree_passes(
            leaves, wood, view, sun_direction=direction,
            sun_irradiance=np.ones(3) if has_sun else np.zeros(3), sky_irradiance=np.ones(3),
            leaf_sun_visibility=leaf_visibility, wood_sun_visibility=wood_visibility, haze=config.sky.haze)
        item = {"sun": passes.sun - passes.sky, "sky": passes.sky, "alpha": passes.alpha}
        if passes.haze is not None:
            item["haze"] = passes.haze
        return item

    return store.get_or_compute("foreground", foreground_params(config, plan, cycle_frame), compute)


def foreground_passes(config: Config, plan: RunPlan, cycle_frame: int, store: cache.Cache,
                      light: Lighting | None = None):
    """(F_sun, F_sky, alpha) of the config's foreground at ``cycle_frame`` [kcd/m^2], the
    built-in trees lit by ``light`` (default: the run's reference Lighting); None without one."""
    fg = config.foreground
    if fg.model == "trees":
        light = light or reference_lighting(config, plan)
        item = foreground_item(config, plan, cycle_frame, store)
        # light bounced off the ground reaches the trees' undersides as more diffuse light: half
        # the ground's radiosity, its sun part following S with the sun pass
        bounce = 0.5 * albedo_mipmap(config.ground).mean
        sun_down = light.sun_irradiance * (light.sun_direction[2] if light.sun_direction is not None else 0.0)
        sky = item["sky"] * (light.sky_irradiance * (1.0 + bounce)).astype(np.float32)
        sun = item["sun"] * light.sun_irradiance.astype(np.float32) + item["sky"] * (bounce * sun_down).astype(np.float32)
        return sky + sun, sky, item["alpha"]
    if fg.model == "passes":
        passes = _imported_passes(config, plan, cycle_frame)
        return passes.sun, passes.sky, passes.alpha
    return None


def _imported_passes(config: Config, plan: RunPlan, cycle_frame: int) -> foreground.ForegroundPasses:
    """The imported passes of ``cycle_frame``, read and checked against the camera's size.
    Raises io.ImageError naming the file."""
    fg = config.foreground
    passes = foreground.read_passes(fg.sun[cycle_frame], fg.sky[cycle_frame], fg.alpha[cycle_frame])
    try:
        foreground.check_passes_size(passes, camera_of(config, plan))
    except ValueError as exc:
        raise io.ImageError(fg.sun[cycle_frame], str(exc)) from None
    return passes


@functools.lru_cache(maxsize=4)
def albedo_mipmap(ground: GroundConfig) -> camera.MipMap:
    """The ground's albedo as a periodic MipMap: the procedural grass, or a tileable image
    covering ``albedo_size`` metres a side."""
    if ground.albedo == "grass":
        image, grid = albedos.grass_albedo(period=ground.albedo_size)
    else:
        image = io.read_image(ground.albedo)
        image = np.repeat(image[..., :1], 3, axis=2) if image.shape[2] < 3 else image[..., :3]
        rows, cols = image.shape[:2]
        grid = Grid((0.0, ground.albedo_size), ground.albedo_size / cols, (rows, cols))
    return camera.mipmap(image, grid, outside="periodic", period=(grid.pixel * grid.shape[1], grid.pixel * grid.shape[0]))


@functools.lru_cache(maxsize=4)
def ground_albedo(ground: GroundConfig) -> albedos.StochasticTiling:
    """The ground's albedo as the camera reads it: the tile of ``albedo_mipmap`` laid by
    stochastic tiling (Heitz & Neyret 2018, ``albedo.StochasticTiling``), so that its period
    does not show in rows to the horizon."""
    return albedos.stochastic_tiling(albedo_mipmap(ground))


def irradiance_maps(config: Config, ground: GroundResult) -> tuple[camera.MipMap, ...]:
    """The ground raster as MipMaps for the camera, finest first: beyond the fine raster the
    coarse one with its coarse sun (when there is one), beyond that the open-sky irradiance
    (isolated canopy), or the raster repeated by the canopy tile (a periodic forest, to the
    horizon)."""
    rasters = [(ground.irradiance, ground.grid)] + ([ground.outer] if ground.outer else [])
    if ground.outer:
        rasters[0] = (blend_band(ground.irradiance, ground.grid, *ground.outer), ground.grid)
    maps = [camera.mipmap(r, g, outside="constant", value=np.full(3, np.nan)) for r, g in rasters[:-1]]
    raster, grid = rasters[-1]
    if config.canopy.layout == "periodic":
        period = config.canopy.layers[0].size
        x0, y0, x1, y1 = grid.extent
        if x1 - x0 >= period[0] and y1 - y0 >= period[1]:
            return (*maps, camera.mipmap(raster, grid, outside="periodic", period=period))
        value = raster.reshape(-1, 3).mean(axis=0)
    else:
        value = ground.unshadowed
    return (*maps, camera.mipmap(raster, grid, outside="constant", value=np.asarray(value, dtype=np.float32)))


BLEND_BAND_PIXELS = 8
"""Least width of the band, in coarse ground pixels, inside the sun window's edge over which the
fine sun-resolved ground gives way to the coarse ground (``blend_band``). [pixel]"""

BLEND_BAND_SHARE = (1 / 8, 1 / 4)
"""The band's width as shares of the sun window's shorter side: at least the first (so that at
full scale the change of texture is spread over a good part of the view), at most the second
(so that a small preview window keeps its middle half sun-resolved). [1]"""


def blend_band(fine: np.ndarray, fine_grid: Grid, coarse: np.ndarray, coarse_grid: Grid) -> np.ndarray:
    """The fine ground raster (rows, cols, 3) [klx] with a band inside its edges where it gives
    way to the coarse raster (resampled bilinearly onto the fine grid), so that the camera,
    which reads the fine raster inside the sun window and the coarse one beyond it, shows no
    seam at the window's edge (issue: a rectangle where sharp sun flecks meet blurred ones).

    Width: ``b = clip(max(BLEND_BAND_PIXELS coarse pixels, BLEND_BAND_SHARE[0] s), ...,
    BLEND_BAND_SHARE[1] s)``, s the window's shorter side [m]. Weight of the fine raster at a
    pixel centre at distance d from the nearest edge: ``w = smoothstep(d / b) = t^2 (3 - 2 t)``,
    t = clip(d / b, 0, 1): 0 at the edge (where the coarse raster takes over), 1 from the
    band's inner side on, with zero slope at both ends. Both rasters hold the same light
    (the fine sun kernel and the coarse one have the same sum), so the blend keeps the mean.
    """
    rows, cols = fine_grid.shape
    shorter = min(rows, cols) * fine_grid.pixel
    width = max(BLEND_BAND_PIXELS * coarse_grid.pixel, BLEND_BAND_SHARE[0] * shorter)
    width = min(width, BLEND_BAND_SHARE[1] * shorter)
    across = lambda n: (np.minimum(np.arange(n), n - 1 - np.arange(n)) + 0.5) * fine_grid.pixel  # noqa: E731
    t = np.clip(np.minimum(across(rows)[:, None], across(cols)[None, :]) / width, 0.0, 1.0)
    weight = (t * t * (3.0 - 2.0 * t)).astype(np.float32)[..., None]
    under = np.moveaxis(shadow.resample_bilinear(np.moveaxis(coarse, -1, 0), coarse_grid, fine_grid), 0, -1)
    return (weight * fine + (1.0 - weight) * under).astype(np.float32)


@dataclass(frozen=True)
class FrameResult:
    """radiance : (rows, cols, 3) float32 scene-linear [kcd/m^2]; sun_fraction : S [1];
    scene : the sun and moon; exposure : the run's exposure [m^2/kcd]; ground : the raster;
    balance : the white balance's gains for display (3,) [1]."""

    radiance: np.ndarray
    sun_fraction: float
    scene: Scene
    exposure: float
    ground: GroundResult
    balance: np.ndarray | None = None


def render_frame(config: Config, *, frame: int = 0, store: cache.Cache | None = None,
                 plan: RunPlan | None = None, workers: int | None = None,
                 timings: dict | None = None) -> FrameResult:
    """The finished frame at output ``frame`` (Max 1991, Fig. 10): the ground raster under the
    frame's sky, resampled in perspective with the sky; the haze; the foreground passes of its
    cycle frame blended by S and composited over them. ``timings``, if given, receives the
    seconds of each stage: ``ground``, ``camera`` (resampling ground and sky), ``composite``."""
    workers = workers or default_workers()
    plan = plan or plan_run(config)
    store = store or cache.Cache(cache.cache_dir(None))
    clock = _Stopwatch(timings)
    scene = scene_at(config, frame)
    sky = load_sky(config.sky, scene)
    ground = render_ground(config, frame=frame, store=store, plan=plan, workers=workers, sky=sky, outer=True)
    clock.lap("ground")
    view = camera_of(config, plan)
    background, distance = camera.background(
        view, irradiance=irradiance_maps(config, ground), albedo=ground_albedo(config.ground), sky=sky)
    clock.lap("camera")
    light = reference_lighting(config, plan)
    sun_fraction = float(sky.sun_fraction()) if light.sun_direction is not None else 0.0
    sky_scale = _sky_scale(sky, light)
    atmosphere = None
    if config.sky.haze > 0:
        # Koschmieder (1924): a thing at distance d is seen as T L + (1 - T) L_horizon, T =
        # exp(-d / haze), L_horizon the sky just above the horizon in its column (the sky model
        # holds its own haze), so the far ground meets the sky at the horizon without a line
        rays = camera.pixel_rays(view)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        transmittance = composite.aerial_perspective(
            distance, rays, length=config.sky.haze, sun_direction=np.array([0.0, 0.0, 1.0]),
            sun_irradiance=np.zeros(3), sky_irradiance=np.zeros(3))[0][..., None]
        background = transmittance * background + (1.0 - transmittance) * camera.horizon_sky(view, sky)[None]
    passes = foreground_passes(config, plan, frame % config.canopy.cycle, store, light)
    if passes is not None and config.foreground.model == "trees" and sky_scale > 0:
        veiled = foreground_item(config, plan, frame % config.canopy.cycle, store).get("haze")
        if veiled is not None:  # the haze in front of the trees, as in front of the ground
            veil = veiled[..., None] * (camera.horizon_sky(view, sky)[None] / np.float32(sky_scale))
            passes = (passes[0] + veil, passes[1] + veil, passes[2])
    if passes is None:
        empty = np.zeros_like(background)
        passes = (empty, empty, empty[..., 0])
    radiance = composite.composite_frame(
        background, sun_pass=passes[0], sky_pass=passes[1], alpha=passes[2],
        sun_fraction=sun_fraction, sky_scale=sky_scale, atmosphere=atmosphere)
    if plan.exposures is not None and plan.exposures[frame] is not None:
        exposure = plan.exposures[frame]
    elif config.camera.auto_exposure is not None:
        exposure = auto_exposures(config, plan, [frame])[frame]
    else:
        exposure = composite.exposure_for(light.unshadowed, stops=config.camera.exposure)
    balance = composite.white_balance(
        config.camera.white_balance, sky_irradiance=light.sky_irradiance,
        sun_irradiance=light.sun_irradiance * light.sun_direction[2] if light.sun_direction is not None else np.zeros(3))
    clock.lap("composite")
    return FrameResult(radiance, sun_fraction, scene, exposure, ground, balance)


class _Stopwatch:
    """Adds the seconds since the last lap to ``timings[stage]`` (nothing when timings is None)."""

    def __init__(self, timings: dict | None):
        self.timings, self.last = timings, time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        if self.timings is not None:
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self.last
        self.last = now


def _sky_scale(sky, light: Lighting) -> float:
    """Skylight now over the reference skylight, by luminance: clouds and the moon dim it. [1]"""
    reference = float(light.sky_irradiance @ REC709_LUMINANCE)
    now = getattr(sky, "sky_irradiance", None)
    if now is None or reference <= 0:
        return 1.0
    return float(np.asarray(now) @ REC709_LUMINANCE) / reference
