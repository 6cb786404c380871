"""The nodes on which the procedural sky is evaluated: Gauss-Legendre quadrature, the quadrature of
the sky outside a sky-plane rectangle, every k-th cell of a raster with its bilinear
interpolation, and the cells' projected solid angles, each made once and cached read-only; and
the clear sky's shape at such nodes and at a still camera's points, kept while the sun stands still.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.geometry import Grid, projected_solid_angle
from pipeline.core.kept import kept_at

if TYPE_CHECKING:  # an annotation only: procedural imports this module
    from pipeline.sky.procedural import ProceduralSky

__all__ = ["gauss_legendre", "lerp_nodes", "outside_nodes", "raster_nodes", "solid_angles32", "relative_nodes",
           "relative_at"]


# numpy's Gauss-Legendre nodes and weights, cached: numpy finds them as the eigenvalues of a
# matrix at each call, several times a frame. Callers must not write to them.
_leggauss = lru_cache(maxsize=4)(np.polynomial.legendre.leggauss)


def gauss_legendre(a: ArrayLike, b: ArrayLike, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of n-point Gauss-Legendre quadrature on [a, b].

    Parameters
    ----------
    a, b : float or numpy.ndarray
        The intervals' ends (broadcast together).
    n : int
        Nodes per interval.

    Returns
    -------
    tuple of numpy.ndarray
        (nodes, weights), each (..., n) float64, nodes on the last axis, in the units of a and b.
    """
    x, w = _leggauss(n)
    a, b = np.asarray(a, dtype=np.float64)[..., None], np.asarray(b, dtype=np.float64)[..., None]
    return a + (b - a) * (x + 1.0) / 2.0, (b - a) / 2.0 * w



