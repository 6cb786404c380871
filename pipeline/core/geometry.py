"""Where things are: directions, the sky-plane mapping, the raster ``Grid``, sky-plane grids of
whole-cell offsets, and the unshadowed irradiance ``I0``. Pure numpy; no physics imports, so
every other module can use it.

Conventions (docs/method.md, "Conventions"): world axes x east, y north, z up; azimuth from north
towards east; zenith angle ``theta`` from +z. Every planar raster is indexed ``[row, col]``
with ``col`` growing with +x and ``row`` growing with -y (north-up), pixel centres at
``origin + (col + 0.5, -(row + 0.5)) * pixel`` where ``origin`` is the north-west corner.

The sky plane is ``z = 1``: a direction ``w`` maps to ``s = (wx / wz, wy / wz)``
(Max 1991, Fig. 2), so ``|s| = tan(theta)`` and a solid-angle element is
``d_omega = cos^3(theta) dA``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import overload

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "Grid", "lattice_offset", "sky_grid", "sky_offset", "fold", "wrapped_spans", "direction_vector", "tangent_axes",
    "normalized", "length3", "sky_plane_from_direction", "direction_from_sky_plane", "cos4_antiderivative",
    "projected_solid_angle", "sky_square_irradiance", "I0", "pinhole_image_axes", "offset_direction",
]


@dataclass(frozen=True)
class Grid:
    """A north-up raster on a plane: ground, canopy or sky plane.

    Pixel centres are at ``origin + (col + 0.5, -(row + 0.5)) * pixel`` (docs/method.md, "Conventions").

    Attributes
    ----------
    origin : tuple of (float, float)
        x and y of the north-west corner of pixel [0, 0]: [m] on the ground and canopy planes,
        [tan] (dimensionless) on the sky plane.
    pixel : float
        Side of a square pixel, in the units of ``origin`` [m] or [tan].
    shape : tuple of (int, int)
        (rows, cols) [1].
    """

    origin: tuple[float, float]
    pixel: float
    shape: tuple[int, int]

    @classmethod
    def from_window(cls, window: Iterable[float], pixel: float) -> Grid:
        """The grid of pixel ``pixel`` whose north-west corner is that of ``window``.

        Its size is the window's rounded to whole pixels (at least one pixel each way).

        Parameters
        ----------
        window : sequence of 4 float
            (x_min, y_min, x_max, y_max) [m].
        pixel : float
            Side of a pixel [m].

        Returns
        -------
        Grid
            The grid with origin (x_min, y_max) [m].
        """
        x_min, y_min, x_max, y_max = (float(v) for v in window)
        cols = max(1, int(round((x_max - x_min) / pixel)))
        rows = max(1, int(round((y_max - y_min) / pixel)))
        return cls((x_min, y_max), float(pixel), (rows, cols))

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """The rectangle covered by the raster.

        Returns
        -------
        tuple of 4 float
            (x_min, y_min, x_max, y_max), in the units of ``origin`` [m] or [tan].
        """
        x0, y0 = self.origin
        rows, cols = self.shape
        return (x0, y0 - rows * self.pixel, x0 + cols * self.pixel, y0)

    @overload
    def ground_from_raster(self, row: float, col: float) -> tuple[float, float]: ...
    @overload
    def ground_from_raster(self, row: ArrayLike, col: ArrayLike) -> tuple[np.ndarray, np.ndarray]: ...
    def ground_from_raster(self, row: ArrayLike, col: ArrayLike) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Plane coordinates of fractional raster indices; integers give pixel centres.

        Parameters
        ----------
        row, col : float or numpy.ndarray
            Fractional raster indices, broadcastable [pixel].

        Returns
        -------
        x, y : numpy.ndarray
            float64 plane coordinates, of the broadcast shape of ``row`` and ``col``, in the units of
            ``origin`` [m] or [tan].
        """
        x = self.origin[0] + (np.asarray(col, dtype=np.float64) + 0.5) * self.pixel
        y = self.origin[1] - (np.asarray(row, dtype=np.float64) + 0.5) * self.pixel
        return x, y

    @overload
    def raster_from_ground(self, x: float, y: float) -> tuple[float, float]: ...
    @overload
    def raster_from_ground(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]: ...
    def raster_from_ground(self, x: ArrayLike, y: ArrayLike) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Fractional raster indices of plane coordinates; inverse of ``ground_from_raster``.

        Parameters
        ----------
        x, y : float or numpy.ndarray
            Plane coordinates, broadcastable, in the units of ``origin`` [m] or [tan].

        Returns
        -------
        row, col : numpy.ndarray
            float64 fractional raster indices, of the broadcast shape of ``x`` and ``y`` [pixel].
        """
        col = (np.asarray(x, dtype=np.float64) - self.origin[0]) / self.pixel - 0.5
        row = (self.origin[1] - np.asarray(y, dtype=np.float64)) / self.pixel - 0.5
        return row, col


def lattice_offset(grid: Grid, lattice: Grid) -> tuple[int, int]:
    """Whole-pixel position of ``grid``'s pixel [0, 0] in ``lattice``'s indices.

    Parameters
    ----------
    grid : Grid
        The grid to place.
    lattice : Grid
        The grid whose indices are wanted; same pixel size and pixel edges as ``grid``.

    Returns
    -------
    tuple of (int, int)
        (row, col) of ``grid``'s pixel [0, 0] in ``lattice`` [pixel].

    Raises
    ------
    ValueError
        If the two grids do not share pixel size and pixel edges.
    """
    if not np.isclose(grid.pixel, lattice.pixel, rtol=1e-9):
        raise ValueError(f"pixel sizes differ: {grid.pixel} and {lattice.pixel}")
    col = (grid.origin[0] - lattice.origin[0]) / lattice.pixel
    row = (lattice.origin[1] - grid.origin[1]) / lattice.pixel
    if abs(col - round(col)) > 1e-6 or abs(row - round(row)) > 1e-6:
        raise ValueError("grids are not aligned to the same pixel lattice")
    return int(round(row)), int(round(col))


def sky_grid(start: tuple[int, int], shape: tuple[int, int], q: float) -> Grid:
    """Sky-plane grid whose cell [0, 0] is the whole-cell offset ``start``.

    Parameters
    ----------
    start : tuple of (int, int)
        (dr, dc) offset of cell [0, 0] from the cell at the zenith [cell].
    shape : tuple of (int, int)
        (rows, cols) [1].
    q : float
        Side of a cell on the sky plane [tan].

    Returns
    -------
    Grid
        The sky-plane grid [tan].
    """
    return Grid(((start[1] - 0.5) * q, (0.5 - start[0]) * q), q, shape)


def sky_offset(grid: Grid) -> tuple[int, int]:
    """Sky offset of cell [0, 0] of a sky-plane grid made by ``sky_grid``; inverse of it.

    Parameters
    ----------
    grid : Grid
        A sky-plane grid [tan] made by ``sky_grid``.

    Returns
    -------
    tuple of (int, int)
        (dr, dc) offset of cell [0, 0] [cell].
    """
    q = grid.pixel
    return int(round(0.5 - grid.origin[1] / q)), int(round(grid.origin[0] / q + 0.5))


def fold(weighted: np.ndarray, start: tuple[int, int], period: tuple[int, int]) -> np.ndarray:
    """Fold a sky raster modulo the tile period: ``e_f[i mod N] += e[i]``.

    Parameters
    ----------
    weighted : numpy.ndarray
        (channels, rows, cols) sky raster with cell [0, 0] at offset ``start`` (any leading axes).
    start : tuple of (int, int)
        (dr, dc) offset of cell [0, 0] [cell].
    period : tuple of (int, int)
        (rows, cols) of the tile period [cell].

    Returns
    -------
    numpy.ndarray
        (channels, period rows, period cols), cell [0, 0] at offset 0, dtype of ``weighted``;
        ``weighted`` itself when it is already folded.
    """
    weighted = np.asarray(weighted)
    if tuple(start) == (0, 0) and weighted.shape[-2:] == tuple(period):
        return weighted  # already folded
    out = np.zeros(weighted.shape[:-2] + tuple(period), dtype=weighted.dtype)
    for src_r, dst_r in wrapped_spans(start[0], weighted.shape[-2], period[0]):
        for src_c, dst_c in wrapped_spans(start[1], weighted.shape[-1], period[1]):
            out[..., dst_r, dst_c] += weighted[..., src_r, src_c]
    return out


def wrapped_spans(start: int, length: int, period: int) -> list[tuple[slice, slice]]:
    """Runs of ``u -> (start + u) mod period`` for u in [0, length).

    They are the pieces a wrapped copy or fold moves in one go.

    Parameters
    ----------
    start : int
        Index of u = 0 before wrapping [cell].
    length : int
        Number of u [cell].
    period : int
        Period of the wrapping [cell].

    Returns
    -------
    list of tuple of (slice, slice)
        Pairs (u-slice, wrapped slice).
    """
    spans, u = [], 0
    while u < length:
        d = (start + u) % period
        run = min(period - d, length - u)
        spans.append((slice(u, u + run), slice(d, d + run)))
        u += run
    return spans


def direction_vector(azimuth: ArrayLike, elevation: ArrayLike) -> np.ndarray:
    """Unit vector(s) of the direction(s) at an azimuth and an elevation.

    Parameters
    ----------
    azimuth : float or numpy.ndarray
        From north towards east [rad].
    elevation : float or numpy.ndarray
        Above the horizon [rad].

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 unit vector(s) in world axes x east, y north, z up [1].
    """
    azimuth = np.asarray(azimuth, dtype=np.float64)
    elevation = np.asarray(elevation, dtype=np.float64)
    ce = np.cos(elevation)
    return np.stack([ce * np.sin(azimuth), ce * np.cos(azimuth), np.sin(elevation)], axis=-1)


def tangent_axes(azimuth: float, elevation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame of the sky at a direction (azimuth a, elevation h).

    s = ``direction_vector(a, h)``; e_az = (cos a, -sin a, 0) is the direction of increasing
    azimuth and e_el = (-sin h sin a, -sin h cos a, cos h) that of increasing elevation. A point
    at gnomonic offset (dx to the right, dy up) is along s + dx e_az + dy e_el. Undefined at the
    zenith.

    Parameters
    ----------
    azimuth : float
        a, from north towards east [rad].
    elevation : float
        h, above the horizon [rad].

    Returns
    -------
    s, e_az, e_el : numpy.ndarray
        Each (3,) float64 in world axes [1].
    """
    a, h = azimuth, elevation
    e_az = np.array([np.cos(a), -np.sin(a), 0.0])
    e_el = np.array([-np.sin(h) * np.sin(a), -np.sin(h) * np.cos(a), np.cos(h)])
    return direction_vector(a, h), e_az, e_el


