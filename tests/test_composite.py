"""The finished frame's arithmetic: blending by S, over, haze, exposure and display."""

import numpy as np
import pytest
import reference
from scipy import integrate

from pipeline.camera import composite
from pipeline.camera.composite import display, white_balance
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky import scattering


@pytest.fixture
def images():
    rng = np.random.default_rng(3)
    shape = (12, 17)
    background = rng.random((*shape, 3), dtype=np.float32) * 5
    sky = rng.random((*shape, 3), dtype=np.float32)
    sun = sky + rng.random((*shape, 3), dtype=np.float32) * 4
    return background, sun, sky, shape


def test_alpha_zero_leaves_the_background_untouched(images):
    background, _, _, shape = images
    zero = np.zeros_like(background)
    for s in (0.0, 0.3, 1.0):
        frame = composite.composite_frame(background, sun_pass=zero, sky_pass=zero,
                                          alpha=np.zeros(shape), sun_fraction=s)
        np.testing.assert_array_equal(frame, background)


def test_alpha_one_hides_the_background_and_its_haze(images):
    background, sun, sky, shape = images
    one = np.ones(shape, dtype=np.float32)
    a = composite.composite_frame(background, sun_pass=sun, sky_pass=sky, alpha=one, sun_fraction=0.4,
                                  atmosphere=background)
    b = composite.composite_frame(7 * background + 1, sun_pass=sun, sky_pass=sky, alpha=one,
                                  sun_fraction=0.4, atmosphere=3 * background)
    np.testing.assert_array_equal(a, b)


def test_sun_fraction_zero_and_one_give_the_two_passes(images):
    background, sun, sky, shape = images
    one = np.ones(shape, dtype=np.float32)
    np.testing.assert_allclose(composite.composite_frame(background, sun_pass=sun, sky_pass=sky, alpha=one,
                                                         sun_fraction=0.0), sky, rtol=1e-6)
    np.testing.assert_allclose(composite.composite_frame(background, sun_pass=sun, sky_pass=sky, alpha=one,
                                                         sun_fraction=1.0), sun, rtol=1e-6)
    half = composite.composite_frame(background, sun_pass=sun, sky_pass=sky, alpha=0.5 * one,
                                     sun_fraction=0.25, sky_scale=0.5)
    np.testing.assert_allclose(half, 0.5 * sky + 0.25 * (sun - sky) + 0.5 * background, rtol=1e-5)


def test_henyey_greenstein_is_normalised_and_forward():
    for g in (0.0, 0.6, 0.85):
        total, _ = integrate.quad(lambda mu: 2 * np.pi * scattering.henyey_greenstein(mu, g), -1, 1)
        assert total == pytest.approx(1.0, rel=1e-6)
    assert scattering.henyey_greenstein(1.0, 0.6) > 10 * scattering.henyey_greenstein(-1.0, 0.6)
    mu = np.linspace(-1.0, 1.0, 9)
    exact = (1 - 0.6**2) / (4 * np.pi * (1 + 0.6**2 - 2 * 0.6 * mu) ** 1.5)
    np.testing.assert_allclose(scattering.henyey_greenstein(mu, 0.6), exact, rtol=1e-14)
    single = scattering.henyey_greenstein(mu.astype(np.float32), 0.6)  # float32 in, float32 out (clouds)
    assert single.dtype == np.float32
    np.testing.assert_allclose(single, exact, rtol=1e-6)


def test_aerial_perspective_follows_beer_lambert_and_spares_the_sky():
    distance = np.array([[0.0, 1000.0, np.inf]])
    view = np.array([[[0.0, 1.0, 0.0]] * 3])
    sun_dir = np.array([0.0, 0.0, 1.0])
    t, sky_haze, sun_haze = reference.aerial_perspective(
        distance, view, length=2000.0, sun_direction=sun_dir, sun_irradiance=np.array([100.0] * 3),
        sky_irradiance=np.array([20.0] * 3), albedo=0.9, g=0.6)
    np.testing.assert_allclose(t[0], [1.0, np.exp(-0.5), 1.0], rtol=1e-6)
    veil = 1 - np.exp(-0.5)
    np.testing.assert_allclose(sun_haze[0, 1], veil * 0.9 * scattering.henyey_greenstein(0.0, 0.6) * 100, rtol=1e-5)
    np.testing.assert_allclose(sky_haze[0, 1], veil * 0.9 * 20 / (2 * np.pi), rtol=1e-5)
    assert not sun_haze[0, [0, 2]].any() and not sky_haze[0, [0, 2]].any()


