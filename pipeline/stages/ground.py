"""The ground stage: the irradiance on the ground under one frame's sky, the correlation of the
sky raster with each canopy layer's cached spectrum at the coarse scale and of the sun kernel
with the fine mask spectrum on the sun window (Max 1991, Fig. 7 and section 3; docs/method.md,
"Two scales"). Takes one frame's ``FrameContext`` (the plan at the frame, its sky and the cache),
which the frame stage makes once per frame."""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING, cast

import numpy as np

from pipeline.cache import store as cache
from pipeline.config.settings import BrdfConfig
from pipeline.core.cores import default_workers
from pipeline.core.geometry import Grid, sky_grid, sky_offset
from pipeline.ground import brdf_bands, shadow
from pipeline.ground.layers import combine_layers, combine_lights
from pipeline.sky.base import Sky
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_kernel import sun_irradiance, sun_kernel
from pipeline.stages.cycle import LayerSpectra, cycle_item
from pipeline.stages.plan import LayerPlan, RunPlan
from pipeline.stages.scene import Scene, sun_lights, sun_shades

if TYPE_CHECKING:
    from pipeline.sky.equirect import EquirectSky
    from pipeline.sky.procedural import ProceduralSky

__all__ = ["FrameContext", "GroundRaster", "CoarseSky", "GroundResult", "LayerGround", "render_ground",
           "ground_of_frame", "sky_view_terms", "BLEND_BAND_PIXELS", "BLEND_BAND_SHARE", "blend_band"]


@dataclass(frozen=True, eq=False)
class FrameContext:
    """What the stages of one output frame share, made once per frame (``FrameContext.of``): the
    frame stage makes it and hands it to the ground stage, so that neither makes it again.

    Attributes
    ----------
    plan : RunPlan
        The plan as this frame sees it (``RunPlan.at``: a following camera's view and sun window,
        docs/method.md, "Framing").
    frame : int
        The output frame index.
    scene : Scene
        The frame's sun and moon.
    sky : base.Sky
        The frame's sky [kcd/m^2 for a procedural sky].
    store : store.Cache
        Where the cycle products come from (computed on a miss).
    workers : int
        FFT threads [1].
    """

    plan: RunPlan
    frame: int
    scene: Scene
    sky: Sky
    store: cache.Cache
    workers: int

    @classmethod
    def of(cls, plan: RunPlan, frame: int, *, store: cache.Cache | None = None, workers: int | None = None,
           sky: Sky | None = None) -> FrameContext:
        """The context of an output frame.

        Parameters
        ----------
        plan : RunPlan
            The run's plan (or the frame's, ``RunPlan.at`` gives it back unchanged).
        frame : int
            Output frame index.
        store : store.Cache or None
            Where the cycle products come from; None: the default cache.
        workers : int or None
            FFT threads; None: ``cores.default_workers``.
        sky : base.Sky or None
            The frame's sky, loaded when not given.

        Returns
        -------
        FrameContext
            The frame's plan, scene, sky, cache and threads.
        """
        plan = plan.at(frame)  # a following camera's sun window (docs/method.md, "Framing")
        scene = plan.scenes[frame]
        return cls(plan, frame, scene, sky or plan.sky.at(scene), store or cache.Cache(cache.cache_dir(None)),
                   workers or default_workers())

    @property
    def cycle_frame(self) -> int:
        """The flutter cycle's frame of this output frame.

        Returns
        -------
        int
            ``frame`` modulo the cycle [frame].
        """
        return self.frame % self.plan.canopy.cycle

    @cached_property
    def spectra(self) -> tuple[LayerSpectra, ...]:
        """Every canopy layer's cycle products at this frame's cycle frame, read once (computed on a miss).

        Returns
        -------
        tuple of cycle.LayerSpectra
            One per ``plan.layers``, in order.
        """
        return tuple(cycle_item(self.plan, index, self.cycle_frame, self.store, workers=self.workers)
                     for index in range(len(self.plan.layers)))


