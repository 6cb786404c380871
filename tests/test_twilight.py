"""The twilight sky's colour (pipeline/sky/twilight.py): the layered single-scattering model against a
brute-force integral of the continuous atmosphere, Hulburt's ozone, and the colours it gives the sky."""

import numpy as np
import pytest

from pipeline.core.colour import REC709_LUMINANCE, XYZ_TO_REC709
from pipeline.sky import twilight
from pipeline.sky.eclipse import AEROSOL_ASYMMETRY, EARTH_RADIUS, RGB_WAVELENGTHS, vertical_optical_depths


def brute_force(elevation, azimuth, sun_elevation, turbidity, n_view=1500, n_sun=800):
    """Single scattering by marching: the continuous exponential Rayleigh (8 km) and aerosol (1.2 km)
    densities and the ozone tent, midpoints along the line of sight and along the sun's ray from
    each of them to the top of the atmosphere; no sunlight where the Earth is in the way. [1/sr]"""
    top = EARTH_RADIUS + twilight.ATMOSPHERE_TOP
    rayleigh, aerosol = vertical_optical_depths(turbidity)
    low, peak, high = twilight.OZONE_LAYER

    def extinction(z):
        tent = np.clip(np.minimum((z - low) / (peak - low), (high - z) / (high - peak)), 0.0, None)
        k_r = rayleigh / 8000.0 * np.exp(-z / 8000.0)[..., None]
        k_a = aerosol / 1200.0 * np.exp(-z / 1200.0)[..., None]
        k_o = (twilight.OZONE_COLUMN / (0.5 * (high - low)) * tent)[..., None] * twilight.OZONE_CROSS_SECTION
        return k_r, k_a, k_r + k_a + k_o

    d = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    s = np.array([np.cos(sun_elevation), 0.0, np.sin(sun_elevation)])
    length = -EARTH_RADIUS * d[2] + np.sqrt(top**2 - EARTH_RADIUS**2 * (1.0 - d[2] ** 2))
    dt = length / n_view
    points = ((np.arange(n_view) + 0.5) * dt)[:, None] * d + np.array([0.0, 0.0, EARTH_RADIUS])
    r = np.linalg.norm(points, axis=1)
    k_r, k_a, k = extinction(r - EARTH_RADIUS)
    to_observer = (np.cumsum(k, axis=0) - 0.5 * k) * dt
    mu = points @ s / r
    lit = ~((mu < 0.0) & (r * r * (1.0 - mu * mu) < EARTH_RADIUS**2))
    ds = (-r * mu + np.sqrt(top**2 - r * r * (1.0 - mu * mu))) / n_sun
    along = points[:, None, :] + ((np.arange(n_sun) + 0.5)[None, :] * ds[:, None])[..., None] * s
    to_sun = extinction(np.linalg.norm(along, axis=-1) - EARTH_RADIUS)[2].sum(axis=1) * ds[:, None]
    c = d @ s
    g = AEROSOL_ASYMMETRY
    phase_r = 3.0 / (16.0 * np.pi) * (1.0 + c * c)
    phase_a = (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * c) ** 1.5)
    return ((k_r * phase_r + k_a * phase_a) * np.exp(-to_observer - to_sun) * lit[:, None]).sum(axis=0) * dt


@pytest.mark.parametrize("elevation, azimuth, sun", [(90.0, 0.0, -3.0), (10.0, 180.0, -3.0), (20.0, 90.0, -5.0),
                                                    (5.0, 180.0, -2.0)])
def test_layered_single_scattering_is_the_brute_force_integral(elevation, azimuth, sun):
    """Within 2.5% per channel, and the colour (channel ratios) within 2%, for lines of sight that
    cross the Earth's shadow and whose sunlight grazes the ground (the layered model's shells of at
    most 1 km against continuous profiles)."""
    model, _ = twilight.single_scattering(np.radians([elevation]), np.radians([azimuth]),
                                          sun_elevation=np.radians(sun), turbidity=3.0)
    reference = brute_force(np.radians(elevation), np.radians(azimuth), np.radians(sun), 3.0)
    ratio = model[0] / reference
    assert np.allclose(ratio, 1.0, atol=0.025), ratio
    assert np.ptp(ratio) < 0.02, ratio


