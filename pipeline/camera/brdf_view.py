"""The ground with the reflectance, as the camera sees it (docs/method.md, "The ground's
reflectance"): each ground pixel's own view vector, the sun's term exact per pixel, the sky's
blended from the view bands (``brdf_bands``), and the background the ground makes with the sky."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, cast

import numpy as np

from pipeline.camera import pinhole
from pipeline.ground.brdf import VIEW_ZENITH_LIMIT, clamp_view, shape
from pipeline.ground.brdf_bands import banded_sky, open_sky, sky_ratio
from pipeline.ground.view_bands import ViewBands

__all__ = ["view_vectors", "ground_radiance", "relative_sky", "background"]

if TYPE_CHECKING:
    from pipeline.config.settings import BrdfConfig  # model and parameters: any value with those two fields
    from pipeline.core.geometry import Grid
    from pipeline.sky.base import Sky
    from pipeline.sky.raster import SkyRaster
    from pipeline.texture.albedo import StochasticTiling
    from pipeline.texture.mipmap import MipMap


def view_vectors(camera: pinhole.Camera) -> np.ndarray:
    """Unit vectors from the ground point each ground pixel sees towards the pinhole.

    For the pixels of ``pinhole.view_footprints`` (rows first).

    Parameters
    ----------
    camera : pinhole.Camera
        The camera [m].

    Returns
    -------
    numpy.ndarray
        (n, 3) float64 [1].
    """
    fp, _ = pinhole.view_footprints(camera)
    d = np.stack([camera.position[0] - fp.x, camera.position[1] - fp.y,
                  np.full(fp.x.shape, float(camera.position[2]))], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


@functools.lru_cache(maxsize=1)
def camera_views(camera: pinhole.Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``view_vectors`` held to VIEW_ZENITH_LIMIT (``clamp_view``) (n, 3), their zenith angles
    (n,) [rad] and azimuths (n,) [rad, from +y towards +x]: they depend on the camera alone, so
    the frames of a run make them once per camera (a following camera's walk changes none of the
    view directions' spread, only the cache's key). Read-only."""
    views = clamp_view(view_vectors(camera))
    zenith = np.arccos(np.clip(views[:, 2], -1.0, 1.0))
    azimuth = np.arctan2(views[:, 0], views[:, 1])
    for array in (views, zenith, azimuth):
        array.flags.writeable = False
    return views, zenith, azimuth


