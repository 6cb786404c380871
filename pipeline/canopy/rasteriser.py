"""The anti-aliased rasteriser: opaque shapes on a canopy plane drawn as a transmittance mask or as fragments.

``rasterize_transmittance`` draws ``grove.Shapes`` as a transmittance mask, ``coverage_fragments``
gives the coverage of every pixel by every shape, and ``grove_mask`` draws a grove at one
flutter frame (``kernels/raster.py`` holds the compiled kernels); ``compile_loops`` compiles those
kernels ahead of a render's cycle products.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pipeline.canopy.grove import FlutterParams, Grove, Shapes, leaves_at, project
from pipeline.core.cores import compiled_once, on_disk
from pipeline.core.geometry import Grid

__all__ = ["rasterize_transmittance", "coverage_fragments", "grove_mask", "loops_cached", "compile_loops"]


# ---------------------------------------------------------------------------------------------
# Anti-aliased rasterization. Coverage of a pixel = mean over k x k sub-samples of the exact area
# fraction of the sub-sample's square that lies inside the shape's local strip: the half-plane
# through the nearest boundary point (signed distance d, normal n) and, for thin shapes, the
# parallel half-plane a thickness T further in. The area fraction of a unit square cut by a
# line is the CDF of n . u for u uniform in the square (a trapezoid of widths |nx| + |ny|,
# ||nx| - |ny||), so straight edges at any angle are exact and only curvature is sampled.
# ---------------------------------------------------------------------------------------------

_CHUNK = 1 << 17  # a box of more than 16 _CHUNK samples gets fewer per pixel [count]


def rasterize_transmittance(shapes: Shapes, grid: Grid, *, period: tuple[float, float] | None = None) -> np.ndarray:
    """Transmittance of opaque ``shapes`` on ``grid``: 1 = open sky.

    Each shape covers a fraction c_i of a pixel's area (box filter; see the comment above for the
    method). Shapes combine as independent occluders: the pixel's transmittance is the product of
    (1 - c_i) in float64 with c_i clipped just below 1, so a fully covered pixel is 0 (to 1e-6)
    and two disjoint shapes each covering half a pixel give 0.25, not 0 (a pixel-scale
    statistical choice: overlaps of shapes are not resolved below a pixel).

    The loops over shapes and their pixels are compiled (``pipeline/kernels/raster.py``, numba), with
    the coverages of ``coverage_fragments`` to float32 rounding (docs/accuracy.md).

    Parameters
    ----------
    shapes : Shapes
        The shapes [m].
    grid : Grid
        The raster [m].
    period : tuple of (float, float) or None, optional
        (Px, Py); if given the shapes repeat with these periods and every translate that touches the
        grid is drawn (one tile or any window of a periodic forest) [m].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 transmittance [1].
    """
    return _compiled(shapes, grid, period, emit=False)


def _compiled(shapes: Shapes, grid: Grid, period: tuple[float, float] | None, *, emit: bool):
    """The compiled rasteriser (pipeline/kernels/raster.py): the transmittance, or with ``emit`` the
    fragments of ``coverage_fragments``."""
    from pipeline.kernels import raster

    rows, cols = grid.shape
    period_px = None if period is None else np.asarray(period, dtype=np.float64) / grid.pixel
    count = 0
    parts = []
    rowwise = period_px is None  # row by row, for the cache (a radix sort of 16-bit rows), every array in that order
    for primitive, capsule, offset in ((_ellipses(shapes, grid, rowwise=rowwise), False, 0),
                                       (_capsule_pieces(shapes, grid), True, len(shapes.center))):
        center, half, params, feature, thickness, owner = primitive
        if rowwise:
            if capsule:  # a few pieces: numpy's gather
                order = _row_order(center[:, 1])
                center, half, feature, thickness, owner = (a[order] for a in (center, half, feature, thickness, owner))
                params = params[order]
            index = np.arange(len(center))
        else:
            index, center = _translates(center, half, period_px, grid.shape)
        parts.append((capsule, center, half, index, params.astype(np.float32), feature, thickness, owner + offset))
    size = sum(raster.box_pixels(part[1], part[2], part[3], rows, cols) for part in parts) if emit else 0
    fragments = (np.empty(size, np.int64), np.empty(size, np.float32), np.empty(size, np.int64))
    transmittance = np.empty((rows, cols)) if emit else np.ones((rows, cols))
    for capsule, center, half, index, params, feature, thickness, owner in parts:
        count = raster.shapes(capsule, center, half, index, params, feature, thickness, 16 * _CHUNK, transmittance,
                               fragments, owner, count)
    if emit:
        return tuple(f[:count] for f in fragments)
    return transmittance.astype(np.float32)


def coverage_fragments(shapes: Shapes, grid: Grid, *,
                       period: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pixel that every shape covers on ``grid``, as fragments (one per shape and pixel).

    The coverages are those that ``rasterize_transmittance`` multiplies: for each fragment the
    fraction c in [0, 1) of the pixel's area that the shape covers (clipped just below 1).
    Fragments are grouped by shape, not sorted; pixels outside the grid and zero coverages are
    dropped.

    Parameters
    ----------
    shapes, grid, period
        As for ``rasterize_transmittance``; every translate keeps its shape index.

    Returns
    -------
    pixel : numpy.ndarray
        (n,) int64, the flat index ``row * cols + col``.
    coverage : numpy.ndarray
        (n,) float32 in (0, 1) [1].
    shape : numpy.ndarray
        (n,) int64: ellipse i is shape i, capsule j is shape ``len(shapes.center) + j``.
    """
    return _compiled(shapes, grid, period, emit=True)


