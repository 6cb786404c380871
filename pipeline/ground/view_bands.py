"""View bands: the views at which the sky's term is correlated, and the weights that blend them
at any view (docs/method.md, "The ground's reflectance"): scattered views, blended piecewise
linearly over their triangulation on an azimuthal map of the view hemisphere."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["COLOUR_BANDS", "LastCalls", "ViewBands", "barycentric", "unit_view", "view_plane"]


def _hats(x, nodes) -> np.ndarray:
    """Hat functions (len(nodes), n) at ``x`` (n,) over sorted ``nodes``: linear between
    neighbours, held beyond the ends; they sum to 1. [1]"""
    nodes, x = np.asarray(nodes, dtype=np.float64), np.asarray(x, dtype=np.float64).reshape(-1)
    eye = np.eye(len(nodes))
    return np.stack([np.interp(x, nodes, eye[:, b]) for b in range(len(nodes))])


def unit_view(zenith: ArrayLike, azimuth: ArrayLike) -> np.ndarray:
    """Unit vectors at zenith angles and azimuths (from +y towards +x).

    Parameters
    ----------
    zenith, azimuth : numpy.ndarray
        (...) angles [rad].

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 [1].
    """
    return np.stack([np.sin(zenith) * np.sin(azimuth), np.sin(zenith) * np.cos(azimuth), np.cos(zenith)], axis=-1)


def view_plane(zenith: ArrayLike, azimuth: ArrayLike) -> np.ndarray:
    """Views on the plane the bands are blended on: zenith angle times the azimuth's direction.

    An azimuthal equidistant map of the view hemisphere: regular at the nadir view (where the
    azimuth means nothing), the zenith angle along each azimuth.

    Parameters
    ----------
    zenith, azimuth : numpy.ndarray
        (n,) view zenith angles and azimuths (from +y towards +x) [rad].

    Returns
    -------
    numpy.ndarray
        (n, 2) float64 [rad].
    """
    zenith = np.asarray(zenith, dtype=np.float64).reshape(-1)
    azimuth = np.asarray(azimuth, dtype=np.float64).reshape(-1)
    return np.stack([zenith * np.sin(azimuth), zenith * np.cos(azimuth)], axis=-1)


def barycentric(nodes: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Piecewise-linear hat weights of scattered nodes at points: they sum to 1, none negative.

    Over the nodes' Delaunay triangulation, each point's barycentric coordinates in its triangle;
    a point outside the nodes' hull takes those of the hull's nearest point (held beyond the
    ends, as ``_hats``). One node: weight 1; nodes on a line: hats along it.

    Parameters
    ----------
    nodes : numpy.ndarray
        (B, 2) distinct nodes on a plane [any length].
    points : numpy.ndarray
        (n, 2) points on the same plane [the same length].

    Returns
    -------
    numpy.ndarray
        (B, n) float64 [1].
    """
    from matplotlib.tri import Triangulation
    from scipy.spatial import Delaunay

    nodes = np.asarray(nodes, dtype=np.float64).reshape(-1, 2)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(nodes) == 1:
        return np.ones((1, len(points)))
    centre = nodes.mean(axis=0)
    _, spread, axes = np.linalg.svd(nodes - centre, full_matrices=False)
    if len(nodes) == 2 or spread[1] <= 1e-9 * spread[0]:  # on a line: hats along it
        along, at = (nodes - centre) @ axes[0], (points - centre) @ axes[0]
        order = np.argsort(along)
        out = np.empty((len(nodes), len(points)))
        out[order] = _hats(at, along[order])
        return out
    triangles = Delaunay(nodes)
    # the triangle of each point: matplotlib's trapezoid map, 4 times faster than scipy's brute
    # force and 7 times its walk at a camera's million views, the same triangles
    finder = Triangulation(nodes[:, 0], nodes[:, 1], triangles.simplices).get_trifinder()
    simplex = np.asarray(finder(points[:, 0], points[:, 1]), dtype=np.intp)
    out = np.zeros((len(nodes), len(points)))
    inside = np.flatnonzero(simplex >= 0)
    affine = triangles.transform[simplex[inside]]  # (k, 3, 2): inverse matrix, then the origin
    first = np.einsum("kij,kj->ki", affine[:, :2], points[inside] - affine[:, 2])
    weights = np.clip(np.concatenate([first, 1.0 - first.sum(axis=1, keepdims=True)], axis=1), 0.0, None)
    weights /= weights.sum(axis=1, keepdims=True)
    corners = triangles.simplices[simplex[inside]]
    for k in range(3):  # a triangle's three corners are distinct nodes
        out[corners[:, k], inside] = weights[:, k]
    outside = np.flatnonzero(simplex < 0)
    if len(outside):  # the nearest point on the hull's edges
        p = points[outside]
        best = np.full(len(outside), np.inf)
        ends, along = np.zeros((2, len(outside)), dtype=np.intp), np.zeros(len(outside))
        for a, b in triangles.convex_hull:
            edge = nodes[b] - nodes[a]
            t = np.clip((p - nodes[a]) @ edge / float(edge @ edge), 0.0, 1.0)
            gap = np.linalg.norm(p - nodes[a] - t[:, None] * edge, axis=1)
            nearer = gap < best
            best[nearer], ends[0, nearer], ends[1, nearer], along[nearer] = gap[nearer], a, b, t[nearer]
        out[ends[0], outside] = 1.0 - along
        out[ends[1], outside] += along
    return out


