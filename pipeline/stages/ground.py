"""The ground stage: the irradiance on the ground under one frame's sky, the correlation of the
sky raster with each canopy layer's cached spectrum at the coarse scale and of the sun kernel
with the fine mask spectrum on the sun window (Max 1991, Fig. 7 and section 3; docs/method.md,
"Two scales"). Takes the RunPlan, the frame's sky and the cache."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from pipeline.cache import store as cache
from pipeline.core.cores import default_workers
from pipeline.core.geometry import Grid, sky_grid, sky_offset
from pipeline.ground import brdf_bands, shadow
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_kernel import sun_irradiance, sun_kernel
from pipeline.stages.cycle import cycle_item
from pipeline.stages.plan import LayerPlan, RunPlan
from pipeline.stages.scene import sun_lights, sun_shades

__all__ = ["GroundResult", "render_ground", "sky_view_terms", "BLEND_BAND_PIXELS", "BLEND_BAND_SHARE", "blend_band"]


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
    outer : tuple or None
        (raster (rows, cols, 3) [klx], its Grid): the coarse raster of the whole window with the sun
        at the coarse cell, where the sun window does not cover it (``render_ground(outer=True)``);
        else None.
    sky_part : GroundResult or None
        The same ground lit by the sky alone, without the sun kernel (a GroundResult whose sky_part
        is None), when ``render_ground`` was asked for ``parts``, else None.
    coarse_sky : tuple or None
        The sky's own share on the coarse window (below), else None.
    """

    irradiance: np.ndarray
    grid: Grid
    unshadowed: np.ndarray
    exact: bool
    outer: tuple[np.ndarray, Grid] | None = None
    sky_part: GroundResult | None = None

    def sun_part(self) -> GroundResult:
        """The ground's light from the sun alone: this ground less its ``sky_part``.

        Every raster and total in float32 as subtracted (the two parts sum to this ground to float
        rounding).

        Returns
        -------
        GroundResult
            The sun's part [radiance x sr], without ``sky_part``.
        """
        sky = self.sky_part
        outer = None if self.outer is None else (self.outer[0] - sky.outer[0], self.outer[1])
        return GroundResult(self.irradiance - sky.irradiance, self.grid,
                            np.asarray(self.unshadowed) - np.asarray(sky.unshadowed), self.exact, outer)
    coarse_sky: tuple | None = None
    """With ``render_ground(coarse_sky=True)``: (sky-only ground (rows, cols, 3) on the coarse
    window [radiance x sr], its open-sky total (3,), each layer's sky raster as correlated),
    for a ground reflectance's sky term (``sky_view_terms``, ``brdf_bands.weighted_raster``)."""


