"""Absolute clear-sky daylight: how much light the sun and the sky give, in klx.

The clear-sky irradiance of Ineichen & Perez (2002) from pvlib, turned into illuminance with the
luminous efficacy model of Perez et al. (1990), and the Linke turbidity climatology of pvlib.
The sky's angular shape is ``clearsky``'s; ``procedural.ProceduralSky`` scales that shape to these
levels (docs/method.md, "The procedural sky": daylight in absolute units).

pvlib is imported inside the functions: its import is slow (measured in docs/accuracy.md), and a
command that draws no sky (``--help``, a resume with nothing to do) should not pay it.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "SOLAR_CONSTANT", "PRECIPITABLE_WATER", "CLEARNESS_BINS", "TWILIGHT_END", "TWILIGHT_BLEND", "Efficacy",
    "perez_efficacy", "ClearDaylight", "clear_daylight", "linke_turbidity", "usno_illuminance", "TWILIGHT_MAX_FALL",
    "twilight_illuminance", "sky_daylight",
]

SOLAR_CONSTANT = 1366.1
"""Extraterrestrial normal irradiance of the sun at 1 au (ASTM E-490; pvlib's default in
``pvlib.irradiance.get_extra_radiation``). [W/m^2]"""

PRECIPITABLE_WATER = 2.0
"""Atmospheric precipitable water of the efficacy model when nothing else is known (the default of
Radiance's gendaylit; mid-latitude air holds about 1 cm in winter, 3 cm in summer). A change of
1 cm moves the clear-sky efficacies by under 2%. [cm]"""

# Perez et al. 1990, Table 4: per sky-clearness bin (Table 1 bounds), coefficients a, b, c, d of
# the global (eq. 6), direct (eq. 8) and diffuse (eq. 7) luminous efficacy. [lm/W]
CLEARNESS_BINS = (1.0, 1.065, 1.230, 1.500, 1.950, 2.800, 4.500, 6.200)
"""Lower bounds of the eight sky-clearness bins of Perez et al. 1990, Table 1. [1]"""

_GLOBAL = np.array([
    [96.63, -0.47, 11.50, -9.16], [107.54, 0.79, 1.79, -1.19], [98.73, 0.70, 4.40, -6.95],
    [92.72, 0.56, 8.36, -8.31], [86.73, 0.98, 7.10, -10.94], [88.34, 1.39, 6.06, -7.60],
    [78.63, 1.47, 4.93, -11.37], [99.65, 1.86, -4.46, -3.15]])
_DIRECT = np.array([
    [57.20, -4.55, -2.98, 117.12], [98.99, -3.46, -1.21, 12.38], [109.83, -4.90, -1.71, -8.81],
    [110.34, -5.84, -1.99, -4.56], [106.36, -3.97, -1.75, -6.16], [107.19, -1.25, -1.51, -26.73],
    [105.75, 0.77, -1.26, -34.44], [101.18, 1.58, -1.10, -8.29]])
_DIFFUSE = np.array([
    [97.24, -0.46, 12.00, -8.91], [107.22, 1.15, 0.59, -3.95], [104.97, 2.96, -5.53, -8.77],
    [102.39, 5.59, -13.95, -13.90], [100.71, 5.94, -22.75, -23.74], [106.42, 3.83, -36.15, -28.83],
    [141.88, 1.90, -53.24, -14.03], [152.23, 0.35, -45.27, -7.98]])


@dataclass(frozen=True)
class Efficacy:
    """Luminous efficacies of daylight (Perez et al. 1990), with the sky they were read at.

    Attributes
    ----------
    global_horizontal : numpy.ndarray
        Efficacy of the global horizontal light, of the broadcast shape of the inputs [lm/W].
    direct_normal : numpy.ndarray
        Efficacy of the direct normal light [lm/W].
    diffuse_horizontal : numpy.ndarray
        Efficacy of the diffuse horizontal light [lm/W].
    clearness : numpy.ndarray
        The sky's clearness epsilon [1].
    brightness : numpy.ndarray
        The sky's brightness Delta [1].
    """

    global_horizontal: np.ndarray
    direct_normal: np.ndarray
    diffuse_horizontal: np.ndarray
    clearness: np.ndarray
    brightness: np.ndarray


def perez_efficacy(sun_zenith: ArrayLike, direct_normal: ArrayLike, diffuse_horizontal: ArrayLike, *,
                   relative_airmass: ArrayLike, extraterrestrial: float = SOLAR_CONSTANT,
                   precipitable_water: float = PRECIPITABLE_WATER) -> Efficacy:
    """Luminous efficacies of the global, direct and diffuse light of a sky.

    Perez, Ineichen, Seals, Michalsky & Stewart 1990, "Modeling daylight availability and irradiance
    components from direct and global irradiance", Solar Energy 44(5), 271-289: eqs. 6-8, Tables 1
    and 4. Clearness epsilon = ((D + I) / D + 1.041 Z^3) / (1 + 1.041 Z^3) picks a bin; brightness
    Delta = D m / I0. Global and diffuse: a + b W + c cos Z + d ln(Delta); direct:
    max(0, a + b W + c exp(5.73 Z - 5) + d Delta).

    Parameters
    ----------
    sun_zenith : float or numpy.ndarray
        Z [rad].
    direct_normal : float or numpy.ndarray
        I [W/m^2].
    diffuse_horizontal : float or numpy.ndarray
        D, above 0 [W/m^2].
    relative_airmass : float or numpy.ndarray
        m (the paper uses Kasten 1966) [1].
    extraterrestrial : float, optional
        I0, normal irradiance above the atmosphere [W/m^2].
    precipitable_water : float, optional
        W [cm].

    Arrays broadcast.

    Returns
    -------
    Efficacy
        The efficacies [lm/W], clearness and brightness [1], of the broadcast shape.

    Raises
    ------
    ValueError
        If a ``diffuse_horizontal`` is not above 0.
    """
    z = np.asarray(sun_zenith, dtype=np.float64)
    direct = np.asarray(direct_normal, dtype=np.float64)
    diffuse = np.asarray(diffuse_horizontal, dtype=np.float64)
    if np.any(diffuse <= 0):
        raise ValueError("diffuse_horizontal must be above 0 [W/m^2]")
    kz3 = 1.041 * z**3
    clearness = ((diffuse + direct) / diffuse + kz3) / (1.0 + kz3)
    brightness = diffuse * np.asarray(relative_airmass, dtype=np.float64) / extraterrestrial
    index = np.clip(np.searchsorted(CLEARNESS_BINS, clearness, side="right") - 1, 0, len(CLEARNESS_BINS) - 1)
    w = precipitable_water

    def row(table):
        return tuple(table[index, k] for k in range(4))

    a, b, c, d = row(_GLOBAL)
    global_horizontal = a + b * w + c * np.cos(z) + d * np.log(brightness)
    a, b, c, d = row(_DIRECT)
    direct_efficacy = np.maximum(0.0, a + b * w + c * np.exp(5.73 * z - 5.0) + d * brightness)
    a, b, c, d = row(_DIFFUSE)
    diffuse_efficacy = a + b * w + c * np.cos(z) + d * np.log(brightness)
    return Efficacy(global_horizontal, direct_efficacy, diffuse_efficacy, clearness, brightness)


@dataclass(frozen=True)
class ClearDaylight:
    """The light of a clear sky: direct normal and diffuse horizontal.

    As irradiance (Ineichen & Perez 2002) and illuminance (Perez et al. 1990 efficacies).

    Attributes
    ----------
    direct_normal_irradiance : float
        [W/m^2].
    diffuse_horizontal_irradiance : float
        [W/m^2].
    direct_normal_illuminance : float
        [klx].
    diffuse_horizontal_illuminance : float
        [klx].
    """

    direct_normal_irradiance: float
    diffuse_horizontal_irradiance: float
    direct_normal_illuminance: float
    diffuse_horizontal_illuminance: float


def clear_daylight(sun_zenith: float, linke_turbidity: float, *, altitude: float = 0.0,
                   distance_factor: float = 1.0,
                   precipitable_water: float = PRECIPITABLE_WATER) -> ClearDaylight:
    """Direct and diffuse light of the clear sky, in irradiance and illuminance.

    Ineichen & Perez 2002, "A new airmass independent formulation for the Linke turbidity
    coefficient", Solar Energy 73(3), 151-157, as ``pvlib.clearsky.ineichen``; in illuminance
    through ``perez_efficacy``.

    Parameters
    ----------
    sun_zenith : float
        Geometric zenith angle of the sun's centre, below pi/2 [rad].
    linke_turbidity : float
        Linke turbidity factor TL (air mass 2), in vocabulary.TURBIDITY_RANGE [1].
    altitude : float, optional
        Of the site above sea level: thinner air, less scattering [m].
    distance_factor : float, optional
        (1 au / sun's distance)^2, on the extraterrestrial irradiance [1].
    precipitable_water : float, optional
        W of the efficacy model [cm].

    Returns
    -------
    ClearDaylight
        Irradiances [W/m^2] and illuminances [klx].
    """
    from pvlib import atmosphere, clearsky

    zenith_deg = float(np.degrees(sun_zenith))
    extraterrestrial = SOLAR_CONSTANT * distance_factor
    airmass = atmosphere.get_absolute_airmass(atmosphere.get_relative_airmass(zenith_deg, "kastenyoung1989"),
                                              atmosphere.alt2pres(altitude))
    sky = clearsky.ineichen(zenith_deg, airmass, linke_turbidity, altitude=altitude,
                            dni_extra=extraterrestrial)
    dni, dhi = float(sky["dni"]), float(sky["dhi"])
    if not dhi > 0:
        return ClearDaylight(dni, 0.0, 0.0, 0.0)
    efficacy = perez_efficacy(sun_zenith, dni, dhi,
                              relative_airmass=atmosphere.get_relative_airmass(zenith_deg, "kasten1966"),
                              extraterrestrial=extraterrestrial, precipitable_water=precipitable_water)
    return ClearDaylight(dni, dhi, dni * float(efficacy.direct_normal) / 1000.0,
                         dhi * float(efficacy.diffuse_horizontal) / 1000.0)


def linke_turbidity(when: datetime, latitude: float, longitude: float) -> float:
    """The Linke turbidity factor of a place and month.

    From the climatology of Remund et al. (2003) shipped with pvlib
    (``pvlib.clearsky.lookup_linke_turbidity``, interpolated between months; no network).

    Parameters
    ----------
    when : datetime.datetime
        UTC time.
    latitude : float
        [rad].
    longitude : float
        [rad].

    Returns
    -------
    float
        TL [1].
    """
    import warnings

    import pandas as pd
    from pvlib import clearsky

    index = pd.DatetimeIndex([pd.Timestamp(when)])
    with warnings.catch_warnings():  # pandas' deprecation notes on pvlib's own calls
        warnings.simplefilter("ignore")
        value = clearsky.lookup_linke_turbidity(index, float(np.degrees(latitude)), float(np.degrees(longitude)))
    return float(np.asarray(value)[0])


# --- low sun and civil twilight (docs/method.md, "The procedural sky": low sun and twilight) ---

TWILIGHT_END = float(np.radians(-6.0))
"""The lowest sun the sky is drawn for: the end of civil twilight. [rad]"""

TWILIGHT_BLEND = (6.0, 10.0)
"""Sun elevations between which the horizontal illuminance passes from the USNO curve (below)
to Ineichen & Perez with the Perez efficacies (above; unchanged there), by a smoothstep in
log illuminance. Below about 6 degrees pvlib's Ineichen model falls far under the measured
curve (at 3 degrees, TL 3: 0.4-0.6 of it; docs/accuracy.md). [deg]"""

# Janiczek & DeYoung 1987 (USNO Circular 171), the sun's illuminance program: log10 E [lx] =
# L0 + L1 x + L2 x^2 + L3 x^3, x = altitude / 90 degrees, per altitude band (lower bound, deg),
# as reproduced in Vallado, Fundamentals of Astrodynamics and Applications (4th ed. 2013),
# Table 5-1.
_USNO_SUN = ((20.0, (3.74, 3.97, -4.07, 1.47)), (5.0, (3.05, 13.28, -45.98, 64.33)),
             (-0.8, (2.88, 22.26, -207.64, 1034.30)), (-5.0, (2.88, 21.81, -258.11, -858.36)),
             (-12.0, (2.70, 12.17, -431.69, -1899.83)), (-18.0, (13.84, 262.72, 1447.42, 2797.93)))


def usno_illuminance(elevation_deg: ArrayLike) -> np.ndarray:
    """Horizontal illuminance of the sun and the clear sky at the mean sun distance.

    Janiczek & DeYoung 1987, USNO Circular 171: the curve of its illuminance program, altitude bands
    of ``_USNO_SUN``; 0 below -18 degrees.

    Parameters
    ----------
    elevation_deg : float or numpy.ndarray
        The sun's (true) altitude [deg].

    Returns
    -------
    numpy.ndarray
        float64 of the shape of ``elevation_deg`` [lx].
    """
    h = np.asarray(elevation_deg, dtype=np.float64)
    x = h / 90.0
    log_e = np.full(h.shape, -np.inf)
    for lower, (l0, l1, l2, l3) in reversed(_USNO_SUN):
        log_e = np.where(h >= lower, l0 + x * (l1 + x * (l2 + x * l3)), log_e)
    return 10.0**log_e


TWILIGHT_MAX_FALL = 1.0
"""The steepest fall of the modelled twilight light, d ln E / dh: 9.5% a tenth of a degree
(``twilight_illuminance``). The USNO curve falls 10.0-12.0% a tenth from -3.4 down to -6 degrees;
capped, the light falls by less than 10% between neighbouring tenths (docs/method.md). [1/deg]"""


def twilight_illuminance(elevation_deg: ArrayLike) -> np.ndarray:
    """The USNO curve with its fall capped: the lowest curve at or above it whose log falls no faster
    than TWILIGHT_MAX_FALL.

    ln E(h) = s h + max over h' in [h, 10 degrees] of (ln E_USNO(h') - s h'), s = TWILIGHT_MAX_FALL,
    on a 0.001-degree grid from the end of civil twilight to 10 degrees, linear in between; the
    curve's own value where that is not above it. It is the curve (``usno_illuminance``) from -4
    degrees up (but for 0.9% just under 5 degrees, where its bands meet with a jump) and departs
    from it below, where the
    curve falls faster than s: 1.06 times the curve at -5 degrees, 1.19 at -6 (4.1 lx for 3.4;
    docs/accuracy.md, "Low sun, civil twilight and the overcast colour").

    Parameters
    ----------
    elevation_deg : float or numpy.ndarray
        The sun's altitude, in [-6, 10] (clamped to it) [deg].

    Returns
    -------
    numpy.ndarray
        float64 of the shape of ``elevation_deg`` [lx].
    """
    s = TWILIGHT_MAX_FALL
    grid = np.arange(round(np.degrees(TWILIGHT_END) * 1000), round(TWILIGHT_BLEND[1] * 1000) + 1) / 1000.0
    capped = np.maximum.accumulate((np.log(usno_illuminance(grid)) - s * grid)[::-1])[::-1]
    h = np.clip(np.asarray(elevation_deg, dtype=np.float64), grid[0], grid[-1])
    curve = usno_illuminance(h)
    ramp = np.exp(np.interp(h, grid, capped) + s * h)
    # the curve's own values where the cap is idle (the ramp there is the curve to rounding)
    return np.where(ramp > curve * (1.0 + 1e-9), ramp, curve)


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def sky_daylight(sun_elevation: float, linke_turbidity: float, *, altitude: float = 0.0,
                 distance_factor: float = 1.0, precipitable_water: float = PRECIPITABLE_WATER,
                 sun_radius: float = float(np.radians(0.2666))) -> ClearDaylight:
    """The clear sky's direct and diffuse light at any sun from the zenith to the end of civil twilight.

    ``clear_daylight`` at and above TWILIGHT_BLEND[1]; below, the global horizontal illuminance E of
    the USNO curve with its fall capped (``twilight_illuminance``, times ``distance_factor``) blended
    into Ineichen & Perez's by a smoothstep in log E over TWILIGHT_BLEND. The sun keeps Ineichen &
    Perez's direct normal light while its whole disc is up (0 below), and the sky takes the rest: diffuse = E - direct x
    sin(elevation), at least 5% of E.

    Parameters
    ----------
    sun_elevation : float
        Of the sun's centre, in [TWILIGHT_END, pi/2] [rad].
    linke_turbidity : float
        As ``clear_daylight`` [1].
    altitude : float, optional
        As ``clear_daylight`` [m].
    distance_factor : float, optional
        As ``clear_daylight`` [1].
    precipitable_water : float, optional
        As ``clear_daylight`` [cm].
    sun_radius : float, optional
        The disc's angular radius: no direct light below it [rad].

    Returns
    -------
    ClearDaylight
        Irradiances [W/m^2] (Ineichen & Perez's) and illuminances [klx].

    Raises
    ------
    ValueError
        If the sun is below TWILIGHT_END.
    """
    h = float(np.degrees(sun_elevation))
    if not sun_elevation >= TWILIGHT_END - 1e-12:
        raise ValueError(f"the sun at {h:.2f} degrees is below the end of civil twilight "
                         f"({np.degrees(TWILIGHT_END):g} degrees): no sky is drawn for it")
    kwargs = dict(altitude=altitude, distance_factor=distance_factor, precipitable_water=precipitable_water)
    low, high = TWILIGHT_BLEND
    if h >= high:
        return clear_daylight(np.pi / 2 - sun_elevation, linke_turbidity, **kwargs)
    ip = clear_daylight(np.pi / 2 - max(sun_elevation, 1e-4), linke_turbidity, **kwargs)
    direct = ip.direct_normal_illuminance if sun_elevation > sun_radius else 0.0
    usno = float(twilight_illuminance(h)) * distance_factor / 1000.0
    w = float(_smoothstep((h - low) / (high - low)))
    if w > 0.0:
        modelled = direct * np.sin(sun_elevation) + ip.diffuse_horizontal_illuminance
        usno = float(np.exp((1.0 - w) * np.log(usno) + w * np.log(modelled)))
    horizontal = direct * max(np.sin(sun_elevation), 0.0)
    diffuse = max(usno - horizontal, 0.05 * usno)
    return ClearDaylight(ip.direct_normal_irradiance if direct else 0.0, ip.diffuse_horizontal_irradiance,
                         direct, diffuse)
