"""The sun and moon discs as seen from the ground: the sun's colour after the atmosphere, its
limb-darkened radiance, the dark moon that cuts it, and their anti-aliased samples.

Directions: azimuth from north towards east, elevation above the horizon [rad]; radiance in the
sky's units (kcd/m^2 for a procedural sky), normal irradiance [radiance x sr].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.constants import SUN_ANGULAR_RADIUS
from pipeline.core.geometry import direction_vector, length3
from pipeline.sky import daylight, eclipse

__all__ = ["LIMB_DARKENING", "RGB_WAVELENGTHS", "MoonDisc", "SunDisc", "SunLight", "sun_colour", "sun_light",
           "sun_disc_radiance"]


RGB_WAVELENGTHS = eclipse.RGB_WAVELENGTHS
"""Representative wavelengths of the R, G, B channels for the colour of the sun's attenuation
(``eclipse.RGB_WAVELENGTHS``, which the eclipse sky's channels share). [um]"""

LIMB_DARKENING = (0.52, 0.59, 0.68)
"""Linear limb-darkening coefficients u of I(mu) / I(1) = 1 - u (1 - mu) for R, G, B. G: the
linear law with the disc-mean of Allen's quadratic law at 550 nm, I/I(1) = 0.30 + 0.93 mu -
0.23 mu^2 (Cox 2000, Allen's Astrophysical Quantities, 4th ed., sec. 14.7), i.e. 1 - u/3 = 0.805;
R and B follow the stronger darkening at shorter wavelengths (Hestroffer & Magnan 1998, A&A 333,
338); approximate. [1]"""


def sun_colour(zenith: float, turbidity: float) -> np.ndarray:
    """The sun's colour after the atmosphere's extinction, scaled to Rec.709 luminance 1.

    The direct transmittance for R, G, B of Preetham et al. (1999, appendix A.1), Rayleigh
    tau_R = exp(-0.008735 lambda^-4.08 m) times Angstrom aerosol tau_a = exp(-beta lambda^-1.3 m),
    beta = 0.04608 T - 0.04586, at RGB_WAVELENGTHS [um] (``eclipse.vertical_optical_depths``), m
    the Kasten & Young (1989) relative air mass of pvlib. Only the ratios between the channels are
    kept: the level is ``daylight``'s.

    Parameters
    ----------
    zenith : float
        The sun's zenith angle, in [0, pi/2) [rad].
    turbidity : float
        Linke turbidity T [1].

    Returns
    -------
    numpy.ndarray
        (3,) float64 linear Rec.709 relative colour, luminance 1 [1].
    """
    from pvlib import atmosphere

    m = float(atmosphere.get_relative_airmass(float(np.degrees(zenith)), "kastenyoung1989"))
    rayleigh, aerosol = eclipse.vertical_optical_depths(turbidity)
    transmittance = np.exp(-m * (rayleigh + aerosol))
    return transmittance / (transmittance @ np.asarray(REC709_LUMINANCE, dtype=np.float64))


def sun_disc_radiance(angular_distance: ArrayLike, *, angular_radius: float, normal_irradiance: ArrayLike,
                      limb_darkening: ArrayLike) -> np.ndarray:
    """Radiance of a limb-darkened disc.

    The linear law I(mu) = I(1) (1 - u (1 - mu)), mu = sqrt(1 - (rho / r)^2) (e.g. Cox 2000,
    Allen's Astrophysical Quantities, sec. 14.7).

    Parameters
    ----------
    angular_distance : float or numpy.ndarray
        rho (...), from the disc centre [rad]; the radiance is 0 beyond the limb.
    angular_radius : float
        The disc's radius r [rad].
    normal_irradiance : array_like
        (3,) integral of the radiance over the flat disc, pi r^2 I(1) (1 - u/3) [klx].
    limb_darkening : array_like
        (3,) linear-law coefficients u, 0 for a uniform disc [1].

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 radiance [kcd/m^2].
    """
    rho = np.asarray(angular_distance, dtype=np.float64)[..., None]
    u = np.asarray(limb_darkening, dtype=np.float64)
    centre = np.asarray(normal_irradiance, dtype=np.float64) / (np.pi * angular_radius**2 * (1.0 - u / 3.0))
    mu = np.sqrt(np.clip(1.0 - (rho / angular_radius) ** 2, 0.0, 1.0))
    return np.where(rho <= angular_radius, centre * (1.0 - u * (1.0 - mu)), 0.0)


@dataclass(frozen=True)
class SunDisc:
    """The sun as seen from the ground.

    Parameters
    ----------
    azimuth : float
        From north towards east [rad].
    elevation : float
        Above the horizon (geometric) [rad].
    angular_radius : float
        Radius of the disc, in (0, 0.1) [rad]; its normal irradiance scales as its square.
    limb_darkening : tuple
        (3,) linear-law coefficients u for R, G, B in [0, 1]; (0, 0, 0) for a uniform disc [1].

    Raises
    ------
    ValueError
        For a direction, radius or limb darkening out of range.
    """

    azimuth: float
    elevation: float
    angular_radius: float = SUN_ANGULAR_RADIUS
    limb_darkening: tuple = LIMB_DARKENING

    def __post_init__(self):
        _check_disc(self, "sun")
        u = np.asarray(self.limb_darkening, dtype=np.float64)
        if u.shape != (3,) or np.any(~((u >= 0) & (u <= 1))):
            raise ValueError(f"sun limb_darkening must be three numbers in [0, 1], got {self.limb_darkening}")


@dataclass(frozen=True, eq=False)
class SunLight:
    """What pvlib's formulas give a procedural sky at its sun (``sun_light``): the clear sky's
    daylight and the sun's colour, with the sun, turbidity and altitude they are of.

    Made once in the command for a sun that stands still and carried by the plan's sky model, so
    that the workers rendering the frames neither import pvlib nor compute them again
    (docs/accuracy.md, "A worker's first frame").

    Attributes
    ----------
    sun : SunDisc
        The sun.
    turbidity : float
        Linke turbidity TL [1].
    altitude : float
        Of the site above sea level [m].
    daylight : daylight.ClearDaylight
        ``daylight.sky_daylight`` at the sun [W/m^2, klx].
    colour : numpy.ndarray
        (3,) ``sun_colour`` at the sun [1].
    """

    sun: SunDisc
    turbidity: float
    altitude: float
    daylight: daylight.ClearDaylight
    colour: np.ndarray

    def of(self, sun: SunDisc, turbidity: float, altitude: float) -> bool:
        """Whether this is the light of ``sun`` at ``turbidity`` [1] and ``altitude`` [m].

        Parameters
        ----------
        sun : SunDisc
            The sun.
        turbidity : float
            Linke turbidity TL [1].
        altitude : float
            Of the site above sea level [m].

        Returns
        -------
        bool
            True when all three are this light's.
        """
        return (self.sun, self.turbidity, self.altitude) == (sun, turbidity, altitude)


def sun_light(sun: SunDisc, turbidity: float, altitude: float) -> SunLight:
    """The clear sky's daylight (``daylight.sky_daylight``) and the sun's colour (``sun_colour``) at a sun.

    Parameters
    ----------
    sun : SunDisc
        The sun, at least ``daylight.TWILIGHT_END`` high; its angular radius gives its distance [rad].
    turbidity : float
        Linke turbidity TL [1].
    altitude : float
        Of the site above sea level [m].

    Returns
    -------
    SunLight
        Irradiances [W/m^2], illuminances [klx] and the colour [1].
    """
    light = daylight.sky_daylight(sun.elevation, turbidity, altitude=altitude,
                                  distance_factor=(sun.angular_radius / SUN_ANGULAR_RADIUS) ** 2,
                                  sun_radius=sun.angular_radius)
    colour = sun_colour(min(np.pi / 2 - sun.elevation, np.pi / 2), turbidity)
    return SunLight(sun, turbidity, altitude, light, colour)


@dataclass(frozen=True)
class MoonDisc:
    """The new moon: a dark disc that cuts the sun (it does not hide the sky, which is lit in front of it).

    Parameters
    ----------
    azimuth, elevation, angular_radius : float
        As in ``SunDisc``.

    Raises
    ------
    ValueError
        For a direction or radius out of range.
    """

    azimuth: float
    elevation: float
    angular_radius: float

    def __post_init__(self):
        _check_disc(self, "moon")


def _check_disc(disc, name):
    """Raise ValueError unless ``disc``'s direction is finite, |elevation| <= pi/2, and its radius in (0, 0.1) [rad]."""
    if not (np.isfinite(disc.azimuth) and np.isfinite(disc.elevation) and abs(disc.elevation) <= np.pi / 2):
        raise ValueError(f"{name} azimuth and elevation must be finite, |elevation| <= pi/2 [rad]")
    if not (0.0 < disc.angular_radius < 0.1):
        raise ValueError(f"{name} angular_radius must be in (0, 0.1) [rad], got {disc.angular_radius}")


def angle_to(w: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Angle [rad] between unit vectors w (..., 3) and c (3,), stable for small angles."""
    return 2.0 * np.arcsin(np.clip(0.5 * length3(w - c), 0.0, 1.0))


def disc_samples(w: np.ndarray, footprint: Callable[[np.ndarray, np.ndarray, np.ndarray], float | np.ndarray],
                 widest: float, sun: SunDisc, direction: np.ndarray, normal_irradiance: ArrayLike,
                 moon: MoonDisc | None = None) -> np.ndarray:
    """Radiance (..., 3) of the limb-darkened sun disc at unit vectors w (..., 3), optionally cut
    by a dark moon, the disc edges (sun limb, moon limb) anti-aliased by a linear ramp over
    ``footprint(centre, rho, near)`` [rad]: the sample spacing measured along the angular distance
    rho from ``centre``, at the samples ``w[near]`` (``near`` a boolean mask of w's leading axes,
    rho their angles), at most ``widest`` [rad].

    The ramp is computed only within ``widest`` of a limb (``_limb_ramp``): beyond, it is exactly
    1 or 0, as its expression gives there. A low sun's kernel holds millions of samples a frame
    (docs/accuracy.md, "A low sun's kernel").

    sun : SunDisc (its radius and limb darkening); direction : (3,) unit vector of its centre. [1]
    normal_irradiance : (3,) of the whole disc. [radiance x sr]
    Returns (..., 3) float64. [radiance]
    """
    r = sun.angular_radius
    rho = angle_to(w, direction)
    cover = _limb_ramp(rho, r, -1.0, lambda near: footprint(direction, rho[near], near), widest)
    if moon is not None:
        centre = direction_vector(moon.azimuth, moon.elevation)
        rho_m = angle_to(w, centre)
        cover *= _limb_ramp(rho_m, moon.angular_radius, 1.0, lambda near: footprint(centre, rho_m[near], near),
                            widest)
    lit = ~(cover <= 0.0)  # elsewhere the radiance times the cover is +0, whatever the radiance
    value = np.zeros((*rho.shape, 3))
    value[lit] = sun_disc_radiance(np.minimum(rho[lit], r), angular_radius=r, normal_irradiance=normal_irradiance,
                                   limb_darkening=sun.limb_darkening)
    return value * cover[..., None]


def _limb_ramp(rho, radius: float, sign: float, footprint_at, widest: float) -> np.ndarray:
    """``clip(0.5 + sign (rho - radius) / f, 0, 1)`` at angles rho (...) [rad] from a disc's centre
    of ``radius`` [rad] (sign -1: 1 inside the disc, the sun's cover; +1: 1 outside, the moon's),
    f = ``footprint_at(near)`` [rad] at most ``widest`` [rad], computed where |rho - radius| <
    widest (``near``, and where rho is NaN). Elsewhere |rho - radius| / f >= 1, so the expression
    is clipped to exactly 1 or 0: the same values, the footprint computed only near the limb."""
    beyond = sign * (rho - radius)  # [rad] past the limb, towards where the ramp is 1
    ramp = (beyond > 0.0).astype(np.float64)
    near = ~(np.abs(beyond) >= widest)  # NaN too
    if sign < 0:
        ramp[near] = np.clip(0.5 - (rho[near] - radius) / footprint_at(near), 0.0, 1.0)
    else:
        ramp[near] = np.clip(0.5 + (rho[near] - radius) / footprint_at(near), 0.0, 1.0)
    return ramp
