import numpy as np
import pytest
from scipy import integrate

from pipeline.core import cores
from pipeline.kernels import arrays as _array_loops
from pipeline.kernels import tiling as _tiling
from pipeline.sky import cloud_noise, clouds
from pipeline.sky.cloud_noise import coverage_knots, fractal_noise
from pipeline.sky.cloud_transfer import (
    delta_eddington_transmittance,
    single_scattering_flux_transmittance,
    two_stream_diffuse_transmittance,
)
from pipeline.sky.clouds import CloudLayer
from pipeline.texture.albedo import SECOND_KEY, unit_hash, vertex_keys

SUN = np.array([80.0, 78.0, 75.0])  # normal irradiance above the cloud [klx]
SKY = np.array([14.0, 17.0, 22.0])  # clear-sky horizontal irradiance [klx]


def layer(**kw):
    args = dict(cover=0.5, scale=400.0, altitude=1500.0, wind=(9.0, -4.0), thickness=8.0,
                seed=3, texels=256)
    args.update(kw)
    return CloudLayer(**args)


def sky_points(n, half=2.5):
    g = np.linspace(-half, half, n)
    return np.stack(np.meshgrid(g, -g), axis=-1)  # (n, n, 2), north-up


def unit(s):
    """Unit direction vector of sky-plane point s (independent of the module)."""
    v = np.array([s[0], s[1], 1.0])
    return v / np.linalg.norm(v)


def hg(cos_angle, g):
    return (1 - g**2) / (4 * np.pi * (1 + g**2 - 2 * g * cos_angle) ** 1.5)


def direction_at(zenith_deg, azimuth_deg):
    """Sky-plane point of a direction; azimuth from north towards east."""
    z, a = np.radians(zenith_deg), np.radians(azimuth_deg)
    return np.tan(z) * np.array([np.sin(a), np.cos(a)])


# 1. drift ------------------------------------------------------------------------------------


@pytest.mark.parametrize("t", [0.0, 7.3, 3600.0 * 5])
def test_drift_is_the_pattern_moving_with_the_wind(t):
    cl = layer()
    s = sky_points(64)
    dt = 12.5
    wind = np.array(cl.wind)
    moved = cl.optical_depth(s, t + dt)
    shifted = cl.optical_depth(s - wind * dt / cl.altitude, t)
    np.testing.assert_allclose(moved, shifted, rtol=0, atol=1e-9 * cl.thickness)
    assert moved.std() > 0.1  # the test sees a real pattern, not a constant


def test_drift_is_continuous_from_frame_to_frame():
    cl = layer(wind=(15.0, 5.0))
    s = sky_points(200)
    t = 100.0
    base = cl.optical_depth(s, t)
    steps = (1 / 24, 1 / 240, 1 / 2400)
    changes = [np.abs(cl.optical_depth(s, t + dt) - base).max() for dt in steps]
    # one 24 fps frame (0.66 m of drift, 1/40 of a 25 m texel) moves the field very little
    assert changes[0] < 0.1 * cl.thickness
    # and the change goes to 0 with dt, linearly (Lipschitz: bilinear noise, piecewise-linear ramp)
    assert changes[1] < 0.15 * changes[0] and changes[2] < 0.15 * changes[1]
    assert changes[0] > 0.0


# 2. cover --------------------------------------------------------------------------------------


@pytest.mark.parametrize("cover", [0.2, 0.5, 0.8])
def test_covered_fraction_is_cover(cover):
    cl = layer(cover=cover, scale=50.0, altitude=1000.0)
    s = sky_points(600, half=3.0)  # 6 km across, 7.5 tiles of 800 m
    assert 2 * 3.0 * cl.altitude > 5 * cl.period * cl.scale
    c = cl.coverage(s, 42.0)
    assert abs((c >= 0.5).mean() - cover) < 0.05
    assert abs(c.mean() - cover) < 0.05
    tau = cl.optical_depth(s, 42.0)
    assert abs((tau >= 0.5 * cl.thickness).mean() - cover) < 0.05
    assert c.max() == 1.0 and c.min() == 0.0  # clear sky and cloud cores both present
    assert ((c > 0.05) & (c < 0.95)).mean() > 0.05  # soft edges
    rad = cl.radiance(s[::10, ::10], 42.0, sun_s=direction_at(30, 100), sun_irradiance=SUN,
                      sky_irradiance=SKY)
    clear = tau[::10, ::10] == 0.0
    assert clear.any() and (rad[clear] == 0.0).all() and (rad[~clear] > 0.0).all()


