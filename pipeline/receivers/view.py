"""A wall in the camera: which pixels see it, where, and how far, and its radiance there
(docs/method.md, "Receivers: walls and slopes").

Each pixel is sampled at ``SAMPLES`` x ``SAMPLES`` points; a point sees the wall where its ray
meets the rectangle in front of the pinhole, nearer than the ground the pixel sees. The wall's
radiance at a point is albedo x irradiance / pi (Lambertian), its irradiance raster read
bilinearly; a pixel takes the mean of its points, the points that miss keeping what was behind.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.camera.pinhole import Camera, image_rays, project_points
from pipeline.core.cores import in_shares
from pipeline.core.geometry import Grid
from pipeline.receivers.plane import ReceiverPlane

__all__ = ["SAMPLES", "WallHits", "wall_hits", "BilinearTaps", "bilinear_taps", "read_taps", "read_taps_arrays",
           "read_bilinear", "read_tiled", "WallPoints", "wall_points", "show_points"]

SAMPLES = 3
"""Points per pixel side at which the camera looks for a wall (its edges anti-aliased). [count]"""


@dataclass(frozen=True)
class WallHits:
    """Where a camera's pixels see a wall.

    Attributes
    ----------
    region : (slice, slice)
        The image rows and columns that may see it.
    hit : numpy.ndarray
        (points, rows, cols) bool: the point's ray meets the wall in front of the pinhole.
    u, w : numpy.ndarray
        (points, rows, cols) float32, the hit's wall coordinates (0 where it misses) [m].
    distance : numpy.ndarray
        (points, rows, cols) float32, from the pinhole along the ray, inf where it misses [m].
    """

    region: tuple[slice, slice]
    hit: np.ndarray
    u: np.ndarray
    w: np.ndarray
    distance: np.ndarray


def _region(camera: Camera, plane: ReceiverPlane) -> tuple[slice, slice]:
    """The image box holding the wall's corners (the whole image if one lies behind the pinhole)."""
    assert plane.width is not None and plane.height is not None
    corners = plane.world_points([(s * plane.width / 2, h, 0.0) for s in (-1, 1) for h in (0.0, plane.height)])
    u, v, depth = project_points(camera, corners)
    if np.any(depth <= 0):
        return slice(0, camera.height), slice(0, camera.width)
    c0, c1 = (int(np.clip(x, 0, camera.width)) for x in (np.floor(u.min()), np.ceil(u.max())))
    r0, r1 = (int(np.clip(x, 0, camera.height)) for x in (np.floor(v.min()), np.ceil(v.max())))
    return slice(r0, r1), slice(c0, c1)


def wall_hits(camera: Camera, plane: ReceiverPlane, *, samples: int = SAMPLES) -> WallHits:
    """Where ``samples`` x ``samples`` points of each pixel see the wall.

    Parameters
    ----------
    camera : camera.pinhole.Camera
        The camera.
    plane : ReceiverPlane
        A wall (with its width and height).
    samples : int, optional
        Points per pixel side [count].

    Returns
    -------
    WallHits
        On the image box that may see it.
    """
    assert plane.width is not None and plane.height is not None
    rows, cols = region = _region(camera, plane)
    offsets = (np.arange(samples) + 0.5) / samples
    v, u = np.mgrid[rows, cols].astype(np.float64)
    origin = plane.local_points(np.asarray(camera.position))
    shape = (samples * samples, *v.shape)
    hit = np.zeros(shape, bool)
    across, up, distance = np.zeros(shape, np.float32), np.zeros(shape, np.float32), np.full(shape, np.inf, np.float32)
    for k, (dv, du) in enumerate((dv, du) for dv in offsets for du in offsets):
        d = image_rays(camera, u + du, v + dv)
        local = plane.local_directions(d / np.linalg.norm(d, axis=-1, keepdims=True))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -origin[2] / local[..., 2]
            a = origin[0] + t * local[..., 0]
            b = origin[1] + t * local[..., 1]
            hit[k] = (t > 0) & np.isfinite(t) & (np.abs(a) <= plane.width / 2) & (b >= 0) & (b <= plane.height)
        across[k][hit[k]], up[k][hit[k]], distance[k][hit[k]] = a[hit[k]], b[hit[k]], t[hit[k]]
    return WallHits(region, hit, across, up, distance)


