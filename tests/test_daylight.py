"""Absolute daylight: the Perez et al. (1990) efficacies against an independent implementation
(ladybug-core) and a worked example; the clear sky's levels against pvlib's Ineichen model; the
Linke turbidity climatology."""

from datetime import UTC, datetime

import numpy as np
import pandas as pd
import pytest
from ladybug.skymodel import estimate_illuminance_from_irradiance
from pvlib import atmosphere, clearsky
from scenes import base_config, write_config, write_inputs

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky.daylight import clear_daylight, linke_turbidity, perez_efficacy
from pipeline.stages.resolve import load


def dew_point_for(water):
    """ladybug reads the precipitable water from the dew point, W = exp(0.08 Td - 0.075). [cm] -> [C]"""
    return (np.log(water) + 0.075) / 0.08


def test_perez_efficacy_matches_ladybug_across_skies():
    rng = np.random.default_rng(3)
    for _ in range(300):
        elevation = rng.uniform(3.0, 89.0)
        zenith = np.radians(90.0 - elevation)
        dhi = rng.uniform(20.0, 400.0)
        dni = rng.uniform(0.0, 1000.0)
        water = rng.uniform(0.3, 5.0)
        airmass = float(atmosphere.get_relative_airmass(90.0 - elevation, "kastenyoung1989"))
        ghi = dhi + dni * np.cos(zenith)
        gh, dn, dh, _ = estimate_illuminance_from_irradiance(elevation, ghi, dni, dhi, dew_point_for(water),
                                                              rel_airmass=airmass)
        ours = perez_efficacy(zenith, dni, dhi, relative_airmass=airmass, extraterrestrial=1360.0,
                              precipitable_water=water)
        assert ours.global_horizontal * ghi == pytest.approx(gh, rel=2e-3)
        assert ours.direct_normal * dni == pytest.approx(dn, rel=2e-3, abs=1e-6)
        assert ours.diffuse_horizontal * dhi == pytest.approx(dh, rel=2e-3)


def test_perez_efficacy_worked_example():
    # Sun at 30 degrees zenith, 800 W/m2 direct normal, 100 W/m2 diffuse, m = 1.154, I0 = 1367,
    # W = 2 cm. By hand: epsilon = (9 + 1.041 z^3) / (1 + 1.041 z^3) = 7.960 (z = 0.5236): the
    # clear bin 8 of Table 4; Delta = 100 x 1.154 / 1367 = 0.08442.
    # Direct: 101.18 + 1.58 x 2 - 1.10 exp(5.73 z - 5) - 8.29 Delta = 103.49 lm/W.
    # Diffuse: 152.23 + 0.35 x 2 - 45.27 cos z - 7.98 ln(Delta) = 133.45 lm/W.
    e = perez_efficacy(np.radians(30.0), 800.0, 100.0, relative_airmass=1.154, extraterrestrial=1367.0,
                       precipitable_water=2.0)
    assert e.clearness == pytest.approx(7.960, abs=1e-3)
    assert e.brightness == pytest.approx(0.08442, abs=1e-5)
    assert e.direct_normal == pytest.approx(103.49, abs=0.01)
    assert e.diffuse_horizontal == pytest.approx(133.45, abs=0.01)


def test_clear_daylight_is_ineichen_in_illuminance():
    for turbidity in (2.0, 3.0, 6.0):
        for elevation in (5.0, 30.0, 75.0):
            for altitude in (0.0, 1600.0):
                zenith = 90.0 - elevation
                am = atmosphere.get_absolute_airmass(atmosphere.get_relative_airmass(zenith),
                                                     atmosphere.alt2pres(altitude))
                ref = clearsky.ineichen(zenith, am, turbidity, altitude=altitude, dni_extra=1366.1)
                got = clear_daylight(np.radians(zenith), turbidity, altitude=altitude)
                assert got.direct_normal_irradiance == pytest.approx(float(ref["dni"]), rel=1e-9)
                assert got.diffuse_horizontal_irradiance == pytest.approx(float(ref["dhi"]), rel=1e-9)
                # clear skies: 90 to 110 lm/W direct above 20 degrees, 110 to 190 lm/W diffuse, the
                # most for a low sun (clear-sky efficacies reviewed by Littlefair 1985, Lighting Res.
                # Technol. 17(4), 162-182)
                direct = got.direct_normal_illuminance / got.direct_normal_irradiance * 1000
                diffuse = got.diffuse_horizontal_illuminance / got.diffuse_horizontal_irradiance * 1000
                assert 110 < diffuse < 190
                if elevation > 20:
                    assert 90 < direct < 110
    # thinner air at altitude: more direct light
    assert clear_daylight(np.radians(40.0), 3.0, altitude=2000.0).direct_normal_illuminance > \
        clear_daylight(np.radians(40.0), 3.0).direct_normal_illuminance


