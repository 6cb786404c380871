"""The pinhole camera: its rays, and where world points land in its image.

Image convention: pixel (row, col) covers ``[col, col + 1) x [row, row + 1)`` in continuous image
coordinates (u along columns to the right, v along rows downwards); its centre is
``(col + 0.5, row + 0.5)``. The camera looks along ``forward``; ``right`` is horizontal and
``up = right x forward``, so with no roll the horizon is level. A camera looking straight down
with yaw 0 has north at the top of its image, as the ground rasters do.

Below the rays, the perspective view of the ground and the sky (the background of the frame):
``ground_hits`` and ``ground_view`` (the Lambertian ground, its anti-aliased horizon and
distances; the ground rasters read over each pixel's footprint through ``mipmap``),
``sky_view``, ``horizon_sky`` and ``background``.

Why one module: the pixels' rays, where they meet the ground and the sky plane, and the
horizon's coverage are one geometry, made once per camera for the frames of a run.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.kept import kept_at
from pipeline.texture import mipmap

if TYPE_CHECKING:
    from pipeline.sky.base import Sky
    from pipeline.texture.albedo import StochasticTiling

__all__ = ["MIN_DOWNWARD", "MIN_UPWARD", "Camera", "background", "ground_distance",
           "ground_fraction_rows", "ground_hits", "ground_irradiance", "ground_view", "horizon_sky", "image_rays",
           "pixel_rays", "project_points", "sky_view"]


@dataclass(frozen=True)
class Camera:
    """A pinhole camera, level (no roll).

    Parameters
    ----------
    position : (float, float, float)
        (x, y, z) of the pinhole. [m]
    yaw : float
        Azimuth of the view direction, from north towards east. [rad]
    pitch : float
        Elevation of the view direction, in [-pi/2, pi/2], negative looking down. [rad]
    vertical_fov : float
        Full vertical field of view, in (0, pi). [rad]
    width, height : int
        Image size. [pixel]
    """

    position: tuple[float, float, float]
    yaw: float
    pitch: float
    vertical_fov: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not (0.0 < self.vertical_fov < np.pi):
            raise ValueError(f"vertical_fov must lie in (0, pi) rad, got {self.vertical_fov}")
        if not (-np.pi / 2 <= self.pitch <= np.pi / 2):
            raise ValueError(f"pitch must lie in [-pi/2, pi/2] rad, got {self.pitch}")
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width} x {self.height}")

    @classmethod
    def look_at(cls, position: ArrayLike, target: ArrayLike, *, vertical_fov: float, width: int,
                height: int) -> Camera:
        """The camera at ``position`` looking at ``target`` (level, no roll).

        Parameters
        ----------
        position, target : array_like
            (x, y, z) of the pinhole and of the point seen at the image's centre; they differ. [m]
        vertical_fov : float
            Full vertical field of view, in (0, pi). [rad]
        width, height : int
            Image size. [pixel]

        Returns
        -------
        Camera
            Its yaw and pitch those of ``target - position``.
        """
        origin = np.asarray(position, dtype=np.float64)
        d = np.asarray(target, dtype=np.float64) - origin
        if not np.any(d):
            raise ValueError("target and position coincide")
        yaw = float(np.arctan2(d[0], d[1]) % (2 * np.pi))
        pitch = float(np.arctan2(d[2], np.hypot(d[0], d[1])))
        return cls((float(origin[0]), float(origin[1]), float(origin[2])), yaw, pitch, vertical_fov, width, height)

    @property
    def focal(self) -> float:
        """Focal length in pixels: pixels per unit of tan(angle) off the axis. [pixel]"""
        return 0.5 * self.height / np.tan(0.5 * self.vertical_fov)

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit (right, up, forward) vectors in world coordinates. A straight-down view takes
        its right from the yaw, so yaw 0 puts east on the right and north at the top."""
        cy, sy = np.cos(self.yaw), np.sin(self.yaw)
        cp, sp = np.cos(self.pitch), np.sin(self.pitch)
        forward = np.array([cp * sy, cp * cy, sp])
        right = np.array([cy, -sy, 0.0])
        return right, np.cross(right, forward), forward


