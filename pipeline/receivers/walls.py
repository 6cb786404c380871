"""A config's wall as a receiver: its plane, its layers (its masks and the procedural grove turned
into its frame) and its light at a frame, on a raster over the whole wall (docs/method.md,
"Receivers: walls and slopes").
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import replace as dataclass_replace
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy.grove import FlutterParams, Grove
from pipeline.canopy.masks import transmittance_from_image
from pipeline.config.receivers import WALL_ALBEDOS, WallConfig
from pipeline.core import io
from pipeline.core.errors import ImageError
from pipeline.core.geometry import Grid
from pipeline.ground.layers import combine_lights
from pipeline.ground.shadow import (
    IsolatedPlan,
    SunPlan,
    fine_mask_spectrum,
    ground_isolated,
    ground_sun,
    occlusion_spectrum,
    plan_isolated,
    plan_sun,
    resample_bilinear,
)
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, hemisphere_raster, world_radiance
from pipeline.receivers.layers import Layer, grove_in_frame, grove_layers, mask_layer
from pipeline.receivers.light import covering_alpha, unshadowed_on
from pipeline.receivers.plane import ReceiverPlane, wall
from pipeline.receivers.sun import (
    kernel_block,
    receiver_disc_layout,
    receiver_sun_irradiance,
    receiver_sun_kernel,
    receiver_sun_point,
    sun_lights,
)
from pipeline.sky.base import Sky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.raster import SkyRaster

__all__ = ["COARSE_FACTOR", "WallLight", "wall_plane", "wall_layers", "wall_light", "wall_albedo_colour",
           "WallLayerPlan", "WallPlan", "wall_plan", "WallSpectra", "wall_spectra",
           "wall_light_from", "sky_key", "kept_by_sky"]

T = TypeVar("T")

COARSE_FACTOR = 4
"""A wall's coarse (sky) raster's pixel over its fine raster's. [1]"""


@dataclass(frozen=True)
class WallLight:
    """A wall's irradiance at a frame.

    Attributes
    ----------
    plane : ReceiverPlane
        The wall.
    grid : Grid
        Its raster, in the wall's (u, w) coordinates: u across (0 at the foot's middle), w up from
        the foot; row 0 at the top [m].
    irradiance : numpy.ndarray
        (rows, cols, 3) float32 on ``grid`` [radiance x sr; klx under a procedural sky].
    sky_unshadowed, sun_unshadowed : numpy.ndarray
        (3,) the open wall's light from its hemisphere and from the sun [radiance x sr].
    """

    plane: ReceiverPlane
    grid: Grid
    irradiance: np.ndarray
    sky_unshadowed: np.ndarray
    sun_unshadowed: np.ndarray


def wall_plane(config: WallConfig, where: str = "receivers.walls[0]") -> ReceiverPlane:
    """The plane of a config's wall.

    Parameters
    ----------
    config : config.receivers.WallConfig
        The wall.
    where : str, optional
        Its key, for the errors.

    Returns
    -------
    ReceiverPlane
        With its width and height [m].
    """
    return wall(config.foot, facing=config.facing, width=config.width, height=config.height, tilt=config.tilt,
                where=where)


