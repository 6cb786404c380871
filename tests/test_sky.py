from dataclasses import replace

import numpy as np
import pytest
import yaml
from ladybug.skymodel import estimate_illuminance_from_irradiance
from pvlib import atmosphere, clearsky
from reference import equirect_patch, unit_vector
from scipy.integrate import quad

from pipeline.cli.main import main
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.constants import SUN_ANGULAR_RADIUS
from pipeline.core.geometry import I0, projected_solid_angle, sky_grid, sky_offset, sky_plane_from_direction
from pipeline.kernels import arrays as _array_loops
from pipeline.sky.base import Sky, UniformSky
from pipeline.sky.ephemeris import obscured_fraction
from pipeline.sky.equirect import EquirectSky, cut_sun
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import MoonDisc, SunDisc, sun_disc_radiance, sun_light
from pipeline.sky.sun_kernel import sun_irradiance, sun_kernel, unshadowed


def square(half, q):
    return sky_grid((-half, -half), (2 * half + 1, 2 * half + 1), q)


def centroid(weighted, grid):
    """Energy centroid (sx, sy) of a sky raster's first channel. [tan]"""
    e = weighted[0].astype(np.float64)
    rows, cols = np.indices(e.shape)
    sx, sy = grid.ground_from_raster(rows, cols)
    return (e * sx).sum() / e.sum(), (e * sy).sum() / e.sum()


def test_uniform_sky_is_exact():
    half, q = 100, 0.02
    raster = UniformSky(np.array([1.0, 2.0, 0.5])).raster(square(half, q))
    assert raster.weighted.dtype == np.float32
    assert raster.irradiance == pytest.approx(np.pi * np.array([1.0, 2.0, 0.5]), rel=1e-12)
    inside = I0(np.arctan((half + 0.5) * q))
    assert raster.weighted[0].sum(dtype=np.float64) == pytest.approx(inside, rel=1e-6)


def test_uniform_equirect_equals_uniform_model():
    grid = square(300, 0.05 / 8)
    uniform = UniformSky(np.ones(3)).raster(grid)
    hdri = EquirectSky(np.ones((256, 512, 3), np.float32)).raster(grid)
    assert hdri.irradiance == pytest.approx(uniform.irradiance, rel=1e-9)
    assert hdri.weighted.sum() == pytest.approx(uniform.weighted.sum(), rel=1e-4)
    # cell by cell the splat carries a fine moire; over 8 x 8 blocks it is gone
    ratio = hdri.weighted[0] / uniform.weighted[0]
    blocks = ratio[:600, :600].reshape(75, 8, 75, 8).mean(axis=(1, 3))
    assert np.abs(blocks - 1).max() < 0.01


def test_small_bright_sun_keeps_its_energy_and_direction():
    width, height = 512, 256
    image, az, zen = equirect_patch(width, height, azimuth=(np.radians(119.0), np.radians(120.5)),
                                    zenith=(np.radians(40.0), np.radians(40.9)), radiance=1e5)
    sky = EquirectSky(image)
    energy = sky.image_irradiance()[0]
    # exact irradiance of the patch: L * integral of cos(theta) d_omega over it
    expected = 1e5 * (az[1] - az[0]) * 0.5 * (np.sin(zen[1]) ** 2 - np.sin(zen[0]) ** 2)
    assert energy == pytest.approx(expected, rel=1e-9)
    grid = square(400, 0.004)
    raster = sky.raster(grid)
    assert raster.weighted[0].sum(dtype=np.float64) == pytest.approx(energy, rel=1e-5)
    assert raster.outside[0] == pytest.approx(0.0, abs=1e-6 * energy)
    sx, sy = centroid(raster.weighted, grid)
    tx, ty = sky_plane_from_direction(np.mean(az), np.mean(zen))
    assert abs(sx - tx) < 0.01 and abs(sy - ty) < 0.01  # a patch is 0.03 wide here
    assert sx > 0 and sy < 0  # azimuth 120 degrees: east and a little south


def test_rotation_turns_the_sky_towards_the_east():
    image, _az, _zen = equirect_patch(256, 128, azimuth=(-0.05, 0.05), zenith=(0.5, 0.6), radiance=100.0)
    grid = square(200, 0.005)
    north = EquirectSky(image).raster(grid)
    turned = EquirectSky(image, rotation=np.radians(90.0)).raster(grid)
    nx, ny = centroid(north.weighted, grid)
    tx, ty = centroid(turned.weighted, grid)
    assert ny > 0.5 and abs(nx) < 0.01  # centre column looks north
    assert tx > 0.5 and abs(ty) < 0.01  # turned by 90 degrees: now east
    assert turned.irradiance == pytest.approx(north.irradiance)


def test_equirect_east_is_at_three_quarters_of_the_width():
    image = np.zeros((64, 128, 3), np.float32)
    image[20:24, 94:98] = 50.0  # u around 0.75
    grid = square(300, 0.01)
    sx, sy = centroid(EquirectSky(image).raster(grid).weighted, grid)
    assert sx > 1.0 and abs(sy) < 0.05 * sx


def test_raster_off_the_sky_counts_as_outside():
    image = np.ones((128, 256, 3), np.float32)
    grid = sky_grid((40, 40), (20, 30), 0.01)  # a small window away from the zenith
    raster = EquirectSky(image).raster(grid)
    assert raster.irradiance == pytest.approx(np.full(3, np.pi), rel=1e-9)
    assert raster.outside[0] > 3.0


# --- the procedural sky (Preetham et al. 1999), sun kernel, moon, clouds --------------------------


