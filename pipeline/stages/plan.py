"""The plan stage: a resolved config made into a RunPlan, every per-run value the later stages
need.

Only this stage (with ``resolve``, ``framing``, ``lighting`` and ``inputs``) reads the config:
the cycle, ground and frame stages take the plan, a frame's scene and the cache
(docs/design.md, "Stages"). The plan's rasters are checked against the compute limits of
``resolve`` before any is made.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from pipeline.camera.pinhole import Camera
from pipeline.canopy import grove as grove_geometry
from pipeline.canopy import masks
from pipeline.config.parse import size_text
from pipeline.config.receivers import ReceiversConfig
from pipeline.config.settings import AutoExposureConfig, CanopyConfig, CanopyLayer, Config, GroundConfig, OutputConfig
from pipeline.config.vocabulary import FOREGROUNDS, PROCEDURAL_MODELS
from pipeline.core import io
from pipeline.core.errors import ConfigError
from pipeline.core.geometry import Grid, sky_plane_from_direction
from pipeline.ground import shadow
from pipeline.receivers.plane import wall_distance, walls_cross
from pipeline.receivers.slope import camera_in_frame, slope_plane
from pipeline.receivers.walls import wall_plane
from pipeline.stages.framing import AUTO_SUN_MASK, Framing, frame_scene
from pipeline.stages.inputs import albedo_mipmap, grove_of, load_mask
from pipeline.stages.resolve import BYTES_PER_CELL, MAX_FFT_CELLS, MAX_GROUND_PIXELS, MAX_SUN_PIXELS
from pipeline.stages.scene import Scene, scene_at, shading_scenes, sky_model, sun_of, sun_shades
from pipeline.stages.slope_framing import frame_slope
from pipeline.stages.wall_framing import WALL_CLEARANCE, camera_wall_problem

if TYPE_CHECKING:
    from pipeline.foreground.models import ForegroundModel
    from pipeline.sky.models import SkyModel
    from pipeline.sky.sun_disc import SunDisc

__all__ = ["LayerPlan", "ExposurePlan", "RunPlan", "check_inputs", "plan_run"]


@dataclass(frozen=True)
class LayerPlan:
    """One canopy plane's correlation plans, fixed for a whole run.

    Attributes
    ----------
    height : float
        The plane's height over the ground [m].
    canopy : Grid
        Its coarse mask grid on the window's lattice [m].
    coarse : shadow.IsolatedPlan or shadow.PeriodicPlan
        The plan of the sky light's correlation on the coarse window.
    sun : shadow.SunPlan or None
        The plan of the fine sun window, or None without a sun kernel.
    """

    height: float
    canopy: Grid
    coarse: shadow.IsolatedPlan | shadow.PeriodicPlan
    sun: shadow.SunPlan | None


@dataclass(frozen=True)
class ExposurePlan:
    """How a run's frames are exposed and shown.

    Attributes
    ----------
    stops : float
        ``camera.exposure``: stops over the default exposure (a white ground under the clear sky
        at 1), or with ``auto`` over the metered light [stops].
    auto : AutoExposureConfig or None
        The auto exposure's time constant [s] and limits [EV], or None for a fixed exposure.
    fps : float
        Frames per second of the animation [1/s].
    white_balance : str
        What the picture shows as white (``vocabulary.WHITE_BALANCES``).
    """

    stops: float
    auto: AutoExposureConfig | None
    fps: float
    white_balance: str


@dataclass(frozen=True)
class RunPlan:
    """Everything a run's later stages need, resolved from the config once: they read these
    fields and never the config (docs/design.md, "Stages").

    Attributes
    ----------
    window : Grid
        The coarse ground grid (sky light) [m].
    sun_window : Grid or None
        The fine ground grid of the sun, or None without a sun kernel [m].
    projection : tuple of float
        The sky-plane point of the sun the leaves are projected along (Max 1991, Fig. 1) [tan].
    layers : tuple of LayerPlan
        Per canopy plane, its grids and correlation plans.
    camera : Camera
        The resolved camera.
    auto : tuple of str
        The config keys the plan placed itself (of ``ground.window``, ``ground.sun_window``,
        ``camera``).
    exposures : tuple or None
        Per frame, its exposure with ``camera.exposure: auto`` (``lighting.with_exposures``), or
        None: a frame then meters the frames its exposure remembers [m^2/kcd].
    scenes : tuple of Scene
        The sky's state at every output frame.
    sky : sky.models.SkyModel
        The sky model (made by ``vocabulary.SKIES``).
    haze : float
        The haze's visibility distance, 0 for none (``sky.haze``) [m].
    canopy : CanopyConfig
        The canopy: its planes' masks or the built-in trees, the layout, the flutter cycle.
    ground : GroundConfig
        The ground's albedo and reflectance.
    foreground : foreground.models.ForegroundModel
        The foreground model (made by ``vocabulary.FOREGROUNDS``).
    exposure : ExposurePlan
        How the frames are exposed and shown.
    output : OutputConfig
        What a run writes (its folder, the passes, half floats, the video, the report).
    source : Path
        The config file (the cache records which items are whose by it).
    follow : tuple or None
        With a camera that follows the shadow (``camera.follow``), per output frame its camera and
        how far its sun window moves with it, (rows, cols) of fine pixels (``at``); None: one
        camera and one sun window for every frame.
    receivers : ReceiversConfig
        The walls besides the level ground (``stages.walls``).
    """

    window: Grid
    sun_window: Grid | None
    projection: tuple[float, float]
    layers: tuple[LayerPlan, ...]
    camera: Camera
    auto: tuple[str, ...]
    exposures: tuple[float | None, ...] | None
    scenes: tuple[Scene, ...]
    sky: SkyModel
    haze: float
    canopy: CanopyConfig
    ground: GroundConfig
    foreground: ForegroundModel
    exposure: ExposurePlan
    output: OutputConfig
    source: Path
    follow: tuple[tuple[Camera, tuple[int, int]], ...] | None = None
    receivers: ReceiversConfig = field(default_factory=ReceiversConfig)

    def at(self, frame: int) -> RunPlan:
        """The plan as one frame sees it: with a following camera, the frame's camera and its sun
        window moved with it by whole fine pixels, the sun's offsets moved back so that the fine
        mask (and the cached spectrum) stays the same (docs/method.md, "Framing").

        Parameters
        ----------
        frame : int
            Output frame index.

        Returns
        -------
        RunPlan
            The frame's plan, without ``follow``; this plan itself when it has none.
        """
        if self.follow is None:
            return self
        view, (dr, dc) = self.follow[frame]
        sun_window, layers = self.sun_window, self.layers
        if sun_window is not None:
            x0, y0 = sun_window.origin
            sun_window = replace(sun_window, origin=(x0 + dc * sun_window.pixel, y0 - dr * sun_window.pixel))
            layers = tuple(lp if lp.sun is None else replace(lp, sun=replace(
                lp.sun, offset_lo=(lp.sun.offset_lo[0] - dr, lp.sun.offset_lo[1] - dc),
                offset_hi=(lp.sun.offset_hi[0] - dr, lp.sun.offset_hi[1] - dc))) for lp in layers)
        return replace(self, camera=view, sun_window=sun_window, layers=layers, follow=None)

    @property
    def frames(self) -> int:
        """The number of output frames of the animation.

        Returns
        -------
        int
            ``len(scenes)`` [1].
        """
        return len(self.scenes)


def check_inputs(config: Config) -> RunPlan:
    """Read every input file of a config and check it, then plan the run.

    The masks, HDRI, albedo image, foreground passes and their size: what a run would stumble on,
    found before any work starts.

    Parameters
    ----------
    config : settings.Config
        The resolved config (``resolve``).

    Returns
    -------
    RunPlan
        The run's plan (``plan_run``).

    Raises
    ------
    io.ImageError
        Naming the file.
    """
    for layer in config.canopy.layers:
        for frame in range(len(layer.mask)):
            load_mask(layer, frame)
    sky_model(config.sky).check()
    if isinstance(config.ground.albedo, Path):
        image = albedo_mipmap(config.ground).level(0)
        if not np.all(np.isfinite(image)) or image.min() < 0:
            raise io.ImageError(config.ground.albedo, "albedo must be finite and not negative")
    plan = plan_run(config)
    plan.foreground.check(plan.camera, config.canopy.cycle)
    if config.canopy.meshes:  # mesh trees read, their shadow inside the masks, their memory (cycle imports plan)
        from pipeline.stages.cycle import check_mesh_trees

        check_mesh_trees(plan)
    return plan


def plan_run(config: Config) -> RunPlan:
    """The grids and correlation plans of a run, from the config alone.

    An HDRI sky is read for its sun; no mask image is read. What the config leaves out of
    ``ground.window``, ``ground.sun_window`` and ``camera`` is placed from the canopy and the sun's
    path over the animation (``frame_scene``).

    Parameters
    ----------
    config : settings.Config
        The config; it must be resolved (``resolve``).

    Returns
    -------
    RunPlan
        Every per-run value the later stages need.

    Raises
    ------
    ValueError
        For a config not resolved (``turbidity: auto`` not looked up).
    ConfigError
        For rasters that would pass the compute limits of ``resolve``.
    """
    if config.sky.model in PROCEDURAL_MODELS and config.sky.turbidity is None:
        raise ValueError("plan_run needs a resolved config (resolve.resolve): turbidity: auto is not looked up")
    scenes = [scene_at(config, f) for f in range(config.animation.frames)]
    shading = shading_scenes(scenes)  # twilight and a sun under SHADOW_FLOOR: no shadow planned
    has_sun = bool(shading)
    projection = (0.0, 0.0)
    if has_sun:
        middle = scenes[len(scenes) // 2]
        if not sun_shades(middle.sun):  # the middle frame's sun is set: the last one that shades
            middle = shading[-1] if shading[-1].frame < len(scenes) // 2 else shading[0]
        sun = sun_of(middle)
        sx, sy = sky_plane_from_direction(sun.azimuth, np.pi / 2 - sun.elevation)
        projection = (float(sx), float(sy))
    heights = [layer.height for layer in config.canopy.layers]
    _check_receivers(config)  # before the framing: a slope's places only what it can draw
    framing = (frame_slope(config, shading or [replace(scenes[0], sun=None)]) if config.receivers.slope is not None
               else frame_scene(config, shading or [replace(scenes[0], sun=None)], projection))
    _check_auto_window(config, framing)
    window = Grid.from_window(framing.window, config.ground.pixel)
    lowest = min(heights) * (np.cos(config.receivers.slope.tilt)  # the crowns' distance along a slope's normal
                             if config.receivers.slope is not None and config.canopy.trees is not None else 1.0)
    sun_window = (_sun_window(config, shading, lowest, framing.sun_window or framing.window)
                  if has_sun else None)
    shifts = _follow_shifts(framing, sun_window, len(scenes))
    layers = _plan_layers(config, shading, window, sun_window, projection, shifts)
    if "ground.sun_window" in framing.auto and config.ground.sun_pixel is None and sun_window is not None:
        # the sun's path over the animation widens the fine mask: keep it within AUTO_SUN_MASK
        cells = max(np.prod(lp.sun.mask.shape) for lp in layers if lp.sun is not None)
        if cells > AUTO_SUN_MASK and framing.sun_window is not None:
            sun_window = Grid.from_window(framing.sun_window, sun_window.pixel * np.sqrt(cells / AUTO_SUN_MASK))
            shifts = _follow_shifts(framing, sun_window, len(scenes))
            layers = _plan_layers(config, shading, window, sun_window, projection, shifts)
    follow = None
    if framing.follow is not None:
        follow = tuple((_nearest(framing.follow, f), shifts[f] if shifts else (0, 0)) for f in range(len(scenes)))
    c = config.camera
    stops = c.exposure + framing.exposure_stops if framing.exposure_stops else c.exposure  # walls: the brightest
    exposure = ExposurePlan(stops, c.auto_exposure, config.animation.fps, c.white_balance)
    from pipeline.sky.models import with_still_sun  # the models are imported on first use (docs/design.md)

    sky = with_still_sun(sky_model(config.sky), [s.sun for s in scenes])  # a still sun's light made once
    plan = RunPlan(window, sun_window, projection, tuple(layers), framing.camera, framing.auto,
                   None, tuple(scenes), sky, config.sky.haze, config.canopy, config.ground,
                   FOREGROUNDS.load(config.foreground.model)(config.foreground), exposure, config.output,
                   config.path, follow, config.receivers)
    _check_sizes(config, plan)
    _check_walls(config, plan)
    _check_slope(config, plan)
    return plan


def _check_receivers(config: Config) -> None:
    """Refuse what the walls cannot be drawn with yet (docs/method.md, "Receivers: walls and slopes")."""
    r = config.receivers
    if r.slope is not None:  # what a slope is not drawn with yet (docs/method.md, "A sloped ground")
        for given, key, what in ((r.walls, "receivers.walls", "walls on a slope are not drawn yet"),
                                 (config.canopy.layout == "periodic", "canopy.layout",
                                  "a slope takes the shade of an isolated canopy: give canopy.layout: isolated"),
                                 (config.output.passes, "output.passes", "the light passes are not made on a slope"),
                                 (config.ground.brdf is not None, "ground.brdf", "a slope is Lambertian: leave "
                                  "ground.brdf out")):
            if given:
                raise ConfigError(config.where(key), what)
    if r.walls and config.canopy.layout == "periodic":
        raise ConfigError(config.where("receivers.walls"), "a wall takes the shade of an isolated canopy; "
                          "give canopy.layout: isolated")
    if r.walls and config.output.passes:
        raise ConfigError(config.where("output.passes"), "the light passes are not made with walls yet; "
                          "give one or the other")


def _check_walls(config: Config, plan: RunPlan) -> None:
    """Refuse walls the method cannot separate from what they meet: one through a tree's trunk, one
    through another, a given camera in a wall or behind one seeing its back (docs/method.md, "Receivers:
    walls and slopes"). Raises ConfigError."""
    walls = config.receivers.walls
    keys = [f"receivers.walls[{i}]" for i in range(len(walls))]
    planes = [wall_plane(w, key) for w, key in zip(walls, keys)]
    trunks = grove_geometry.trunks(grove_of(config.canopy)[0]) if walls and config.canopy.trees else None
    cameras = [plan.camera] + [view for view, _ in plan.follow or ()]  # given, or placed (framing keeps clear)
    placed = " (placed by the plan: give camera.position and camera.look_at)" if "camera" in plan.auto else ""
    for i, (w, key, plane) in enumerate(zip(walls, keys, planes)):
        if trunks is not None:
            inside = np.flatnonzero(wall_distance(plane, trunks.start, trunks.end) < trunks.radius)
            if len(inside):
                x, y = (round(float(v), 2) for v in trunks.start[inside[0], :2])
                raise ConfigError(config.where(f"{key}.foot"), f"wall {w.name!r} stands through the trunk of "
                                  f"the tree at ({x}, {y}) m: move the wall or the trees")
        for other, plane_other, key_other in zip(walls[:i], planes, keys):
            if walls_cross(plane, plane_other, margin=WALL_CLEARANCE):
                raise ConfigError(config.where(key), f"wall {w.name!r} passes through wall {other.name!r} "
                                  f"({key_other}): walls may meet at an edge, not cross")
        for camera in cameras:
            problem = camera_wall_problem(camera, plane)
            if problem == "in":
                raise ConfigError(config.where("camera.position"), f"the camera stands in wall {w.name!r} ({key})"
                                  + placed)
            if problem == "behind":
                raise ConfigError(config.where("camera.position"), f"the camera is behind wall {w.name!r} ({key}) "
                                  "and sees its back, which is not drawn: move it to the side the wall faces" + placed)


def _check_slope(config: Config, plan: RunPlan) -> None:
    """Refuse a camera on a slope that follows the shadow, does not look straight up or down the
    slope or is not above it (docs/method.md, "A sloped ground")."""
    if config.receivers.slope is None:
        return
    if plan.follow is not None or config.camera.follow == "shadow":
        raise ConfigError(config.where("camera.follow"), "a camera on a slope stands still")
    try:
        camera_in_frame(plan.camera, slope_plane(config.receivers.slope))
    except ValueError as exc:
        raise ConfigError(config.where("camera.look_at"), str(exc)) from None


def _nearest(follow: tuple[tuple[int, Camera], ...], frame: int) -> Camera:
    """The camera of the shading frame nearest ``frame`` (a set sun's frames keep the last)."""
    return min(follow, key=lambda item: abs(item[0] - frame))[1]


def _follow_shifts(framing: Framing, sun_window: Grid | None, frames: int) -> list[tuple[int, int]] | None:
    """Per output frame, (rows, cols) of fine pixels the sun window moves with a following camera
    (its ground moves with the camera's foot); None without one."""
    if framing.follow is None or sun_window is None:
        return None
    x, y = framing.camera.position[:2]
    shifts = []
    for f in range(frames):
        px, py = _nearest(framing.follow, f).position[:2]
        shifts.append((int(round(-(py - y) / sun_window.pixel)), int(round((px - x) / sun_window.pixel))))
    return shifts


def _check_auto_window(config: Config, framing: Framing) -> None:
    """Refuse an isolated canopy's automatic ground.window whose raster, or (mask images) whose
    transform with the canopy, would pass the limits. Raises ConfigError."""
    if "ground.window" not in framing.auto or config.canopy.layout == "periodic":
        return
    window, pixel = framing.window, config.ground.pixel
    checks = [(window, MAX_GROUND_PIXELS)]
    if config.canopy.trees is None:  # an image canopy's transform: window and canopy
        half = max(max(layer.size) for layer in config.canopy.layers) / 2
        checks.append(((window[0] - half, window[1] - half, window[2] + half, window[3] + half), MAX_FFT_CELLS))
    for box, most in checks:
        cells = ((box[2] - box[0]) / pixel) * ((box[3] - box[1]) / pixel)
        if cells > most:
            raise ConfigError(f"{config.path}: ground.window", f"the automatic window "
                              f"{[round(v, 2) for v in box]} would be {cells:.3g} pixels; the most is "
                              f"{most:.3g}: give ground.window or raise ground.pixel")


def _plan_layers(config: Config, scenes: list[Scene], window: Grid, sun_window: Grid | None,
                 projection: tuple[float, float], shifts: list[tuple[int, int]] | None = None) -> list[LayerPlan]:
    """Each canopy plane's LayerPlan: its mask grid, coarse plan and fine sun plan."""
    layers = []
    for layer in config.canopy.layers:
        grid = _canopy_grid(config, layer, window, projection)
        coarse: shadow.IsolatedPlan | shadow.PeriodicPlan
        if config.canopy.layout == "isolated":
            coarse = shadow.plan_isolated(window, grid, height=layer.height, alpha=config.sky.alpha)
        else:
            coarse = shadow.plan_periodic(window, grid, height=layer.height, alpha=config.sky.alpha)
        sun = None
        if sun_window is not None:
            q = sun_window.pixel / layer.height
            centres = np.array([sky_plane_from_direction(disc.azimuth, np.pi / 2 - disc.elevation)
                                for disc in map(sun_of, scenes)])
            if shifts is not None:  # a sun window moved (dr, dc) reads the mask as the kernel moved so
                centres = centres + q * np.array([(shifts[sc.frame][1], -shifts[sc.frame][0]) for sc in scenes])
            reach = max(_sun_reach(sun_of(sc)) for sc in scenes)
            lo, hi = shadow.sun_offset_range(np.array(centres), reach=reach, q=q)
            sun = shadow.plan_sun(sun_window, offset_lo=lo, offset_hi=hi)
        layers.append(LayerPlan(layer.height, grid, coarse, sun))
    return layers


# ---------------------------------------------------------------------------------------------
# The limits and the sun's fine window (framing.py places the windows and the camera).

def _check_sizes(config: Config, plan: RunPlan) -> None:
    """Refuse a plan whose rasters would pass the stated limits (resolve.MAX_SUN_PIXELS and
    MAX_FFT_CELLS), before any is made, with the memory they would take. Raises ConfigError."""
    def refuse(key: str, what: str, cells: float | np.integer, most: int, advice: str) -> NoReturn:
        raise ConfigError(f"{config.path}: {key}", f"{what} would be {cells:,.0f} cells, about "
                          f"{size_text(cells * BYTES_PER_CELL)}; the most is {most:,.0f}: {advice}")

    if plan.sun_window is not None and np.prod(plan.sun_window.shape) > MAX_SUN_PIXELS:
        refuse("ground.sun_window", "the sun's fine raster", np.prod(plan.sun_window.shape),
               MAX_SUN_PIXELS, "shrink ground.sun_window (or ground.window) or raise ground.pixel")
    for layer in plan.layers:
        if isinstance(layer.coarse, shadow.IsolatedPlan) and np.prod(layer.coarse.fft_shape) > MAX_FFT_CELLS:
            refuse("ground.window", "the sky light's transform", np.prod(layer.coarse.fft_shape),
                   MAX_FFT_CELLS, "shrink ground.window or the canopy, or raise ground.pixel")
        if layer.sun is not None and np.prod(layer.sun.fft_shape) > MAX_FFT_CELLS:
            refuse("ground.sun_window", "the sun's transform (its window and the sun's path)",
                   np.prod(layer.sun.fft_shape), MAX_FFT_CELLS,
                   "shrink ground.sun_window or the time span, or raise ground.sun_pixel")


def _sun_reach(sun: SunDisc) -> float:
    """How far the sun disc reaches from its centre on the sky plane, with 10% to spare. [tan]"""
    zenith = np.pi / 2 - sun.elevation
    return 1.1 * sun.angular_radius / np.cos(min(zenith + sun.angular_radius, np.radians(89.0))) ** 2


def _sun_window(config: Config, scenes: list[Scene], lowest: float, window: tuple[float, float, float, float]) -> Grid:
    """The fine ground grid of the sun: ``ground.sun_pixel`` or a pixel small enough for the
    sun disc to span render.sun_cells cells under the lowest canopy plane, unless the window would then
    pass MAX_SUN_PIXELS (the pixel grows) or the pixel would pass ground.pixel."""
    ground = config.ground
    pixel = ground.sun_pixel
    if pixel is None:
        radius = min(sun_of(sc).angular_radius for sc in scenes)
        pixel = lowest * 2 * np.tan(radius) / config.render.sun_cells
        area = (window[2] - window[0]) * (window[3] - window[1])
        pixel = min(max(pixel, np.sqrt(area / MAX_SUN_PIXELS)), ground.pixel)
    return Grid.from_window(window, pixel)


def _canopy_grid(config: Config, layer: CanopyLayer, window: Grid, projection: tuple[float, float]) -> Grid:
    """The coarse mask grid of a layer on the window's lattice: the image's area, or the
    grove's bounds over the whole flutter cycle, or one periodic tile."""
    periodic = config.canopy.layout == "periodic"
    if config.canopy.trees is None or periodic:
        return masks.lattice_grid(layer.center, layer.size, window, periodic=periodic)
    grove, flutter = grove_of(config.canopy)
    bounds = grove_geometry.grove_bounds(grove, flutter, sun=np.array(projection), plane_height=layer.height)
    size = (bounds[2] - bounds[0], bounds[3] - bounds[1])
    center = ((bounds[0] + bounds[2]) / 2, (bounds[1] + bounds[3]) / 2)
    return masks.lattice_grid(center, size, window, periodic=False)
