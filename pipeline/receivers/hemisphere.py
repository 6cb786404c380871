"""A receiver's hemisphere as a weighted raster on its own sky plane: the sky above the world
horizon, the ground's radiance below it (docs/method.md, "Receivers: walls and slopes").

The light around a receiver is a function of world direction, ``radiance(d (..., 3)) -> (..., 3)``:
``world_radiance`` makes it from any ``Sky`` (its ``view_radiance``, the sun disc left out for the
two-scale sun) and the ground's radiance below the horizon. ``hemisphere_raster`` integrates it
cell by cell on a receiver's sky-plane grid into the ``SkyRaster`` that ``ground.shadow``
correlates, as ``Sky.raster`` does for the level ground.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from pipeline.camera.pinhole import MIN_UPWARD
from pipeline.core.geometry import Grid, projected_solid_angle
from pipeline.receivers.plane import ReceiverPlane
from pipeline.sky.base import Sky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.raster import KEPT_RASTERS, SkyRaster, kept_raster

__all__ = ["Radiance", "CELL_NODES", "HEMISPHERE_NODES", "ground_radiance", "world_radiance", "WorldRadiance",
           "hemisphere_raster", "hemisphere_irradiance"]

Radiance = Callable[[np.ndarray], np.ndarray]
"""The light around a receiver: world unit directions (..., 3) -> (..., 3) radiance [radiance]."""

CELL_NODES = 2
"""Gauss-Legendre nodes per cell side at which ``hemisphere_raster`` reads the radiance. [count]"""

HEMISPHERE_NODES = (128, 256)
"""(|z|, azimuth) midpoint nodes of each half of the sphere in ``hemisphere_irradiance``. [count]"""

_CHUNK = 1 << 18  # radiance reads per call, to bound memory [count]


def ground_radiance(albedo: ArrayLike, irradiance: ArrayLike) -> np.ndarray:
    """The open ground's radiance as a Lambertian reflector: albedo x irradiance / pi.

    The first approximation of the light below a receiver's horizon: the open ground's mean
    (no shadows of the trees or of the receiver itself, no reflectance model).

    Parameters
    ----------
    albedo : numpy.ndarray
        (3,) or scalar, the ground's albedo [1].
    irradiance : numpy.ndarray
        (3,) the open ground's irradiance, sky and sun [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (3,) float64 radiance [radiance].
    """
    return np.broadcast_to(np.asarray(albedo, dtype=np.float64) * np.asarray(irradiance, dtype=np.float64)
                           / np.pi, (3,)).copy()


def world_radiance(sky: Sky, ground: ArrayLike) -> WorldRadiance:
    """The light around a receiver: ``sky``'s radiance without its sun disc above the horizon, ``ground`` below.

    Parameters
    ----------
    sky : sky.base.Sky
        Any sky (procedural, HDRI, uniform, overcast); read through its ``view_radiance``.
    ground : numpy.ndarray
        (3,) the ground's radiance (``ground_radiance``) [radiance].

    Returns
    -------
    WorldRadiance
        d (..., 3) -> (..., 3) float64 [radiance]; the rasters and irradiance made of it are kept
        while the sky stands still (``hemisphere_raster``).
    """
    below = np.asarray(ground, dtype=np.float64)
    return WorldRadiance(sky, (float(below[0]), float(below[1]), float(below[2])))


@dataclass(frozen=True)
class WorldRadiance:
    """The light around a receiver by world direction (``world_radiance``), a ``Radiance``.

    Attributes
    ----------
    sky : sky.base.Sky
        The sky above the world's horizon, read without its sun disc.
    below : tuple of 3 float
        The ground's radiance below it [radiance].
    """

    sky: Sky
    below: tuple[float, float, float]

    def __call__(self, d: np.ndarray) -> np.ndarray:
        """The radiance (..., 3) float64 along world unit directions d (..., 3) [radiance]."""
        d = np.asarray(d, dtype=np.float64)
        up = d[..., 2] > 0.0
        out = np.empty(d.shape[:-1] + (3,))
        out[~up] = np.asarray(self.below, dtype=np.float64)
        w = d[up]
        if len(w):
            z = np.maximum(w[:, 2], MIN_UPWARD)  # the sky read near the horizon as the camera reads it
            w = np.column_stack([w[:, :2] * (np.sqrt(1.0 - z * z) / np.maximum(np.hypot(w[:, 0], w[:, 1]), 1e-300))
                                 [:, None], z])
            out[up] = self.sky.view_radiance(w, w[:, :2] / w[:, 2:])
        return out

    @property
    def still(self) -> Hashable | None:
        """What the light depends on while the sky stands still: a procedural sky without clouds
        at time 0 (its time moves only the clouds), any other sky by value or, unhashable (an
        image's), by identity; None for a sky whose clouds move. Read-only."""
        sky = self.sky
        if isinstance(sky, ProceduralSky):
            return None if sky.clouds is not None else (replace(sky, time=0.0), self.below)
        try:
            hash(sky)
        except TypeError:
            return (_Same(sky), self.below)
        return (sky, self.below)


@dataclass(frozen=True, eq=False)
class _Same:
    """A key that is equal to another of the same object only (holding it, so its id is not reused)."""

    thing: object

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Same) and other.thing is self.thing

    def __hash__(self) -> int:
        return id(self.thing)