LUMA = np.asarray(REC709_LUMINANCE, dtype=np.float64)
NO_LIMB = (0.0, 0.0, 0.0)


def sun_sky(elevation_deg, azimuth_deg=135.0, *, turbidity=2.5, limb=None, moon=None, clouds=None):
    sun = SunDisc(np.radians(azimuth_deg), np.radians(elevation_deg))
    if limb is not None:
        sun = SunDisc(sun.azimuth, sun.elevation, limb_darkening=limb)
    return ProceduralSky(turbidity, sun, moon=moon, clouds=clouds)


def disc_horizontal_irradiance(sky):
    """Independent: radial quadrature of the limb-darkened disc in the sun's own frame,
    2 pi int L(rho) sin(rho) d rho, times cos(zenith). [klx]"""
    sun = sky.sun
    out = []
    for ch in range(3):
        def f(rho):
            L = sun_disc_radiance(rho, angular_radius=sun.angular_radius,
                                  normal_irradiance=sky.sun_normal_irradiance, limb_darkening=sun.limb_darkening)
            return L[ch] * 2 * np.pi * np.sin(rho)
        out.append(quad(f, 0.0, sun.angular_radius, epsabs=0, epsrel=1e-10, limit=200)[0])
    return np.array(out) * np.sin(sun.elevation)


def lens_fraction(d, r, big_r):
    """Area of the sun (radius r) covered by the moon (radius big_r, centres d apart) over pi r^2:
    two circular segments, each a sector minus a triangle."""
    if d >= r + big_r:
        return 0.0
    if d <= big_r - r:
        return 1.0
    if d <= r - big_r:
        return big_r**2 / r**2
    x = (d * d + r * r - big_r * big_r) / (2 * d)  # chord's distance from the sun's centre

    def seg(rad, a):
        return rad * rad * np.arccos(a / rad) - a * np.sqrt(rad * rad - a * a)

    return (seg(r, x) + seg(big_r, d - x)) / (np.pi * r * r)


def moon_at(sun, separation, position_angle=0.7, radius=None):
    """A moon whose centre is ``separation`` [rad] from the sun's, on a great circle through it."""
    c = np.array([np.cos(sun.elevation) * np.sin(sun.azimuth), np.cos(sun.elevation) * np.cos(sun.azimuth),
                  np.sin(sun.elevation)])
    e1 = np.array([np.cos(sun.azimuth), -np.sin(sun.azimuth), 0.0])
    e2 = np.cross(c, e1)
    m = np.cos(separation) * c + np.sin(separation) * (np.cos(position_angle) * e1 + np.sin(position_angle) * e2)
    radius = sun.angular_radius * 1.03 if radius is None else radius
    return MoonDisc(float(np.arctan2(m[0], m[1])), float(np.arcsin(m[2])), radius)


def reference_daylight(elevation, turbidity, altitude):
    """Independent: pvlib's Ineichen clear sky, its light turned into klx by ladybug-core's Perez
    et al. (1990) efficacies (W = 2 cm); returns (direct horizontal, diffuse horizontal). [klx]"""
    zenith = 90.0 - elevation
    am = atmosphere.get_absolute_airmass(atmosphere.get_relative_airmass(zenith), atmosphere.alt2pres(altitude))
    sky = clearsky.ineichen(zenith, am, turbidity, altitude=altitude, dni_extra=1366.1)
    dni, dhi = float(sky["dni"]), float(sky["dhi"])
    ghi = dhi + dni * np.cos(np.radians(zenith))
    _, direct, diffuse, _ = estimate_illuminance_from_irradiance(
        elevation, ghi, dni, dhi, (np.log(2.0) + 0.075) / 0.08,
        rel_airmass=float(atmosphere.get_relative_airmass(zenith, "kasten1966")))
    return direct * np.cos(np.radians(zenith)) / 1000, diffuse / 1000


def hemisphere_irradiance(radiance, n_theta=128, n_phi=256):
    """Independent: midpoint rule in (theta, phi) of L cos(theta) sin(theta) over the upper
    hemisphere, radiance taking sky-plane points (..., 2). [radiance x sr]"""
    theta = (np.arange(n_theta) + 0.5) * (np.pi / 2 / n_theta)
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    t = np.tan(theta)[:, None]
    s = np.stack(np.broadcast_arrays(t * np.sin(phi), t * np.cos(phi)), axis=-1)
    weight = (np.cos(theta) * np.sin(theta))[:, None, None] * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)
    return (radiance(s) * weight).sum(axis=(0, 1))


@pytest.mark.parametrize("turbidity", [2.0, 3.0, 4.0, 6.0])
def test_clear_sky_levels_match_ineichen_with_perez_efficacy(turbidity):
    """Direct and diffuse horizontal illuminance within 2% of the standard clear-sky models, sun
    at 10 to 90 degrees (lower, the USNO twilight curve takes over: test_daylight), at sea level
    and at 1500 m (the sky integrated here; the sun's kernel sums to E_n cos(zenith),
    test_sun_kernel_keeps_the_disc_energy)."""
    for altitude in (0.0, 1500.0):
        for elevation in (10.0, 15.0, 30.0, 60.0, 90.0):
            sky = ProceduralSky(turbidity, SunDisc(np.radians(200.0), np.radians(elevation)), altitude=altitude)
            direct, diffuse = reference_daylight(elevation, turbidity, altitude)
            assert sky.undimmed_sun_irradiance() @ LUMA == pytest.approx(direct, rel=0.02), (elevation, altitude)
            assert hemisphere_irradiance(sky.radiance) @ LUMA == pytest.approx(diffuse, rel=0.02), (elevation, altitude)
    # the shade is lit by a blue sky, the flecks by a sun whiter at noon than at sunset
    high, low = (ProceduralSky(turbidity, SunDisc(0.0, np.radians(e))) for e in (60.0, 8.0))
    assert high.clear_sky_irradiance[2] > high.clear_sky_irradiance[0]
    assert low.sun_normal_irradiance[0] / low.sun_normal_irradiance[2] > \
        high.sun_normal_irradiance[0] / high.sun_normal_irradiance[2]