def test_softness_zero_gives_hard_edges():
    cl = layer(cover=0.4, softness=0.0)
    c = cl.coverage(sky_points(200), 1.0)
    assert set(np.unique(c)) == {0.0, 1.0}
    assert abs(c.mean() - 0.4) < 0.1


def test_no_cover_is_clear():
    s = sky_points(32)
    for cl in (layer(cover=0.0), layer(thickness=0.0)):
        np.testing.assert_array_equal(cl.transmittance(s, 3.0), 1.0)
        rad = cl.radiance(s, 3.0, sun_s=direction_at(30, 120), sun_irradiance=SUN,
                          sky_irradiance=SKY)
        assert rad.shape == (32, 32, 3)
        np.testing.assert_array_equal(rad, 0.0)


def test_full_cover_is_a_uniform_overcast():
    cl = layer(cover=1.0, thickness=12.0)
    s = sky_points(32)
    np.testing.assert_array_equal(cl.optical_depth(s, 5.0), 12.0)
    cos_theta = 1.0 / np.linalg.norm(np.concatenate([s, np.ones((*s.shape[:-1], 1))], -1), axis=-1)
    np.testing.assert_allclose(cl.transmittance(s, 5.0), np.exp(-12.0 / cos_theta), rtol=1e-12)
    rad = cl.radiance(s, 5.0, sun_s=direction_at(40, 200), sun_irradiance=SUN, sky_irradiance=SKY)
    assert (rad > 0).all()
    # grey-white: the colour of the light that comes in, no more than it
    assert rad.max() < (SUN.max() + SKY.max()) / np.pi


# 3. seeds --------------------------------------------------------------------------------------


def test_seed_determinism():
    s = sky_points(64)
    a = layer(seed=11).optical_depth(s, 4.0)
    cloud_noise._noise.cache_clear()
    cloud_noise.coverage_knots.cache_clear()
    b = layer(seed=11).optical_depth(s, 4.0)
    np.testing.assert_array_equal(a, b)
    c = layer(seed=12).optical_depth(s, 4.0)
    assert np.abs(a - c).mean() > 0.1 * layer().thickness


def test_noise_is_cached_read_only_and_fractal():
    tex = fractal_noise(5, 256, period=16.0)
    assert fractal_noise(5, 256, period=16.0) is tex
    assert not tex.flags.writeable
    assert abs(tex.mean()) < 1e-12 and abs(tex.std() - 1.0) < 1e-12
    # 1-D transect spectrum ~ k^-5/3 above the outer scale (k0 = 8 cycles per tile here)
    power = (np.abs(np.fft.rfft(tex, axis=1)) ** 2).mean(axis=0)
    k = np.arange(power.size)
    band = (k >= 24) & (k <= 96)
    slope = np.polyfit(np.log(k[band]), np.log(power[band]), 1)[0]
    assert abs(slope + 5.0 / 3.0) < 0.25
    # and flat for wavelengths longer than 2 scale (k < 8): features are about `scale` wide
    assert power[1:4].mean() / power[4:8].mean() < 2.0


# 4. Blinn single scattering, glow and energy ---------------------------------------------------


def slab_quadrature(tau, s_view, s_sun, *, albedo, g, altitude=1500.0, depth=300.0):
    """Single scattering along the view ray through a slab [altitude, altitude + depth]:
    sun attenuated from the top, scattered (sigma w p), attenuated to the viewer."""
    v, u = unit(s_view), unit(s_sun)
    mu, mu0 = v[2], u[2]
    sigma = tau / depth
    p = hg(v @ u, g)

    def integrand(length):
        z = length * mu
        return (sigma * albedo * p * np.exp(-sigma * (altitude + depth - z) / mu0)
                * np.exp(-sigma * (z - altitude) / mu))

    value, _ = integrate.quad(integrand, altitude / mu, (altitude + depth) / mu, epsabs=0,
                              epsrel=1e-10)
    return value


@pytest.mark.parametrize("tau", [0.05, 0.6, 3.0])
def test_blinn_single_scattering_matches_slab_quadrature(tau):
    cl = layer(cover=1.0, thickness=tau, albedo=0.7, asymmetry=0.8)
    s_sun = direction_at(35, 150)
    views = np.array([direction_at(z, a) for z, a in
                      [(0, 0), (35, 150), (36, 152), (60, 150), (70, 300), (20, 10), (80, 90)]])
    rad = cl.radiance(views, 0.0, sun_s=s_sun, sun_irradiance=SUN, sky_irradiance=SKY,
                      multiple_scattering=False)
    for view, got in zip(views, rad):
        expected = SUN * slab_quadrature(tau, view, s_sun, albedo=0.7, g=0.8)
        np.testing.assert_allclose(got, expected, rtol=0.01)