def ground_radiance(camera: pinhole.Camera, brdf: BrdfConfig, albedo: MipMap | StochasticTiling, *,
                    sun: Sequence[MipMap], sky_maps: Sequence[MipMap] | tuple[np.ndarray, Grid],
                    bands: ViewBands, sun_direction: np.ndarray | None, raster: SkyRaster,
                    open_light: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The ground's radiance with the reflectance ``brdf``.

    rho / pi [ s(V(x), L_sun) E_sun(x) + r(x) sum_b w_b(x) G_b(x) sum_z u_z(x) E_z(x) / sum_ch E_z,ch ],
    rho the albedo texture, E_sun the ground's light from the sun alone, the sky's term ``banded_sky``:
    w_b the bands' weights at the pixel's view zenith and azimuth, u_z the zeniths', r(x) ``sky_ratio``
    over ``raster``, V(x) each pixel's own view vector. The sun's term is exact per pixel; the sky's is
    blended (docs/method.md, "The ground's reflectance"). 0 where no ground is seen.

    Parameters
    ----------
    camera : pinhole.Camera
        The camera [m].
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).
    albedo : mipmap.MipMap or albedo.StochasticTiling
        The albedo texture rho [1].
    sun : sequence of mipmap.MipMap
        MipMap chain of E_sun (``GroundResult.sun_part``) [radiance x sr].
    sky_maps : sequence of mipmap.MipMap, or tuple of (numpy.ndarray, Grid)
        The bands' terms: one MipMap chain whose channels are each band's, three for a colour
        band (``ViewBands.colours``, E_z), one (the channels' sum, G_b) for the others, so that the
        camera's footprints are filtered once for all of them [radiance x sr]. With
        ``open_light``, instead the raster of ``relative_sky`` (rows, cols, 3) and its grid, read
        bilinearly at each pixel's footprint centre (1 beyond it; it is smooth) [1].
    bands : ViewBands
        The view bands.
    sun_direction : numpy.ndarray or None
        (3,) unit vector towards the sun [1].
    raster : sky.raster.SkyRaster
        The sky raster [radiance x sr].
    open_light : tuple, optional
        The colour bands' open-sky light (Z, 3) and every band's on the channels' sum (B,)
        [radiance x sr]: the sky's term is then the read of ``sky_maps`` times the same term on
        open ground at the pixel's view (``open_sky``): the same formula with the per-point part
        done on the ground raster before the camera reads it.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) float32 [radiance].
    """
    rows, _ = pinhole.rows_seeing_ground(camera)
    radiance = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    if not len(rows):
        return radiance
    fp, _ = pinhole.view_footprints(camera)
    views, zenith, azimuth = camera_views(camera)
    light = pinhole.filtered_chain(sun, fp)
    if sun_direction is not None:
        light *= _sun_shape(brdf, camera, tuple(float(c) for c in sun_direction))[None]
    weights = _band_weights(camera, _nodes(bands))
    ratio = sky_ratio(brdf, raster, bands, views, angles=(zenith, azimuth), weights=weights)
    if open_light is not None:
        relative, grid = cast("tuple[np.ndarray, Grid]", sky_maps)  # with open_light: relative_sky's raster
        sky = _relative_at_pixels(camera, relative, grid)  # (3, n), relative to open ground
        sky *= open_sky(bands, weights, *open_light)
        sky *= ratio
        light += sky
    else:
        light += _stacked_sky(pinhole.filtered_chain(cast("Sequence[MipMap]", sky_maps), fp), bands, weights, ratio)
    rho = pinhole.albedo_in_view(camera, albedo)
    light *= rho
    light *= np.float32(1.0 / np.pi)
    radiance[rows] = light.T.reshape(len(rows), camera.width, -1)
    return radiance


def _stacked_sky(stack: np.ndarray, bands: ViewBands, weights: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """``banded_sky`` of the bands' terms read as one stack (3 Z + B - Z, n): each band's channel,
    three for a colour band (``ViewBands.colours``). [radiance x sr]"""
    colours, starts, at = set(bands.colours), [], 0
    for band in range(bands.count):
        starts.append(at)
        at += 3 if band in colours else 1
    tints = np.stack([stack[starts[b]:starts[b] + 3] for b in bands.colours])
    bands_light = np.stack([stack[starts[b]:starts[b] + 3].sum(axis=0) if b in colours else stack[starts[b]]
                            for b in range(bands.count)])
    return banded_sky(bands, tints, bands_light, weights, ratio)


def relative_sky(camera: pinhole.Camera, grid: Grid, bands: ViewBands, colours: np.ndarray, bands_light: np.ndarray,
                 colours_open: np.ndarray, bands_open: np.ndarray) -> np.ndarray:
    """``banded_sky`` before ``sky_ratio``, over the same on open ground, at each cell of a ground raster.

    r-free and 1 on open ground, so the camera can read it like any ground raster (1 beyond it) and
    ``ground_radiance`` multiply by the open term at each pixel's own view. The views are each cell's
    own, from its centre to the camera's pinhole (``_cell_weights``).

    Parameters
    ----------
    camera : pinhole.Camera
        The camera [m].
    grid : Grid
        The ground raster's grid [m].
    bands : ViewBands
        The view bands.
    colours : numpy.ndarray
        (rows, cols, Z, 3): the colour bands' terms (``ViewBands.colours``) [radiance x sr].
    bands_light : numpy.ndarray
        (rows, cols, B): every band's on the channels' sum [radiance x sr].
    colours_open : numpy.ndarray
        (Z, 3) the same on open ground [radiance x sr].
    bands_open : numpy.ndarray
        (B,) the same on open ground [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 [1].
    """
    weights = _cell_weights(camera, grid, _nodes(bands))  # (B, rows * cols)
    flat = np.moveaxis(bands_light.reshape(-1, bands.count), -1, 0)
    colour_flat = np.moveaxis(colours.reshape(-1, *colours.shape[-2:]), 0, -1)  # (Z, 3, rows * cols)
    sky = banded_sky(bands, colour_flat, flat, weights, np.float32(1.0))
    sky /= np.maximum(open_sky(bands, weights, colours_open, bands_open), np.float32(1e-30))
    return np.moveaxis(sky, 0, -1).reshape(*grid.shape, 3)


def _relative_at_pixels(camera: pinhole.Camera, relative: np.ndarray, grid: Grid) -> np.ndarray:
    """``relative_sky``'s raster (rows, cols, 3) on ``grid`` at the camera's ground pixels'
    footprint centres, bilinearly, with a ring of 1 (open ground) round it and 1 beyond (3, n)
    float32 [1]: the sky's term under the leaves changes over metres, so a point read serves
    where the sun's light needs the footprint's filter."""
    from pipeline.kernels import arrays

    rows, cols = grid.shape
    padded = np.ones((3, rows + 2, cols + 2), dtype=np.float32)
    padded[:, 1:-1, 1:-1] = np.moveaxis(relative, -1, 0)
    corner, taps = _pixel_reads(camera, grid)
    out = np.empty((3, len(corner)), dtype=np.float32)
    arrays.lattice_read(padded.reshape(3, -1), corner, taps, cols + 2, out)
    return out


@functools.lru_cache(maxsize=2)
def _pixel_reads(camera: pinhole.Camera, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """Where ``_relative_at_pixels`` reads: each ground pixel's first corner in the raster padded
    by one cell (n,) intp and the bilinear weights of its four corners (4, n) float32, held at
    the padding's edge. They depend on the camera and the grid alone. Read-only."""
    fp, _ = pinhole.view_footprints(camera)
    r, c = grid.raster_from_ground(fp.x, fp.y)
    i = np.clip(r + 1.0, 0.0, grid.shape[0] + 1.0)
    j = np.clip(c + 1.0, 0.0, grid.shape[1] + 1.0)
    i0, j0 = np.minimum(i.astype(np.intp), grid.shape[0]), np.minimum(j.astype(np.intp), grid.shape[1])
    fi, fj = (i - i0).astype(np.float32), (j - j0).astype(np.float32)
    taps = np.stack([(1 - fi) * (1 - fj), (1 - fi) * fj, fi * (1 - fj), fi * fj])
    corner = i0 * (grid.shape[1] + 2) + j0
    for array in (corner, taps):
        array.flags.writeable = False
    return corner, taps


def _nodes(bands: ViewBands) -> ViewBands:
    """The bands without their error: the key of the weights' caches (the same nodes every frame)."""
    return replace(bands, error=0.0)


@functools.lru_cache(maxsize=2)
def _cell_weights(camera: pinhole.Camera, grid: Grid, bands: ViewBands) -> np.ndarray:
    """``ViewBands.weights`` (B, rows * cols) float32 at the views from a ground grid's cell
    centres to the camera's pinhole (zenith held to VIEW_ZENITH_LIMIT). Read-only. [1]"""
    gx, gy = grid.ground_from_raster(np.arange(grid.shape[0])[:, None], np.arange(grid.shape[1])[None, :])
    dx, dy = np.broadcast_arrays(camera.position[0] - gx, camera.position[1] - gy)
    zenith = np.minimum(np.arctan2(np.hypot(dx, dy).reshape(-1), float(camera.position[2])), VIEW_ZENITH_LIMIT)
    out = bands.weights(zenith, np.arctan2(dx, dy).reshape(-1)).astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=2)
