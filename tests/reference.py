"""Independent references for the tests: a direct sum and a world-coordinate Monte Carlo estimator,
and the numpy references of the compiled loops (the pixels' ground footprints, the mip map's levels
and filtering, the albedo's tiling).

Nothing here imports ``pipeline.ground.shadow``: the Monte Carlo estimator traces rays from ground
points in metres through a canopy image placed in the world, so it checks orientation, scale
and units, not only the FFT.
"""

from __future__ import annotations

import functools

import numpy as np

from pipeline.camera.pinhole import Camera, row_hits
from pipeline.sky.scattering import haze_transmittance, henyey_greenstein
from pipeline.sky.sun_disc import LIMB_DARKENING, SUN_ANGULAR_RADIUS
from pipeline.texture.albedo import BLEND_SHARPNESS, LOOKUP_BINS, StochasticTiling
from pipeline.texture.mipmap import MAX_TAPS, Footprints, MipMap, footprint_axes, pair_mean


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
    out = np.zeros((channels, *tuple(window_shape)))
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


# ---------------------------------------------------------------------------------------------
# The sun through pinholes, in world coordinates (tests/test_sun.py, benchmarks/accuracy_sun.py).
# Directions are unit vectors (x east, y north, z up); the discs are sampled on the plane tangent
# to the sky at the sun's centre. Nothing here knows about rasters, kernels or FFTs.
# ---------------------------------------------------------------------------------------------


def unit_vector(azimuth, elevation):
    """Unit vector (x east, y north, z up) of a direction; azimuth from north towards east. [rad]"""
    return np.array([np.cos(elevation) * np.sin(azimuth), np.cos(elevation) * np.cos(azimuth),
                     np.sin(elevation)])


def tangent_frame(azimuth, elevation):
    """(centre, right, up) unit vectors at a direction: ``right`` is horizontal, to the right of an
    observer facing that direction (increasing azimuth), ``up`` towards the zenith. [1]"""
    centre = unit_vector(azimuth, elevation)
    right = np.array([np.cos(azimuth), -np.sin(azimuth), 0.0])
    return centre, right, np.cross(right, centre)


def offset_direction(azimuth, elevation, dx, dy):
    """Unit vector of the point (dx right, dy up) [rad] on the gnomonic plane tangent at (azimuth,
    elevation): the convention of a config's moon offsets."""
    centre, right, up = tangent_frame(azimuth, elevation)
    w = centre + dx * right + dy * up
    return w / np.linalg.norm(w)


def angle_between(w, c):
    """Angle [rad] between unit vectors w (..., 3) and c (3,), stable for small angles."""
    return 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(w - np.asarray(c), axis=-1), 0.0, 1.0))


def limb_darkened_profile(rho, radius, limb_darkening):
    """Relative radiance (..., channels) of a disc under the linear law I / I(centre) =
    1 - u (1 - mu), mu = sqrt(1 - (rho / radius)^2); 0 beyond the limb. [1]"""
    u = np.asarray(limb_darkening, dtype=np.float64)
    rho = np.asarray(rho, dtype=np.float64)[..., None]
    mu = np.sqrt(np.clip(1.0 - (rho / radius) ** 2, 0.0, 1.0))
    return np.where(rho <= radius, 1.0 - u * (1.0 - mu), 0.0)


def sun_radiance_function(sun_direction, radius, centre_radiance, limb_darkening,
                          moon_direction=None, moon_radius=None):
    """L(w) -> (..., channels): a limb-darkened disc of angular ``radius`` [rad] about
    ``sun_direction``, ``centre_radiance`` (channels,) at its centre, 0 where the dark disc of the
    moon covers it. Sharp edges, no anti-aliasing."""
    centre_radiance = np.asarray(centre_radiance, dtype=np.float64)

    def radiance(w):
        L = limb_darkened_profile(angle_between(w, sun_direction), radius, limb_darkening) * centre_radiance
        if moon_direction is not None:
            L = L * (angle_between(w, moon_direction) > moon_radius)[..., None]
        return L

    return radiance