def grove_mask(grove: Grove, flutter: FlutterParams, frame: int, *, sun: ArrayLike, plane_height: float, grid: Grid,
               period: tuple[float, float] | None = None,
               select: tuple[np.ndarray | slice, np.ndarray | slice] | None = None) -> np.ndarray:
    """Transmittance mask of the grove at ``frame`` on the canopy plane z = ``plane_height``.

    Parameters
    ----------
    grove : Grove
        The grove.
    flutter : FlutterParams
        The flutter.
    frame : int
        The frame [frames].
    sun : numpy.ndarray
        (2,) the sun's sky-plane point [tan].
    plane_height : float
        Height of the canopy plane [m].
    grid : Grid
        The raster [m].
    period : tuple of (float, float) or None, optional
        (Px, Py); None uses the grove's own tile for a periodic layout [m].
    select : tuple or None, optional
        None or (leaf selector, wood selector) for ``Shapes.subset``, e.g. from ``layer_index``.

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 transmittance [1].

    Raises
    ------
    ValueError
        For a periodic grove without a tile period.
    """
    if period is None and grove.params.layout == "periodic":
        tile = grove.params.tile
        if tile is None:
            raise ValueError("a periodic grove needs a tile period [m]")
        period = (tile, tile)
    shapes = project(leaves_at(grove, flutter, frame), grove.wood, sun=sun, plane_height=plane_height)
    if select is not None:
        shapes = shapes.subset(*select)
    return rasterize_transmittance(shapes, grid, period=period)


def _pixels(points: np.ndarray, grid: Grid) -> np.ndarray:
    """Plane points (n, 2) [m] to continuous raster coordinates (u along columns, v along rows)
    [pixel], pixel (row, col) covering [col, col + 1) x [row, row + 1)."""
    return np.column_stack([points[:, 0] - grid.origin[0], grid.origin[1] - points[:, 1]]) / grid.pixel


def _row_order(rows: np.ndarray) -> np.ndarray:
    """The stable order of the rows [pixel] taken as 16-bit integers (clipped): a radix sort."""
    return np.argsort(np.clip(rows, 0, 65535).astype(np.uint16), kind="stable")


def _ellipses(shapes: Shapes, grid: Grid, *, rowwise: bool = False):
    """Ellipses in pixel units: centre, bbox half-size, (major unit vector, semi-axes A >= B),
    feature size B, thickness 2B, each ellipse's index; with ``rowwise`` in ``_row_order`` of their
    centres' rows, computed in that order (their arrays are then read one after another, not at
    random: docs/accuracy.md, "The leaf rasteriser"), those whose box misses the grid only as far
    as the rasteriser reads them. (Compiled: kernels.raster.ellipse_params.)"""
    from pipeline.kernels import raster

    center, axis_a, axis_b = (np.ascontiguousarray(a, dtype=np.float64)
                              for a in (shapes.center, shapes.axis_a, shapes.axis_b))
    origin_x, origin_y, pixel = float(grid.origin[0]), float(grid.origin[1]), float(grid.pixel)
    # the rows as ellipse_params computes them
    order = _row_order((origin_y - center[:, 1]) / pixel) if rowwise else np.arange(len(center))
    rows, cols = (float(n) for n in grid.shape) if rowwise else (0.0, 0.0)  # not with translates
    return (*raster.ellipse_params(order, center, axis_a, axis_b, origin_x, origin_y, pixel, rows, cols), order)


