"""The eclipse sky and the corona (pipeline/sky/eclipse.py, pipeline/sky/procedural.py), against independent
references: the ephemeris at a displaced site, quadrature of the corona's profile, the
published totality sky (docs/method.md, "The eclipse sky")."""

from datetime import UTC, datetime, timedelta
from functools import lru_cache

import numpy as np
import pytest
from scipy import integrate

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import direction_vector
from pipeline.sky import daylight, eclipse, ephemeris
from pipeline.sky.equirect import EquirectSky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import MoonDisc, SunDisc

DALLAS = ephemeris.Site.from_degrees(32.78, -96.80, 140.0)
STANLEY = ephemeris.Site.from_degrees(44.22, -114.94, 1900.0)  # Idaho, 2017 August 21: the sun 46.8 degrees up
Y = np.asarray(REC709_LUMINANCE, dtype=np.float64)
RGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
"""Linear Rec.709 (sRGB primaries, D65) to CIE XYZ: IEC 61966-2-1."""


@lru_cache(maxsize=2)
def second_and_third_contact(site, near):
    contacts = ephemeris.contact_times(site, near - timedelta(hours=1), near + timedelta(hours=1))
    return contacts["C2"], contacts["C3"]


C2, C3 = second_and_third_contact(DALLAS, datetime(2024, 4, 8, 18, 40, tzinfo=UTC))


def dallas_sky(when, *, moon=True):
    sun, m = ephemeris.sun_and_moon(DALLAS, when)
    disc = SunDisc(sun.azimuth, sun.elevation, sun.angular_radius)
    moon_disc = MoonDisc(m.azimuth, m.elevation, m.angular_radius) if moon else None
    return ProceduralSky(3.08, disc, moon=moon_disc, altitude=140.0)


def test_parallax_gives_the_ephemeris_at_a_displaced_site():
    # S at a point 80 km east and 60 km north, from the observer's sun and moon by parallax,
    # against ephem computed for an observer standing there (the ground curves away by d^2 / 2R)
    when = C2 - timedelta(minutes=3)
    sun, moon = ephemeris.sun_and_moon(DALLAS, when)
    east, north = 80e3, 60e3
    drop = (east**2 + north**2) / (2 * 6_371_000.0)
    point = np.array([east, north, -drop])
    lat = DALLAS.latitude + north / 6_371_000.0
    lon = DALLAS.longitude + east / (6_371_000.0 * np.cos(DALLAS.latitude))
    there_sun, there_moon = ephemeris.sun_and_moon(ephemeris.Site(lat, lon, DALLAS.elevation), when)
    expected = 1 - ephemeris.obscured_fraction(ephemeris.separation(there_sun, there_moon),
                                               there_sun.angular_radius, there_moon.angular_radius)
    here = 1 - ephemeris.obscured_fraction(ephemeris.separation(sun, moon), sun.angular_radius, moon.angular_radius)
    got = eclipse.point_sun_fraction(point, sun_direction=direction_vector(sun.azimuth, sun.elevation),
                                     moon_direction=direction_vector(moon.azimuth, moon.elevation),
                                     sun_radius=sun.angular_radius, moon_radius=moon.angular_radius)
    assert abs(expected - here) > 0.01  # the displacement matters ...
    assert got == pytest.approx(expected, abs=2e-3)  # ... and parallax gets it


def test_a_partial_eclipse_sky_is_exactly_the_clear_sky_times_s():
    # far outside the umbra (S = 0.3): the sky of before, the clear sky times S, to rounding
    sun = SunDisc(np.radians(150.0), np.radians(50.0))
    clear = ProceduralSky(3.0, sun)
    e1 = np.array([np.cos(sun.azimuth), -np.sin(sun.azimuth), 0.0])
    m = np.cos(0.004) * clear.sun_direction + np.sin(0.004) * e1
    moon = MoonDisc(float(np.arctan2(m[0], m[1])), float(np.arcsin(m[2])), 1.03 * sun.angular_radius)
    eclipsed = ProceduralSky(3.0, sun, moon=moon)
    assert eclipsed._deep == 0.0 and 0.2 < eclipsed.sun_fraction() < 0.5
    points = np.random.default_rng(1).uniform(-3, 3, (500, 2))
    np.testing.assert_allclose(eclipsed.radiance(points), clear.radiance(points) * eclipsed.moon_visible, rtol=1e-12)
    np.testing.assert_allclose(eclipsed.sky_irradiance, clear.sky_irradiance * eclipsed.moon_visible, rtol=1e-12)