@dataclass(frozen=True)
class GroundRaster:
    """A ground raster on its grid.

    Attributes
    ----------
    irradiance : ndarray, shape (rows, cols, channels), float32
        Irradiance [radiance x sr: klx for a sky in kcd/m^2].
    grid : Grid
        Its ground grid [m].
    """

    irradiance: np.ndarray
    grid: Grid


@dataclass(frozen=True)
class CoarseSky:
    """The sky's own share of a frame's ground on the coarse window, kept for a ground
    reflectance's sky term (``sky_view_terms``, ``brdf_bands.weighted_raster``).

    Attributes
    ----------
    irradiance : ndarray, shape (rows, cols, 3), float32
        The ground lit by the sky alone, the layers combined [radiance x sr].
    unshadowed : ndarray, shape (3,), float64
        Its open-sky total [radiance x sr].
    rasters : tuple of SkyRaster
        Each layer's sky raster as it was correlated (a periodic layer's folded by its tile)
        [radiance x sr].
    """

    irradiance: np.ndarray
    unshadowed: np.ndarray
    rasters: tuple[SkyRaster, ...]


@dataclass(frozen=True)
class GroundResult:
    """The irradiance on the ground under one frame's sky and canopy.

    Attributes
    ----------
    irradiance : ndarray, shape (rows, cols, 3), float32
        Irradiance [radiance x sr: klx for a sky in kcd/m^2].
    grid : Grid
        Its ground grid [m].
    unshadowed : ndarray, shape (3,)
        Irradiance of the open sky [klx].
    exact : bool
        Whether every ray that meets the canopy lies inside the sky square (else light from beyond
        it was taken as unshadowed).
    outer : GroundRaster or None
        The coarse raster of the whole window with the sun at the coarse cell [klx], where the
        sun window does not cover it (``render_ground(outer=True)``); else None.
    sky_part : GroundResult or None
        The same ground lit by the sky alone, without the sun kernel (a GroundResult whose sky_part
        is None), when ``render_ground`` was asked for ``parts``, else None.
    coarse_sky : CoarseSky or None
        With ``render_ground(coarse_sky=True)``: the sky's own share on the coarse window, for a
        ground reflectance's sky term; else None.
    """

    irradiance: np.ndarray
    grid: Grid
    unshadowed: np.ndarray
    exact: bool
    outer: GroundRaster | None = None
    sky_part: GroundResult | None = None
    coarse_sky: CoarseSky | None = None

    def sun_part(self) -> GroundResult:
        """The ground's light from the sun alone: this ground less its ``sky_part``.

        Every raster and total in float32 as subtracted (the two parts sum to this ground to float
        rounding).

        Returns
        -------
        GroundResult
            The sun's part [radiance x sr], without ``sky_part``.

        Raises
        ------
        ValueError
            For a ground made without its ``sky_part``.
        """
        sky = self.sky_part
        if sky is None:
            raise ValueError("the ground was made without its sky part (render_ground(parts=True))")
        outer = None
        if self.outer is not None and sky.outer is not None:
            outer = GroundRaster(self.outer.irradiance - sky.outer.irradiance, self.outer.grid)
        return GroundResult(self.irradiance - sky.irradiance, self.grid,
                            np.asarray(self.unshadowed) - np.asarray(sky.unshadowed), self.exact, outer)


