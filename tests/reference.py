"""Independent references for the tests: a direct sum and a world-coordinate Monte Carlo estimator.

Nothing here imports ``pipeline.shadow``: the Monte Carlo estimator traces rays from ground
points in metres through a canopy image placed in the world, so it checks orientation, scale
and units, not only the FFT.
"""

from __future__ import annotations

import numpy as np


def direct_sum(sky, sky_start, mask, mask_start, window_shape, outside_value):
    """g[k] = sum_i e[i] m[k + i], the paper's eq. 2, by brute force (O(n^4)).

    sky : (channels, rows, cols), cell [0, 0] at offset ``sky_start`` = (dr, dc).
    mask : (rows, cols) transmittance, pixel [0, 0] at lattice ``mask_start``;
        pixels off the mask take ``outside_value`` (1 for an isolated canopy), or
        ``None`` for a periodic mask (indices wrap).
    Ground pixel k runs over ``window_shape`` from lattice (0, 0).
    """
    channels, sr, sc = sky.shape
    mr, mc = mask.shape
    out = np.zeros((channels,) + tuple(window_shape))
    for kr in range(window_shape[0]):
        for kc in range(window_shape[1]):
            acc = np.zeros(channels)
            for ir in range(sr):
                for ic in range(sc):
                    r = kr + sky_start[0] + ir - mask_start[0]
                    c = kc + sky_start[1] + ic - mask_start[1]
                    if outside_value is None:
                        m = mask[r % mr, c % mc]
                    elif 0 <= r < mr and 0 <= c < mc:
                        m = mask[r, c]
                    else:
                        m = outside_value
                    acc += sky[:, ir, ic] * m
            out[:, kr, kc] = acc
    return out


def monte_carlo_irradiance(points, *, height, transmittance, radiance, rays, rng):
    """Irradiance at ground points, by cosine-weighted rays through a canopy plane. [radiance x sr]

    points : (n, 2) world x, y [m] (x east, y north); each point may be an array of
        per-ray positions of shape (n, rays, 2) to average over pixel areas.
    height : canopy plane height. [m]
    transmittance : f(x, y) -> transmittance of the canopy plane at world points [m].
    radiance : f(azimuth, zenith) -> (..., channels) sky radiance; azimuth from north
        towards east, zenith from +z. [rad]
    Stratified cosine-weighted sampling: E = pi * mean(L * T).
    """
    points = np.asarray(points, dtype=np.float64)
    n = points.shape[0]
    side = int(np.sqrt(rays))
    rays = side * side
    ju, jv = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    u1 = (ju.ravel()[None, :] + rng.random((n, rays))) / side
    u2 = (jv.ravel()[None, :] + rng.random((n, rays))) / side
    sin_theta = np.sqrt(u1)
    zenith = np.arcsin(sin_theta)
    azimuth = 2.0 * np.pi * u2
    dx = np.sin(azimuth) * np.tan(zenith)  # east
    dy = np.cos(azimuth) * np.tan(zenith)  # north
    if points.ndim == 2:
        px, py = points[:, 0:1], points[:, 1:2]
    else:
        px, py = points[..., 0], points[..., 1]
    t = transmittance(px + height * dx, py + height * dy)
    L = radiance(azimuth, zenith)
    return np.pi * (L * t[..., None]).mean(axis=1)


def image_transmittance(image, *, center, size, outside=1.0, periodic=False):
    """f(x, y) [m] -> transmittance of a north-up image covering ``size`` [m] around ``center``,
    texels as piecewise constant (nearest texel)."""
    image = np.asarray(image, dtype=np.float64)
    rows, cols = image.shape
    x0 = center[0] - size[0] / 2
    y1 = center[1] + size[1] / 2

    def f(x, y):
        x, y = np.broadcast_arrays(x, y)
        c = np.floor((x - x0) / size[0] * cols).astype(np.int64)
        r = np.floor((y1 - y) / size[1] * rows).astype(np.int64)
        if periodic:
            return image[r % rows, c % cols]
        inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        out = np.full(np.shape(x), outside, dtype=np.float64)
        out[inside] = image[r[inside], c[inside]]
        return out

    return f


def monte_carlo_patch(points, *, height, transmittance, azimuth, zenith, radiance, rays, rng):
    """Irradiance at ground points from a patch of sky of constant radiance, sampling the patch.

    azimuth, zenith : (low, high) bounds of the patch. [rad]
    radiance : (channels,) radiance of the patch.
    Directions uniform in solid angle over the patch: E = Omega * mean(L cos(theta) T). [radiance x sr]
    """
    points = np.asarray(points, dtype=np.float64)
    n = points.shape[0]
    phi = rng.uniform(azimuth[0], azimuth[1], (n, rays))
    cos_theta = rng.uniform(np.cos(zenith[1]), np.cos(zenith[0]), (n, rays))
    tan_theta = np.sqrt(1.0 - cos_theta**2) / cos_theta
    omega = (azimuth[1] - azimuth[0]) * (np.cos(zenith[0]) - np.cos(zenith[1]))
    x = points[:, 0:1] + height * tan_theta * np.sin(phi)
    y = points[:, 1:2] + height * tan_theta * np.cos(phi)
    t = transmittance(x, y)
    return omega * (cos_theta * t).mean(axis=1)[:, None] * np.asarray(radiance)[None, :]


def equirect_patch(width, height, *, azimuth, zenith, radiance, background=0.0):
    """An equirectangular sky (height, width, 3) that is ``radiance`` over whole texels whose
    centres fall in the azimuth and zenith bounds [rad], ``background`` elsewhere.
    Centre column north, east at three quarters of the width, top row at the zenith.
    Returns (image, the exact texel-aligned azimuth bounds, zenith bounds)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    phi = (u - 0.5) * 2 * np.pi
    theta = v * np.pi
    cols = np.nonzero((phi >= azimuth[0]) & (phi <= azimuth[1]))[0]
    rows = np.nonzero((theta >= zenith[0]) & (theta <= zenith[1]))[0]
    image = np.full((height, width, 3), background, dtype=np.float32)
    image[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1] = radiance
    az = ((cols[0] / width) - 0.5) * 2 * np.pi, (((cols[-1] + 1) / width) - 0.5) * 2 * np.pi
    zen = rows[0] * np.pi / height, (rows[-1] + 1) * np.pi / height
    return image, az, zen