@pytest.mark.parametrize("site, when", [
    ((32.78, -96.80), datetime(2024, 4, 8, 18, 30, tzinfo=UTC)),  # Dallas, April
    ((40.42, -3.70), datetime(2026, 8, 12, 18, 0, tzinfo=UTC)),   # Madrid, August
])
@pytest.mark.filterwarnings("ignore:DatetimeIndex.dayofyear")  # pandas 3 on pvlib's own call (the reference)
def test_linke_turbidity_is_the_climatology(site, when):
    want = clearsky.lookup_linke_turbidity(pd.DatetimeIndex([when]), *site).iloc[0]
    got = linke_turbidity(when, np.radians(site[0]), np.radians(site[1]))
    assert got == pytest.approx(want, rel=1e-9)
    assert 1.5 < got < 7.0


@pytest.mark.filterwarnings("ignore:DatetimeIndex.dayofyear")  # pandas 3 on pvlib's own call (the reference)
def test_turbidity_auto_reads_the_climatology_of_the_site_and_month(tmp_path):
    write_inputs(tmp_path)
    config = base_config()
    config["sky"] = {"model": "cie", "turbidity": "auto", "alpha": 80.0,
                     "site": {"latitude": 32.78, "longitude": -96.80, "elevation": 140.0},
                     "time": {"start": "2024-04-08T18:20:00Z", "end": "2024-04-08T18:40:00Z"}}
    sky = load(write_config(tmp_path, config)).sky
    middle = datetime(2024, 4, 8, 18, 30, tzinfo=UTC)
    assert sky.turbidity_auto
    assert sky.turbidity == pytest.approx(
        clearsky.lookup_linke_turbidity(pd.DatetimeIndex([middle]), 32.78, -96.80).iloc[0], rel=1e-9)


# --- low sun and civil twilight -----------------------------------------------------------------
# The USNO sun illuminance curve (Janiczek & DeYoung 1987, USNO Circular 171), typed in here from
# Vallado, Fundamentals of Astrodynamics and Applications, Table 5-1, for the bands from -12 to
# 20 degrees: (lower bound [deg], L0..L3), log10 E [lx] = L0 + L1 x + L2 x^2 + L3 x^3, x = h / 90.
USNO_BANDS = ((5.0, (3.05, 13.28, -45.98, 64.33)), (-0.8, (2.88, 22.26, -207.64, 1034.30)),
              (-5.0, (2.88, 21.81, -258.11, -858.36)), (-12.0, (2.70, 12.17, -431.69, -1899.83)))


def usno_table(h):
    _lower, (l0, l1, l2, l3) = next(band for band in USNO_BANDS if h >= band[0])
    x = h / 90.0
    return 10.0 ** (l0 + l1 * x + l2 * x**2 + l3 * x**3)


def open_ground_lux(elevation_deg, turbidity):
    """Horizontal illuminance of the procedural sky and its sun on open ground. [lx]"""
    from pipeline.sky.procedural import ProceduralSky
    from pipeline.sky.sun_disc import SunDisc

    sky = ProceduralSky(turbidity, SunDisc(np.radians(250.0), np.radians(elevation_deg)))
    return 1000.0 * float((sky.sky_irradiance + sky.undimmed_sun_irradiance()) @ REC709_LUMINANCE)


def test_the_usno_curve_meets_the_ams_glossary_at_sunset_and_the_end_of_civil_twilight():
    """AMS Glossary of Meteorology, "civil twilight": about 410-585 lx at sunset (the sun's centre
    0.83 degrees down) and 2-3.5 lx at -6 degrees; the module's curve and the table typed in here agree."""
    from pipeline.sky.daylight import usno_illuminance

    assert 410.0 <= usno_illuminance(-0.83) <= 585.0
    assert 2.0 <= usno_illuminance(-6.0) <= 3.5
    for h in np.arange(-6.0, 10.01, 0.5):
        assert usno_illuminance(h) == pytest.approx(usno_table(h), rel=1e-9)


@pytest.mark.parametrize("turbidity", [2.0, 3.0, 4.5])
def test_open_ground_follows_the_usno_curve_from_10_degrees_to_civil_twilight(turbidity):
    for h in range(10, -7, -1):
        ratio = open_ground_lux(h, turbidity) / usno_table(h)
        assert 1 / 1.5 <= ratio <= 1.5, (h, ratio)


