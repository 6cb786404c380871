"""The sun disc's kernel for the two-scale method (docs/method.md, "Two scales for the sun"): the
limb-darkened disc, cut by the moon and dimmed by the clouds, rasterised on a fine sky-plane grid;
its sum, the sun's irradiance on the open ground, and that of the sky and sun together.

The kernel draws a sky's sun: it uses the sky models (``sky``, ``equirect``), not the other way.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from functools import lru_cache, partial

import numpy as np

from pipeline.core.geometry import Grid, length3, sky_grid, tangent_axes
from pipeline.sky.equirect import EquirectSky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_disc import angle_to, disc_samples

__all__ = ["KERNEL_CACHE_SAMPLES", "KERNEL_FLOOR", "MAX_KERNEL_CELLS", "disc_layout", "disc_sub_samples",
           "sub_sample_footprint", "sun_irradiance", "sun_kernel", "unshadowed"]


MAX_KERNEL_CELLS = 4_000_000
"""Largest sun kernel block, in cells: a low sun on a fine grid is refused rather than ground out."""

KERNEL_FLOOR = float(np.radians(2.0))
"""Below this sun elevation ``sun_irradiance`` does without the kernel: stretched
1 / cos^2(theta) > 800 times on the sky plane, it would pass MAX_KERNEL_CELLS; the renderer
takes such a sun's light as unshadowed (``scene.SHADOW_FLOOR``). [rad]"""

KERNEL_CACHE_SAMPLES = 1 << 20
"""Most sub-samples of a sun kernel whose samples before the clouds (``_kernel_samples``) are kept
for the next frame: 32 MB of them, to a kernel of 64 x 64 cells at 8 x 8 sub-samples. [count]"""


def sun_kernel(sky: ProceduralSky | EquirectSky, q: float) -> SkyRaster:
    """The sun disc on a fine sky-plane grid of cell q, for the two-scale method (docs/method.md,
    "Two scales for the sun").

    Limb-darkened, cut by the moon, dimmed by the clouds' transmittance towards the sun's centre,
    rasterized directly on the sky plane (a low sun is an ellipse stretched radially by about
    1 / cos^2(theta)). Each cell holds the integral of L_sun(s) cos^4(theta) dA over it: n x n
    sub-samples per cell (n >= 8, more when the disc spans few cells), the sun and moon limbs
    anti-aliased by a linear ramp one sub-sample wide measured along the gradient of the angular
    distance (|grad_s rho| = cos(theta) |u_xy|, u the unit tangent away from the disc centre),
    which keeps the disc's energy with no renormalisation (measured in docs/accuracy.md; the
    worst case comes from the limb-darkening law's square root at the limb).

    Parameters
    ----------
    sky : procedural.ProceduralSky or equirect.EquirectSky
        A procedural sky, or an HDRI with a sun (``equirect.cut_sun``; no moon, no cloud
        dimming); the whole sun disc must be above the horizon.
    q : float
        The sky-plane cell [tan].

    Returns
    -------
    sky.raster.SkyRaster
        The kernel (outside = 0) on ``geometry.sky_grid(start, shape, q)``: the block covers the
        disc with a margin of one cell; ``geometry.sky_offset(kernel.grid)`` is its offset
        ``start``. In the sky's irradiance units ([klx] for a procedural sky); its sum is
        ``sun_irradiance(sky)``.

    Raises
    ------
    ValueError
        Without a sun, with q not positive, with the disc not wholly above the horizon, or
        with a block over MAX_KERNEL_CELLS.
    """
    sun = sky.sun
    if sun is None:
        raise ValueError("the sky has no sun to draw a kernel of (cut_sun finds an HDRI's)")
    r = sun.angular_radius
    if not q > 0:
        raise ValueError(f"q must be positive [tan], got {q}")
    if sun.elevation - r <= 1e-3:
        raise ValueError("the sun disc must lie wholly above the horizon for its sky-plane kernel")
    grid, h_sub, samples = _kernel_samples(sky, q)
    dimming = sky.sun_cloud_transmittance if isinstance(sky, ProceduralSky) else None
    out = np.zeros((3, grid.shape[0] * grid.shape[1]))
    for idx, disc, cos4 in samples:
        L = disc if dimming is None else disc * dimming  # as ProceduralSky._sun_samples dims it
        out[:, idx] = np.einsum("kijc,kij->ck", L, cos4) * h_sub**2
    weighted = out.reshape(3, *grid.shape).astype(np.float32)
    return SkyRaster(grid, weighted, np.zeros(3))



