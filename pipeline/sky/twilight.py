"""The colour of the sky after sunset: how each direction's colour changes as the sun goes down.

Single scattering of sunlight in a spherical, layered atmosphere, the explanation of the twilight
sky's colours by Hulburt (1953, "Explanation of the brightness and color of the sky, particularly
the twilight sky", JOSA 43(2), 113-118): molecules (Rayleigh) and aerosol (Angstrom) with their
scale heights (``eclipse``'s constants and optical depths), and ozone's Chappuis band, which
absorbs the orange and red of the sunlight that grazes the stratosphere and keeps the zenith blue
after sunset. A point along a line of sight is lit through the whole atmosphere the sun's ray
crosses to reach it, or not at all where the Earth hides the sun (its shadow): the sky opposite
the sun is lit only above the shadow, by reddened light (the Belt of Venus). No refraction, no
multiple scattering but a floor (``eclipse.MULTIPLE_SCATTERING``) in the zenith's colour, a point sun.

``twilight_colour`` gives the factor, per channel, by which this light's colour at a sun below
the horizon differs from its colour with the sun on the horizon; ``clearsky.relative_sky`` puts
it on the colour it has there (docs/method.md, "The procedural sky": low sun and twilight).
Units: metres, radians.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky.eclipse import (
    AEROSOL_ASYMMETRY,
    AEROSOL_SCALE_HEIGHT,
    EARTH_RADIUS,
    MULTIPLE_SCATTERING,
    RAYLEIGH_SCALE_HEIGHT,
    vertical_optical_depths,
)

__all__ = ["OZONE_COLUMN", "OZONE_CROSS_SECTION", "OZONE_LAYER", "ATMOSPHERE_TOP", "SHELL_THICKNESS", "SHELL_HEIGHTS",
           "TABLE_ELEVATIONS", "TABLE_AZIMUTHS", "single_scattering", "twilight_colour"]

OZONE_COLUMN = 300.0 * 2.687e20
"""Ozone's vertical column: 300 Dobson units (a mid-latitude mean), 2.687e20 molecules/m^2 each. [1/m^2]"""

OZONE_CROSS_SECTION = np.array([0.5 * (5.019e-25 + 4.305e-25), 0.5 * (3.091e-25 + 3.5e-25), 3.669e-26])
"""Ozone's absorption cross-section at ``eclipse.RGB_WAVELENGTHS`` (610, 550, 465 nm): Serdyuchenko
et al. (2014, Atmos. Meas. Tech. 7, 625) at 233 K, the means of their 10-nm bins as tabulated by
Bruneton (2017, "A qualitative and quantitative evaluation of 8 clear sky models", its reference
implementation): 610 and 550 nm the two bins either side, 465 nm the bin 460-470. [m^2]"""

OZONE_LAYER = (10_000.0, 25_000.0, 40_000.0)
"""Ozone's number density: a tent from 0 at the first height to its peak at the second and 0 at the
third (Bruneton 2017's profile). [m]"""

ATMOSPHERE_TOP = 80_000.0
"""Height above which the atmosphere is left out (Rayleigh's density there: e^-10). [m]"""

SHELL_THICKNESS = 1_000.0
"""Thickest shell of the layered atmosphere (an eighth of Rayleigh's scale height): within 1.6% of
the brute-force integral of the continuous profiles along grazing rays (``tests/test_twilight.py``). [m]"""

_geometric = 50.0 * 1.15 ** np.arange(30)
SHELL_HEIGHTS = np.unique(np.concatenate([[0.0], _geometric[_geometric < SHELL_THICKNESS],
                                          np.arange(SHELL_THICKNESS, ATMOSPHERE_TOP + 1.0, SHELL_THICKNESS),
                                          OZONE_LAYER]))
"""Boundaries of the homogeneous shells the atmosphere is cut into: 15% thicker each from 50 m up
to SHELL_THICKNESS, then SHELL_THICKNESS apart to ATMOSPHERE_TOP, the ozone tent's corners among
them (so its density is linear within a shell). [m]"""

TABLE_ELEVATIONS = 17
"""Elevations at which ``twilight_colour`` computes the colour, quadratically spaced from the
horizon to the zenith (0.35 degrees apart at the horizon); bilinear in between. [count]"""

TABLE_AZIMUTHS = 13
"""Azimuths from the sun's, 15 degrees apart from 0 to 180 (the sky is symmetric). [count]"""