def wall_layers(config: WallConfig, plane: ReceiverPlane, sky: Sky | None, *,
                grove: tuple[Grove, FlutterParams] | None, cycle_frame: int, where: str = "receivers.walls[0]",
                sun: tuple[float, float] | None = None) -> list[Layer]:
    """A wall's occluders: its mask layers, and the grove's leaves and wood in front of it drawn
    into one layer at their median distance along its normal, projected along the sun.

    One layer for the grove: the product rule over several layers multiplies each layer's loss of
    the sun (docs/accuracy.md, "Receivers: walls and slopes").

    Parameters
    ----------
    config : config.receivers.WallConfig
        The wall.
    plane : ReceiverPlane
        Its plane (``wall_plane``).
    sky : sky.base.Sky or None
        The frame's sky (the sun's direction for the projection); None with ``sun``.
    grove : (canopy.grove.Grove, canopy.grove.FlutterParams) or None
        An isolated procedural grove in world axes and its flutter; None: none.
    cycle_frame : int
        The flutter's frame [frames].
    where : str, optional
        The wall's key, for the errors.
    sun : (float, float) or None, optional
        The wall's sky-plane point to project the grove along [tan]; None: the sky's sun's
        (``sun.receiver_sun_point``), or along the normal where it does not light the wall.

    Returns
    -------
    list of Layer
        Nearest the wall first; empty for an open wall.
    """
    layers: list[Layer] = []
    for i, m in enumerate(config.masks):
        image = io.read_finite_image(m.image, "mask")
        try:
            transmittance = transmittance_from_image(image)
        except ValueError as exc:
            raise ImageError(m.image, str(exc)) from None
        layers.append(mask_layer(transmittance, center=m.center, size=m.size, distance=m.distance,
                                 where=f"{where}.masks[{i}]"))
    if grove is not None:
        turned = grove_in_frame(grove[0], plane)
        front = turned.leaves.center[:, 2]
        front = front[front > 0.0]
        if len(front):
            if sun is None:
                if sky is None:
                    raise ValueError("wall_layers needs the sky or the sun's point to project the grove along")
                s = receiver_sun_point(sky, plane) if sun_lights(sky, plane) else np.zeros(2)
                sun = (float(s[0]), float(s[1]))
            layers += grove_layers(turned, grove[1], cycle_frame, distances=(float(np.median(front)),), sun=sun)
    return sorted(layers, key=lambda layer: layer.distance)


def wall_albedo_colour(config: WallConfig) -> np.ndarray:
    """A wall's mean albedo: its preset's or its colour (an image's is read where it is drawn).

    Parameters
    ----------
    config : config.receivers.WallConfig
        The wall.

    Returns
    -------
    numpy.ndarray
        (3,) linear RGB [1].

    Raises
    ------
    ValueError
        For a wall whose albedo is an image.
    """
    if isinstance(config.albedo, str):
        return np.asarray(WALL_ALBEDOS[config.albedo], dtype=np.float64)
    if isinstance(config.albedo, tuple):
        return np.asarray(config.albedo, dtype=np.float64)
    raise ValueError("the wall's albedo is an image")


def wall_light(config: WallConfig, sky: Sky, *, ground_albedo: ArrayLike, open_ground: ArrayLike,
               grove: tuple[Grove, FlutterParams] | None = None, cycle_frame: int = 0,
               where: str = "receivers.walls[0]", workers: int = 1) -> WallLight:
    """A wall's irradiance at a frame over the whole wall, at its ``pixel``, its layers drawn for
    this frame alone (a run reads them from its cycle products: ``wall_plan``, ``wall_spectra``).

    The light below its horizon is the open ground's mean radiance (``hemisphere.ground_radiance``:
    ``ground_albedo`` x ``open_ground`` / pi), the first approximation. The sky raster's pixel is
    ``COARSE_FACTOR`` times the fine one's.

    Parameters
    ----------
    config : config.receivers.WallConfig
        The wall.
    sky : sky.base.Sky
        The frame's sky.
    ground_albedo : numpy.ndarray
        (3,) or scalar, the ground's mean albedo [1].
    open_ground : numpy.ndarray
        (3,) the open ground's irradiance, sky and sun [radiance x sr].
    grove : (Grove, FlutterParams) or None, optional
        An isolated procedural grove and its flutter.
    cycle_frame : int, optional
        The flutter's frame [frames].
    where : str, optional
        The wall's key, for the errors.
    workers : int, optional
        FFT threads.

    Returns
    -------
    WallLight
        [radiance x sr].
    """
    plan = wall_plan(config, sky, grove=grove, suns=(sky,), where=where)
    spectra = wall_spectra(config, plan, grove=grove, cycle_frame=cycle_frame, where=where, workers=workers)
    light = wall_light_from(plan, spectra, sky, ground_radiance(ground_albedo, open_ground), workers=workers)
    assert light is not None  # planned for this very sky
    return light


