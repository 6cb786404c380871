"""Occluders as layers parallel to a receiver: an image mask at a distance (a trellis, a pergola, a
grille) and the procedural grove's leaves turned into the receiver's frame and drawn into layers at
their distances along its normal (docs/method.md, "Receivers: walls and slopes").

A layer gives the correlation two rasters on the receiver's (u, w) lattice: its occlusion over the
cells it touches (the sky's isolated correlation) and its transmittance on any grid (the fine sun
window's mask), as the ground's layers do (``stages.cycle``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy.grove import FlutterParams, Grove, Leaves, Wood, grove_bounds, layer_index
from pipeline.canopy.masks import lattice_grid, occlusion_on_lattice, transmittance_on_grid
from pipeline.canopy.rasteriser import grove_mask
from pipeline.core.errors import ConfigError
from pipeline.core.geometry import Grid
from pipeline.receivers.plane import ReceiverPlane

__all__ = ["Layer", "MaskLayer", "mask_layer", "GroveLayer", "grove_in_frame", "grove_layers"]


class Layer(Protocol):
    """A layer of occluders parallel to a receiver, at ``distance`` [m] along its normal."""

    @property
    def distance(self) -> float:
        """Distance of the layer's plane from the receiver along its normal [m] (read-only)."""

    def occlusion_on(self, lattice: Grid) -> tuple[np.ndarray, Grid]:
        """Occlusion ``1 - m`` (rows, cols) float32 on the cells of ``lattice`` it touches, and their grid [m]."""

    def transmittance_on(self, grid: Grid) -> np.ndarray:
        """Transmittance (rows, cols) float32 on every pixel of ``grid`` (receiver plane coordinates) [1]."""


@dataclass(frozen=True)
class MaskLayer:
    """An image mask parallel to a receiver: 1 = open, rows along -w (upright as one faces the receiver).

    Attributes
    ----------
    transmittance : numpy.ndarray
        (rows, cols) in [0, 1] [1].
    center : tuple of (float, float)
        (u, w) of the image's centre in the receiver's plane coordinates [m].
    size : tuple of (float, float)
        (u, w) extent of the image [m].
    distance : float
        Of its plane along the receiver's normal [m].
    """

    transmittance: np.ndarray
    center: tuple[float, float]
    size: tuple[float, float]
    distance: float

    def occlusion_on(self, lattice: Grid) -> tuple[np.ndarray, Grid]:
        """Occlusion area-averaged onto the cells of ``lattice`` the image touches (``masks.occlusion_on_lattice``).

        Parameters
        ----------
        lattice : Grid
            The receiver's pixel lattice [m].

        Returns
        -------
        occlusion : numpy.ndarray
            float32 (rows, cols) [1].
        grid : Grid
            The cells [m].
        """
        occlusion, grid = occlusion_on_lattice(self.transmittance, center=self.center, size=self.size, lattice=lattice)
        return occlusion.astype(np.float32), grid

    def transmittance_on(self, grid: Grid) -> np.ndarray:
        """The image area-averaged onto every pixel of ``grid``, open beyond it.

        Parameters
        ----------
        grid : Grid
            Receiver plane pixels [m].

        Returns
        -------
        numpy.ndarray
            float32 of ``grid.shape`` [1].
        """
        return transmittance_on_grid(self.transmittance, center=self.center, size=self.size,
                                     grid=grid).astype(np.float32)


def mask_layer(transmittance: ArrayLike, *, center: Sequence[float], size: Sequence[float], distance: float,
               where: str = "mask") -> MaskLayer:
    """A ``MaskLayer``, its values checked.

    Parameters
    ----------
    transmittance : numpy.ndarray
        (rows, cols) in [0, 1] [1].
    center, size : sequence of 2 float
        (u, w) of its centre and its (u, w) extent, positive [m].
    distance : float
        Along the receiver's normal, positive [m].
    where : str, optional
        The config key, for the errors.

    Returns
    -------
    MaskLayer
        The layer.

    Raises
    ------
    ConfigError
        Naming the key of a size or distance that is not positive, or a mask outside [0, 1].
    """
    t = np.asarray(transmittance, dtype=np.float32)
    if t.ndim != 2 or not np.all((t >= 0) & (t <= 1)):
        raise ConfigError(f"{where}.image", "must be one channel of transmittance in [0, 1] (1 = open)")
    if len(size) != 2 or not all(np.isfinite(s) and s > 0 for s in size):
        raise ConfigError(f"{where}.size", f"must be two positive numbers (u, w) [m], got {list(size)}")
    if len(center) != 2 or not all(np.isfinite(c) for c in center):
        raise ConfigError(f"{where}.center", f"must be two finite numbers (u, w) [m], got {list(center)}")
    if not (np.isfinite(distance) and distance > 0):
        raise ConfigError(f"{where}.distance", f"must be positive [m], got {distance:g}")
    return MaskLayer(t, (float(center[0]), float(center[1])), (float(size[0]), float(size[1])), float(distance))