def test_forward_glow_follows_the_phase_function():
    g = 0.85
    cl = layer(cover=1.0, thickness=0.4, asymmetry=g)
    zen = 40.0
    s_sun = direction_at(zen, 0.0)
    # views at the same zenith angle as the sun, at 5, 60 and 120 degrees from it
    views, angles = [], (5.0, 60.0, 80.0)
    for ang in angles:
        z = np.radians(zen)
        cos_az = (np.cos(np.radians(ang)) - np.cos(z) ** 2) / np.sin(z) ** 2
        views.append(direction_at(zen, np.degrees(np.arccos(cos_az))))
        assert np.isclose(unit(views[-1]) @ unit(s_sun), np.cos(np.radians(ang)))
    views = np.array(views)
    p = hg(np.cos(np.radians(angles)), g)
    single = cl.radiance(views, 0.0, sun_s=s_sun, sun_irradiance=SUN, sky_irradiance=SKY,
                         multiple_scattering=False)[:, 1]
    np.testing.assert_allclose(single[0] / single[1], p[0] / p[1], rtol=1e-4)
    assert single[0] / single[1] > 30  # thin cloud around the sun glows
    full = cl.radiance(views, 0.0, sun_s=s_sun, sun_irradiance=SUN, sky_irradiance=SKY)[:, 1]
    assert full[0] > full[1] > full[2]
    # the multiple-scattered part is the same at equal zenith: differences follow HG
    np.testing.assert_allclose((full[0] - full[1]) / (full[1] - full[2]),
                               (p[0] - p[1]) / (p[1] - p[2]), rtol=1e-3)


def hemisphere_flux(cl, s_sun, n_theta=300, n_phi=600):
    """Midpoint quadrature of radiance cos(theta) d_omega over the lower sky hemisphere."""
    theta = (np.arange(n_theta) + 0.5) * (0.5 * np.pi / n_theta)
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    s = np.stack([np.tan(th) * np.sin(ph), np.tan(th) * np.cos(ph)], -1)
    rad = cl.radiance(s, 0.0, sun_s=s_sun, sun_irradiance=SUN, sky_irradiance=SKY).astype(float)
    weight = np.cos(th) * np.sin(th) * (0.5 * np.pi / n_theta) * (2 * np.pi / n_phi)
    return (rad * weight[..., None]).sum(axis=(0, 1))


@pytest.mark.parametrize("tau", [0.3, 3.0, 30.0])
@pytest.mark.parametrize("sun_zenith", [0.0, 60.0, 80.0])
@pytest.mark.parametrize("albedo", [1.0, 0.5])
def test_energy_is_bounded_by_what_comes_in(tau, sun_zenith, albedo):
    cl = layer(cover=1.0, thickness=tau, albedo=albedo)
    s_sun = direction_at(sun_zenith, 70.0)
    mu0 = np.cos(np.radians(sun_zenith))
    scattered = hemisphere_flux(cl, s_sun)
    direct_sun = SUN * mu0 * np.exp(-tau / mu0)
    # unscattered skylight (uniform sky): E * 2 E3(tau), computed here by quadrature
    e3, _ = integrate.quad(lambda mu: np.exp(-tau / mu) * 2 * mu, 0, 1)
    incoming = SUN * mu0 + SKY
    below = scattered + direct_sun + SKY * e3
    assert (below <= 1.01 * incoming).all()
    if albedo == 1.0:
        # nothing absorbed: below the cloud is what two-stream theory lets through
        expected = (SUN * mu0 * max(delta_eddington_transmittance(tau, mu0, asymmetry=0.85),
                                    np.exp(-tau / mu0) + single_scattering_flux_transmittance(
                                        tau, mu0, asymmetry=0.85, albedo=1.0))
                    + SKY * two_stream_diffuse_transmittance(tau, albedo=1.0, asymmetry=0.85))
        np.testing.assert_allclose(below, expected, rtol=0.02)
    else:
        assert (below < incoming).all()