@dataclass(frozen=True)
class LayerGround:
    """One canopy layer's ground under a frame's sky, before ``ground_of_frame`` combines the
    layers by the paper's product rule.

    Attributes
    ----------
    irradiance : ndarray, shape (3, rows, cols), float32
        The light through the layer, sky and sun, on the sun window's grid where the layer has a
        sun plan, else on the window's [radiance x sr].
    unshadowed : ndarray, shape (3,), float64
        Its open-sky total [radiance x sr].
    exact : bool
        Whether every ray that meets the layer lies inside its sky square.
    sky_raster : SkyRaster
        The sky raster correlated with the layer's coarse spectrum (a periodic layer's folded by
        its tile) [radiance x sr]; its ``irradiance`` is the sky's open-sky total.
    sky_ground : ndarray, shape (3, rows, cols), float32
        The sky's light through the layer on the window [radiance x sr] (not written to
        afterwards).
    outer : ndarray, shape (3, rows, cols), float32, or None
        When asked for: ``sky_ground`` with the sun's light at the coarse cell [radiance x sr].
    sky_part : ndarray, shape (3, rows, cols), float32, or None
        When asked for: the sky's light alone on ``irradiance``'s grid [radiance x sr].
    """

    irradiance: np.ndarray
    unshadowed: np.ndarray
    exact: bool
    sky_raster: SkyRaster
    sky_ground: np.ndarray
    outer: np.ndarray | None = None
    sky_part: np.ndarray | None = None


def render_ground(plan: RunPlan, frame: int = 0, *, store: cache.Cache | None = None,
                  workers: int | None = None, sky: Sky | None = None, outer: bool = False,
                  parts: bool = False, coarse_sky: bool = False) -> GroundResult:
    """Ground irradiance at an output frame, every canopy layer under the sky.

    The coarse sky raster, and the fine sun kernel where the sky has a sun; layers combined by the
    paper's product rule (``ground_of_frame`` of the frame's ``FrameContext``).

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    frame : int
        Output frame index.
    store : store.Cache or None
        Where the cycle products come from (computed on a miss); None: the default cache.
    workers : int or None
        FFT threads; None: ``cores.default_workers``.
    sky : base.Sky or None
        The frame's sky, loaded when not given.
    outer, parts, coarse_sky : bool
        As in ``ground_of_frame``.

    Returns
    -------
    GroundResult
        On the sun window's grid, or the window's without a sun [radiance x sr].
    """
    context = FrameContext.of(plan, frame, store=store, workers=workers, sky=sky)
    return ground_of_frame(context, outer=outer, parts=parts, coarse_sky=coarse_sky)


def ground_of_frame(context: FrameContext, *, outer: bool = False, parts: bool = False,
                    coarse_sky: bool = False) -> GroundResult:
    """Ground irradiance at one frame, every canopy layer under its sky.

    The coarse sky raster, and the fine sun kernel where the sky has a sun; layers combined by the
    paper's product rule.

    Parameters
    ----------
    context : FrameContext
        The frame: its plan, sky, cycle products and threads.
    outer : bool
        Also the coarse raster of the whole window with the sun at the coarse cell (the paper's
        single scale), where the sun window does not cover it: what a camera sees beyond the sun
        window.
    parts : bool
        Also the ground lit by the sky alone (``GroundResult.sky_part``), from the same
        correlations before the sun kernel's light is added (the light passes, docs/runs.md); with
        several layers the sky part is combined by the same product rule over its own open-sky
        total.
    coarse_sky : bool
        Also keep the sky's own share on the coarse window (``GroundResult.coarse_sky``).

    Returns
    -------
    GroundResult
        On the sun window's grid, or the window's without a sun [radiance x sr].
    """
    plan = context.plan
    outer = outer and plan.sun_window is not None and not _covers(plan.sun_window, plan.window)
    several = len(plan.layers) > 1  # the sky's light and the sun's combined apart: each layer's sky part
    layers = [_ground_of_layer(context, lp, spectra, outer=outer, parts=parts or several)
              for lp, spectra in zip(plan.layers, context.spectra)]
    exact = True
    for layer in layers:
        exact &= layer.exact
    total, sky_total = layers[0].unshadowed, layers[0].sky_raster.irradiance
    grid = plan.sun_window or plan.window
    around = None
    if outer:
        around = GroundRaster(_combined([g.outer for g in layers], total, [g.sky_ground for g in layers], sky_total),
                              plan.window)
    sky_part = None
    if parts:
        sky_around = None
        if outer:
            sky_around = GroundRaster(_combined([g.sky_ground for g in layers], sky_total), plan.window)
        sky_part = GroundResult(_combined([g.sky_part for g in layers], sky_total), grid, sky_total, exact,
                                sky_around)
    kept = None
    if coarse_sky:
        kept = CoarseSky(_combined([g.sky_ground for g in layers], sky_total), sky_total,
                         tuple(g.sky_raster for g in layers))
    # one layer: its own fresh raster, not a copy (the results above are copies of theirs)
    irradiance = np.moveaxis(layers[0].irradiance, 0, -1) if not several else _combined(
        [g.irradiance for g in layers], total, [g.sky_part for g in layers], sky_total)
    return GroundResult(irradiance, grid, total, exact, around, sky_part, kept)


