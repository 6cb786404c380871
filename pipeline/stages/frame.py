"""The frame stage: the finished picture of one output frame (Max 1991, Figs. 10 and 13): the
ground raster and the sky resampled in the camera, the haze, the foreground passes blended by
the sun fraction S and composited over them (docs/method.md). Takes the RunPlan and the
cache."""

from __future__ import annotations

import functools
import time
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from pipeline.cache import store as cache
from pipeline.camera import brdf_view, composite, pinhole
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.cores import default_workers, loop_threads
from pipeline.core.geometry import Grid
from pipeline.foreground.models import ForegroundLayer
from pipeline.ground import brdf_bands
from pipeline.sky import scattering
from pipeline.sky.base import Sky, UniformSky
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_disc import SunDisc
from pipeline.stages import slope, walls
from pipeline.stages.cycle import foreground_item
from pipeline.stages.ground import FrameContext, GroundResult, blend_band, ground_of_frame, sky_view_terms
from pipeline.stages.inputs import albedo_mipmap, ground_albedo
from pipeline.stages.lighting import LUX_PER_KLX, Lighting, auto_exposures, open_ground_light, reference_lighting
from pipeline.stages.plan import RunPlan
from pipeline.stages.scene import Scene
from pipeline.texture import mipmap

if TYPE_CHECKING:
    from pipeline.sky.procedural import ProceduralSky
    from pipeline.texture.albedo import StochasticTiling

__all__ = ["foreground_layer", "irradiance_maps", "FrameResult", "render_frame", "light_layers", "brdf_background",
           "compile_loops"]


