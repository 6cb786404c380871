"""Canopy masks: transmittance rasters on the canopy plane, area-averaged onto the ground lattice.

A mask image is linear transparency (1 = open sky), north-up, covering ``size`` [m] around
``center`` [m]; its texels are taken as piecewise constant, so resampling by exact overlap
areas (a box filter) is exact for any ratio of texel to ground pixel.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse

from .composite import REC709_LUMINANCE
from .geometry import Grid


def transmittance_from_image(image: np.ndarray) -> np.ndarray:
    """Transmittance (rows, cols) float32 in [0, 1] from an image (rows, cols, channels).

    One or two channels: the first (grey, or grey and alpha). Three or more: the Rec.709
    luminance of the first three (alpha ignored). Raises ValueError for values outside [0, 1]
    or not finite.
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


def occlusion_on_lattice(transmittance, *, center, size, lattice: Grid):
    """Occlusion ``1 - m`` of an isolated canopy, area-averaged onto the cells of ``lattice``'s
    pixel lattice that the mask touches.

    transmittance : (rows, cols) in [0, 1]. center, size : (x, y) of the mask's area. [m]
    Returns (occlusion float32 (rows, cols), its Grid on the lattice).
    """
    x0, y1 = center[0] - size[0] / 2, center[1] + size[1] / 2
    p = lattice.pixel
    col_lo, col_hi = _cells_spanning(x0 - lattice.origin[0], size[0], p)
    row_lo, row_hi = _cells_spanning(lattice.origin[1] - y1, size[1], p)
    grid = Grid(
        (lattice.origin[0] + col_lo * p, lattice.origin[1] - row_lo * p),
        p,
        (row_hi - row_lo, col_hi - col_lo),
    )
    occlusion = 1.0 - np.asarray(transmittance, dtype=np.float64)
    rows = _overlap(row_lo * p, row_hi - row_lo, p, lattice.origin[1] - y1, occlusion.shape[0], size[1])
    cols = _overlap(col_lo * p, col_hi - col_lo, p, x0 - lattice.origin[0], occlusion.shape[1], size[0])
    return _apply(rows, cols, occlusion), grid


def tile_on_lattice(transmittance, *, center, size, lattice: Grid):
    """Transmittance of one period of a periodic canopy, area-averaged onto ``lattice``'s pixels.

    The period ``size`` [m] must be a whole number of lattice pixels on both axes.
    Returns (transmittance float32 (rows, cols), the tile's Grid on the lattice).
    """
    p = lattice.pixel
    n_cols, n_rows = (int(round(s / p)) for s in size)
    x0, y1 = center[0] - size[0] / 2, center[1] + size[1] / 2
    col_lo = int(np.floor((x0 - lattice.origin[0]) / p + 1e-9))
    row_lo = int(np.floor((lattice.origin[1] - y1) / p + 1e-9))
    grid = Grid((lattice.origin[0] + col_lo * p, lattice.origin[1] - row_lo * p), p, (n_rows, n_cols))
    m = np.asarray(transmittance, dtype=np.float64)
    rows = _overlap(row_lo * p, n_rows, p, lattice.origin[1] - y1, m.shape[0], size[1], periodic=True)
    cols = _overlap(col_lo * p, n_cols, p, x0 - lattice.origin[0], m.shape[1], size[0], periodic=True)
    return _apply(rows, cols, m), grid


def _cells_spanning(start: float, length: float, pixel: float) -> tuple[int, int]:
    """Whole lattice cells [lo, hi) covering the interval [start, start + length) [m]."""
    lo = int(np.floor(start / pixel + 1e-9))
    hi = int(np.ceil((start + length) / pixel - 1e-9))
    return lo, max(hi, lo + 1)


def _overlap(t0, n_target, t_step, s0, n_source, s_length, *, periodic=False):
    """Sparse (n_target, n_source) matrix: the share of each target cell covered by each source
    texel, along one axis (coordinates increasing with the index). [dimensionless]

    Targets are [t0 + j t_step, t0 + (j+1) t_step); sources split [s0, s0 + s_length) evenly.
    With ``periodic`` the source repeats with period ``s_length``.
    """
    t_edges = t0 + np.arange(n_target + 1) * t_step
    s_step = s_length / n_source
    shifts = (-1, 0, 1) if periodic else (0,)
    weights = np.zeros((n_target, n_source))
    for k in shifts:
        s_edges = s0 + k * s_length + np.arange(n_source + 1) * s_step
        lo = np.maximum(t_edges[:-1, None], s_edges[None, :-1])
        hi = np.minimum(t_edges[1:, None], s_edges[None, 1:])
        weights += np.clip(hi - lo, 0.0, None) / t_step
    return sparse.csr_matrix(weights)


def _apply(rows, cols, image):
    """rows @ image @ cols.T as float32, with sparse overlap matrices."""
    return np.asarray((cols @ (rows @ image).T).T, dtype=np.float32)