def _combined(grounds: list, unshadowed: np.ndarray, skies: list | None = None,
              sky_total: np.ndarray | None = None) -> np.ndarray:
    """The layers' rasters (channels, rows, cols) combined by the paper's product rule, as (rows,
    cols, channels): with their sky parts ``skies``, the sky's light and the sun's apart
    (``layers.combine_lights``), else as one light (``layers.combine_layers``)."""
    if skies is None or sky_total is None:
        return np.moveaxis(combine_layers(grounds, unshadowed), 0, -1)
    return np.moveaxis(combine_lights(grounds, skies, unshadowed, sky_total), 0, -1)


def sky_view_terms(context: FrameContext, views: np.ndarray, ground: GroundResult, *,
                   colour: int | None = None) -> list[GroundResult]:
    """The sky's ground rasters under the canopy, one per view, the sky weighted by the BRDF's shape.

    Every channel for the view ``colour`` (all of them when None), the channels' sum (one channel)
    for the others (``brdf_bands.banded_sky``); layers combined by the paper's product rule, each term
    with its own open-sky total.

    Parameters
    ----------
    context : FrameContext
        The frame: its plan (with a ground reflectance), sky, cycle products and threads.
    views : ndarray, shape (B, 3)
        View directions [1].
    ground : GroundResult
        The frame's ground with its ``coarse_sky`` (each layer's sky raster: an isolated layer's is
        weighted as it is, a periodic layer's made again unfolded, weighted, then folded).
    colour : int or None
        The view whose every channel is kept; None: all of them.

    Returns
    -------
    list of GroundResult
        Per view, on the coarse window, or under an isolated canopy on cells
        ``brdf_bands.band_factor`` times as wide (``shadow.coarser_isolated``) [radiance x sr].

    Raises
    ------
    ValueError
        Without a ground reflectance, or for a ground made without its ``coarse_sky``.
    """
    plan, workers = context.plan, context.workers
    brdf, kept = plan.ground.brdf, ground.coarse_sky
    if brdf is None or kept is None:
        raise ValueError("the sky's view terms need ground.brdf and the ground's coarse_sky")
    factor = brdf_bands.band_factor(plan)
    grounds, grid = [], plan.window
    views_of_first: list[SkyRaster] = []
    channels: list[SkyRaster] = []
    for index, (lp, spectra) in enumerate(zip(plan.layers, context.spectra)):
        coarse = lp.coarse
        if isinstance(coarse, shadow.PeriodicPlan):
            rasters = _view_rasters(context.sky.raster(coarse.sky), brdf, views, colour, factor, coarse.tile_shape)
            raster = _as_channels(rasters)
            g = shadow.ground_periodic(raster, spectra.coarse, coarse, spectra.mean, workers=workers)
        else:
            spectrum, layer_grid = spectra.coarse, plan.window
            if factor > 1:  # the bands at a coarser pixel: the sky's term is smooth (brdf_bands.band_factor)
                coarse, spectrum, layer_grid = shadow.coarser_isolated(spectrum, coarse, factor, plan.window)
                grid = layer_grid if index == 0 else grid
            rasters = _view_rasters(kept.rasters[index], brdf, views, colour, factor, None)
            raster = _as_channels(rasters)
            g = shadow.ground_isolated(raster, spectrum, coarse, workers=workers)
            g = g if layer_grid == grid else shadow.resample_bilinear(g, layer_grid, grid)
        grounds.append(g)
        channels.append(raster)
        views_of_first = views_of_first or rasters
    total = channels[0].irradiance
    split = np.cumsum([len(r.weighted) for r in views_of_first])[:-1]
    combined = _combined(grounds, total)
    return [GroundResult(g, grid, t, True)
            for g, t in zip(np.split(combined, split, axis=-1), np.split(total, split))]