@dataclass(frozen=True)
class WallLayerPlan:
    """One of a wall's layers, planned for a run: where it lies and how it is correlated.

    Attributes
    ----------
    distance : float
        Its plane's along the wall's normal [m].
    cells : Grid
        The coarse lattice's cells it can touch at any flutter frame [m].
    coarse : ground.shadow.IsolatedPlan
        Its correlation with the hemisphere raster on the wall's coarse grid.
    sun : ground.shadow.SunPlan or None
        Its fine mask's correlation with the sun's kernel for every sun of the run that lights the
        wall; None where none does.
    """

    distance: float
    cells: Grid
    coarse: IsolatedPlan
    sun: SunPlan | None


@dataclass(frozen=True)
class WallPlan:
    """A wall's rasters and layers for a run (``wall_plan``): what its cycle products depend on.

    Attributes
    ----------
    plane : ReceiverPlane
        The wall.
    fine, coarse : Grid
        Its rasters over the whole wall, at ``pixel`` and ``COARSE_FACTOR`` times it [m].
    sun : tuple of (float, float)
        The point of the wall's sky plane the grove's layer is projected along [tan].
    layers : tuple of WallLayerPlan
        Nearest the wall first; empty for an open wall.
    """

    plane: ReceiverPlane
    fine: Grid
    coarse: Grid
    sun: tuple[float, float]
    layers: tuple[WallLayerPlan, ...]


def wall_plan(config: WallConfig, sky: Sky, *, grove: tuple[Grove, FlutterParams] | None,
              suns: Sequence[Sky], where: str = "receivers.walls[0]") -> WallPlan:
    """A wall's rasters and layers for a run: each layer's cells, its coarse correlation's plan and
    its fine one's for every sun in ``suns`` that lights the wall.

    Parameters
    ----------
    config : config.receivers.WallConfig
        The wall.
    sky : sky.base.Sky
        The sky whose sun the grove's layer is projected along (a run's middle frame's, as the
        ground's canopy is: ``stages.plan``).
    grove : (Grove, FlutterParams) or None
        An isolated procedural grove and its flutter.
    suns : sequence of sky.base.Sky
        The skies of the frames the fine plan must hold the sun's kernel of.
    where : str, optional
        The wall's key, for the errors.

    Returns
    -------
    WallPlan
        The plan [m].
    """
    plane = wall_plane(config, where)
    extent = (-config.width / 2, 0.0, config.width / 2, config.height)
    fine = Grid.from_window(extent, config.pixel)
    coarse = Grid.from_window(extent, config.pixel * COARSE_FACTOR)
    s = receiver_sun_point(sky, plane) if sun_lights(sky, plane) else np.zeros(2)
    planned = []
    for layer in wall_layers(config, plane, sky, grove=grove, cycle_frame=0, where=where):
        _, cells = layer.occlusion_on(coarse)
        alpha = covering_alpha(coarse, cells, layer.distance)
        offsets = [kernel_block(receiver_disc_layout(lit, plane, fine.pixel / layer.distance)[0])  # without drawing it
                   for lit in suns if sun_lights(lit, plane)]
        sun = None
        if offsets:
            lo = (min(o[0][0] for o in offsets), min(o[0][1] for o in offsets))
            hi = (max(o[1][0] for o in offsets), max(o[1][1] for o in offsets))
            sun = plan_sun(fine, offset_lo=lo, offset_hi=hi)
        planned.append(WallLayerPlan(layer.distance, cells,
                                     plan_isolated(coarse, cells, height=layer.distance, alpha=alpha), sun))
    return WallPlan(plane, fine, coarse, (float(s[0]), float(s[1])), tuple(planned))


@dataclass(frozen=True)
class WallSpectra:
    """A wall's layers' spectra at one flutter frame: its cycle products.

    Attributes
    ----------
    coarse : tuple of numpy.ndarray
        Per layer, the occlusion spectrum on its ``WallLayerPlan.coarse`` (complex64) [1].
    fine : tuple of (numpy.ndarray or None)
        Per layer, its fine mask's spectrum on its ``WallLayerPlan.sun`` (complex64), None without one [1].
    """

    coarse: tuple[np.ndarray, ...]
    fine: tuple[np.ndarray | None, ...]