def test_delta_eddington_and_two_stream_match_their_equations():
    """Closed forms against a numerical solution of the two-stream ODEs (Meador & Weaver 1980,
    Eddington coefficients after delta scaling; hemispheric mean for diffuse light)."""
    g = 0.85

    def solve(tau, g1, g2, g3, g4, mu0, source, top):
        def rhs(t, y):
            e = source * np.exp(-t / mu0)
            return np.vstack([g1 * y[0] - g2 * y[1] - g3 * e, g2 * y[0] - g1 * y[1] + g4 * e])

        def bc(ya, yb):
            return np.array([ya[1] - top, yb[0]])

        t = np.linspace(0, tau, 200)
        sol = integrate.solve_bvp(rhs, bc, t, np.zeros((2, t.size)), tol=1e-8, max_nodes=100000)
        assert sol.success
        return sol.sol(tau)[1]

    for tau in (0.2, 2.0, 15.0):
        for mu0 in (1.0, 0.5, 0.2):
            ts, gs = (1 - g * g) * tau, g / (1 + g)
            g1 = g2 = 0.75 * (1 - gs)
            g3 = 0.25 * (2 - 3 * gs * mu0)
            down = solve(ts, g1, g2, g3, 1 - g3, mu0, 1.0, 0.0)  # diffuse flux at the base / F
            expected = (down + mu0 * np.exp(-ts / mu0)) / mu0
            got = delta_eddington_transmittance(tau, mu0, asymmetry=g)
            np.testing.assert_allclose(got, expected, rtol=1e-5)
        for w in (1.0, 0.9):
            down = solve(tau, 2 - w * (1 + g), w * (1 - g), 0, 0, 1.0, 0.0, 1.0)
            np.testing.assert_allclose(two_stream_diffuse_transmittance(tau, albedo=w, asymmetry=g),
                                       down, rtol=1e-5)
        np.testing.assert_allclose(two_stream_diffuse_transmittance(tau, albedo=1.0, asymmetry=g),
                                   1 / (1 + (1 - g) * tau), rtol=1e-12)


def test_single_scattering_flux_for_isotropic_scattering():
    """S1 with g = 0: the azimuth integral is 1/2, leaving a double integral over mu and depth."""
    for tau, mu0 in [(0.1, 0.9), (1.0, 0.5), (4.0, 0.3)]:
        def inner(mu):
            return integrate.quad(lambda t: np.exp(-t / mu0 - (tau - t) / mu), 0, tau)[0]

        expected = 0.8 / (2 * mu0) * integrate.quad(inner, 0, 1, limit=200)[0]
        got = single_scattering_flux_transmittance(tau, mu0, asymmetry=0.0, albedo=0.8)
        np.testing.assert_allclose(got, expected, rtol=1e-4)


# 5. slant ---------------------------------------------------------------------------------------


def test_transmittance_decreases_with_slant_through_the_same_cloud_point():
    cl = layer(cover=0.7, wind=(30.0, 10.0))
    s = sky_points(40, half=0.4)
    t = 60.0
    # at time t the direction s + wind t / altitude meets the pattern point that s met at 0
    s_slant = s + np.array(cl.wind) * t / cl.altitude
    tau = cl.optical_depth(s, 0.0)
    np.testing.assert_allclose(cl.optical_depth(s_slant, t), tau, atol=1e-9)
    assert (np.hypot(*np.moveaxis(s_slant, -1, 0)) > np.hypot(*np.moveaxis(s, -1, 0))).all()
    t_near, t_far = cl.transmittance(s, 0.0), cl.transmittance(s_slant, t)
    cloudy = tau > 0.1
    assert cloudy.mean() > 0.3
    assert (t_far[cloudy] < t_near[cloudy]).all()
    cos_far = np.array([unit(p)[2] for p in s_slant.reshape(-1, 2)]).reshape(tau.shape)
    np.testing.assert_allclose(t_far, np.exp(-tau / cos_far), rtol=1e-9)


# API details -------------------------------------------------------------------------------------


def test_shapes_inputs_and_shade():
    cl = layer(wind=np.array([3.0, 1.0]))
    assert cl.wind == (3.0, 1.0) and hash(cl) == hash(layer(wind=(3.0, 1.0)))
    s = sky_points(12).reshape(3, 4, 12, 2)
    s_copy = s.copy()
    sun_s = direction_at(30, 200)
    kw = dict(sun_s=sun_s, sun_irradiance=SUN, sky_irradiance=SKY)
    t, r = cl.shade(s, 9.0, **kw)
    assert t.shape == (3, 4, 12) and r.shape == (3, 4, 12, 3)
    np.testing.assert_array_equal(t, cl.transmittance(s, 9.0))
    np.testing.assert_array_equal(r, cl.radiance(s, 9.0, **kw))
    np.testing.assert_array_equal(s, s_copy)
    assert cl.optical_depth(np.zeros(2), 0.0).shape == ()
    with pytest.raises(ValueError):
        layer(cover=1.5)
    with pytest.raises(ValueError):
        layer(wind=(1.0, 2.0, 3.0))