def foreground_layer(plan: RunPlan, cycle_frame: int, store: cache.Cache,
                     light: Lighting | None = None) -> ForegroundLayer | None:
    """The foreground of ``cycle_frame`` (``foreground.models.ForegroundLayer``), its cycle product
    fetched once when the model has one: the built-in trees lit by ``light`` (default: the run's
    reference Lighting), or imported passes; None without a foreground.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    cycle_frame : int
        The cycle frame.
    store : store.Cache
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
    return plan.foreground.layer(cycle_frame, view=plan.camera, item=item, sun_irradiance=light.sun_irradiance,
                                 sky_irradiance=light.sky_irradiance, sun_down=light.sun_down,
                                 bounce=0.5 * albedo_mipmap(plan.ground).mean)


def irradiance_maps(plan: RunPlan, ground: GroundResult, *,
                    far: mipmap.MipMap | None = None) -> tuple[mipmap.MipMap, ...]:
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
    far : texture.mipmap.MipMap or None
        Read beyond the window's rasters instead of the open ground (the walls' shade there,
        ``walls.shade_ground``); isolated canopy only.

    Returns
    -------
    tuple of mipmap.MipMap
        The rasters (rows, cols, channels) [klx], finest first; the fine one blended into the
        coarse one at its edge (``stages.ground.blend_band``).
    """
    outer = ground.outer
    rasters = [(ground.irradiance, ground.grid)]
    if outer is not None:
        rasters = [(blend_band(ground.irradiance, ground.grid, outer.irradiance, outer.grid), ground.grid),
                   (outer.irradiance, outer.grid)]
    maps = [mipmap.mipmap(r, g, outside="constant", value=np.full(3, np.nan)) for r, g in rasters[:-1]]
    raster, grid = rasters[-1]
    if plan.canopy.layout == "periodic":
        period = plan.canopy.layers[0].size
        x0, y0, x1, y1 = grid.extent
        if x1 - x0 >= period[0] and y1 - y0 >= period[1]:
            return (*maps, mipmap.mipmap(raster, grid, outside="periodic", period=period))
        value = raster.reshape(-1, raster.shape[-1]).mean(axis=0)
    elif far is not None:
        return (*maps, mipmap.mipmap(raster, grid, outside="constant", value=np.full(3, np.nan)), far)
    else:
        value = ground.unshadowed
    return (*maps, mipmap.mipmap(raster, grid, outside="constant", value=np.asarray(value, dtype=np.float32)))


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
        The open ground's light (``lighting.open_ground_light``).
    layers : dict
        The light passes asked for, {name: (rows, cols, channels) float32} (``light_layers``;
        ``sun``, ``sky`` [kcd/m^2], ``alpha`` [1], ``illuminance`` [lx], ``depth`` [m]), in the
        order asked, empty when none were. A mapping, not a record: which passes it holds is the
        config's choice (``output.passes``, a subset of ``vocabulary.PASSES``), and each is
        written as an EXR layer of its name.
    """

    radiance: np.ndarray
    sun_fraction: float
    scene: Scene
    exposure: float
    ground: GroundResult
    balance: np.ndarray | None
    light: dict[str, Any] | None = None
    layers: dict[str, np.ndarray] = field(default_factory=dict)


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
    store : store.Cache or None
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


def _render_frame(plan: RunPlan, frame: int, store: cache.Cache | None, workers: int,
                  timings: dict[str, float] | None, passes: tuple[str, ...] | None) -> FrameResult:
    """``render_frame`` in the threads of its compiled loops."""
    clock = _Stopwatch(timings)
    # made once for the frame and handed to the ground stage: the plan at the frame (a following
    # camera's view and sun window, docs/method.md, "Framing"), its scene, sky and cycle products
    context = FrameContext.of(plan, frame, store=store, workers=workers)
    plan, sky = context.plan, context.sky
    passes = plan.output.passes if passes is None else tuple(passes)
    brdf = plan.ground.brdf
    ground = slope.slope_ground(context) if plan.receivers.slope else ground_of_frame(
        context, outer=True, parts=bool({"sun", "sky"} & set(passes)) or brdf is not None
        or bool(plan.receivers.walls), coarse_sky=brdf is not None)
    wall_lights, far = walls.wall_lights(context) if plan.receivers.walls else (), None
    if wall_lights:  # each wall's shadow and lost sky on the ground (docs/method.md, "A wall on the ground")
        ground, far = walls.shade_ground(context, ground, wall_lights)
    clock.lap("ground")
    view = plan.camera
    seen_sky, maps = None, None
    horizon: np.ndarray | None = None  # the sky the far ground fades to; None: the level horizon's
    if plan.receivers.slope:  # the level ground's camera turned into the slope's frame
        maps = irradiance_maps(plan, ground)
        background, distance, horizon = slope.slope_background(plan, maps, sky)
    elif brdf is None:  # lambert: the camera's own path, bytes unchanged
        seen_sky = pinhole.sky_view(view, sky) if "sky" in passes else None  # read once, for the sky pass too
        maps = irradiance_maps(plan, ground, far=far)
        background, distance = pinhole.background(
            view, irradiance=maps, albedo=ground_albedo(plan.ground), sky=sky, seen_sky=seen_sky)
    elif passes:
        raise ValueError("the light passes split a Lambertian ground's light; ground.brdf has none yet")
    else:
        background = brdf_background(context, ground)
    if plan.receivers.walls:  # the walls in front of the ground, by depth (docs/method.md, "Receivers")
        distance = (distance if brdf is None else pinhole.ground_distance(view)).copy()
        walls.show_walls(view, plan.receivers.walls, wall_lights, background, distance)
    clock.lap("camera")
    light = reference_lighting(plan)
    sun_fraction = float(sky.sun_fraction())
    sky_scale = _sky_scale(sky, light)
    if plan.haze > 0:
        # Koschmieder (1924): a thing at distance d is seen as T L + (1 - T) L_horizon, T =
        # exp(-d / haze), L_horizon the sky just above the horizon in its column (the sky model
        # holds its own haze), so the far ground meets the sky at the horizon without a line
        haze = _haze_of_view(view, plan.haze)
        if plan.receivers.walls or plan.receivers.slope:  # the haze in front of them by their distance
            haze = walls.distance_haze(distance, plan.haze)
        _apply_haze(background, *haze, pinhole.horizon_sky(view, sky) if horizon is None else horizon)
    else:
        background += np.float32(0.0)  # as _apply_haze: -0 + 0 is +0
    fg = foreground_layer(plan, context.cycle_frame, context.store, light)
    if fg is not None and fg.haze is not None and sky_scale > 0:
        # the haze in front of the trees, as in front of the ground
        horizon = (pinhole.horizon_sky(view, sky) if horizon is None else horizon)[None, fg.region[1]]
        veil = fg.haze[..., None] * (horizon / np.float32(sky_scale))
        fg = replace(fg, sun=fg.sun + veil, sky=fg.sky + veil)
    # outside the passes' region, and everywhere without a foreground, the trees add nothing:
    # B + 0 (above), the same bits composite_frame gives with passes of 0
    radiance = background
    if fg is not None:
        radiance[fg.region] = composite.composite_frame(
            background[fg.region], sun_pass=fg.sun, sky_pass=fg.sky, alpha=fg.alpha,
            sun_fraction=sun_fraction, sky_scale=sky_scale)
    exposure = _exposure_of(plan, frame, light)
    balance = composite.white_balance(plan.exposure.white_balance, sky_irradiance=light.sky_irradiance,
                                      sun_irradiance=light.sun_down)
    clock.lap("composite")
    layers = {}
    if passes:
        layers = light_layers(plan, passes, ground=ground, sky=sky, foreground=fg,
                              sun_fraction=sun_fraction, sky_scale=sky_scale, distance=distance,
                              seen_sky=seen_sky, maps=maps)
        clock.lap("passes")
    return FrameResult(radiance, sun_fraction, context.scene, exposure, ground, balance,
                       open_ground_light(sky, exposure, balance), layers)


def _exposure_of(plan: RunPlan, frame: int, light: Lighting) -> float:
    """The frame's exposure [m^2/kcd]: metered for the run (``lighting.with_exposures``), else
    metered now (auto), else set by the reference light and the stops."""
    metered = plan.exposures[frame] if plan.exposures is not None else None
    if metered is not None:
        return metered
    if plan.exposure.auto is not None:
        return auto_exposures(plan, [frame])[frame]
    return composite.exposure_for(light.unshadowed, stops=plan.exposure.stops)


def light_layers(plan: RunPlan, passes: Iterable[str], *, ground: GroundResult, sky: Sky,
                 foreground: ForegroundLayer | None, sun_fraction: float, sky_scale: float, distance: np.ndarray,
                 seen_sky: np.ndarray | None = None,
                 maps: tuple[mipmap.MipMap, ...] | None = None) -> dict[str, np.ndarray]:
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
    inf at the sky [m]. ``seen_sky``: the sky's ``pinhole.sky_view``, and ``maps`` the ground's
    ``irradiance_maps``, if made already.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    passes : iterable of str
        The passes' names (``vocabulary.PASSES``).
    ground : GroundResult
        The frame's ground, with its ``sky_part``.
    sky : base.Sky
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
        The sky's ``pinhole.sky_view`` [kcd/m^2], if made already.
    maps : tuple of mipmap.MipMap or None
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
        alpha[foreground.region] = foreground.alpha
    if "sun" in passes or "sky" in passes:
        layers = _sun_and_sky(plan, passes, ground=ground, sky=sky, foreground=foreground,
                              sun_fraction=sun_fraction, sky_scale=sky_scale, seen_sky=seen_sky)
    if "alpha" in passes:
        layers["alpha"] = alpha[..., None]
    if "illuminance" in passes:
        irradiance = pinhole.ground_irradiance(view, irradiance=maps or irradiance_maps(plan, ground))
        layers["illuminance"] = (irradiance @ REC709_LUMINANCE.astype(np.float32) * np.float32(LUX_PER_KLX))[..., None]
    if "depth" in passes:
        layers["depth"] = np.asarray(distance, dtype=np.float32)[..., None].copy()
    return {name: layers[name] for name in passes if name in layers}


def _sun_and_sky(plan: RunPlan, passes: Iterable[str], *, ground: GroundResult, sky: Sky,
                 foreground: ForegroundLayer | None, sun_fraction: float, sky_scale: float,
                 seen_sky: np.ndarray | None) -> dict[str, np.ndarray]:
    """``light_layers``' ``sky`` and ``sun`` passes, those of the two in ``passes``."""
    sky_part = ground.sky_part
    if sky_part is None:
        raise ValueError("the sun and sky passes need the ground's sky part (render_ground(parts=True))")
    view = plan.camera
    albedo = ground_albedo(plan.ground)
    layers = {}
    dark: Sky = _DarkSky()
    for name, part, light_of in (("sky", sky_part, sky), ("sun", ground.sun_part(), dark)):
        if name not in passes:
            continue
        behind, _ = pinhole.background(view, irradiance=irradiance_maps(plan, part), albedo=albedo, sky=light_of,
                                      seen_sky=seen_sky if name == "sky" else None)
        if plan.haze > 0:
            _apply_haze(behind, *_haze_of_view(view, plan.haze), pinhole.horizon_sky(view, light_of))
        if foreground is not None:
            region, f_sun, f_sky = foreground.region, foreground.sun, foreground.sky
            if name == "sky":
                behind[region] = composite.composite_frame(
                    behind[region], sun_pass=f_sky, sky_pass=f_sky, alpha=foreground.alpha,
                    sun_fraction=sun_fraction, sky_scale=sky_scale)
            else:
                behind[region] = composite.composite_frame(
                    behind[region], sun_pass=f_sun - f_sky, sky_pass=np.zeros_like(f_sky),
                    alpha=foreground.alpha, sun_fraction=sun_fraction, sky_scale=0.0)
        layers[name] = behind
    return layers