@pytest.mark.parametrize("turbidity", [2.0, 3.0, 4.5, 10.0])
def test_twilight_light_has_no_step_over_10_percent_a_tenth_of_a_degree(turbidity):
    """Each tenth of a degree from 10 down to -6 gets at least 0.9 of the light of its neighbour above."""
    from pipeline.sky.daylight import sky_daylight

    def lux(h):
        d = sky_daylight(np.radians(h), turbidity)
        return d.direct_normal_illuminance * max(np.sin(np.radians(h)), 0.0) + d.diffuse_horizontal_illuminance

    tenths = np.arange(-60, 101) / 10.0
    light = np.array([lux(h) for h in tenths])
    assert np.all(light[:-1] >= 0.9 * light[1:]), tenths[np.argmin(light[:-1] / light[1:])]
    # the curve itself does not: it falls 10-12% a tenth below -3.3 degrees
    curve = np.array([usno_table(h) for h in tenths])
    assert np.min(curve[:-1] / curve[1:]) < 0.895


def test_the_capped_curve_is_the_lowest_at_or_above_usno_that_falls_no_faster_than_the_cap():
    """Against the table typed in here: the capped curve is USNO's from -4 degrees up, never under
    it, never falls faster than TWILIGHT_MAX_FALL, and where it is above the curve it falls at
    exactly that rate (so it is the lowest such curve); within 1.2 of USNO at -6 degrees."""
    from pipeline.sky.daylight import TWILIGHT_MAX_FALL, twilight_illuminance

    h = np.arange(-6000, 10001) / 1000.0
    capped = twilight_illuminance(h)
    curve = np.array([usno_table(x) for x in h])
    # the curve's bands meet with a jump of 0.9% at 5 degrees, which the cap ramps over below it
    # and its 0.001-degree grid may put on either side
    assert np.all(capped >= curve * (1 - 1e-3))
    assert np.allclose(capped[h >= -4.0], curve[h >= -4.0], rtol=1e-2, atol=0.0)
    slope = np.diff(np.log(capped)) / 0.001
    assert np.max(slope) <= TWILIGHT_MAX_FALL * (1 + 1e-6)
    above = (capped[:-1] > curve[:-1] * 1.001) & (capped[1:] > curve[1:] * 1.001)
    assert above.any() and np.allclose(slope[above], TWILIGHT_MAX_FALL, rtol=1e-6)
    assert 1.0 < capped[0] / curve[0] < 1.2


def test_above_the_blend_the_sky_is_ineichen_perez_and_below_twilight_an_error():
    from pipeline.sky.daylight import clear_daylight, sky_daylight
    from pipeline.sky.procedural import ProceduralSky
    from pipeline.sky.sun_disc import SunDisc

    assert sky_daylight(np.radians(10.0), 3.0) == clear_daylight(np.radians(80.0), 3.0)
    with pytest.raises(ValueError, match=r"-6\.50 degrees"):
        ProceduralSky(3.0, SunDisc(0.0, np.radians(-6.5)))


def test_low_sun_colours_warm_sun_and_horizon_blue_zenith():
    """At 2 degrees the sun (its air mass about 19) is redder than at 30, the horizon under the sun
    warmer than D65 and the zenith bluer; after sunset the sky under the sun stays the brightest."""
    from pipeline.core.colour import XYZ_TO_REC709
    from pipeline.sky.procedural import ProceduralSky
    from pipeline.sky.sun_disc import SunDisc
    from pipeline.sky.sun_kernel import sun_irradiance

    def xy(rgb):
        X, Y, Z = np.linalg.solve(XYZ_TO_REC709, np.asarray(rgb, dtype=np.float64))
        return np.array([X, Y]) / (X + Y + Z)

    low, high = (ProceduralSky(3.0, SunDisc(np.radians(250.0), np.radians(h))) for h in (2.0, 30.0))
    assert xy(low.sun_normal_irradiance)[0] > xy(high.sun_normal_irradiance)[0] + 0.05
    under_sun = 50.0 * np.array([np.sin(np.radians(250.0)), np.cos(np.radians(250.0))])
    assert xy(low.clear_radiance(under_sun))[0] > 0.3127 + 0.05
    assert xy(low.clear_radiance(np.zeros(2)))[0] < 0.3127 - 0.02
    dusk = ProceduralSky(3.0, SunDisc(np.radians(250.0), np.radians(-4.0)))
    around = [dusk.clear_radiance(50.0 * np.array([np.sin(a), np.cos(a)])) @ REC709_LUMINANCE
              for a in np.radians(np.arange(0.0, 360.0, 30.0) + 250.0)]
    assert np.argmax(around) == 0 and around[0] > 10 * (dusk.clear_radiance(np.zeros(2)) @ REC709_LUMINANCE)
    assert dusk.sun_fraction() == 0.0 and not sun_irradiance(dusk).any()