def test_footprint_filters_the_pattern_like_a_box_average():
    """With a footprint the field is the pattern averaged over about that width on the layer:
    its variance falls as the footprint grows, the mean stays, and a footprint below a texel
    changes nothing."""
    layer = CloudLayer(cover=0.5, scale=800.0, altitude=2000.0, wind=(0.0, 0.0), thickness=1.0, seed=0)
    rng = np.random.default_rng(5)
    s = rng.uniform(-2, 2, size=(20000, 2))
    sharp = layer.field(s, 0.0)
    np.testing.assert_allclose(layer.field(s, 0.0, footprint=1e-4 * layer.texel / layer.altitude), sharp)
    texel_tan = layer.texel / layer.altitude
    spreads = [layer.field(s, 0.0, footprint=k * texel_tan).std() for k in (1, 8, 64)]
    assert spreads[0] > spreads[1] > spreads[2]
    # against brute force: the mean of the sharp field over the 8 x 8 texel block around a point
    k = 8
    point = np.array([[0.3, -0.2]])
    offsets = (np.arange(64) + 0.5) / 64 - 0.5
    grid = np.stack(np.meshgrid(offsets, offsets), axis=-1).reshape(-1, 2) * k * texel_tan + point
    brute = layer.field(grid, 0.0).mean()
    filtered = layer.field(point, 0.0, footprint=k * texel_tan)[0]
    assert abs(filtered - brute) < 0.25 * sharp.std(), (filtered, brute)


@pytest.mark.parametrize("texels_across", [0.5, 2.0, 8.0, 64.0])
def test_a_footprints_coverage_is_the_mean_coverage_within_it(texels_across):
    """Anti-aliased edges at every distance: the coverage read with a footprint is close to the
    mean of the sharp coverage over that footprint (24 x 24 point samples, the reference),
    closer than the coverage of the filtered field (which draws a hard edge through a pixel
    and, far off, loses the thin clouds altogether)."""
    layer = CloudLayer(cover=0.4, scale=800.0, altitude=2000.0, wind=(0.0, 0.0), thickness=1.0, seed=0)
    s = np.random.default_rng(1).uniform(-1, 1, size=(300, 2))
    width = texels_across * layer.texel / layer.altitude  # [tan]
    offsets = ((np.arange(24) + 0.5) / 24 - 0.5) * width
    box = np.stack(np.meshgrid(offsets, offsets), axis=-1).reshape(-1, 2)
    reference = layer.coverage(s[:, None, :] + box[None], 0.0).mean(axis=1)
    filtered = layer.coverage(s, 0.0, footprint=width)
    values, levels = coverage_knots(*layer._noise_key(), layer.cover, layer.softness)
    hard = np.interp(layer.field(s, 0.0, footprint=width), values, levels)
    rms = np.sqrt(np.mean((filtered - reference) ** 2))
    assert rms < 0.11
    if texels_across >= 2:
        assert rms < 0.8 * np.sqrt(np.mean((hard - reference) ** 2))


