"""Topocentric sun and moon: positions, angular radii, eclipse obscuration and contact times.

Positions come from PyEphem (``ephem``, libastro; offline, no data download). Conventions
(docs/method.md, "Conventions"): radians everywhere, azimuth from north towards east, elevation from the
horizon. Elevations are *geometric* topocentric ones: the observer's pressure is set to 0 so
that ephem applies no atmospheric refraction, and the sun and moon keep their true shapes and
relative positions (refraction would lift both by about the same amount and squash the discs
near the horizon, which the renderer does not model).

Angular radii are computed here, not taken from ephem, from the topocentric distances ephem
gives and the radii adopted for eclipse predictions (Espenak & Meeus 2006, *Five Millennium
Canon of Solar Eclipses*, NASA/TP-2006-214141, section 1.2): the sun's radius is 959.63 arcsec
at 1 au, the moon's is k = 0.2725076 Earth equatorial radii (its mean limb, used there for the
partial-phase contacts). One radius per body is used for every contact and for the obscured
fraction, so ``obscured_fraction`` is exactly 1 between the C2 and C3 that ``contact_times``
returns. The lunar limb profile (valleys, mountains; a few seconds at C2 and C3) is ignored.

Times are UTC, taken as UT1 (|UT1 - UTC| < 0.9 s). Delta T = TT - UT1 is ``delta_t``: ephem's own
before 2018, the values the USNO measured after (ephem 4.2.1 extrapolates there, 74.6 s in 2027
against the measured 69.2 s, which made contacts about 5 s early). Contact times against
published local circumstances and against JPL's DE421 are in docs/accuracy.md ("The eclipse
finder against DE421"; tests/test_ephemeris.py, tests/test_eclipse_finder.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

import ephem
import numpy as np
from numpy.typing import ArrayLike

from pipeline.core.constants import SUN_ANGULAR_RADIUS
from pipeline.core.geometry import direction_vector, tangent_axes

__all__ = [
    "AU", "SUN_RADIUS", "EARTH_EQUATORIAL_RADIUS", "MOON_RADIUS", "Site", "BodyPosition", "sun_and_moon",
    "separation", "obscured_fraction", "moon_offset_from_sun", "contact_times", "Circumstances", "circumstances",
    "EARTH_ROTATION_RATE", "DELTA_T_MEASURED", "delta_t", "ephem_date",
]

AU = 149_597_870_700.0
"""Astronomical unit (IAU 2012 resolution B2). [m]"""

SUN_RADIUS = AU * np.sin(SUN_ANGULAR_RADIUS)
"""Solar radius giving ``constants.SUN_RADIUS_ARCSEC`` (959.63 arcsec) at 1 au, the
eclipse-prediction value (Espenak & Meeus 2006). [m]"""

EARTH_EQUATORIAL_RADIUS = 6_378_137.0
"""WGS84 / IERS equatorial radius of the Earth. [m]"""

MOON_RADIUS = 0.2725076 * EARTH_EQUATORIAL_RADIUS
"""Mean lunar radius k = 0.2725076 Earth radii (IAU 1982; Espenak & Meeus 2006). [m]"""

EARTH_ROTATION_RATE = 7.292115e-5
"""The Earth's rotation rate against the stars (IERS Conventions 2010, table 1.1). [rad/s]"""

DELTA_T_MEASURED = (
    ("2018-01-01", 68.9676), ("2018-07-01", 69.1134), ("2019-01-01", 69.2202), ("2019-07-01", 69.3582),
    ("2020-01-01", 69.3612), ("2020-07-01", 69.4241), ("2021-01-01", 69.3594), ("2021-07-01", 69.3514),
    ("2022-01-01", 69.2945), ("2022-07-01", 69.2527), ("2023-01-01", 69.2039), ("2023-07-01", 69.2201),
    ("2024-01-01", 69.1752), ("2024-07-01", 69.1879), ("2025-01-01", 69.1377), ("2025-07-01", 69.1406),
    ("2026-01-01", 69.1099), ("2026-07-01", 69.1695), ("2026-10-01", 69.2065),
)
"""Delta T = TT - UT1 as measured, at 0h UTC of each date: the USNO's monthly table
(maia.usno.navy.mil/ser7/deltat.data), every sixth month and the last. Between its dates
``delta_t`` interpolates linearly; after the last it holds the last value (Delta T stayed within
68.97-69.44 s from 2018 to 2026; the USNO's 2022 prediction, deltat.preds, rose to 69.97 s by
2030.0, about a second more: the uncertainty of a contact predicted for 2030). [s]"""