_kept_rasters: dict = {}  # hemisphere_raster's of a still light: (light, plane, grid, nodes) -> SkyRaster
_kept_irradiance: dict = {}  # hemisphere_irradiance's of a still light: (light, plane) -> (3,) read-only


def hemisphere_raster(radiance: Radiance, plane: ReceiverPlane, grid: Grid, *, nodes: int = CELL_NODES) -> SkyRaster:
    """The weighted light of a receiver's hemisphere on a grid of its sky plane.

    Each cell holds the integral of ``L cos^4(theta) dA`` over it, theta from the receiver's normal:
    its exact projected solid angle times the cos^4-weighted mean of the radiance at ``nodes`` x
    ``nodes`` Gauss-Legendre points (exact for a uniform light). ``outside`` is the hemisphere's
    irradiance (``hemisphere_irradiance``) minus the cells' sum, so that ``irradiance`` is the
    unshadowed receiver's.

    Parameters
    ----------
    radiance : Radiance
        The light around the receiver, by world direction.
    plane : ReceiverPlane
        The receiver.
    grid : Grid
        A sky-plane grid of the receiver (``geometry.sky_grid``) [tan].
    nodes : int, optional
        Nodes per cell side [count].

    Returns
    -------
    sky.raster.SkyRaster
        float32 cells [radiance x sr]; of a still light (``WorldRadiance.still``), kept from the
        second frame that asks for it, read-only (``sky.raster.kept_raster``: 0.9 s of a frame of
        hillside-low-sun.yaml).
    """
    still = radiance.still if isinstance(radiance, WorldRadiance) else None
    if still is None:
        return _hemisphere_raster(radiance, plane, grid, nodes)
    return kept_raster(_kept_rasters, (still, plane, grid, nodes),
                       lambda: _hemisphere_raster(radiance, plane, grid, nodes), again=True)


def _hemisphere_raster(radiance: Radiance, plane: ReceiverPlane, grid: Grid, nodes: int) -> SkyRaster:
    """``hemisphere_raster`` computed. [radiance x sr]"""
    x, weight = np.polynomial.legendre.leggauss(nodes)
    ox, oy = np.meshgrid(x * grid.pixel / 2, -x * grid.pixel / 2)
    wk = np.outer(weight, weight).ravel()
    rows, cols = np.indices(grid.shape)
    centre_x, centre_y = grid.ground_from_raster(rows, cols)
    cx, cy = np.ravel(centre_x), np.ravel(centre_y)
    means = np.empty((len(cx), 3))
    step = max(1, _CHUNK // len(wk))
    for lo in range(0, len(cx), step):
        sx = cx[lo:lo + step, None] + ox.ravel()[None, :]
        sy = cy[lo:lo + step, None] + oy.ravel()[None, :]
        cos4 = wk / (1.0 + sx * sx + sy * sy) ** 2
        L = radiance(plane.direction(np.stack([sx, sy], axis=-1)))
        means[lo:lo + step] = np.einsum("nkc,nk->nc", L, cos4) / cos4.sum(axis=1)[:, None]
    weighted = (means.T.reshape(3, *grid.shape) * projected_solid_angle(grid)[None]).astype(np.float32)
    outside = hemisphere_irradiance(radiance, plane) - weighted.sum(axis=(1, 2), dtype=np.float64)
    return SkyRaster(grid, weighted, outside)


def hemisphere_irradiance(radiance: Radiance, plane: ReceiverPlane) -> np.ndarray:
    """The unshadowed receiver's irradiance: the integral of L max(d.n, 0) over the sphere.

    In world axes, the sphere split at the horizon (where the light steps from the sky to the
    ground): in each half, d_omega = d|z| d_phi with midpoint nodes in |z| and in the azimuth
    (``HEMISPHERE_NODES``), so the level ground under a uniform light is exact and the receiver's
    own edge, d.n = 0, is a kink of the integrand, not a step.

    Parameters
    ----------
    radiance : Radiance
        The light around the receiver.
    plane : ReceiverPlane
        The receiver.

    Returns
    -------
    numpy.ndarray
        (3,) float64 [radiance x sr]; of a still light (``WorldRadiance.still``), kept, read-only.
    """
    still = radiance.still if isinstance(radiance, WorldRadiance) else None
    if still is None:
        return _hemisphere_irradiance(radiance, plane)
    key = (still, plane)
    found = _kept_irradiance.pop(key, None)
    if found is None:
        found = _hemisphere_irradiance(radiance, plane)
        found.flags.writeable = False
        while len(_kept_irradiance) >= KEPT_RASTERS:
            _kept_irradiance.pop(next(iter(_kept_irradiance)))
    _kept_irradiance[key] = found
    return found


def _hemisphere_irradiance(radiance: Radiance, plane: ReceiverPlane) -> np.ndarray:
    """``hemisphere_irradiance`` computed. [radiance x sr]"""
    n_z, n_phi = HEMISPHERE_NODES
    z = (np.arange(n_z) + 0.5) / n_z
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    rho = np.sqrt(1.0 - z * z)[:, None]
    total = np.zeros(3)
    for sign in (1.0, -1.0):
        d = np.stack([rho * np.sin(phi), rho * np.cos(phi), np.broadcast_to(sign * z[:, None], (n_z, n_phi))], axis=-1)
        cos_n = d @ plane.normal
        seen = cos_n > 0.0
        if seen.any():
            total += (radiance(d[seen]) * cos_n[seen][:, None]).sum(axis=0)
    return total * (2.0 * np.pi / (n_z * n_phi))