def _shell_extinction(turbidity: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The extinction coefficients (Rayleigh, aerosol, ozone), each (shells, 3), of the homogeneous
    shells [1/m]: the exact mean of the exponential Rayleigh and aerosol densities over each shell,
    and the ozone tent's mean."""
    z0, z1 = SHELL_HEIGHTS[:-1], SHELL_HEIGHTS[1:]
    rayleigh, aerosol = vertical_optical_depths(turbidity)

    def exponential(h):
        return ((np.exp(-z0 / h) - np.exp(-z1 / h)) / (z1 - z0))[:, None]

    low, peak, high = OZONE_LAYER
    mid = 0.5 * (z0 + z1)
    tent = np.clip(np.minimum((mid - low) / (peak - low), (high - mid) / (high - peak)), 0.0, None)
    ozone = (OZONE_COLUMN / (0.5 * (high - low)) * tent)[:, None] * OZONE_CROSS_SECTION
    return (rayleigh * exponential(RAYLEIGH_SCALE_HEIGHT), aerosol * exponential(AEROSOL_SCALE_HEIGHT), ozone)


def _within(r, mu, radii):
    """Length (..., K) of the ray from radius r (...) with direction cosine mu (...) to the local
    vertical that lies inside each sphere of ``radii`` (K,) ahead of it. [m]"""
    r, mu = r[..., None], mu[..., None]
    root = np.sqrt(np.maximum((radii - r) * (radii + r) + (r * mu) ** 2, 0.0))
    inside = r <= radii
    crosses = (mu < 0.0) & ((radii - r) * (radii + r) + (r * mu) ** 2 > 0.0)
    return np.where(inside, root - r * mu, np.where(crosses, 2.0 * root, 0.0))


def single_scattering(view_elevation: ArrayLike, view_azimuth: ArrayLike, *, sun_elevation: float,
                      turbidity: float, sub_points: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Singly scattered sunlight reaching the ground observer along lines of sight.

    Each line of sight is cut where it crosses the shells' boundaries; in each piece, ``sub_points``
    points at its midpoints scatter the sunlight that reaches them (the shells' optical depths
    along the sun's ray, exact for the layered atmosphere: the lengths of chords; 0 behind the
    Earth) by Rayleigh's phase function and aerosol's Henyey-Greenstein (``eclipse.AEROSOL_ASYMMETRY``),
    dimmed on the way to the observer.

    Parameters
    ----------
    view_elevation, view_azimuth : numpy.ndarray
        (n,) of the lines of sight, elevation in [0, pi/2], azimuth from the sun's [rad].
    sun_elevation : float
        [rad].
    turbidity : float
        Linke turbidity T of ``eclipse.vertical_optical_depths`` [1].
    sub_points : int, optional
        Points per piece of a line of sight [count].

    Returns
    -------
    radiance : numpy.ndarray
        (n, 3) per channel, for a sun of unit irradiance at every wavelength [1/sr].
    depth : numpy.ndarray
        (n, 3) the lines of sight's optical depths to the top of the atmosphere [1].
    """
    e = np.asarray(view_elevation, dtype=np.float64)
    phi = np.asarray(view_azimuth, dtype=np.float64)
    radii = EARTH_RADIUS + SHELL_HEIGHTS
    rayleigh, aerosol, ozone = _shell_extinction(turbidity)
    extinction = rayleigh + aerosol + ozone
    mu = np.sin(e)[:, None]
    crossing = np.sqrt((radii - EARTH_RADIUS) * (radii + EARTH_RADIUS) + (EARTH_RADIUS * mu) ** 2) - EARTH_RADIUS * mu
    piece = np.diff(crossing, axis=1)  # (n, shells) [m]
    view = np.stack([np.cos(e) * np.cos(phi), np.cos(e) * np.sin(phi), np.sin(e)], axis=-1)
    sun = np.array([np.cos(sun_elevation), 0.0, np.sin(sun_elevation)])
    c = view @ sun
    p_r = 3.0 / (16.0 * np.pi) * (1.0 + c * c)
    g = AEROSOL_ASYMMETRY
    p_a = (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * c) ** 1.5)
    before = np.concatenate([np.zeros((len(e), 1, 3)), np.cumsum(piece[..., None] * extinction, axis=1)[:, :-1]], 1)
    total = np.zeros((len(e), 3))
    for f in (np.arange(sub_points) + 0.5) / sub_points:
        t = crossing[:, :-1] + f * piece  # (n, shells)
        point = t[..., None] * view[:, None, :]
        point[..., 2] += EARTH_RADIUS
        r = np.linalg.norm(point, axis=-1)
        mu_sun = (point @ sun) / r
        lit = ~((mu_sun < 0.0) & (r * r * (1.0 - mu_sun * mu_sun) < EARTH_RADIUS**2))
        to_sun = np.diff(_within(r, mu_sun, radii), axis=-1) @ extinction  # (n, shells, 3)
        to_observer = before + f * piece[..., None] * extinction
        scattering = rayleigh * p_r[:, None, None] + aerosol * p_a[:, None, None]
        total += np.einsum("nkc,nk->nc", scattering * np.exp(-to_sun - to_observer),
                           lit * piece / sub_points)
    return total, (piece[..., None] * extinction).sum(axis=1)


def _sky_light(view_elevation, view_azimuth, sun_elevation: float, turbidity: float) -> np.ndarray:
    """``single_scattering`` (n, 3) plus a floor of multiply scattered light: MULTIPLE_SCATTERING
    times the zenith's single-scattered light, in its colour, times 1 - exp(-depth) of the line of
    sight over the zenith's (the Earth's shadow, where no single-scattered light comes from, takes
    the colour of the sky above it). [1/sr]"""
    e = np.append(view_elevation, np.pi / 2)
    radiance, depth = single_scattering(e, np.append(view_azimuth, 0.0), sun_elevation=sun_elevation,
                                        turbidity=turbidity)
    reach = -np.expm1(-depth)
    return radiance[:-1] + MULTIPLE_SCATTERING * radiance[-1] * reach[:-1] / reach[-1]


def _nodes() -> tuple[np.ndarray, np.ndarray]:
    """The table's directions: (elevations, azimuths from the sun's), each (TABLE_ELEVATIONS x TABLE_AZIMUTHS,).
    [rad]"""
    e = np.radians(90.0) * np.linspace(0.0, 1.0, TABLE_ELEVATIONS) ** 2
    phi = np.radians(np.linspace(0.0, 180.0, TABLE_AZIMUTHS))
    elevations, azimuths = np.meshgrid(e, phi, indexing="ij")
    return elevations.ravel(), azimuths.ravel()


@lru_cache(maxsize=4)
def _at_sunset(turbidity: float) -> np.ndarray:
    """``_sky_light`` at the table's nodes with the sun on the horizon, read-only. [1/sr]"""
    light = _sky_light(*_nodes(), 0.0, turbidity)
    light.setflags(write=False)
    return light