class _DarkSky:
    """A sky that sends no light: the sky the sun pass sees (its light is in the sky pass)."""

    sun: SunDisc | None = None
    sky_irradiance: np.ndarray = np.zeros(3)

    def raster(self, grid: Grid, *, fold_period: tuple[int, int] | None = None) -> SkyRaster:
        """No light on a sky-plane grid (``base.Sky.raster``): a uniform sky of radiance 0.

        Parameters
        ----------
        grid : Grid
            The sky-plane grid [tan].
        fold_period : tuple of int or None
            (rows, cols): folded modulo that period.

        Returns
        -------
        SkyRaster
            Zeros [radiance x sr].
        """
        return UniformSky(np.zeros(3)).raster(grid, fold_period=fold_period)

    def view_radiance(self, w: np.ndarray, s: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """No light along view directions (``base.Sky.view_radiance``).

        Parameters
        ----------
        w : ndarray, shape (..., 3)
            Unit vectors [1].
        s, footprint
            Not used.

        Returns
        -------
        ndarray, shape (..., 3), float32
            Zeros [kcd/m^2].
        """
        return np.zeros((*np.shape(w)[:-1], 3), dtype=np.float32)

    def sun_fraction(self) -> float:
        """S = 0: no sun.

        Returns
        -------
        float
            0 [1].
        """
        return 0.0

    def undimmed_sun_irradiance(self) -> np.ndarray:
        """No sun.

        Returns
        -------
        ndarray, shape (3,)
            Zeros [klx].
        """
        return np.zeros(3)


def brdf_background(context: FrameContext, ground: GroundResult) -> np.ndarray:
    """The background B with the ground's reflectance ``ground.brdf``.

    The sun's term at each pixel's own view, the sky's through view bands chosen by
    ``brdf_bands.choose_bands`` (docs/method.md, "The ground's reflectance").

    Parameters
    ----------
    context : stages.ground.FrameContext
        The frame: its plan (with ``ground.brdf``), sky, cycle products and threads.
    ground : GroundResult
        The frame's ground, with its ``sky_part`` and ``coarse_sky``.

    Returns
    -------
    ndarray, shape (height, width, 3), float32
        Radiance [kcd/m^2].

    Raises
    ------
    ValueError
        Without a ground reflectance, or for a ground made without its ``coarse_sky``.
    """
    plan, sky = context.plan, context.sky
    view = plan.camera
    model, kept = plan.ground.brdf, ground.coarse_sky
    if model is None or kept is None:
        raise ValueError("a ground reflectance's background needs ground.brdf and the ground's coarse_sky")
    # the first layer's sky raster, in the blocks the bands are correlated on: the open-sky sums
    # of the band choice and of the ratio take it coarsened further (brdf_bands.SKY_CELLS)
    raster = brdf_bands.summed_blocks(kept.rasters[0], brdf_bands.band_factor(plan))
    bands = brdf_bands.choose_bands(model, raster, brdf_view.camera_views(view)[0])
    # the colour bands in every channel, the others on the channels' sum (colour -1: none kept)
    directions, colours = bands.directions(), list(bands.colours)
    others = [b for b in range(bands.count) if b not in colours]
    made = dict(zip(colours, sky_view_terms(context, directions[colours], ground)))
    if others:
        made.update(zip(others, sky_view_terms(context, directions[others], ground, colour=-1)))
    terms = [made[b] for b in range(bands.count)]
    # a sky with a sun disc under a ground reflectance is a procedural one (its sun_direction)
    sun = cast("ProceduralSky", sky).sun_direction if getattr(sky, "sun", None) is not None else None
    sky_maps: tuple[mipmap.MipMap, ...] | tuple[np.ndarray, Grid]
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
        relative = brdf_view.relative_sky(view, grid, bands, np.stack([terms[c].irradiance for c in colours], axis=-2),
                                        np.concatenate([t.irradiance.sum(axis=-1, keepdims=True)
                                                        for t in terms], axis=-1),
                                        *open_light)
        sky_maps = (relative, grid)
    radiance = brdf_view.ground_radiance(
        view, model, ground_albedo(plan.ground), sun=irradiance_maps(plan, ground.sun_part()),
        sky_maps=sky_maps, bands=bands, sun_direction=sun, raster=raster, open_light=open_light)
    return brdf_view.background(view, radiance, sky)


def compile_loops(plan: RunPlan) -> None:
    """Compile the frame phase's loops (numba) in this process, or load them from numba's
    cache on disk, by resampling a tiny view of the plan's ground and sky with its haze, and by
    making a tiny sky raster and blend band (and, with a ground reflectance, reading a tiny
    lattice as ``brdf_bands.sky_ratio`` does). A render's command calls it while its workers make the cycle
    products (``render.render_run``), so that after an install the workers of the frame phase load the
    loops instead of each compiling them (docs/accuracy.md, "The frame phase"). Nothing is
    kept; any error is left to the frames.

    Parameters
    ----------
    plan : RunPlan
        The run's plan.
    """
    try:
        view = plan.camera
        tiny = pinhole.Camera(view.position, view.yaw, view.pitch, view.vertical_fov, width=8, height=6)
        empty = np.zeros((*plan.window.shape, 3), dtype=np.float32)
        maps = (mipmap.mipmap(empty, plan.window, outside="constant", value=np.full(3, np.nan)),
                mipmap.mipmap(empty, plan.window, outside="constant", value=np.zeros(3)))
        sky = plan.sky.at(plan.scenes[0])
        # one read compiles the kept taps' loops too: a first read finds its taps as the later ones read them
        background, _ = pinhole.background(tiny, irradiance=maps, albedo=_stand_in_albedo(), sky=sky)
        share = np.ones((tiny.height, tiny.width, 1), dtype=np.float32)
        share.flags.writeable = False  # as _haze_of_view's
        _apply_haze(background, share, share, pinhole.horizon_sky(tiny, sky))
        sky.raster(replace(plan.window, origin=(0.0, 0.0), pixel=0.01, shape=(2, 2)))  # the ground stage's, tiny
        coarse = replace(plan.window, shape=(2, 2))
        blend_band(np.zeros((4, 4, 3), dtype=np.float32), replace(coarse, pixel=coarse.pixel / 2, shape=(4, 4)),
                   np.zeros((2, 2, 3), dtype=np.float32), coarse)
        if plan.ground.brdf is not None:  # the ground reflectance's read of its open-sky ratio
            from pipeline.kernels import arrays

            arrays.lattice_read(np.zeros((3, 4), dtype=np.float32), np.zeros(1, dtype=np.intp),
                                      np.zeros((4, 1), dtype=np.float32), 2, np.empty((3, 1), dtype=np.float32))
    except Exception:
        pass


@functools.lru_cache(maxsize=1)
def _stand_in_albedo() -> StochasticTiling:
    """A tiny albedo laid by stochastic tiling, of the types the ground's own has (``compile_loops``
    compiles the same loops with it): making the built-in grass and its tiling took about 1 s of
    the command's CPU while its workers made the cycle products (docs/accuracy.md, "The warm-up's
    albedo")."""
    from pipeline.texture.albedo import stochastic_tiling

    image = np.random.default_rng(0).random((8, 8, 3), dtype=np.float32)
    return stochastic_tiling(mipmap.mipmap(image, Grid((0.0, 1.0), 0.125, (8, 8)), outside="periodic",
                                            period=(1.0, 1.0)))


def _apply_haze(background: np.ndarray, transmittance: np.ndarray, veil: np.ndarray, horizon: np.ndarray) -> None:
    """``background`` (rows, cols, 3) float32, in place: T B + (1 - T) L_horizon + 0, T the haze's
    transmittance (rows, cols, 1), L_horizon (cols, 3) the sky at the horizon; compiled
    (``kernels.arrays.haze_over``), the float32 operations, in order, of ``B *= T; B += (1 - T) L;
    B + 0`` on arrays (tests/test_frame.py holds it to them)."""
    from pipeline.kernels import arrays

    arrays.haze_over(background, transmittance, veil, np.ascontiguousarray(horizon, dtype=np.float32))


@functools.lru_cache(maxsize=2)
def _haze_of_view(view: pinhole.Camera, haze: float) -> tuple[np.ndarray, np.ndarray]:
    """The haze's transmittance T (height, width, 1) float32 over the ground the camera sees
    (1 at the sky) and 1 - T [1]: they depend on the camera and the haze alone, so the frames of
    a run make them once. Read-only."""
    transmittance = scattering.haze_transmittance(pinhole.ground_distance(view), haze)[..., None]
    veil = 1.0 - transmittance
    for array in (transmittance, veil):
        array.flags.writeable = False
    return transmittance, veil


class _Stopwatch:
    """Adds the seconds since the last lap to ``timings[stage]`` (nothing when timings is None)."""

    def __init__(self, timings: dict[str, float] | None):
        self.timings, self.last = timings, time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        if self.timings is not None:
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self.last
        self.last = now


def _sky_scale(sky: Sky, light: Lighting) -> float:
    """Skylight now over the reference skylight, by luminance: clouds and the moon dim it. [1]"""
    reference = float(light.sky_irradiance @ REC709_LUMINANCE)
    if reference <= 0:
        return 1.0
    return float(np.asarray(sky.sky_irradiance) @ REC709_LUMINANCE) / reference
