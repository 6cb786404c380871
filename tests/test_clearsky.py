"""The clear sky's shape: the CIE standard general sky against ISO 15469 written out here, and
Preetham's shape and colour."""

import numpy as np
import pytest

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky.clearsky import (
    CIE_TYPES,
    cie_relative_luminance,
    preetham_relative,
    relative_sky,
    zenith_chromaticity,
)

# ISO 15469:2004 / CIE S 011/E:2003, Table 1 (gradation groups I-VI: a, b), Table 2 (indicatrix
# groups 1-6: c, d, e) and Table 3 (type: gradation, indicatrix), typed in from the standard.
ISO_GRADATION = {"I": (4.0, -0.70), "II": (1.1, -0.8), "III": (0.0, -1.0), "IV": (-1.0, -0.55),
                 "V": (-1.0, -0.32), "VI": (-1.0, -0.15)}
ISO_INDICATRIX = {1: (0.0, -1.0, 0.0), 2: (2.0, -1.5, 0.15), 3: (5.0, -2.5, 0.3), 4: (10.0, -3.0, 0.45),
                  5: (16.0, -3.0, 0.3), 6: (24.0, -2.8, 0.15)}
ISO_TYPES = {1: ("I", 1), 2: ("I", 2), 3: ("II", 1), 4: ("II", 2), 5: ("III", 1), 6: ("III", 2),
             7: ("III", 3), 8: ("III", 4), 9: ("IV", 2), 10: ("IV", 3), 11: ("IV", 4), 12: ("V", 4),
             13: ("V", 5), 14: ("VI", 5), 15: ("VI", 6)}


def iso_relative_luminance(sky_type, zenith, azimuth, sun_zenith, sun_azimuth):
    """L / Lz of ISO 15469, eqs. (1)-(4), with chi from the spherical cosine rule (all in radians)."""
    a, b = ISO_GRADATION[ISO_TYPES[sky_type][0]]
    c, d, e = ISO_INDICATRIX[ISO_TYPES[sky_type][1]]
    chi = np.arccos(np.cos(sun_zenith) * np.cos(zenith)
                    + np.sin(sun_zenith) * np.sin(zenith) * np.cos(abs(azimuth - sun_azimuth)))

    def phi(z):
        return 1 + a * np.exp(b / np.cos(z)) if z < np.pi / 2 else 1.0

    def f(x):
        return 1 + c * (np.exp(d * x) - np.exp(d * np.pi / 2)) + e * np.cos(x) ** 2

    return f(chi) * phi(zenith) / (f(sun_zenith) * phi(0.0))


DIRECTIONS = [(z, a) for z in (0.0, 15.0, 40.0, 65.0, 85.0, 90.0) for a in (10.0, 170.0)]  # a dozen, degrees


@pytest.mark.parametrize("sky_type", range(1, 16))
def test_cie_types_follow_iso_15469(sky_type):
    sun_zenith, sun_azimuth = np.radians(35.0), np.radians(150.0)
    for zenith, azimuth in DIRECTIONS:
        z, a = np.radians(zenith), np.radians(azimuth)
        w = np.array([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)])
        s = np.array([np.sin(sun_zenith) * np.sin(sun_azimuth), np.sin(sun_zenith) * np.cos(sun_azimuth),
                      np.cos(sun_zenith)])
        gamma = np.arccos(np.clip(w @ s, -1, 1))
        got = cie_relative_luminance(np.cos(z), gamma, sun_zenith=sun_zenith, cie_type=sky_type)
        want = iso_relative_luminance(sky_type, z, a, sun_zenith, sun_azimuth)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12), (zenith, azimuth)
    assert set(CIE_TYPES) == set(range(1, 16))


