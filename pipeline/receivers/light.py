"""A receiver's light by Max's correlation in its own frame: each layer's occlusion correlated with
the receiver's hemisphere raster (``ground.shadow``'s isolated correlation), the two-scale sun at
the receiver's own incidence through the layer's fine mask, layers combined by the product rule
(docs/method.md, "Receivers: walls and slopes").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.core.geometry import Grid
from pipeline.ground.layers import combine_layers, combine_lights
from pipeline.ground.shadow import (
    fine_mask_spectrum,
    ground_isolated,
    ground_sun,
    occlusion_spectrum,
    plan_isolated,
    plan_sun,
    resample_bilinear,
)
from pipeline.receivers.hemisphere import Radiance, hemisphere_irradiance, hemisphere_raster
from pipeline.receivers.layers import Layer
from pipeline.receivers.plane import ReceiverPlane
from pipeline.receivers.sun import kernel_block, receiver_sun_irradiance, receiver_sun_kernel, sun_lights
from pipeline.sky.base import Sky

__all__ = ["MAX_ALPHA", "ReceiverLight", "covering_alpha", "unshadowed_on", "receiver_light"]

MAX_ALPHA = float(np.radians(89.0))
"""Widest sky square ``covering_alpha`` gives a layer; beyond it the layer's light is taken as unshadowed. [rad]"""


@dataclass(frozen=True)
class ReceiverLight:
    """A receiver's irradiance at two scales.

    Attributes
    ----------
    window : Grid
        The receiver's coarse window, in its (u, w) plane coordinates [m].
    sky : numpy.ndarray
        (3, rows, cols) float32 on ``window``: the hemisphere's light (sky, and ground below the
        horizon) through the layers, no sun [radiance x sr].
    sun_window : Grid or None
        The fine window [m].
    total : numpy.ndarray or None
        (3, rows, cols) float32 on ``sun_window``: the sky resampled plus the sun, layers combined;
        None without a sun window [radiance x sr].
    sky_unshadowed, sun_unshadowed : numpy.ndarray
        (3,) the open receiver's light from the hemisphere and from the sun (zeros where it does not
        light it) [radiance x sr].
    exact : bool
        Every layer seen within its sky square from every window pixel.
    outer : numpy.ndarray or None
        (3, rows, cols) float32 on ``window``: the sky plus the sun at the coarse cell, layers
        combined (``receiver_light(coarse_sun=True)``; the camera reads it beyond the sun window);
        else None [radiance x sr].
    """

    window: Grid
    sky: np.ndarray
    sun_window: Grid | None
    total: np.ndarray | None
    sky_unshadowed: np.ndarray
    sun_unshadowed: np.ndarray
    exact: bool
    outer: np.ndarray | None = None


def covering_alpha(window: Grid, canopy: Grid, distance: float) -> float:
    """The half-angle of the sky square that sees all of ``canopy`` from every pixel of ``window``, at most MAX_ALPHA.

    Parameters
    ----------
    window, canopy : Grid
        The receiver's window and a layer's cells, one lattice [m].
    distance : float
        The layer's distance [m].

    Returns
    -------
    float
        alpha [rad].
    """
    wx0, wy0, wx1, wy1 = window.extent
    cx0, cy0, cx1, cy1 = canopy.extent
    reach = max(cx1 - wx0, wx1 - cx0, cy1 - wy0, wy1 - cy0) + window.pixel
    return float(min(np.arctan(reach / distance), MAX_ALPHA))


def unshadowed_on(window: Grid, total: np.ndarray) -> np.ndarray:
    """A layer's light where it has no sky square (beyond MAX_ALPHA): the unshadowed light on every pixel.

    Parameters
    ----------
    window : Grid
        The receiver's coarse window [m].
    total : numpy.ndarray
        (3,) the open receiver's light [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (3, rows, cols) float32 on ``window`` [radiance x sr].
    """
    return np.broadcast_to(total.astype(np.float32)[:, None, None], (3, *window.shape)).copy()