def _capsule_pieces(shapes: Shapes, grid: Grid):
    """Capsules in pixel units, long ones cut into pieces of length <= max(4 r, 16) pixels so
    that their boxes stay tight. A piece keeps the whole capsule's distance but only the pixels
    whose centre projects onto its stretch of the axis, so the pieces tile the capsule exactly.
    The last item is the index of each piece's capsule."""
    p0, p1 = _pixels(shapes.start, grid), _pixels(shapes.end, grid)
    radius = shapes.radius / grid.pixel
    axis = p1 - p0
    pieces = np.maximum(1, np.ceil(np.hypot(*axis.T) / np.maximum(4 * radius, 16))).astype(np.int64)
    src = np.repeat(np.arange(len(radius)), pieces)
    i = np.arange(len(src)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    n = pieces[src]
    lo, hi = p0[src] + axis[src] * (i / n)[:, None], p0[src] + axis[src] * ((i + 1) / n)[:, None]
    center = 0.5 * (lo + hi)
    r = radius[src]
    half = 0.5 * np.abs(hi - lo) + (r + (n > 1))[:, None]
    inverse = 1.0 / np.maximum(np.sum(axis**2, axis=1), 1e-12)[src]
    t_lo = np.where(i == 0, -np.inf, i / n)
    t_hi = np.where(i == n - 1, np.inf, (i + 1) / n)
    params = np.column_stack([p0[src] - center, axis[src], inverse, r, t_lo, t_hi])
    return center, half, params, r, 2 * r, src


def _translates(center, half, period, shape):
    """Indices of the shapes and their centres [pixel], one per translate by whole periods
    ``period`` (Pu, Pv) [pixel] whose box touches the raster ``shape`` (rows, cols)."""
    extent = np.array([shape[1], shape[0]])
    first = np.ceil(-(center + half) / period).astype(np.int64)
    count = np.maximum(np.floor((extent - (center - half)) / period).astype(np.int64) - first + 1, 0)
    copies = count[:, 0] * count[:, 1]
    src = np.repeat(np.arange(len(center)), copies)
    m = np.arange(len(src)) - np.repeat(np.cumsum(copies) - copies, copies)
    nu = np.maximum(count[src, 0], 1)
    shift = np.column_stack([first[src, 0] + m % nu, first[src, 1] + m // nu]) * period
    return src, center[src] + shift


def loops_cached() -> bool:
    """Whether numba's cache on disk holds the rasteriser's loops (``compile_loops``'s), so that a
    cycle product loads them instead of compiling them; False where numba keeps no cache of them.

    Returns
    -------
    bool
        The cache's index of the kernel that draws the shapes exists.
    """
    from pipeline.kernels import raster

    return on_disk(raster.shapes)


def compile_loops() -> None:
    """Compile the loops of a cycle product (flutter, projection, the ellipses and capsule pieces
    drawn as a mask), or load them from numba's cache, on one tiny leaf and one tiny stem with the
    types a cycle product passes, holding ``cores.compiled_once``'s lock meanwhile so that the
    cycle phase's other workers wait for them and load them. A render's command has one of its
    workers run this while it plans the run (``render.render_run``): the first cycle products then
    find the loops compiled or load them (docs/accuracy.md, "Compiling after an install").
    """
    from pipeline.kernels import raster

    with compiled_once(raster.shapes):
        one = np.zeros((1, 3))
        pose = raster.flutter(one + (0.0, 0.0, 1.0), one + (0.05, 0.0, 0.0), one + (0.0, 0.03, 0.0), one,
                              one + (1.0, 0.0, 0.0), np.zeros(1), np.zeros(1), 0.1, 0.2, 0.3)
        center = raster.onto(np.ascontiguousarray(pose[0]), 0.1, 0.2, 0.0)
        ends = raster.onto(np.array([[0.0, 0.0, 0.0], [0.0, 0.1, 1.0]]), 0.1, 0.2, 0.0)
        axis_a, axis_b = (raster.onto(axis, 0.1, 0.2, 0.0) - center for axis in pose[1:])
        shapes = Shapes(center, axis_a, axis_b, ends[:1], ends[1:], np.full(1, 0.02))
        rasterize_transmittance(shapes, Grid((-0.5, 0.5), 0.05, (20, 20)))
