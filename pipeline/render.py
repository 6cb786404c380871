"""The orchestrator: reads a config's inputs and runs the stages in order.

The cycle phase makes the products of every cycle frame (mask spectra, foreground passes) and
caches them; the frame phase makes a frame: the ground raster (Max 1991, Fig. 7) under that
frame's sky, resampled in the camera with the sky, the foreground blended by S over it.
"""

from __future__ import annotations

import functools
import hashlib
import os
import time
from dataclasses import asdict, dataclass
from datetime import datetime
from pathlib import Path

import joblib
import numpy as np

from . import albedo as albedos
from . import cache, camera, canopy, composite, ephemeris, foreground, io, shadow
from . import sky as sky_models
from .composite import REC709_LUMINANCE
from .config import MAX_RADIANCE, MAX_SUN_PIXELS, CanopyConfig, CanopyLayer, Config, GroundConfig, SkyConfig
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
    if sky.model == "procedural":
        clouds = None
        if sky.clouds is not None:
            c = sky.clouds
            clouds = CloudLayer(cover=c.cover, scale=c.scale, altitude=c.altitude,
                                wind=np.asarray(c.wind), thickness=c.thickness, seed=c.seed)
        return sky_models.ProceduralSky(turbidity=sky.turbidity, sun=scene.sun, moon=scene.moon,
                                        clouds=clouds, time=scene.time, skylight=sky.skylight)
    return _load_hdri(sky)


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
    if sky.model != "procedural":
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
    leaves are projected along (Max 1991, Fig. 1) [tan]; layers : per canopy plane.
    """

    window: Grid
    sun_window: Grid | None
    projection: tuple[float, float]
    layers: tuple[LayerPlan, ...]


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
    for its sun; no mask image is read)."""
    window = Grid.from_window(config.ground.window, config.ground.pixel)
    scenes = [scene_at(config, f) for f in range(config.animation.frames)]
    has_sun = scenes[0].sun is not None
    projection = (0.0, 0.0)
    if has_sun:
        middle = scenes[len(scenes) // 2].sun
        projection = tuple(float(v) for v in sky_plane_from_direction(
            middle.azimuth, np.pi / 2 - middle.elevation))
    heights = [layer.height for layer in config.canopy.layers]
    sun_window = _sun_window(config, scenes, min(heights)) if has_sun else None
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
    return RunPlan(window, sun_window, projection, tuple(layers))


def _sun_reach(sun) -> float:
    """How far the sun disc reaches from its centre on the sky plane, with 10% to spare. [tan]"""
    zenith = np.pi / 2 - sun.elevation
    return 1.1 * sun.angular_radius / np.cos(min(zenith + sun.angular_radius, np.radians(89.0))) ** 2


def _sun_window(config: Config, scenes, lowest: float) -> Grid:
    """The fine ground grid of the sun: ``ground.sun_pixel`` or a pixel small enough for the
    sun disc to span render.sun_cells cells under the lowest canopy plane, unless the window would then
    pass MAX_SUN_PIXELS (the pixel grows) or the pixel would pass ground.pixel."""
    ground = config.ground
    window = ground.sun_window or ground.window
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
    """Everything a layer's cycle products at ``cycle_frame`` depend on (DESIGN.md section 6)."""
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
    clear = sky_models.ProceduralSky(turbidity=sky.turbidity, sun=middle, skylight=sky.skylight)
    return Lighting(direction, clear.sun_normal_irradiance, clear.clear_sky_irradiance)


CAMERA_HEIGHT = 1.7
"""Eye height of a camera placed by default. [m]"""


def camera_of(config: Config, plan: RunPlan) -> camera.Camera:
    """The config's camera, with what it leaves out filled in: by default it stands at eye
    height on the shadow side of the canopy, 35 degrees round from the sun's line and 2.2
    canopy heights from its centre, looking at the middle of the crowns, so that the shadows
    come towards it and the leaves are lit from behind."""
    c = config.camera
    centre = np.array(config.canopy.layers[0].center, dtype=np.float64)
    height = max(layer.height for layer in config.canopy.layers)
    position = c.position
    if position is None:
        sx, sy = plan.projection
        sun_azimuth = np.arctan2(sx, sy) if sx or sy else np.pi
        bearing = sun_azimuth + np.pi - np.radians(35.0)
        distance = 2.2 * height
        position = (*(centre + distance * np.array([np.sin(bearing), np.cos(bearing)])), CAMERA_HEIGHT)
    width, rows = c.resolution
    if c.yaw is not None:
        return camera.Camera(tuple(position), c.yaw, c.pitch, c.fov, width, rows)
    target = c.look_at or (*centre, 0.45 * height)
    return camera.Camera.look_at(position, target, vertical_fov=c.fov, width=width, height=rows)


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
    scene : the sun and moon; exposure : the run's exposure [m^2/kcd]; ground : the raster."""

    radiance: np.ndarray
    sun_fraction: float
    scene: Scene
    exposure: float
    ground: GroundResult


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
    exposure = composite.exposure_for(light.unshadowed, stops=config.camera.exposure)
    clock.lap("composite")
    return FrameResult(radiance, sun_fraction, scene, exposure, ground)


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
