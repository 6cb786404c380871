"""The frame stage: the finished picture of one output frame (Max 1991, Figs. 10 and 13): the
ground raster and the sky resampled in the camera, the haze, the foreground passes blended by
the sun fraction S and composited over them (docs/method.md). Takes the RunPlan and the
cache."""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace

import numpy as np

from . import brdf as reflect
from . import cache, camera, composite
from .colour import REC709_LUMINANCE
from .cycle import foreground_item, tree_box
from .ground import GroundResult, blend_band, render_ground, sky_view_terms
from .inputs import albedo_mipmap, ground_albedo, imported_passes, load_sky
from .lighting import Lighting, auto_exposures, reference_lighting
from .cores import default_workers
from .plan import RunPlan, Scene


def foreground_passes(plan: RunPlan, cycle_frame: int, store: cache.Cache,
                      light: Lighting | None = None):
    """(F_sun, F_sky, alpha, region) of the config's foreground at ``cycle_frame`` [kcd/m^2]:
    the built-in trees lit by ``light`` (default: the run's reference Lighting) over the
    (rows, cols) slices ``region`` of the frame they touch, or imported passes over the whole
    frame; None without a foreground."""
    config = plan.config
    fg = config.foreground
    if fg.model == "trees":
        light = light or reference_lighting(plan)
        item = foreground_item(plan, cycle_frame, store)
        # light bounced off the ground reaches the trees' undersides as more diffuse light: half
        # the ground's radiosity, its sun part following S with the sun pass
        bounce = 0.5 * albedo_mipmap(config.ground).mean
        sun_down = light.sun_irradiance * (light.sun_direction[2] if light.sun_direction is not None else 0.0)
        sky = item["sky"] * (light.sky_irradiance * (1.0 + bounce)).astype(np.float32)
        sun = item["sun"] * light.sun_irradiance.astype(np.float32) + item["sky"] * (bounce * sun_down).astype(np.float32)
        return sky + sun, sky, item["alpha"], tree_box(item)
    if fg.model == "passes":
        passes = imported_passes(fg, plan.camera, cycle_frame)
        return passes.sun, passes.sky, passes.alpha, (slice(None), slice(None))
    return None


def irradiance_maps(plan: RunPlan, ground: GroundResult) -> tuple[camera.MipMap, ...]:
    """The ground raster as MipMaps for the camera, finest first: beyond the fine raster the
    coarse one with its coarse sun (when there is one), beyond that the open-sky irradiance
    (isolated canopy), or the raster repeated by the canopy tile (a periodic forest, to the
    horizon)."""
    rasters = [(ground.irradiance, ground.grid)] + ([ground.outer] if ground.outer else [])
    if ground.outer:
        rasters[0] = (blend_band(ground.irradiance, ground.grid, *ground.outer), ground.grid)
    maps = [camera.mipmap(r, g, outside="constant", value=np.full(3, np.nan)) for r, g in rasters[:-1]]
    raster, grid = rasters[-1]
    if plan.config.canopy.layout == "periodic":
        period = plan.config.canopy.layers[0].size
        x0, y0, x1, y1 = grid.extent
        if x1 - x0 >= period[0] and y1 - y0 >= period[1]:
            return (*maps, camera.mipmap(raster, grid, outside="periodic", period=period))
        value = raster.reshape(-1, 3).mean(axis=0)
    else:
        value = ground.unshadowed
    return (*maps, camera.mipmap(raster, grid, outside="constant", value=np.asarray(value, dtype=np.float32)))


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


def render_frame(plan: RunPlan, frame: int = 0, *, store: cache.Cache | None = None,
                 workers: int | None = None, timings: dict | None = None) -> FrameResult:
    """The finished frame at output ``frame`` (Max 1991, Fig. 10): the ground raster under the
    frame's sky, resampled in perspective with the sky; the haze; the foreground passes of its
    cycle frame blended by S and composited over them. ``timings``, if given, receives the
    seconds of each stage: ``ground``, ``camera`` (resampling ground and sky), ``composite``."""
    config = plan.config
    workers = workers or default_workers()
    store = store or cache.Cache(cache.cache_dir(None))
    clock = _Stopwatch(timings)
    scene = plan.scenes[frame]
    sky = load_sky(config.sky, scene)
    ground = render_ground(plan, frame, store=store, workers=workers, sky=sky, outer=True,
                           sky_parts=config.ground.brdf is not None)
    clock.lap("ground")
    view = plan.camera
    if config.ground.brdf is None:  # lambert: the camera's own path, bytes unchanged
        background, _ = camera.background(
            view, irradiance=irradiance_maps(plan, ground), albedo=ground_albedo(config.ground), sky=sky)
    else:
        background = brdf_background(plan, frame, ground, sky, store, workers)
    clock.lap("camera")
    light = reference_lighting(plan)
    sun_fraction = float(sky.sun_fraction())
    sky_scale = _sky_scale(sky, light)
    if config.sky.haze > 0:
        # Koschmieder (1924): a thing at distance d is seen as T L + (1 - T) L_horizon, T =
        # exp(-d / haze), L_horizon the sky just above the horizon in its column (the sky model
        # holds its own haze), so the far ground meets the sky at the horizon without a line
        _apply_haze(background, *_haze_of_view(view, config.sky.haze), camera.horizon_sky(view, sky))
    else:
        background += np.float32(0.0)  # as _apply_haze: -0 + 0 is +0
    passes = foreground_passes(plan, frame % config.canopy.cycle, store, light)
    if passes is not None and config.foreground.model == "trees" and sky_scale > 0:
        veiled = foreground_item(plan, frame % config.canopy.cycle, store).get("haze")
        if veiled is not None:  # the haze in front of the trees, as in front of the ground
            horizon = camera.horizon_sky(view, sky)[None, passes[3][1]]
            veil = veiled[..., None] * (horizon / np.float32(sky_scale))
            passes = (passes[0] + veil, passes[1] + veil, *passes[2:])
    # outside the passes' region, and everywhere without a foreground, the trees add nothing:
    # B + 0 (above), the same bits composite_frame gives with passes of 0
    radiance = background
    if passes is not None:
        region = passes[3]
        radiance[region] = composite.composite_frame(
            background[region], sun_pass=passes[0], sky_pass=passes[1], alpha=passes[2],
            sun_fraction=sun_fraction, sky_scale=sky_scale)
    if plan.exposures is not None and plan.exposures[frame] is not None:
        exposure = plan.exposures[frame]
    elif config.camera.auto_exposure is not None:
        exposure = auto_exposures(plan, [frame])[frame]
    else:
        exposure = composite.exposure_for(light.unshadowed, stops=config.camera.exposure)
    balance = composite.white_balance(
        config.camera.white_balance, sky_irradiance=light.sky_irradiance,
        sun_irradiance=light.sun_irradiance * light.sun_direction[2] if light.sun_direction is not None else np.zeros(3))
    clock.lap("composite")
    return FrameResult(radiance, sun_fraction, scene, exposure, ground, balance)