def render_ground(plan: RunPlan, frame: int = 0, *, store: cache.Cache | None = None,
                  workers: int | None = None, sky=None, outer: bool = False,
                  parts: bool = False, coarse_sky: bool = False) -> GroundResult:
    """Ground irradiance at an output frame, every canopy layer under the sky.

    The coarse sky raster, and the fine sun kernel where the sky has a sun; layers combined by the
    paper's product rule.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    frame : int
        Output frame index.
    store : cache.Cache or None
        Where the cycle products come from (computed on a miss); None: the default cache.
    workers : int or None
        FFT threads; None: ``cores.default_workers``.
    sky : sky.Sky or None
        The frame's sky, loaded when not given.
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
    plan = plan.at(frame)  # a following camera's sun window (docs/method.md, "Framing")
    workers = workers or default_workers()
    store = store or cache.Cache(cache.cache_dir(None))
    sky = sky or plan.sky.at(plan.scenes[frame])
    cycle_frame = frame % plan.canopy.cycle
    outer = outer and plan.sun_window is not None and not _covers(plan.sun_window, plan.window)
    grounds, outers, totals, exact, skies, coarse_skies = [], [], [], True, [], []
    for index, layer_plan in enumerate(plan.layers):
        item = cycle_item(plan, index, cycle_frame, store, workers=workers)
        g, total, layer_exact, g_outer, sky_only = _ground_of_layer(
            sky, layer_plan, item, plan, workers, outer, parts, coarse_skies if coarse_sky else None)
        grounds.append(g)
        outers.append(g_outer)
        totals.append(total)
        skies.append(sky_only)
        exact &= layer_exact
    combined = shadow.combine_layers(grounds, totals[0])
    grid = plan.sun_window or plan.window
    around = None
    if outer:
        around = (np.moveaxis(shadow.combine_layers(outers, totals[0]), 0, -1), plan.window)
    sky_part = None
    if parts:
        sky_total = skies[0][1]
        sky_around = None
        if outer:
            sky_around = (np.moveaxis(shadow.combine_layers([s[2] for s in skies], sky_total), 0, -1), plan.window)
        sky_part = GroundResult(np.moveaxis(shadow.combine_layers([s[0] for s in skies], sky_total), 0, -1),
                                grid, sky_total, exact, sky_around)
    kept = None
    if coarse_sky:  # (coarse sky-only ground, raster) per layer
        sky_total = coarse_skies[0][1].irradiance
        kept = (np.moveaxis(shadow.combine_layers([g for g, _ in coarse_skies], sky_total), 0, -1), sky_total,
                tuple(r for _, r in coarse_skies))
    return GroundResult(np.moveaxis(combined, 0, -1), grid, totals[0], exact, around, sky_part, kept)


def sky_view_terms(plan: RunPlan, frame: int, sky, store: cache.Cache, workers: int, views,
                   ground: GroundResult, *, colour: int | None = None) -> list:
    """The sky's ground rasters under the canopy, one per view, the sky weighted by the BRDF's shape.

    Every channel for the view ``colour`` (all of them when None), the channels' sum (one channel)
    for the others (``brdf_bands.banded_sky``); layers combined by the paper's product rule, each term
    with its own open-sky total.

    Parameters
    ----------
    plan, frame
        As in ``render_ground``.
    sky : sky.Sky
        The frame's sky.
    store : cache.Cache
        The cache of the cycle products.
    workers : int
        FFT threads.
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
    """
    brdf = plan.ground.brdf
    cycle_frame = frame % plan.canopy.cycle
    factor = brdf_bands.band_factor(plan)
    grounds, total, grid = [], None, plan.window
    for index, lp in enumerate(plan.layers):
        item = cycle_item(plan, index, cycle_frame, store, workers=workers)
        coarse = lp.coarse
        periodic = isinstance(coarse, shadow.PeriodicPlan)
        raw = sky.raster(coarse.sky) if periodic else ground.coarse_sky[2][index]
        spectrum, layer_grid = item["coarse"], plan.window
        if factor > 1:  # the bands at a coarser pixel: the sky's term is smooth (brdf_bands.band_factor)
            coarse, spectrum, layer_grid = shadow.coarser_isolated(spectrum, coarse, factor, plan.window)
            grid = layer_grid if index == 0 else grid
        # every view's weighted raster as channels of one: one correlation call for all
        rasters = [brdf_bands.weighted_raster(raw, brdf, v, fold_period=coarse.tile_shape if periodic else None,
                                              summed=colour is not None and t != colour, factor=factor)
                   for t, v in enumerate(views)]
        raster = SkyRaster(rasters[0].grid, np.concatenate([r.weighted for r in rasters]),
                                      np.concatenate([np.asarray(r.outside, dtype=np.float64) for r in rasters]))
        if periodic:
            g = shadow.ground_periodic(raster, item["coarse"], coarse, float(item["mean"][0]), workers=workers)
        else:
            g = shadow.ground_isolated(raster, spectrum, coarse, workers=workers)
            g = g if layer_grid == grid else shadow.resample_bilinear(g, layer_grid, grid)
        grounds.append(g)
        if total is None:
            total, split = raster.irradiance, np.cumsum([len(r.weighted) for r in rasters])[:-1]
    combined = np.moveaxis(shadow.combine_layers(grounds, total), 0, -1)
    return [GroundResult(g, grid, t, True)
            for g, t in zip(np.split(combined, split, axis=-1), np.split(total, split))]


def _covers(inner: Grid, outer: Grid) -> bool:
    """Whether ``inner`` reaches over all of ``outer`` (to a hundredth of a pixel)."""
    a, b = inner.extent, outer.extent
    tol = 0.01 * outer.pixel
    return a[0] <= b[0] + tol and a[1] <= b[1] + tol and a[2] >= b[2] - tol and a[3] >= b[3] - tol


def _ground_of_layer(sky, lp: LayerPlan, item, plan: RunPlan, workers, outer=False, parts=False, keep=None):
    """(ground raster, unshadowed total, exact, outer raster or None, sky part or None) of one
    layer: the coarse sky light, plus the fine sun kernel on the sun window; with ``outer``
    also the coarse raster with the sun kernel at the coarse cell; with ``parts`` the sky part
    (raster, total, outer raster or None): the same rasters before the sun's light is added.
    ``keep``, a list: appends (the coarse sky light, its sky raster), neither written to
    afterwards (a ground reflectance's sky term)."""
    coarse = lp.coarse
    if isinstance(coarse, shadow.IsolatedPlan):
        grid = coarse.sky or sky_grid((0, 0), (1, 1), plan.window.pixel / lp.height)
        raster = sky.raster(grid)  # a 1 x 1 stand-in when no ray reaches the canopy
        g = shadow.ground_isolated(raster, item["coarse"], coarse, workers=workers)
        exact = coarse.exact
    else:
        raster = sky.raster(coarse.sky, fold_period=coarse.tile_shape)
        g = shadow.ground_periodic(raster, item["coarse"], coarse, float(item["mean"][0]),
                                   workers=workers)
        exact = True
    total = raster.irradiance
    if keep is not None:
        keep.append((g, raster))
    g_outer = None
    sky_only = (g, total, g) if parts else None
    sun = getattr(sky, "sun", None)
    if lp.sun is not None and sun_shades(sun):
        if outer:
            g_outer = g + _coarse_sun(sky, lp, item, plan, workers)
        kernel = sun_kernel(sky, plan.sun_window.pixel / lp.height)
        g = shadow.resample_bilinear(g, plan.window, plan.sun_window)
        if parts:
            sky_only = (g.copy(), total, sky_only[2])
        g += shadow.ground_sun(kernel, item["fine"], lp.sun, workers=workers)
        total = total + kernel.weighted.sum(axis=(1, 2), dtype=np.float64)
        return g, total, exact, g_outer, sky_only
    # a sun under scene.SHADOW_FLOOR throws the canopy's shadow beyond the window: its light
    # reaches the window unshadowed; set (twilight), it gives none: the sky alone lights it
    if lp.sun is None and not sun_lights(sun):
        return g, total, exact, g_outer, sky_only
    light = np.asarray(sun_irradiance(sky), dtype=np.float64) if sun_lights(sun) else np.zeros(3)
    if outer:
        g_outer = g + light.astype(g.dtype)[:, None, None]
    if lp.sun is not None:
        g = shadow.resample_bilinear(g, plan.window, plan.sun_window)
    if parts:
        sky_only = (g.copy(), total, sky_only[2])
    g = g + light.astype(g.dtype)[:, None, None]
    return g, total + light, exact, g_outer, sky_only


def _coarse_sun(sky, lp: LayerPlan, item, plan: RunPlan, workers):
    """The sun's light through one layer on the coarse window (channels, rows, cols): its
    kernel at the coarse sky cell, correlated like the sky. [klx]"""
    kernel = sun_kernel(sky, plan.window.pixel / lp.height)
    coarse = lp.coarse
    if isinstance(coarse, shadow.PeriodicPlan):
        return shadow.ground_periodic(SkyRaster(kernel.grid, kernel.weighted, np.zeros(3)),
                                      item["coarse"], coarse, float(item["mean"][0]), workers=workers)
    weighted = np.zeros((3, *coarse.sky.shape), dtype=np.float32) if coarse.sky else np.zeros((3, 1, 1), np.float32)
    if coarse.sky is not None:  # the kernel's cells inside the sky square; the rest reach the ground
        dr, dc = np.subtract(sky_offset(kernel.grid), sky_offset(coarse.sky))
        rows, cols = kernel.weighted.shape[1:]
        r0, c0 = max(dr, 0), max(dc, 0)
        r1, c1 = min(dr + rows, coarse.sky.shape[0]), min(dc + cols, coarse.sky.shape[1])
        if r1 > r0 and c1 > c0:
            weighted[:, r0:r1, c0:c1] = kernel.weighted[:, r0 - dr:r1 - dr, c0 - dc:c1 - dc]
    outside = kernel.weighted.sum(axis=(1, 2), dtype=np.float64) - weighted.sum(axis=(1, 2), dtype=np.float64)
    raster = SkyRaster(coarse.sky or sky_grid((0, 0), (1, 1), kernel.grid.pixel),
                                  weighted, outside)
    return shadow.ground_isolated(raster, item["coarse"], coarse, workers=workers)


# ---------------------------------------------------------------------------------------------
# The finished frame: camera, foreground, compositing (Max 1991, Figs. 10 and 13)
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
