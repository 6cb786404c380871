"""Canopy mask images: transmittance rasters on the canopy plane, area-averaged onto the ground lattice.

A mask image is linear transparency (1 = open sky), north-up, covering ``size`` [m] around
``center`` [m]; its texels are taken as piecewise constant, so resampling by exact overlap
areas (a box filter) is exact for any ratio of texel to ground pixel. A drawn grove's masks are
made by ``grove.py`` (the grove, its flutter, its projection) and ``rasteriser.py``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from numpy.typing import ArrayLike

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import Grid

__all__ = ["transmittance_from_image", "lattice_grid", "transmittance_on_grid", "occlusion_on_lattice",
           "tile_on_lattice"]


def transmittance_from_image(image: np.ndarray) -> np.ndarray:
    """Transmittance from a mask image.

    One or two channels: the first (grey, or grey and alpha). Three or more: the Rec.709
    luminance of the first three (alpha ignored).

    Parameters
    ----------
    image : numpy.ndarray
        (rows, cols, channels) or (rows, cols) linear transparency, 1 = open sky [1].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 transmittance in [0, 1] [1].

    Raises
    ------
    ValueError
        For values outside [0, 1] or not finite.
    """
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[..., None]
    if image.shape[2] >= 3:
        mask = image[..., :3] @ REC709_LUMINANCE
    else:
        mask = image[..., 0]
    if not np.all(np.isfinite(mask)):
        raise ValueError("the mask has values that are not finite numbers")
    low, high = float(mask.min()), float(mask.max())
    if low < -1e-3 or high > 1 + 1e-3:
        raise ValueError(
            f"mask values must lie in [0, 1] (1 = open sky); found {low:.4g} to {high:.4g}"
        )
    return np.clip(mask, 0.0, 1.0)


def lattice_grid(center: tuple[float, float], size: tuple[float, float], lattice: Grid, *,
                 periodic: bool = False) -> Grid:
    """The grid of ``lattice``'s pixels for a canopy area ``size`` around ``center``.

    The whole cells it touches (isolated), or one period of whole cells starting at the cell of its
    north-west corner (periodic; ``size`` must be whole pixels).

    Parameters
    ----------
    center : tuple of (float, float)
        (x, y) of the centre of the mask's area [m].
    size : tuple of (float, float)
        (x, y) extent of the mask's area [m].
    lattice : Grid
        The pixel lattice [m].
    periodic : bool, optional
        Whether the area is one period of a periodic canopy.

    Returns
    -------
    Grid
        The cells, on ``lattice`` [m].
    """
    p = lattice.pixel
    x0, y1 = center[0] - size[0] / 2, center[1] + size[1] / 2
    if periodic:
        n_cols, n_rows = (int(round(s / p)) for s in size)
        col_lo = int(np.floor((x0 - lattice.origin[0]) / p + 1e-9))
        row_lo = int(np.floor((lattice.origin[1] - y1) / p + 1e-9))
    else:
        col_lo, col_hi = _cells_spanning(x0 - lattice.origin[0], size[0], p)
        row_lo, row_hi = _cells_spanning(lattice.origin[1] - y1, size[1], p)
        n_cols, n_rows = col_hi - col_lo, row_hi - row_lo
    return Grid((lattice.origin[0] + col_lo * p, lattice.origin[1] - row_lo * p), p, (n_rows, n_cols))


def transmittance_on_grid(transmittance: ArrayLike, *, center: tuple[float, float], size: tuple[float, float],
                          grid: Grid, periodic: bool = False) -> np.ndarray:
    """A mask image area-averaged onto every pixel of ``grid`` (any pixel, any position).

    Exact overlap areas of its texels, open sky (1) beyond an isolated image, the image repeating
    with period ``size`` for a periodic one.

    Parameters
    ----------
    transmittance : numpy.ndarray
        (rows, cols) mask in [0, 1], north-up [1].
    center, size : tuple of (float, float)
        (x, y) of the centre and (x, y) extent of the mask's area [m].
    grid : Grid
        The target pixels [m].
    periodic : bool, optional
        Whether the image repeats with period ``size``.

    Returns
    -------
    numpy.ndarray
        float32 of ``grid.shape`` [1].
    """
    x0, y1 = center[0] - size[0] / 2, center[1] + size[1] / 2
    occlusion = 1.0 - np.asarray(transmittance, dtype=np.float64)
    rows = _overlap(y1 - grid.origin[1], grid.shape[0], grid.pixel, occlusion.shape[0], size[1],
                    periodic=periodic)
    cols = _overlap(grid.origin[0] - x0, grid.shape[1], grid.pixel, occlusion.shape[1], size[0],
                    periodic=periodic)
    return 1.0 - _apply(rows, cols, occlusion)


def occlusion_on_lattice(transmittance: ArrayLike, *, center: tuple[float, float], size: tuple[float, float],
                         lattice: Grid) -> tuple[np.ndarray, Grid]:
    """Occlusion ``1 - m`` of an isolated canopy, area-averaged onto the cells of ``lattice`` that the mask touches.

    Parameters
    ----------
    transmittance : numpy.ndarray
        (rows, cols) in [0, 1] [1].
    center, size, lattice
        As in ``lattice_grid``.

    Returns
    -------
    occlusion : numpy.ndarray
        float32 (rows, cols) of the cells [1].
    grid : Grid
        The cells' grid on the lattice [m].
    """
    grid = lattice_grid(center, size, lattice)
    return 1.0 - transmittance_on_grid(transmittance, center=center, size=size, grid=grid), grid


def tile_on_lattice(transmittance: ArrayLike, *, center: tuple[float, float], size: tuple[float, float],
                    lattice: Grid) -> tuple[np.ndarray, Grid]:
    """Transmittance of one period of a periodic canopy, area-averaged onto ``lattice``'s pixels.

    Parameters
    ----------
    transmittance : numpy.ndarray
        (rows, cols) in [0, 1] [1].
    center, size : tuple of (float, float)
        (x, y) of the centre of the tile, and the period: a whole number of lattice pixels on
        both axes [m].
    lattice : Grid
        The pixel lattice [m].

    Returns
    -------
    transmittance : numpy.ndarray
        float32 (rows, cols) of the tile [1].
    grid : Grid
        The tile's grid on the lattice [m].
    """
    grid = lattice_grid(center, size, lattice, periodic=True)
    return transmittance_on_grid(transmittance, center=center, size=size, grid=grid, periodic=True), grid


def _cells_spanning(start: float, length: float, pixel: float) -> tuple[int, int]:
    """Whole lattice cells [lo, hi) covering the interval [start, start + length) [m]."""
    lo = int(np.floor(start / pixel + 1e-9))
    hi = int(np.ceil((start + length) / pixel - 1e-9))
    return lo, max(hi, lo + 1)


def _overlap(t0, n_target, t_step, n_source, s_length, *, periodic=False):
    """Sparse (n_target, n_source) matrix: the share of each target cell covered by each source
    texel, along one axis (coordinates increasing with the index). [dimensionless]

    Targets are [t0 + j t_step, t0 + (j+1) t_step); sources split [0, s_length) evenly.
    With ``periodic`` the source repeats with period ``s_length``.
    """
    t_edges = t0 + np.arange(n_target + 1) * t_step
    s_step = s_length / n_source
    shifts = range(int(np.floor(t_edges[0] / s_length)), int(np.ceil(t_edges[-1] / s_length)) + 1) \
        if periodic else (0,)
    weights = sparse.csr_matrix((n_target, n_source))
    for k in shifts:
        s_edges = k * s_length + np.arange(n_source + 1) * s_step
        lo = np.maximum(t_edges[:-1, None], s_edges[None, :-1])
        hi = np.minimum(t_edges[1:, None], s_edges[None, 1:])
        weights = weights + sparse.csr_matrix(np.clip(hi - lo, 0.0, None) / t_step)
    return weights


def _apply(rows, cols, image):
    """rows @ image @ cols.T as float32, with sparse overlap matrices."""
    return np.asarray((cols @ (rows @ image).T).T, dtype=np.float32)
