"""A sloped ground at a frame: its light by Max's correlation in its own frame (``receivers.slope``)
and its picture by the level ground's camera turned into that frame (docs/method.md, "A sloped
ground")."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from pipeline.camera import pinhole
from pipeline.config.settings import CanopyLayer
from pipeline.receivers.hemisphere import hemisphere_irradiance, world_radiance
from pipeline.receivers.layers import Layer, mask_layer
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import ReceiverPlane
from pipeline.receivers.slope import SkyInFrame, camera_in_frame, slope_layers, slope_plane
from pipeline.receivers.sun import receiver_sun_irradiance, sun_incidence
from pipeline.sky.base import Sky
from pipeline.stages.ground import FrameContext, GroundRaster, GroundResult
from pipeline.stages.inputs import ground_albedo, grove_of, load_mask
from pipeline.stages.plan import RunPlan
from pipeline.stages.slope_framing import below_radiance
from pipeline.texture.mipmap import MipMap

__all__ = ["plane_of", "layers_on_slope", "slope_ground", "slope_background", "OpenSlope", "open_slope"]


def plane_of(plan: RunPlan) -> ReceiverPlane:
    """The plan's slope.

    Parameters
    ----------
    plan : plan.RunPlan
        A plan with ``receivers.slope``.

    Returns
    -------
    receivers.plane.ReceiverPlane
        Its plane.
    """
    assert plan.receivers.slope is not None
    return slope_plane(plan.receivers.slope)


def _below(plan: RunPlan, sky: Sky) -> np.ndarray:
    """The radiance (3,) below the world's horizon: the open level ground's, albedo x its light / pi;
    kept for the last few skies, so that a frame's light and its picture read it once."""
    for kept, ground, value in _BELOW:
        if kept is sky and ground is plan.ground:
            return value
    value = below_radiance(plan.ground, sky)
    _BELOW[:] = [(sky, plan.ground, value), *_BELOW[:3]]
    return value


_BELOW: list[tuple[Sky, object, np.ndarray]] = []


def slope_ground(context: FrameContext) -> GroundResult:
    """The slope's irradiance at a frame, on the plan's windows read in the slope's (u, w) metres.

    The grove standing on the slope, turned into its frame, in one layer (``receivers.slope``);
    the hemisphere's light: the sky above the world's horizon, the open level ground's mean
    radiance below; the sun at the slope's incidence through the fine window, and at the coarse
    cell beyond it.

    Parameters
    ----------
    context : ground.FrameContext
        The frame.

    Returns
    -------
    ground.GroundResult
        On the sun window (the window without a sun), with the coarse raster as ``outer``
        [radiance x sr].
    """
    plan, sky = context.plan, context.sky
    plane = plane_of(plan)
    radiance = world_radiance(sky, _below(plan, sky))
    layers = layers_on_slope(plan, sky, context.cycle_frame)
    fine = plan.sun_window
    if not layers:
        sky_total = hemisphere_irradiance(radiance, plane)
        total = sky_total + (receiver_sun_irradiance(sky, plane) if fine is not None else 0.0)
        grid = plan.window if fine is None else fine
        image = np.broadcast_to(total.astype(np.float32), (*grid.shape, 3)).copy()
        return GroundResult(image, grid, total, True)
    x0, y0, x1, y1 = plan.window.extent
    covered = fine is not None and all(a <= b for a, b in zip(fine.extent[:2], (x0, y0))) \
        and all(a >= b for a, b in zip(fine.extent[2:], (x1, y1)))
    light = receiver_light(radiance, sky, plane, plan.window, layers, sun_window=fine,
                           coarse_sun=fine is not None and not covered, workers=context.workers)
    unshadowed = light.sky_unshadowed + light.sun_unshadowed
    if light.total is None:
        return GroundResult(_hwc(light.sky), plan.window, unshadowed, light.exact)
    assert fine is not None
    outer = None if light.outer is None else GroundRaster(_hwc(light.outer), plan.window)
    return GroundResult(_hwc(light.total), fine, unshadowed, light.exact, outer)


