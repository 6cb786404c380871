"""The frame stage: the finished picture of one output frame (Max 1991, Figs. 10 and 13): the
ground raster and the sky resampled in the camera, the haze, the foreground passes blended by
the sun fraction S and composited over them (docs/method.md). Takes the RunPlan and the
cache."""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.cache import store as cache
from pipeline.camera import brdf_view as reflect
from pipeline.camera import composite
from pipeline.camera import pinhole as camera
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.cores import default_workers, loop_threads
from pipeline.foreground.models import ForegroundLayer
from pipeline.ground import brdf_bands
from pipeline.sky import scattering
from pipeline.stages.cycle import foreground_item
from pipeline.stages.ground import GroundResult, blend_band, render_ground, sky_view_terms
from pipeline.stages.inputs import albedo_mipmap, ground_albedo
from pipeline.stages.lighting import Lighting, auto_exposures, reference_lighting
from pipeline.stages.plan import RunPlan
from pipeline.stages.scene import Scene
from pipeline.texture import mipmap as texture

__all__ = ["foreground_layer", "irradiance_maps", "FrameResult", "LUX_PER_KLX", "INCIDENT_METER_C", "ev100",
           "open_ground_light", "render_frame", "light_layers", "brdf_background", "compile_loops"]


def foreground_layer(plan: RunPlan, cycle_frame: int, store: cache.Cache,
                     light: Lighting | None = None) -> ForegroundLayer | None:
    """The foreground of ``cycle_frame`` (``foregrounds.ForegroundLayer``), its cycle product
    fetched once when the model has one: the built-in trees lit by ``light`` (default: the run's
    reference Lighting), or imported passes; None without a foreground.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    cycle_frame : int
        The cycle frame.
    store : cache.Cache
        Where the cycle products are (computed on a miss).
    light : Lighting or None
        The light of the trees [klx].

    Returns
    -------
    ForegroundLayer or None
        Its passes [kcd/m^2], coverage [1], region and haze share [1].
    """
    light = light or reference_lighting(plan)
    item = foreground_item(plan, cycle_frame, store) if plan.foreground.cached else None
    sun_down = light.sun_irradiance * (light.sun_direction[2] if light.sun_direction is not None else 0.0)
    return plan.foreground.layer(cycle_frame, view=plan.camera, item=item, sun_irradiance=light.sun_irradiance,
                                 sky_irradiance=light.sky_irradiance, sun_down=sun_down,
                                 bounce=0.5 * albedo_mipmap(plan.ground).mean)


def irradiance_maps(plan: RunPlan, ground: GroundResult) -> tuple[texture.MipMap, ...]:
    """The ground raster as MipMaps for the camera, finest first.

    Beyond the fine raster the coarse one with its coarse sun (when there is one), beyond that the
    open-sky irradiance (isolated canopy), or the raster repeated by the canopy tile (a periodic
    forest, to the horizon).

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    ground : GroundResult
        The frame's ground, with its ``outer`` raster when there is one.

    Returns
    -------
    tuple of texture.MipMap
        The rasters (rows, cols, channels) [klx], finest first; the fine one blended into the
        coarse one at its edge (``ground.blend_band``).
    """
    rasters = [(ground.irradiance, ground.grid)] + ([ground.outer] if ground.outer else [])
    if ground.outer:
        rasters[0] = (blend_band(ground.irradiance, ground.grid, *ground.outer), ground.grid)
    maps = [texture.mipmap(r, g, outside="constant", value=np.full(3, np.nan)) for r, g in rasters[:-1]]
    raster, grid = rasters[-1]
    if plan.canopy.layout == "periodic":
        period = plan.canopy.layers[0].size
        x0, y0, x1, y1 = grid.extent
        if x1 - x0 >= period[0] and y1 - y0 >= period[1]:
            return (*maps, texture.mipmap(raster, grid, outside="periodic", period=period))
        value = raster.reshape(-1, raster.shape[-1]).mean(axis=0)
    else:
        value = ground.unshadowed
    return (*maps, texture.mipmap(raster, grid, outside="constant", value=np.asarray(value, dtype=np.float32)))