@dataclass(frozen=True)
class GroveLayer:
    """The leaves and wood of a grove (in a receiver's frame) nearest one layer plane, at one flutter frame.

    Projected along ``sun`` (the receiver sky-plane point the shapes' sun shadows fall along;
    (0, 0) projects straight onto the plane) and drawn by ``rasteriser.grove_mask``.

    Attributes
    ----------
    grove : canopy.grove.Grove
        The grove in the receiver's frame (``grove_in_frame``) [m].
    flutter : canopy.grove.FlutterParams
        Its flutter.
    frame : int
        The flutter frame [frames].
    distance : float
        Of the layer's plane along the normal [m].
    sun : tuple of (float, float)
        Projection direction on the receiver's sky plane [tan].
    select : tuple
        (leaf selector, wood selector) of ``Shapes.subset``.
    """

    grove: Grove
    flutter: FlutterParams
    frame: int
    distance: float
    sun: tuple[float, float]
    select: tuple[np.ndarray, np.ndarray]

    def occlusion_on(self, lattice: Grid) -> tuple[np.ndarray, Grid]:
        """Occlusion on the lattice's cells the layer can touch at any flutter frame.

        Parameters
        ----------
        lattice : Grid
            The receiver's pixel lattice [m].

        Returns
        -------
        occlusion : numpy.ndarray
            float32 (rows, cols) [1].
        grid : Grid
            The cells [m].
        """
        x0, y0, x1, y1 = grove_bounds(self.grove, sun=self.sun, plane_height=self.distance)
        grid = lattice_grid(((x0 + x1) / 2, (y0 + y1) / 2), (x1 - x0, y1 - y0), lattice)
        return 1.0 - self.transmittance_on(grid), grid

    def transmittance_on(self, grid: Grid) -> np.ndarray:
        """The layer's shapes drawn on ``grid`` (``rasteriser.grove_mask``).

        Parameters
        ----------
        grid : Grid
            Receiver plane pixels [m].

        Returns
        -------
        numpy.ndarray
            float32 of ``grid.shape`` [1].
        """
        return grove_mask(self.grove, self.flutter, self.frame, sun=self.sun, plane_height=self.distance,
                          grid=grid, period=None, select=self.select)


def grove_in_frame(grove: Grove, plane: ReceiverPlane) -> Grove:
    """The grove's leaves, stems, swing axes and wood in the receiver's frame (u, w, along n) [m].

    Parameters
    ----------
    grove : canopy.grove.Grove
        An isolated grove in world axes [m].
    plane : ReceiverPlane
        The receiver.

    Returns
    -------
    canopy.grove.Grove
        The same grove, turned: its flutter turns with it.

    Raises
    ------
    ValueError
        For a periodic grove: its tiles are level.
    """
    if grove.params.layout != "isolated":
        raise ValueError("only an isolated grove can be turned into a receiver's frame")
    leaves = Leaves(plane.local_points(grove.leaves.center), plane.local_directions(grove.leaves.axis_u),
                    plane.local_directions(grove.leaves.axis_v))
    wood = Wood(plane.local_points(grove.wood.start), plane.local_points(grove.wood.end), grove.wood.radius)
    return replace(grove, leaves=leaves, pivot=plane.local_points(grove.pivot),
                   swing_axis=plane.local_directions(grove.swing_axis), wood=wood,
                   bases=plane.local_points(grove.bases))


def grove_layers(grove: Grove, flutter: FlutterParams, frame: int, *, distances: Sequence[float],
                 sun: Sequence[float] = (0.0, 0.0)) -> list[GroveLayer]:
    """A turned grove (``grove_in_frame``) split into layers: each leaf and wood segment to the
    nearest plane, those behind the receiver (at or below distance 0) left out.

    Parameters
    ----------
    grove : canopy.grove.Grove
        In the receiver's frame [m].
    flutter : canopy.grove.FlutterParams
        Its flutter.
    frame : int
        The flutter frame [frames].
    distances : sequence of float
        The layer planes along the normal, positive [m].
    sun : sequence of 2 float, optional
        The projection direction on the receiver's sky plane [tan].

    Returns
    -------
    list of GroveLayer
        One per distance, nearest first as given.
    """
    leaf_layer, wood_layer = layer_index(grove, distances)
    in_front = grove.leaves.center[:, 2] > 0.0
    wood_front = 0.5 * (grove.wood.start[:, 2] + grove.wood.end[:, 2]) > 0.0
    s = (float(sun[0]), float(sun[1]))
    return [GroveLayer(grove, flutter, frame, float(d), s,
                       ((leaf_layer == i) & in_front, (wood_layer == i) & wood_front)) for i, d in enumerate(distances)]