def test_clear_day_diffuse_share_is_that_of_measured_clear_skies():
    # turbidity 3, sun at 60 degrees: diffuse over global 0.12 to 0.16 (clear skies measured by
    # Littlefair 1985; the Preetham zenith luminance taken as absolute gave 0.28)
    sky = sun_sky(60.0, turbidity=3.0)
    direct, diffuse = sky.undimmed_sun_irradiance() @ LUMA, sky.sky_irradiance @ LUMA
    assert 0.12 < diffuse / (direct + diffuse) < 0.16
    assert unshadowed(sky) @ LUMA == pytest.approx(direct + diffuse, rel=5e-4)  # the kernel sum, to 2e-4
    shares = []  # more haze: a smaller direct share
    for T in (2.0, 3.0, 5.0, 8.0):
        s = sun_sky(60.0, turbidity=T)
        shares.append(s.undimmed_sun_irradiance() @ LUMA / (unshadowed(s) @ LUMA))
    assert np.all(np.diff(shares) < 0)


def test_preetham_shape_takes_the_same_levels():
    cie = sun_sky(40.0, turbidity=3.0)
    preetham = replace(cie, shape="preetham")
    assert preetham.clear_sky_irradiance @ LUMA == pytest.approx(cie.clear_sky_irradiance @ LUMA, rel=1e-9)
    assert hemisphere_irradiance(preetham.radiance) @ LUMA == pytest.approx(cie.daylight.diffuse_horizontal_illuminance,
                                                                            rel=0.01)
    assert not np.allclose(preetham.radiance(np.array([0.3, 0.1])), cie.radiance(np.array([0.3, 0.1])), rtol=0.01)


@pytest.mark.parametrize("limb", [None, NO_LIMB])
def test_sun_kernel_keeps_the_disc_energy(limb):
    rng = np.random.default_rng(7)
    for elevation in (15.0, 30.0, 50.0, 75.0, 90.0):
        for _ in range(3):  # random sub-cell positions of the sun's centre
            sky = sun_sky(elevation + rng.uniform(-0.5, 0.0), rng.uniform(0.0, 360.0), limb=limb)
            zenith = np.pi / 2 - sky.sun.elevation
            minor = 2 * sky.sun.angular_radius / np.cos(zenith)  # tangential diameter on the sky plane
            q = minor / 16 * rng.uniform(0.9, 1.1)  # 16 cells across, as in intended use
            kernel = sun_kernel(sky, q)
            assert kernel.weighted.dtype == np.float32
            total = kernel.weighted.sum(axis=(1, 2), dtype=np.float64)
            assert total == pytest.approx(disc_horizontal_irradiance(sky), rel=1e-3)
            assert total == pytest.approx(sun_irradiance(sky), rel=1e-3)


def test_sun_kernel_keeps_its_energy_when_the_disc_spans_few_cells():
    sky = sun_sky(40.0, 20.0)
    ref = disc_horizontal_irradiance(sky)
    for cells in (1.0, 1.7, 3.0):
        q = 2 * sky.sun.angular_radius / np.cos(np.radians(50.0)) / cells
        total = sun_kernel(sky, q).weighted.sum(axis=(1, 2), dtype=np.float64)
        assert total == pytest.approx(ref, rel=1e-3)


def test_sun_kernel_lies_at_the_sun_and_a_low_sun_is_a_radial_ellipse():
    sky = sun_sky(20.0, 90.0, limb=NO_LIMB)  # low in the east
    q = 4e-3
    kernel = sun_kernel(sky, q)
    e = kernel.weighted[1].astype(np.float64)
    start = sky_offset(kernel.grid)
    assert kernel.grid == sky_grid(start, e.shape, q)
    sx, sy = centroid(kernel.weighted, kernel.grid)
    assert sx == pytest.approx(sky.sun_point[0], abs=0.05 * q) and sy == pytest.approx(sky.sun_point[1], abs=0.05 * q)
    assert sx > 2.0 and abs(sy) < 1e-9 + 0.05 * q  # east
    # the block holds the whole disc: its border is empty
    assert e[0].max() == 0 and e[-1].max() == 0 and e[:, 0].max() == 0 and e[:, -1].max() == 0
    # extent along x (radial, east) over extent along y (tangential): 1 / cos(theta) = 1 / sin(20 deg)
    cols = np.flatnonzero(e.sum(axis=0) > 0)
    rows = np.flatnonzero(e.sum(axis=1) > 0)
    assert (len(cols) / len(rows)) == pytest.approx(1 / np.sin(np.radians(20.0)), rel=0.1)