def _view_rasters(raw: SkyRaster, brdf: BrdfConfig, views: np.ndarray, colour: int | None, factor: int,
                  fold_period: tuple[int, int] | None) -> list[SkyRaster]:
    """``raw`` weighted by the BRDF's shape for every view (``brdf_bands.weighted_raster``): every
    channel for the view ``colour`` (all when None), the channels' sum for the others."""
    return [brdf_bands.weighted_raster(raw, brdf, v, fold_period=fold_period,
                                       summed=colour is not None and t != colour, factor=factor)
            for t, v in enumerate(views)]


def _as_channels(rasters: list[SkyRaster]) -> SkyRaster:
    """Every view's weighted raster as the channels of one: one correlation call for all."""
    return SkyRaster(rasters[0].grid, np.concatenate([r.weighted for r in rasters]),
                     np.concatenate([np.asarray(r.outside, dtype=np.float64) for r in rasters]))


def _covers(inner: Grid, outer: Grid) -> bool:
    """Whether ``inner`` reaches over all of ``outer`` (to a hundredth of a pixel)."""
    a, b = inner.extent, outer.extent
    tol = 0.01 * outer.pixel
    return a[0] <= b[0] + tol and a[1] <= b[1] + tol and a[2] >= b[2] - tol and a[3] >= b[3] - tol


def _ground_of_layer(context: FrameContext, lp: LayerPlan, spectra: LayerSpectra, *, outer: bool,
                     parts: bool) -> LayerGround:
    """One layer's ground: the coarse sky light, plus the sun (``_with_sun``). ``outer``: also
    the coarse raster with the sun at the coarse cell; ``parts``: the sky part, the same raster
    before the sun's light is added."""
    sky, plan, workers = context.sky, context.plan, context.workers
    coarse = lp.coarse
    if isinstance(coarse, shadow.IsolatedPlan):
        grid = coarse.sky or sky_grid((0, 0), (1, 1), plan.window.pixel / lp.height)
        raster = sky.raster(grid)  # a 1 x 1 stand-in when no ray reaches the canopy
        g = shadow.ground_isolated(raster, spectra.coarse, coarse, workers=workers)
        exact = coarse.exact
    else:
        raster = sky.raster(coarse.sky, fold_period=coarse.tile_shape)
        g = shadow.ground_periodic(raster, spectra.coarse, coarse, spectra.mean, workers=workers)
        exact = True
    sky_light = LayerGround(g, raster.irradiance, exact, raster, g, sky_part=g if parts else None)
    return _with_sun(context, lp, spectra, sky_light, outer=outer, parts=parts)


