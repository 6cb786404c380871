"""The finished frame: blending the foreground passes by S, over the background, the haze,
exposure and the display transforms (sRGB, filmic, or an OpenColorIO view). EXR output stays
scene-linear."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pipeline.config.vocabulary import DISPLAYS, WHITE_BALANCES
from pipeline.core import io, ocio
from pipeline.core.colour import REC709_LUMINANCE

__all__ = ["srgb_encode", "display_ground", "display_sky", "white_balance", "composite_frame",
           "aces_filmic", "display", "display_codes", "CODES_BAND", "display_view", "exposure_for",
           "auto_exposure"]


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of linear values, clipped to [0, 1].

    Parameters
    ----------
    linear : array_like
        Display-linear values, any shape [1].

    Returns
    -------
    numpy.ndarray
        float32 sRGB code values in [0, 1], of ``linear``'s shape [1].
    """
    shape = np.shape(linear)
    x = np.clip(np.array(linear, dtype=np.float32, ndmin=1), 0.0, 1.0)
    # in place, in float32: the same bits as np.where(x <= 0.0031308, 12.92 x, 1.055 x^(1/2.4)
    # - 0.055) in two thirds of the time
    low = x <= np.float32(0.0031308)
    linear_part = x[low] * np.float32(12.92)
    np.power(x, np.float32(1.0 / 2.4), out=x)
    x *= np.float32(1.055)
    x -= np.float32(0.055)
    x[low] = linear_part
    return x.reshape(shape)


def display_ground(irradiance: np.ndarray, unshadowed: ArrayLike, *, white: float = 1.25) -> np.ndarray:
    """Display-referred sRGB picture of a ground irradiance raster.

    The open-sky irradiance maps to ``1 / white`` of full scale, grey-balanced by its luminance,
    so sunlit ground is a light grey and shade keeps its depth.

    Parameters
    ----------
    irradiance : numpy.ndarray
        (rows, cols, 3) horizontal irradiance of the ground [klx].
    unshadowed : array_like
        (3,) the open sky's and sun's horizontal irradiance [klx].
    white : float, optional
        The open-sky irradiance over full scale [1].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 sRGB code values in [0, 1] [1].
    """
    luminance = float(np.asarray(unshadowed, dtype=np.float64) @ REC709_LUMINANCE)
    scale = 1.0 / (white * luminance) if luminance > 0 else 1.0
    return srgb_encode(np.asarray(irradiance, dtype=np.float32) * np.float32(scale))