def test_exposure_puts_white_ground_under_the_open_sky_at_one():
    unshadowed = np.array([110.0, 100.0, 90.0])
    exposure = composite.exposure_for(unshadowed)
    white = unshadowed / np.pi  # radiance of a white Lambertian ground [kcd/m^2]
    assert float(white @ REC709_LUMINANCE) * exposure == pytest.approx(1.0)
    assert composite.exposure_for(unshadowed, stops=1) == pytest.approx(2 * exposure)


def test_display_transforms():
    ramp = np.linspace(0, 4, 400, dtype=np.float32)[None, :, None] * np.ones(3, np.float32)
    srgb = composite.display(ramp, exposure=1.0, transform="srgb")
    filmic = composite.display(ramp, exposure=1.0, transform="filmic")
    assert srgb.min() >= 0 and srgb.max() == pytest.approx(1.0)
    assert np.all(np.diff(filmic[0, :, 0]) > 0), "filmic keeps highlights apart instead of clipping"
    assert filmic.max() < 0.99
    assert composite.display(np.full((1, 1, 3), 0.18), exposure=1, transform="srgb")[0, 0, 0] == pytest.approx(
        1.055 * 0.18 ** (1 / 2.4) - 0.055, rel=1e-5)
    with pytest.raises(ValueError, match="filmic"):
        composite.display(ramp, exposure=1.0, transform="log")


def test_white_balance_makes_the_chosen_light_grey_and_keeps_its_luminance():
    sun, sky = np.array([70.0, 71.0, 62.0]), np.array([9.0, 13.0, 22.0])  # a warm sun, a blue sky [klx]
    luma = np.asarray(REC709_LUMINANCE, dtype=np.float64)
    for setting, light in (("daylight", sun + sky), ("shade", sky)):
        gains = white_balance(setting, sun_irradiance=sun, sky_irradiance=sky)
        balanced = gains * light
        assert np.ptp(balanced) == pytest.approx(0.0, abs=1e-9)  # grey
        assert balanced @ luma == pytest.approx(light @ luma)  # as bright
    assert np.all(white_balance("none", sun_irradiance=sun, sky_irradiance=sky) == 1.0)
    shade = white_balance("shade", sun_irradiance=sun, sky_irradiance=sky)
    assert shade[0] > 1.0 > shade[2]  # the sun flecks come out warm
    with pytest.raises(ValueError, match="valid: daylight, shade, none"):
        white_balance("tungsten", sun_irradiance=sun, sky_irradiance=sky)


def test_display_applies_the_white_balance_before_the_tone_curve():
    radiance = np.full((2, 2, 3), 0.2, dtype=np.float32)
    plain = display(radiance, exposure=1.0, transform="srgb")
    warm = display(radiance, exposure=1.0, transform="srgb", balance=np.array([1.5, 1.0, 0.5]))
    assert np.allclose(display(radiance * np.float32([1.5, 1.0, 0.5]), exposure=1.0, transform="srgb"), warm)
    assert warm[0, 0, 0] > plain[0, 0, 0] > warm[0, 0, 2]


@pytest.mark.parametrize("transform", ["filmic", "srgb"])
def test_display_codes_are_the_codes_of_the_display_written_as_png(transform):
    """display_codes (two compiled passes around numpy's power) gives, bit for bit, the codes of
    display() quantised as write_png does: floor(clip(p, 0, 1) 255 + 0.5 + (u0 - u1) / 2), u0 and
    u1 uniform of seeds 0 and 1; over radiance from below 0 to far above white, through the sRGB
    knee, with and without a white balance."""
    rng = np.random.default_rng(11)
    shape = (37, 53, 3)  # no multiple of a vector's width: the loops' tails are read too
    radiance = rng.uniform(-0.2, 1.5, shape).astype(np.float32) ** 3 * 4
    radiance[:4] = np.geomspace(1e-5, 20.0, shape[1], dtype=np.float32)[None, :, None]
    radiance[4, :, :] = np.float32(0.0031308) / np.float32(0.37)  # at the knee after the exposure
    noise = np.random.default_rng(0).random(shape, dtype=np.float32)
    noise -= np.random.default_rng(1).random(shape, dtype=np.float32)
    for exposure, balance in ((0.37, None), (2.9, np.array([1.12, 1.0, 0.83])), (150.0, None)):
        picture = display(radiance, exposure=exposure, transform=transform, balance=balance)
        want = np.clip(np.floor(np.clip(picture, 0.0, 1.0) * 255.0 + 0.5 + 0.5 * noise), 0, 255).astype(np.uint8)
        codes = composite.display_codes(radiance, exposure=exposure, transform=transform, balance=balance)
        assert codes.dtype == np.uint8
        np.testing.assert_array_equal(codes, want)
    with pytest.raises(ValueError, match="valid: "):
        composite.display_codes(radiance, exposure=1.0, transform="log")