@dataclass(frozen=True)
class BilinearTaps:
    """Where points read a raster bilinearly (``bilinear_taps``): the four neighbours' flat indices
    into its (rows x cols) cells and the weights along each axis.

    Attributes
    ----------
    corners : tuple of numpy.ndarray
        (top-left, top-right, bottom-left, bottom-right) flat cell indices, each (n,) int32 (int64
        for a raster of 2**31 cells or more).
    fx, fy : numpy.ndarray
        (n, 1), the points' fractions across and down from the top-left centre, float32 for float32
        points (exact), else float64 [1].
    """

    corners: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    fx: np.ndarray
    fy: np.ndarray

    def take(self, keep: np.ndarray) -> BilinearTaps:
        """The taps of the points ``keep`` selects (a boolean or index array)."""
        return BilinearTaps(tuple(c[keep] for c in self.corners), self.fx[keep], self.fy[keep])  # type: ignore[arg-type]


def bilinear_taps(grid: Grid, u: np.ndarray, w: np.ndarray) -> BilinearTaps:
    """Where points (u, w) read a raster on a wall's grid bilinearly, its edge pixels held beyond
    its centres (``read_bilinear`` in two steps, so that fixed points read each frame's raster).

    Parameters
    ----------
    grid : Grid
        The raster's grid in the wall's (u, w) [m].
    u, w : numpy.ndarray
        Wall coordinates (n,) [m].

    Returns
    -------
    BilinearTaps
        The points' neighbours and weights.
    """
    x = (u - grid.origin[0]) / grid.pixel - 0.5
    y = (grid.origin[1] - w) / grid.pixel - 0.5
    rows, cols = grid.shape
    x = np.clip(x, 0.0, cols - 1.0)
    y = np.clip(y, 0.0, rows - 1.0)
    c0 = np.minimum(x.astype(np.int64), max(cols - 2, 0))
    r0 = np.minimum(y.astype(np.int64), max(rows - 2, 0))
    c1, r1 = np.minimum(c0 + 1, cols - 1), np.minimum(r0 + 1, rows - 1)
    index = np.int32 if rows * cols < 2**31 else np.int64  # kept per camera: half the memory
    corners = tuple((r * cols + c).astype(index) for r, c in ((r0, c0), (r0, c1), (r1, c0), (r1, c1)))
    fx, fy = (x - c0)[..., None], (y - r0)[..., None]
    if x.dtype == np.float32:  # a float32 point's fraction is a float32 exactly (read_taps widens it again)
        fx, fy = fx.astype(np.float32), fy.astype(np.float32)
    return BilinearTaps(corners, fx, fy)  # type: ignore[arg-type]


def read_taps(image: np.ndarray, taps: BilinearTaps) -> np.ndarray:
    """A raster read at the points of ``taps``.

    Parameters
    ----------
    image : numpy.ndarray
        (rows, cols, channels) on the taps' grid.
    taps : BilinearTaps
        The points (``bilinear_taps``).

    Returns
    -------
    numpy.ndarray
        (n, channels) float32.
    """
    flat = image.reshape(-1, image.shape[-1])
    if flat.dtype == np.float32 and taps.fx.dtype == np.float32 and all(c.dtype == np.int32 for c in taps.corners):
        from pipeline.kernels.arrays import taps_read  # numba: imported when a wall is seen

        out = np.empty((len(taps.fx), flat.shape[1]), np.float32)
        fx, fy = taps.fx.reshape(-1), taps.fy.reshape(-1)
        in_shares(len(out), lambda start, stop: taps_read(flat, *taps.corners, fx, fy, out, start, stop))
        return out
    return read_taps_arrays(flat, taps)


def read_taps_arrays(flat: np.ndarray, taps: BilinearTaps) -> np.ndarray:
    """``read_taps`` with whole arrays (numpy), for any dtypes: the compiled loop's reference.

    Parameters
    ----------
    flat : numpy.ndarray
        (rows x cols, channels), the raster's cells row by row.
    taps : BilinearTaps
        The points (``bilinear_taps``).

    Returns
    -------
    numpy.ndarray
        (n, channels) float32.
    """
    fx, fy = taps.fx.astype(np.float64), taps.fy.astype(np.float64)
    gx = 1 - fx
    top = flat[taps.corners[0]] * gx  # in place where it can be: the same operations as read_bilinear's
    top += flat[taps.corners[1]] * fx
    bottom = flat[taps.corners[2]] * gx
    bottom += flat[taps.corners[3]] * fx
    top *= 1 - fy
    bottom *= fy
    top += bottom
    return top.astype(np.float32)