def brdf_background(plan: RunPlan, frame: int, ground: GroundResult, sky, store: cache.Cache,
                    workers: int) -> np.ndarray:
    """The background B (height, width, 3) float32 [kcd/m^2] with the ground's reflectance
    ``ground.brdf`` (docs/method.md, "The ground's reflectance"): the sun's term at each
    pixel's own view, the sky's through view bands chosen by ``brdf.choose_bands``."""
    config, view = plan.config, plan.camera
    model = config.ground.brdf
    raster = ground.sky_parts[2][0]  # the first layer's sky raster
    bands = reflect.choose_bands(model, raster, reflect.view_vectors(view))
    terms = sky_view_terms(plan, frame, sky, store, workers, bands.directions(), ground)
    sun = sky.sun_direction if getattr(sky, "sun", None) is not None else None
    sky_only = GroundResult(ground.sky_parts[0], plan.window, ground.sky_parts[1], ground.exact)
    radiance = reflect.ground_radiance(
        view, model, ground_albedo(config.ground), total=irradiance_maps(plan, ground),
        sky_only=irradiance_maps(plan, sky_only), bands=bands,
        band_maps=[irradiance_maps(plan, t) for t in terms], sun_direction=sun, raster=raster)
    return reflect.background(view, radiance, sky)


def compile_loops(plan: RunPlan) -> None:
    """Compile the frame phase's loops (numba) in this process, or load them from numba's
    cache on disk, by resampling a tiny view of the plan's ground and sky with its haze, and by
    making a tiny sky raster and blend band. A render's command calls it while its workers make the cycle products
    (``run.render_run``), so that after an install the workers of the frame phase load the
    loops instead of each compiling them (docs/accuracy.md, "The frame phase"). Nothing is
    kept; any error is left to the frames."""
    try:
        config, view = plan.config, plan.camera
        tiny = camera.Camera(view.position, view.yaw, view.pitch, view.vertical_fov, width=8, height=6)
        empty = np.zeros((*plan.window.shape, 3), dtype=np.float32)
        maps = (camera.mipmap(empty, plan.window, outside="constant", value=np.full(3, np.nan)),
                camera.mipmap(empty, plan.window, outside="constant", value=np.zeros(3)))
        sky = load_sky(config.sky, plan.scenes[0])
        background, _ = camera.background(tiny, irradiance=maps, albedo=ground_albedo(config.ground), sky=sky)
        share = np.ones((tiny.height, tiny.width, 1), dtype=np.float32)
        share.flags.writeable = False  # as _haze_of_view's
        _apply_haze(background, share, share, camera.horizon_sky(tiny, sky))
        sky.raster(replace(plan.window, origin=(0.0, 0.0), pixel=0.01, shape=(2, 2)))  # the ground stage's, tiny
        coarse = replace(plan.window, shape=(2, 2))
        blend_band(np.zeros((4, 4, 3), dtype=np.float32), replace(coarse, pixel=coarse.pixel / 2, shape=(4, 4)),
                   np.zeros((2, 2, 3), dtype=np.float32), coarse)
    except Exception:  # noqa: BLE001 -- only a head start: a frame meets the same error itself
        pass


def _apply_haze(background, transmittance, veil, horizon) -> None:
    """``background`` (rows, cols, 3) float32, in place: T B + (1 - T) L_horizon + 0, T the haze's
    transmittance (rows, cols, 1), L_horizon (cols, 3) the sky at the horizon; compiled
    (``_filter.haze_over``), the float32 operations, in order, of ``B *= T; B += (1 - T) L;
    B + 0`` on arrays (tests/test_frame.py holds it to them)."""
    from . import _filter

    _filter.haze_over(background, transmittance, veil, np.ascontiguousarray(horizon, dtype=np.float32))


@functools.lru_cache(maxsize=2)
def _haze_of_view(view: camera.Camera, haze: float) -> tuple[np.ndarray, np.ndarray]:
    """The haze's transmittance T (height, width, 1) float32 over the ground the camera sees
    (1 at the sky) and 1 - T [1]: they depend on the camera and the haze alone, so the frames of
    a run make them once. Read-only."""
    transmittance = composite.haze_transmittance(camera.ground_distance(view), haze)[..., None]
    veil = 1.0 - transmittance
    for array in (transmittance, veil):
        array.flags.writeable = False
    return transmittance, veil


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
    if reference <= 0:
        return 1.0
    return float(np.asarray(sky.sky_irradiance) @ REC709_LUMINANCE) / reference