def uncovered_by_rings(d, r, big_r):
    """The sun's uncovered area fraction ring by ring (quadrature; the lens formula not used): the
    ring of radius rho is covered over arccos((rho^2 + d^2 - R^2) / (2 rho d)) / pi of its length."""
    def ring(rho):
        return 2 * rho * (1 - np.arccos(np.clip((rho**2 + d**2 - big_r**2) / (2 * rho * d), -1, 1)) / np.pi)

    kink = big_r - d
    return integrate.quad(ring, kink, r, epsabs=1e-13, epsrel=1e-10)[0] / r**2


def test_the_blend_into_the_deep_eclipse_starts_at_99_8_percent_of_the_area():
    # b = (1 - u / 0.002)^3 of the uncovered area u, exactly 0 from u = 0.002 up (the partial
    # sky's own code path) ...
    u = np.linspace(0.0, 0.004, 81)
    b = np.array([eclipse.deep_weight(v) for v in u])
    assert np.all(b[u >= eclipse.SHARP_LIMIT] == 0.0) and eclipse.deep_weight(1.0) == 0.0
    assert eclipse.deep_weight(0.0) == 1.0 and np.all(np.diff(b[u <= eclipse.SHARP_LIMIT]) < 0)
    np.testing.assert_allclose(b, np.clip(1 - u / 0.002, 0, 1) ** 3, rtol=1e-12, atol=0)
    # ... and a sky at 99.79% of the sun's area covered, where limb darkening leaves S = 0.0012 of
    # the light (under 0.002), is still exactly the clear sky times S; at 99.81% the blend has begun
    from scipy.optimize import brentq

    sun = SunDisc(np.radians(150.0), np.radians(50.0))
    r, big_r = sun.angular_radius, 1.03 * sun.angular_radius
    clear = ProceduralSky(3.0, sun)
    e1 = np.array([np.cos(sun.azimuth), -np.sin(sun.azimuth), 0.0])

    def sky_at(uncovered):
        d = brentq(lambda d: uncovered_by_rings(d, r, big_r) - uncovered, big_r - r + 1e-12, big_r)
        m = np.cos(d) * clear.sun_direction + np.sin(d) * e1
        return ProceduralSky(3.0, sun, moon=MoonDisc(float(np.arctan2(m[0], m[1])), float(np.arcsin(m[2])), big_r))

    shallow, deep = sky_at(0.0021), sky_at(0.0019)
    assert shallow._deep == 0.0 and shallow.sun_fraction() < 0.0015
    points = np.random.default_rng(2).uniform(-3, 3, (200, 2))
    np.testing.assert_allclose(shallow.radiance(points), clear.radiance(points) * shallow.moon_visible, rtol=1e-12)
    assert deep._deep == pytest.approx((1 - 0.0019 / 0.002) ** 3, rel=1e-4)


def test_corona_profile_integral():
    def flux(a, b):
        return 2 * integrate.quad(lambda r: r * eclipse.corona_profile(r), a, b, limit=200, epsabs=0.0, epsrel=1e-10)[0]

    numeric = flux(1.0, 2.0) + flux(2.0, 100.0) + flux(100.0, np.inf)
    assert eclipse.corona_beyond(1.0) == pytest.approx(numeric, rel=1e-6)
    assert eclipse.corona_beyond(1.0) == pytest.approx(1.1e-6, rel=0.05)  # about half a full moon
    tail = flux(1.05, 2.0) + flux(2.0, 30.0)
    assert eclipse.corona_beyond(1.05) - eclipse.corona_beyond(30.0) == pytest.approx(tail, rel=1e-6)
    drawn = 2 * integrate.quad(lambda r: r * eclipse.corona_drawn(r), 1.05, eclipse.CORONA_REACH,
                               limit=200, epsabs=0.0, epsrel=1e-10)[0]
    assert eclipse.corona_drawn_beyond(1.05) == pytest.approx(drawn, rel=1e-6)
    assert eclipse.corona_drawn(eclipse.CORONA_REACH * (1 - 1e-9)) == pytest.approx(0.0, abs=1e-18)


