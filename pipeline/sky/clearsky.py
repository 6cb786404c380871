"""The clear sky's angular shape: where in the sky its light comes from, and its colour.

Relative luminance from the CIE standard general sky (ISO 15469:2004 / CIE S 011/E:2003, 15 types)
or from Preetham, Shirley & Smits (1999); chromaticity from Preetham's model for the clear types and
from the CIE daylight locus (D series, CIE 15) for the overcast and intermediate ones. The shapes carry no
absolute level: ``procedural.ProceduralSky`` scales them to the diffuse illuminance of ``daylight``
(docs/method.md, "The procedural sky": daylight in absolute units). Angles in radians; directions by the cosine of
their zenith angle and their angle ``gamma`` from the sun.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pipeline.config.vocabulary import DEFAULT_CIE_TYPE, PROCEDURAL_MODELS
from pipeline.core.colour import REC709_LUMINANCE, XYZ_TO_REC709
from pipeline.sky.twilight import twilight_colour

__all__ = [
    "CIE_TYPES", "DAYLIGHT_CCT", "daylight_chromaticity", "cie_relative_luminance", "perez_coefficients",
    "zenith_chromaticity", "preetham_relative", "rgb_from_xyY", "relative_sky",
]

_GRADATION = {1: (4.0, -0.70), 2: (1.1, -0.8), 3: (0.0, -1.0), 4: (-1.0, -0.55), 5: (-1.0, -0.32),
              6: (-1.0, -0.15)}
_INDICATRIX = {1: (0.0, -1.0, 0.0), 2: (2.0, -1.5, 0.15), 3: (5.0, -2.5, 0.30), 4: (10.0, -3.0, 0.45),
               5: (16.0, -3.0, 0.30), 6: (24.0, -2.8, 0.15)}
_TYPE_GROUPS = {1: (1, 1), 2: (1, 2), 3: (2, 1), 4: (2, 2), 5: (3, 1), 6: (3, 2), 7: (3, 3), 8: (3, 4),
                9: (4, 2), 10: (4, 3), 11: (4, 4), 12: (5, 4), 13: (5, 5), 14: (6, 5), 15: (6, 6)}
CIE_TYPES = {t: (*_GRADATION[g], *_INDICATRIX[i]) for t, (g, i) in _TYPE_GROUPS.items()}
"""The 15 CIE standard general skies (ISO 15469:2004, Tables 1 and 2): type -> (a, b, c, d, e),
gradation groups I-VI and indicatrix groups 1-6. Types 1-5 are overcast, 6-10 partly cloudy,
11-15 clear (12: clear, low illuminance turbidity; 13: clear, polluted atmosphere)."""

DAYLIGHT_CCT = {**{t: 6504.0 for t in range(1, 6)}, **{t: 7000.0 for t in range(6, 11)}}
"""Correlated colour temperature of the overcast (1-5) and intermediate (6-10) CIE types, whose sky
takes the chromaticity of CIE daylight at it (``daylight_chromaticity``): 6504 K is D65 (measured
overcast skies lie near the daylight locus at 6500-7500 K); the partly cloudy types, with some
blue sky between the clouds, 7000 K, a choice within that band (docs/method.md, "The procedural
sky"). The clear types (11-15) keep Preetham's blue sky. [K]"""


def daylight_chromaticity(cct: float) -> tuple[float, float]:
    """CIE xy of the D-series daylight of a correlated colour temperature.

    CIE 15:2004, eqs. 3.3-3.4: x_D a cubic in 1/T on 4000-7000 K and on 7000-25000 K,
    y_D = -3 x_D^2 + 2.870 x_D - 0.275. The CIE's D65 is 6504 K (6500 K before the 1968 change
    of c2).

    Parameters
    ----------
    cct : float
        Correlated colour temperature, in [4000, 25000] [K].

    Returns
    -------
    x, y : float
        The chromaticity [1].

    Raises
    ------
    ValueError
        If ``cct`` is outside [4000, 25000] K.
    """
    t = float(cct)
    if not 4000.0 <= t <= 25000.0:
        raise ValueError(f"cct must be in [4000, 25000] K, got {cct}")
    if t <= 7000.0:
        x = -4.6070e9 / t**3 + 2.9678e6 / t**2 + 0.09911e3 / t + 0.244063
    else:
        x = -2.0064e9 / t**3 + 1.9018e6 / t**2 + 0.24748e3 / t + 0.237040
    return x, -3.000 * x * x + 2.870 * x - 0.275


# Preetham et al. 1999, appendix A.2: Perez coefficients (A..E) = slope * T + intercept, rows Y, x, y.
_PEREZ_SLOPE = np.array(
    [[0.1787, -0.3554, -0.0227, 0.1206, -0.0670],
     [-0.0193, -0.0665, -0.0004, -0.0641, -0.0033],
     [-0.0167, -0.0950, -0.0079, -0.0441, -0.0109]]
)
_PEREZ_INTERCEPT = np.array(
    [[-1.4630, 0.4275, 5.3251, -2.5771, 0.3703],
     [-0.2592, 0.0008, 0.2125, -0.8989, 0.0452],
     [-0.2608, 0.0092, 0.2102, -1.6537, 0.0529]]
)
# zenith chromaticity x_z, y_z = [T^2 T 1] M [theta_s^3 theta_s^2 theta_s 1]^T (appendix A.2)
_ZENITH_X = np.array(
    [[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394], [0.11693, -0.21196, 0.06052, 0.25886]]
)
_ZENITH_Y = np.array(
    [[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516], [0.15346, -0.26756, 0.06670, 0.26688]]
)


def cie_relative_luminance(cos_zenith: ArrayLike, gamma: ArrayLike, *, sun_zenith: float, cie_type: int) -> np.ndarray:
    """Luminance over zenith luminance of a CIE standard general sky (ISO 15469:2004, eqs. 1-4).

    L / Lz = f(gamma) phi(Z) / (f(Zs) phi(0)), gradation phi(Z) = 1 + a exp(b / cos Z) (1 at the
    horizon), indicatrix f(chi) = 1 + c (exp(d chi) - exp(d pi/2)) + e cos^2 chi.

    Parameters
    ----------
    cos_zenith : float or numpy.ndarray
        cos Z of the directions, in [0, 1] [1].
    gamma : float or numpy.ndarray
        Angle of the directions from the sun, broadcastable with ``cos_zenith`` [rad].
    sun_zenith : float
        Zs [rad].
    cie_type : int
        1..15 (CIE_TYPES).

    Returns
    -------
    numpy.ndarray
        (...) float64, of the broadcast shape of ``cos_zenith`` and ``gamma`` [1].
    """
    a, b, c, d, e = CIE_TYPES[cie_type]
    gamma = np.asarray(gamma, dtype=np.float64)

    def gradation(cos_z):
        return 1.0 + a * np.exp(b / np.maximum(cos_z, 1e-6))

    def indicatrix(chi):
        return 1.0 + c * (np.exp(d * chi) - np.exp(d * np.pi / 2)) + e * np.cos(chi) ** 2

    cos_zenith = np.asarray(cos_zenith, dtype=np.float64)
    return indicatrix(gamma) * gradation(cos_zenith) / (indicatrix(sun_zenith) * gradation(1.0))


def perez_coefficients(turbidity: float) -> np.ndarray:
    """Perez distribution coefficients A..E for Y, x and y (Preetham et al. 1999, appendix A.2).

    Parameters
    ----------
    turbidity : float
        Atmospheric turbidity T [1].

    Returns
    -------
    numpy.ndarray
        (3, 5): rows Y, x, y; columns A, B, C, D, E [1].
    """
    return _PEREZ_SLOPE * float(turbidity) + _PEREZ_INTERCEPT


def zenith_chromaticity(turbidity: float, sun_zenith: float) -> tuple[float, float]:
    """CIE xy chromaticity of the zenith (Preetham et al. 1999, appendix A.2).

    Parameters
    ----------
    turbidity : float
        T [1].
    sun_zenith : float
        theta_s [rad].

    Returns
    -------
    x, y : float
        The zenith's chromaticity [1].
    """
    t = np.array([turbidity**2, turbidity, 1.0])
    a = np.array([sun_zenith**3, sun_zenith**2, sun_zenith, 1.0])
    return float(t @ _ZENITH_X @ a), float(t @ _ZENITH_Y @ a)


def _perez(c, inv_cos, gamma, cos_gamma):
    """The Perez function F(theta, gamma) = (1 + A exp(B / cos theta)) (1 + C exp(D gamma) + E cos^2 gamma)."""
    A, B, C, D, E = c
    return (1.0 + A * np.exp(B * inv_cos)) * (1.0 + C * np.exp(D * gamma) + E * cos_gamma * cos_gamma)


def preetham_relative(cos_zenith: ArrayLike, gamma: ArrayLike, *, turbidity: float, sun_zenith: float) -> np.ndarray:
    """Preetham et al. (1999) eq. 3 for Y, x and y: the zenith values times F(theta, gamma) / F(0, theta_s).

    The zenith values are x_z, y_z (``zenith_chromaticity``) and 1 for Y.

    Parameters
    ----------
    cos_zenith : float or numpy.ndarray
        cos theta of the directions, in [0, 1] [1].
    gamma : float or numpy.ndarray
        Angle from the sun, broadcastable with ``cos_zenith`` [rad].
    turbidity, sun_zenith : float
        T [1] and theta_s [rad].

    Returns
    -------
    numpy.ndarray
        (3, ...) float64: luminance over the zenith's, and the chromaticity x, y [1].
    """
    gamma = np.asarray(gamma, dtype=np.float64)
    cos_gamma = np.cos(gamma)
    inv_cos = 1.0 / np.maximum(np.asarray(cos_zenith, dtype=np.float64), 1e-6)
    coef = perez_coefficients(turbidity)
    zenith = (1.0, *zenith_chromaticity(turbidity, sun_zenith))
    return np.stack([
        z * _perez(coef[k], inv_cos, gamma, cos_gamma) / _perez(coef[k], 1.0, sun_zenith, np.cos(sun_zenith))
        for k, z in enumerate(zenith)
    ])


def rgb_from_xyY(x: np.ndarray | float, y: np.ndarray | float, Y: np.ndarray | float) -> np.ndarray:
    """Linear Rec.709 from CIE xyY; its Rec.709 luminance is Y.

    Parameters
    ----------
    x, y : float or numpy.ndarray
        Chromaticity, broadcastable [1].
    Y : float or numpy.ndarray
        Luminance, in any unit.

    Returns
    -------
    numpy.ndarray
        (..., 3) linear Rec.709, in the unit of ``Y``.
    """
    X = x / y * Y
    Z = (1.0 - x - y) / y * Y
    M = XYZ_TO_REC709
    return np.stack([M[i, 0] * X + M[i, 1] * Y + M[i, 2] * Z for i in range(3)], axis=-1)


def relative_sky(cos_zenith: ArrayLike, gamma: ArrayLike, *, sun_zenith: float, turbidity: float, shape: str = "cie",
                 cie_type: int = DEFAULT_CIE_TYPE) -> np.ndarray:
    """The sky's colour and relative luminance: luminance 1 at the zenith.

    Shaped by the CIE type or by Preetham's model (``shape``), coloured by Preetham's chromaticity at
    ``turbidity``, or, for the overcast and intermediate CIE types (``DAYLIGHT_CCT``), by CIE
    daylight's.

    Parameters
    ----------
    cos_zenith : float or numpy.ndarray
        cos of the directions' zenith angle, in [0, 1] [1].
    gamma : float or numpy.ndarray
        Angle from the sun, broadcastable with ``cos_zenith`` [rad].
    sun_zenith : float
        Beyond pi/2 (the sun set, to 96 degrees) the CIE shape follows it, Preetham's shape is
        the one at pi/2, and the colour (but the overcast and intermediate types') is Preetham's at
        pi/2 times ``twilight.twilight_colour``'s change since, the luminance kept [rad].
    turbidity : float
        T of the colour (and of the Preetham shape) [1].
    shape : str, optional
        "cie" or "preetham" (vocabulary.PROCEDURAL_MODELS).
    cie_type : int, optional
        1..15 (CIE_TYPES), for ``shape`` "cie".

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 linear Rec.709, zenith luminance 1 [1].

    Raises
    ------
    ValueError
        If ``shape`` is unknown.
    """
    # Preetham's model stops at the horizon: below it (twilight) the colours of sunset are kept
    Y, x, y = preetham_relative(cos_zenith, gamma, turbidity=turbidity, sun_zenith=min(sun_zenith, np.pi / 2))
    if shape == "cie":
        Y = cie_relative_luminance(cos_zenith, gamma, sun_zenith=sun_zenith, cie_type=cie_type)
        if cie_type in DAYLIGHT_CCT:
            x, y = (np.full_like(Y, c) for c in daylight_chromaticity(DAYLIGHT_CCT[cie_type]))
    elif shape != "preetham":
        raise ValueError(f"unknown sky shape {shape!r} (valid: {', '.join(PROCEDURAL_MODELS)})")
    rgb = rgb_from_xyY(x, y, Y)
    if sun_zenith > np.pi / 2 and not (shape == "cie" and cie_type in DAYLIGHT_CCT):
        # after sunset (docs/method.md, "The procedural sky": low sun and twilight)
        rgb = rgb * twilight_colour(cos_zenith, gamma, sun_elevation=np.pi / 2 - sun_zenith, turbidity=turbidity)
        luminance = rgb @ np.asarray(REC709_LUMINANCE, dtype=np.float64)
        rgb *= (Y / np.maximum(luminance, 1e-300))[..., None]
    return rgb