def test_the_field_bends_smoothly_between_texels():
    """Magnified, the field has no kinks at the texel lines (bilinear reading had one at each,
    whence the blocky cloud edges): along a line sampled at 1/64 texel, the slope changes from
    step to step by under 5 % of the largest slope."""
    layer = CloudLayer(cover=0.4, scale=800.0, altitude=2000.0, wind=(0.0, 0.0), thickness=1.0, seed=0)
    step = layer.texel / layer.altitude / 64  # [tan]
    t = np.arange(64 * 12) * step
    s = np.column_stack([0.1 + t, 0.05 + 0.37 * t])  # across texel lines of both axes
    slope = np.diff(layer.field(s, 0.0))
    assert np.abs(np.diff(slope)).max() < 0.05 * np.abs(slope).max()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_pattern_does_not_repeat_with_the_tile(seed):
    """The plane is laid with shifted copies of the tile: one tile along a lattice axis or its
    diagonal the field is another (a repeating tile lined its copies up towards the horizon,
    where a pixel's footprint runs along an axis over many copies: a dark or light streak from
    the horizon up, docs/method.md, "The cloud pattern"). Magnified 64 times, the field crosses
    a copy's edge without a seam."""
    cl = layer(seed=seed, wind=(8.0, 2.0))
    period = cl.period * cl.scale / cl.altitude  # one tile [tan]
    x = np.linspace(0.1, 0.1 + 6 * period, 6 * 1000, endpoint=False)
    for y, shift in ((0.0, (period, 0.0)), (0.3 * period, (0.0, period)), (0.0, (period, period))):
        s = np.stack([x, np.full_like(x, y)], -1)
        here, there = cl.field(s, 5.0), cl.field(s + shift, 5.0)
        assert abs(np.corrcoef(here, there)[0, 1]) < 0.2
    step = cl.texel / cl.altitude / 64  # [tan]
    t = 0.5 * period + (np.arange(64 * 12) - 64 * 6) * step  # across a copy's edge at time 0
    steps = np.abs(np.diff(cl.field(np.column_stack([t, 0.05 + 0.37 * (t - t[0])]), 0.0)))
    assert steps.max() < 1.5 * np.percentile(steps, 99)  # no seam: no step stands out


def test_a_long_footprint_blurs_along_its_length_only():
    """Near the horizon a pixel's footprint is long along the radius and narrow across it:
    filtered as such, the field keeps more of its detail than filtered round at the long width,
    and about as much as filtered round at the narrow width over the long one's taps."""
    layer = CloudLayer(cover=0.4, scale=800.0, altitude=2000.0, wind=(0.0, 0.0), thickness=1.0, seed=0)
    texel = layer.texel / layer.altitude
    s = np.random.default_rng(2).uniform(-3, 3, size=(5000, 2))
    long_thin = layer.field(s, 0.0, footprint=np.broadcast_to([32 * texel, 2 * texel], s.shape)).std()
    round_long = layer.field(s, 0.0, footprint=32 * texel).std()
    round_thin = layer.field(s, 0.0, footprint=2 * texel).std()
    assert round_long < long_thin < round_thin
    assert long_thin > 1.3 * round_long  # 1.49 measured


# 7. the compiled reads -----------------------------------------------------------------------


def tile_shifts(seed: int, rows, cols, side: int) -> np.ndarray:
    """The shifts (2, m) [texel] of copies (rows, cols) (m,) of the cloud tile: none for copy
    (0, 0), else the copy's offsets as the ground albedo's stochastic tiling draws a lattice
    vertex's (``albedo.vertex_keys``)."""
    key = vertex_keys(rows, cols, seed)
    shifts = np.stack([unit_hash(key), unit_hash(key ^ SECOND_KEY)]) * side
    shifts[:, (rows == 0) & (cols == 0)] = 0.0
    return shifts