def layers_on_slope(plan: RunPlan, sky: Sky, cycle_frame: int) -> list[Layer]:
    """The slope's occluders at a frame: its mask layers parallel to it (``canopy.layers``: each
    image's centre and size in the slope's (u, w) metres, its top up the slope, its height along the
    slope's normal), or the trees standing on it in one layer (``receivers.slope.slope_layers``).

    Parameters
    ----------
    plan : plan.RunPlan
        A plan with ``receivers.slope``.
    sky : sky.base.Sky
        The frame's sky (the sun the grove is projected along).
    cycle_frame : int
        The flutter's frame (a mask sequence's image) [frames].

    Returns
    -------
    list of receivers.layers.Layer
        Nearest the slope first; none for an open slope.
    """
    c = plan.canopy
    if c.trees is None:
        return sorted((mask_layer(_mask(layer, cycle_frame % len(layer.mask)), center=layer.center, size=layer.size,
                                  distance=layer.height, where=f"canopy.layers[{i}]")
                       for i, layer in enumerate(c.layers)), key=lambda layer: layer.distance)
    return slope_layers(plane_of(plan), sky, grove_of(c, plan.receivers.slope), cycle_frame)


@functools.lru_cache(maxsize=8)
def _mask(layer: CanopyLayer, frame: int) -> np.ndarray:
    """A mask layer's transmittance at a frame of its sequence, read once a process (read-only)."""
    transmittance = load_mask(layer, frame)
    transmittance.flags.writeable = False
    return transmittance


def _hwc(raster: np.ndarray) -> np.ndarray:
    """(3, rows, cols) -> (rows, cols, 3) float32, contiguous."""
    return np.ascontiguousarray(np.moveaxis(raster, 0, -1), dtype=np.float32)


def slope_background(plan: RunPlan, maps: tuple[MipMap, ...], sky: Sky) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The slope and the sky in the camera's picture: the level ground's camera turned into the
    slope's frame (``receivers.slope.camera_in_frame``), the sky read by world direction.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan (its camera looks straight up or down the slope).
    maps : tuple of texture.mipmap.MipMap
        The slope's light (``slope_ground``) as the camera reads it (``frame.irradiance_maps``),
        in its (u, w) metres [radiance x sr].
    sky : sky.base.Sky
        The frame's sky.

    Returns
    -------
    radiance : numpy.ndarray
        (height, width, 3) float32 [radiance].
    distance : numpy.ndarray
        (height, width) float32: to the slope along each ray, inf for the sky [m].
    horizon : numpy.ndarray
        (width, 3) float32: the sky just above the slope's vanishing line in each column, what the
        far slope fades to in the haze [radiance].
    """
    plane = plane_of(plan)
    view = camera_in_frame(plan.camera, plane)
    turned = SkyInFrame(sky, plane, tuple(float(v) for v in _below(plan, sky)))  # type: ignore[arg-type]
    radiance, distance = pinhole.background(view, irradiance=maps,
                                            albedo=ground_albedo(plan.ground), sky=turned)
    return radiance, distance, pinhole.horizon_sky(view, turned)


@dataclass(frozen=True)
class OpenSlope:
    """The open slope's light at a frame, before any shade (``sunshade check``).

    Attributes
    ----------
    frame : int
        Output frame index.
    incidence : float
        cos of the sun's angle from the slope's normal (negative: behind it; 0 without a sun) [1].
    sun, sky : numpy.ndarray
        (3,) the open slope's light from the sun and from its hemisphere [radiance x sr].
    """

    frame: int
    incidence: float
    sun: np.ndarray
    sky: np.ndarray


def open_slope(plan: RunPlan, frames: Iterable[int]) -> list[OpenSlope]:
    """The open slope's light at each of ``frames``.

    Parameters
    ----------
    plan : plan.RunPlan
        A plan with ``receivers.slope``.
    frames : iterable of int
        Output frame indices.

    Returns
    -------
    list of OpenSlope
        Frame by frame.
    """
    plane = plane_of(plan)
    found = []
    for frame in frames:
        sky = plan.sky.at(plan.scenes[frame])
        found.append(OpenSlope(frame, sun_incidence(sky, plane), receiver_sun_irradiance(sky, plane),
                               hemisphere_irradiance(world_radiance(sky, _below(plan, sky)), plane)))
    return found