def display_sky(radiance: np.ndarray) -> np.ndarray:
    """Display-referred sRGB picture of an equirectangular sky.

    Exposure puts the median luminance of the upper hemisphere at 0.4, then ``x / (1 + x)``
    compresses the sun and the glow around it instead of clipping them flat.

    Parameters
    ----------
    radiance : numpy.ndarray
        (rows, cols, 3) equirectangular sky radiance, the upper hemisphere in the top half of the rows
        [kcd/m^2].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 sRGB code values in [0, 1] [1].
    """
    radiance = np.asarray(radiance, dtype=np.float32)
    upper = radiance[: radiance.shape[0] // 2] @ REC709_LUMINANCE
    median = float(np.median(upper))
    exposed = radiance * np.float32(0.4 / median if median > 0 else 1.0)
    return srgb_encode(exposed / (1.0 + exposed))


def white_balance(setting: str, *, sun_irradiance: ArrayLike, sky_irradiance: ArrayLike) -> np.ndarray:
    """Per-channel gains of a von Kries white balance.

    The chosen light comes out grey, its luminance kept; a light with a channel not above 0 gets
    gains of 1.

    Parameters
    ----------
    setting : str
        One of ``WHITE_BALANCES``: ``daylight`` (sun and sky), ``shade`` (sky alone), ``none``.
    sun_irradiance : array_like
        (3,) horizontal irradiance of the run's clear sun [klx].
    sky_irradiance : array_like
        (3,) horizontal irradiance of the run's clear sky [klx].

    Returns
    -------
    numpy.ndarray
        (3,) float64 gains [1].

    Raises
    ------
    ValueError
        For a setting not in ``WHITE_BALANCES``.
    """
    if setting not in WHITE_BALANCES:
        raise ValueError(f"unknown white balance {setting!r}; valid: {', '.join(WHITE_BALANCES)}")
    light = {"daylight": np.asarray(sun_irradiance, dtype=np.float64) + np.asarray(sky_irradiance, dtype=np.float64),
             "shade": np.asarray(sky_irradiance, dtype=np.float64), "none": np.ones(3)}[setting]
    if not np.all(light > 0):
        return np.ones(3)
    return float(light @ REC709_LUMINANCE) / light


def composite_frame(background: np.ndarray, *, sun_pass: np.ndarray, sky_pass: np.ndarray,
                    alpha: np.ndarray, sun_fraction: float, sky_scale: float = 1.0,
                    atmosphere: np.ndarray | None = None) -> np.ndarray:
    """The finished frame (Max 1991, implementation section).

        frame = k F_sky + S (F_sun - F_sky) + (1 - A) (B + S atmosphere)

    The sun-lit haze (atmosphere) is behind the trees (they are near; the paper adds it over
    everything).

    Parameters
    ----------
    background : numpy.ndarray
        (rows, cols, 3) radiance B of the ground and sky seen [kcd/m^2].
    sun_pass : numpy.ndarray
        (rows, cols, 3) premultiplied foreground F_sun, lit by sun and sky [kcd/m^2].
    sky_pass : numpy.ndarray
        (rows, cols, 3) premultiplied foreground F_sky, lit by the sky alone [kcd/m^2].
    alpha : numpy.ndarray
        (rows, cols) coverage A of the foreground [1].
    sun_fraction : float
        S, the visible fraction of the sun [1].
    sky_scale : float, optional
        k, the skylight now over the skylight the passes were lit by (1 in the paper; below 1 when
        clouds or the moon dim the sky too) [1].
    atmosphere : numpy.ndarray, optional
        (rows, cols, 3) the sun-lit haze in front of the background [kcd/m^2].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 radiance [kcd/m^2].
    """
    sun_pass = np.asarray(sun_pass, dtype=np.float32)
    sky_pass = np.asarray(sky_pass, dtype=np.float32)
    alpha = np.asarray(alpha, dtype=np.float32)[..., None]
    frame = np.float32(sky_scale) * sky_pass + np.float32(sun_fraction) * (sun_pass - sky_pass)
    behind = np.asarray(background, dtype=np.float32)
    if atmosphere is not None:
        behind = behind + np.float32(sun_fraction) * np.asarray(atmosphere, dtype=np.float32)
    frame += (1.0 - alpha) * behind
    return frame


def aces_filmic(x: np.ndarray) -> np.ndarray:
    """The ACES filmic tone curve as fitted by Narkowicz (2015).

    Scene-linear [0, inf) to display-linear [0, 1), a toe that keeps shadows rich and a shoulder
    that rolls the sun and bright cloud off instead of clipping them.

    Parameters
    ----------
    x : array_like
        Exposed scene-linear values, any shape [1].

    Returns
    -------
    numpy.ndarray
        float32 display-linear values in [0, 1), of ``x``'s shape [1].
    """
    shape = np.shape(x)
    x = np.maximum(np.array(x, dtype=np.float32, ndmin=1), np.float32(0.0))
    numerator = x * np.float32(2.51)  # x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), in place
    numerator += np.float32(0.03)
    numerator *= x
    denominator = x * np.float32(2.43)
    denominator += np.float32(0.59)
    denominator *= x
    denominator += np.float32(0.14)
    numerator /= denominator
    return np.clip(numerator, 0.0, 1.0, out=numerator).reshape(shape)


def display(radiance: np.ndarray, *, exposure: float, transform: str = "filmic",
            balance: ArrayLike | None = None) -> np.ndarray:
    """sRGB display values in [0, 1] of scene-linear radiance, exposed and white-balanced.

    Parameters
    ----------
    radiance : numpy.ndarray
        (rows, cols, 3) scene-linear radiance [kcd/m^2].
    exposure : float
        Exposure [m^2/kcd] (``exposure_for``, ``auto_exposure``).
    transform : str, optional
        One of ``DISPLAYS``: ``srgb`` clips at 1, ``filmic`` rolls off with ``aces_filmic`` first.
    balance : array_like, optional
        (3,) the white balance's gains (``white_balance``) [1]; None: 1.

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 sRGB code values in [0, 1] [1].

    Raises
    ------
    ValueError
        Naming the valid ones, for a transform that is not one of ``DISPLAYS``.
    """
    _check_display(transform)
    gain = np.float32(exposure) if balance is None else (np.asarray(balance) * exposure).astype(np.float32)
    exposed = np.asarray(radiance, dtype=np.float32) * gain
    if transform == "filmic":
        exposed = aces_filmic(exposed)
    return srgb_encode(exposed)


def _check_display(transform: str) -> None:
    """Raises ValueError naming the valid ones for a transform that is not one of ``DISPLAYS``."""
    if transform not in DISPLAYS:
        raise ValueError(f"unknown display transform {transform!r}; valid: {', '.join(DISPLAYS)}")


def display_codes(radiance: np.ndarray, *, exposure: float, transform: str = "filmic",
                  balance: ArrayLike | None = None) -> np.ndarray:
    """The 8-bit codes ``io.write_png`` writes of ``display(radiance, ...)``, bit for bit, in
    two compiled passes around numpy's power, CODES_BAND rows at a time (docs/runs.md, "Writing").

    Parameters
    ----------
    radiance, exposure, transform, balance
        As ``display``'s.

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) uint8 sRGB codes, dithered as ``io.write_png`` dithers.

    Raises
    ------
    ValueError
        As ``display``.
    """
    _check_display(transform)
    from pipeline.kernels import arrays  # numba costs 0.3 s to import: only where frames are written

    radiance = np.ascontiguousarray(radiance, dtype=np.float32)
    gain = np.array(np.broadcast_to(np.float32(exposure) if balance is None  # a copy: one compiled signature
                                    else (np.asarray(balance) * exposure).astype(np.float32), 3), dtype=np.float32)
    dither = io.half_dither(radiance.shape)
    codes = np.empty(radiance.shape, dtype=np.uint8)
    band = (min(CODES_BAND, radiance.shape[0]), *radiance.shape[1:])
    linear, powered = np.empty(band, dtype=np.float32), np.empty(band, dtype=np.float32)
    for top in range(0, radiance.shape[0], CODES_BAND):
        rows = slice(top, top + CODES_BAND)
        size = len(range(*rows.indices(radiance.shape[0])))
        arrays.exposed_display(radiance[rows], gain, transform == "filmic", linear[:size])
        # numpy's power, as srgb_encode takes it (its vector loops may differ from a compiled powf in
        # the last bit): value by value the same over a band as over the frame
        np.power(linear[:size], np.float32(1.0 / 2.4), out=powered[:size])
        arrays.display_codes(linear[:size], powered[:size], dither[rows], codes[rows])
    return codes


CODES_BAND = 32
"""Rows of a frame that ``display_codes`` takes at a time: its two float32 bands of a 1280-wide frame
(0.5 MB each) stay in the core's cache between the passes and are not made afresh for each frame's
whole size, whose pages the kernel would clear (docs/accuracy.md, "The write stage")."""


def display_view(radiance: np.ndarray, *, exposure: float, source: str, view: tuple[str, str],
                 balance: ArrayLike | None = None) -> np.ndarray:
    """Display values in [0, 1] of scene-linear radiance through an OpenColorIO display and view.

    The exposure and the white balance are applied in scene-linear Rec.709, as for ``display``,
    before the view (docs/runs.md, "Colour").

    Parameters
    ----------
    radiance : numpy.ndarray
        (rows, cols, 3) scene-linear Rec.709 radiance [kcd/m^2].
    exposure : float
        Exposure [m^2/kcd] (``exposure_for``, ``auto_exposure``).
    source : str
        The OCIO config: a file path or an ``ocio://`` URI.
    view : tuple of (str, str)
        (display, view) of that config.
    balance : array_like, optional
        (3,) the white balance's gains (``white_balance``) [1]; None: 1.

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 display code values in [0, 1] [1].
    """
    gain = np.float32(exposure) if balance is None else (np.asarray(balance) * exposure).astype(np.float32)
    return ocio.apply_view(np.asarray(radiance, dtype=np.float32) * gain, source, *view)


def exposure_for(unshadowed: ArrayLike, *, stops: float = 0.0) -> float:
    """The exposure at which a white Lambertian ground under the open clear sky and sun is 1, times 2^stops.

    Fixed for a whole run, so an eclipse or a cloud darkens the picture as it darkens the day.

    Parameters
    ----------
    unshadowed : array_like
        (3,) horizontal irradiance of the open clear sky and sun [klx].
    stops : float, optional
        Exposure compensation [stops].

    Returns
    -------
    float
        The exposure [m^2/kcd].
    """
    luminance = float(np.asarray(unshadowed, dtype=np.float64) @ REC709_LUMINANCE)
    return float(2.0**stops * np.pi / luminance) if luminance > 0 else float(2.0**stops)


def auto_exposure(readings: ArrayLike, *, reference: ArrayLike, frame_time: float, time_constant: float,
                  limits: tuple[float, float], stops: float = 0.0) -> np.ndarray:
    """Exposure per frame that follows the scene's light like a camera's auto exposure.

    Each frame's meter reading is followed in log (stops) through a first-order lag, the first
    frame metered at once:
    ``m_k = m_(k-1) + (1 - exp(-frame_time / time_constant)) (log2 E_k - m_(k-1))``.
    The exposure puts a white Lambertian ground under the metered light at 1, times 2^stops,
    clamped to ``limits`` over ``exposure_for(reference)`` (the clear sky's): under the least light
    it goes no brighter than 2^most times that, so totality darkens.

    Parameters
    ----------
    readings : array_like
        (frames, 3) the meter's reading per frame: the open ground's horizontal irradiance [klx].
    reference : array_like
        (3,) the clear sky's and sun's horizontal irradiance [klx].
    frame_time : float
        Time between frames [s].
    time_constant : float
        The lag's time constant; 0 follows each frame at once [s].
    limits : tuple of (float, float)
        (least, most) over ``exposure_for(reference)`` [stops].
    stops : float, optional
        Exposure compensation [stops].

    Returns
    -------
    numpy.ndarray
        (frames,) float64 exposure [m^2/kcd].
    """
    luminance = np.asarray(readings, dtype=np.float64) @ REC709_LUMINANCE.astype(np.float64)
    base = exposure_for(reference)
    floor = np.log2(np.pi / base) - limits[1]  # the dimmest light the exposure follows [log2 klx]
    metered = np.log2(np.maximum(luminance, 2.0**floor * 1e-3))
    keep = np.exp(-frame_time / time_constant) if time_constant > 0 else 0.0
    level = np.empty_like(metered)
    for k, value in enumerate(metered):
        level[k] = value if k == 0 else keep * level[k - 1] + (1.0 - keep) * value
    exposure = 2.0**stops * np.pi / 2.0**level
    return np.clip(exposure, base * 2.0 ** (limits[0] + stops), base * 2.0 ** (limits[1] + stops))