def receiver_light(radiance: Radiance, sky: Sky, plane: ReceiverPlane, window: Grid, layers: Sequence[Layer], *,
                   sun_window: Grid | None = None, alpha: float | None = None, coarse_sun: bool = False,
                   workers: int = 1) -> ReceiverLight:
    """The receiver's irradiance under its layers: the ground's correlation in the receiver's frame.

    Per layer, its occlusion on the window's lattice is correlated with the receiver's hemisphere
    raster (``hemisphere.hemisphere_raster``) at cell ``q = p / distance``, and, where the sun
    lights the receiver (``sun.sun_lights``), the sun's fine kernel at ``q_f = p_f / distance`` with
    the layer's transmittance under ``sun_window``. The layers combine by the product rule (Max
    1991), on the coarse window over the hemisphere's unshadowed light, on the fine one over it
    plus the sun's.

    Parameters
    ----------
    radiance : hemisphere.Radiance
        The light around the receiver by world direction (``hemisphere.world_radiance``).
    sky : sky.base.Sky
        The sky, for its sun.
    plane : ReceiverPlane
        The receiver.
    window : Grid
        The coarse window in the receiver's plane coordinates (u, w) [m].
    layers : sequence of Layer
        Its occluders (at least one).
    sun_window : Grid or None, optional
        The fine window [m]; None: no sun raster.
    alpha : float or None, optional
        The sky square's half-angle; None: ``covering_alpha`` per layer [rad].
    coarse_sun : bool, optional
        Also the sun through each layer at the coarse cell, in ``ReceiverLight.outer``.
    workers : int, optional
        FFT threads.

    Returns
    -------
    ReceiverLight
        [radiance x sr; klx under a procedural sky].
    """
    sky_total = hemisphere_irradiance(radiance, plane)
    lit = sun_window is not None and sun_lights(sky, plane)
    sun_total = receiver_sun_irradiance(sky, plane) if lit else np.zeros(3)
    coarse, fine, fine_sky, outer = [], [], [], []
    exact = True
    for layer in layers:
        occlusion, cells = layer.occlusion_on(window)
        layer_alpha = covering_alpha(window, cells, layer.distance) if alpha is None else alpha
        plan = plan_isolated(window, cells, height=layer.distance, alpha=layer_alpha)
        exact &= plan.exact
        if plan.sky is None:
            g = unshadowed_on(window, sky_total)
        else:
            raster = hemisphere_raster(radiance, plane, plan.sky)
            g = ground_isolated(raster, occlusion_spectrum(occlusion, plan, workers=workers), plan, workers=workers)
        coarse.append(g)
        if coarse_sun:
            outer.append(g + (_sun_through(sky, plane, layer, window, workers) if lit else 0.0))
        if sun_window is not None:
            fine_sky.append(resample_bilinear(g, window, sun_window))
            fine.append(fine_sky[-1] + (_sun_through(sky, plane, layer, sun_window, workers) if lit else 0.0))
    light = sky_total + sun_total  # the sky's light and the sun's combined apart (layers.combine_lights)
    total = None if sun_window is None else combine_lights(fine, fine_sky, light, sky_total)
    return ReceiverLight(window, combine_layers(coarse, sky_total), sun_window, total, sky_total, sun_total, exact,
                         combine_lights(outer, coarse, light, sky_total) if coarse_sun else None)


def _sun_through(sky: Sky, plane: ReceiverPlane, layer: Layer, sun_window: Grid, workers: int) -> np.ndarray:
    """The sun's light (3, rows, cols) on ``sun_window`` through ``layer``'s fine mask. [radiance x sr]"""
    kernel = receiver_sun_kernel(sky, plane, sun_window.pixel / layer.distance)
    lo, hi = kernel_block(kernel.grid)
    plan = plan_sun(sun_window, offset_lo=lo, offset_hi=hi)
    spectrum = fine_mask_spectrum(layer.transmittance_on(plan.mask), plan, workers=workers)
    return ground_sun(kernel, spectrum, plan, workers=workers)