_EPHEM_EPOCH = datetime(1899, 12, 31, 12, 0, 0, tzinfo=UTC)  # ephem.Date(0)
_SECONDS_PER_DAY = 86400.0
_CONTACTS = ("C1", "C2", "C3", "C4")
_MEASURED_DATES = np.array([(datetime.fromisoformat(day).replace(tzinfo=UTC) - _EPHEM_EPOCH).total_seconds()
                            / _SECONDS_PER_DAY for day, _ in DELTA_T_MEASURED])
_MEASURED_VALUES = np.array([value for _, value in DELTA_T_MEASURED])


def _delta_t_at(date: float) -> float:
    """Delta T [s] at ephem date ``date`` [day]: ephem's own before ``DELTA_T_MEASURED``, then it."""
    if date < _MEASURED_DATES[0]:
        return float(ephem.delta_t(date))
    return float(np.interp(date, _MEASURED_DATES, _MEASURED_VALUES))


def delta_t(when: datetime) -> float:
    """Delta T = TT - UT1, the clock the ephemeris runs on less the Earth's rotation, at ``when``.

    ephem's own model (libastro's table, which matches the USNO's measurements to 0.01 s) before
    2018; from 2018 on the USNO's measured values ``DELTA_T_MEASURED``, interpolated linearly and
    held at the last one after it. Every position this module gives uses it.

    Parameters
    ----------
    when : datetime.datetime
        An aware datetime.

    Returns
    -------
    float
        Delta T [s].
    """
    return _delta_t_at(ephem_date(when))


def ephem_date(when: datetime) -> float:
    """ephem's Dublin Julian date of an aware datetime: days since 1899-12-31 12:00 UT.

    Parameters
    ----------
    when : datetime.datetime
        An aware datetime (any time zone).

    Returns
    -------
    float
        The date [day].
    """
    return _ephem_date(_utc(when))


@dataclass(frozen=True)
class Site:
    """A place on the Earth.

    Attributes
    ----------
    latitude : float
        Geodetic latitude, north positive, in [-pi/2, pi/2] [rad].
    longitude : float
        Longitude, east positive (Dallas is about -1.689) [rad].
    elevation : float, optional
        Height above mean sea level [m].

    Raises
    ------
    ValueError
        If a field is not finite or the latitude is out of [-pi/2, pi/2].
    """

    latitude: float
    longitude: float
    elevation: float = 0.0

    def __post_init__(self):
        for name in ("latitude", "longitude", "elevation"):
            value = getattr(self, name)
            if not np.isfinite(value):
                raise ValueError(f"Site.{name} must be finite, got {value!r}")
        if abs(self.latitude) > np.pi / 2:
            raise ValueError(
                f"Site.latitude must lie in [-pi/2, pi/2] rad, got {self.latitude!r} "
                "(use Site.from_degrees for degrees)"
            )

    @classmethod
    def from_degrees(cls, latitude: float, longitude: float, elevation: float = 0.0) -> Site:
        """The site at a latitude and longitude in degrees; the config boundary, where degrees are allowed.

        Parameters
        ----------
        latitude : float
            North positive [deg].
        longitude : float
            East positive [deg].
        elevation : float, optional
            Above sea level [m].

        Returns
        -------
        Site
            The site, in radians [rad] and metres [m].
        """
        return cls(float(np.deg2rad(latitude)), float(np.deg2rad(longitude)), float(elevation))


@dataclass(frozen=True)
class BodyPosition:
    """Where a body's disc is on the observer's sky.

    Attributes
    ----------
    azimuth : float
        Direction of the centre, from north towards east, in [0, 2 pi) [rad].
    elevation : float
        Topocentric elevation of the centre above the horizon, without refraction [rad].
    angular_radius : float
        Topocentric angular radius of the disc, arcsin(R / distance) [rad].
    """

    azimuth: float
    elevation: float
    angular_radius: float


def _utc(when: datetime, name: str = "when") -> datetime:
    """``when`` converted to UTC; ValueError for a naive datetime."""
    if not isinstance(when, datetime):
        raise TypeError(f"{name} must be a datetime, got {type(when).__name__}")
    if when.tzinfo is None or when.tzinfo.utcoffset(when) is None:
        raise ValueError(
            f"{name} is a naive datetime ({when.isoformat()}); give an aware one, "
            "e.g. datetime(..., tzinfo=timezone.utc)"
        )
    return when.astimezone(UTC)