def sun_irradiance(sky: ProceduralSky | EquirectSky) -> np.ndarray:
    """The sun's horizontal irradiance on the open ground, after the moon and the clouds dim it.

    A procedural sky's: the sum of its kernel with 16 cells across the disc, which weights each
    part of a moon-cut disc by its own cos(theta) (its error is measured in docs/accuracy.md);
    zeros when the disc is not wholly above the horizon (``daylight.sky_daylight`` gives it no
    light then). Below KERNEL_FLOOR, where the kernel stretches past its limit: E_n cos(zenith)
    times the moon's ``moon_visible`` and the clouds' transmittance (the centre's cos(theta)).
    An HDRI's: its cut sun's, ``EquirectSky.sun_irradiance()``.

    Parameters
    ----------
    sky : procedural.ProceduralSky or equirect.EquirectSky
        The sky whose sun it is.

    Returns
    -------
    numpy.ndarray
        (3,) float64 irradiance [klx for a procedural sky; radiance x sr].
    """
    if isinstance(sky, EquirectSky):
        return sky.sun_irradiance()
    if sky.sun.elevation - sky.sun.angular_radius <= 1e-3:
        return np.zeros(3)
    if sky.sun.elevation < KERNEL_FLOOR:
        return sky.undimmed_sun_irradiance() * sky.moon_visible * sky.sun_cloud_transmittance
    return sun_kernel(sky, sky.sun.angular_radius / 8).weighted.sum(axis=(1, 2), dtype=np.float64)


def unshadowed(sky: ProceduralSky | EquirectSky) -> np.ndarray:
    """The sky's and the sun's irradiance together on the open, unshadowed ground.

    Any raster's ``SkyRaster.irradiance`` plus the sun kernel's sum.

    Parameters
    ----------
    sky : procedural.ProceduralSky or equirect.EquirectSky
        The sky.

    Returns
    -------
    numpy.ndarray
        (3,) float64 horizontal irradiance, ``sky.sky_irradiance + sun_irradiance(sky)``
        [klx for a procedural sky; radiance x sr].
    """
    return sky.sky_irradiance + sun_irradiance(sky)


def _kernel_samples(sky, q: float) -> tuple:
    """(grid, sub-sample side h_sub [tan], ((cells, sun radiance cut by the moon (k, n, n, 3),
    cos^4(theta) (k, n, n)), ...)) of ``sun_kernel``: its sub-samples by chunks of cells, before
    the clouds dim the sun. Kept (``_kept_kernel_samples``) for a procedural sky, whose sun changes
    far more slowly than its clouds, where there are at most KERNEL_CACHE_SAMPLES of them.
    [kcd/m^2 for a procedural sky]"""
    if isinstance(sky, ProceduralSky):
        key = replace(sky, clouds=None, time=0.0)
        try:
            hash(key)
        except TypeError:
            pass
        else:
            _grid, cells, n = _kernel_layout(sky, q)
            if len(cells) * n * n <= KERNEL_CACHE_SAMPLES:
                return _kept_kernel_samples(key, q)
    return _kept_kernel_samples.__wrapped__(sky, q)


def _kernel_layout(sky, q: float) -> tuple:
    """(grid, flat indices of the cells that can hold any of the disc, sub-samples n per cell
    side) of ``sun_kernel``."""
    sun = sky.sun
    return disc_layout(sky.sun_direction, sun.azimuth, sun.elevation, sun.angular_radius, q)


def disc_layout(centre: np.ndarray, azimuth: float, elevation: float, r: float, q: float) -> tuple:
    """Where a disc's kernel lies on a sky plane: its cells and how finely each is sampled.

    Parameters
    ----------
    centre : numpy.ndarray
        (3,) unit vector towards the disc's centre, in the plane's frame (z its normal) [1].
    azimuth, elevation : float
        The same direction's azimuth (from +y towards +x) and elevation [rad].
    r : float
        The disc's angular radius [rad].
    q : float
        The sky plane's cell [tan].

    Returns
    -------
    tuple
        (grid, flat indices (k,) of the cells that can hold any of the disc, sub-samples n per
        cell side).

    Raises
    ------
    ValueError
        For a kernel of more than MAX_KERNEL_CELLS cells.
    """
    # the disc's bounding box on the sky plane, from points on its limb
    _, e1, e2 = tangent_axes(azimuth, elevation)
    psi = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
    limb = np.cos(r) * centre + np.sin(r) * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    limb = limb[:, :2] / limb[:, 2:]
    (x_min, y_min), (x_max, y_max) = limb.min(axis=0), limb.max(axis=0)
    c0, c1 = int(np.floor(x_min / q + 0.5)) - 1, int(np.floor(x_max / q + 0.5)) + 1
    r0, r1 = int(np.floor(-y_max / q + 0.5)) - 1, int(np.floor(-y_min / q + 0.5)) + 1
    shape = (r1 - r0 + 1, c1 - c0 + 1)
    if shape[0] * shape[1] > MAX_KERNEL_CELLS:
        raise ValueError(f"the sun kernel would be {shape[0]} x {shape[1]} cells: raise q or the sun")
    grid = sky_grid((r0, c0), shape, q)
    minor = min(x_max - x_min, y_max - y_min) / q
    n = int(min(128, max(8, np.ceil(128.0 / minor))))
    # cells that can hold any of the disc: centre within r + half a cell diagonal (in angle)
    rr, cc = np.indices(shape)
    cx, cy = grid.ground_from_raster(rr, cc)
    centres = np.stack([cx, cy, np.ones_like(cx)], axis=-1)
    centres /= np.linalg.norm(centres, axis=-1, keepdims=True)
    reach = r + q * 0.75 * centres[..., 2]  # a cell spans at most q cos(theta) x sqrt(2)/2 in angle
    near = angle_to(centres, centre) <= reach
    cells = np.flatnonzero(near.ravel())
    return grid, cells, n