def test_clear_types_brighten_round_the_sun_and_overcast_ones_at_the_zenith():
    sun_zenith = np.radians(40.0)
    near_sun = cie_relative_luminance(np.cos(sun_zenith), np.radians(5.0), sun_zenith=sun_zenith, cie_type=12)
    assert near_sun > 3.0  # circumsolar brightening of the clear sky
    horizon = cie_relative_luminance(0.0, np.radians(120.0), sun_zenith=sun_zenith, cie_type=1)
    assert horizon == pytest.approx(1 / 3, rel=0.02)  # type 1, the old CIE overcast sky: 1:3 horizon to zenith


def test_preetham_shape_is_one_at_the_zenith_and_blue():
    T, theta_s = 3.0, np.radians(40.0)
    Y, x, y = preetham_relative(1.0, theta_s, turbidity=T, sun_zenith=theta_s)
    assert Y == pytest.approx(1.0)
    assert (x, y) == pytest.approx(zenith_chromaticity(T, theta_s))
    assert 0.22 < x < 0.3127 and 0.22 < y < 0.329  # bluer than D65 (0.3127, 0.3290)
    rgb = relative_sky(1.0, theta_s, sun_zenith=theta_s, turbidity=T, shape="preetham")
    assert rgb @ np.asarray(REC709_LUMINANCE) == pytest.approx(1.0, rel=1e-4)  # Rec.709 luminance is Y
    assert rgb[2] > rgb[0]
    cie = relative_sky(1.0, theta_s, sun_zenith=theta_s, turbidity=T, shape="cie", cie_type=12)
    assert cie @ np.asarray(REC709_LUMINANCE) == pytest.approx(1.0, rel=1e-4)
    with pytest.raises(ValueError, match="valid: cie, preetham"):
        relative_sky(1.0, theta_s, sun_zenith=theta_s, turbidity=T, shape="perez")


# CIE 15:2004, Table T.1 (and ISO 11664-2): the tabulated chromaticities of the CIE illuminants,
# typed in from the standard, not computed with the D-series formula.
CIE_TABLE_XY = {5003.0: (0.34567, 0.35850), 6504.0: (0.31271, 0.32902), 7504.0: (0.29902, 0.31485)}


@pytest.mark.parametrize("cct", sorted(CIE_TABLE_XY))
def test_daylight_chromaticity_matches_the_cie_table(cct):
    from pipeline.sky.clearsky import daylight_chromaticity

    assert np.allclose(daylight_chromaticity(cct), CIE_TABLE_XY[cct], atol=2e-4)


def _xy(rgb):
    from pipeline.core.colour import XYZ_TO_REC709

    X, Y, Z = np.linalg.solve(XYZ_TO_REC709, np.asarray(rgb, dtype=np.float64))
    return np.array([X, Y]) / (X + Y + Z)


def _distance_to_segment(p, a, b):
    a, b = np.asarray(a), np.asarray(b)
    t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * (b - a))))


@pytest.mark.parametrize("cie_type", range(1, 11))
def test_overcast_and_intermediate_skies_are_d65_to_d75(cie_type):
    """The whole sky's light (its horizontal irradiance, sun left out) lies within 0.01 in xy of the
    segment from D65 to D75 of the CIE table; the clear type 12 stays bluer, Preetham's."""
    from pipeline.sky.procedural import ProceduralSky
    from pipeline.sky.sun_disc import SunDisc

    for elevation in (10.0, 40.0):
        sky = ProceduralSky(3.0, SunDisc(np.radians(200.0), np.radians(elevation)), cie_type=cie_type)
        xy = _xy(sky.clear_sky_irradiance)
        assert _distance_to_segment(xy, CIE_TABLE_XY[6504.0], CIE_TABLE_XY[7504.0]) < 0.01, xy
    clear = ProceduralSky(3.0, SunDisc(np.radians(200.0), np.radians(40.0)), cie_type=12)
    assert _distance_to_segment(_xy(clear.clear_sky_irradiance), CIE_TABLE_XY[6504.0], CIE_TABLE_XY[7504.0]) > 0.02