@dataclass(frozen=True)
class FrameResult:
    """One finished output frame.

    Attributes
    ----------
    radiance : ndarray, shape (rows, cols, 3), float32
        Scene-linear radiance [kcd/m^2].
    sun_fraction : float
        S, the share of the sun's disc not covered [1].
    scene : Scene
        The sun and moon.
    exposure : float
        The run's exposure [m^2/kcd].
    ground : GroundResult
        The ground raster.
    balance : ndarray, shape (3,), or None
        The white balance's gains for display [1].
    light : dict or None
        The open ground's light (``open_ground_light``).
    layers : dict
        The light passes asked for, {name: (rows, cols, channels) float32} (``light_layers``),
        empty when none were.
    """

    radiance: np.ndarray
    sun_fraction: float
    scene: Scene
    exposure: float
    ground: GroundResult
    balance: np.ndarray | None
    light: dict | None = None
    layers: dict = field(default_factory=dict)


LUX_PER_KLX = 1000.0
"""Lux in a kilolux. [lx/klx]"""
INCIDENT_METER_C = 250.0
"""The calibration constant C of an incident-light meter with a flat receptor (ISO 2720:1974,
240 to 400 for flat receptors; 250 as commonly used): EV100 = log2(E / 2.5), E in lux. [lx s]"""


def ev100(lux: float) -> float:
    """The exposure value at ISO 100 that an incident-light meter gives for a horizontal illuminance.

    log2(E 100 / C) (``INCIDENT_METER_C``).

    Parameters
    ----------
    lux : float
        Horizontal illuminance E [lx].

    Returns
    -------
    float or None
        EV100 [EV]; None without light.
    """
    return float(np.log2(lux * 100.0 / INCIDENT_METER_C)) if lux > 0 else None


def open_ground_light(sky, exposure: float, balance) -> dict:
    """The light of a frame on open ground, for the run's report and the EXR's attributes.

    Sums by luminance (Rec.709) of the sky model's own irradiances (lighting.meter's reading).

    Parameters
    ----------
    sky : sky.Sky
        The frame's sky.
    exposure : float
        The camera's exposure [m^2/kcd].
    balance : ndarray, shape (3,), or None
        The white balance's display gains [1]; None: 1.

    Returns
    -------
    dict
        ``sun_lux`` the sun's horizontal illuminance now (its clear light times S) and ``sky_lux``
        the sky's (clouds and the moon dim it) [lx, for a procedural sky; an HDRI's or a uniform
        sky's in its own units x 1000]; ``ev100`` what an incident meter reads of the two together
        [EV]; ``camera_ev100`` the light the camera's exposure is set for (pi / exposure [klx], a
        white ground at 1) as EV100 [EV]; ``white_balance`` the display gains (3,) [1].
    """
    sun = float(sky.sun_fraction()) * np.asarray(sky.undimmed_sun_irradiance(), dtype=np.float64)
    sun_lux = float(sun @ REC709_LUMINANCE) * LUX_PER_KLX
    sky_lux = float(np.asarray(sky.sky_irradiance, dtype=np.float64) @ REC709_LUMINANCE) * LUX_PER_KLX
    return {"sun_lux": sun_lux, "sky_lux": sky_lux, "ev100": ev100(sun_lux + sky_lux),
            "camera_ev100": ev100(np.pi / exposure * LUX_PER_KLX) if exposure > 0 else None,
            "white_balance": [float(g) for g in (np.ones(3) if balance is None else balance)]}


def render_frame(plan: RunPlan, frame: int = 0, *, store: cache.Cache | None = None,
                 workers: int | None = None, timings: dict | None = None,
                 passes: tuple[str, ...] | None = None) -> FrameResult:
    """The finished frame at an output frame (Max 1991, Fig. 10).

    The ground raster under the frame's sky, resampled in perspective with the sky; the haze; the
    foreground passes of its cycle frame blended by S and composited over them.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    frame : int
        Output frame index.
    store : cache.Cache or None
        Where the cycle products are (computed on a miss); None: the default cache.
    workers : int or None
        FFT threads, and threads of the compiled loops (``cores.loop_threads``); None:
        ``cores.default_workers``.
    timings : dict or None
        If given, receives the seconds of each stage [s]: ``ground``, ``camera`` (resampling ground
        and sky), ``composite``, and ``passes`` when light passes are made.
    passes : tuple of str or None
        The light passes to make (``vocabulary.PASSES``; None: the config's ``output.passes``), in
        ``FrameResult.layers``.

    Returns
    -------
    FrameResult
        The frame's radiance [kcd/m^2], its exposure [m^2/kcd] and light.

    Raises
    ------
    ValueError
        For light passes with a ground reflectance (``ground.brdf``).
    """
    workers = workers or default_workers()
    with loop_threads(workers):
        return _render_frame(plan, frame, store, workers, timings, passes)