def disc_directions(sun_direction, right, up, radius, *, n, rng=None):
    """Directions stratified over the gnomonic disc of radius tan(radius) about ``sun_direction``:
    an n x n grid of cells on the tangent plane (jittered with ``rng``, else at cell centres),
    those inside the disc. Returns w (k, 3) and the solid angle each stands for (k,). [sr]"""
    t = np.tan(radius)
    step = 2.0 * t / n
    grid = (np.arange(n) + 0.5) * step - t
    a, b = np.meshgrid(grid, grid, indexing="ij")
    a, b = a.ravel(), b.ravel()
    if rng is not None:
        a = a + rng.uniform(-0.5, 0.5, a.shape) * step
        b = b + rng.uniform(-0.5, 0.5, b.shape) * step
    inside = a * a + b * b <= t * t * (1 + 1e-12)
    a, b = a[inside], b[inside]
    p = sun_direction + a[:, None] * right + b[:, None] * up
    norm = np.linalg.norm(p, axis=1)
    return p / norm[:, None], step * step / norm**3


def cosine_rays(normal, count, rng):
    """Cosine-weighted unit vectors about ``normal`` (world), stratified, built from an arbitrary tangent."""
    t = np.cross(normal, rng.normal(size=3))
    t /= np.linalg.norm(t)
    b = np.cross(normal, t)
    side = int(np.sqrt(count))
    i, j = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    u1 = (i.ravel() + rng.random(side * side)) / side
    u2 = (j.ravel() + rng.random(side * side)) / side
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    return (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * b + np.sqrt(1 - u1)[:, None] * normal


def receiver_monte_carlo(points, *, origin, u, w, normal, distance, transmittance, sky, ground, pixel, rng):
    """A receiver's irradiance behind a plane of ``transmittance(a, b)`` ``distance`` along its ``normal`` by a
    world Monte Carlo at ``points`` ((k, 2) along its axes ``u``, ``w`` from ``origin``, jittered over a ``pixel``):
    cosine-weighted rays (the sky above the world's horizon, ``ground`` below) plus the limb-darkened sun disc.
    Two independent estimates: returns their mean (k, 3) and its relative noise from their difference [1]."""
    sun = sky.sun_direction
    r = SUN_ANGULAR_RADIUS
    centre_radiance = sky.sun_normal_irradiance / (np.pi * r**2 * (1 - np.asarray(LIMB_DARKENING) / 3))
    ref_right = np.cross(sun, [0, 0, 1.0])
    ref_right /= np.linalg.norm(ref_right)

    def estimate(a, b):
        rays = cosine_rays(normal, 128 * 128, rng)
        jitter = rng.uniform(-0.5, 0.5, (len(rays), 2)) * pixel
        start = origin + (a + jitter[:, :1]) * u + (b + jitter[:, 1:]) * w
        hit = start + rays * (distance / (rays @ normal))[:, None] - origin
        through = transmittance(hit @ u, hit @ w)
        up = rays[:, 2] > 0
        radiance = np.tile(ground, (len(rays), 1))
        z = np.maximum(rays[up, 2], 1e-3)
        radiance[up] = sky.radiance(rays[up, :2] / z[:, None])
        e = np.pi * (radiance * through[:, None]).mean(axis=0)
        dirs, omega = disc_directions(sun, ref_right, np.cross(ref_right, sun), r * 1.02, n=60, rng=rng)
        o = origin + (a + jitter[: len(dirs), :1]) * u + (b + jitter[: len(dirs), 1:]) * w
        hit = o + dirs * (distance / (dirs @ normal))[:, None] - origin
        weight = transmittance(hit @ u, hit @ w) * (dirs @ normal) * omega
        profile = limb_darkened_profile(np.arccos(np.clip(dirs @ sun, -1, 1)), r, LIMB_DARKENING)
        return e + (weight[:, None] * profile * centre_radiance).sum(axis=0)

    first, second = (np.array([estimate(a, b) for a, b in points]) for _ in range(2))
    mc = (first + second) / 2
    return mc, np.sqrt(np.mean((first - second) ** 2)) / 2 / np.mean(mc)


def pinhole_spot_moments(hole_points, *, height, directions, weights):
    """Weighted mean (2,) and covariance (2, 2) [m, m^2] of the light spot a canopy hole throws
    on the ground: light arriving along direction w through hole point p lands at
    x = p - height * (wx, wy) / wz, with weight L(w) cos(theta) d_omega (the irradiance E(x)
    integrates to exactly this: E(x) dx = sum over w of L cos d_omega over the hole's area).

    hole_points : (m, 2) points spread evenly over the hole [m] (the hole's own spread enters
        the covariance); directions : (k, 3); weights : (k,) L cos(theta) d_omega.
    """
    shift = height * directions[:, :2] / directions[:, 2:3]
    w = np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    mean_shift = w @ shift
    cov_shift = (shift - mean_shift).T @ ((shift - mean_shift) * w[:, None])
    hole = np.asarray(hole_points, dtype=np.float64)
    mean_hole = hole.mean(axis=0)
    cov_hole = np.cov(hole.T, bias=True)
    return mean_hole - mean_shift, cov_hole + cov_shift


def pinhole_irradiance(points, *, height, hole_points, hole_area, radiance):
    """Irradiance [radiance x sr] at ground points (n, 2) [m] of light through a small canopy hole,
    by integrating over the hole: a hole element dA at p seen from x subtends
    d_omega = cos^3(theta) dA / height^2, so E(x) = sum L(w) cos^4(theta) dA / height^2 with
    w the unit vector from x to (p, height).

    hole_points : (m, 2) points spread evenly over the hole [m]; hole_area [m^2];
    radiance : L(w (..., 3)) -> (..., channels).
    """
    points = np.asarray(points, dtype=np.float64)
    hole = np.asarray(hole_points, dtype=np.float64)
    out = []
    for lo in range(0, len(points), 64):  # bounded memory
        d = hole[None, :, :] - points[lo : lo + 64, None, :]
        v = np.concatenate([d, np.full((*d.shape[:2], 1), float(height))], axis=-1)
        norm = np.linalg.norm(v, axis=-1)
        w = v / norm[..., None]
        cos4 = w[..., 2] ** 4
        out.append((radiance(w) * cos4[..., None]).sum(axis=1) * hole_area / len(hole) / height**2)
    return np.concatenate(out)


def monte_carlo_sun(points, *, height, transmittance, radiance, sun_direction, right, up, radius,
                    n, rng):
    """Direct-sun irradiance [radiance x sr] at ground points by sampling the sun's disc.

    points : (k, 2) or (k, rays, 2) world x, y [m]: per-ray positions (jittered over pixels)
        with ``rays`` = the number of directions inside the disc for this n.
    The disc of angular ``radius`` (a little beyond the sun's, so the moon's and sun's limbs are
    inside) is sampled stratified on the tangent plane, n x n jittered cells, independently per
    point; each direction w is traced from the ground point to the canopy plane at ``height``
    (x + height (wx, wy) / wz) and weighted by radiance(w) cos(theta) d_omega times the canopy's
    ``transmittance`` there. E = sum of the weights.
    """
    points = np.asarray(points, dtype=np.float64)
    out = []
    for i in range(points.shape[0]):
        w, d_omega = disc_directions(sun_direction, right, up, radius, n=n, rng=rng)
        x = points[i] if points.ndim == 2 else points[i, : len(w)]
        if points.ndim == 3 and points.shape[1] < len(w):
            raise ValueError("fewer per-ray positions than directions")
        tx = x[..., 0] + height * w[:, 0] / w[:, 2]
        ty = x[..., 1] + height * w[:, 1] / w[:, 2]
        weight = transmittance(tx, ty) * w[:, 2] * d_omega
        out.append(weight @ radiance(w))
    return np.array(out)


def aerial_perspective(distance: np.ndarray, view: np.ndarray, *, length: float, sun_direction,
                       sun_irradiance, sky_irradiance, albedo: float = 0.9, g: float = 0.6):
    """A homogeneous haze between the camera and the ground (single scattering, no shadows).

    The ground seen through it is T B + sky haze, and the sun-lit haze is the paper's atmosphere,
    added times S (``composite_frame``). Sky light is taken as scattered evenly: radiance
    albedo E_sky / (2 pi) per unit of optical depth.

    Parameters
    ----------
    distance : numpy.ndarray
        (rows, cols) distance to the ground, inf where the sky is seen (the sky model already holds
        its haze) [m].
    view : numpy.ndarray
        (rows, cols, 3) unit directions from the camera [1].
    length : float
        Extinction length, so a thing at distance d keeps exp(-d / length) of its radiance [m].
    sun_direction : array_like
        (3,) unit vector towards the sun [1].
    sun_irradiance : array_like
        (3,) normal irradiance of the clear sun [klx].
    sky_irradiance : array_like
        (3,) horizontal irradiance of the clear sky [klx].
    albedo : float, optional
        Single-scattering albedo of the haze [1].
    g : float, optional
        Its Henyey-Greenstein asymmetry [1].

    Returns
    -------
    transmittance : numpy.ndarray
        (rows, cols) float32 T [1].
    sky_haze : numpy.ndarray
        (rows, cols, 3) float32 sky-lit haze [kcd/m^2].
    sun_haze : numpy.ndarray
        (rows, cols, 3) float32 sun-lit haze [kcd/m^2].
    """
    transmittance = haze_transmittance(distance, length).astype(np.float64)
    veil = (1.0 - transmittance)[..., None]
    phase = henyey_greenstein(np.asarray(view, dtype=np.float64) @ np.asarray(sun_direction), g)
    sun_haze = veil * (albedo * phase)[..., None] * np.asarray(sun_irradiance)
    sky_haze = veil * (albedo / (2.0 * np.pi)) * np.asarray(sky_irradiance)
    return (transmittance.astype(np.float32), sky_haze.astype(np.float32), sun_haze.astype(np.float32))


# ---------------------------------------------------------------------------------------------
# The compiled loops' numpy references (pipeline/kernels): the tests hold each loop to its
# reference bit for bit, the same float32 operations in the same order.


def lattice_read_arrays(flat, corner, taps, lattice):
    """``kernels.arrays.lattice_read`` with whole arrays (numpy): its reference, ``brdf_bands.sky_ratio``'s
    bilinear read of its lattice. (channels, n) float32"""
    out = flat[:, corner] * taps[0]
    out += flat[:, corner + 1] * taps[1]
    out += flat[:, corner + lattice] * taps[2]
    out += flat[:, corner + lattice + 1] * taps[3]
    return out


def row_footprints_arrays(camera: Camera, rows: np.ndarray, part: np.ndarray) -> tuple[np.ndarray, ...]:
    """``pinhole._row_footprints`` with whole arrays (numpy), the reference of its compiled loop
    (``kernels.filter.row_footprints``): x, y [m], major, minor [m], ex, ey [1], each (r width,)
    float64, and the distances [m] float32, of the pixels of image rows that see ground."""
    hits = row_hits(camera, rows, part)
    x, y, dxdu, dxdv, dydu, dydv, distance = (u.ravel() for u in (
        hits.x, hits.y, hits.dxdu, hits.dxdv, hits.dydu, hits.dydv, hits.distance))
    return (x, y, *footprint_axes(dxdu, dxdv, dydu, dydv), distance.astype(np.float32))


def constant_levels(a: np.ndarray, value: np.ndarray) -> list[np.ndarray]:
    """Levels of a raster (rows, cols, channels) float32 on a plane of ``value``: pad to even sizes
    with the value, average 2 x 2 (``pair_mean``); the reference of ``mipmap.mipmap`` with
    ``outside="constant"`` (its compiled step ``kernels.filter.halve_level``)."""
    levels = [a]
    while max(a.shape[:2]) > 1:
        rows, cols = a.shape[:2]
        if rows % 2 or cols % 2:
            padded = np.empty((rows + rows % 2, cols + cols % 2, a.shape[2]), dtype=np.float32)
            padded[...] = value
            padded[:rows, :cols] = a
            a = padded
        a = pair_mean(pair_mean(a, 0), 1)
        levels.append(a)
    return levels


_CHUNK = 16384
"""Footprints filtered together: the working arrays of one tap stay in the processor's cache."""


_BLOCK = 32768
"""Footprints a block in the per-footprint steps (``_in_blocks``)."""


def _in_blocks(function, *arrays, size: int):
    """``function(*arrays)`` for a function that works item by item along the arrays' first
    axis and returns a tuple of arrays: applied to blocks of ``size`` items and the results
    joined, so that its temporaries stay small (in the processor's cache, and no fresh pages)."""
    starts = range(0, max(len(arrays[0]), 1), size)  # one empty block for empty arrays
    parts = [function(*(a[i : i + size] for a in arrays)) for i in starts]
    return tuple(np.concatenate(results) for results in zip(*parts))


def filtered_arrays(mip: MipMap, fp: Footprints, lod_bias: float) -> np.ndarray:
    """``mipmap.filtered_read`` with whole arrays (numpy), the reference of the compiled loops.

    The footprints are grouped by level (and whether they blend two) and sorted by tap count
    within a group; each run of up to _CHUNK footprints of a group is filtered at once, tap by
    tap (``_tap_mean``). Footprints that read only the outside value ("constant") form a group
    of their own, which needs no samples.
    """
    n = len(fp)
    if n == 0:
        return np.zeros((mip.channels, 0), dtype=np.float32)
    taps, level, blend = _in_blocks(functools.partial(filter_choice_arrays, mip, lod_bias), fp.major, fp.minor,
                                    size=_BLOCK)
    group = 2 * level + (blend > 0)
    if mip.outside == "constant":
        beyond, = _in_blocks(lambda *arrays: (_beyond(mip, *arrays),), fp.x, fp.y, fp.major, fp.ex, fp.ey,
                             taps, level + (blend > 0), size=_BLOCK)
        group[beyond] = _BEYOND
    key = group * (MAX_TAPS + 1) + (MAX_TAPS - taps)  # int16: under 64 levels of 17 tap counts
    order = np.argsort(key, kind="stable")  # a radix sort
    group, taps = group.take(order), taps.take(order)
    starts = np.flatnonzero(np.diff(group, prepend=group[0] - 1))
    mean = np.empty((mip.channels, n), dtype=np.float32)
    for a, b in zip(starts, np.append(starts[1:], n)):
        if group[a] == _BEYOND:
            mean[:, a:b] = _outside_means(mip).take(taps[a:b], axis=1)
            continue
        k, blended = divmod(int(group[a]), 2)
        for c in range(a, b, _CHUNK):
            s = slice(c, min(c + _CHUNK, b))
            chosen = order[s]
            t = blend.take(chosen) if blended else None
            x, y, major, ex, ey = (u.take(chosen) for u in (fp.x, fp.y, fp.major, fp.ex, fp.ey))
            mean[:, s] = _tap_mean(mip, k, t, x, y, major, ex, ey, taps[s])
    inverse = np.empty_like(order)
    inverse[order] = np.arange(n)
    return mean.take(inverse, axis=1)


_BEYOND = -1
"""The group of the footprints that read only the outside value (``_beyond``)."""


def _beyond(mip: MipMap, x, y, major, ex, ey, taps, level) -> np.ndarray:
    """Whether each footprint (n,) bool (``Footprints``' fields x, y, major, ex, ey) of ``taps``
    taps has them all beyond one edge of the raster in its coarsest level read, ``level`` (n,)
    int, by half a texel more than the border: every trilinear sample of it reads the outside
    value alone (in the finer level too, whose texels are smaller and whose border is nearer).
    Mode "constant"."""
    (x0, y0), (rows, cols) = mip.origins[0], np.asarray(mip.shapes, dtype=np.float64).T
    px, py = np.asarray(mip.pixels, dtype=np.float64).T
    # the edges [m] a tap must lie beyond, level by level: a texel out from the raster
    west, east = (x0 - px).take(level), (x0 + (cols + 1) * px).take(level)
    north, south = (y0 + py).take(level), (y0 - (rows + 1) * py).take(level)
    reach = (0.5 - 0.5 / taps) * major  # from the centre to the farthest tap [m]
    across, along = np.abs(reach * ex), np.abs(reach * ey)
    with np.errstate(invalid="ignore"):
        return (x + across <= west) | (x - across >= east) | (y - along >= north) | (y + along <= south)


def _outside_means(mip: MipMap) -> np.ndarray:
    """(channels, MAX_TAPS + 1) float32: column n is what ``_tap_mean`` makes of n samples of
    the outside value: their float32 sum, in order, over n (column 0 unused)."""
    table = np.zeros((mip.channels, MAX_TAPS + 1), dtype=np.float32)
    total = np.zeros(mip.channels, dtype=np.float32)
    for n in range(1, MAX_TAPS + 1):
        total += mip.value
        table[:, n] = total / np.float32(n)
    return table


def filter_choice_arrays(mip: MipMap, lod_bias: float, major, minor):
    """``mipmap.filter_choice`` with whole arrays (numpy), the reference of the compiled loop."""
    texel = float(np.sqrt(mip.pixels[0][0] * mip.pixels[0][1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.nan_to_num(major / np.maximum(minor, texel), nan=1.0, posinf=MAX_TAPS, copy=False)
        ratio -= 1e-3
        np.ceil(ratio, out=ratio)
        taps = np.clip(ratio, 1, MAX_TAPS, out=ratio).astype(np.int8)
        lod = major / taps
        np.maximum(minor, lod, out=lod)
        lod /= texel
        np.log2(lod, out=lod)
        lod += lod_bias
    lod = np.clip(np.nan_to_num(lod, nan=0.0, copy=False), 0.0, mip.count - 1, out=lod)
    floor = np.floor(lod)
    k = floor.astype(np.int16)
    t = np.subtract(lod, floor, out=lod)
    done = t > 1.0 - 1e-6  # all in the next level
    k[done] += 1
    t[done | (t < 1e-6)] = 0.0
    return taps, k, t.astype(np.float32)


def _tap_mean(mip: MipMap, level: int, t, x, y, major, ex, ey, taps) -> np.ndarray:
    """Means (channels, m) float32 over each footprint's taps of its trilinear samples.

    level : the finer level read; t : (m,) float32 blend towards level + 1, or None for level
        alone. [level, 1]
    x, y, major, ex, ey : (m,) the footprints' ellipses (``Footprints``). [m, m, 1]
    taps : (m,) tap counts, in decreasing order.
    The taps of footprint j lie at (x, y) + ((i + 0.5) / taps - 0.5) major (ex, ey), i < taps[j].
    """
    spacing = major / taps  # [m]
    first = (0.5 - 0.5 * taps) * spacing  # the first tap's offset along the major axis [m]
    start = (x + first * ex, y + first * ey, spacing * ex, spacing * ey)  # the first tap, the step [m]
    finer = _texel_coords(mip, level, *start)
    coarser = None if t is None else _texel_coords(mip, level + 1, *start)
    descending = -taps
    for i in range(int(taps[0])):
        m = int(np.searchsorted(descending, -i, side="left"))  # footprints with more than i taps
        col, row, dcol, drow = (u[:m] for u in finer)
        sample = _bilinear(mip, level, col, row)
        col += dcol
        row += drow
        if coarser is not None:
            col, row, dcol, drow = (u[:m] for u in coarser)
            upper = _bilinear(mip, level + 1, col, row)
            col += dcol
            row += drow
            upper -= sample
            upper *= t[:m]
            sample += upper
        if i == 0:
            total = sample
        else:
            total[:, :m] += sample
    total /= taps.astype(np.float32)
    return total


def _texel_coords(mip: MipMap, level: int, x, y, dx, dy):
    """(col, row) [texel] in level ``level`` of ground points (x, y) [m], texel centres at whole
    numbers, and (dcol, drow) [texel] of ground steps (dx, dy) [m]; new arrays."""
    (x0, y0), (px, py) = mip.origins[level], mip.pixels[level]
    col = (x - x0) * (1.0 / px) - 0.5
    row = (y0 - y) * (1.0 / py) - 0.5
    dcol, drow = dx * (1.0 / px), dy * (-1.0 / py)
    # held where a float has no fraction left, so that no tap's texel overflows an integer
    for u, limit in ((col, 2.0**52), (row, 2.0**52), (dcol, 2.0**48), (drow, 2.0**48)):
        np.clip(u, -limit, limit, out=u)
    return col, row, dcol, drow


def _bilinear(mip: MipMap, level: int, col, row) -> np.ndarray:
    """Bilinear samples (channels, m) float32 of one level at texel coordinates (col, row) (m,)
    [texel] (``_texel_coords``), the plane beyond the raster as ``mip.outside`` says. The four
    texels of a sample lie at fixed offsets from the first (``_first_texel``) and are gathered
    in one ``take``."""
    first, fc, fr = _first_texel(mip, level, col, row)
    flat = mip.texels.reshape(-1)
    gathered = np.empty((4, mip.channels, len(first)), dtype=np.float32)
    offsets = _corner_offsets(mip.shapes[level][1] + 2, mip.channels)
    for offset, out in zip(offsets, gathered.reshape(-1, len(first))):
        flat[offset:].take(first, out=out, mode="clip")  # no index array of all the corners
    a, b, c, d = gathered  # each (channels, m)
    b -= a  # the upper row, along the columns
    b *= fc
    a += b
    d -= c  # the lower row
    d *= fc
    c += d
    c -= a  # along the rows
    c *= fr
    a += c
    return a


def _first_texel(mip: MipMap, level: int, col, row):
    """The first of the four texels of bilinear samples at texel coordinates (col, row) (m,)
    [texel], the one at (floor(row), floor(col)): the index (m,) intp of its channel 0 in the
    flat texel array, and the fractions (fc, fr) (m,) float32 of (col, row) beyond it [texel].

    The texel is brought into the stored level, border included: held at the border of the
    outside value ("constant"), or moved by whole periods ("periodic")."""
    rows, cols = mip.shapes[level]
    if mip.outside == "constant":
        col, row = np.clip(col, -1.0, cols), np.clip(row, -1.0, rows)
    c0, r0 = np.floor(col), np.floor(row)
    fc = np.empty(len(col), dtype=np.float32)
    fr = np.empty(len(row), dtype=np.float32)
    np.subtract(col, c0, out=fc)
    np.subtract(row, r0, out=fr)
    c0, r0 = c0.astype(np.intp), r0.astype(np.intp)
    if mip.outside == "periodic":
        _wrap(c0, cols)
        _wrap(r0, rows)
    r0 *= cols + 2  # stored rows, one texel of border all round
    r0 += c0
    r0 += mip.offsets[level] + cols + 3
    r0 *= mip.channels
    return r0, fc, fr


@functools.lru_cache(maxsize=256)
def _corner_offsets(stride: int, channels: int) -> tuple:
    """Offsets in the flat texel array of the four texels of a bilinear sample, (r0, c0),
    (r0, c0 + 1), (r0 + 1, c0), (r0 + 1, c0 + 1), channel by channel, from channel 0 of the
    first: 4 channels ints; ``stride`` the stored texels a row."""
    return tuple(texel * channels + k for texel in (0, 1, stride, stride + 1) for k in range(channels))


def _wrap(i: np.ndarray, n: int) -> None:
    """i modulo n, in place (n > 0); a mask when n is a power of two."""
    if n & (n - 1):
        np.remainder(i, n, out=i)
    else:
        np.bitwise_and(i, n - 1, out=i)


def tiling_sample_arrays(tiling: StochasticTiling, fp: Footprints, *, lod_bias: float,
                         skip: float = 0.0) -> np.ndarray:
    """``albedo.StochasticTiling.sample`` with whole arrays (numpy): the reference of the compiled pass.

    Parameters
    ----------
    tiling : albedo.StochasticTiling
        The tiling.
    fp, lod_bias
        As for ``sample``.
    skip : float, optional
        Reads of sharpened weight under this are left out [1].

    Returns
    -------
    numpy.ndarray
        (channels, n) float32 albedo [1].
    """
    vertices, w = tiling.weights(fp.x, fp.y)
    w = w**BLEND_SHARPNESS
    w /= w.sum(axis=0)
    offset = tiling.offsets(vertices)
    g = np.zeros((tiling.channels, len(fp)), dtype=np.float64)
    for i in range(3):
        moved = Footprints(fp.x + offset[i, :, 0], fp.y + offset[i, :, 1], fp.major, fp.minor,
                                   fp.ex, fp.ey)
        g += np.where(w[i] < skip, 0.0, w[i]) * filtered_arrays(tiling.gaussian, moved, lod_bias)
    g /= np.sqrt(np.sum(w * w, axis=0))
    _, level, blend = filter_choice_arrays(tiling.gaussian, lod_bias, fp.major, fp.minor)
    level = level.astype(np.intp)
    upper = np.minimum(level + 1, tiling.gaussian.count - 1)
    position = np.clip((g + 4.0) * (LOOKUP_BINS / 8.0) - 0.5, 0.0, LOOKUP_BINS - 1.0)
    low = np.minimum(np.floor(position).astype(np.intp), LOOKUP_BINS - 2)
    frac = position - low
    components = np.empty_like(g)
    for c in range(tiling.channels):
        def lookup(k):
            table = tiling.lookups[:, c]
            return table[k, low[c]] * (1.0 - frac[c]) + table[k, low[c] + 1] * frac[c]
        components[c] = lookup(level) * (1.0 - blend) + lookup(upper) * blend
    out = tiling.center[:, None] + _times(components.T, tiling.basis.T).T
    return np.clip(out, 0.0, None).astype(np.float32)


def _times(rows, matrix):
    """``albedo._times``: rows (n, c) @ matrix (c, c), summed column by column."""
    out = np.zeros((rows.shape[0], matrix.shape[1]))
    for i in range(matrix.shape[0]):
        out += rows[:, i : i + 1] * matrix[i]
    return out
