"""The two-scale sun (docs/method.md, "Two scales for the sun"), validated end to end in world coordinates.

Every test renders through ``stages.ground.render_ground`` from a YAML config and a mask image, and
compares with references in ``tests/reference.py`` that trace light in metres and radians (no
rasters, kernels or FFTs): the pinhole image of the sun (an ellipse, The Physics Teacher 61, 716
(2023)), the crescents of an eclipse, the sun fraction over frames, and energy.

The spot a hole throws is isolated from the sky's light by rendering twice, with the hole and
with the same canopy solid, and subtracting: what is left is the light through the hole (the sky
through a 1 cm hole adds about 1e-5 of the spot's power).
"""

from __future__ import annotations

import numpy as np
import pytest
from reference import (
    angle_between,
    disc_directions,
    image_transmittance,
    limb_darkened_profile,
    monte_carlo_irradiance,
    monte_carlo_sun,
    offset_direction,
    pinhole_irradiance,
    pinhole_spot_moments,
    sun_radiance_function,
    tangent_frame,
)
from scenes import config_of

from pipeline.cache import store as cache
from pipeline.core import io
from pipeline.sky import ephemeris
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import LIMB_DARKENING, SunDisc
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.ground import render_ground
from pipeline.stages.plan import plan_run
from pipeline.stages.scene import load_sky, scene_at

HEIGHT = 8.0
"""Canopy height of every case. [m]"""
HOLE_IMAGE = (400, 1.0)
"""The pinhole canopy: a 400 x 400 image over 1 m x 1 m centred on (0, 0) (2.5 mm texels)."""
HOLE_TEXELS = slice(198, 202)
"""The hole: 4 x 4 texels, the square |x|, |y| <= 5 mm (h a_sun = 74 mm: a pinhole)."""
HOLE_SIDE = 0.01


# --- helpers ---------------------------------------------------------------------------------


def write_masks(folder):
    """hole.png (one 1 cm hole at the origin in an opaque 1 m square) and solid.png (no hole)."""
    n = HOLE_IMAGE[0]
    solid = np.zeros((n, n, 1), np.float32)
    hole = solid.copy()
    hole[HOLE_TEXELS, HOLE_TEXELS] = 1.0
    io.write_png(folder / "hole.png", hole)
    io.write_png(folder / "solid.png", solid)


def hole_points(n=24):
    """Points spread evenly over the hole (n x n cell centres). [m]"""
    u = ((np.arange(n) + 0.5) / n - 0.5) * HOLE_SIDE
    return np.stack(np.meshgrid(u, u), axis=-1).reshape(-1, 2)


def sun_point(elevation_deg, azimuth_deg):
    """Sky-plane point (2,) of the sun's centre, from the angles alone. [tan]"""
    zenith, azimuth = np.radians(90.0 - elevation_deg), np.radians(azimuth_deg)
    return np.tan(zenith) * np.array([np.sin(azimuth), np.cos(azimuth)])


def pinhole_config(folder, mask, *, elevation, azimuth, moon=None, frames=1, half=0.15,
                   name="case"):
    """A config: the 1 m pinhole canopy at HEIGHT, the procedural sun, the window (coarse and
    fine) a square of side 2 ``half`` [m] centred where the sun's centre shines through the hole."""
    cx, cy = -HEIGHT * sun_point(elevation, azimuth)
    sky = {"model": "procedural", "turbidity": 3,
           "sun": {"elevation": elevation, "azimuth": azimuth}}
    if moon is not None:
        sky["moon"] = {"offset_start": list(moon[0]), "offset_end": list(moon[1])}
    config = {
        "canopy": {"mask": mask, "size": [HOLE_IMAGE[1]] * 2, "center": [0, 0], "height": HEIGHT},
        "sky": sky,
        "ground": {"window": [float(cx - half), float(cy - half), float(cx + half), float(cy + half)],
                   "pixel": 0.05},
        "animation": {"frames": frames},
    }
    return config_of(config, folder)


def spot(folder, store, **case):
    """The light through the hole (rows, cols, 3) at every frame, its ground Grid and the
    hole config. [klx]"""
    lit = pinhole_config(folder, "hole.png", **case)
    dark = pinhole_config(folder, "solid.png", **case)
    plans = plan_run(lit), plan_run(dark)
    frames = []
    for frame in range(lit.animation.frames):
        a = render_ground(plans[0], frame, store=store)
        b = render_ground(plans[1], frame, store=store)
        assert a.grid == b.grid
        frames.append(a.irradiance.astype(np.float64) - b.irradiance.astype(np.float64))
    return np.stack(frames), a.grid, lit