@lru_cache(maxsize=1)
def totality():
    return dallas_sky(C2 + (C3 - C2) / 2)


def test_the_corona_in_the_raster_and_the_equirect_keeps_its_light():
    sky = totality()
    assert sky._deep == 1.0 and sky.sun_fraction() == 0.0
    expected = sky.corona_irradiance  # as drawn: out to CORONA_REACH solar radii, with no edge
    # cells of the sky raster near the sun, without the sky: the corona alone
    from pipeline.core.geometry import sky_grid

    q = 2e-3
    centre = sky.sun_point / q
    grid = sky_grid((int(-centre[1]) - 60, int(centre[0]) - 60), (120, 120), q)
    _idx, cells = sky._corona_cells(grid)
    assert cells.sum(axis=1) == pytest.approx(expected, rel=0.015)  # 8 x 8 samples of the steep inner corona
    image = np.zeros((256, 512, 3))
    sky._deposit(image, sky.corona_radiance, eclipse.CORONA_REACH * sky.sun.angular_radius,
                 sky.sun.angular_radius / 16)
    assert EquirectSky(image.astype(np.float32)).image_irradiance() == pytest.approx(expected, rel=0.01)


def chromaticity_x(rgb):
    xyz = RGB_TO_XYZ @ rgb
    return xyz[0] / xyz.sum()


@pytest.mark.parametrize("site, near", [(DALLAS, datetime(2024, 4, 8, 18, 40, tzinfo=UTC)),
                                        (STANLEY, datetime(2017, 8, 21, 17, 30, tzinfo=UTC))])
def test_the_totality_sky_is_as_measured(site, near):
    # mid-totality with the sun 45-65 degrees up, against the published bands (docs/method.md, "The
    # eclipse sky"): zenith 0.8e-4 to 4e-4 of the day's (Sharp et al. 1971, Shaw 1975, Dandekar &
    # Turtle 1971, Bolivia 1966) and 0.5-1.2 cd/m^2 (Idaho 2017's sky-quality meters); open ground
    # 1-5 lx; the zenith bluer than the day's (Dandekar & Turtle); the band 0-8 degrees above the
    # horizon reddened as at sunset: at least 2.5 times the day's band's red/blue (docs/method.md)
    c2, c3 = second_and_third_contact(site, near)
    middle = c2 + (c3 - c2) / 2
    sun, moon = ephemeris.sun_and_moon(site, middle)
    disc = SunDisc(sun.azimuth, sun.elevation, sun.angular_radius)
    turbidity = daylight.linke_turbidity(middle, site.latitude, site.longitude)
    sky = ProceduralSky(turbidity, disc, moon=MoonDisc(moon.azimuth, moon.elevation, moon.angular_radius),
                        altitude=site.elevation)
    day = ProceduralSky(turbidity, disc, altitude=site.elevation)
    assert sky._deep == 1.0 and 45 < np.degrees(sun.elevation) < 65
    zenith, day_zenith = (s.clear_radiance(np.zeros((1, 2)))[0] for s in (sky, day))
    assert 0.5 <= 1e3 * zenith @ Y <= 1.2
    assert 0.8e-4 <= (zenith @ Y) / (day_zenith @ Y) <= 4e-4
    image = sky.equirect(256).astype(np.float64)  # its own quadrature of the same sky
    lux = 1e3 * EquirectSky(image.astype(np.float32)).image_irradiance() @ Y
    assert 1.0 <= lux <= 5.0
    assert 1e3 * sky.sky_irradiance @ Y == pytest.approx(lux, rel=0.03)
    assert zenith[2] / zenith[0] > day_zenith[2] / day_zenith[0]  # bluer: more blue for its red ...
    assert chromaticity_x(zenith) < chromaticity_x(day_zenith)  # ... and towards the blue in CIE x
    azimuths = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    band = np.stack([np.sin(azimuths), np.cos(azimuths)], axis=-1) / np.tan(np.radians(4.0))
    red_blue, day_red_blue = ((lambda v: v[0] / v[2])(s.clear_radiance(band).mean(axis=0)) for s in (sky, day))
    assert red_blue >= 2.5 * day_red_blue  # 4.1 at Dallas, 3.3 at Stanley (docs/accuracy.md, "The eclipse sky")