def test_sun_fraction_clear_partial_total():
    clear = sun_sky(50.0, limb=NO_LIMB)
    assert clear.sun_fraction() == 1.0
    sun = clear.sun
    for separation in (0.3, 1.0, 1.6):
        d = separation * sun.angular_radius
        moon = moon_at(sun, d)
        sky = sun_sky(50.0, limb=NO_LIMB, moon=moon)
        area = lens_fraction(d, sun.angular_radius, moon.angular_radius)
        assert obscured_fraction(d, sun.angular_radius, moon.angular_radius) == pytest.approx(area, abs=1e-9)
        assert sky.sun_fraction() == pytest.approx(1.0 - area, abs=1e-4)
        # the kernel with the moon holds S times the clear kernel's energy
        q = sun.angular_radius / 10
        ratio = sun_kernel(sky, q).weighted.sum(dtype=np.float64) / sun_kernel(clear, q).weighted.sum(dtype=np.float64)
        assert ratio == pytest.approx(sky.sun_fraction(), abs=2e-3)
    total = sun_sky(50.0, moon=moon_at(sun, 0.0, radius=1.05 * sun.angular_radius))
    assert total.sun_fraction() == 0.0
    assert sun_kernel(total, sun.angular_radius / 10).weighted.max() == 0.0
    # limb darkening on: a moon over the bright centre hides more than its area's share
    annular = moon_at(sun, 0.1 * sun.angular_radius, radius=0.6 * sun.angular_radius)
    dark = sun_sky(50.0, moon=annular)
    area = lens_fraction(0.1 * sun.angular_radius, sun.angular_radius, annular.angular_radius)
    assert dark.sun_fraction() < 1.0 - area - 0.05


def test_procedural_raster_total_outside_and_folding():
    sky = sun_sky(35.0, 200.0)
    full = sky.sky_irradiance
    # outside, independently: a fine midpoint rule over the hemisphere, less each grid's rectangle
    # (the sky's radiance at its nodes evaluated once, for both grids)
    theta = (np.arange(1500) + 0.5) * (np.pi / 2 / 1500)
    phi = (np.arange(3000) + 0.5) * (2 * np.pi / 3000)
    tan = np.tan(theta)[:, None]
    s = np.stack(np.broadcast_arrays(tan * np.sin(phi), tan * np.cos(phi)), axis=-1)
    radiance = sky.radiance(s)
    for grid in (square(300, np.tan(np.radians(70.0)) / 300), sky_grid((40, -80), (50, 70), 0.01)):
        raster = sky.raster(grid)
        assert raster.weighted.dtype == np.float32 and raster.weighted.shape == (3, *grid.shape)
        assert raster.irradiance == pytest.approx(full, rel=1e-3)
        x0, y0, x1, y1 = grid.extent
        out = ~((s[..., 0] >= x0) & (s[..., 0] <= x1) & (s[..., 1] >= y0) & (s[..., 1] <= y1))
        w = (np.cos(theta) * np.sin(theta))[:, None] * (np.pi / 2 / 1500) * (2 * np.pi / 3000) * out
        expected = np.einsum("tpc,tp->c", radiance, w)
        assert raster.outside == pytest.approx(expected, rel=5e-3)
    grid = square(60, 0.02)
    folded = sky.raster(grid, fold_period=(32, 48))
    assert folded.weighted.shape == (3, 32, 48) and sky_offset(folded.grid) == (0, 0)
    assert folded.irradiance == pytest.approx(sky.raster(grid).irradiance, rel=1e-6)


def test_procedural_raster_cells_are_radiance_times_projected_solid_angle():
    sky = sun_sky(45.0, 30.0)
    grid = square(100, 0.02)  # interpolated nodes every 0.02 / 0.02 = 1 cell: exact centres
    raster = sky.raster(grid)
    rows, cols = np.indices(grid.shape)
    s = np.stack(grid.ground_from_raster(rows, cols), axis=-1)
    expected = np.moveaxis(sky.radiance(s), -1, 0) * projected_solid_angle(grid)
    np.testing.assert_allclose(raster.weighted, expected, rtol=1e-5)
    coarse = sky.raster(square(400, 0.005))  # nodes every 4 cells, interpolated
    assert coarse.weighted.sum(axis=(1, 2), dtype=np.float64) == pytest.approx(
        sky.raster(square(400, 0.005)).weighted.sum(axis=(1, 2), dtype=np.float64))


def test_unshadowed_is_raster_irradiance_plus_sun_kernel():
    sky = sun_sky(55.0, 300.0, moon=moon_at(SunDisc(np.radians(300.0), np.radians(55.0)), 0.004))
    raster = sky.raster(square(200, 0.015))
    kernel = sun_kernel(sky, 4e-4)
    total = raster.irradiance + kernel.weighted.sum(axis=(1, 2), dtype=np.float64)
    assert total == pytest.approx(unshadowed(sky), rel=1e-3)


class Overcast:
    """A test-only cloud layer: transmittance 0.5 everywhere and a uniform grey glow."""
    def __init__(self, glow):
        self.glow = glow
        self.calls = []

    def transmittance(self, s, time, footprint=None):
        return np.full(np.shape(s)[:-1], 0.5)

    def radiance(self, s, time, *, sun_s, sun_irradiance, sky_irradiance, footprint=None):
        self.calls.append((np.array(sun_s), np.array(sun_irradiance), np.array(sky_irradiance), time))
        return np.full((*np.shape(s)[:-1], 3), self.glow)


class TwoCalls:
    """A cloud layer seen through the protocol's two calls alone (no ``shade``)."""
    def __init__(self, layer):
        self.transmittance, self.radiance = layer.transmittance, layer.radiance


