"""The sky's term of the ground's reflectance through view bands (docs/method.md, "The ground's
reflectance"): Max holds f_r(V, L) independent of V over a patch, so the sky raster is weighted
by the shape at a few views, the bands (``weighted_raster``), each correlated, and blended per
pixel by its view zenith and azimuth (``banded_sky``) with a factor that makes the blend exact on
open ground (``sky_ratio``); ``choose_bands`` places the bands. Directions as in ``brdf``."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.geometry import Grid, fold, sky_grid, sky_offset
from pipeline.ground import shadow
from pipeline.ground.brdf import cell_directions, clamp_view, shape
from pipeline.ground.shadow import IsolatedPlan
from pipeline.ground.view_bands import LastCalls, ViewBands, barycentric, unit_view, view_plane
from pipeline.sky.raster import SkyRaster, coarser

__all__ = [
    "BAND_TOLERANCE", "MAX_BANDS", "SKY_CELLS", "SHAPE_STEP", "BAND_SKY_CELL", "band_factor", "summed_blocks",
    "shaded_bound", "choose_bands", "sky_ratio",
    "banded_sky",
    "open_sky", "shape_on_grid", "weighted_raster",
]

if TYPE_CHECKING:
    from pipeline.config.settings import BrdfConfig  # model and parameters: any value with those two fields
    from pipeline.stages.plan import RunPlan

BAND_TOLERANCE = 0.01
"""Largest bound of the blend's relative error under shading (``shaded_bound``) over the pixels
that ``choose_bands`` accepts: it adds view bands until the blend meets it, up to MAX_BANDS. [1]"""

MAX_BANDS = 24
"""Most view bands (each one a channel of the sky raster's correlation per canopy layer). [count]"""


BAND_SKY_CELL = 0.05
"""Widest sky cell [tan] (about 2.9 degrees at the zenith) on which the bands' terms are
correlated under an isolated canopy (``band_factor``). [tan]"""


def band_factor(plan: RunPlan) -> int:
    """How many ground cells a side the bands' terms are correlated on, under an isolated canopy.

    The sky's term under the leaves changes over the shadow of a whole sky's light, much more
    slowly than the ground pixel: the bands' terms are correlated at a pixel ``factor`` times the
    ground's (``shadow.coarser_isolated``), the largest power of 2 whose sky cell is at most
    BAND_SKY_CELL for every layer and that divides every layer's transform; 1 for a periodic
    canopy (its raster repeats with the tile).

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan: its layers' coarse FFT plans are read.

    Returns
    -------
    int
        The factor [1].
    """
    layers = [lp.coarse for lp in plan.layers if isinstance(lp.coarse, IsolatedPlan)]
    if len(layers) < len(plan.layers):
        return 1

    def fits(f: int) -> bool:
        return all(c.fft_shape[0] % f == 0 and c.fft_shape[1] % (2 * f) == 0
                   and min(c.window_shape) >= 8 * f
                   and (c.sky is None or c.sky.pixel * f <= BAND_SKY_CELL * (1 + 1e-9)) for c in layers)

    factor = 1
    while fits(2 * factor):
        factor *= 2
    return factor


_COARSE = LastCalls()
"""``_coarsened``: ``choose_bands`` and ``sky_ratio`` coarsen the same raster in one frame."""

SKY_CELLS = 2048
"""Most cells of the coarsened sky raster on which ``choose_bands`` and ``sky_ratio`` sum the
open sky's term (blocks of the raster's cells). [count]"""


def _coarsened(raster, most_cells: int = 4096, *, channels: bool = False):
    """A sky raster's cells summed in blocks to at most ``most_cells``: directions (m, 3)
    towards each block's centre on the sky plane (the same array for the same grid, so that
    the shape there can be kept while the views stand still) and weights (m,) (channels
    summed), or (m, channels) with ``channels``. [1], [radiance x sr]"""
    dirs, per_channel = _COARSE.get((raster, most_cells), lambda: _coarsen(raster, most_cells))
    return (dirs, per_channel) if channels else (dirs, per_channel.sum(axis=-1))


def _block_step(shape, most_cells: int) -> int:
    """The side of ``_coarsen``'s blocks [cell]."""
    return max(1, int(np.ceil(np.sqrt(shape[0] * shape[1] / most_cells))))


@functools.lru_cache(maxsize=4)
def _block_directions(grid, most_cells: int) -> np.ndarray:
    """Unit vectors (m + k, 3) towards the centres of ``_coarsen``'s blocks of a sky grid, then
    towards its k outermost cells (``_ring_cells``). Read-only. [1]"""
    step = _block_step(grid.shape, most_cells)
    rows, cols = (max(n // step * step, 1) for n in grid.shape)
    sx, sy = grid.ground_from_raster(np.arange(rows), np.arange(cols))
    x, y = sx.reshape(-1, min(step, cols)).mean(axis=-1), sy.reshape(-1, min(step, rows)).mean(axis=-1)
    w = np.stack(np.broadcast_arrays(x[None, :], y[:, None], 1.0), axis=-1)
    dirs = np.concatenate([(w / np.linalg.norm(w, axis=-1, keepdims=True)).reshape(-1, 3), _ring_cells(grid)[1]])
    dirs.flags.writeable = False
    return dirs


def _coarsen(raster, most_cells: int):
    """``_coarsened``'s work: directions (m + k, 3) and light per block and channel (m + k,
    channels); the last k, the raster's outermost cells, carry the light outside the raster,
    shared as their light is, as ``weighted_raster`` weights it (by their mean shape)."""
    light = raster.weighted
    count, rows, cols = light.shape
    step = _block_step((rows, cols), most_cells)
    rows, cols = max(rows // step * step, 1), max(cols // step * step, 1)
    step_r, step_c = min(step, rows), min(step, cols)
    cut = light[:, :rows, :cols].reshape(count, rows // step_r, step_r, cols // step_c, step_c)
    per_block = cut.sum(axis=(2, 4), dtype=np.float64)  # (channels, block rows, block cols)
    (r, c), _ = _ring_cells(raster.grid)
    ring = light[:, r, c].sum(axis=0, dtype=np.float64)
    outside = ring[:, None] * (np.asarray(raster.outside, dtype=np.float64) / max(float(ring.sum()), 1e-30))[None]
    return _block_directions(raster.grid, most_cells), np.concatenate([per_block.reshape(count, -1).T, outside])


_SHAPES = LastCalls(), LastCalls()
"""The shape at ``choose_bands``' sampled views and at ``sky_ratio``'s lattice of views, towards
``_coarsen``'s blocks: the same while the camera and the bands' azimuth stand still."""


def shaded_bound(shapes: np.ndarray, blend: np.ndarray, light: np.ndarray) -> np.ndarray:
    """A bound of the blend's relative error under any canopy, per view.

    Under leaves the sky's term is sum_i e_i m_i s(V, L_i), m_i in [0, 1] the light through the
    canopy along L_i; the bands give r sum_i e_i m_i d_i(V) with d_i = sum_b w_b s(V_b, L_i) and r
    (``sky_ratio``) making it exact on open ground (m = 1). The error sum_i e_i m_i (s_i - r d_i)
    sums to 0 at m = 1, so whatever the shading it is at most half of sum_i e_i |s_i - r d_i|:
    that over the open term (docs/method.md, "The ground's reflectance").

    Parameters
    ----------
    shapes : numpy.ndarray
        (n, m) s(V, L_i) at each view's own V [1].
    blend : numpy.ndarray
        (n, m) the bands' shapes blended at each view, sum_b w_b s(V_b, L_i) [1].
    light : numpy.ndarray
        (m,) e_i, the sky's light per direction [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (n,) [1].
    """
    own = shapes @ light
    ratio = own / np.maximum(blend @ light, 1e-30)
    return 0.5 * (np.abs(shapes - ratio[:, None] * blend) @ light) / np.maximum(own, 1e-30)


def choose_bands(brdf: BrdfConfig, raster: SkyRaster, views: np.ndarray, *, tolerance: float = BAND_TOLERANCE,
                 most: int = MAX_BANDS, samples: int = 192) -> ViewBands:
    """View bands added one at a time where the blend is worst under shading.

    First one band at the sampled view nearest the views' middle (on ``view_plane``); then, while
    the largest ``shaded_bound`` over the sampled pixels exceeds ``tolerance``, a band at the
    worst sampled view, up to ``most`` bands. The samples: about ``samples`` of the views evenly,
    and the views at the ends of their range (nearest the nadir, farthest, both ends of their
    azimuths), so that the bound holds where the blend is held beyond its nodes. Sums over the
    raster's cells coarsened to SKY_CELLS.

    Parameters
    ----------
    brdf : settings.BrdfConfig
        As in ``brdf.shape``.
    raster : sky.raster.SkyRaster
        The sky raster [radiance x sr].
    views : numpy.ndarray
        (n, 3) the pixels' view vectors [1].
    tolerance : float, optional
        Largest bound accepted [1].
    most : int, optional
        Most bands [count].
    samples : int, optional
        About how many of the views are sampled [count].

    Returns
    -------
    ViewBands
        The bands, with the bound they reached.
    """
    dirs, e = _coarsened(raster, SKY_CELLS)
    # the same bands while the camera and the sky's light stand still (a run's frames)
    return _CHOSEN.get((brdf, views, dirs, e.tobytes(), tolerance, most, samples),
                       lambda: _choose(brdf, views, dirs, e, tolerance, most, samples))


_CHOSEN = LastCalls()
"""``choose_bands``' last bands."""


def _turn_from(azimuth, reference: float) -> np.ndarray:
    """Azimuths turned to ``reference``: in [-pi, pi) [rad]."""
    return (np.asarray(azimuth) - reference + np.pi) % (2.0 * np.pi) - np.pi


def _choose(brdf, views_in, dirs, e, tolerance: float, most: int, samples: int) -> ViewBands:
    """``choose_bands``' work over the coarsened raster's directions (m, 3) and light (m,)."""
    spread = clamp_view(views_in[:: max(1, len(views_in) // samples)])
    middle = float(np.arctan2(*spread.mean(axis=0)[:2]))
    every = views_in[:, 2], _turn_from(np.arctan2(views_in[:, 0], views_in[:, 1]), middle)
    ends = [int(np.argmax(every[0])), int(np.argmin(every[0])), int(np.argmin(every[1])), int(np.argmax(every[1]))]
    pick = np.concatenate([spread, clamp_view(views_in[ends])])
    zenith, azimuth = np.arccos(np.clip(pick[:, 2], -1.0, 1.0)), np.arctan2(pick[:, 0], pick[:, 1])
    turn = _turn_from(azimuth, middle)
    middle += 0.5 * float(turn.min() + turn.max())  # the middle of the views' azimuths (sky_ratio's lattice)
    plane = view_plane(zenith, azimuth)
    # a band at a sampled view has that view's shape: the blend is exact there
    exact = _SHAPES[0].get((brdf, views_in, samples, dirs), lambda: shape(brdf, pick[:, None, :], dirs[None]))
    nodes = [int(np.argmin(np.linalg.norm(plane - plane.mean(axis=0), axis=1)))]
    while True:
        errors = shaded_bound(exact, barycentric(plane[nodes], plane).T @ exact[nodes], e)
        worst = int(np.argmax(errors))
        if errors[worst] <= tolerance or len(nodes) >= most or worst in nodes:
            break
        nodes.append(worst)
    return ViewBands(tuple(float(z) for z in zenith[nodes]), tuple(float(a) for a in azimuth[nodes]), middle,
                     float(errors[worst]))


def sky_ratio(brdf: BrdfConfig, raster: SkyRaster, bands: ViewBands, views: np.ndarray, *, lattice: int = 16,
              angles: tuple[np.ndarray, np.ndarray] | None = None, weights: np.ndarray | None = None) -> np.ndarray:
    """The factor that makes the banded sky term exact on open ground, per channel and pixel.

    The open sky's term at the pixel's own view, sum_i e_i s(V, L_i), over what ``banded_sky`` gives
    on open ground (``open_sky`` of S_b,ch = sum_i e_i,ch s(V_b, L_i)), all over the raster
    coarsened to SKY_CELLS cells: it carries the blend's own error on open ground and the change of
    the sky's colour with the view. The open term, smooth in the view, is read on a lattice of
    ``lattice`` x ``lattice`` view zeniths and azimuths over the views' range, bilinearly (held at
    its edges); the blend, with its kinks at the bands, at each pixel's own weights.

    Parameters
    ----------
    brdf, raster
        As for ``choose_bands``.
    bands : ViewBands
        The view bands.
    views : numpy.ndarray
        (n, 3) unit view vectors [1].
    lattice : int, optional
        Side of the lattice of views [count].
    angles : tuple of numpy.ndarray, optional
        If given, the views' zenith angles and azimuths after ``clamp_view`` ((n,) each,
        ``brdf_view.camera_views``) [rad].
    weights : numpy.ndarray, optional
        If given, the bands' weights at the views (B, n) (``ViewBands.weights``) [1].

    Returns
    -------
    numpy.ndarray
        (channels, n) float32 [1].
    """
    dirs, e = _coarsened(raster, SKY_CELLS, channels=True)
    if angles is None:
        views = clamp_view(views)
        angles = np.arccos(np.clip(views[:, 2], -1.0, 1.0)), np.arctan2(views[:, 0], views[:, 1])
    if weights is None:
        weights = bands.weights(*angles).astype(np.float32)
    lows, spans, corner, taps = _lattice_reads(angles[0], angles[1], bands.azimuth, lattice)
    axes = [low + span * np.linspace(0.0, 1.0, lattice) for low, span in zip(lows, spans)]

    def at_lattice() -> np.ndarray:
        z, t = np.meshgrid(*axes, indexing="ij")
        return shape(brdf, unit_view(z, bands.azimuth + t)[..., None, :], dirs)
    own = _SHAPES[1].get((brdf, angles[0], angles[1], bands.azimuth, lattice, dirs), at_lattice) @ e  # (L, L, ch)
    at_bands = shape(brdf, bands.directions()[:, None, :], dirs[None]) @ e  # (B, channels)
    from pipeline.kernels import arrays

    flat = np.ascontiguousarray(np.moveaxis(own, -1, 0).reshape(own.shape[-1], -1).astype(np.float32))
    out = np.empty((len(flat), len(corner)), dtype=np.float32)
    arrays.lattice_read(flat, corner, taps, lattice, out)
    out /= np.maximum(open_sky(bands, weights, at_bands[list(bands.colours)], at_bands.sum(axis=-1)),
                      np.float32(1e-30))
    return out


_READS = LastCalls()
"""``_lattice_reads``: a camera's views are the same every frame (``brdf_view.camera_views``)."""


def _lattice_reads(zenith, azimuth, band_azimuth: float, lattice: int):
    """Where ``sky_ratio`` reads its lattice for views of zenith angles and azimuths (n,) each
    [rad]: the lattice's lowest zenith and turn from ``band_azimuth`` and their spans [rad],
    the flat index (n,) of each view's first lattice corner and the bilinear weights (4, n)
    float32 of its four corners (held at the lattice's edges)."""
    return _READS.get((zenith, azimuth, band_azimuth, lattice),
                      lambda: _lattice_reads_made(zenith, azimuth, band_azimuth, lattice))


def _lattice_reads_made(zenith, azimuth, band_azimuth: float, lattice: int):
    """``_lattice_reads``' work."""
    turn = (azimuth - band_azimuth + np.pi) % (2.0 * np.pi) - np.pi
    lows = [float(zenith.min()), float(turn.min())]
    spans = [max(float(zenith.max()) - lows[0], 1e-9), max(float(turn.max()) - lows[1], 1e-9)]
    i = np.clip((zenith - lows[0]) / spans[0] * (lattice - 1), 0.0, lattice - 1.0)
    j = np.clip((turn - lows[1]) / spans[1] * (lattice - 1), 0.0, lattice - 1.0)
    i0, j0 = np.minimum(i.astype(np.intp), lattice - 2), np.minimum(j.astype(np.intp), lattice - 2)
    fi, fj = (i - i0).astype(np.float32), (j - j0).astype(np.float32)
    taps = np.stack([(1 - fi) * (1 - fj), (1 - fi) * fj, fi * (1 - fj), fi * fj])
    return lows, spans, i0 * lattice + j0, taps


def banded_sky(bands: ViewBands, colours: np.ndarray, bands_light: np.ndarray, weights: np.ndarray,
               ratio: ArrayLike) -> np.ndarray:
    """The sky's term with the reflectance: r_ch sum_b w_b G_b sum_z u_z E_z,ch / sum_ch E_z,ch.

    The bands give how the reflectance modulates the sky's light at the point with the view, the
    colour bands (``ViewBands.colours``) its colour, blended by the view zenith (u_z, the zeniths'
    hats), the ratio the open sky's term at the pixel's own view (docs/method.md, "The ground's
    reflectance").

    Parameters
    ----------
    bands : ViewBands
        The view bands.
    colours : numpy.ndarray
        E_z (Z, channels, n): the colour bands' terms (the sky raster weighted at their views,
        every channel, correlated) [radiance x sr].
    bands_light : numpy.ndarray
        G_b (B, n): each band's term on the channels' sum (``weighted_raster(summed=True)``; a
        colour band's is the sum of its channels) [radiance x sr].
    weights : numpy.ndarray
        w_b (B, n): the bands' weights [1].
    ratio : numpy.ndarray or float
        r_ch (channels, n): ``sky_ratio`` [1].

    Returns
    -------
    numpy.ndarray
        (channels, n) float32 [radiance x sr].
    """
    blend = bands_light[0] * weights[0]
    for b in range(1, len(weights)):
        blend += bands_light[b] * weights[b]
    sky = _tint(bands, colours, weights)
    sky *= blend[None]
    sky *= ratio
    return sky


def _tint(bands: ViewBands, colours: ArrayLike, weights: ArrayLike) -> np.ndarray:
    """sum_z u_z E_z,ch / sum_ch E_z,ch (channels, n) float32 for colour bands' terms (Z, channels,
    n) or (Z, channels) (then broadcast over the n views of ``weights``). [1]"""
    by_zenith = bands.colour_weights(np.asarray(weights, dtype=np.float32))
    colours = np.asarray(colours, dtype=np.float32)
    colours = colours if colours.ndim == 3 else colours[..., None]
    tint = np.zeros((colours.shape[1], by_zenith.shape[1]), dtype=np.float32)
    for z in range(len(colours)):
        tint += colours[z] * (by_zenith[z] / np.maximum(colours[z].sum(axis=0), np.float32(1e-30)))[None]
    return tint


def open_sky(bands: ViewBands, weights: ArrayLike, colours_open: ArrayLike, bands_open: ArrayLike) -> np.ndarray:
    """``banded_sky`` on open ground, before ``sky_ratio``.

    sum_b w_b G_b,open sum_z u_z E_z,open / sum_ch E_z,open.

    Parameters
    ----------
    bands : ViewBands
        The view bands.
    weights : numpy.ndarray
        w_b (B, n) the weights [1].
    colours_open : numpy.ndarray
        (Z, 3) the colour bands' open light [radiance x sr].
    bands_open : numpy.ndarray
        G_b,open (B,) each band's open light on the channels' sum [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (3, n) float32 [radiance x sr].
    """
    blend = np.tensordot(np.asarray(bands_open, dtype=np.float32), np.asarray(weights, dtype=np.float32), axes=1)
    sky = _tint(bands, colours_open, weights)
    sky *= blend[None]
    return sky


SHAPE_STEP = 0.04
"""Spacing on the sky plane [tan] (about 2.3 degrees at the zenith, less away from it) of the
lattice on which ``weighted_raster`` evaluates the shape s(V, L), read bilinearly at the sky
raster's cells: the shape changes over degrees (its sharpest feature, the hot spot's cusp
1 / (1 + G), is a cone in G, the distance on this same plane)."""


def shape_on_grid(brdf: BrdfConfig, view: ArrayLike, grid: Grid) -> np.ndarray:
    """The shape s(view, L) at the cells of a sky-plane grid.

    Exact on a lattice of spacing at most SHAPE_STEP over the grid, bilinear between (the grid's own
    cells when they are coarser).

    Parameters
    ----------
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).
    view : numpy.ndarray
        (3,) unit view vector [1].
    grid : Grid
        A sky-plane grid [tan].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 [1].
    """
    step = max(1, int(round(SHAPE_STEP / grid.pixel)))
    if step == 1 or min(grid.shape) < 4 * step:
        return shape(brdf, np.asarray(view)[None, None, :], cell_directions(grid)).astype(np.float32)
    pitch = step * grid.pixel
    rows, cols = (int(np.ceil(n / step)) + 3 for n in grid.shape)
    x0, y0 = grid.origin
    lattice = Grid((x0 + 0.5 * grid.pixel - 1.5 * pitch, y0 - 0.5 * grid.pixel + 1.5 * pitch), pitch, (rows, cols))
    coarse = shape(brdf, np.asarray(view)[None, None, :], cell_directions(lattice)).astype(np.float32)
    return shadow.resample_bilinear(coarse[None], lattice, grid)[0]


_SUM = LastCalls()
"""``_channel_sum``: the bands of a frame sum the same raster."""


def _channel_sum(raster) -> np.ndarray:
    """The sky raster's channels summed (1, rows, cols) float32, made once for the bands of a
    frame. Read-only. [radiance x sr]"""
    def made():
        total = raster.weighted.sum(axis=0, keepdims=True)
        total.flags.writeable = False
        return total
    return _SUM.get((raster,), made)


_COARSER = LastCalls()
"""``weighted_raster``'s raster summed in blocks: the bands of a frame weight the same one."""

_RING = LastCalls()
"""``_ring``: the bands of a frame weight the same raster's outside."""


def summed_blocks(raster: SkyRaster, factor: int) -> SkyRaster:
    """``sky.raster.coarser``, made once for the bands of a frame (the raster itself for 1).

    Parameters
    ----------
    raster : sky.raster.SkyRaster
        The sky raster [radiance x sr].
    factor : int
        Cells a side per block (``band_factor``) [1].

    Returns
    -------
    sky.raster.SkyRaster
        [radiance x sr]; not to be written: the same object serves the frame's bands (its key
        is the raster's identity).
    """
    return raster if factor == 1 else _COARSER.get((raster, factor), lambda: coarser(raster, factor))


@functools.lru_cache(maxsize=4)
def _ring_cells(grid) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """A sky grid's outermost ring of cells: their (rows, cols) (k,) each and unit vectors
    towards them (k, 3). Read-only. [index], [1]"""
    ring = np.ones(grid.shape, dtype=bool)
    ring[1:-1, 1:-1] = False
    r, c = np.nonzero(ring)
    sx, sy = grid.ground_from_raster(r, c)
    w = np.stack([sx, sy, np.ones_like(sx)], axis=-1)
    dirs = w / np.linalg.norm(w, axis=-1, keepdims=True)
    for array in (r, c, dirs):
        array.flags.writeable = False
    return (r, c), dirs


def _ring(raster):
    """The directions (m, 3) [1] and the light (m,) [radiance x sr] of a sky raster's outermost
    ring of cells, made once for the bands of a frame."""
    def made():
        (r, c), dirs = _ring_cells(raster.grid)
        return dirs, raster.weighted[:, r, c].sum(axis=0, dtype=np.float64)
    return _RING.get((raster,), made)


def weighted_raster(raster: SkyRaster, brdf: BrdfConfig, view: ArrayLike, *, fold_period: tuple[int, int] | None = None,
                    summed: bool = False, factor: int = 1) -> SkyRaster:
    """The sky raster with each cell's light times the shape s(view, L_cell).

    Max's f_r(V, L) on the sky raster, before the correlation (``shape_on_grid``), folded after the
    weighting when ``fold_period`` is given; the light outside the raster times the mean shape over
    the raster's outermost ring of cells (the nearest directions to it).

    Parameters
    ----------
    raster : sky.raster.SkyRaster
        The sky raster [radiance x sr].
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).
    view : numpy.ndarray
        (3,) unit view vector [1].
    fold_period : tuple of (int, int), optional
        The tile period to fold onto [cell].
    summed : bool, optional
        One channel, the channels' sum weighted (the view bands').
    factor : int, optional
        The raster's cells summed in blocks of ``factor`` x ``factor`` first (``sky.raster.coarser``,
        for ``shadow.coarser_isolated``) and weighted at the blocks; the outside still by the
        raster's own ring [1].

    Returns
    -------
    sky.raster.SkyRaster
        The weighted raster, float32 [radiance x sr].
    """
    cells = summed_blocks(raster, factor)
    s = shape_on_grid(brdf, view, cells.grid)
    light = _channel_sum(cells) if summed else cells.weighted
    outside = np.asarray(raster.outside, dtype=np.float64)
    outside = outside.sum(keepdims=True) if summed else outside
    weighted = light * s[None]
    if factor == 1:
        ring = np.ones(s.shape, dtype=bool)
        ring[1:-1, 1:-1] = False
        e = raster.weighted.sum(axis=0)
        edge = float((e[ring] * s[ring]).sum() / max(float(e[ring].sum()), 1e-30))
    else:
        directions, e = _ring(raster)
        edge = float(shape(brdf, np.asarray(view)[None], directions) @ e / max(float(e.sum()), 1e-30))
    grid = cells.grid
    if fold_period is not None:
        weighted = fold(weighted, sky_offset(grid), fold_period)
        grid = sky_grid((0, 0), (fold_period[0], fold_period[1]), grid.pixel)
    return SkyRaster(grid, weighted.astype(np.float32), outside * edge)
