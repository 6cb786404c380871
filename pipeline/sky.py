"""Sky models and their weighted sky-plane rasters ``e`` (Max 1991, eq. 1 and Fig. 6).

A sky raster cell holds the integral of ``L(s) cos^4(theta) dA`` over the cell: radiance times
projected solid angle, so that the unshadowed irradiance of the ground is the plain sum of the
raster plus ``outside``, the irradiance of all the sky the raster does not cover. No hidden
normalising factor: radiance in, irradiance [radiance x sr] out.

Equirectangular skies (DESIGN.md section 3): the top row touches the zenith, the centre column
looks north, east is at three quarters of the width, texel centres at
``((col + 0.5) / width, (row + 0.5) / height)``. ``rotation`` turns the sky about the zenith
towards the east: a feature at image azimuth ``phi`` is seen at azimuth ``phi + rotation``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .geometry import Grid, projected_solid_angle
from .shadow import fold, sky_grid, sky_offset


@dataclass(frozen=True)
class SkyRaster:
    """The weighted sky on a sky-plane grid.

    grid : Grid -- sky-plane grid [tan]; cell (r, c) is the sky offset s = grid centre.
    weighted : ndarray (channels, rows, cols) float32 -- radiance x projected solid angle per cell.
    outside : ndarray (channels,) float64 -- irradiance of the sky outside the raster. [radiance x sr]
    """

    grid: Grid
    weighted: np.ndarray
    outside: np.ndarray

    @cached_property
    def total(self) -> np.ndarray:
        """Irradiance of the whole unshadowed sky per channel (float64). [radiance x sr]"""
        return self.weighted.sum(axis=(1, 2), dtype=np.float64) + self.outside


@dataclass(frozen=True)
class UniformSky:
    """A sky of the same radiance in every direction.

    radiance : ndarray (3,) -- linear RGB radiance. [scene-linear radiance]
    """

    radiance: np.ndarray

    def raster(self, grid: Grid, *, fold_period=None) -> SkyRaster:
        """Exact cell integrals of the uniform sky on ``grid``; with ``fold_period`` (rows, cols)
        folded modulo that period (see ``EquirectSky.raster``)."""
        radiance = np.asarray(self.radiance, dtype=np.float64)
        weights = projected_solid_angle(grid)
        if fold_period is not None:
            weights = fold(weights[None], sky_offset(grid), fold_period)[0]
            grid = sky_grid((0, 0), tuple(fold_period), grid.pixel)
        weighted = (radiance[:, None, None] * weights[None]).astype(np.float32)
        outside = radiance * np.pi - weighted.sum(axis=(1, 2), dtype=np.float64)
        return SkyRaster(grid, weighted, outside)


@dataclass(frozen=True)
class EquirectSky:
    """A sky from an equirectangular image (HDRI), texels taken as piecewise constant.

    image : ndarray (height, width, 3) float32 -- linear RGB radiance, finite, not negative.
    rotation : float -- turn about the zenith towards the east. [rad]
    """

    image: np.ndarray
    rotation: float = 0.0

    def total_irradiance(self) -> np.ndarray:
        """Exact irradiance of the upper hemisphere of the piecewise-constant image. [radiance x sr]"""
        height, width, _ = self.image.shape
        theta0, theta1 = _row_bounds(height)
        weight = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
        rows = len(weight)
        return np.einsum("r,rcn->n", weight, self.image[:rows].astype(np.float64))

    def raster(self, grid: Grid, *, fold_period=None) -> SkyRaster:
        """Area-averaged resampling onto ``grid`` that keeps every texel's energy.

        Each texel is cut into sub-texels no larger than half a cell on the sky plane; each
        sub-texel's energy (radiance x its exact projected solid angle) is spread bilinearly
        over the four nearest cells. A small bright sun keeps its energy exactly; what lands
        off the grid is counted in ``outside``.

        fold_period : (rows, cols) or None -- deposit each cell at its offset modulo this period
            (a periodic canopy tile): the raster returned is the folded one, on the grid of
            offsets 0..period-1, and the full ``grid`` never exists in memory.
        """
        height, width, channels = self.image.shape
        wrap = None
        if fold_period is not None:
            wrap = (sky_offset(grid), tuple(fold_period))
        rows, cols = grid.shape if wrap is None else wrap[1]
        step = 0.5 * grid.pixel
        near, reach, keep_phi = _grid_footprint(grid)
        accum = np.zeros((channels, rows * cols), dtype=np.float64)
        pending: list = []
        theta0, theta1 = _row_bounds(height)
        for row in range(len(theta0)):
            # only the band of the row that can land on the grid (one cell of bilinear reach)
            t0 = max(np.tan(theta0[row]), near - 2 * step)
            t1 = min(np.tan(theta1[row]) if theta1[row] < np.pi / 2 else np.inf, reach)
            if t1 <= t0:
                continue
            n_theta = max(1, int(np.ceil((t1 - t0) / step)))
            n_phi = max(1, int(np.ceil(t1 * (2.0 * np.pi / width) / step)))
            edges = np.arctan(np.linspace(t0, t1, n_theta + 1))
            centres = 0.5 * (np.tan(edges[:-1]) + np.tan(edges[1:]))
            weight = 0.5 * (np.sin(edges[1:]) ** 2 - np.sin(edges[:-1]) ** 2) * (
                2.0 * np.pi / (width * n_phi)
            )
            sub_cols = np.arange(width * n_phi)
            phi = ((sub_cols + 0.5) / (width * n_phi) - 0.5) * 2.0 * np.pi + self.rotation
            kept = keep_phi(phi, 2.0 * np.pi / (width * n_phi))
            sub_cols, phi = sub_cols[kept], phi[kept]
            chunk = max(1, (1 << 21) // max(1, len(phi)))  # bounded memory per pass
            for lo in range(0, n_theta, chunk):
                sx = centres[lo : lo + chunk, None] * np.sin(phi)[None, :]
                sy = centres[lo : lo + chunk, None] * np.cos(phi)[None, :]
                index, share, sub_row, sub_col = _bilinear_shares(grid, sx, sy, wrap)
                texel = self.image[row, sub_cols[sub_col] // n_phi].astype(np.float64)
                pending.append((index, texel * (share * weight[lo + sub_row])[:, None]))
                if sum(len(i) for i, _ in pending) > 1 << 22:
                    _flush(accum, pending)
        _flush(accum, pending)
        weighted = accum.reshape(channels, rows, cols).astype(np.float32)
        outside = self.total_irradiance() - weighted.sum(axis=(1, 2), dtype=np.float64)
        if wrap is not None:
            grid = sky_grid((0, 0), wrap[1], grid.pixel)
        return SkyRaster(grid, weighted, outside)


def _grid_footprint(grid: Grid):
    """Where a sky-plane grid lies as seen from the zenith, with one cell of margin.

    Returns (near, reach, keep_phi): the nearest and farthest distances [tan] of the grid from
    the origin, and keep_phi(phi, dphi) -> bool mask of the azimuths [rad] (each of width dphi)
    whose rays can cross the grid.
    """
    x_min, y_min, x_max, y_max = grid.extent
    margin = grid.pixel
    x_min, y_min, x_max, y_max = x_min - margin, y_min - margin, x_max + margin, y_max + margin
    reach = np.hypot(max(abs(x_min), abs(x_max)), max(abs(y_min), abs(y_max)))
    near = np.hypot(max(0.0, x_min, -x_max), max(0.0, y_min, -y_max))
    if near == 0.0:
        return near, reach, lambda phi, dphi: np.ones(len(phi), dtype=bool)
    corners = np.arctan2([x_min, x_min, x_max, x_max], [y_min, y_max, y_min, y_max])
    middle = np.arctan2((x_min + x_max) / 2, (y_min + y_max) / 2)
    spread = np.angle(np.exp(1j * (corners - middle)))  # within (-pi/2, pi/2): the grid is off the origin
    lo, hi = spread.min(), spread.max()

    def keep_phi(phi, dphi):
        off = np.angle(np.exp(1j * (phi - middle)))
        return (off >= lo - dphi) & (off <= hi + dphi)

    return near, reach, keep_phi


def _row_bounds(height: int):
    """Zenith-angle bounds [rad] of the equirectangular rows that reach above the horizon."""
    edges = np.arange(height + 1) * (np.pi / height)
    upper = edges[:-1] < np.pi / 2
    return edges[:-1][upper], np.minimum(edges[1:][upper], np.pi / 2)


def _bilinear_shares(grid: Grid, sx, sy, wrap=None):
    """Bilinear deposits of sky-plane points (sx, sy) (2-D arrays) on the cells of ``grid``.

    Returns the flat cell index, the share (the four shares of a point sum to 1), and the row and
    column of the point each deposit came from; shares falling off the grid are left out. With
    ``wrap`` = (offset of grid cell [0, 0], period), the index is that of the offset modulo
    the period, on a (period rows, period cols) raster.
    """
    rows, cols = grid.shape
    rowf, colf = grid.raster_from_ground(sx, sy)
    r0 = np.floor(rowf)
    c0 = np.floor(colf)
    fr, fc = rowf - r0, colf - c0
    r0, c0 = r0.astype(np.int64), c0.astype(np.int64)
    point_row, point_col = np.indices(sx.shape)
    parts = []
    for dr, dc, share in (
        (0, 0, (1 - fr) * (1 - fc)),
        (0, 1, (1 - fr) * fc),
        (1, 0, fr * (1 - fc)),
        (1, 1, fr * fc),
    ):
        r, c = r0 + dr, c0 + dc
        inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        r, c = r[inside], c[inside]
        if wrap is not None:
            (r_start, c_start), (r_period, c_period) = wrap
            r, c, cols_out = (r + r_start) % r_period, (c + c_start) % c_period, c_period
        else:
            cols_out = cols
        parts.append((r * cols_out + c, share[inside], point_row[inside], point_col[inside]))
    return tuple(np.concatenate(arrays) for arrays in zip(*parts))


def _flush(accum, pending: list) -> None:
    """Add the pending (flat index, values (n, channels)) deposits to ``accum`` and empty the list."""
    if not pending:
        return
    index = np.concatenate([i for i, _ in pending])
    values = np.concatenate([v for _, v in pending])
    for ch in range(accum.shape[0]):
        accum[ch] += np.bincount(index, weights=values[:, ch], minlength=accum.shape[1])
    pending.clear()


MODELS = {"uniform": UniformSky, "hdri": EquirectSky}