def test_ozone_keeps_the_zenith_blue_after_sunset():
    """Hulburt (1953): without ozone the zenith would turn yellow as the sun goes down (the sunlight
    reaching it grazes the lower air); with the Chappuis band it turns bluer. Sun 0 to -5 degrees."""
    zenith = (np.radians([90.0]), np.zeros(1))

    def change(monkeypatch=None):
        light = [twilight.single_scattering(*zenith, sun_elevation=np.radians(h), turbidity=3.0)[0][0]
                 for h in (0.0, -5.0)]
        ratio = light[1] / light[0]
        return ratio / ratio[1]

    with_ozone = change()
    assert with_ozone[2] > 1.25 and with_ozone[0] < 0.95
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(twilight, "OZONE_CROSS_SECTION", np.zeros(3))
        without = change()
    assert without[2] < 1.0 and without[0] > 1.0


def test_rayleigh_depths_are_bodhaine_s_to_4_percent():
    """The vertical Rayleigh optical depths of the sun's and the sky's colour (Preetham's
    0.008735 lambda^-4.08) against Bodhaine et al. (1999, J. Atmos. Oceanic Technol. 16, eq. 30)
    at sea level."""
    lam = RGB_WAVELENGTHS
    bodhaine = (0.0021520 * (1.0455996 - 341.29061 * lam**-2 - 0.90230850 * lam**2)
                / (1.0 + 0.0027059889 * lam**-2 - 85.968563 * lam**2))
    assert np.allclose(vertical_optical_depths(3.0)[0] / bodhaine, 1.0, atol=0.04)


def xy(rgb):
    X, Y, Z = np.linalg.solve(XYZ_TO_REC709, np.asarray(rgb, dtype=np.float64))
    return np.array([X, Y]) / (X + Y + Z)


def sky_colour(elevation, azimuth, sun, cie_type=12):
    """The relative sky's linear Rec.709 (3,) at a direction (degrees, azimuth from the sun's)."""
    from pipeline.sky.clearsky import relative_sky

    e, a, h = np.radians([elevation, azimuth, sun])
    view = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    gamma = np.arccos(np.clip(view @ np.array([np.cos(h), 0.0, np.sin(h)]), -1.0, 1.0))
    return relative_sky(np.sin(e), gamma, sun_zenith=np.pi / 2 - h, turbidity=3.0, cie_type=cie_type)


def test_twilight_sky_blue_zenith_warm_horizon_under_the_sun_and_the_earth_s_shadow():
    """After sunset (CIE type 12, TL 3): the zenith bluer than at sunset, the horizon under the sun
    still warm, and opposite the sun, at -3 degrees, the Earth's shadow (5 degrees up) less warm
    than the band above it (12 degrees: the Belt of Venus), which is warmer than the zenith; the
    luminance is the CIE shape's."""
    from pipeline.sky.clearsky import cie_relative_luminance

    assert xy(sky_colour(90.0, 0.0, -5.0))[0] < xy(sky_colour(90.0, 0.0, 0.0))[0] - 0.015
    assert xy(sky_colour(2.0, 0.0, -5.0))[0] > 0.4
    belt = xy(sky_colour(12.0, 180.0, -3.0))[0]
    assert belt > xy(sky_colour(5.0, 180.0, -3.0))[0] + 0.015 and belt > xy(sky_colour(90.0, 0.0, -3.0))[0] + 0.04
    e, h = np.radians(10.0), np.radians(-4.0)
    gamma = np.arccos(-np.cos(e) * np.cos(h) + np.sin(e) * np.sin(h))
    luminance = sky_colour(10.0, 180.0, -4.0) @ REC709_LUMINANCE
    assert luminance == pytest.approx(cie_relative_luminance(np.sin(e), gamma, sun_zenith=np.pi / 2 - h,
                                                             cie_type=12), rel=1e-5)


def test_the_overcast_types_keep_daylight_s_colour_after_sunset():
    assert np.allclose(xy(sky_colour(30.0, 90.0, -4.0, cie_type=1)), (0.3127, 0.3290), atol=1e-3)