def _with_sun(context: FrameContext, lp: LayerPlan, spectra: LayerSpectra, sky_light: LayerGround, *,
              outer: bool, parts: bool) -> LayerGround:
    """The layer's sky light ``sky_light`` with the sun's: the fine sun kernel on the sun window,
    or the open sun's light unshadowed; ``sky_light`` itself without either."""
    sky, plan, workers = context.sky, context.plan, context.workers
    g, total = sky_light.irradiance, sky_light.unshadowed
    sun = getattr(sky, "sun", None)
    if lp.sun is not None and sun_shades(sun):
        # a layer with a sun plan has a sun window and a fine spectrum (plan.LayerPlan, cycle.cycle_item)
        assert plan.sun_window is not None and spectra.fine is not None
        g_outer = g + _coarse_sun(context, lp, spectra) if outer else None
        kernel = sun_kernel(_sun_sky(sky), plan.sun_window.pixel / lp.height)
        g = shadow.resample_bilinear(g, plan.window, plan.sun_window)
        sky_part = g.copy() if parts else None
        shadow.ground_sun(kernel, spectra.fine, lp.sun, workers=workers, add_to=g)
        total = total + kernel.weighted.sum(axis=(1, 2), dtype=np.float64)
        return replace(sky_light, irradiance=g, unshadowed=total, outer=g_outer, sky_part=sky_part)
    # a sun under scene.SHADOW_FLOOR throws the canopy's shadow beyond the window: its light
    # reaches the window unshadowed; set (twilight), it gives none: the sky alone lights it
    if lp.sun is None and not sun_lights(sun):
        return sky_light
    light = np.asarray(sun_irradiance(_sun_sky(sky)), dtype=np.float64) if sun_lights(sun) else np.zeros(3)
    g_outer = g + light.astype(g.dtype)[:, None, None] if outer else None
    if lp.sun is not None:
        assert plan.sun_window is not None  # a layer with a sun plan has a sun window (plan.LayerPlan)
        g = shadow.resample_bilinear(g, plan.window, plan.sun_window)
    sky_part = g.copy() if parts else None
    g = g + light.astype(g.dtype)[:, None, None]
    return replace(sky_light, irradiance=g, unshadowed=total + light, outer=g_outer, sky_part=sky_part)


def _sun_sky(sky: Sky) -> ProceduralSky | EquirectSky:
    """``sky`` as ``sun_kernel`` takes it: a sky whose sun lights the ground (``scene.sun_lights``,
    ``sun_shades``) is one with a sun disc, a procedural sky or an HDRI's."""
    return cast("ProceduralSky | EquirectSky", sky)


def _coarse_sun(context: FrameContext, lp: LayerPlan, spectra: LayerSpectra) -> np.ndarray:
    """The sun's light through one layer on the coarse window (channels, rows, cols): its
    kernel at the coarse sky cell, correlated like the sky. [klx]"""
    sky, plan, workers = context.sky, context.plan, context.workers
    kernel = sun_kernel(_sun_sky(sky), plan.window.pixel / lp.height)
    coarse = lp.coarse
    if isinstance(coarse, shadow.PeriodicPlan):
        return shadow.ground_periodic(SkyRaster(kernel.grid, kernel.weighted, np.zeros(3)),
                                      spectra.coarse, coarse, spectra.mean, workers=workers)
    weighted = np.zeros((3, *coarse.sky.shape), dtype=np.float32) if coarse.sky else np.zeros((3, 1, 1), np.float32)
    block = None
    if coarse.sky is not None:  # the kernel's cells inside the sky square; the rest reach the ground
        dr, dc = np.subtract(sky_offset(kernel.grid), sky_offset(coarse.sky))
        rows, cols = kernel.weighted.shape[1:]
        r0, c0 = max(dr, 0), max(dc, 0)
        r1, c1 = min(dr + rows, coarse.sky.shape[0]), min(dc + cols, coarse.sky.shape[1])
        if r1 > r0 and c1 > c0:
            block = kernel.weighted[:, r0 - dr:r1 - dr, c0 - dc:c1 - dc]
            weighted[:, r0:r1, c0:c1] = block
    inside = weighted.sum(axis=(1, 2), dtype=np.float64)  # the whole raster's sum, as SkyRaster.irradiance's
    outside = kernel.weighted.sum(axis=(1, 2), dtype=np.float64) - inside
    if block is not None:  # only the kernel's rows transformed: the same bits (shadow.ground_isolated_block)
        return shadow.ground_isolated_block(block, (r0, c0), inside + outside, spectra.coarse, coarse,
                                            workers=workers)
    raster = SkyRaster(coarse.sky or sky_grid((0, 0), (1, 1), kernel.grid.pixel), weighted, outside)
    return shadow.ground_isolated(raster, spectra.coarse, coarse, workers=workers)