def test_clouds_sampled_once_by_shade_give_what_the_two_calls_give():
    """The sky samples a layer with ``shade`` once where the protocol's two calls sampled it
    twice: the same raster and radiance, to the bit, with and without a footprint."""
    from pipeline.sky.clouds import CloudLayer

    layer = CloudLayer(cover=0.5, scale=400.0, altitude=1500.0, wind=(9.0, -4.0), thickness=8.0, seed=3,
                       texels=256)
    once, twice = (replace(sun_sky(40.0, 100.0), clouds=c, time=30.0) for c in (layer, TwoCalls(layer)))
    grid = square(40, 0.05)
    a, b = once.raster(grid), twice.raster(grid)
    np.testing.assert_array_equal(a.weighted, b.weighted)
    assert a.outside.tolist() == b.outside.tolist()
    s = np.random.default_rng(0).normal(0, 2, (500, 2))
    footprint = np.abs(np.random.default_rng(1).normal(0, 0.02, (500, 2)))
    for fp in (None, footprint):
        np.testing.assert_array_equal(once.radiance(s, fp), twice.radiance(s, fp))


def test_clouds_compose_by_the_protocol():
    clear = sun_sky(40.0, 100.0)
    clouds = Overcast(glow=2.0)
    cloudy = ProceduralSky(clear.turbidity, clear.sun, clouds=clouds, time=12.5)
    grid = square(150, 0.02)
    a, b = clear.raster(grid), cloudy.raster(grid)

    np.testing.assert_allclose(b.weighted, 0.5 * a.weighted + 2.0 * projected_solid_angle(grid)[None], rtol=1e-5)
    assert b.irradiance == pytest.approx(0.5 * a.irradiance + 2.0 * np.pi, rel=1e-3)
    assert cloudy.sun_fraction() == pytest.approx(0.5)
    q = 5e-4
    np.testing.assert_allclose(sun_kernel(cloudy, q).weighted, 0.5 * sun_kernel(clear, q).weighted, rtol=1e-6)
    sun_s, sun_e, sky_e, time = clouds.calls[-1]
    np.testing.assert_allclose(sun_s, clear.sun_point)
    np.testing.assert_allclose(sun_e, clear.sun_normal_irradiance)
    np.testing.assert_allclose(sky_e, clear.sky_irradiance)
    assert time == 12.5


def test_equirect_integral_and_orientation():
    sky = sun_sky(30.0, 90.0)  # east
    width = 1024
    image = sky.equirect(width)
    assert image.shape == (512, 1024, 3) and image.dtype == np.float32
    assert np.all(image[256:] == 0)  # below the horizon
    total = EquirectSky(image).image_irradiance()
    assert total == pytest.approx(unshadowed(sky), rel=1e-2)
    row, col = np.unravel_index(np.argmax(image[..., 1]), image.shape[:2])
    assert col == int(0.75 * width) or col == int(0.75 * width) - 1
    assert (row + 0.5) / 512 * 180 == pytest.approx(60.0, abs=0.5)  # zenith angle 60 degrees
    eclipsed = sun_sky(30.0, 90.0, moon=moon_at(sky.sun, 0.0, radius=1.05 * sky.sun.angular_radius))
    dark = eclipsed.equirect(width)
    assert EquirectSky(dark).image_irradiance() == pytest.approx(unshadowed(eclipsed), rel=1e-2)
    assert dark.max() < 0.01 * image.max()


def test_procedural_sky_refuses_bad_input():
    sun = SunDisc(0.0, 0.5)
    with pytest.raises(ValueError, match="turbidity"):
        ProceduralSky(1.0, sun)
    with pytest.raises(ValueError, match="elevation"):
        ProceduralSky(2.0, SunDisc(0.0, -0.11))
    with pytest.raises(ValueError, match="limb_darkening"):
        SunDisc(0.0, 0.5, limb_darkening=(0.5, 1.5, 0.5))
    with pytest.raises(ValueError, match="angular_radius"):
        MoonDisc(0.0, 0.5, 0.0)
    with pytest.raises(ValueError, match="horizon"):
        sun_kernel(ProceduralSky(2.0, SunDisc(0.0, 0.003)), 1e-3)
    with pytest.raises(ValueError, match="cells"):
        sun_kernel(ProceduralSky(2.0, SunDisc(0.0, 0.03)), 1e-5)


# --- an HDRI's sun cut out into the fine kernel (cut_sun) --------------------------------------


def texel_directions(height, width, rotation=0.0):
    """Unit vectors (height // 2, width, 3) of the upper texel centres, ``rotation`` included."""
    theta = (np.arange(height // 2)[:, None] + 0.5) * np.pi / height
    phi = ((np.arange(width)[None, :] + 0.5) / width - 0.5) * 2 * np.pi + rotation
    theta, phi = np.broadcast_arrays(theta, phi)
    return np.stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)], axis=-1)


def angle_between(a, b):
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


@pytest.mark.parametrize("azimuth, elevation, rotation", [(200.0, 35.0, 0.4), (180.0, 20.0, 0.0), (90.0, 85.0, -1.0)])
def test_cut_sun_finds_the_sun_of_an_hdri(azimuth, elevation, rotation):
    sky = sun_sky(elevation, azimuth)
    image = sky.equirect(1024)  # the limb-darkened disc deposited area-correctly on a Preetham sky
    hdri = EquirectSky(image.copy(), rotation=rotation)
    cut = cut_sun(hdri)
    assert np.array_equal(hdri.image, image) and hdri.sun is None  # the input is left alone
    assert cut.rotation == rotation and cut.sun.angular_radius == SUN_ANGULAR_RADIUS
    texel = np.pi / 512
    truth = unit_vector(sky.sun.azimuth + rotation, sky.sun.elevation)
    assert angle_between(cut.sun_direction, truth) < 0.25 * texel  # (180, 20): on the seam of the image
    assert cut.sun_irradiance() == pytest.approx(sun_irradiance(sky), rel=1e-3)
    # exact bookkeeping: the image lost what the sun carries away
    assert cut.image_irradiance() + cut.sun_irradiance() == pytest.approx(hdri.image_irradiance(), rel=1e-9)
    assert cut_sun(cut) is cut