@lru_cache(maxsize=8)
def _table(sun_elevation: float, turbidity: float) -> np.ndarray:
    """(TABLE_ELEVATIONS, TABLE_AZIMUTHS, 3) the colour factor of ``twilight_colour`` at the table's
    nodes, luminance 1 each. [1]"""
    ratio = _sky_light(*_nodes(), sun_elevation, turbidity) / _at_sunset(turbidity)
    ratio /= (ratio @ np.asarray(REC709_LUMINANCE, dtype=np.float64))[:, None]
    ratio = ratio.reshape(TABLE_ELEVATIONS, TABLE_AZIMUTHS, 3)
    ratio.setflags(write=False)
    return ratio


def twilight_colour(cos_zenith: ArrayLike, gamma: ArrayLike, *, sun_elevation: float, turbidity: float) -> np.ndarray:
    """The change of the sky's colour from a sun on the horizon to a sun below it.

    The ratio, per channel, of ``single_scattering`` at ``sun_elevation`` to its value with the sun
    on the horizon, scaled to luminance 1; computed on a table of TABLE_ELEVATIONS x TABLE_AZIMUTHS
    directions (cached per sun and turbidity) and interpolated bilinearly in elevation and
    azimuth.

    Parameters
    ----------
    cos_zenith : float or numpy.ndarray
        cos of the directions' zenith angle, in [0, 1] [1].
    gamma : float or numpy.ndarray
        Their angle from the sun, broadcastable with ``cos_zenith`` [rad].
    sun_elevation : float
        Below 0 [rad].
    turbidity : float
        T [1].

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 factors, Rec.709 luminance 1 [1].
    """
    cos_z, gamma = np.broadcast_arrays(np.asarray(cos_zenith, dtype=np.float64), np.asarray(gamma, dtype=np.float64))
    elevation = np.arcsin(np.clip(cos_z, 0.0, 1.0))
    cos_e = np.sqrt(np.maximum(1.0 - cos_z * cos_z, 1e-12))
    cos_phi = (np.cos(gamma) - cos_z * np.sin(sun_elevation)) / (cos_e * np.cos(sun_elevation))
    phi = np.arccos(np.clip(cos_phi, -1.0, 1.0))
    table = _table(float(sun_elevation), float(turbidity))
    row = np.sqrt(elevation / (np.pi / 2)) * (TABLE_ELEVATIONS - 1)
    col = phi / np.pi * (TABLE_AZIMUTHS - 1)
    i = np.clip(np.floor(row).astype(np.int64), 0, TABLE_ELEVATIONS - 2)
    j = np.clip(np.floor(col).astype(np.int64), 0, TABLE_AZIMUTHS - 2)
    a, b = (row - i)[..., None], (col - j)[..., None]
    return ((1 - a) * ((1 - b) * table[i, j] + b * table[i, j + 1])
            + a * ((1 - b) * table[i + 1, j] + b * table[i + 1, j + 1]))