def wall_spectra(config: WallConfig, plan: WallPlan, *, grove: tuple[Grove, FlutterParams] | None,
                 cycle_frame: int, where: str = "receivers.walls[0]", workers: int = 1) -> WallSpectra:
    """A wall's layers drawn at a flutter frame and transformed: the occlusion on each layer's
    cells and its transmittance on its fine plan's mask, as ``plan`` plans them.

    Parameters
    ----------
    config : config.receivers.WallConfig
        The wall.
    plan : WallPlan
        Its plan (``wall_plan``).
    grove : (Grove, FlutterParams) or None
        The grove ``plan`` was made with.
    cycle_frame : int
        The flutter's frame [frames].
    where : str, optional
        The wall's key, for the errors.
    workers : int, optional
        FFT threads.

    Returns
    -------
    WallSpectra
        complex64 [1].
    """
    layers = _planned_layers(config, plan, grove, cycle_frame, where)
    coarse, fine = [], []
    for layer, lp in zip(layers, plan.layers):
        occlusion, cells = layer.occlusion_on(plan.coarse)
        if cells != lp.cells:
            raise ValueError(f"{where}: the layer at {lp.distance:g} m moved off its planned cells")
        coarse.append(occlusion_spectrum(occlusion, lp.coarse, workers=workers))
        fine.append(None if lp.sun is None else
                    fine_mask_spectrum(layer.transmittance_on(lp.sun.mask), lp.sun, workers=workers))
    return WallSpectra(tuple(coarse), tuple(fine))


def _planned_layers(config: WallConfig, plan: WallPlan, grove: tuple[Grove, FlutterParams] | None,
                    cycle_frame: int, where: str) -> list[Layer]:
    """``wall_layers`` at a flutter frame, the grove's projected along the plan's sun."""
    layers = wall_layers(config, plan.plane, None, grove=grove, cycle_frame=cycle_frame, where=where, sun=plan.sun)
    if [layer.distance for layer in layers] != [lp.distance for lp in plan.layers]:
        raise ValueError(f"{where}: the wall's layers are not those of its plan")
    return layers


def wall_light_from(plan: WallPlan, spectra: WallSpectra, sky: Sky, ground: ArrayLike, *,
                    workers: int = 1) -> WallLight | None:
    """A wall's irradiance at a frame from its layers' spectra: Max's correlation in its frame
    (as ``light.receiver_light``), the sun's fine kernel through each layer's fine mask.

    Parameters
    ----------
    plan : WallPlan
        The wall's plan.
    spectra : WallSpectra
        Its layers' spectra at the frame's flutter frame (``wall_spectra``, or the cache's).
    sky : sky.base.Sky
        The frame's sky.
    ground : numpy.ndarray
        (3,) the ground's radiance below the wall's horizon [radiance].
    workers : int, optional
        FFT threads.

    Returns
    -------
    WallLight or None
        [radiance x sr]; None where the sun's kernel at this frame lies outside a layer's fine plan
        (a sun the plan was not made for).
    """
    plane, fine, window = plan.plane, plan.fine, plan.coarse
    sky_total = np.array(kept_by_sky(_open_light, sky, _values(ground), plane))
    lit = sun_lights(sky, plane)
    sun_total = np.array(kept_by_sky(_sun_on, sky, plane)) if lit else np.zeros(3)
    if not plan.layers:
        image = np.broadcast_to((sky_total + sun_total).astype(np.float32), (*fine.shape, 3)).copy()
        return WallLight(plane, fine, image, sky_total, sun_total)
    coarse, fined, skies = [], [], []  # skies: each layer's sky part, where there are several
    for lp, spectrum, fine_spectrum in zip(plan.layers, spectra.coarse, spectra.fine):
        if lp.coarse.sky is None:
            g = unshadowed_on(window, sky_total)
        else:
            raster = kept_by_sky(_hemisphere, sky, _values(ground), plane, lp.coarse.sky)
            g = ground_isolated(raster, spectrum, lp.coarse, workers=workers)
        coarse.append(g)
        sun: np.ndarray | float = 0.0
        if lit:
            kernel = kept_by_sky(_kernel, sky, plane, fine.pixel / lp.distance)
            if lp.sun is None or fine_spectrum is None or not _inside(kernel, lp.sun):
                return None
            sun = ground_sun(kernel, fine_spectrum, lp.sun, workers=workers)
        seen = resample_bilinear(g, window, fine)
        skies += [seen.copy()] if len(plan.layers) > 1 else []
        if isinstance(sun, np.ndarray) and sun.dtype == seen.dtype:
            seen += sun  # in place: the bits of seen + sun
        else:
            seen = seen + sun
        fined.append(seen)
    # one layer: its raster itself, not a copy
    total = fined[0] if len(fined) == 1 else combine_lights(fined, skies, sky_total + sun_total, sky_total)
    return WallLight(plane, fine, np.ascontiguousarray(np.moveaxis(total, 0, -1)), sky_total, sun_total)