def test_cut_sun_kernel_and_coarse_sky_balance_the_original():
    hdri = EquirectSky(sun_sky(35.0, 200.0).equirect(1024), rotation=0.4)
    cut = cut_sun(hdri)
    minor = 2 * cut.sun.angular_radius / np.sin(cut.sun.elevation)
    kernel = sun_kernel(cut, minor / 16)
    e = kernel.weighted.sum(axis=(1, 2), dtype=np.float64)
    assert e == pytest.approx(cut.sun_irradiance(), rel=1e-3)
    assert cut.image_irradiance() + e == pytest.approx(hdri.image_irradiance(), rel=1e-3)  # measured 1e-4
    assert cut.image_irradiance()[1] < 0.5 * hdri.image_irradiance()[1]  # the sun was most of the light
    sx, sy = centroid(kernel.weighted, kernel.grid)
    tx, ty = cut.sun_direction[:2] / cut.sun_direction[2]
    assert sx == pytest.approx(tx, abs=0.05 * minor / 16) and sy == pytest.approx(ty, abs=0.05 * minor / 16)


def test_cut_sun_leaves_no_bright_texel_near_the_old_peak():
    hdri = EquirectSky(sun_sky(35.0, 200.0).equirect(1024))
    cut = cut_sun(hdri)
    luminance = hdri.image[:256] @ LUMA
    peak = np.unravel_index(np.argmax(luminance), luminance.shape)
    after = cut.image[:256] @ LUMA
    background = after[peak]
    assert luminance[peak] > 1e4 * background
    near = angle_between(texel_directions(512, 1024), cut.sun_direction) < np.radians(3.0)
    assert after[near].max() < 1.2 * background  # only the circumsolar glow's slope is left
    changed = np.any(cut.image != hdri.image, axis=-1)
    assert 0 < changed.sum() < 50 and np.all(near[changed[:256]]) and not changed[256:].any()


def test_cut_sun_leaves_skies_without_a_sun_alone():
    height, width = 256, 512
    elevation = np.pi / 2 - (np.arange(height) + 0.5) * np.pi / height
    gradient = np.repeat((1.0 + 9.0 * np.exp(-np.abs(elevation) / 0.2))[:, None, None], width, axis=1)
    clear = sun_sky(10.0, 200.0)  # Preetham's circumsolar glow of a low sun, about 15 x the median
    s = texel_directions(height, width)
    glow = np.zeros((height, width, 3))
    glow[: height // 2] = clear.radiance(s[..., :2] / s[..., 2:])
    wide, _, _ = equirect_patch(width, height, azimuth=(0.0, 0.2), zenith=(0.6, 0.8), radiance=1e4, background=1.0)
    low = sun_sky(1.5, 200.0).equirect(1024)  # a sun this low stays in the coarse raster
    for image in (np.ones((height, width, 3)), gradient * [0.3, 0.5, 1.0], glow, wide, low):
        sky = EquirectSky(image.astype(np.float32))
        assert cut_sun(sky) is sky
    with pytest.raises(ValueError, match="no sun"):
        sun_kernel(EquirectSky(np.ones((height, width, 3), np.float32)), 1e-3)
    with pytest.raises(ValueError, match="together"):
        EquirectSky(np.ones((height, width, 3), np.float32), sun=SunDisc(0.0, 0.5))


def test_skylight_scales_the_blue_sky_and_leaves_the_sun():
    """skylight 0 is the sun alone (the paper's Fig. 11); 0.5 halves the clear sky."""
    sky = sun_sky(45.0)
    dark, half = replace(sky, skylight=0.0), replace(sky, skylight=0.5)
    s = np.array([[0.3, -0.2], [1.5, 0.4]])
    assert not dark.radiance(s).any() and not dark.sky_irradiance.any()
    np.testing.assert_allclose(half.radiance(s), 0.5 * sky.radiance(s), rtol=1e-12)
    np.testing.assert_allclose(sun_irradiance(dark), sun_irradiance(sky), rtol=1e-12)
    assert dark.sun_fraction() == sky.sun_fraction() == 1.0


def test_sunshade_sky_integrates_to_the_open_ground_of_sunshade_ground(tmp_path):
    """What a user sees: the hemisphere integral of the `sunshade sky` image (texels' exact
    projected solid angles, the sun disc deposited in it) is the light `sunshade ground` gives
    ground that no leaf shades, and both are the standard models' daylight."""
    rng = np.random.default_rng(0)
    io.write_png(tmp_path / "mask.png", np.where(rng.random((40, 40)) < 0.4, 0.0, 1.0).astype(np.float32)[..., None])
    config = {"canopy": {"mask": "mask.png", "size": [4.0, 4.0], "height": 3.0},
              "sky": {"model": "cie", "turbidity": 4.0, "sun": {"elevation": 40.0, "azimuth": 120.0}, "alpha": 80.0},
              "ground": {"window": [-24, -24, 24, 24], "pixel": 0.5, "sun_window": [20, 20, 22, 22],
                         "sun_pixel": 0.05}}
    path = tmp_path / "open.yaml"
    path.write_text(yaml.safe_dump(config))
    assert main(["sky", str(path), "--width", "1024", "-o", str(tmp_path / "sky.exr")]) == 0
    assert main(["ground", str(path), "-o", str(tmp_path / "ground.exr")]) == 0
    sky_total = EquirectSky(io.read_image(tmp_path / "sky.exr")).image_irradiance()
    ground = io.read_image(tmp_path / "ground.exr")  # the sun window, 20..22 m: 17 m (3 tan 80) from the leaves
    assert np.ptp(ground[..., 1]) < 1e-3 * ground[..., 1].mean()  # open ground: no shadow
    assert ground.reshape(-1, 3).mean(axis=0) == pytest.approx(sky_total, rel=1e-2)
    direct, diffuse = reference_daylight(40.0, 4.0, 0.0)
    assert ground.reshape(-1, 3).mean(axis=0) @ LUMA == pytest.approx(direct + diffuse, rel=0.01)


# --- the one sky interface (base.Sky) ----------------------------------------------------------


def protocol_skies():
    """One sky of each model: uniform, an HDRI without and with a cut sun, procedural with clouds."""
    procedural = sun_sky(40.0, clouds=Overcast(glow=2.0))
    hdri = EquirectSky(procedural.equirect(256))
    return {"uniform": UniformSky(np.array([1.0, 2.0, 0.5])), "hdri": hdri, "hdri-sun": cut_sun(hdri),
            "procedural": procedural}


@pytest.mark.parametrize("name", ["uniform", "hdri", "hdri-sun", "procedural"])
def test_every_sky_model_implements_the_sky_protocol(name):
    sky = protocol_skies()[name]
    assert isinstance(sky, Sky)
    grid = sky_grid((-2, -2), (5, 5), 0.1)
    raster = sky.raster(grid)
    assert raster.weighted.shape == (3, 5, 5) and raster.irradiance.shape == (3,)
    folded = sky.raster(grid, fold_period=(2, 3))
    assert folded.weighted.shape == (3, 2, 3)
    assert folded.irradiance == pytest.approx(raster.irradiance, rel=1e-5)
    has_sun = sky.sun is not None
    assert has_sun == (name in ("hdri-sun", "procedural"))
    fraction = sky.sun_fraction()
    assert isinstance(fraction, float) and (0.0 < fraction <= 1.0 if has_sun else fraction == 0.0)
    sun = np.asarray(sky.undimmed_sun_irradiance())
    assert sun.shape == (3,) and (np.all(sun > 0) if has_sun else np.all(sun == 0))
    irradiance = np.asarray(sky.sky_irradiance)
    assert irradiance.shape == (3,) and np.all(irradiance > 0)
    w = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.6, 0.8]])
    s = w[:, :2] / w[:, 2:]
    for footprint in (None, 0.01, np.full((3, 2), 0.01)):
        radiance = np.asarray(sky.view_radiance(w, s, footprint))
        assert radiance.shape == (3, 3) and np.all(np.isfinite(radiance)) and np.all(radiance > 0)