COLOUR_BANDS = 3
"""Bands whose terms are correlated in every channel (``ViewBands.colours``): the first chosen,
the middle view's and the two farthest from it. [count]"""


@dataclass(frozen=True)
class ViewBands:
    """View bands: the sky's term with the view V held per band (Max: f_r independent of V over a patch).

    Views scattered over the pixels' views, where ``choose_bands`` found the blend worst, blended
    piecewise linearly over their triangulation on ``view_plane`` (``barycentric``).

    Attributes
    ----------
    zeniths : tuple of float
        (B,) the bands' view zenith angles [rad].
    azimuths : tuple of float
        (B,) the bands' view azimuths (from the ground towards the camera) [rad].
    azimuth : float
        The views' middle azimuth: where ``sky_ratio``'s lattice of views measures turns from [rad].
    error : float
        The largest bound of the blend's relative error under any shading over the sampled
        pixels that ``choose_bands`` measured (``shaded_bound``) [1].
    """

    zeniths: tuple[float, ...]
    azimuths: tuple[float, ...]
    azimuth: float
    error: float

    @property
    def count(self) -> int:
        """The number of bands, B [count]."""
        return len(self.zeniths)

    @property
    def colours(self) -> tuple[int, ...]:
        """The bands whose terms are correlated in every channel: the first COLOUR_BANDS.

        They give the sky light's colour under the canopy, blended over the view (``colour_weights``);
        the others are correlated on the channels' sum and give only how the reflectance
        modulates it (``banded_sky``).

        Returns
        -------
        tuple of int
            Their indices [index].
        """
        return tuple(range(min(COLOUR_BANDS, self.count)))

    def colour_weights(self, weights: np.ndarray) -> np.ndarray:
        """The colour bands' weights from the bands' weights: each band's passed on to the colour
        bands by its own weights among them (``barycentric``), so they sum to 1 too.

        Parameters
        ----------
        weights : numpy.ndarray
            (B, n) ``weights`` [1].

        Returns
        -------
        numpy.ndarray
            (C, n), the dtype of ``weights`` [1].
        """
        def made() -> np.ndarray:
            plane = view_plane(self.zeniths, self.azimuths)
            share = barycentric(plane[list(self.colours)], plane).astype(weights.dtype)  # (C, B)
            return share @ weights
        return _COLOUR.get((weights, self.zeniths, self.azimuths), made)

    def directions(self) -> np.ndarray:
        """Unit view vectors of the bands.

        Returns
        -------
        numpy.ndarray
            (B, 3) float64 [1].
        """
        return unit_view(np.asarray(self.zeniths), np.asarray(self.azimuths))

    def weights(self, zenith: ArrayLike, azimuth: ArrayLike) -> np.ndarray:
        """Weights of each band at views (``barycentric`` on ``view_plane``); they sum to 1.

        Parameters
        ----------
        zenith, azimuth : numpy.ndarray
            (n,) view zenith angles and azimuths [rad].

        Returns
        -------
        numpy.ndarray
            (B, n) float64 [1].
        """
        return barycentric(view_plane(self.zeniths, self.azimuths), view_plane(zenith, azimuth))


class LastCalls:
    """The last ``size`` calls of a function and their results, kept in this process: a frame asks
    again for what the frame (or the frame before, from the same camera) made. The keys' objects
    are held, so their ids are not reused, and matched by identity; numbers, strings, bytes by value.

    Parameters
    ----------
    size : int, optional
        How many calls are kept [count].
    """

    def __init__(self, size: int = 1):
        self.size = size
        self.calls: list[tuple[tuple, Any]] = []

    def get(self, key: tuple, make: Callable[[], Any]) -> Any:
        """The result for ``key``: a kept one if ``key`` is a kept call's, else ``make()``."""
        for kept, value in self.calls:
            if len(kept) == len(key) and all(a == b if isinstance(b, (int, float, str, bytes)) else a is b
                                             for a, b in zip(kept, key)):
                return value
        self.calls = [(key, make()), *self.calls][: self.size]
        return self.calls[0][1]


_COLOUR = LastCalls(2)
"""``ViewBands.colour_weights``: of the ground raster's cells and of the pixels, each the same every frame."""
