"""The weighted sky on a sky-plane grid (Max 1991, eq. 1 and Fig. 6), and the bilinear deposits
that rasterise an image's texels onto such a grid keeping their energy.

A sky raster cell holds the integral of ``L(s) cos^4(theta) dA`` over the cell: radiance times
projected solid angle, so that the unshadowed irradiance of the ground is the plain sum of the
raster plus ``outside``, the irradiance of all the sky the raster does not cover. No hidden
normalising factor: radiance in, irradiance [radiance x sr] out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from pipeline.core.geometry import Grid

__all__ = ["KEPT_RASTERS", "SkyRaster", "coarser", "kept_raster"]


KEPT_RASTERS = 4
"""Most sky-plane rasters a still sky keeps for the next frames (an ``EquirectSky``; a procedural
sky without clouds, ``procedural.ProceduralSky.raster``): a run asks for one or two per layer. [count]"""


@dataclass(frozen=True)
class SkyRaster:
    """The weighted sky on a sky-plane grid.

    Parameters
    ----------
    grid : geometry.Grid
        The sky-plane grid [tan]; cell (r, c) is the sky offset s = grid centre.
    weighted : numpy.ndarray
        (channels, rows, cols) float32 radiance x projected solid angle per cell [radiance x sr].
    outside : numpy.ndarray
        (channels,) float64 irradiance of the sky outside the raster [radiance x sr].
    """

    grid: Grid
    weighted: np.ndarray
    outside: np.ndarray

    @cached_property
    def irradiance(self) -> np.ndarray:
        """The raster's sum over its cells plus ``outside``: the irradiance the open, unshadowed
        ground gets from the light the raster holds, per channel (channels,) float64 [radiance x sr]."""
        return self.weighted.sum(axis=(1, 2), dtype=np.float64) + self.outside


_SEEN = object()  # a key asked for once, its raster not kept (kept_raster's ``again``)


def kept_raster(kept: dict, key: tuple, compute: Callable[[], SkyRaster], *, again: bool = False) -> SkyRaster:
    """The raster ``compute()`` makes, kept in ``kept`` under ``key`` for the next call (read-only; at
    most ``KEPT_RASTERS`` keys, the oldest dropped first): a still sky gives every frame of a run the
    same raster. A key that cannot be hashed (a grid given with lists) keeps nothing.

    Parameters
    ----------
    kept : dict
        {key: raster}, the sky's, written.
    key : tuple
        What the raster depends on (the grid, the fold, a sky that changes over time).
    compute : callable
        ``compute()`` -> SkyRaster.
    again : bool
        Keep the raster only once its key is asked for a second time: a sky that moves (the sun
        along its path) asks for each key once, and rasters kept for nothing cost a frame of
        eclipse.yaml 10 ms more in fresh memory.

    Returns
    -------
    SkyRaster
        The raster [radiance x sr].
    """
    try:
        raster = kept.get(key)
    except TypeError:
        return compute()
    if raster is None or raster is _SEEN:
        keep = raster is _SEEN or not again
        raster = compute()
        if keep:
            for array in (raster.weighted, raster.outside):
                array.flags.writeable = False
        kept.pop(key, None)
        while len(kept) >= KEPT_RASTERS:
            kept.pop(next(iter(kept)))
        kept[key] = raster if keep else _SEEN
    return raster


def coarser(raster: SkyRaster, factor: int) -> SkyRaster:
    """A sky raster's cells summed in blocks of ``factor`` x ``factor`` (the last ones padded
    with dark cells): the same light on cells ``factor`` times as wide, cell [0, 0] holding the
    first block (``shadow.coarser_isolated``).

    Parameters
    ----------
    raster : SkyRaster
        The sky raster [radiance x sr].
    factor : int
        Coarse cell over fine cell [1].

    Returns
    -------
    SkyRaster
        float32, ``outside`` as given [radiance x sr].
    """
    f = int(factor)
    count, rows, cols = raster.weighted.shape
    by_cols = np.zeros((count, rows, -(-cols // f)), dtype=np.float32)
    for m in range(f):  # the m-th column of every block
        part = raster.weighted[:, :, m::f]
        by_cols[:, :, :part.shape[2]] += part
    summed = np.zeros((count, -(-rows // f), by_cols.shape[2]), dtype=np.float32)
    for m in range(f):
        part = by_cols[:, m::f]
        summed[:, :part.shape[1]] += part
    grid = Grid(raster.grid.origin, f * raster.grid.pixel, summed.shape[1:])
    return SkyRaster(grid, summed, raster.outside)


def grid_footprint(grid: Grid) -> tuple[float, float, Callable[[np.ndarray, float], np.ndarray]]:
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


def bilinear_shares(grid: Grid, sx: np.ndarray, sy: np.ndarray,
                    wrap: tuple[Sequence[int], Sequence[int]] | None = None) -> tuple[np.ndarray, ...]:
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
    indices = np.indices(sx.shape)
    point_row, point_col = indices[0], indices[1]
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


def flush(accum: np.ndarray, pending: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """Add the pending (flat index, values (n, channels)) deposits to ``accum`` and empty the list."""
    if not pending:
        return
    index = np.concatenate([i for i, _ in pending])
    values = np.concatenate([v for _, v in pending])
    for ch in range(accum.shape[0]):
        accum[ch] += np.bincount(index, weights=values[:, ch], minlength=accum.shape[1])
    pending.clear()