def test_the_way_in_is_the_chance_of_one_scattering_on_the_sideways_path():
    # way_in: the share of light crossing DIFFUSION_LENGTH sideways at a point's height that is
    # scattered there once and not again: Poisson's probability of exactly one event; the
    # ground's dense air takes almost none, a few kilometres up the most (tau = 1)
    from scipy import stats

    rayleigh, aerosol = eclipse.vertical_optical_depths(3.08)
    heights = np.array([0.0, 1e3, 3e3, 5e3, 8e3, 15e3])[:, None]
    extinction = (rayleigh / eclipse.RAYLEIGH_SCALE_HEIGHT * np.exp(-heights / eclipse.RAYLEIGH_SCALE_HEIGHT)
                  + aerosol / eclipse.AEROSOL_SCALE_HEIGHT * np.exp(-heights / eclipse.AEROSOL_SCALE_HEIGHT))
    share = eclipse.way_in(extinction)
    np.testing.assert_allclose(share, stats.poisson.pmf(1, extinction * eclipse.DIFFUSION_LENGTH), rtol=1e-12)
    assert np.all(share[0] < 1e-5) and np.all(share[0, 0] > share[0, 1:])  # the ground: dark, reddest
    assert np.all(np.argmax(share, axis=0) == [3, 3, 4])  # the most at 5 km, blue's higher up ...
    assert np.all(share[3] > 0.3) and share[5, 2] > share[5, 0]  # ... and above, blue before red


def test_the_sky_light_bends_smoothly_into_the_deep_eclipse():
    # the totality demo's sky light as light.csv gives it (the meter's coarser table: within 0.5%
    # of it, smoothly): no second difference of its log above 0.015 a frame from S = 0.01 to S =
    # 0.0005 on either side of totality (with the linear blend of before: 0.053 where it starts)
    from pathlib import Path

    from pipeline.stages.lighting import open_ground_light
    from pipeline.stages.resolve import load
    from pipeline.stages.scene import load_sky, scene_at

    config = load(Path(__file__).resolve().parents[1] / "configs" / "eclipse-2024-dallas-totality.yaml")
    s = np.array([load_sky(config.sky, scene_at(config, n)).sun_fraction() for n in range(config.animation.frames)])
    inside = np.flatnonzero((s >= 0.0005) & (s <= 0.01))
    inside = inside[(inside > 0) & (inside < len(s) - 1)]  # with both neighbours in the film
    frames = np.unique(np.concatenate([inside - 1, inside, inside + 1]))
    light = {int(n): open_ground_light(load_sky(config.sky, scene_at(config, int(n)), metering=True), 1.0,
                                       None)["sky_lux"] for n in frames}
    bends = [np.log(light[n + 1]) - 2 * np.log(light[n]) + np.log(light[n - 1]) for n in inside]
    deepest = int(inside[np.argmin(s[inside])])  # the blend is under way in the range (b 0.14 at S = 0.00055)
    assert load_sky(config.sky, scene_at(config, deepest))._deep > 0.1
    assert np.max(np.abs(bends)) <= 0.015


def test_the_light_falls_smoothly_into_totality_and_rises_after():
    # open ground (sun times S plus the sky) every 5 s through second and third contact; the
    # moon placed about the mid-totality sun at its true offset from the sun of the moment, so
    # that the clear sky's shape is computed once (the sun moves 0.03 degrees in 2 minutes)
    from pipeline.core.geometry import offset_direction

    fixed = totality().sun

    def light(when):
        sun, moon = ephemeris.sun_and_moon(DALLAS, when)
        dx, dy = ephemeris.moon_offset_from_sun(sun, moon)
        azimuth, elevation = offset_direction(fixed.azimuth, fixed.elevation, dx, dy)
        sky = ProceduralSky(3.08, fixed, moon=MoonDisc(azimuth, elevation, moon.angular_radius), altitude=140.0)
        return float(sky.sky_irradiance @ Y), float(sky.sun_fraction() * sky.undimmed_sun_irradiance() @ Y)

    sky_before, sun_before = np.array([light(C2 + timedelta(seconds=t)) for t in range(-60, 11, 5)]).T
    sky_after, sun_after = np.array([light(C3 + timedelta(seconds=t)) for t in range(-10, 61, 5)]).T
    before, after = sky_before + sun_before, sky_after + sun_after
    # two decades from a minute before C2 to C2 (published: 2 to 2.5)
    assert before[0] / before[12] > 100
    assert np.all(np.diff(before) < 0) and np.all(np.diff(after) > 0)
    # the sun's last sliver goes in the last seconds; the sky follows with no step (its steepest
    # 5 s, at the contacts themselves: 1.50 and 1.54 times, where the open ground's light changes
    # 4.4 and 4.8 times)
    assert np.max(sky_before[:-1] / sky_before[1:]) < 1.8 and np.max(sky_after[1:] / sky_after[:-1]) < 1.8