def image_rays(camera: Camera, u: ArrayLike, v: ArrayLike) -> np.ndarray:
    """World directions through image points.

    Parameters
    ----------
    camera : Camera
        The pinhole camera.
    u, v : array_like
        Image coordinates, of one shape (...). [pixel]

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 directions, not normalised: the point on the image plane at distance 1
        along ``forward``. [m per m of depth]
    """
    right, up, forward = camera.basis
    x = (np.asarray(u, dtype=np.float64) - 0.5 * camera.width) / camera.focal
    y = (0.5 * camera.height - np.asarray(v, dtype=np.float64)) / camera.focal
    return forward + x[..., None] * right + y[..., None] * up


def pixel_rays(camera: Camera) -> np.ndarray:
    """Directions through every pixel centre, as ``image_rays``.

    Parameters
    ----------
    camera : Camera
        The pinhole camera.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) float64 directions, not normalised. [m per m of depth]
    """
    right, up, forward = camera.basis
    x = (np.arange(camera.width, dtype=np.float64) + 0.5 - 0.5 * camera.width) / camera.focal
    y = (0.5 * camera.height - (np.arange(camera.height, dtype=np.float64) + 0.5)) / camera.focal
    out = np.empty((camera.height, camera.width, 3))
    for k in range(3):  # image_rays' (forward + x right) + y up, one component at a time
        np.add((forward[k] + x * right[k])[None, :], (y * up[k])[:, None], out=out[..., k])
    return out


