"""Ground irradiance as the correlation of a weighted sky raster with a canopy mask (Max 1991).

Orientation, fixed here and used everywhere. All rasters share one pixel lattice of pixel ``p``
[m] on the ground and canopy planes. A sky *offset* ``i = (dr, dc)`` in whole cells is the
sky-plane point ``s = (dc * q, -dr * q)`` with ``q = p / h`` [tan], so a ray leaving ground
pixel ``k`` through offset ``i`` crosses the canopy plane at lattice pixel ``k + i``
(paper eq. 2, with north-up rows). The ground irradiance is the correlation

    g[k] = sum_i e[i] m[k + i]                                          (paper eq. 2)

and with FFTs, for real ``e`` (sky) and ``m`` (mask) on a circular domain,

    g = irfft2(conj(rfft2(e)) * rfft2(m)).

A sun low in the east has ``dc > 0``, so the shadow of canopy pixel ``c`` falls on
``k = c - i``: west of it. ``tests/test_shadow.py`` proves this against a Monte Carlo estimator
that works in world coordinates.

Two layouts, both exact for the discrete sum (docs/method.md, "The correlation"):

- isolated: ``m = 1 - o`` with the occlusion ``o`` zero away from the canopy, so
  ``g = total - (e correlated with o)``; only the offsets that can reach the canopy from
  some window pixel are kept, and the FFT is padded to the full linear size.
- periodic: the sky is folded modulo the tile period and correlated circularly on one tile;
  the sky outside the square is added times the mean transmittance of the tile.

Spectra are complex64 (float32 rasters); ``workers`` is the FFT thread count.

Why one module: the isolated, periodic and fine-sun correlations share the one orientation of
offsets fixed above and its index bookkeeping; apart, each would restate the sign conventions.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.fft as sfft
import scipy.sparse as sparse
from numpy.typing import ArrayLike

from pipeline.core.geometry import Grid, fold, lattice_offset, sky_grid, sky_offset, wrapped_spans

__all__ = [
    "MAX_SKY_CELLS", "sky_half_cells", "IsolatedPlan", "plan_isolated", "occlusion_spectrum", "ground_isolated",
    "ground_isolated_block", "coarser_isolated",
    "PeriodicPlan", "plan_periodic", "transmittance_spectrum", "ground_periodic", "SunPlan", "sun_offset_range",
    "plan_sun", "fine_mask_spectrum", "ground_sun", "resample_bilinear", "interpolation_matrices",
]

if TYPE_CHECKING:
    from pipeline.sky.raster import SkyRaster

MAX_SKY_CELLS = 25_000_000  # most cells of the sky square of a periodic plan (plan_periodic) [count]


def sky_half_cells(height: float, pixel: float, alpha: float) -> int:
    """Half-width A, in cells, of the sky square |s|_inf <= tan(alpha): offsets -A..A.

    Parameters
    ----------
    height : float
        Canopy height above the ground [m].
    pixel : float
        Ground pixel [m].
    alpha : float
        Half-angle of the sky square [rad].

    Returns
    -------
    int
        A = round(tan(alpha) height / pixel) [cell].
    """
    return int(round(np.tan(alpha) * height / pixel))


@dataclass(frozen=True)
class IsolatedPlan:
    """Index bookkeeping of one isolated canopy layer under one ground window.

    Attributes
    ----------
    window_shape : tuple of (int, int)
        (rows, cols) of the ground window, which is the lattice origin [pixel].
    canopy_start : tuple of (int, int)
        Lattice position of the occlusion raster [pixel].
    canopy_shape : tuple of (int, int)
        Size of the occlusion raster [pixel].
    sky : Grid or None
        The sky offsets that can reach the canopy, within the sky square; None if none does [tan].
    fft_shape : tuple of (int, int)
        (rows, cols) of the zero-padded transforms.
    start : tuple of (int, int)
        (rows, cols) index of ground pixel [0, 0] in the circular correlation.
    exact : bool
        Every ray from the window that meets the canopy lies inside the square.
    """

    window_shape: tuple[int, int]
    canopy_start: tuple[int, int]
    canopy_shape: tuple[int, int]
    sky: Grid | None
    fft_shape: tuple[int, int]
    start: tuple[int, int]
    exact: bool


def plan_isolated(window: Grid, canopy: Grid, *, height: float, alpha: float) -> IsolatedPlan:
    """Plan the exact linear correlation of an isolated canopy raster with the sky.

    Parameters
    ----------
    window : Grid
        Ground grid [m].
    canopy : Grid
        Occlusion grid on the same lattice [m].
    height : float
        Canopy height [m].
    alpha : float
        Half-angle of the sky square [rad].

    Returns
    -------
    IsolatedPlan
        The plan.
    """
    q = window.pixel / height
    half = sky_half_cells(height, window.pixel, alpha)
    canopy_start = lattice_offset(canopy, window)
    sky_start: list[int] = []
    sky_shape: list[int] = []
    fft_shape: list[int] = []
    start: list[int] = []
    exact = True
    for axis in range(2):
        n_win, n_can, c0 = window.shape[axis], canopy.shape[axis], canopy_start[axis]
        lo, hi = c0 - (n_win - 1), c0 + n_can - 1  # offsets that reach the canopy
        exact &= -half <= lo and hi <= half
        lo, hi = max(lo, -half), min(hi, half)
        n_sky = hi - lo + 1
        d_lo = lo - c0  # circular index of ground pixel 0: r[d] = sum_u a[u] b[d + u]
        d_hi = d_lo + n_win - 1
        length = max(n_can - d_lo, d_hi + n_sky, n_can, n_sky, 1)
        sky_start.append(lo)
        sky_shape.append(n_sky)
        fft_shape.append(sfft.next_fast_len(length, real=True))
        start.append(d_lo)
    reaches = all(n > 0 for n in sky_shape)
    sky = sky_grid(_pair(sky_start), _pair(sky_shape), q) if reaches else None
    return IsolatedPlan(
        window.shape, canopy_start, canopy.shape, sky, _pair(fft_shape), _pair(start), exact
    )


def _pair(values: Iterable[int]) -> tuple[int, int]:
    """The two (rows, cols) of ``values`` as a tuple."""
    rows, cols = values
    return rows, cols


def occlusion_spectrum(occlusion: np.ndarray, plan: IsolatedPlan, *, workers: int = 1) -> np.ndarray:
    """rfft2 of the occlusion raster ``o = 1 - m``, zero-padded to the plan.

    As two passes, the rows' rfft then the columns' FFT, so that the rows of padding (about
    half of them) are not transformed: the same sums as ``rfft2(o, s=plan.fft_shape)``. This is
    done per frame, from the stored occlusion (docs/accuracy.md, "The cache").

    Parameters
    ----------
    occlusion : numpy.ndarray
        (rows, cols) occlusion [1].
    plan : IsolatedPlan
        The plan.
    workers : int, optional
        FFT thread count.

    Returns
    -------
    numpy.ndarray
        complex64 (plan.fft_shape[0], plan.fft_shape[1] // 2 + 1).
    """
    o = np.asarray(occlusion, dtype=np.float32)
    rows = sfft.rfft(o, n=plan.fft_shape[1], axis=-1, workers=workers)
    return sfft.fft(rows, n=plan.fft_shape[0], axis=-2, workers=workers, overwrite_x=True)


def ground_isolated(sky: SkyRaster, spectrum: np.ndarray, plan: IsolatedPlan, *, workers: int = 1) -> np.ndarray:
    """Ground irradiance under an isolated canopy layer.

    g = total - (e correlated with o): exact for the discrete sum, no periodic copies.

    Parameters
    ----------
    sky : sky.raster.SkyRaster
        The weighted sky raster on ``plan.sky`` [radiance x sr].
    spectrum : numpy.ndarray
        ``occlusion_spectrum`` of the layer.
    plan, workers
        As in ``occlusion_spectrum``.

    Returns
    -------
    numpy.ndarray
        (channels, rows, cols) float32 [radiance x sr].
    """
    total = sky.irradiance.astype(np.float32)[:, None, None]
    if plan.sky is None:
        return np.broadcast_to(total, (len(total), *plan.window_shape)).copy()
    blocked = _correlate(sky.weighted, spectrum, plan.fft_shape, workers, rows=(plan.start[0], plan.window_shape[0]))
    g = _take_wrapped(blocked, (0, plan.start[1]), plan.window_shape)
    return np.subtract(total, g, out=g)


def ground_isolated_block(block: np.ndarray, at: tuple[int, int], irradiance: np.ndarray, spectrum: np.ndarray,
                          plan: IsolatedPlan, *, workers: int = 1) -> np.ndarray:
    """``ground_isolated`` of a sky raster on ``plan.sky`` zero but for one block (the coarse sun
    kernel), transforming only the block's rows along the rows (``_correlate``'s ``at``): the same bits.

    Parameters
    ----------
    block : numpy.ndarray
        (channels, r, c) float32: the raster's cells that are not zero, from (row, column) ``at``.
    at : (int, int)
        Where the block starts in the raster.
    irradiance : numpy.ndarray
        (channels,) float64: the whole raster's ``SkyRaster.irradiance`` [radiance x sr].
    spectrum, plan, workers
        As in ``ground_isolated``.

    Returns
    -------
    numpy.ndarray
        (channels, rows, cols) float32, as ``ground_isolated`` [radiance x sr].
    """
    total = np.asarray(irradiance).astype(np.float32)[:, None, None]
    blocked = _correlate(np.ascontiguousarray(block, dtype=np.float32), spectrum, plan.fft_shape, workers,
                         rows=(plan.start[0], plan.window_shape[0]), at=at)
    g = _take_wrapped(blocked, (0, plan.start[1]), plan.window_shape)
    return np.subtract(total, g, out=g)


def coarser_isolated(spectrum: np.ndarray, plan: IsolatedPlan, factor: int,
                     window: Grid) -> tuple[IsolatedPlan, np.ndarray, Grid]:
    """An isolated layer's plan and occlusion spectrum at ``factor`` times the ground pixel.

    The occlusion averaged over blocks of ``factor`` x ``factor`` cells, by its spectrum (each
    axis: the block mean's transfer, then the aliases of the decimation summed), so that
    ``ground_isolated`` of the sky raster summed over the same blocks of sky cells gives the
    ground's light at the coarser pixel: the full-resolution correlation at the coarse cells'
    centres, smoothed over less than ``factor`` cells each way. The coarse cells are centred on
    fine cells of the window (those whose correlation index is a multiple of ``factor``).

    Parameters
    ----------
    spectrum : numpy.ndarray
        ``occlusion_spectrum`` of the layer, complex (plan.fft_shape[0], plan.fft_shape[1] // 2 + 1).
    plan : IsolatedPlan
        Its plan; each of ``fft_shape`` a multiple of ``factor``, the columns' of ``2 factor``.
    factor : int
        Coarse cell over fine cell [1].
    window : Grid
        The ground window of ``plan`` [m].

    Returns
    -------
    coarse_plan : IsolatedPlan
        For ``ground_isolated`` with the sky raster summed in blocks of ``factor`` cells
        (``sky.raster.coarser``).
    coarse_spectrum : numpy.ndarray
        complex64 (fft rows / factor, fft cols / (2 factor) + 1).
    grid : Grid
        The coarse cells' grid: centres on the window's cells, inside the window [m].
    """
    n0, n1 = plan.fft_shape
    f = int(factor)
    shifts = np.arange(f)
    h0 = np.exp(2j * np.pi * np.outer(np.arange(n0), shifts) / n0).mean(axis=1)  # the block mean's transfer
    rows = (spectrum * h0[:, None].astype(np.complex64)).reshape(f, n0 // f, -1).mean(axis=0)
    m0 = n0 // f  # the columns: whole spectrum from the half one (a real raster's), then the same
    whole = np.concatenate([rows, np.conj(rows[(-np.arange(m0)) % m0, n1 // 2 - 1:0:-1])], axis=1)
    h1 = np.exp(2j * np.pi * np.outer(np.arange(n1), shifts) / n1).mean(axis=1)
    coarse = (whole * h1[None, :].astype(np.complex64)).reshape(m0, f, n1 // f).mean(axis=1)
    coarse = np.ascontiguousarray(coarse[:, : n1 // (2 * f) + 1], dtype=np.complex64)
    first = [(-s) % f for s in plan.start]  # window index of the first coarse centre
    shape = _pair((n - 1 - i) // f + 1 for n, i in zip(plan.window_shape, first))
    start = _pair((i + s) // f for i, s in zip(first, plan.start))
    coarse_plan = replace(plan, window_shape=shape, fft_shape=(n0 // f, n1 // f), start=start,
                          sky=None if plan.sky is None else replace(plan.sky, pixel=f * plan.sky.pixel,
                                                                    shape=_pair(-(-n // f) for n in plan.sky.shape)))
    origin = (window.origin[0] + (first[1] + 0.5 - 0.5 * f) * window.pixel,
              window.origin[1] - (first[0] + 0.5 - 0.5 * f) * window.pixel)
    return coarse_plan, coarse, Grid(origin, f * window.pixel, shape)


@dataclass(frozen=True)
class PeriodicPlan:
    """Index bookkeeping of one periodic canopy tile under one ground window.

    Attributes
    ----------
    window_shape : tuple of (int, int)
        (rows, cols) of the ground window, the lattice origin [pixel].
    tile_start : tuple of (int, int)
        Lattice position of tile pixel [0, 0] [pixel].
    tile_shape : tuple of (int, int)
        The period [pixel].
    sky : Grid
        The whole sky square, offsets -A..A [tan].
    """

    window_shape: tuple[int, int]
    tile_start: tuple[int, int]
    tile_shape: tuple[int, int]
    sky: Grid


def plan_periodic(window: Grid, tile: Grid, *, height: float, alpha: float) -> PeriodicPlan:
    """Plan the circular correlation of a periodic canopy tile (on ``window``'s lattice) with the sky.

    The sky is the whole square of offsets -A..A (``sky_half_cells``), in cells of ``window.pixel / height``.

    Parameters
    ----------
    window, height, alpha
        As in ``plan_isolated``.
    tile : Grid
        One period of the canopy, on the same lattice [m].

    Returns
    -------
    PeriodicPlan
        The plan.

    Raises
    ------
    ValueError
        If the sky square would have more than MAX_SKY_CELLS cells.
    """
    half = sky_half_cells(height, window.pixel, alpha)
    n = 2 * half + 1
    if n * n > MAX_SKY_CELLS:
        raise ValueError(
            f"the sky square would be {n} x {n} cells; lower sky.alpha or raise ground.pixel"
        )
    sky = sky_grid((-half, -half), (n, n), window.pixel / height)
    return PeriodicPlan(window.shape, lattice_offset(tile, window), tile.shape, sky)


def transmittance_spectrum(transmittance: np.ndarray, *, workers: int = 1) -> np.ndarray:
    """rfft2 of a periodic tile's transmittance ``m``.

    Parameters
    ----------
    transmittance : numpy.ndarray
        (rows, cols) transmittance [1].
    workers : int, optional
        FFT thread count.

    Returns
    -------
    numpy.ndarray
        complex64 (rows, cols // 2 + 1).
    """
    m = np.asarray(transmittance, dtype=np.float32)
    return sfft.rfft2(m, axes=(-2, -1), workers=workers)


def ground_periodic(
    sky: SkyRaster, spectrum: np.ndarray, plan: PeriodicPlan, mean_transmittance: float, *, workers: int = 1
) -> np.ndarray:
    """Ground irradiance under a periodic canopy tile.

    The sky square is folded onto one tile (unless the raster comes folded already, made with
    ``raster(plan.sky, fold_period=plan.tile_shape)``) and correlated circularly (exact for the discrete
    sum over the square); the sky outside the square reaches the ground times the tile's mean
    transmittance.

    Parameters
    ----------
    sky, workers
        As in ``ground_isolated``.
    spectrum : numpy.ndarray
        ``transmittance_spectrum`` of the tile.
    plan : PeriodicPlan
        The plan.
    mean_transmittance : float
        Mean transmittance of the tile [1].

    Returns
    -------
    numpy.ndarray
        The ground irradiance, as ``ground_isolated`` returns it.
    """
    sky_start = sky_offset(sky.grid)
    folded = fold(sky.weighted, sky_start, plan.tile_shape)
    lit = _correlate(folded, spectrum, plan.tile_shape, workers, rows=(-plan.tile_start[0], plan.window_shape[0]))
    g = _take_wrapped(lit, (0, -plan.tile_start[1]), plan.window_shape)
    g += (sky.outside * mean_transmittance).astype(np.float32)[:, None, None]
    return g


@dataclass(frozen=True)
class SunPlan:
    """Index bookkeeping of the fine sun correlation over one ground window.

    docs/method.md, "Two scales for the sun": the sun disc as a small kernel of fine sky cells
    ``q = p / h``, correlated with a fine transmittance mask of the canopy plane.

    Attributes
    ----------
    window_shape : tuple of (int, int)
        (rows, cols) of the fine ground window, the lattice origin [pixel].
    offset_lo, offset_hi : tuple of (int, int)
        The fine sky offsets (dr, dc) the kernel may occupy, both inclusive [cell].
    mask : Grid
        The fine canopy mask this needs: the window moved by ``offset_lo`` and grown by the range,
        so no ray from the window through the kernel leaves it [m].
    fft_shape : tuple of (int, int)
        (rows, cols) of the transforms; the correlation never wraps.
    """

    window_shape: tuple[int, int]
    offset_lo: tuple[int, int]
    offset_hi: tuple[int, int]
    mask: Grid
    fft_shape: tuple[int, int]


def sun_offset_range(centres: ArrayLike, *, reach: float, q: float) -> tuple[tuple[int, int], tuple[int, int]]:
    """The fine sky offsets that cover a sun disc at each of several centres, with two cells to spare.

    Parameters
    ----------
    centres : numpy.ndarray
        (n, 2) or (2,) sky-plane points of the disc's centre [tan].
    reach : float
        How far the disc reaches from its centre [tan].
    q : float
        Fine sky cell [tan].

    Returns
    -------
    lo, hi : tuple of (int, int)
        The offsets (dr, dc), inclusive [cell].
    """
    points = np.atleast_2d(np.asarray(centres, dtype=np.float64))
    rows = -points[:, 1] / q
    cols = points[:, 0] / q
    span = reach / q + 2.0
    lo = (int(np.floor(rows.min() - span)), int(np.floor(cols.min() - span)))
    hi = (int(np.ceil(rows.max() + span)), int(np.ceil(cols.max() + span)))
    return lo, hi


def plan_sun(window: Grid, *, offset_lo: tuple[int, int], offset_hi: tuple[int, int]) -> SunPlan:
    """Plan the fine sun correlation of ``window`` for kernels inside the offsets ``offset_lo``..``offset_hi``.

    Parameters
    ----------
    window : Grid
        Fine ground grid [m].
    offset_lo, offset_hi : tuple of (int, int)
        The fine sky offsets (dr, dc), inclusive [cell].

    Returns
    -------
    SunPlan
        The plan.
    """
    p = window.pixel
    extra = tuple(hi - lo for lo, hi in zip(offset_lo, offset_hi))
    shape = _pair(n + e for n, e in zip(window.shape, extra))
    origin = (window.origin[0] + offset_lo[1] * p, window.origin[1] - offset_lo[0] * p)
    fft_shape = _pair(sfft.next_fast_len(n, real=True) for n in shape)
    return SunPlan(window.shape, _pair(offset_lo), _pair(offset_hi), Grid(origin, p, shape), fft_shape)


def fine_mask_spectrum(transmittance: np.ndarray, plan: SunPlan, *, workers: int = 1) -> np.ndarray:
    """rfft2 of the fine mask ``m`` on ``plan.mask``, zero-padded to the plan; the padding is never read.

    Parameters
    ----------
    transmittance : numpy.ndarray
        ``plan.mask.shape`` transmittance [1].
    plan, workers
        As in ``occlusion_spectrum``, the plan a SunPlan.

    Returns
    -------
    numpy.ndarray
        complex64, as ``occlusion_spectrum`` returns it.

    Raises
    ------
    ValueError
        If the mask is not of ``plan.mask.shape``.
    """
    m = np.asarray(transmittance, dtype=np.float32)
    if m.shape != plan.mask.shape:
        raise ValueError(f"the fine mask is {m.shape}; the plan needs {plan.mask.shape}")
    return sfft.rfft2(m, s=plan.fft_shape, axes=(-2, -1), workers=workers)


def ground_sun(kernel: SkyRaster, spectrum: np.ndarray, plan: SunPlan, *, workers: int = 1,
               add_to: np.ndarray | None = None) -> np.ndarray:
    """Ground irradiance of the sun kernel through the fine mask.

    Exact for the discrete sum: every ray from the window through the kernel meets the fine mask.

    Parameters
    ----------
    kernel : sky.raster.SkyRaster
        The sun disc on a fine sky grid (``sky_grid(start, shape, q)``, q = fine pixel / height);
        it must lie inside the plan's offsets [radiance x sr].
    spectrum : numpy.ndarray
        ``fine_mask_spectrum`` of the mask.
    plan, workers
        The SunPlan; the FFT thread count (optional).
    add_to : numpy.ndarray or None
        (channels, rows, cols) float32: when given, the light is added to it in place (the bits
        of ``add_to + ground_sun(...)``, without the light's own copy) and it is returned.

    Returns
    -------
    numpy.ndarray
        (channels, rows, cols) float32 [radiance x sr], as in ``ground_isolated`` (or ``add_to``).

    Raises
    ------
    ValueError
        If the kernel lies outside the planned offsets.
    """
    start = sky_offset(kernel.grid)
    u0 = tuple(s - lo for s, lo in zip(start, plan.offset_lo))
    room = tuple(hi - lo + 1 for lo, hi in zip(plan.offset_lo, plan.offset_hi))
    shape = kernel.weighted.shape[-2:]
    if min(u0) < 0 or any(u + n > r for u, n, r in zip(u0, shape, room)):
        raise ValueError(
            f"the sun kernel at offsets {start} size {shape} lies outside the planned "
            f"offsets {plan.offset_lo}..{plan.offset_hi}"
        )
    lit = _correlate(kernel.weighted, spectrum, plan.fft_shape, workers, rows=(0, plan.window_shape[0]), at=u0)
    if add_to is not None:
        return np.add(add_to, lit[..., :, : plan.window_shape[1]], out=add_to)
    return np.ascontiguousarray(lit[..., :, : plan.window_shape[1]])


def resample_bilinear(raster: np.ndarray, grid: Grid, target: Grid) -> np.ndarray:
    """``raster`` on ``grid`` sampled bilinearly at the pixel centres of ``target``, edges held.

    The coarse sky light under the fine sun window. Separable: a sparse interpolation matrix per
    axis, ``R @ raster @ C.T``, applied by a compiled loop (``kernels.arrays.resample_separable``) with the
    float32 arithmetic of scipy's sparse products, which tests/test_shadow.py holds it to.

    Parameters
    ----------
    raster : numpy.ndarray
        (channels, rows, cols) on ``grid``.
    grid : Grid
        The raster's grid [m].
    target : Grid
        The grid sampled (same units, axes aligned) [m].

    Returns
    -------
    numpy.ndarray
        (channels, target rows, target cols) float32, in the units of ``raster``.
    """
    from pipeline.kernels import arrays

    out = np.empty(raster.shape[:-2] + target.shape, dtype=np.float32)
    image = np.ascontiguousarray(raster, dtype=np.float32).reshape(-1, *grid.shape)
    arrays.resample_separable(image, *_interpolations(grid, target), out.reshape(-1, *target.shape))
    return out


@functools.lru_cache(maxsize=8)
def _interpolations(grid: Grid, target: Grid) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``interpolation_matrices`` as the rows and weights that ``kernels.arrays.resample_separable``
    reads: (row_at, row_weight, col_at, col_weight), each (n, k), in the matrices' stored order.
    They depend on the grids alone, so the frames of a run make them once. Read-only."""
    tables: list[np.ndarray] = []
    for matrix in interpolation_matrices(grid, target):
        k = matrix.nnz // matrix.shape[0]  # the same in every row (_interpolation)
        assert np.array_equal(matrix.indptr, np.arange(matrix.shape[0] + 1) * k)
        tables += [matrix.indices.astype(np.int64).reshape(-1, k),
                   matrix.data.astype(np.float32, copy=False).reshape(-1, k)]
    for table in tables:
        table.flags.writeable = False
    row_at, row_weight, col_at, col_weight = tables
    return row_at, row_weight, col_at, col_weight


def interpolation_matrices(grid: Grid, target: Grid) -> tuple[sparse.csr_matrix, sparse.csr_matrix]:
    """``resample_bilinear``'s sparse matrices R and C along rows and columns.

    Parameters
    ----------
    grid : Grid
        The raster's grid [m].
    target : Grid
        The grid sampled [m].

    Returns
    -------
    R, C : scipy.sparse.csr_matrix
        (target rows, grid rows) and (target cols, grid cols) float32 weights [1].
    """
    x, _ = target.ground_from_raster(0.0, np.arange(target.shape[1]))
    _, y = target.ground_from_raster(np.arange(target.shape[0]), 0.0)
    r, _ = grid.raster_from_ground(0.0, y)
    _, c = grid.raster_from_ground(x, 0.0)
    return _interpolation(r, grid.shape[0]), _interpolation(c, grid.shape[1])


def _interpolation(u: np.ndarray, n: int) -> sparse.csr_matrix:
    """Sparse (len(u), n) matrix of linear interpolation at fractional indices ``u``, held at
    the ends."""
    u = np.clip(u, 0, n - 1)
    u0 = np.minimum(np.floor(u).astype(np.intp), max(n - 2, 0))
    u1 = np.minimum(u0 + 1, n - 1)
    f = (u - u0).astype(np.float32)
    at = np.arange(len(u))
    return sparse.csr_matrix((np.concatenate([1 - f, f]), (np.concatenate([at, at]),
                              np.concatenate([u0, u1]))), shape=(len(u), n))


def _correlate(sky, spectrum, fft_shape, workers, rows=None, at=None):
    """Circular correlation of sky (channels, rows, cols) with a mask given by its spectrum: the
    whole (channels, *fft_shape), or with ``rows`` = (start, count) only its rows (start + u) mod
    fft_shape[0], u < count (channels, count, fft_shape[1]). With ``at`` = (row, col), sky is a block
    at that place in a raster of zeros of ``fft_shape`` (the fine sun kernel).

    Both are made as ``rfft2`` and ``irfft2`` make them, to the bit (pocketfft's ``r2c`` and ``c2r``
    over two axes, docs/accuracy.md, "The rows a window keeps"): forward, a real pass along the rows
    (a row of zeros gives zeros: only the block's rows are transformed), then a complex pass down the
    columns; back, the complex pass down the columns unscaled, the real pass along the rows kept,
    and one scale 1 / (rows x cols) in float32 (a grove frame's 1500 x 1440 inverse 43 to 28 ms for
    the 800 rows its window keeps)."""
    if at is None:
        sky_spectrum = sfft.rfft2(sky, s=fft_shape, axes=(-2, -1), workers=workers)
    else:
        placed = np.zeros((*sky.shape[:-1], fft_shape[1]), dtype=np.float32)
        placed[..., at[1]:at[1] + sky.shape[-1]] = sky
        sky_spectrum = np.zeros((*sky.shape[:-2], fft_shape[0], fft_shape[1] // 2 + 1), dtype=np.complex64)
        sky_spectrum[..., at[0]:at[0] + sky.shape[-2], :] = sfft.rfft(placed, axis=-1, workers=workers)
        sky_spectrum = sfft.fft(sky_spectrum, axis=-2, workers=workers, overwrite_x=True)
    np.conjugate(sky_spectrum, out=sky_spectrum)
    sky_spectrum *= spectrum
    if rows is None or rows[1] >= fft_shape[0]:
        whole = sfft.irfft2(sky_spectrum, s=fft_shape, axes=(-2, -1), workers=workers)
        return whole if rows is None else _take_wrapped(whole, (rows[0], 0), (rows[1], fft_shape[1]))
    columns = sfft.ifft(sky_spectrum, axis=-2, norm="forward", workers=workers, overwrite_x=True)
    first = rows[0] % fft_shape[0]  # the rows kept: a view where they do not wrap round the period
    kept = (columns[..., first:first + rows[1], :] if first + rows[1] <= fft_shape[0]
            else columns[..., (first + np.arange(rows[1])) % fft_shape[0], :])
    out = sfft.irfft(kept, n=fft_shape[1], axis=-1, norm="forward", workers=workers, overwrite_x=True)
    out *= np.float32(np.longdouble(1) / np.longdouble(fft_shape[0] * fft_shape[1]))  # pocketfft's T(1 / ldbl(N))
    return out


def _take_wrapped(raster, start, shape):
    """raster[..., (start + arange(shape)) mod size] on the last two axes, as a new array
    (the raster itself when that is the identity: callers pass fresh arrays)."""
    size = raster.shape[-2:]
    if tuple(shape) == size and start[0] % size[0] == 0 and start[1] % size[1] == 0:
        return raster
    out = np.empty(raster.shape[:-2] + tuple(shape), dtype=raster.dtype)
    for dst_r, src_r in wrapped_spans(start[0], shape[0], size[0]):
        for dst_c, src_c in wrapped_spans(start[1], shape[1], size[1]):
            out[..., dst_r, dst_c] = raster[..., src_r, src_c]
    return out