def test_the_totality_config_brings_totality_up_to_dusk_not_black():
    # the shipped config's auto exposure follows the light of mid-totality (about 15.5 stops
    # under the day) up to its most, 11 stops: a white ground at totality is then exposed 2 to 6
    # stops under the day's (dusk: darker than the crescent frames, not black), where the
    # day's is exposed at 2^stops
    from pathlib import Path

    from pipeline.camera import composite
    from pipeline.stages.resolve import load

    config = load(Path(__file__).resolve().parents[1] / "configs" / "eclipse-2024-dallas-totality.yaml")
    auto = config.camera.auto_exposure
    sky, day = totality(), dallas_sky(C2 + (C3 - C2) / 2, moon=False)
    reference = day.sky_irradiance + day.undimmed_sun_irradiance()
    readings = np.geomspace(reference, sky.sky_irradiance, 60)  # four and a half decades down
    readings = np.concatenate([readings, np.repeat(readings[-1:], 40, axis=0)])
    exposure = composite.auto_exposure(readings, reference=reference, frame_time=1 / 24,
                                       time_constant=auto.time_constant, limits=auto.limits,
                                       stops=config.camera.exposure)
    day_white = exposure[0] * (readings[0] @ Y) / np.pi  # the day's white ground, exposed
    white = exposure[-1] * (readings[-1] @ Y) / np.pi  # the same ground at totality
    assert day_white == pytest.approx(2.0**config.camera.exposure, rel=1e-3)
    assert exposure[-1] == pytest.approx(composite.exposure_for(reference)
                                         * 2.0**(auto.limits[1] + config.camera.exposure),
                                         rel=1e-9)  # held at its most
    assert 2.0**-6 < white / day_white < 2.0**-2


def test_the_crescents_are_reversed_after_third_contact():
    # the lit sliver of the sun (its kernel's centroid from the disc's centre) lies on the far
    # side 20 s after C3 from where it was 20 s before C2 (131 degrees round at Dallas, off the
    # centre line: the moon's path misses the sun's centre): the pinhole images turn round
    from pipeline.sky.sun_kernel import sun_kernel

    def sliver(when):
        sky = dallas_sky(when)
        kernel = sun_kernel(sky, sky.sun.angular_radius / 8)
        weight = kernel.weighted[1]
        rows, cols = np.indices(weight.shape)
        x, y = kernel.grid.ground_from_raster(rows, cols)
        centre = np.array([(weight * x).sum(), (weight * y).sum()]) / weight.sum()
        return (centre - sky.sun_point) / sky.sun.angular_radius

    before, after = sliver(C2 - timedelta(seconds=20)), sliver(C3 + timedelta(seconds=20))
    assert np.linalg.norm(before) > 0.5 and np.linalg.norm(after) > 0.5  # thin slivers near the limb
    assert before @ after / (np.linalg.norm(before) * np.linalg.norm(after)) < -0.5


def test_the_meters_coarser_table_reads_the_deep_eclipse_sky_as_the_full_one():
    # an exposure meter reads the whole sky's horizontal light only: from the coarser
    # METER_TABLE it is within 0.5% of the full table's (0.35% at worst over C2 to C3 at Dallas),
    # at second contact, mid-totality and just before third contact
    from dataclasses import replace

    for when in (C2 + timedelta(seconds=3), C2 + (C3 - C2) / 2, C3 - timedelta(seconds=5)):
        full = dallas_sky(when)
        coarse = replace(full, eclipse_table=eclipse.METER_TABLE)
        assert full._deep == 1.0 and coarse._eclipse_field.table.shape == (17, 37, 6)
        assert np.asarray(coarse.sky_irradiance) == pytest.approx(np.asarray(full.sky_irradiance), rel=5e-3)