def _inside(kernel: SkyRaster, plan: SunPlan) -> bool:
    """Whether a sun kernel's block lies within a fine plan's offsets."""
    lo, hi = kernel_block(kernel.grid)
    return all(plan.offset_lo[i] <= lo[i] and hi[i] <= plan.offset_hi[i] for i in range(2))



def sky_key(sky: Sky) -> Sky:
    """The sky as a key of what depends on it: a procedural sky without clouds at time 0 (its time
    goes to its clouds alone), so that the frames of a still sun share their light's products.

    Parameters
    ----------
    sky : sky.base.Sky
        A frame's sky.

    Returns
    -------
    sky.base.Sky
        The same light.
    """
    if isinstance(sky, ProceduralSky) and sky.clouds is None and sky.time != 0.0:
        return dataclass_replace(sky, time=0.0)
    return sky


def kept_by_sky(function: Callable[..., T], sky: Sky, *args: Any) -> T:
    """``function(sky_key(sky), *args)`` for a function kept by ``functools.lru_cache`` (a run's sun
    and sky often stand still); computed each time for a sky that cannot be a key (an HDRI's arrays).

    Parameters
    ----------
    function : callable
        An ``lru_cache`` function of a sky and hashable arguments.
    sky : sky.base.Sky
        The sky.
    *args
        Its other arguments.

    Returns
    -------
    object
        What ``function`` returns.
    """
    key = sky_key(sky)
    try:
        return function(key, *args)
    except TypeError:
        return function.__wrapped__(key, *args)  # type: ignore[attr-defined]


def _values(ground: ArrayLike) -> tuple[float, ...]:
    """A radiance (3,) as a key."""
    return tuple(float(v) for v in np.asarray(ground, dtype=np.float64).reshape(-1))


@functools.lru_cache(maxsize=8)
def _sun_on(sky: Sky, plane: ReceiverPlane) -> np.ndarray:
    """``receiver_sun_irradiance``, (3,) [radiance x sr]."""
    total = receiver_sun_irradiance(sky, plane)
    total.setflags(write=False)
    return total


@functools.lru_cache(maxsize=8)
def _kernel(sky: Sky, plane: ReceiverPlane, q: float) -> SkyRaster:
    """``receiver_sun_kernel``."""
    kernel = receiver_sun_kernel(sky, plane, q)
    kernel.weighted.setflags(write=False)
    return kernel


@functools.lru_cache(maxsize=8)
def _open_light(sky: Sky, ground: tuple[float, ...], plane: ReceiverPlane) -> np.ndarray:
    """The open receiver's light from its hemisphere (``hemisphere_irradiance``), (3,) [radiance x sr]."""
    total = hemisphere_irradiance(world_radiance(sky, np.array(ground)), plane)
    total.setflags(write=False)
    return total


@functools.lru_cache(maxsize=8)
def _hemisphere(sky: Sky, ground: tuple[float, ...], plane: ReceiverPlane, grid: Grid) -> SkyRaster:
    """``hemisphere_raster`` of the light around the receiver on ``grid`` of its sky plane."""
    raster = hemisphere_raster(world_radiance(sky, np.array(ground)), plane, grid)
    raster.weighted.setflags(write=False)
    return raster