def _ephem_date(when_utc: datetime) -> float:
    """ephem's Dublin Julian date (days since 1899-12-31 12:00 UT) of an aware datetime. [day]"""
    return (when_utc - _EPHEM_EPOCH).total_seconds() / _SECONDS_PER_DAY


def _observer(site: Site) -> ephem.Observer:
    observer = ephem.Observer()
    observer.lat = float(site.latitude)  # floats are radians to ephem
    observer.lon = float(site.longitude)
    observer.elevation = float(site.elevation)
    observer.pressure = 0.0  # no refraction: geometric topocentric positions
    return observer


class _Sky:
    """A reusable ephem observer with the sun and moon, evaluated at ephem dates.

    ephem takes its own Delta T; ``delta_t`` replaces it: ephem is asked for the moment ``c`` =
    delta_t - ephem's later, so that its ephemeris clock (UT + its Delta T) reads UT + delta_t,
    and the observer is turned back by the Earth's rotation over ``c``, so that the sky over it
    (sidereal time plus longitude) is the one at UT. Precession over ``c`` is below 1e-9 rad.
    """

    def __init__(self, site: Site):
        self.observer = _observer(site)
        self.longitude = float(site.longitude)
        self.sun = ephem.Sun()
        self.moon = ephem.Moon()

    def at(self, date: float) -> tuple[BodyPosition, BodyPosition]:
        correction = _delta_t_at(date) - float(ephem.delta_t(date))  # [s]
        self.observer.date = date + correction / _SECONDS_PER_DAY
        self.observer.lon = self.longitude - EARTH_ROTATION_RATE * correction
        self.sun.compute(self.observer)
        self.moon.compute(self.observer)
        # earth_distance is topocentric when computed for an Observer. [au]
        sun = BodyPosition(
            float(self.sun.az),
            float(self.sun.alt),
            float(np.arcsin(SUN_RADIUS / (self.sun.earth_distance * AU))),
        )
        moon = BodyPosition(
            float(self.moon.az),
            float(self.moon.alt),
            float(np.arcsin(MOON_RADIUS / (self.moon.earth_distance * AU))),
        )
        return sun, moon


def sun_and_moon(site: Site, when: datetime) -> tuple[BodyPosition, BodyPosition]:
    """Topocentric sun and moon seen from ``site`` at ``when``.

    Parameters
    ----------
    site : Site
        Latitude, longitude [rad] and elevation [m] of the observer.
    when : datetime.datetime
        An aware datetime (any time zone; converted to UTC). A naive datetime raises ValueError
        rather than being guessed as UTC or local time.

    Returns
    -------
    sun, moon : BodyPosition
        Azimuth, elevation (no refraction) and angular radius [rad].
    """
    return _Sky(site).at(_ephem_date(_utc(when)))


def separation(sun: BodyPosition, moon: BodyPosition) -> float:
    """Great-circle angle between the centres of two bodies.

    Vincenty's form atan2(|u x v|, u . v) of the unit vectors, accurate at all angles
    (arccos of the dot product loses half the digits near 0, i.e. near mid-eclipse).
    Works on arrays of azimuths and elevations too; exactly symmetric in its arguments.

    Parameters
    ----------
    sun, moon : BodyPosition
        The two bodies (their azimuth and elevation may be arrays that broadcast) [rad].

    Returns
    -------
    float or numpy.ndarray
        The angle; a float for scalar positions [rad].
    """
    u = direction_vector(sun.azimuth, sun.elevation)
    v = direction_vector(moon.azimuth, moon.elevation)
    cross = np.cross(u, v)  # swapping u and v negates it exactly: the result is symmetric
    out = np.arctan2(np.sqrt(np.sum(cross * cross, axis=-1)), np.sum(u * v, axis=-1))
    return float(out) if out.ndim == 0 else out