def centres(grid):
    """World x, y [m] of every pixel centre of a ground grid (rows, cols)."""
    rows, cols = np.indices(grid.shape)
    return grid.ground_from_raster(rows, cols)


def moments(g, x, y):
    """Weighted mean (2,) and covariance (2, 2) of a non-negative raster. [m, m^2]"""
    total = g.sum()
    mean = np.array([(g * x).sum(), (g * y).sum()]) / total
    dx, dy = x - mean[0], y - mean[1]
    cov = np.array([[(g * dx * dx).sum(), (g * dx * dy).sum()],
                    [(g * dx * dy).sum(), (g * dy * dy).sum()]]) / total
    return mean, cov


def limb_darkened_k(u, n=20000):
    """<x^2> / r^2 over a disc of radius r under the linear limb-darkening law: 1/4 for a
    uniform disc. (1/2) int I rho^3 / int I rho, by the midpoint rule. [1]"""
    rho = (np.arange(n) + 0.5) / n
    intensity = 1.0 - u * (1.0 - np.sqrt(1.0 - rho**2))
    return 0.5 * (intensity * rho**3).sum() / (intensity * rho).sum()


@pytest.fixture
def store(tmp_path):
    write_masks(tmp_path)
    return cache.Cache(tmp_path / "cache")


# --- 1. the pinhole ellipse ------------------------------------------------------------------


@pytest.mark.parametrize("elevation,azimuth", [(35.0, 120.0), (60.0, 250.0)])
def test_pinhole_image_of_the_sun_is_the_expected_ellipse(tmp_path, store, elevation, azimuth):
    """A hole much smaller than h a_sun throws an ellipse of minor axis h a_sun / sin(beta), axis
    ratio sin(beta), long axis along the sun's azimuth, centred at hole - h s_sun.

    Second moments per channel against (a) a world-coordinate integral over the limb-darkened
    disc and the hole (``pinhole_spot_moments``): 1% (pixel 4.7 mm against a spot sigma of 21 mm
    or more: the kernel's and mask's cells add about p^2/6 to the variance, 0.4%); (b) the
    closed form to first order in the sun's radius, with the second moment of a limb-darkened disc
    and the hole's own w^2/12: 2%. Centre: 0.1 pixel; axis direction: 1 degree.
    """
    g, grid, config = spot(tmp_path, store, elevation=elevation, azimuth=azimuth)
    g = g[0]
    x, y = centres(grid)
    sun = config.sky.sun
    assert sun.radius == pytest.approx(np.radians(0.2666))
    beta = sun.elevation
    centre, right, up = tangent_frame(sun.azimuth, beta)
    directions, d_omega = disc_directions(centre, right, up, sun.radius, n=400)
    along = np.array([np.sin(sun.azimuth), np.cos(sun.azimuth)])
    expected_centre = -HEIGHT * sun_point(elevation, azimuth)  # the hole is at the origin
    for channel, u in enumerate(LIMB_DARKENING):
        mean, cov = moments(g[..., channel], x, y)
        assert np.hypot(*(mean - expected_centre)) < 0.1 * grid.pixel
        # (a) against the world-coordinate moments of the disc through the hole
        radiance = limb_darkened_profile(angle_between(directions, centre), sun.radius, [u])[:, 0]
        ref_mean, ref_cov = pinhole_spot_moments(hole_points(), height=HEIGHT, directions=directions,
                                                 weights=radiance * directions[:, 2] * d_omega)
        assert np.hypot(*(mean - ref_mean)) < 0.1 * grid.pixel
        values, vectors = np.linalg.eigh(cov)
        ref_values = np.linalg.eigvalsh(ref_cov)
        np.testing.assert_allclose(np.sqrt(values), np.sqrt(ref_values), rtol=0.01)
        # the long axis lies along the sun's azimuth
        assert abs(vectors[:, 1] @ along) > np.cos(np.radians(1.0))
        # (b) the closed form: axes h a / sin(beta) and h a / sin(beta)^2 of the disc's image
        k = limb_darkened_k(u)
        hole_var = HOLE_SIDE**2 / 12
        minor, major = 2 * np.sqrt((values - hole_var) / k)  # equivalent full axes [m]
        a_sun = 2 * sun.radius
        assert minor == pytest.approx(HEIGHT * a_sun / np.sin(beta), rel=0.02)
        assert minor / major == pytest.approx(np.sin(beta), rel=0.02)