def _render_frame(plan: RunPlan, frame: int, store: cache.Cache | None, workers: int, timings: dict | None,
                  passes: tuple[str, ...] | None) -> FrameResult:
    """``render_frame`` in the threads of its compiled loops."""
    plan = plan.at(frame)  # a following camera's view and sun window (docs/method.md, "Framing")
    passes = plan.output.passes if passes is None else tuple(passes)
    brdf = plan.ground.brdf
    store = store or cache.Cache(cache.cache_dir(None))
    clock = _Stopwatch(timings)
    scene = plan.scenes[frame]
    sky = plan.sky.at(scene)
    ground = render_ground(plan, frame, store=store, workers=workers, sky=sky, outer=True,
                           parts=bool({"sun", "sky"} & set(passes)) or brdf is not None,
                           coarse_sky=brdf is not None)
    clock.lap("ground")
    view = plan.camera
    if brdf is None:  # lambert: the camera's own path, bytes unchanged
        seen_sky = camera.sky_view(view, sky) if "sky" in passes else None  # read once, for the sky pass too
        maps = irradiance_maps(plan, ground)
        background, distance = camera.background(
            view, irradiance=maps, albedo=ground_albedo(plan.ground), sky=sky, seen_sky=seen_sky)
    elif passes:
        raise ValueError("the light passes split a Lambertian ground's light; ground.brdf has none yet")
    else:
        background = brdf_background(plan, frame, ground, sky, store, workers)
    clock.lap("camera")
    light = reference_lighting(plan)
    sun_fraction = float(sky.sun_fraction())
    sky_scale = _sky_scale(sky, light)
    if plan.haze > 0:
        # Koschmieder (1924): a thing at distance d is seen as T L + (1 - T) L_horizon, T =
        # exp(-d / haze), L_horizon the sky just above the horizon in its column (the sky model
        # holds its own haze), so the far ground meets the sky at the horizon without a line
        _apply_haze(background, *_haze_of_view(view, plan.haze), camera.horizon_sky(view, sky))
    else:
        background += np.float32(0.0)  # as _apply_haze: -0 + 0 is +0
    fg = foreground_layer(plan, frame % plan.canopy.cycle, store, light)
    if fg is not None and fg.haze is not None and sky_scale > 0:
        # the haze in front of the trees, as in front of the ground
        horizon = camera.horizon_sky(view, sky)[None, fg.region[1]]
        veil = fg.haze[..., None] * (horizon / np.float32(sky_scale))
        fg = replace(fg, sun=fg.sun + veil, sky=fg.sky + veil)
    # outside the passes' region, and everywhere without a foreground, the trees add nothing:
    # B + 0 (above), the same bits composite_frame gives with passes of 0
    radiance = background
    if fg is not None:
        radiance[fg.region] = composite.composite_frame(
            background[fg.region], sun_pass=fg.sun, sky_pass=fg.sky, alpha=fg.alpha,
            sun_fraction=sun_fraction, sky_scale=sky_scale)
    if plan.exposures is not None and plan.exposures[frame] is not None:
        exposure = plan.exposures[frame]
    elif plan.exposure.auto is not None:
        exposure = auto_exposures(plan, [frame])[frame]
    else:
        exposure = composite.exposure_for(light.unshadowed, stops=plan.exposure.stops)
    balance = composite.white_balance(
        plan.exposure.white_balance, sky_irradiance=light.sky_irradiance,
        sun_irradiance=(light.sun_irradiance * light.sun_direction[2] if light.sun_direction is not None
                        else np.zeros(3)))
    clock.lap("composite")
    layers = {}
    if passes:
        layers = light_layers(plan, passes, ground=ground, sky=sky, foreground=fg,
                              sun_fraction=sun_fraction, sky_scale=sky_scale, distance=distance,
                              seen_sky=seen_sky, maps=maps)
        clock.lap("passes")
    return FrameResult(radiance, sun_fraction, scene, exposure, ground, balance,
                       open_ground_light(sky, exposure, balance), layers)