def reference_field(cl, s, time, footprint=None):
    """``CloudLayer.field`` as numpy and scipy.ndimage.map_coordinates compute it, from where
    ``CloudLayer._taps`` says to read: the reference the compiled loop is held to, bit for bit.
    The plane is laid with the tile's shifted copies, blended near their edges, written here
    for all four combinations of the copies on either side at once (those not read weigh 0)."""
    from scipy import ndimage

    key = cl._noise_key()
    levels = cloud_noise._noise_levels(*key)
    n, base = cl.texels, np.array(cl._drifted_copies(time))[:, None]

    def read(level, coords):
        if level == 0:
            return ndimage.map_coordinates(cloud_noise._spline(*key), coords, order=3, mode="grid-wrap",
                                           prefilter=False)
        return ndimage.map_coordinates(levels[level], coords, order=1, mode="grid-wrap")

    def tiled(at, read_at):
        copy = np.floor(at / n + 0.5)
        edge = at - (copy - 0.5) * n
        band = clouds.TILE_BLEND * n
        low, high = edge < 0.5 * band, edge > n - 0.5 * band
        u = np.clip(np.where(low, edge / band + 0.5, (edge - n) / band + 0.5), 0.0, 1.0)
        upper = np.where(low | high, u * u * (3.0 - 2.0 * u), 0.0)
        shares = (np.where(low | high, 1.0 - upper, 1.0), upper)  # lower and upper copy, per axis
        first = (copy + base - low).astype(np.int64)
        weighted = squares = 0.0
        for r in range(2):
            for c in range(2):
                w = shares[r][0] * shares[c][1]
                shift = tile_shifts(cl.seed, first[0] + r, first[1] + c, n).reshape(at.shape)
                weighted = weighted + w * read_at(at + shift)
                squares = squares + w * w
        return weighted / np.sqrt(squares)

    shape, coords, taps = cl._taps(s, time, footprint)
    if taps is None:
        return tiled(coords, lambda at: read(0, at)).reshape(shape)
    taps, k0, blend, major, ex, ey = taps
    order = np.lexsort((-taps, k0))
    coords, taps, k0, blend, major, ex, ey = (a[..., order] for a in (coords, taps, k0, blend, major, ex, ey))
    out = np.zeros(len(k0))
    starts = np.flatnonzero(np.diff(k0, prepend=-1))
    for a, b in zip(starts, np.append(starts[1:], len(k0))):
        k = int(k0[a])
        for t in range(int(taps[a])):
            m = a + int(np.count_nonzero(taps[a:b] > t))
            step = ((t + 0.5) / taps[a:m] - 0.5) * major[a:m]
            at = coords[:, a:m] + np.stack([-ey[a:m] * step, ex[a:m] * step])

            def both_levels(at, k=k, blend=blend[a:m]):
                value = read(k, (at + 0.5) / 2.0**k - 0.5)
                upper = blend > 0
                if k + 1 < len(levels) and upper.any():
                    finer = value[upper]
                    coarser = read(k + 1, (at[:, upper] + 0.5) / 2.0 ** (k + 1) - 0.5)
                    value[upper] = finer + blend[upper] * (coarser - finer)
                return value

            out[a:m] += tiled(at, both_levels) / taps[a:m]
    result = np.empty_like(out)
    result[order] = out
    return result.reshape(shape)