@lru_cache(maxsize=8)
def outside_nodes(extent: tuple[float, float, float, float] | None, n_azimuth: int = 1024,
                  n_zenith: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature of the irradiance of the sky outside a sky-plane rectangle.

    For each azimuth (midpoint rule) the ray from the zenith leaves the rectangle at exact zenith
    angles; the outside parts of the ray are integrated with Gauss-Legendre in theta of
    L cos(theta) sin(theta). Read-only, cached.

    Parameters
    ----------
    extent : tuple or None
        (x_min, y_min, x_max, y_max) [tan]; None: the whole hemisphere.
    n_azimuth, n_zenith : int
        Azimuths, and Gauss-Legendre nodes along each part of a ray.

    Returns
    -------
    tuple of numpy.ndarray
        (sky-plane points s (n_azimuth, 2, n_zenith, 2) [tan], weights (n_azimuth, 2, n_zenith)
        [sr]): the irradiance is the sum of L(s) times the weights.
    """
    phi = (np.arange(n_azimuth) + 0.5) * (2.0 * np.pi / n_azimuth)
    d = np.stack([np.sin(phi), np.cos(phi)], axis=-1)
    t_in = np.zeros(n_azimuth)
    t_out = np.zeros(n_azimuth)
    if extent is not None:
        lo = np.array(extent[:2])
        hi = np.array(extent[2:])
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = lo / d, hi / d
        near, far = np.minimum(a, b), np.maximum(a, b)
        parallel = d == 0.0
        inside = (lo <= 0.0) & (hi >= 0.0)
        near = np.where(parallel, np.where(inside, -np.inf, np.inf), near)
        far = np.where(parallel, np.where(inside, np.inf, -np.inf), far)
        t_in = np.maximum(near.max(axis=1), 0.0)
        t_out = far.min(axis=1)
        hit = t_out > t_in
        t_in, t_out = np.where(hit, t_in, 0.0), np.where(hit, t_out, 0.0)
    a = np.stack([np.zeros(n_azimuth), np.arctan(t_out)], axis=1)
    b = np.stack([np.arctan(t_in), np.full(n_azimuth, np.pi / 2)], axis=1)
    theta, w = gauss_legendre(a, b, n_zenith)  # (n_azimuth, 2, n_zenith)
    tan = np.tan(theta)
    s = np.stack([tan * d[:, None, None, 0], tan * d[:, None, None, 1]], axis=-1)
    weight = w * np.cos(theta) * np.sin(theta) * (2.0 * np.pi / n_azimuth)
    s.setflags(write=False)
    weight.setflags(write=False)
    return s, weight


@lru_cache(maxsize=8)
def raster_nodes(grid: Grid, k: int) -> tuple[np.ndarray]:
    """The nodes on which ``procedural.ProceduralSky.raster`` evaluates the clear sky. Read-only, cached.

    Parameters
    ----------
    grid : geometry.Grid
        The sky-plane grid [tan].
    k : int
        Every k-th cell centre of ``grid`` and the last (``lerp_nodes``) [cells].

    Returns
    -------
    tuple of numpy.ndarray
        (sky-plane points (nodes, nodes, 2) [tan],).
    """
    rows, cols = grid.shape
    x, y = grid.ground_from_raster(lerp_nodes(rows, k)[0][:, None], lerp_nodes(cols, k)[0][None, :])
    s = np.stack(np.broadcast_arrays(x, y), axis=-1)
    s.setflags(write=False)
    return (s,)


@lru_cache(maxsize=8)
def solid_angles32(grid: Grid) -> np.ndarray:
    """The projected solid angles of a grid's cells as float32, made once per grid (read-only).

    Parameters
    ----------
    grid : geometry.Grid
        The sky-plane grid [tan].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 ``geometry.projected_solid_angle(grid)`` [sr].
    """
    weights = projected_solid_angle(grid).astype(np.float32)
    weights.flags.writeable = False
    return weights


def lerp_nodes(n: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolation nodes every k of n indices, the last one included.

    Parameters
    ----------
    n : int
        Indices [cells].
    k : int
        The nodes' spacing [cells].

    Returns
    -------
    tuple of numpy.ndarray
        (nodes, at, fraction): the node indices; for each of the n indices the node interval it
        falls in (``at``, ``at + 1`` valid) and its fraction along it (float32) [1].
    """
    nodes = np.arange(0, n, k)
    if nodes[-1] != n - 1:
        nodes = np.append(nodes, n - 1)
    if len(nodes) == 1:
        nodes = np.array([0, 0])
    index = np.arange(n)
    at = np.minimum(np.searchsorted(nodes, index, side="right") - 1, len(nodes) - 2)
    span = np.maximum(nodes[at + 1] - nodes[at], 1)
    return nodes, at, ((index - nodes[at]) / span).astype(np.float32)


@lru_cache(maxsize=16)
def relative_nodes(clear: ProceduralSky, nodes: Callable[..., tuple[np.ndarray, ...]], *where: object) -> np.ndarray:
    """The clear sky's shape at a set of nodes, read-only, cached: the same in every frame while the sun
    stands still.

    Parameters
    ----------
    clear : procedural.ProceduralSky
        The sky without what does not shape its clear sky (``ProceduralSky._clear_key``).
    nodes : callable
        ``outside_nodes`` or ``raster_nodes``.
    *where
        Their arguments.

    Returns
    -------
    numpy.ndarray
        (..., 3) ``clear._shape_at`` at ``nodes(*where)[0]``: zenith luminance 1 [1].
    """
    relative = clear._shape_at(nodes(*where)[0])
    relative.setflags(write=False)
    return relative


_kept_points: dict = {}  # relative_at's: (clear sky, id(points)) -> (points, their relative sky or None)


def relative_at(clear: ProceduralSky, s: np.ndarray) -> np.ndarray:
    """The clear sky's shape at read-only points, kept (``kept.kept_at``) for the last ``POINTS_KEPT`` skies
    and points: a camera that stands still (its rays made once, ``pinhole._sky_rays``) sees the clear
    sky's shape at the same points in every frame while the sun stands still (76 ms of a frame of
    sun-and-shade.yaml).

    Parameters
    ----------
    clear : procedural.ProceduralSky
        As ``relative_nodes`` takes it.
    s : numpy.ndarray
        (..., 2) read-only sky-plane points [tan].

    Returns
    -------
    numpy.ndarray
        (..., 3) ``clear._shape_at(s)``, read-only when kept [1].
    """
    return kept_at(_kept_points, clear, s, lambda: clear._shape_at(s))