def light_layers(plan: RunPlan, passes, *, ground: GroundResult, sky, foreground, sun_fraction: float,
                 sky_scale: float, distance: np.ndarray, seen_sky=None, maps=None) -> dict:
    """The light passes of a frame (docs/runs.md, "Light passes"), {name: (rows, cols, channels)
    float32}, for the names in ``passes``:

    ``sun``, ``sky`` (RGB) [kcd/m^2]: the frame's light from the sun and from the sky, each
    composited as the beauty is (``composite.composite_frame``) from its own part of the
    ground (``GroundResult.sky_part``, ``sun_part``) seen through the camera and the haze:
    ``sky = k F_sky + (1 - A) B_sky`` (the veil of haze and the sky seen are sky light) and
    ``sun = S (F_sun - F_sky) + (1 - A) T B_sun``; the camera, the haze and the composite are
    linear in the light, so ``sun + sky`` is the beauty to float rounding (tests/test_passes.py).
    ``alpha`` (1): the foreground's coverage A [1] (0 without one). ``illuminance`` (1): the
    horizontal illuminance of the ground each pixel sees [lx] (luminance of the irradiance,
    x 1000; 0 where the pixel sees no ground). ``depth`` (1): the distance to the ground seen,
    inf at the sky [m]. ``seen_sky``: the sky's ``camera.sky_view``, and ``maps`` the ground's
    ``irradiance_maps``, if made already.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    passes : iterable of str
        The passes' names (``vocabulary.PASSES``).
    ground : GroundResult
        The frame's ground, with its ``sky_part``.
    sky : sky.Sky
        The frame's sky.
    foreground : ForegroundLayer or None
        The frame's foreground, or None.
    sun_fraction : float
        S [1].
    sky_scale : float
        Skylight now over the reference skylight [1].
    distance : ndarray, shape (rows, cols)
        The distance to the ground each pixel sees, inf at the sky [m].
    seen_sky : ndarray, shape (rows, cols, 3), float32, or None
        The sky's ``camera.sky_view`` [kcd/m^2], if made already.
    maps : tuple of texture.MipMap or None
        The ground's ``irradiance_maps``, if made already.

    Returns
    -------
    dict
        {name: (rows, cols, channels) float32}, in the order of ``passes``.
    """
    view = plan.camera
    layers = {}
    alpha = np.zeros((view.height, view.width), dtype=np.float32)
    if foreground is not None:
        region = foreground.region
        alpha[region] = foreground.alpha
    if "sun" in passes or "sky" in passes:
        albedo = ground_albedo(plan.ground)
        dark = _DarkSky()
        for name, part, light_of in (("sky", ground.sky_part, sky), ("sun", ground.sun_part(), dark)):
            if name not in passes:
                continue
            behind, _ = camera.background(view, irradiance=irradiance_maps(plan, part), albedo=albedo, sky=light_of,
                                          seen_sky=seen_sky if name == "sky" else None)
            if plan.haze > 0:
                _apply_haze(behind, *_haze_of_view(view, plan.haze), camera.horizon_sky(view, light_of))
            if foreground is not None:
                f_sun, f_sky = foreground.sun, foreground.sky
                if name == "sky":
                    behind[region] = composite.composite_frame(
                        behind[region], sun_pass=f_sky, sky_pass=f_sky, alpha=foreground.alpha,
                        sun_fraction=sun_fraction, sky_scale=sky_scale)
                else:
                    behind[region] = composite.composite_frame(
                        behind[region], sun_pass=f_sun - f_sky, sky_pass=np.zeros_like(f_sky),
                        alpha=foreground.alpha, sun_fraction=sun_fraction, sky_scale=0.0)
            layers[name] = behind
    if "alpha" in passes:
        layers["alpha"] = alpha[..., None]
    if "illuminance" in passes:
        irradiance = camera.ground_irradiance(view, irradiance=maps or irradiance_maps(plan, ground))
        layers["illuminance"] = (irradiance @ REC709_LUMINANCE.astype(np.float32) * np.float32(LUX_PER_KLX))[..., None]
    if "depth" in passes:
        layers["depth"] = np.asarray(distance, dtype=np.float32)[..., None].copy()
    return {name: layers[name] for name in passes if name in layers}