def project_points(camera: Camera, points: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where world points land in the image.

    Parameters
    ----------
    camera : Camera
        The pinhole camera.
    points : array_like
        (..., 3) world points. [m]

    Returns
    -------
    u, v : numpy.ndarray
        (...) float64 image coordinates. [pixel]
    depth : numpy.ndarray
        (...) float64 depth along ``forward``; points at depth <= 0 are behind the pinhole and
        their (u, v) are meaningless. [m]
    """
    right, up, forward = camera.basis
    d = np.asarray(points, dtype=np.float64) - np.asarray(camera.position)
    depth = d @ forward
    safe = np.where(np.abs(depth) > 1e-12, depth, 1e-12)
    u = 0.5 * camera.width + camera.focal * (d @ right) / safe
    v = 0.5 * camera.height - camera.focal * (d @ up) / safe
    return u, v, depth


# ---------------------------------------------------------------------------------------------
# The perspective view of the ground and the sky: the background B of the frame composite
# (docs/method.md, "The camera, the foreground and the finished frame": frame = F_sky + S (F_sun - F_sky) + (1 - A) B).
#
# Ground rasters are minified far from the camera, so they are read over each pixel's footprint
# on the ground (the parallelogram spanned by the columns of the Jacobian d(x, y)/d(u, v) of its
# ray's hit point), through the mip maps and the anisotropic filter of ``mipmap``.
# ---------------------------------------------------------------------------------------------

MIN_DOWNWARD = 1e-9
"""Least downward slope |wz| of a ray (unnormalised, |w| >= 1) that is taken to hit the ground:
caps the hit distance at height / MIN_DOWNWARD. [1]"""

MIN_UPWARD = 1e-3
"""Least upward slope wz / |w| used to look up a sky model on the sky plane, whose points run to
infinity at the horizon: |s| <= 1 / MIN_UPWARD. [1]"""

def ground_fraction_rows(camera: Camera) -> np.ndarray:
    """The fraction of each image row's pixels that lies below the horizon.

    Parameters
    ----------
    camera : Camera
        The pinhole camera, which has no roll (Notes).

    Returns
    -------
    numpy.ndarray
        (height,) float64 fraction, in [0, 1]. [1]

    Notes
    -----
    The camera has no roll, so the horizon (rays with wz = 0) is the image line
    v = height / 2 + focal tan(pitch), the same for every column, and a ray's wz falls linearly
    with v: the fraction is the analytic coverage clip(row + 1 - v_horizon, 0, 1).
    """
    _, up, forward = camera.basis
    v = np.arange(camera.height + 1, dtype=np.float64)
    wz = forward[2] + (0.5 * camera.height - v) / camera.focal * up[2]  # at the row edges
    top, bottom = wz[:-1], wz[1:]
    crossing = (top > 0) & (bottom < 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        partial = np.where(crossing, -bottom / (top - bottom), 0.0)
    return np.where(top <= 0, np.where(bottom < 0, 1.0, 0.0), np.where(bottom < 0, partial, 0.0))


def ground_hits(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where each pixel's ground part meets the ground plane z = 0, and its footprint there.

    Parameters
    ----------
    camera : Camera
        The pinhole camera, above the ground (position z > 0). [m]

    Returns
    -------
    x, y : numpy.ndarray
        (height, width) float64: the ground point seen at the centre of the pixel's ground part
        (the whole pixel, or the part below the horizon); NaN where no ground is seen. [m]
    jacobian : numpy.ndarray
        (height, width, 2, 2) float64 d(x, y)/d(u, v): the ground steps of one image pixel along
        u (column 0) and along v (column 1, times the ground part's height), the footprint
        parallelogram; NaN where no ground is seen. [m per pixel]
    distance : numpy.ndarray
        (height, width) float64: from the pinhole to that point, along the ray; inf where no
        ground is seen. [m]
    ground_fraction : numpy.ndarray
        (height, width) float64: the fraction of the pixel below the horizon, analytic
        (``ground_fraction_rows``). [1]

    Notes
    -----
    The Jacobian is the analytic derivative of the ray-plane hit P = C + t w, t = -z_C / wz:
    dP/du = t (dw/du - w (dwz/du) / wz), and the same along v. Near the horizon the hit runs to
    infinity; wz is held at -MIN_DOWNWARD or below, so every number stays finite.
    """
    rows_total, cols_total = camera.height, camera.width
    rows, part = rows_seeing_ground(camera)
    hits = row_hits(camera, rows, part)
    x = np.full((rows_total, cols_total), np.nan)
    y = np.full((rows_total, cols_total), np.nan)
    jacobian = np.full((rows_total, cols_total, 2, 2), np.nan)
    distance = np.full((rows_total, cols_total), np.inf)
    coverage = np.broadcast_to(ground_fraction_rows(camera)[:, None], (rows_total, cols_total)).copy()
    x[rows], y[rows], distance[rows] = hits.x, hits.y, hits.distance
    for (i, j), entry in zip(((0, 0), (0, 1), (1, 0), (1, 1)), (hits.dxdu, hits.dxdv, hits.dydu, hits.dydv)):
        jacobian[rows, :, i, j] = entry
    return x, y, jacobian, distance, coverage


def rows_seeing_ground(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The image rows that see ground, (r,) int, every pixel of which sees it, and their
    fractions below the horizon (r,) float64 [1]; checks that the camera is above the ground."""
    height_m = float(camera.position[2])
    if not height_m > 0:
        raise ValueError(f"the camera must be above the ground, got z = {height_m} [m]")
    fraction = ground_fraction_rows(camera)
    rows = np.flatnonzero(fraction > 0)
    return rows, fraction[rows]


@dataclass(frozen=True)
class RowHits:
    """``ground_hits`` for some image rows (``row_hits``), each (r, width) float64.

    Attributes
    ----------
    x, y : numpy.ndarray
        The ground point seen at the centre of each pixel's ground part [m].
    dxdu, dxdv, dydu, dydv : numpy.ndarray
        The footprint's Jacobian d(x, y)/d(u, v), its v column times the ground part's height
        [m per pixel].
    distance : numpy.ndarray
        From the pinhole to the ground point, along the ray [m].
    """

    x: np.ndarray
    y: np.ndarray
    dxdu: np.ndarray
    dxdv: np.ndarray
    dydu: np.ndarray
    dydv: np.ndarray
    distance: np.ndarray


def row_hits(camera: Camera, rows: np.ndarray, part: np.ndarray) -> RowHits:
    """``ground_hits`` for some image rows that see ground, without the full-image arrays.

    Parameters
    ----------
    camera : Camera
        The pinhole camera, above the ground [m].
    rows : numpy.ndarray
        (r,) int, image rows every pixel of which sees ground (``rows_seeing_ground``).
    part : numpy.ndarray
        (r,) float64, their fractions below the horizon [1].

    Returns
    -------
    RowHits
        The ground points [m], the Jacobian's entries [m per pixel] and the distances [m], each
        (r, width) float64.
    """
    height_m = float(camera.position[2])
    part = part[:, None]
    v = rows[:, None] + 1.0 - 0.5 * part
    u = np.arange(camera.width, dtype=np.float64)[None, :] + 0.5
    right, up, forward = camera.basis
    f = camera.focal
    # image_rays, one component at a time: (r, width) arrays
    across, down = (u - 0.5 * camera.width) / f, (0.5 * camera.height - v) / f
    wx, wy, w_z = (forward[k] + across * right[k] + down * up[k] for k in range(3))
    wz = np.minimum(w_z, -MIN_DOWNWARD)
    t = height_m / -wz
    x = camera.position[0] + t * wx
    y = camera.position[1] + t * wy
    jacobian = {}
    for j, (dw, scale) in enumerate(((right / f, 1.0), (-up / f, part))):
        slope = dw[2] / wz  # d(wz)/d(image) over wz
        jacobian[0, j] = t * (dw[0] - wx * slope) * scale
        jacobian[1, j] = t * (dw[1] - wy * slope) * scale
    distance = t * np.sqrt(wx * wx + wy * wy + w_z * w_z)
    return RowHits(x, y, jacobian[0, 0], jacobian[0, 1], jacobian[1, 0], jacobian[1, 1], distance)


def ground_view(camera: Camera, *, irradiance: mipmap.MipMap | Sequence[mipmap.MipMap],
                albedo: mipmap.MipMap | StochasticTiling) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Lambertian ground z = 0 in the camera's image: radiance = albedo E / pi.

    Parameters
    ----------
    camera : Camera
        The pinhole camera, above the ground (position z > 0). [m]
    irradiance : mipmap.MipMap or sequence of mipmap.MipMap
        The ground irradiance E (channels 3, or 1 for grey), or a sequence of maps, finest
        first: each but the last holds NaN beyond its raster ("constant" with value NaN), and a
        footprint that reaches NaN is read from the next. [radiance x sr]
    albedo : mipmap.MipMap or albedo.StochasticTiling
        The ground's albedo (channels 3 or 1), or a laying of one with a
        ``sample(footprints, lod_bias=)`` method. [1]

    Returns
    -------
    radiance : numpy.ndarray
        (height, width, 3) float32: albedo E / pi over the pixel's ground part, with albedo and
        E each averaged over its ground footprint (``ground_hits``,
        ``mipmap.sample_footprint``); 0 where no ground is seen. [radiance]
    ground_fraction : numpy.ndarray
        (height, width) float32: the fraction of the pixel below the horizon, the anti-aliased
        horizon; read-only, made once per camera. [1]
    distance : numpy.ndarray
        (height, width) float32: from the pinhole to the ground point seen, along the ray (for
        aerial perspective); inf where no ground is seen; read-only, made once per camera. [m]

    Notes
    -----
    Near the horizon the footprints grow without bound and the samples reach the rasters'
    coarsest levels: their means for periodic rasters, the outside value otherwise.
    """
    rows, e = _seen_radiance(camera, irradiance, albedo)
    radiance = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    if len(rows):
        radiance[rows] = e.T.reshape(len(rows), camera.width, -1)
    return radiance, ground_fractions(camera)[0], ground_distance(camera)


def _seen_radiance(camera: Camera, irradiance: mipmap.MipMap | Sequence[mipmap.MipMap],
                   albedo: mipmap.MipMap | StochasticTiling):
    """(the image rows that see ground, albedo E / pi (channels, pixels) float32 over their
    footprints or None without such rows): ``ground_view``'s radiance, channels first. [radiance]"""
    rows, e = _seen_irradiance(camera, irradiance)
    if len(rows):
        rho = albedo_in_view(camera, albedo)
        e = np.multiply(e, rho, out=e if len(e) >= len(rho) else None)  # (e rho) / pi in float32
        e *= np.float32(1.0 / np.pi)
    return rows, e


def ground_irradiance(camera: Camera, *, irradiance: mipmap.MipMap | Sequence[mipmap.MipMap]) -> np.ndarray:
    """The ground's horizontal irradiance E that each pixel sees, without the albedo.

    Parameters
    ----------
    camera : Camera
        The pinhole camera, above the ground (position z > 0). [m]
    irradiance : mipmap.MipMap or sequence of mipmap.MipMap
        The ground irradiance, as ``ground_view`` takes it. [radiance x sr]

    Returns
    -------
    numpy.ndarray
        (height, width, 3) float32: E averaged over each pixel's ground footprint as
        ``ground_view`` averages it (the same filtered chain); 0 where no ground is seen.
        [radiance x sr]
    """
    rows, e = _seen_irradiance(camera, irradiance)
    out = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    if len(rows):
        out[rows] = e.T.reshape(len(rows), camera.width, -1)
    return out


def _seen_irradiance(camera: Camera, irradiance: mipmap.MipMap | Sequence[mipmap.MipMap]):
    """(the image rows that see ground, E (channels, pixels) float32 over their footprints or
    None without such rows): ``ground_view``'s and ``ground_irradiance``'s read of the
    irradiance MipMaps (a MipMap or a sequence, finest first). [radiance x sr]"""
    rows, _ = rows_seeing_ground(camera)
    if not len(rows):
        return rows, None
    fp, _ = view_footprints(camera)
    return rows, filtered_chain(irradiance if isinstance(irradiance, (tuple, list)) else (irradiance,), fp)


@functools.lru_cache(maxsize=1)
def ground_fractions(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ground_view``'s ground fraction f (height, width) float32, and per image row f and
    1 - f (height, 1, 1) float32, to blend an image row by row (a tenth of the time of a
    product pixel by pixel, with the same values): they depend on the camera alone. Read-only."""
    row = ground_fraction_rows(camera).astype(np.float32)[:, None, None]
    fraction = np.broadcast_to(row[:, :, 0], (camera.height, camera.width)).copy()
    rest = 1.0 - row
    for array in (fraction, row, rest):
        array.flags.writeable = False
    return fraction, row, rest


@functools.lru_cache(maxsize=1)
def ground_distance(camera: Camera) -> np.ndarray:
    """The distance from the pinhole to the ground point each pixel sees, along the ray.

    Made once for the frames of a run, whose camera stands still.

    Parameters
    ----------
    camera : Camera
        As in ``ground_hits``.

    Returns
    -------
    numpy.ndarray
        (height, width) float32, read-only: ``ground_view``'s distance; inf where no ground is
        seen. [m]
    """
    rows, _ = rows_seeing_ground(camera)
    distance = np.full((camera.height, camera.width), np.inf, dtype=np.float32)
    if len(rows):
        distance[rows] = view_footprints(camera)[1].reshape(len(rows), camera.width)
    distance.flags.writeable = False
    return distance


@functools.lru_cache(maxsize=1)
def view_footprints(camera: Camera) -> tuple[mipmap.Footprints, np.ndarray]:
    """``ground_view``'s Footprints of the pixels of the image rows that see ground, rows
    first, and their distances (n,) float32 [m] (``_row_footprints``): made once for the
    frames of a run, whose camera stands still. Not to be written to (left writable: numba
    compiles read-only arrays as another type)."""
    rows, part = rows_seeing_ground(camera)
    *ellipses, distance = _row_footprints(camera, rows, part)
    return mipmap.Footprints(*ellipses), distance


@functools.lru_cache(maxsize=2)
def albedo_in_view(camera: Camera, albedo: mipmap.MipMap | StochasticTiling) -> np.ndarray:
    """The albedo (channels, n) float32 (read-only) of the ground pixels of ``camera``'s view
    (``view_footprints``), for a MipMap or a laying with ``sample``. It depends on the view
    and the albedo alone, so the frames of a run, whose camera stands still, read it once (the
    lru_cache holds the albedo, so its id is not reused)."""
    fp, _ = view_footprints(camera)
    if isinstance(albedo, mipmap.MipMap):
        rho = mipmap.filtered_read(albedo, fp, mipmap.LOD_BIAS)
    else:
        rho = albedo.sample(fp, lod_bias=mipmap.LOD_BIAS)
    rho.flags.writeable = False
    return rho


def filtered_chain(maps: Sequence[mipmap.MipMap], fp: mipmap.Footprints) -> np.ndarray:
    """(channels, n) samples of the first of ``maps`` whose footprint stays finite; the footprints
    read from a later map are a still camera's same arrays each frame, so that their taps are kept
    (docs/accuracy.md, "The far ground's taps")."""
    values = mipmap.filtered_read(maps[0], fp, mipmap.LOD_BIAS)
    for mip in maps[1:]:
        missing = np.flatnonzero(~np.isfinite(values).all(axis=0))
        if not len(missing):
            break
        arrays = tuple(getattr(fp, f.name) for f in fields(mipmap.Footprints))
        subset = kept_at(_SUBSETS, missing.tobytes(), arrays, lambda: mipmap.Footprints(*(a[missing] for a in arrays)),
                         read_only=False)  # to numba's loops, as they are
        values[:, missing] = mipmap.filtered_read(mip, subset, mipmap.LOD_BIAS)
    return values


_SUBSETS: dict = {}  # filtered_chain's footprints beyond a map: a still camera's are the same each frame,
# kept as the same arrays so that mipmap.filtered_read keeps their taps too


def _row_footprints(camera: Camera, rows: np.ndarray, part: np.ndarray) -> tuple[np.ndarray, ...]:
    """The ``Footprints`` fields and the distances of the pixels of some image rows that see
    ground (``row_hits``), each (r width,) float64 (the distances float32): compiled
    (``kernels.filter.row_footprints``), the operations of its numpy reference
    (tests/reference.py, ``row_footprints_arrays``)."""
    from pipeline.kernels import filter as _filter

    n = len(rows) * camera.width
    x, y, major, minor, ex, ey = (np.empty(n) for _ in range(6))
    distance = np.empty(n, dtype=np.float32)
    right, up, forward = camera.basis
    _filter.row_footprints(np.asarray(rows, dtype=np.float64), np.asarray(part, dtype=np.float64),
                           camera.width, camera.height, float(camera.focal),
                           np.asarray(camera.position, dtype=np.float64), right, up, forward, MIN_DOWNWARD,
                           x, y, major, minor, ex, ey, distance)
    return x, y, major, minor, ex, ey, distance


def sky_view(camera: Camera, sky: Sky) -> np.ndarray:
    """The sky's radiance in the camera's image, without the sun disc.

    Parameters
    ----------
    camera : Camera
        The pinhole camera.
    sky : base.Sky
        Asked for its ``view_radiance`` along each pixel's unit vector w, at sky-plane points
        s = (wx / wz, wy / wz) [tan] with wz / |w| held at MIN_UPWARD or more, with a pixel's
        width on the sky plane along the radius and across as the footprint.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) float32: each pixel cut by the horizon sampled at the centre of its
        sky part; 0 for pixels wholly below the horizon. [radiance]
    """
    out = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    rows, w, s, footprint = _sky_rays(camera)
    if len(rows):
        out[rows] = sky.view_radiance(w, s, footprint)
    return out


@functools.lru_cache(maxsize=1)
def _sky_rays(camera: Camera):
    """``sky_view``'s image rows that see sky, and their pixels' unit vectors w, sky-plane
    points s and footprints: made once for the frames of a run, whose camera stands still.
    Read-only."""
    fraction = ground_fraction_rows(camera)
    rows = np.flatnonzero(fraction < 1)
    v = (rows + 0.5 * (1.0 - fraction[rows]))[:, None]
    u = np.arange(camera.width, dtype=np.float64)[None, :] + 0.5
    w = image_rays(camera, u, v)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    wz = np.maximum(w[..., 2], MIN_UPWARD)
    s = np.stack([w[..., 0] / wz, w[..., 1] / wz], axis=-1)
    footprint = np.stack(np.broadcast_arrays(1.0 / (camera.focal * wz * wz), 1.0 / (camera.focal * wz)), axis=-1)
    for array in (rows, w, s, footprint):
        array.flags.writeable = False
    return rows, w, s, footprint


def horizon_sky(camera: Camera, sky: Sky) -> np.ndarray:
    """The sky's radiance just above the horizon in each image column.

    The radiance of an endless column of haze seen level (the sky model holds its haze), which
    the ground tends to with distance (Koschmieder 1924, ``frame.render_frame``).

    Parameters
    ----------
    camera : Camera
        The pinhole camera.
    sky : base.Sky
        As ``sky_view`` takes it.

    Returns
    -------
    numpy.ndarray
        (width, 3) float32: each column sampled in its direction at the horizon, raised to
        wz / |w| = MIN_UPWARD, with the footprint of ``sky_view`` there (the cloud pattern
        filtered to its mean so far out). [radiance]
    """
    right, _up, _forward = camera.basis
    u = np.arange(camera.width, dtype=np.float64) + 0.5
    # the level ray of column u is forward + x right + y up with wz = 0: y = -tan(pitch), and its
    # horizontal part (sin yaw, cos yaw) / cos(pitch) + x right
    ahead = np.array([np.sin(camera.yaw), np.cos(camera.yaw), 0.0]) / max(np.cos(camera.pitch), 1e-6)
    x = (u - 0.5 * camera.width) / camera.focal
    w = ahead[None, :] + x[:, None] * np.array([right[0], right[1], 0.0])[None, :]
    w[:, :2] /= np.hypot(w[:, 0], w[:, 1])[:, None]
    w[:, 2] = MIN_UPWARD / np.sqrt(1.0 - MIN_UPWARD**2)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    s = w[:, :2] / w[:, 2:3]
    return np.asarray(sky.view_radiance(w, s, 1.0 / (camera.focal * MIN_UPWARD**2)), dtype=np.float32)


def background(camera: Camera, *, irradiance: mipmap.MipMap | Sequence[mipmap.MipMap],
               albedo: mipmap.MipMap | StochasticTiling, sky: Sky,
               seen_sky: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The background B of the composite: ground and sky blended by the horizon's coverage.

    Parameters
    ----------
    camera, irradiance
        As in ``ground_irradiance``.
    albedo : mipmap.MipMap or albedo.StochasticTiling
        The ground's albedo, as ``ground_view`` takes it. [1]
    sky : base.Sky
        As ``sky_view`` takes it.
    seen_sky : numpy.ndarray, optional
        The sky's ``sky_view`` made before (not changed), so that a frame's light passes read
        the sky once. [radiance]

    Returns
    -------
    radiance : numpy.ndarray
        (height, width, 3) float32: f ground + (1 - f) sky, with f the pixel's ground fraction
        (``ground_view``, ``sky_view``). [radiance]
    distance : numpy.ndarray
        (height, width) float32: the ground's (inf where there is no ground). [m]
    """
    rows, e = _seen_radiance(camera, irradiance, albedo)
    _, row, rest = ground_fractions(camera)
    if not len(rows) or rows[-1] - rows[0] + 1 != len(rows):
        ground = np.zeros((camera.height, camera.width, 3), dtype=np.float32)  # ground_view's radiance
        if len(rows):
            ground[rows] = e.T.reshape(len(rows), camera.width, -1)
        sky_radiance = sky_view(camera, sky) if seen_sky is None else seen_sky.copy()
        ground *= row  # f ground + (1 - f) sky in float32, in place
        sky_radiance *= rest
        ground += sky_radiance
        return ground, ground_distance(camera)
    # the same float32 operations on the ground's rows, f ground made channels first and added to
    # (1 - f) sky channel by channel: a pass less than the image's f ground, and no transposed copy
    top, bottom = int(rows[0]), int(rows[-1]) + 1
    ground = e.reshape(len(e), bottom - top, camera.width)
    ground *= row[top:bottom, :, 0]
    if seen_sky is None and not len(_sky_rays(camera)[0]):  # no sky in view: (1 - f) sky is +0 throughout
        out = np.empty((camera.height, camera.width, 3), dtype=np.float32)
        out[:top], out[bottom:] = 0.0, 0.0
        for k in range(3):
            np.add(ground[min(k, len(ground) - 1)], np.float32(0.0), out=out[top:bottom, :, k])
        return out, ground_distance(camera)
    out = sky_view(camera, sky) if seen_sky is None else seen_sky.copy()
    out *= rest
    out[:top] += np.float32(0.0)  # 0 f + (1 - f) sky where no ground is seen
    out[bottom:] += np.float32(0.0)
    for k in range(3):
        np.add(ground[min(k, len(ground) - 1)], out[top:bottom, :, k], out=out[top:bottom, :, k])
    return out, ground_distance(camera)
