"""A sloped ground as a receiver: its plane, the trees standing vertical on it, its layers, and the
camera and sky turned into its frame, so that the level ground's camera draws it (docs/method.md,
"Receivers: walls and slopes", "A sloped ground").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from pipeline.camera.pinhole import MIN_UPWARD, Camera
from pipeline.canopy.grove import FlutterParams, Grove, Leaves, Wood
from pipeline.config.receivers import SlopeConfig
from pipeline.core.geometry import Grid
from pipeline.receivers.layers import Layer, grove_in_frame, grove_layers
from pipeline.receivers.plane import ReceiverPlane, slope
from pipeline.receivers.sun import receiver_sun_point, sun_lights
from pipeline.sky.base import Sky
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_disc import SunDisc

__all__ = ["TRUNK_SEGMENTS", "slope_plane", "height_on", "grove_on_slope", "shading_grove", "slope_layers",
           "camera_in_frame", "SkyInFrame"]

TRUNK_SEGMENTS = 3
"""Segments of a procedural tree's trunk, first in its wood (``canopy.grove``). [count]"""

ALONG_FALL_LINE = 1e-6
"""Most |right . n| of a camera drawn on a slope: it looks straight up or down the slope. [1]"""


def slope_plane(config: SlopeConfig, where: str = "receivers.slope") -> ReceiverPlane:
    """The plane of a config's slope, through the world's origin.

    Parameters
    ----------
    config : config.receivers.SlopeConfig
        Its tilt and the azimuth it falls towards [rad].
    where : str, optional
        Its key, for the errors.

    Returns
    -------
    ReceiverPlane
        The unbounded plane; (u, w) = (0, 0) at the world's origin [m].
    """
    return slope(tilt=config.tilt, facing=config.facing, where=where)


def height_on(plane: ReceiverPlane, x: ArrayLike, y: ArrayLike) -> np.ndarray:
    """The height of an unbounded, not vertical plane above world points (x, y).

    Parameters
    ----------
    plane : ReceiverPlane
        A slope (its normal's z positive).
    x, y : array_like
        World coordinates [m].

    Returns
    -------
    numpy.ndarray
        z on the plane [m].
    """
    n, o = plane.normal, plane.origin
    return o[2] - (n[0] * (np.asarray(x, dtype=np.float64) - o[0]) + n[1] * (np.asarray(y, dtype=np.float64)
                                                                              - o[1])) / n[2]