# --- 2. crescents ----------------------------------------------------------------------------


def test_eclipse_crescent_through_a_pinhole_matches_a_world_coordinate_estimator(tmp_path, store):
    """The moon 0.15 degrees to the right of the sun (facing it): the pinhole inverts the image, so
    the crescent's light lies to the observer's right on the ground, along +e_right = (cos A,
    -sin A). Compared with a brute-force integral over the hole of the limb-darkened, moon-cut
    sun (``pinhole_irradiance``, at the pixel centres): offset direction 5 degrees, lit power
    fraction 1%, lit area fraction (above 30% of the full spot's peak) 5% of 1 - obscured_fraction
    and 3% of the estimator's, normalized pixelwise shape error 6% (measured 2.5%: the estimator
    samples points, the pipeline averages over cells), absolute power 1%."""
    elevation, azimuth, dx = 35.0, 120.0, 0.15
    full, grid, config = spot(tmp_path, store, elevation=elevation, azimuth=azimuth, name="full")
    eclipse, grid_e, config_e = spot(tmp_path, store, elevation=elevation, azimuth=azimuth,
                                     moon=((dx, 0.0), (dx, 0.0)), name="eclipse")
    assert grid == grid_e
    full, eclipse = full[0], eclipse[0]
    x, y = centres(grid)
    sun = config.sky.sun
    centre, right, _up = tangent_frame(sun.azimuth, sun.elevation)
    moon_radius = config_e.sky.moon.radius
    moon = offset_direction(sun.azimuth, sun.elevation, np.radians(dx), 0.0)
    # the light source: the pipeline's sun radiance value, geometry of our own
    sky = ProceduralSky(3.0, SunDisc(sun.azimuth, sun.elevation, sun.radius))
    u = np.array(LIMB_DARKENING)
    centre_radiance = sky.sun_normal_irradiance / (np.pi * sun.radius**2 * (1 - u / 3))
    points = np.stack([x.ravel(), y.ravel()], axis=1)
    brute, brute_full = (
        pinhole_irradiance(points, height=HEIGHT, hole_points=hole_points(), hole_area=HOLE_SIDE**2,
                           radiance=sun_radiance_function(centre, sun.radius, centre_radiance, u, *m))
        .reshape((*grid.shape, 3))
        for m in ((moon, moon_radius), ()))
    separation = angle_between(moon, centre)
    lit_area = 1.0 - ephemeris.obscured_fraction(separation, sun.radius, moon_radius)
    for channel in range(3):
        e, f = eclipse[..., channel], full[..., channel]
        b, bf = brute[..., channel], brute_full[..., channel]
        offset = moments(e, x, y)[0] - moments(f, x, y)[0]
        ref_offset = moments(b, x, y)[0] - moments(bf, x, y)[0]
        assert np.hypot(*offset) > 2 * grid.pixel  # a crescent, well off the full spot's centre
        for want in (ref_offset, right[:2]):
            cos = offset @ want / np.hypot(*offset) / np.hypot(*want)
            assert cos > np.cos(np.radians(5.0))
        assert e.sum() / f.sum() == pytest.approx(b.sum() / bf.sum(), rel=0.01)
        area = (e > 0.3 * f.max()).sum() / (f > 0.3 * f.max()).sum()
        ref_area = (b > 0.3 * bf.max()).sum() / (bf > 0.3 * bf.max()).sum()
        assert area == pytest.approx(lit_area, rel=0.05)
        assert area == pytest.approx(ref_area, rel=0.03)
        shape = np.linalg.norm(e / e.sum() - b / b.sum()) / np.linalg.norm(b / b.sum())
        assert shape < 0.06
        # absolute: power through the hole [klx m^2], the same pixel area on both sides
        assert e.sum() == pytest.approx(b.sum(), rel=0.01)


# --- 3. over frames --------------------------------------------------------------------------