def obscured_fraction(separation: ArrayLike, sun_radius: ArrayLike, moon_radius: ArrayLike) -> float | np.ndarray:
    """Fraction of the sun's disc area covered by the moon's disc, in [0, 1].

    Exact area of the lens where two circles of radii r (sun) and R (moon) with centres d apart
    intersect, over pi r^2::

        A = r^2 acos((d^2 + r^2 - R^2) / (2 d r)) + R^2 acos((d^2 + R^2 - r^2) / (2 d R))
            - 1/2 sqrt((-d + r + R)(d + r - R)(d - r + R)(d + r + R)),

    with the cases d >= r + R (no overlap: 0), d <= R - r (total: 1) and d <= r - R (annular,
    moon inside the sun: R^2 / r^2). The discs are treated as flat circles of radius equal to
    their angular radii (error of order radius^2, about 2e-5 relative). No limb darkening: this is
    an area fraction, and the uneclipsed sun fraction is S = 1 - obscured_fraction.

    Parameters
    ----------
    separation : float or numpy.ndarray
        Angle between the centres, >= 0 [rad].
    sun_radius : float or numpy.ndarray
        Angular radius of the sun, > 0 [rad].
    moon_radius : float or numpy.ndarray
        Angular radius of the moon, > 0 [rad].

    Arrays broadcast.

    Returns
    -------
    float or numpy.ndarray
        The fraction, of the broadcast shape; a float for scalar inputs [1].

    Raises
    ------
    ValueError
        If a radius is not positive or the separation negative.
    """
    d = np.asarray(separation, dtype=np.float64)
    r = np.asarray(sun_radius, dtype=np.float64)
    big_r = np.asarray(moon_radius, dtype=np.float64)
    if np.any(~(r > 0)) or np.any(~(big_r > 0)):
        raise ValueError("sun_radius and moon_radius must be positive [rad]")
    if np.any(~(d >= 0)):
        raise ValueError("separation must be non-negative [rad]")
    d, r, big_r = np.broadcast_arrays(d, r, big_r)

    inside = d <= np.abs(big_r - r)
    apart = d >= r + big_r
    partial = ~(inside | apart)
    # Lens area, evaluated where the circles cross; safe placeholders elsewhere.
    ds = np.where(partial, d, 1.0)
    rs = np.where(partial, r, 1.0)
    rm = np.where(partial, big_r, 1.0)
    cos_sun = np.clip((ds * ds + rs * rs - rm * rm) / (2.0 * ds * rs), -1.0, 1.0)
    cos_moon = np.clip((ds * ds + rm * rm - rs * rs) / (2.0 * ds * rm), -1.0, 1.0)
    kite = (-ds + rs + rm) * (ds + rs - rm) * (ds - rs + rm) * (ds + rs + rm)
    lens = (
        rs * rs * np.arccos(cos_sun)
        + rm * rm * np.arccos(cos_moon)
        - 0.5 * np.sqrt(np.maximum(kite, 0.0))
    ) / (np.pi * rs * rs)

    contained = np.minimum(big_r * big_r / (r * r), 1.0)
    out = np.where(apart, 0.0, np.where(inside, contained, np.clip(lens, 0.0, 1.0)))
    return float(out) if out.ndim == 0 else out


def moon_offset_from_sun(sun: BodyPosition, moon: BodyPosition) -> tuple[float, float]:
    """The moon's centre relative to the sun's, on the plane tangent to the sky at the sun.

    Gnomonic projection centred on the sun: with s the sun's unit vector (world x east,
    y north, z up), e_az = (cos a, -sin a, 0) the direction of increasing azimuth and
    e_el = (-sin h sin a, -sin h cos a, cos h) that of increasing elevation at the sun
    (azimuth a, elevation h), and m the moon's unit vector,
    ``dx = (m . e_az) / (m . s)``, ``dy = (m . e_el) / (m . s)``.
    dx grows towards increasing azimuth along the horizon direction (to the observer's right
    when facing the sun), dy towards the zenith. Within a degree of the sun these are angles on
    the sky to better than 1e-4 relative, so a moon disc of angular radius R is drawn as a
    circle of radius R at (dx, dy) on a tangent-plane grid centred on the sun. The frame is
    tied to the sun's azimuth, so it is undefined with the sun exactly at the zenith.

    Parameters
    ----------
    sun, moon : BodyPosition
        The two bodies [rad].

    Returns
    -------
    dx, dy : float
        The offset on the tangent plane [rad].

    Raises
    ------
    ValueError
        If the moon is 90 degrees or more from the sun.
    """
    s, e_az, e_el = tangent_axes(sun.azimuth, sun.elevation)
    m = direction_vector(moon.azimuth, moon.elevation)
    depth = float(m @ s)
    if depth <= 0.0:
        raise ValueError("the moon is 90 degrees or more from the sun; no gnomonic offset")
    return float(m @ e_az) / depth, float(m @ e_el) / depth