def grove_on_slope(grove: Grove, plane: ReceiverPlane) -> Grove:
    """The grove's trees standing vertical on a slope: each lifted whole by the slope's height at
    its foot, its trunk's foot lowered by its radius x tan(tilt) so that it meets the slope on its
    downhill side too.

    Parameters
    ----------
    grove : canopy.grove.Grove
        An isolated grove on the level ground, world axes [m].
    plane : ReceiverPlane
        The slope.

    Returns
    -------
    canopy.grove.Grove
        The same trees in world axes, lifted [m].

    Raises
    ------
    ValueError
        For a periodic grove, or one whose leaves and wood do not split evenly into its trees.
    """
    count = len(grove.bases)
    if grove.params.layout != "isolated":
        raise ValueError("only an isolated grove stands on a slope")
    if len(grove.leaves.center) % count or len(grove.wood.start) % count:
        raise ValueError("the grove's leaves and wood do not split evenly into its trees")
    lift = height_on(plane, grove.bases[:, 0], grove.bases[:, 1]) - grove.bases[:, 2]
    per_leaf = np.repeat(lift, len(grove.leaves.center) // count)[:, None] * np.array([0.0, 0.0, 1.0])
    per_wood = np.repeat(lift, len(grove.wood.start) // count)[:, None] * np.array([0.0, 0.0, 1.0])
    start = grove.wood.start + per_wood
    feet = _feet(grove)
    start[feet, 2] -= grove.wood.radius[feet] * np.tan(plane.zenith)
    bases = grove.bases + lift[:, None] * np.array([0.0, 0.0, 1.0])
    return replace(grove, leaves=Leaves(grove.leaves.center + per_leaf, grove.leaves.axis_u, grove.leaves.axis_v),
                   pivot=grove.pivot + per_leaf, wood=Wood(start, grove.wood.end + per_wood, grove.wood.radius),
                   bases=bases)


def _feet(grove: Grove) -> np.ndarray:
    """The index of each tree's first trunk segment in ``grove.wood``."""
    return np.arange(len(grove.bases)) * (len(grove.wood.start) // len(grove.bases))


def shading_grove(grove: Grove, plane: ReceiverPlane) -> Grove:
    """The grove standing on a slope (``grove_on_slope``) as it shades the slope: each trunk's foot
    raised back to the slope's height at the trunk's axis. The foot lowered for the picture, where
    the trunk meets the slope downhill, would cast the shadow of its buried part past the foot
    towards a sun from downhill.

    Parameters
    ----------
    grove : canopy.grove.Grove
        The grove standing on the slope, world axes [m].
    plane : ReceiverPlane
        The slope.

    Returns
    -------
    canopy.grove.Grove
        The same grove, its feet on the slope at their axes [m].
    """
    feet = _feet(grove)
    start = grove.wood.start.copy()
    start[feet, 2] += grove.wood.radius[feet] * np.tan(plane.zenith)
    return replace(grove, wood=Wood(start, grove.wood.end, grove.wood.radius))


def slope_layers(plane: ReceiverPlane, sky: Sky, grove: tuple[Grove, FlutterParams] | None,
                 cycle_frame: int) -> list[Layer]:
    """A slope's occluders: the grove standing on it (``grove_on_slope``) turned into its frame,
    its leaves and wood drawn into one layer at their median distance along the normal, projected
    along the sun (as a wall's, ``receivers.walls.wall_layers``: every crown stands at about the
    same distance from the slope).

    Parameters
    ----------
    plane : ReceiverPlane
        The slope.
    sky : sky.base.Sky
        The frame's sky (the sun's direction).
    grove : (canopy.grove.Grove, canopy.grove.FlutterParams) or None
        The grove already standing on the slope, world axes, and its flutter; None: none.
    cycle_frame : int
        The flutter's frame [frames].

    Returns
    -------
    list of Layer
        One layer, or none for an open slope.
    """
    if grove is None:
        return []
    turned = grove_in_frame(shading_grove(grove[0], plane), plane)
    front = turned.leaves.center[:, 2]
    front = front[front > 0.0]
    if not len(front):
        return []
    s = receiver_sun_point(sky, plane) if sun_lights(sky, plane) else np.zeros(2)
    return list(grove_layers(turned, grove[1], cycle_frame, distances=(float(np.median(front)),),
                             sun=(float(s[0]), float(s[1]))))


def camera_in_frame(camera: Camera, plane: ReceiverPlane) -> Camera:
    """The camera turned into the slope's frame, where the slope is the level ground z = 0: the same
    picture, with the slope's depth per pixel and its vanishing line for a horizon.

    The camera has no roll, so it must look straight up or down the slope (its right along u).

    Parameters
    ----------
    camera : camera.pinhole.Camera
        In world axes [m].
    plane : ReceiverPlane
        The slope.

    Returns
    -------
    camera.pinhole.Camera
        Its position (u, w, along n) and its view in the slope's axes [m].

    Raises
    ------
    ValueError
        For a camera that does not look along the fall line, or is not above the slope.
    """
    right, _, forward = camera.basis
    if abs(float(right @ plane.normal)) > ALONG_FALL_LINE:
        raise ValueError("a camera on a slope looks straight up or down it (its azimuth the slope's, or opposite)")
    position = plane.local_points(camera.position)
    if not position[2] > 0.0:
        raise ValueError("the camera must stand above the slope")
    f = plane.local_directions(forward)
    local = Camera.look_at(position, position + f, vertical_fov=camera.vertical_fov, width=camera.width,
                           height=camera.height)
    if float(local.basis[0] @ plane.local_directions(right)) < 0.0:  # straight up or down: the yaw's right
        local = replace(local, yaw=(local.yaw + np.pi) % (2 * np.pi))
    return local


@dataclass(frozen=True)
class SkyInFrame:
    """A sky as the camera turned into a receiver's frame reads it (``camera_in_frame``): its
    ``view_radiance`` at the world direction of each frame direction, the ground's radiance below
    the world's horizon. Its other members are the world sky's.

    Attributes
    ----------
    sky : sky.base.Sky
        The frame's sky.
    plane : ReceiverPlane
        The receiver.
    below : tuple of 3 float
        The radiance below the world's horizon (``hemisphere.ground_radiance``) [radiance].
    """

    sky: Sky
    plane: ReceiverPlane
    below: tuple[float, float, float]

    @property
    def sun(self) -> SunDisc | None:
        """The world sky's sun disc (read-only)."""
        return self.sky.sun

    @property
    def sky_irradiance(self) -> np.ndarray:
        """(3,) the world sky's horizontal irradiance (read-only) [radiance x sr]."""
        return self.sky.sky_irradiance

    def raster(self, grid: Grid, *, fold_period: tuple[int, int] | None = None) -> SkyRaster:
        """Not drawn in a receiver's frame: ``hemisphere.hemisphere_raster`` draws it.

        Parameters
        ----------
        grid : Grid
            A sky-plane grid [tan].
        fold_period : tuple of int or None
            Unused.

        Returns
        -------
        sky.raster.SkyRaster
            Never.

        Raises
        ------
        NotImplementedError
            Always.
        """
        raise NotImplementedError("a receiver's sky raster is hemisphere.hemisphere_raster's")

    def sun_fraction(self) -> float:
        """The world sky's S [1]."""
        return self.sky.sun_fraction()

    def undimmed_sun_irradiance(self) -> np.ndarray:
        """The world sky's undimmed sun, (3,) [radiance x sr]."""
        return self.sky.undimmed_sun_irradiance()

    def view_radiance(self, w: np.ndarray, s: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """The radiance along frame directions, without the sun disc.

        Parameters
        ----------
        w : numpy.ndarray
            (..., 3) unit vectors in the receiver's axes [1].
        s : numpy.ndarray
            (..., 2) their points on the receiver's sky plane (unused: taken from w in world axes) [tan].
        footprint : float, numpy.ndarray or None
            The camera's footprint on the receiver's sky plane (``pinhole.sky_view``: (..., 2),
            along the radius and across; a scalar at ``MIN_UPWARD``, ``pinhole.horizon_sky``) [tan].

        Returns
        -------
        numpy.ndarray
            (..., 3) [radiance].
        """
        local = np.asarray(w, dtype=np.float64)
        d = self.plane.world_directions(local)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        if footprint is None:
            angle = None
        elif np.ndim(footprint) == 0:
            angle = np.full(local.shape[:-1], float(footprint) * MIN_UPWARD**2)  # horizon_sky's, at MIN_UPWARD
        else:
            angle = np.asarray(footprint)[..., 1] * np.maximum(local[..., 2], MIN_UPWARD)
        up = d[..., 2] > 0.0
        out = np.empty(local.shape[:-1] + (3,), dtype=np.float32)
        out[~up] = np.asarray(self.below, dtype=np.float32)
        v = d[up]
        if len(v):
            z = np.maximum(v[:, 2], MIN_UPWARD)  # read near the horizon as the camera reads the level sky
            v = np.column_stack([v[:, :2] * (np.sqrt(1.0 - z * z) / np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-300))
                                 [:, None], z])
            fp = None if angle is None else np.stack([angle[up] / (z * z), angle[up] / z], axis=-1)
            out[up] = self.sky.view_radiance(v, v[:, :2] / v[:, 2:], fp)
        return out