def test_sun_fraction_follows_the_moon_frame_by_frame(tmp_path, store):
    """The moon slides from beside the sun to 0.05 degrees above its centre over 7 frames: the
    power through the pinhole, over the uneclipsed power, falls strictly frame by frame and equals
    the limb-weighted visible fraction of the disc (a direction-grid integral, 2e-3) and, in
    luminance, ``sun_fraction()`` of the frame's sky."""
    case = dict(elevation=50.0, azimuth=160.0, half=0.12)
    frames = 7
    g, _grid, config = spot(tmp_path, store, moon=((-0.6, 0.05), (0.0, 0.05)), frames=frames,
                           name="slide", **case)
    full, _, _ = spot(tmp_path, store, name="clear", **case)
    measured = g.sum(axis=(1, 2)) / full[0].sum(axis=(0, 1))  # (frames, 3)
    sun = config.sky.sun
    centre, right, up = tangent_frame(sun.azimuth, sun.elevation)
    directions, d_omega = disc_directions(centre, right, up, sun.radius, n=600)
    profile = limb_darkened_profile(angle_between(directions, centre), sun.radius, LIMB_DARKENING)
    weight = profile * (directions[:, 2] * d_omega)[:, None]
    for frame in range(frames):
        dx = -0.6 + 0.6 * frame / (frames - 1)
        moon = offset_direction(sun.azimuth, sun.elevation, np.radians(dx), np.radians(0.05))
        visible = angle_between(directions, moon) > config.sky.moon.radius
        expected = weight[visible].sum(axis=0) / weight.sum(axis=0)
        np.testing.assert_allclose(measured[frame], expected, atol=2e-3)
        sky = load_sky(config.sky, scene_at(config, frame))
        luminance = measured[frame] @ (sky.sun_normal_irradiance * [0.2126, 0.7152, 0.0722])
        luminance /= sky.sun_normal_irradiance @ [0.2126, 0.7152, 0.0722]
        assert luminance == pytest.approx(sky.sun_fraction(), abs=2e-3)
    assert measured[0] == pytest.approx(np.ones(3), abs=1e-3)  # not yet touching
    assert np.all(np.diff(measured, axis=0) < -0.01)  # strictly falling, no frame stuck
    assert measured[-1].max() < 0.1


# --- 4. energy -------------------------------------------------------------------------------


def test_open_canopy_gives_the_unshadowed_irradiance_everywhere(tmp_path, store):
    io.write_png(tmp_path / "open.png", np.ones((40, 40, 1), np.float32))
    config = pinhole_config(tmp_path, "open.png", elevation=40.0, azimuth=75.0, half=0.2,
                            moon=((0.1, -0.1), (0.1, -0.1)))
    result = render_ground(plan_run(config), store=store)
    assert result.grid.pixel < 0.005  # the fine sun window, not the coarse one
    relative = result.irradiance / result.unshadowed.astype(np.float32) - 1.0
    assert np.abs(relative).max() < 1e-4
    # and that is the open sky's quadrature plus the moon-cut disc integrated in directions
    sky = load_sky(config.sky, scene_at(config, 0))
    expected = sky.sky_irradiance + eclipsed_sun_irradiance(config, sky)
    np.testing.assert_allclose(result.unshadowed, expected, rtol=5e-4)


def eclipsed_sun_irradiance(config, sky, n=1000):
    """Horizontal irradiance (3,) of the limb-darkened sun less the moon [klx]: the integral of
    L cos(theta) d_omega over a direction grid on the disc, the pipeline's normal irradiance only
    setting the scale."""
    sun = config.sky.sun
    centre, right, up = tangent_frame(sun.azimuth, sun.elevation)
    u = np.array(LIMB_DARKENING)
    centre_radiance = sky.sun_normal_irradiance / (np.pi * sun.radius**2 * (1 - u / 3))
    moon = ()
    if config.sky.moon is not None:
        dx, dy = config.sky.moon.offset_start
        moon = (offset_direction(sun.azimuth, sun.elevation, dx, dy), config.sky.moon.radius)
    directions, d_omega = disc_directions(centre, right, up, sun.radius, n=n)
    radiance = sun_radiance_function(centre, sun.radius, centre_radiance, u, *moon)(directions)
    return (radiance * (directions[:, 2] * d_omega)[:, None]).sum(axis=0)