def contact_times(
    site: Site,
    start: datetime,
    end: datetime,
    *,
    step: float = 30.0,
    tolerance: float = 0.05,
) -> dict[str, datetime | None]:
    """Local contact times of the solar eclipse seen from ``site`` between ``start`` and ``end``.

    C1 and C4 are the roots of d - (r_sun + r_moon) (external contacts), C2 and C3 those of
    d - |r_moon - r_sun| (internal contacts: totality for a larger moon, the annulus for a smaller
    one), d being ``separation`` and r the angular radii of ``sun_and_moon``.

    Each function is sampled every ``step``, its minimum refined with a bounded Brent search
    (so a totality shorter than ``step`` is still found) and the roots on either side bracketed
    from the samples and solved with Brent's method (scipy.optimize.brentq). Only the eclipse of
    closest approach in the window is reported. Contacts are geometric: they are returned even
    when the sun is below the horizon; check ``sun_and_moon(...)[0].elevation``.

    Parameters
    ----------
    site : Site
        The observer.
    start, end : datetime.datetime
        Aware datetimes bounding the search, start < end.
    step : float, optional
        Spacing of the coarse scan [s].
    tolerance : float, optional
        Accuracy of the returned times [s].

    Returns
    -------
    dict of str to datetime.datetime or None
        {'C1', 'C2', 'C3', 'C4'} -> aware UTC datetime, or None when that contact is not in
        the window (no eclipse, a partial eclipse has no C2/C3, an eclipse under way at ``start``
        has no C1).

    Raises
    ------
    ValueError
        If ``end`` is not after ``start``, ``step`` or ``tolerance`` is not positive, or a datetime
        is naive.
    """
    start_utc = _utc(start, "start")
    span = _search_span(start_utc, _utc(end, "end"), step, tolerance)
    gaps = _contact_gaps(_Sky(site), _ephem_date(start_utc))
    times = np.append(np.arange(0.0, span, step), span)
    sampled = np.array([gaps(t) for t in times])  # (n, 2): external, internal

    result: dict[str, datetime | None] = dict.fromkeys(_CONTACTS)
    for column, (first, last) in enumerate((("C1", "C4"), ("C2", "C3"))):

        def gap(t: float, column: int = column) -> float:
            return gaps(t)[column]

        before, after = _contact_roots(gap, times, sampled[:, column], tolerance)
        if before is not None:
            result[first] = start_utc + timedelta(seconds=before)
        if after is not None:
            result[last] = start_utc + timedelta(seconds=after)
    return result


def _search_span(start_utc: datetime, end_utc: datetime, step: float, tolerance: float) -> float:
    """``contact_times``' window start_utc..end_utc checked with its ``step`` and ``tolerance`` [s]:
    its length [s]; ValueError when it is empty or ``step`` or ``tolerance`` is not positive."""
    span = (end_utc - start_utc).total_seconds()
    if not span > 0:
        raise ValueError(f"end ({end_utc.isoformat()}) must be after start ({start_utc.isoformat()})")
    if not (step > 0 and tolerance > 0):
        raise ValueError("step and tolerance must be positive [s]")
    return span


def _contact_gaps(sky: _Sky, date0: float) -> Callable[[float], tuple[float, float]]:
    """The function of t [s] after ephem date ``date0`` [day] whose roots are the contacts
    (``contact_times``): (d - (r_sun + r_moon), d - |r_moon - r_sun|) [rad], external then internal."""

    def gaps(t: float) -> tuple[float, float]:
        sun, moon = sky.at(date0 + t / _SECONDS_PER_DAY)
        d = separation(sun, moon)
        return (
            d - (sun.angular_radius + moon.angular_radius),
            d - abs(moon.angular_radius - sun.angular_radius),
        )

    return gaps


def _closest_approach(gap: Callable[[float], float], times: np.ndarray, values: np.ndarray,
                      tolerance: float) -> tuple[float, float]:
    """The minimum (t [s], gap(t) [rad]) of ``gap``, sampled as ``values`` at ``times``: the least
    sample's, or where a bounded Brent search between its neighbours finds a lower one to
    ``tolerance`` [s] (so a totality shorter than the sampling is still found)."""
    from scipy.optimize import minimize_scalar  # 0.3 s to import: only when asked

    i = int(np.argmin(values))
    lo, hi = times[max(i - 1, 0)], times[min(i + 1, len(times) - 1)]
    t_min, g_min = times[i], values[i]
    if hi > lo:
        found = minimize_scalar(gap, bounds=(lo, hi), method="bounded", options={"xatol": tolerance})
        if found.fun < g_min:
            t_min, g_min = float(found.x), float(found.fun)
    return t_min, g_min