@lru_cache(maxsize=4)
def _kept_kernel_samples(sky, q: float) -> tuple:
    """``_kernel_samples`` computed (cached for the keys ``_kernel_samples`` gives it)."""
    grid, cells, n = _kernel_layout(sky, q)
    h_sub = q / n
    chunks = []
    for idx, cos_t, w in disc_sub_samples(grid, cells, n, q):
        # 2 h_sub is a safe ``widest``: the footprint is at most h_sub (cos_t <= 1, the ratio <= 1 to rounding)
        disc = disc_samples(w, partial(sub_sample_footprint, h_sub, w, cos_t), 2.0 * h_sub, sky.sun,
                            sky.sun_direction, sky.sun_normal_irradiance, getattr(sky, "moon", None))
        cos4 = cos_t**4
        for a in (idx, disc, cos4):
            a.setflags(write=False)
        chunks.append((idx, disc, cos4))
    return grid, h_sub, tuple(chunks)


def disc_sub_samples(grid: Grid, cells: np.ndarray, n: int, q: float) -> Iterator[tuple[np.ndarray, ...]]:
    """A disc's kernel's sub-samples (``disc_layout``'s), n x n a cell, by chunks of at most 2^20.

    Parameters
    ----------
    grid : Grid
        The kernel's sky-plane grid [tan].
    cells : numpy.ndarray
        (k,) flat indices of the cells to sample.
    n : int
        Sub-samples per cell side.
    q : float
        The sky plane's cell [tan].

    Yields
    ------
    tuple
        (cells (c,), cos(theta) (c, n, n) [1], unit directions (c, n, n, 3) in the plane's frame [1]),
        theta from the plane's normal.
    """
    cx, cy = grid.ground_from_raster(*np.indices(grid.shape))
    offsets = (np.arange(n) + 0.5) / n - 0.5
    ox, oy = np.meshgrid(offsets * q, -offsets * q)
    chunk = max(1, (1 << 20) // (n * n))
    for lo in range(0, len(cells), chunk):
        idx = cells[lo : lo + chunk]
        sx = np.ravel(cx)[idx, None, None] + ox
        sy = np.ravel(cy)[idx, None, None] + oy
        cos_t = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
        yield idx, cos_t, np.stack([sx * cos_t, sy * cos_t, cos_t], axis=-1)


def sub_sample_footprint(h_sub: float, w: np.ndarray, cos_t: np.ndarray, centre: np.ndarray, rho: np.ndarray,
                         near: np.ndarray) -> np.ndarray:
    """The sky-plane sub-sample spacing expressed in angle along the gradient of rho (``disc_samples``'
    ``footprint``), at most ``h_sub``.

    Parameters
    ----------
    h_sub : float
        The sub-sample spacing on the sky plane [tan].
    w, cos_t : numpy.ndarray
        A chunk's directions and cos(theta) (``disc_sub_samples``) [1].
    centre : numpy.ndarray
        (3,) the disc's centre in the same frame as ``w`` [1].
    rho : numpy.ndarray
        The angles from it of the samples ``near`` picks [rad].
    near : numpy.ndarray
        The samples, as an index of ``w``.

    Returns
    -------
    numpy.ndarray
        The spacing at each [rad].
    """
    away = w[near] * np.cos(rho)[..., None] - centre
    norm = np.maximum(length3(away), 1e-300)
    return h_sub * cos_t[near] * np.maximum(np.hypot(away[..., 0], away[..., 1]) / norm, 1e-9)
