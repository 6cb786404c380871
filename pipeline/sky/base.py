"""The ``Sky`` interface the renderer and the camera ask of a sky model, and the uniform sky.

The procedural sky is ``procedural.ProceduralSky``, the HDRI sky ``equirect.EquirectSky``; each
implements all of ``Sky``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from pipeline.core.geometry import Grid, fold, projected_solid_angle, sky_grid, sky_offset
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_disc import SunDisc

__all__ = ["Sky", "UniformSky"]


@runtime_checkable
class Sky(Protocol):
    """What the renderer and the camera ask of a sky model.

    ``UniformSky``, ``equirect.EquirectSky`` and ``ProceduralSky`` implement all of it.
    Irradiances are (3,) float64, horizontal, in the sky's units ([radiance x sr]; klx for
    ProceduralSky).

    Attributes
    ----------
    sun : sun_disc.SunDisc or None
        The disc drawn by ``sun_kernel.sun_kernel`` on the fine grid, None without one.
    sky_irradiance : numpy.ndarray
        (3,) the sky's irradiance without the sun disc (clouds and the moon included).
    """

    @property
    def sun(self) -> SunDisc | None:
        """The disc drawn by ``sun_kernel.sun_kernel``, None without one (read-only)."""

    @property
    def sky_irradiance(self) -> np.ndarray:
        """(3,) the sky's irradiance without the sun disc (read-only)."""

    def raster(self, grid: Grid, *, fold_period: tuple[int, int] | None = None) -> SkyRaster:
        """The weighted sky on a sky-plane ``grid`` [tan], folded modulo ``fold_period`` (rows, cols) if given."""

    def sun_fraction(self) -> float:
        """S, the sun's power reaching the ground over the clear, uneclipsed sun's [1]; 0.0 without a sun."""

    def undimmed_sun_irradiance(self) -> np.ndarray:
        """(3,) the sun's irradiance before the moon and clouds dim it (an HDRI's: as photographed); zeros
        without a sun."""

    def view_radiance(self, w: np.ndarray, s: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """(..., 3) the sky's radiance without the sun disc along unit vectors w (..., 3) with sky-plane
        points s (..., 2) [tan] (the camera holds wz at MIN_UPWARD or more), each standing for a sky-plane
        width ``footprint`` [tan] (None, scalar, (...) or (..., 2): along the radius and across) over which
        a cloud pattern is filtered. A model uses what it needs of w, s and footprint."""


@dataclass(frozen=True)
class UniformSky:
    """A sky of the same radiance in every direction; a ``Sky``.

    Parameters
    ----------
    radiance : numpy.ndarray
        (3,) linear RGB radiance [scene-linear radiance].
    """

    radiance: np.ndarray

    @property
    def sun(self) -> None:
        """No sun disc."""
        return None

    @property
    def sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,), pi L. [radiance x sr]"""
        return np.pi * np.asarray(self.radiance, dtype=np.float64)

    def sun_fraction(self) -> float:
        """S = 0: no sun. [1]"""
        return 0.0

    def undimmed_sun_irradiance(self) -> np.ndarray:
        """Zeros (3,): no sun. [radiance x sr]"""
        return np.zeros(3)

    def view_radiance(self, w: np.ndarray, s: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """The sky's radiance along view directions: the same along every one.

        Parameters
        ----------
        w : numpy.ndarray
            (..., 3) unit vectors [1].
        s, footprint :
            Unused (the ``Sky`` interface).

        Returns
        -------
        numpy.ndarray
            (..., 3) float32 radiance [radiance].
        """
        radiance = np.asarray(self.radiance, dtype=np.float32)
        return np.broadcast_to(radiance, np.shape(w)[:-1] + radiance.shape).copy()

    def raster(self, grid: Grid, *, fold_period: tuple[int, int] | None = None) -> SkyRaster:
        """Exact cell integrals of the uniform sky on a sky-plane grid.

        Parameters
        ----------
        grid : geometry.Grid
            The sky-plane grid [tan].
        fold_period : tuple of int or None
            (rows, cols): folded modulo that period (see ``equirect.EquirectSky.raster``).

        Returns
        -------
        sky.raster.SkyRaster
            The weighted sky [radiance x sr].
        """
        radiance = np.asarray(self.radiance, dtype=np.float64)
        weights = projected_solid_angle(grid)
        if fold_period is not None:
            weights = fold(weights[None], sky_offset(grid), fold_period)[0]
            period_rows, period_cols = fold_period
            grid = sky_grid((0, 0), (period_rows, period_cols), grid.pixel)
        weighted = (radiance[:, None, None] * weights[None]).astype(np.float32)
        outside = radiance * np.pi - weighted.sum(axis=(1, 2), dtype=np.float64)
        return SkyRaster(grid, weighted, outside)