@pytest.mark.parametrize("seed, threads", [(0, 1), (1, 1), (2, 1), (0, 3)])
def test_the_compiled_field_is_the_map_coordinates_field_to_the_bit(seed, threads, monkeypatch):
    """Random directions (out to 30 tan, and on the tile's edges, where the reads wrap), times
    (to 5 h), round and long footprints from a hundredth of a texel to beyond the tile; in one
    thread, or shared among three (cores.in_shares)."""
    monkeypatch.setattr(cores, "SMALLEST_SHARE", 100)
    with cores.loop_threads(threads):
        rng = np.random.default_rng(seed)
        cl = layer(texels=64 * 2**seed, wind=tuple(rng.normal(0, 20, 2)), seed=seed)
        n = 2000
        s = rng.normal(0, 1, (n, 2)) * np.exp(rng.uniform(-6, np.log(30), (n, 1)))
        per_texel = cl.altitude / cl.texel
        edge = rng.integers(-3, 4, (n // 4, 2)) * cl.texels + rng.uniform(-1.5, 1.5, (n // 4, 2))
        s[: n // 4] = edge / per_texel * [1, -1]  # at time 0 on a tile's edge, read across it
        s[5] = 0.0
        for time in (0.0, rng.uniform(0, 5 * 3600)):
            np.testing.assert_array_equal(cl.field(s, time), reference_field(cl, s, time))
            texel = 1.0 / per_texel  # one texel [tan]
            round_ = texel * np.exp(rng.uniform(np.log(0.01), np.log(4 * cl.texels), n))
            long_ = texel * np.exp(rng.uniform(np.log(0.01), np.log(4 * cl.texels), (n, 2)))
            for footprint in (round_, long_, 3.0 * texel):
                np.testing.assert_array_equal(cl.field(s, time, footprint),
                                              reference_field(cl, s, time, footprint))


@pytest.mark.parametrize("seed, threads", [(0, 1), (1, 3)])
def test_a_grids_field_is_the_map_coordinates_field_to_the_bit(seed, threads, monkeypatch):
    """A raster's points (x down each column, y along each row; ``kernels.tiling.cloud_grid``) over
    several copies of the tile and their blend bands, with a row and a column at a tile's edge
    and one at x = 0: the bits of the reference at the same points, in one thread or three."""
    monkeypatch.setattr(cores, "SMALLEST_SHARE", 100)
    rng = np.random.default_rng(seed)
    cl = layer(texels=64, wind=tuple(rng.normal(0, 20, 2)), seed=seed)
    per_texel = cl.altitude / cl.texel
    x = np.sort(rng.uniform(-4.0, 4.0, 90)) * cl.texels / per_texel  # four tiles across
    y = np.sort(rng.uniform(-4.0, 4.0, 70))[::-1] * cl.texels / per_texel
    x[10], y[7], x[50] = 1.5 * cl.texels / per_texel, -2.5 * cl.texels / per_texel, 0.0
    s = np.stack(np.broadcast_arrays(x[None, :], y[:, None]), axis=-1)
    monkeypatch.setattr(_tiling, "cloud_field", None)  # the grid's own loop, not the samples'
    with cores.loop_threads(threads):
        for time in (0.0, rng.uniform(0, 5 * 3600)):
            field = cl.field(s, time)
            assert field.shape == (70, 90)
            assert field.tobytes() == reference_field(cl, s.reshape(-1, 2), time).reshape(70, 90).tobytes()


def test_the_compiled_scattering_weights_are_np_interp_to_the_bit():
    layer = CloudLayer(cover=0.5, scale=800.0, altitude=2000.0, wind=(0.0, 0.0), thickness=6.0, seed=0)
    nodes, m_sun, m_sky = layer._multiple_tables(0.6)
    tables = np.stack([m_sun * (0.6 / np.pi), m_sky / np.pi])
    rng = np.random.default_rng(6)
    tau = np.concatenate([rng.random(20000) * 6.5 - 0.2, nodes, [np.nan, -np.inf, np.inf]])
    start = rng.random(tau.size).astype(np.float32)
    sun, sky = start.copy(), np.empty_like(start)
    _array_loops.scattering_weights(tau, nodes, tables, sun, sky)
    assert sun.tobytes() == (start + np.interp(tau, nodes, tables[0]).astype(np.float32)).tobytes()
    assert sky.tobytes() == np.interp(tau, nodes, tables[1]).astype(np.float32).tobytes()


def test_a_cloud_layers_light_shared_among_threads_is_the_same_to_the_bit(monkeypatch):
    """``radiance`` (its field, mean coverage and scattering weights) of many directions with
    footprints: the same bits in one thread as shared among three (cores.in_shares)."""
    rng = np.random.default_rng(3)
    cl = layer(texels=64, seed=4, thickness=2.0)
    s = rng.normal(0, 1, (5000, 2))
    footprint = np.exp(rng.uniform(np.log(1e-4), np.log(3.0), (5000, 2)))
    monkeypatch.setattr(cores, "SMALLEST_SHARE", 100)
    lights = []
    for threads in (1, 3):
        with cores.loop_threads(threads):
            lights.append(cl.radiance(s, 40.0, sun_s=direction_at(35, 150), sun_irradiance=SUN,
                                      sky_irradiance=SKY, footprint=footprint))
    assert lights[0].tobytes() == lights[1].tobytes()


@pytest.mark.parametrize("threads", [1, 3])
def test_the_compiled_mean_coverage_is_the_array_quadrature_to_the_bit(threads, monkeypatch):
    """``coverage`` with a footprint (the compiled Gauss-Hermite sum over ``np.interp``s) gives the
    bits of the array expression it stands for, over fields through and beyond the knots, knots
    hit exactly, NaN and zero spreads; in one thread or three (cores.in_shares)."""
    monkeypatch.setattr(cores, "SMALLEST_SHARE", 100)
    with cores.loop_threads(threads):
        from pipeline.sky.cloud_noise import coverage_knots, lost_variance

        rng = np.random.default_rng(8)
        cl = layer(texels=64, seed=2)
        values, levels = coverage_knots(*cl._noise_key(), cl.cover, cl.softness)
        s = rng.normal(0, 1, (3000, 2))
        footprint = np.exp(rng.uniform(np.log(1e-4), np.log(3.0), (3000, 2)))
        footprint[:50] = 0.0
        field = cl.field(s, 17.0, footprint)
        along, across = cl._widths((3000,), footprint)
        spread = np.sqrt(lost_variance(cl._noise_key(), along, across))
        nodes, weights = np.polynomial.hermite_e.hermegauss(8)
        want = np.zeros(3000)
        for z, w in zip(nodes, weights / weights.sum()):
            want += w * np.interp(field + z * spread, values, levels)
        np.testing.assert_array_equal(cl.coverage(s, 17.0, footprint), want)
        out = np.empty(4)
        _array_loops.hermite_mean(np.array([values[3], np.nan, -50.0, 50.0]), np.zeros(4), nodes,
                                  weights / weights.sum(), values, levels, out)
        np.testing.assert_array_equal(out[[0, 2, 3]], [levels[3], levels[0], levels[-1]])
        assert np.isnan(out[1])

