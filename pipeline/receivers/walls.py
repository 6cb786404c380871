"""A config's wall as a receiver: its plane, its layers (its masks and the procedural grove turned
into its frame) and its light at a frame, on a raster over the whole wall (docs/method.md,
"Receivers: walls and slopes").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy.grove import FlutterParams, Grove
from pipeline.canopy.masks import transmittance_from_image
from pipeline.config.receivers import WALL_ALBEDOS, WallConfig
from pipeline.core import io
from pipeline.core.errors import ImageError
from pipeline.core.geometry import Grid
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, world_radiance
from pipeline.receivers.layers import Layer, grove_in_frame, grove_layers, mask_layer
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import ReceiverPlane, wall
from pipeline.receivers.sun import receiver_sun_irradiance, receiver_sun_point, sun_lights
from pipeline.sky.base import Sky

__all__ = ["COARSE_FACTOR", "WallLight", "wall_plane", "wall_layers", "wall_light", "wall_albedo_colour"]

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


def wall_layers(config: WallConfig, plane: ReceiverPlane, sky: Sky, *, grove: tuple[Grove, FlutterParams] | None,
                cycle_frame: int, where: str = "receivers.walls[0]") -> list[Layer]:
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
    sky : sky.base.Sky
        The frame's sky (the sun's direction for the projection).
    grove : (canopy.grove.Grove, canopy.grove.FlutterParams) or None
        An isolated procedural grove in world axes and its flutter; None: none.
    cycle_frame : int
        The flutter's frame [frames].
    where : str, optional
        The wall's key, for the errors.

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
            s = receiver_sun_point(sky, plane) if sun_lights(sky, plane) else np.zeros(2)
            layers += grove_layers(turned, grove[1], cycle_frame, distances=(float(np.median(front)),),
                                   sun=(float(s[0]), float(s[1])))
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
    """A wall's irradiance at a frame over the whole wall, at its ``pixel``.

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
    plane = wall_plane(config, where)
    radiance = world_radiance(sky, ground_radiance(ground_albedo, open_ground))
    extent = (-config.width / 2, 0.0, config.width / 2, config.height)
    fine = Grid.from_window(extent, config.pixel)
    layers = wall_layers(config, plane, sky, grove=grove, cycle_frame=cycle_frame, where=where)
    if not layers:
        sky_total = hemisphere_irradiance(radiance, plane)
        sun_total = receiver_sun_irradiance(sky, plane)
        image = np.broadcast_to((sky_total + sun_total).astype(np.float32), (*fine.shape, 3)).copy()
        return WallLight(plane, fine, image, sky_total, sun_total)
    coarse = Grid.from_window(extent, config.pixel * COARSE_FACTOR)
    light = receiver_light(radiance, sky, plane, coarse, layers, sun_window=fine, workers=workers)
    assert light.total is not None  # a sun window was given
    return WallLight(plane, fine, np.ascontiguousarray(np.moveaxis(light.total, 0, -1)), light.sky_unshadowed,
                     light.sun_unshadowed)