def read_bilinear(grid: Grid, image: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """A raster on a wall's grid read bilinearly at (u, w), its edge pixels held beyond its centres.

    Parameters
    ----------
    grid : Grid
        The raster's grid in the wall's (u, w) [m].
    image : numpy.ndarray
        (rows, cols, channels) on ``grid``.
    u, w : numpy.ndarray
        Wall coordinates, one shape (...) [m].

    Returns
    -------
    numpy.ndarray
        (..., channels) float32.
    """
    shape = np.shape(u)
    taps = bilinear_taps(grid, np.reshape(u, -1), np.reshape(w, -1))
    return read_taps(image, taps).reshape(*shape, image.shape[-1])


def read_tiled(image: np.ndarray, size: float, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """An albedo image tiled over a wall, ``size`` metres wide, its bottom row at w = 0, read at the
    nearest texel.

    Parameters
    ----------
    image : numpy.ndarray
        (rows, cols, channels) [1].
    size : float
        The wall covered by the image's width [m].
    u, w : numpy.ndarray
        Wall coordinates (...) [m].

    Returns
    -------
    numpy.ndarray
        (..., channels) float32 [1].
    """
    rows, cols = image.shape[:2]
    texel = size / cols
    col = np.floor(u / texel).astype(np.int64) % cols
    row = (rows - 1 - np.floor(w / texel).astype(np.int64)) % rows
    return image[row, col].astype(np.float32)


@dataclass(frozen=True)
class WallPoints:
    """The pixels' points that meet a wall, pixel by pixel (``wall_points``).

    Attributes
    ----------
    first : numpy.ndarray
        (pixels + 1,) int64: pixel p's points are ``first[p]`` to ``first[p + 1] - 1``, over
        ``WallHits.region``'s pixels row by row.
    sample : numpy.ndarray
        (n,) uint8: which of its pixel's points each is (``WallHits``' first axis), ascending.
    """

    first: np.ndarray
    sample: np.ndarray


def wall_points(hits: WallHits) -> tuple[WallPoints, np.ndarray, np.ndarray]:
    """The points of ``hits`` that meet the wall, pixel by pixel, each pixel's in the order of its points.

    Parameters
    ----------
    hits : WallHits
        Where a camera's pixels see a wall.

    Returns
    -------
    points : WallPoints
        Their pixels and samples.
    u, w : numpy.ndarray
        (n,) their wall coordinates, in that order [m].
    """
    samples = len(hits.hit)
    flat = np.flatnonzero(np.moveaxis(hits.hit, 0, -1))  # pixel by pixel, then sample by sample
    pixel, sample = flat // samples, (flat % samples).astype(np.uint8)
    counts = hits.hit.reshape(samples, -1).sum(axis=0)
    first = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return (WallPoints(first, sample), hits.u.reshape(samples, -1)[sample, pixel],
            hits.w.reshape(samples, -1)[sample, pixel])


def show_points(radiance: np.ndarray, distance: np.ndarray, hits: WallHits, points: WallPoints, image: np.ndarray,
                taps: BilinearTaps, albedo: np.ndarray, scale: np.float32) -> None:
    """Put a wall into a picture in place from its raster read at the pixels' points, compiled in one
    pass over the pixels: each pixel's points that see the wall nearer than ``distance`` take the
    radiance ``read (image) albedo scale`` (``read_taps``'s bits), summed in the order of the points
    and weighted 1 / points; the pixel keeps ``1 - cover`` of its radiance; the distance becomes
    the nearest point's where more than half of the points see the wall.

    Parameters
    ----------
    radiance : numpy.ndarray
        (height, width, 3) float32, the picture so far; changed [radiance].
    distance : numpy.ndarray
        (height, width) float32, what each pixel sees so far (inf: nothing); changed [m].
    hits : WallHits
        Where the wall is seen.
    points : WallPoints
        The points that meet it (``wall_points(hits)``).
    image : numpy.ndarray
        (rows, cols, 3) the wall's raster [radiance x sr].
    taps : BilinearTaps
        The points' reads of it (``bilinear_taps`` at their ``wall_points`` coordinates).
    albedo : numpy.ndarray
        (3,) or (n, 3) float32 [1].
    scale : numpy.float32
        The factor after the albedo (1 / pi) [1].
    """
    weight = np.float32(1.0 / len(hits.hit))
    if not all(a.dtype == np.float32 and a.flags.c_contiguous for a in (radiance, distance, hits.distance)) or \
            albedo.dtype != np.float32:
        raise ValueError("show_points takes C-contiguous float32 pictures and distances and float32 albedos")
    rows, cols = hits.region
    flat = image.reshape(-1, image.shape[-1])
    colour = albedo.reshape(-1, albedo.shape[-1])
    fx, fy = taps.fx.reshape(-1), taps.fy.reshape(-1)
    far = hits.distance.reshape(len(hits.distance), -1)
    from pipeline.kernels.arrays import points_over  # numba: imported when a wall is seen

    in_shares(len(points.first) - 1, lambda start, stop: points_over(
        radiance, distance, rows.start, cols.start, cols.stop - cols.start, far, points.first, points.sample, flat,
        *taps.corners, fx, fy, colour, scale, weight, start, stop))