class _DarkSky:
    """A sky that sends no light: the sky the sun pass sees (its light is in the sky pass)."""

    sun = None
    sky_irradiance = np.zeros(3)

    def view_radiance(self, w, s, footprint=None) -> np.ndarray:
        return np.zeros((*np.shape(w)[:-1], 3), dtype=np.float32)

    def sun_fraction(self) -> float:
        return 0.0

    def undimmed_sun_irradiance(self) -> np.ndarray:
        return np.zeros(3)


def brdf_background(plan: RunPlan, frame: int, ground: GroundResult, sky, store: cache.Cache,
                    workers: int) -> np.ndarray:
    """The background B with the ground's reflectance ``ground.brdf``.

    The sun's term at each pixel's own view, the sky's through view bands chosen by
    ``brdf_bands.choose_bands`` (docs/method.md, "The ground's reflectance").

    Parameters
    ----------
    plan, frame
        As in ``render_frame``.
    ground : GroundResult
        The frame's ground, with its ``sky_part`` and ``coarse_sky``.
    sky, store, workers
        As in ``ground.sky_view_terms``.

    Returns
    -------
    ndarray, shape (height, width, 3), float32
        Radiance [kcd/m^2].
    """
    view = plan.camera
    model = plan.ground.brdf
    # the first layer's sky raster, in the blocks the bands are correlated on: the open-sky sums
    # of the band choice and of the ratio take it coarsened further (brdf_bands.SKY_CELLS)
    raster = brdf_bands.summed_blocks(ground.coarse_sky[2][0], brdf_bands.band_factor(plan))
    bands = brdf_bands.choose_bands(model, raster, reflect.camera_views(view)[0])
    # the colour bands in every channel, the others on the channels' sum (colour -1: none kept)
    directions, colours = bands.directions(), list(bands.colours)
    others = [b for b in range(bands.count) if b not in colours]
    made = dict(zip(colours, sky_view_terms(plan, frame, sky, store, workers, directions[colours], ground)))
    if others:
        made.update(zip(others, sky_view_terms(plan, frame, sky, store, workers, directions[others], ground,
                                               colour=-1)))
    terms = [made[b] for b in range(bands.count)]
    sun = sky.sun_direction if getattr(sky, "sun", None) is not None else None
    if plan.canopy.layout == "periodic":
        # the bands' rasters as the channels of one raster, repeated by the tile: the camera
        # filters its footprints once for all of them, the blend is made per pixel
        stacked = GroundResult(np.concatenate([t.irradiance for t in terms], axis=-1), plan.window,
                               np.concatenate([np.asarray(t.unshadowed, dtype=np.float64) for t in terms]),
                               ground.exact)
        sky_maps, open_light = irradiance_maps(plan, stacked), None
    else:
        # an isolated canopy: the blend made on the ground raster, relative to open ground (1
        # beyond the window), so that the camera reads three channels
        open_light = (np.array([np.asarray(terms[c].unshadowed, dtype=np.float64) for c in colours]),
                      np.array([float(np.sum(t.unshadowed)) for t in terms]))
        grid = terms[0].grid  # the window, or the coarser grid of brdf_bands.band_factor
        relative = reflect.relative_sky(view, grid, bands, np.stack([terms[c].irradiance for c in colours], axis=-2),
                                        np.concatenate([t.irradiance.sum(axis=-1, keepdims=True)
                                                        for t in terms], axis=-1),
                                        *open_light)
        sky_maps = (relative, grid)
    radiance = reflect.ground_radiance(
        view, model, ground_albedo(plan.ground), sun=irradiance_maps(plan, ground.sun_part()),
        sky_maps=sky_maps, bands=bands, sun_direction=sun, raster=raster, open_light=open_light)
    return reflect.background(view, radiance, sky)