def _contact_roots(gap: Callable[[float], float], times: np.ndarray, values: np.ndarray,
                   tolerance: float) -> tuple[float | None, float | None]:
    """The roots of ``gap`` (sampled as ``values`` at ``times`` [s]) on either side of its minimum,
    to ``tolerance`` [s] by Brent's method: (before, after) [s], either None where the samples
    bracket no root on that side, both None when the minimum is not below 0."""
    from scipy.optimize import brentq  # 0.3 s to import: only when asked

    t_min, g_min = _closest_approach(gap, times, values, tolerance)
    if not g_min < 0:
        return None, None
    before = after = None
    # Before the minimum: the last sample still outside the contact brackets the root.
    outside = np.flatnonzero((times < t_min) & (values > 0))
    if outside.size:
        j = outside[-1]
        before = brentq(gap, times[j], min(times[j + 1], t_min), xtol=tolerance)
    outside = np.flatnonzero((times > t_min) & (values > 0))
    if outside.size:
        j = outside[0]
        after = brentq(gap, max(times[j - 1], t_min), times[j], xtol=tolerance)
    return before, after


@dataclass(frozen=True)
class Circumstances:
    """A solar eclipse as seen from a site.

    Attributes
    ----------
    contacts : dict
        C1..C4 -> aware UTC datetime or None.
    maximum : datetime.datetime or None
        Time of greatest obscuration.
    obscuration : float
        The greatest obscured area fraction [1].
    kind : str or None
        'total', 'annular', 'partial' or None without an eclipse.
    central : float or None
        C3 - C2: the duration of totality or annularity, None if partial [s].
    """

    contacts: dict
    maximum: datetime | None
    obscuration: float
    kind: str | None
    central: float | None


def circumstances(site: Site, start: datetime, end: datetime, *, margin: float = 4 * 3600.0,
                  step: float = 10.0) -> Circumstances:
    """The eclipse nearest the span ``start``..``end`` seen from ``site``.

    ``contact_times`` over the span widened by ``margin`` on each side (a whole eclipse lasts at most
    about 3.5 h), the greatest obscuration sampled every ``step`` between the contacts (and refined
    around C2..C3, where it is 1 for a total eclipse).

    Parameters
    ----------
    site : Site
        The observer.
    start, end : datetime.datetime
        Aware datetimes of the span.
    margin : float, optional
        Widening of the span on each side [s].
    step : float, optional
        Sampling of the obscuration [s].

    Returns
    -------
    Circumstances
        The eclipse's contacts, maximum, obscuration [1], kind and central duration [s].
    """
    start_utc, end_utc = _utc(start, "start"), _utc(end, "end")
    lo, hi = start_utc - timedelta(seconds=margin), end_utc + timedelta(seconds=margin)
    contacts = contact_times(site, lo, hi)
    first = contacts["C1"] or (lo if contacts["C4"] else None)
    last = contacts["C4"] or (hi if contacts["C1"] else None)
    if first is None or last is None:  # last is set whenever first is
        return Circumstances(contacts, None, 0.0, None, None)
    sky = _Sky(site)
    span = (last - first).total_seconds()
    times = np.append(np.arange(0.0, span, step), span)
    date0 = _ephem_date(first)
    fractions: list[float] = []
    for t in times:
        sun, moon = sky.at(date0 + t / _SECONDS_PER_DAY)
        fractions.append(float(obscured_fraction(separation(sun, moon), sun.angular_radius, moon.angular_radius)))
    k = int(np.argmax(fractions))
    maximum, obscuration = first + timedelta(seconds=float(times[k])), float(fractions[k])
    kind, central = "partial", None
    if contacts["C2"] is not None and contacts["C3"] is not None:
        middle = contacts["C2"] + (contacts["C3"] - contacts["C2"]) / 2
        sun, moon = sky.at(_ephem_date(middle))
        kind = "total" if moon.angular_radius > sun.angular_radius else "annular"
        maximum = middle
        obscuration = float(obscured_fraction(separation(sun, moon), sun.angular_radius, moon.angular_radius))
        central = (contacts["C3"] - contacts["C2"]).total_seconds()
    return Circumstances(contacts, maximum, obscuration, kind, central)