def test_sun_irradiance_under_an_eclipse_is_the_horizontal_integral(tmp_path):
    io.write_png(tmp_path / "open.png", np.ones((40, 40, 1), np.float32))
    config = pinhole_config(tmp_path, "open.png", elevation=40.0, azimuth=75.0,
                            moon=((0.0, 0.15), (0.0, 0.15)))
    sky = load_sky(config.sky, scene_at(config, 0))
    np.testing.assert_allclose(sun_irradiance(sky), eclipsed_sun_irradiance(config, sky), rtol=5e-4)


def test_opaque_canopy_stops_the_sun_and_its_edge_casts_the_penumbra(tmp_path, store):
    """A solid 4 m square at 8 m; the sun window straddles the shadow of its east edge. The sky's
    part comes from a world-coordinate Monte Carlo estimate with the pipeline's sky radiance;
    what is left, the sun's part, is 0 in the umbra, the whole sun in the open, and across the
    penumbra the sun disc traced to the canopy plane (``monte_carlo_sun``): all to 0.5% of the
    sun's irradiance."""
    io.write_png(tmp_path / "square.png", np.zeros((80, 80, 1), np.float32))
    elevation, azimuth = 50.0, 200.0
    sx, sy = sun_point(elevation, azimuth)
    edge = float(2.0 - HEIGHT * sx)  # the shadow of x = 2 along the sun's centre
    y0 = float(-HEIGHT * sy)
    config = config_of({
        "canopy": {"mask": "square.png", "size": [4, 4], "center": [0, 0], "height": HEIGHT},
        "sky": {"model": "procedural", "turbidity": 3,
                "sun": {"elevation": elevation, "azimuth": azimuth}},
        "ground": {"window": [edge - 0.4, y0 - 0.1, edge + 0.4, y0 + 0.1], "pixel": 0.05},
        "animation": {"frames": 1},
    }, tmp_path)
    result = render_ground(plan_run(config), store=store)
    grid = result.grid
    row = grid.shape[0] // 2
    cols = np.arange(0, grid.shape[1], 4)
    x, y = grid.ground_from_raster(np.full(len(cols), row), cols)
    points = np.stack([x, y], axis=1)
    sky = load_sky(config.sky, scene_at(config, 0))
    square = image_transmittance(np.zeros((80, 80)), center=(0, 0), size=(4, 4))

    def sky_radiance(az, zen):
        t = np.tan(zen)
        return sky.radiance(np.stack([t * np.sin(az), t * np.cos(az)], axis=-1))

    rng = np.random.default_rng(3)
    sky_part = monte_carlo_irradiance(points, height=HEIGHT, transmittance=square,
                                      radiance=sky_radiance, rays=128 * 128, rng=rng)
    sun = config.sky.sun
    centre, right, up = tangent_frame(sun.azimuth, sun.elevation)
    u = np.array(LIMB_DARKENING)
    centre_radiance = sky.sun_normal_irradiance / (np.pi * sun.radius**2 * (1 - u / 3))
    sun_part = monte_carlo_sun(points, height=HEIGHT, transmittance=square,
                               radiance=sun_radiance_function(centre, sun.radius, centre_radiance, u),
                               sun_direction=centre, right=right, up=up, radius=sun.radius, n=128,
                               rng=rng)
    ours = result.irradiance[row, cols].astype(np.float64) - sky_part
    full = sun_irradiance(sky)
    umbra, open_ = x < edge - 0.1, x > edge + 0.1
    assert umbra.sum() >= 5 and open_.sum() >= 5 and (~umbra & ~open_).sum() >= 5
    assert np.abs(ours[umbra]).max() < 0.005 * full.max()
    np.testing.assert_allclose(ours[open_], np.broadcast_to(full, ours[open_].shape),
                               atol=0.005 * full.max())
    np.testing.assert_allclose(ours, sun_part, atol=0.005 * full.max())
    np.testing.assert_allclose(sun_part[open_], np.broadcast_to(full, sun_part[open_].shape),
                               rtol=2e-3)