# ---------------------------------------------------------------------------------------------
# The fine ground given way to the coarse one at the sun window's edge
# ---------------------------------------------------------------------------------------------


BLEND_BAND_PIXELS = 8
"""Least width of the band, in coarse ground pixels, inside the sun window's edge over which the
fine sun-resolved ground gives way to the coarse ground (``blend_band``). [pixel]"""

BLEND_BAND_SHARE = (1 / 8, 1 / 4)
"""The band's width as shares of the sun window's shorter side: at least the first (so that at
full scale the change of texture is spread over a good part of the view), at most the second
(so that a small preview window keeps its middle half sun-resolved). [1]"""


def blend_band(fine: np.ndarray, fine_grid: Grid, coarse: np.ndarray, coarse_grid: Grid) -> np.ndarray:
    """The fine ground raster with a band inside its edges where it gives way to the coarse one.

    The coarse raster is resampled bilinearly onto the fine grid, so that the camera, which reads
    the fine raster inside the sun window and the coarse one beyond it, shows no seam at the
    window's edge (issue: a rectangle where sharp sun flecks meet blurred ones).

    Width: ``b = clip(max(BLEND_BAND_PIXELS coarse pixels, BLEND_BAND_SHARE[0] s), ...,
    BLEND_BAND_SHARE[1] s)``, s the window's shorter side [m]. Weight of the fine raster at a
    pixel centre at distance d from the nearest edge: ``w = smoothstep(d / b) = t^2 (3 - 2 t)``,
    t = clip(d / b, 0, 1): 0 at the edge (where the coarse raster takes over), 1 from the
    band's inner side on, with zero slope at both ends. Both rasters hold the same light
    (the fine sun kernel and the coarse one have the same sum), so the blend keeps the mean.

    Parameters
    ----------
    fine : ndarray, shape (rows, cols, 3), float32
        The fine ground raster [klx].
    fine_grid : Grid
        Its grid (the sun window) [m].
    coarse : ndarray, shape (r, c, 3), float32
        The coarse ground raster [klx].
    coarse_grid : Grid
        Its grid (the window) [m].

    Returns
    -------
    ndarray, shape (rows, cols, 3), float32
        The blend [klx].
    """
    weight, rest = _band_weights(fine_grid, coarse_grid.pixel)
    under = np.moveaxis(shadow.resample_bilinear(np.moveaxis(coarse, -1, 0), coarse_grid, fine_grid), 0, -1)
    out = weight * fine  # float32 throughout: w f + (1 - w) u
    out += rest * under
    return out


@functools.lru_cache(maxsize=4)
def _band_weights(fine_grid: Grid, coarse_pixel: float) -> tuple[np.ndarray, np.ndarray]:
    """``blend_band``'s weight w of the fine raster (rows, cols, 1) float32 and 1 - w: they depend
    on the grids alone, so the frames of a run make them once. Read-only."""
    rows, cols = fine_grid.shape
    shorter = min(rows, cols) * fine_grid.pixel
    width = max(BLEND_BAND_PIXELS * coarse_pixel, BLEND_BAND_SHARE[0] * shorter)
    width = min(width, BLEND_BAND_SHARE[1] * shorter)
    across = lambda n: (np.minimum(np.arange(n), n - 1 - np.arange(n)) + 0.5) * fine_grid.pixel  # noqa: E731
    t = np.clip(np.minimum(across(rows)[:, None], across(cols)[None, :]) / width, 0.0, 1.0)
    weight = (t * t * (3.0 - 2.0 * t)).astype(np.float32)[..., None]
    rest = 1.0 - weight
    for array in (weight, rest):
        array.flags.writeable = False
    return weight, rest