def test_sky_protocol_values_keep_each_models_meaning():
    skies = protocol_skies()
    uniform = skies["uniform"]
    assert np.array_equal(uniform.sky_irradiance, np.pi * np.array([1.0, 2.0, 0.5]))
    w = np.array([[0.0, 0.0, 1.0], [0.8, 0.0, 0.6]])
    assert np.array_equal(uniform.view_radiance(w, w[:, :2] / w[:, 2:]), np.float32([[1.0, 2.0, 0.5]] * 2))
    for name in ("hdri", "hdri-sun"):
        hdri = skies[name]
        assert np.array_equal(hdri.sky_irradiance, hdri.image_irradiance())
        assert np.array_equal(hdri.undimmed_sun_irradiance(), hdri.sun_irradiance())
    assert skies["hdri-sun"].sun_fraction() == 1.0
    procedural = skies["procedural"]
    s = w[:, :2] / w[:, 2:]
    assert np.array_equal(procedural.view_radiance(w, s, 0.02), procedural.radiance(s, footprint=0.02))


@pytest.mark.parametrize("clouded", [False, True])
def test_the_compiled_sky_rows_have_the_bits_of_the_array_operations(clouded):
    # kernels.arrays.sky_rows against the numpy operations ProceduralSky.raster made before it
    rng = np.random.default_rng(7)
    rows, cols, nodes = 23, 31, 4
    along = rng.random((3, nodes, cols), dtype=np.float32) * 5.0
    row_at = np.minimum(np.arange(rows) // 8, nodes - 2)
    row_frac = rng.random(rows, dtype=np.float32)
    weights = rng.random((rows, cols), dtype=np.float32) * 1e-3
    transmittance = rng.random((rows, cols)) * 1.4 - 0.2  # clipped to [0, 1]
    glow = rng.random((rows, cols, 3), dtype=np.float32)
    f = row_frac[:, None]
    expected = along[:, row_at] * (1 - f) + along[:, row_at + 1] * f
    if clouded:
        expected *= np.clip(transmittance, 0.0, 1.0).astype(np.float32)
        expected += np.moveaxis(glow, -1, 0)
    expected = expected * weights
    out = np.empty((3, rows, cols), dtype=np.float32)
    for lo in (0, 10):  # in two parts, as the raster's bounded chunks
        part = slice(lo, 10 if lo == 0 else rows)
        _array_loops.sky_rows(along, row_at, row_frac, lo, len(row_at[part]), clouded,
                              np.ascontiguousarray(transmittance[part]), np.ascontiguousarray(glow[part]), weights, out)
    assert out.tobytes() == expected.tobytes()


def test_an_hdri_keeps_its_rasters_read_only():
    # a still image gives every frame the same raster: made once per grid and fold, not changed
    image = np.random.default_rng(8).random((32, 64, 3), dtype=np.float32)
    sky = EquirectSky(image)
    grid = sky_grid((-20, -20), (40, 40), 0.05)
    first = sky.raster(grid)
    assert sky.raster(grid) is first and not first.weighted.flags.writeable
    assert first.weighted.tobytes() == sky._raster(grid).weighted.tobytes()
    folded = sky.raster(grid, fold_period=(16, 16))
    assert folded is not first and folded.weighted.shape == (3, 16, 16)
    assert folded.weighted.tobytes() == sky._raster(grid, fold_period=(16, 16)).weighted.tobytes()
    other = sky.raster(sky_grid((-10, -10), (20, 20), 0.05))
    assert other.weighted.shape == (3, 20, 20) and sky.raster(grid) is first


def test_a_still_sky_keeps_its_raster_and_its_shape_at_a_cameras_points():
    """Without clouds a frame's procedural sky (a new object each frame, its time moved on) gets the
    raster kept from the frame before, read-only, the same as computed afresh, once a second frame
    has asked for it (a sky that moves asks once per key: nothing kept); another sun or a moon makes
    its own, and a sky with clouds keeps none. The clear sky's shape at read-only points (a still
    camera's) is kept the same way, and equals it computed at writable ones."""
    from pipeline.sky.raster import KEPT_RASTERS

    grid = square(30, 0.01)
    first = sun_sky(50.0)
    once = first.raster(grid)
    raster = replace(first, time=7.5).raster(grid)
    later = replace(first, time=15.0)
    assert raster is not once and later.raster(grid) is raster and not raster.weighted.flags.writeable
    assert once.weighted.flags.writeable
    np.testing.assert_array_equal(raster.weighted, once.weighted)
    np.testing.assert_array_equal(raster.weighted, later._raster(grid, None).weighted)
    moved = [sun_sky(51.0), sun_sky(50.0, moon=moon_at(first.sun, 0.004))]
    assert all(sky.raster(grid).weighted.flags.writeable for sky in moved)  # asked once: not kept
    assert all(sky.raster(grid) is not raster for sky in moved)
    assert sun_sky(50.0).raster(grid) is raster  # an equal sky, made again
    for k in range(KEPT_RASTERS):  # the oldest dropped once more skies are kept
        sun_sky(52.0 + k).raster(grid)
    assert sun_sky(50.0).raster(grid) is not raster
    cloudy = replace(first, clouds=_ConstantClouds())
    assert cloudy.raster(grid) is not cloudy.raster(grid)

    s = np.stack(np.meshgrid(np.linspace(-1, 1, 7), np.linspace(-0.5, 2, 5)), axis=-1)
    still = s.copy()
    still.flags.writeable = False
    asked = [sky._relative_sky(still) for sky in (first, later, replace(first, time=30.0))]
    assert asked[0] is not asked[1] and asked[2] is asked[1]  # kept when asked for again
    np.testing.assert_array_equal(later.clear_radiance(still), first.clear_radiance(s))
    assert sun_sky(40.0)._relative_sky(still) is not first._relative_sky(still)
    assert first._relative_sky(s) is not first._relative_sky(s)


class _ConstantClouds:
    """Clouds of transmittance 1/2 and no glow."""

    def transmittance(self, s, time, footprint=None):
        return np.full(np.shape(s)[:-1], 0.5)

    def radiance(self, s, time, **light):
        return np.zeros((*np.shape(s)[:-1], 3), dtype=np.float32)


def test_an_hdri_keeps_a_still_cameras_view():
    """An HDRI's view at read-only directions (a still camera's rays) is kept from the second frame
    that asks for it, read-only, and equals the lookup at the same directions given writable."""
    hdri = EquirectSky(sun_sky(40.0).equirect(64))
    w = np.stack(np.meshgrid(np.linspace(-0.9, 0.9, 9), np.linspace(-0.5, 0.5, 4)), axis=-1)
    w = np.concatenate([w, np.full((*w.shape[:-1], 1), 0.3)], axis=-1)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    still = w.copy()
    still.flags.writeable = False
    views = [hdri.view_radiance(still, None) for _ in range(3)]
    assert views[0] is not views[1] and views[2] is views[1] and not views[1].flags.writeable
    np.testing.assert_array_equal(views[1], hdri.view_radiance(w, None))
    assert hdri.view_radiance(w, None) is not hdri.view_radiance(w, None)


def test_a_still_suns_light_made_once_gives_the_same_bits_and_only_for_its_sun():
    sun, other = SunDisc(0.3, 0.5), SunDisc(0.3, 0.9)
    light = sun_light(sun, 3.0, 200.0)
    computed = ProceduralSky(turbidity=3.0, sun=sun, altitude=200.0)
    carried = ProceduralSky(turbidity=3.0, sun=sun, altitude=200.0, light=light)
    assert carried.sun_light is light and computed.sun_light is not light
    assert carried.sun_normal_irradiance.tobytes() == computed.sun_normal_irradiance.tobytes()
    assert carried.zenith_luminance == computed.zenith_luminance
    # a light of another sun, turbidity or altitude is not taken: the sky's own is computed
    for sky in (ProceduralSky(turbidity=3.0, sun=other, altitude=200.0, light=light),
                ProceduralSky(turbidity=4.0, sun=sun, altitude=200.0, light=light),
                ProceduralSky(turbidity=3.0, sun=sun, altitude=0.0, light=light)):
        assert sky.sun_light is not light
        assert sky.daylight == sun_light(sky.sun, sky.turbidity, sky.altitude).daylight