def compile_loops(plan: RunPlan) -> None:
    """Compile the frame phase's loops (numba) in this process, or load them from numba's
    cache on disk, by resampling a tiny view of the plan's ground and sky (twice) with its haze, and by
    making a tiny sky raster and blend band (and, with a ground reflectance, reading a tiny
    lattice as ``brdf_bands.sky_ratio`` does). A render's command calls it while its workers make the cycle
    products (``run.render_run``), so that after an install the workers of the frame phase load the
    loops instead of each compiling them (docs/accuracy.md, "The frame phase"). Nothing is
    kept; any error is left to the frames.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    """
    try:
        view = plan.camera
        tiny = camera.Camera(view.position, view.yaw, view.pitch, view.vertical_fov, width=8, height=6)
        empty = np.zeros((*plan.window.shape, 3), dtype=np.float32)
        maps = (texture.mipmap(empty, plan.window, outside="constant", value=np.full(3, np.nan)),
                texture.mipmap(empty, plan.window, outside="constant", value=np.zeros(3)))
        sky = plan.sky.at(plan.scenes[0])
        for _ in range(2):  # the second read of the same view compiles the kept taps' loops (texture.filtered_read)
            background, _ = camera.background(tiny, irradiance=maps, albedo=_stand_in_albedo(), sky=sky)
        share = np.ones((tiny.height, tiny.width, 1), dtype=np.float32)
        share.flags.writeable = False  # as _haze_of_view's
        _apply_haze(background, share, share, camera.horizon_sky(tiny, sky))
        sky.raster(replace(plan.window, origin=(0.0, 0.0), pixel=0.01, shape=(2, 2)))  # the ground stage's, tiny
        coarse = replace(plan.window, shape=(2, 2))
        blend_band(np.zeros((4, 4, 3), dtype=np.float32), replace(coarse, pixel=coarse.pixel / 2, shape=(4, 4)),
                   np.zeros((2, 2, 3), dtype=np.float32), coarse)
        if plan.ground.brdf is not None:  # the ground reflectance's read of its open-sky ratio
            from pipeline.kernels import arrays as _array_loops

            _array_loops.lattice_read(np.zeros((3, 4), dtype=np.float32), np.zeros(1, dtype=np.intp),
                                      np.zeros((4, 1), dtype=np.float32), 2, np.empty((3, 1), dtype=np.float32))
    except Exception:
        pass


@functools.lru_cache(maxsize=1)
def _stand_in_albedo():
    """A tiny albedo laid by stochastic tiling, of the types the ground's own has (``compile_loops``
    compiles the same loops with it): making the built-in grass and its tiling took about 1 s of
    the command's CPU while its workers made the cycle products (docs/accuracy.md, "The warm-up's
    albedo")."""
    from pipeline.core.geometry import Grid
    from pipeline.texture.albedo import stochastic_tiling

    image = np.random.default_rng(0).random((8, 8, 3), dtype=np.float32)
    return stochastic_tiling(texture.mipmap(image, Grid((0.0, 1.0), 0.125, (8, 8)), outside="periodic",
                                            period=(1.0, 1.0)))


def _apply_haze(background, transmittance, veil, horizon) -> None:
    """``background`` (rows, cols, 3) float32, in place: T B + (1 - T) L_horizon + 0, T the haze's
    transmittance (rows, cols, 1), L_horizon (cols, 3) the sky at the horizon; compiled
    (``_array_loops.haze_over``), the float32 operations, in order, of ``B *= T; B += (1 - T) L;
    B + 0`` on arrays (tests/test_frame.py holds it to them)."""
    from pipeline.kernels import arrays as _array_loops

    _array_loops.haze_over(background, transmittance, veil, np.ascontiguousarray(horizon, dtype=np.float32))


@functools.lru_cache(maxsize=2)
def _haze_of_view(view: camera.Camera, haze: float) -> tuple[np.ndarray, np.ndarray]:
    """The haze's transmittance T (height, width, 1) float32 over the ground the camera sees
    (1 at the sky) and 1 - T [1]: they depend on the camera and the haze alone, so the frames of
    a run make them once. Read-only."""
    transmittance = scattering.haze_transmittance(camera.ground_distance(view), haze)[..., None]
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