def _band_weights(camera: pinhole.Camera, bands: ViewBands) -> np.ndarray:
    """``ViewBands.weights`` (B, n) float32 at the camera's ground pixels' own views: the same
    while the camera and the bands stay (the sky changes slowly). Read-only. [1]"""
    _, zenith, azimuth = camera_views(camera)
    out = bands.weights(zenith, azimuth).astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=2)
def _sun_shape(brdf: BrdfConfig, camera: pinhole.Camera, sun_direction: tuple[float, ...]) -> np.ndarray:
    """The shape s(V(x), L_sun) (n,) float32 at the camera's ground pixels' own views: made once
    while neither the camera nor the sun moves. Read-only. [1]"""
    out = shape(brdf, camera_views(camera)[0], np.asarray(sun_direction)[None]).astype(np.float32)
    out.flags.writeable = False
    return out


def background(camera: pinhole.Camera, ground_radiance_: np.ndarray, sky: Sky) -> np.ndarray:
    """``pinhole.background`` with the ground's radiance given: f ground + (1 - f) sky.

    Parameters
    ----------
    camera : pinhole.Camera
        The camera [m].
    ground_radiance_ : numpy.ndarray
        (height, width, 3) the ground's radiance [radiance].
    sky : object
        The sky, as ``pinhole.sky_view`` takes it.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) radiance [radiance].
    """
    _, row, rest = pinhole.ground_fractions(camera)
    out = ground_radiance_ * row
    seen = pinhole.sky_view(camera, sky)
    seen *= rest  # in place: the sky's view is this call's own
    out += seen
    return out