def normalized(v: np.ndarray) -> np.ndarray:
    """Vectors scaled to unit length along the last axis (a zero vector stays 0).

    Parameters
    ----------
    v : numpy.ndarray
        (..., n) vectors.

    Returns
    -------
    numpy.ndarray
        (..., n) unit vectors [1].
    """
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def length3(v: ArrayLike) -> np.ndarray:
    """The lengths of 3-vectors: ``np.linalg.norm(v, axis=-1)``, the same bits in less than half the
    time (numpy reduces a last axis of three as (x^2 + y^2) + z^2, as here; a test holds the two
    together): the sun kernel measures millions of angles a frame under a moving sun.

    Parameters
    ----------
    v : numpy.ndarray
        (..., 3) float64 vectors.

    Returns
    -------
    numpy.ndarray
        (...) their lengths.
    """
    v = np.asarray(v, dtype=np.float64)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.sqrt(x * x + y * y + z * z)


def sky_plane_from_direction(azimuth: float | np.ndarray,
                             zenith: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
    """Sky-plane point s = tan(zenith) * (sin(azimuth), cos(azimuth)) of a direction (Max 1991, Fig. 2).

    Parameters
    ----------
    azimuth : float or numpy.ndarray
        Angle from north towards east [rad].
    zenith : float or numpy.ndarray
        Angle from the zenith, below pi/2 [rad].

    Returns
    -------
    sx, sy : float or numpy.ndarray
        The point (x east, y north) on the plane z = 1 [tan].
    """
    t = np.tan(zenith)
    return t * np.sin(azimuth), t * np.cos(azimuth)


def direction_from_sky_plane(sx: float | np.ndarray,
                             sy: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
    """The direction through a sky-plane point; inverse of ``sky_plane_from_direction``.

    Parameters
    ----------
    sx, sy : float or numpy.ndarray
        The point (x east, y north) on the plane z = 1 [tan].

    Returns
    -------
    azimuth : float or numpy.ndarray
        From north towards east, in [0, 2 pi) [rad].
    zenith : float or numpy.ndarray
        Angle from the zenith [rad].
    """
    azimuth = np.mod(np.arctan2(sx, sy), 2.0 * np.pi)
    zenith = np.arctan(np.hypot(sx, sy))
    return azimuth, zenith


def cos4_antiderivative(x: ArrayLike, y: ArrayLike) -> np.ndarray:
    """F(x, y) with d2F/dx dy = 1 / (1 + x^2 + y^2)^2 = cos^4(theta), F(0, y) = F(x, 0) = 0.

    The integral of cos^4(theta) dA over a sky-plane rectangle is the projected solid angle
    (integral of cos(theta) d_omega) of that patch of sky.

    Parameters
    ----------
    x, y : float or numpy.ndarray
        Sky-plane coordinates, broadcastable [tan].

    Returns
    -------
    numpy.ndarray
        float64 F(x, y), of the broadcast shape [sr].
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    rx = np.sqrt(1.0 + x * x)
    ry = np.sqrt(1.0 + y * y)
    return 0.5 * (x / rx * np.arctan(y / rx) + y / ry * np.arctan(x / ry))


def projected_solid_angle(grid: Grid) -> np.ndarray:
    """Exact projected solid angle of every cell of a sky-plane grid.

    Cell (r, c) weight is the integral of cos^4(theta) over the cell (Max 1991, eq. 1), so a sky
    of uniform radiance L contributes exactly L times this to the unshadowed irradiance.

    Parameters
    ----------
    grid : Grid
        A sky-plane grid [tan].

    Returns
    -------
    numpy.ndarray
        float64 of ``grid.shape``, the weight of every cell [sr].
    """
    rows, cols = grid.shape
    x0, y0 = grid.origin
    xe = x0 + np.arange(cols + 1) * grid.pixel
    ye = y0 - np.arange(rows + 1) * grid.pixel
    f = cos4_antiderivative(xe[None, :], ye[:, None])
    return f[:-1, 1:] - f[:-1, :-1] - f[1:, 1:] + f[1:, :-1]


def sky_square_irradiance(alpha: float | np.ndarray) -> float | np.ndarray:
    """I0(alpha) = 4 sin(alpha) atan(sin(alpha)): projected solid angle of the sky square.

    The irradiance under a sky of radiance 1 restricted to the square (Max 1991, section
    "Error analysis", Fig. 16); pi at alpha = pi/2. Also named ``I0``.

    Parameters
    ----------
    alpha : float or numpy.ndarray
        Half-angle of the square on the sky plane, |s|_inf <= tan(alpha) [rad].

    Returns
    -------
    float or numpy.ndarray
        I0(alpha), of the shape of ``alpha`` [sr].
    """
    sa = np.sin(alpha)
    return 4.0 * sa * np.arctan(sa)


I0 = sky_square_irradiance


def pinhole_image_axes(height: float, elevation: float, angular_radius: float) -> tuple[float, float]:
    """Full axes of the sun's image cast on the ground by a pinhole ``height`` above it.

    The cone of the disc's rays meets the ground in an ellipse. Length H (cot(h - r) - cot(h + r))
    from the rays at elevations h -/+ r; width 2 H sin r / sqrt(sin(h - r) sin(h + r)) (the conic's
    minor axis). Their ratio is about 1 / sin h: 5.8 at 10 degrees, 11.5 at 5, 29 at 2.

    Parameters
    ----------
    height : float
        H, of the pinhole above the ground [m].
    elevation : float
        h, of the disc's centre, above ``angular_radius`` [rad].
    angular_radius : float
        r, of the sun's disc [rad].

    Returns
    -------
    length : float
        Axis along the sun's azimuth [m].
    width : float
        Axis across it [m].

    Raises
    ------
    ValueError
        If the whole sun disc is not above the horizon.
    """
    lo, hi = elevation - angular_radius, elevation + angular_radius
    if not lo > 0.0:
        raise ValueError("the whole sun disc must be above the horizon for its pinhole image")
    length = height * (1.0 / np.tan(lo) - 1.0 / np.tan(hi))
    width = 2.0 * height * np.sin(angular_radius) / np.sqrt(np.sin(lo) * np.sin(hi))
    return float(length), float(width)


def offset_direction(azimuth: float, elevation: float, dx: float, dy: float) -> tuple[float, float]:
    """The direction at gnomonic offset (dx to the right, dy up) from (azimuth, elevation): the
    inverse of ``ephemeris.moon_offset_from_sun``.

    Parameters
    ----------
    azimuth, elevation : float
        The centre direction [rad].
    dx, dy : float
        The offset on the tangent plane, to the right and up [tan].

    Returns
    -------
    tuple of float
        (azimuth in [0, 2 pi), elevation) [rad].
    """
    s, e_az, e_el = tangent_axes(azimuth, elevation)
    w = s + dx * e_az + dy * e_el
    w /= np.linalg.norm(w)
    return float(np.arctan2(w[0], w[1]) % (2 * np.pi)), float(np.arcsin(np.clip(w[2], -1, 1)))
