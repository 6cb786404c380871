"""Absolute daylight: the Perez et al. (1990) efficacies against an independent implementation
(ladybug-core) and a worked example; the clear sky's levels against pvlib's Ineichen model; the
Linke turbidity climatology."""

from datetime import datetime, timezone

import numpy as np
import pandas as pd
import pytest
from ladybug.skymodel import estimate_illuminance_from_irradiance
from pvlib import atmosphere, clearsky

from pipeline.daylight import clear_daylight, linke_turbidity, perez_efficacy
from pipeline.resolve import load

from scenes import base_config, write_config, write_inputs


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
                am = atmosphere.get_absolute_airmass(atmosphere.get_relative_airmass(zenith), atmosphere.alt2pres(altitude))
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
    ((32.78, -96.80), datetime(2024, 4, 8, 18, 30, tzinfo=timezone.utc)),  # Dallas, April
    ((40.42, -3.70), datetime(2026, 8, 12, 18, 0, tzinfo=timezone.utc)),   # Madrid, August
])
def test_linke_turbidity_is_the_climatology(site, when):
    want = clearsky.lookup_linke_turbidity(pd.DatetimeIndex([when]), *site).iloc[0]
    got = linke_turbidity(when, np.radians(site[0]), np.radians(site[1]))
    assert got == pytest.approx(want, rel=1e-9)
    assert 1.5 < got < 7.0


def test_turbidity_auto_reads_the_climatology_of_the_site_and_month(tmp_path):
    write_inputs(tmp_path)
    config = base_config()
    config["sky"] = {"model": "cie", "turbidity": "auto", "alpha": 80.0,
                     "site": {"latitude": 32.78, "longitude": -96.80, "elevation": 140.0},
                     "time": {"start": "2024-04-08T18:20:00Z", "end": "2024-04-08T18:40:00Z"}}
    sky = load(write_config(tmp_path, config)).sky
    middle = datetime(2024, 4, 8, 18, 30, tzinfo=timezone.utc)
    assert sky.turbidity_auto
    assert sky.turbidity == pytest.approx(
        clearsky.lookup_linke_turbidity(pd.DatetimeIndex([middle]), 32.78, -96.80).iloc[0], rel=1e-9)