@pytest.mark.parametrize("elevation", [2.0, 5.0, 10.0])
def test_pinhole_image_axes_match_traced_rays(elevation):
    """The ellipse a pinhole casts, from its closed form, against the disc's limb rays traced to
    the ground (20,000 of them); at 2 to 10 degrees it is 6 to 30 times longer than wide."""
    from pipeline.core.geometry import direction_vector, pinhole_image_axes, tangent_axes

    h, r, height = np.radians(elevation), np.radians(0.2666), 7.0
    _, e1, e2 = tangent_axes(0.0, h)
    psi = np.linspace(0.0, 2.0 * np.pi, 20001)
    rays = np.cos(r) * direction_vector(0.0, h) + np.sin(r) * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    ground = -height * rays[:, :2] / rays[:, 2:]
    length, width = pinhole_image_axes(height, h, r)
    assert length == pytest.approx(np.ptp(ground[:, 1]), rel=1e-6)
    assert width == pytest.approx(np.ptp(ground[:, 0]), rel=1e-6)
    assert 5.5 < length / width < 30.0


def test_sun_kernel_at_5_degrees_is_the_pinhole_ellipse():
    """The renderer's sun kernel (the pinhole image of a unit height on the sky plane) of a
    uniform disc at 5 degrees: its chords through the ellipse's centre, from each cell's
    coverage (its value over L cos^4(theta) q^2), are the pinhole geometry's axes to 0.2%."""
    from pipeline.core.geometry import pinhole_image_axes
    from pipeline.sky.sun_kernel import sun_kernel

    h, r = np.radians(5.0), np.radians(0.2666)
    sky = ProceduralSky(3.0, SunDisc(0.0, h, r, (0.0, 0.0, 0.0)))
    length, width = pinhole_image_axes(1.0, h, r)
    q = width / 40.0
    kernel = sun_kernel(sky, q)
    rows, cols = kernel.grid.shape
    x, y = kernel.grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
    radiance = sky.sun_normal_irradiance[1] / (np.pi * r * r)
    coverage = kernel.weighted[1] / (radiance * q * q / (1.0 + x * x + y * y) ** 2)
    centre_y = 0.5 * (1.0 / np.tan(h - r) + 1.0 / np.tan(h + r))
    column = int(np.argmin(np.abs(x[0])))
    row = int(np.argmin(np.abs(y[:, 0] - centre_y)))
    assert coverage[:, column].sum() * q == pytest.approx(length, rel=2e-3)
    assert coverage[row].sum() * q == pytest.approx(width, rel=2e-3)


def test_the_disc_samples_are_those_of_the_ramp_and_radiance_everywhere():
    """sun_disc.disc_samples computes the limbs' ramp only near the limbs and the radiance only
    where the cover is above 0: the same bits as the whole expressions at every sample (a sun cut by
    a moon, samples inside, on and beyond both limbs, footprints up to ``widest``, a NaN)."""
    from pipeline.sky.sun_disc import MoonDisc, angle_to, direction_vector, disc_samples, sun_disc_radiance

    rng = np.random.default_rng(12)
    sun = SunDisc(azimuth=2.0, elevation=0.3, angular_radius=0.0047)
    moon = MoonDisc(azimuth=2.0, elevation=0.3 + 0.004, angular_radius=0.0049)
    direction, centre = direction_vector(sun.azimuth, sun.elevation), direction_vector(moon.azimuth, moon.elevation)
    tangent = np.cross(direction, [0.0, 0.0, 1.0])
    tangent /= np.linalg.norm(tangent)
    up = np.cross(tangent, direction)
    a, b = rng.uniform(-0.012, 0.012, (2, 40000))
    w = direction + a[:, None] * tangent + b[:, None] * up
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    w[7] = np.nan
    widest = 4e-4
    spacing = rng.uniform(0.0, widest, len(w))  # each sample's footprint, at most widest

    def footprint(where_from, rho, near=None):
        return spacing if near is None else spacing[near]

    got = disc_samples(w, footprint, widest, sun, direction, np.ones(3), moon)
    rho, rho_m = angle_to(w, direction), angle_to(w, centre)
    cover = np.clip(0.5 - (rho - sun.angular_radius) / spacing, 0.0, 1.0)
    cover *= np.clip(0.5 + (rho_m - moon.angular_radius) / spacing, 0.0, 1.0)
    want = sun_disc_radiance(np.minimum(rho, sun.angular_radius), angular_radius=sun.angular_radius,
                             normal_irradiance=np.ones(3), limb_darkening=sun.limb_darkening) * cover[..., None]
    assert ((cover > 0) & (cover < 1)).sum() > 100 and (cover == 0).sum() > 100 and (cover == 1).sum() > 100
    assert got.tobytes() == want.tobytes()
