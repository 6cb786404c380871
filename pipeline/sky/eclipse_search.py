"""Every solar eclipse seen from a site over a span: new moons searched, the local contacts, the
greatest eclipse and the horizon at each (docs/method.md, "Finding the eclipses of a site").

Positions, contacts and Delta T are ``sky.ephemeris``'s. "Up" is the sun's centre above the
geometric horizon (no refraction), the renderer's convention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

import ephem
import numpy as np

from pipeline.sky.ephemeris import (
    BodyPosition,
    Site,
    contact_times,
    ephem_date,
    obscured_fraction,
    separation,
    sun_and_moon,
)

__all__ = ["NEW_MOON_REACH", "SEARCH_HALF_WINDOW", "SiteEclipse", "find_eclipses", "eclipse_at", "sun_above"]

NEW_MOON_REACH = math.radians(1.7)
"""Geocentric sun-moon separation at new moon beyond which no place on the Earth sees an eclipse:
the moon's greatest horizontal parallax (1.02 degrees) plus the two largest radii (0.29 and 0.27
degrees), rounded up. [rad]"""

SEARCH_HALF_WINDOW = 6 * 3600.0
"""Half the window searched around a new moon: parallax moves a site's eclipse up to about 2 h from
the geocentric conjunction, and an eclipse lasts at most about 3.5 h at a site. [s]"""

_EPHEM_EPOCH = datetime(1899, 12, 31, 12, tzinfo=UTC)  # ephem.Date(0)
_SCAN_STEP = 600.0  # [s] the first look around a new moon
_SCAN_MARGIN = math.radians(0.15)  # [rad] the discs close in at most 0.7 degrees/h: 0.06 in 5 min
_CONTACT_HALF_WINDOW = 4 * 3600.0  # [s] around the closest sample: a whole eclipse, at most 3.5 h
_CONTACT_STEP = 120.0  # [s] contact_times' scan; its Brent searches find shorter totalities
_HORIZON_STEP = 60.0  # [s] sampling of the sun's elevation between C1 and C4
_CONTACTS = ("C1", "C2", "C3", "C4")


@dataclass(frozen=True)
class SiteEclipse:
    """A solar eclipse as seen from a site.

    Attributes
    ----------
    kind : str
        'total', 'annular' or 'partial': the eclipse at the site, whether or not the sun is up.
    seen : str
        The kind while the sun is up: 'partial' when totality or annularity is below the horizon.
    contacts : dict
        'C1'..'C4' -> aware UTC datetime; C2 and C3 None for a partial eclipse.
    maximum : datetime.datetime
        Greatest eclipse: the least separation of the centres (mid C2..C3 for a central one).
    obscuration : float
        The sun's area covered at ``maximum`` [1].
    central : float or None
        C3 - C2, the duration of totality or annularity [s]; None if partial.
    sun : dict
        'C1'..'C4', 'max' -> the sun's ``BodyPosition`` at that moment (azimuth, elevation [rad]).
    visible : tuple of (datetime, datetime)
        The stretches of C1..C4 with the sun up, in order.
    seen_obscuration : float
        The greatest obscuration while the sun is up [1].
    seen_maximum : datetime.datetime
        When it is.
    """

    kind: str
    seen: str
    contacts: dict[str, datetime | None]
    maximum: datetime
    obscuration: float
    central: float | None
    sun: dict[str, BodyPosition]
    visible: tuple[tuple[datetime, datetime], ...]
    seen_obscuration: float
    seen_maximum: datetime

    @property
    def rises_eclipsed(self) -> bool:
        """Whether the sun rises during the eclipse (it is below the horizon at C1)."""
        return self.sun["C1"].elevation < 0.0

    @property
    def sets_eclipsed(self) -> bool:
        """Whether the sun sets before C4 (it is below the horizon at C4)."""
        return self.sun["C4"].elevation < 0.0


def find_eclipses(site: Site, start: datetime, end: datetime) -> list[SiteEclipse]:
    """Every solar eclipse seen from ``site`` whose greatest eclipse lies between ``start`` and ``end``.

    New moons from ``start`` less a day to ``end`` plus a day (``ephem.next_new_moon``); those with
    the geocentric sun and moon within ``NEW_MOON_REACH`` are searched at the site over
    ``SEARCH_HALF_WINDOW`` on each side (``eclipse_at``); an eclipse is kept when the sun is up
    for some of it.

    Parameters
    ----------
    site : Site
        The observer.
    start, end : datetime.datetime
        Aware datetimes, start < end.

    Returns
    -------
    list of SiteEclipse
        In time order.

    Raises
    ------
    ValueError
        If ``end`` is not after ``start`` or a datetime is naive.
    """
    if not end > start:
        raise ValueError(f"end ({end.isoformat()}) must be after start ({start.isoformat()})")
    found = []
    date = ephem_date(start) - 1.0
    last = ephem_date(end) + 1.0
    while (conjunction := float(ephem.next_new_moon(date))) <= last:
        date = conjunction + 1.0
        if float(ephem.separation(ephem.Sun(conjunction), ephem.Moon(conjunction))) > NEW_MOON_REACH:
            continue
        eclipse = eclipse_at(site, _EPHEM_EPOCH + timedelta(days=conjunction))
        if eclipse is not None and eclipse.visible and start <= eclipse.maximum <= end:
            found.append(eclipse)
    return found


def eclipse_at(site: Site, new_moon: datetime) -> SiteEclipse | None:
    """The eclipse seen from ``site`` near ``new_moon``, whether the sun is up or not.

    ``ephemeris.contact_times`` over ``SEARCH_HALF_WINDOW`` on each side, the least separation
    between C1 and C4 by a bounded Brent search, the sun's elevation every minute and its
    crossings of the horizon by Brent's method.

    Parameters
    ----------
    site : Site
        The observer.
    new_moon : datetime.datetime
        An aware datetime near the conjunction.

    Returns
    -------
    SiteEclipse or None
        None when the site sees no eclipse then (its ``visible`` is empty when the sun is down
        throughout).
    """
    closest = _closest_sample(site, new_moon)
    if closest is None:
        return None
    half = timedelta(seconds=_CONTACT_HALF_WINDOW)
    contacts = contact_times(site, closest - half, closest + half, step=_CONTACT_STEP)
    c1, c4 = contacts["C1"], contacts["C4"]
    if c1 is None or c4 is None:
        return None
    if contacts["C2"] is not None and contacts["C3"] is not None:
        maximum = contacts["C2"] + (contacts["C3"] - contacts["C2"]) / 2
    else:
        maximum = _least_separation(site, c1, c4)
    sun, moon = sun_and_moon(site, maximum)
    obscuration = float(obscured_fraction(separation(sun, moon), sun.angular_radius, moon.angular_radius))
    kind, central = "partial", None
    if contacts["C2"] is not None and contacts["C3"] is not None:
        kind = "total" if moon.angular_radius > sun.angular_radius else "annular"
        central = (contacts["C3"] - contacts["C2"]).total_seconds()
    suns = {name: sun_and_moon(site, when)[0] for name, when in contacts.items() if when is not None}
    suns["max"] = sun
    visible = _sun_up(site, c1, c4)
    seen_maximum, seen_obscuration = _seen_maximum(site, maximum, obscuration, visible)
    seen = kind
    if kind != "partial" and not any(a <= contacts["C3"] and contacts["C2"] <= b for a, b in visible):  # type: ignore[operator]
        seen = "partial"
    return SiteEclipse(kind, seen, contacts, maximum, obscuration, central, suns, visible,
                       seen_obscuration, seen_maximum)


def _closest_sample(site: Site, new_moon: datetime) -> datetime | None:
    """The sample every ``_SCAN_STEP`` within ``SEARCH_HALF_WINDOW`` of ``new_moon`` where the discs
    come closest, or None when even there they stand over ``_SCAN_MARGIN`` apart (no eclipse)."""
    best, best_gap = new_moon, math.inf
    for t in np.arange(-SEARCH_HALF_WINDOW, SEARCH_HALF_WINDOW + 1.0, _SCAN_STEP):
        when = new_moon + timedelta(seconds=float(t))
        sun, moon = sun_and_moon(site, when)
        gap = separation(sun, moon) - sun.angular_radius - moon.angular_radius
        if gap < best_gap:
            best, best_gap = when, gap
    return best if best_gap < _SCAN_MARGIN else None


def _least_separation(site: Site, c1: datetime, c4: datetime) -> datetime:
    """The moment between ``c1`` and ``c4`` when the centres are closest, to 0.05 s."""
    from scipy.optimize import minimize_scalar  # 0.3 s to import: only when asked

    span = (c4 - c1).total_seconds()

    def apart(t: float) -> float:
        return separation(*sun_and_moon(site, c1 + timedelta(seconds=t)))

    found = minimize_scalar(apart, bounds=(0.0, span), method="bounded", options={"xatol": 0.05})
    return c1 + timedelta(seconds=float(found.x))


def _sun_up(site: Site, c1: datetime, c4: datetime) -> tuple[tuple[datetime, datetime], ...]:
    """The stretches of ``c1``..``c4`` with the sun's centre above the horizon."""
    return sun_above(site, c1, c4, 0.0)


def sun_above(site: Site, start: datetime, end: datetime,
              elevation: float) -> tuple[tuple[datetime, datetime], ...]:
    """The stretches of ``start``..``end`` with the sun's centre at least ``elevation`` high.

    The sun's elevation sampled every minute, its crossings solved to 0.1 s by Brent's method.

    Parameters
    ----------
    site : Site
        The observer.
    start, end : datetime.datetime
        Aware datetimes, start <= end.
    elevation : float
        The least elevation, geometric (no refraction) [rad].

    Returns
    -------
    tuple of (datetime, datetime)
        The stretches, in order; empty when the sun stays lower.
    """
    from scipy.optimize import brentq  # 0.3 s to import: only when asked

    span = (end - start).total_seconds()
    times = np.append(np.arange(0.0, span, _HORIZON_STEP), span)

    def height(t: float) -> float:
        return sun_and_moon(site, start + timedelta(seconds=t))[0].elevation - elevation

    heights = np.array([height(t) for t in times])
    up = heights >= 0.0
    edges = [0.0] if up[0] else []
    for i in np.flatnonzero(up[1:] != up[:-1]):
        edges.append(float(brentq(height, times[i], times[i + 1], xtol=0.1)))
    if up[-1]:
        edges.append(span)
    return tuple((start + timedelta(seconds=a), start + timedelta(seconds=b)) for a, b in zip(edges[::2], edges[1::2]))


def _seen_maximum(site: Site, maximum: datetime, obscuration: float,
                  visible: tuple[tuple[datetime, datetime], ...]) -> tuple[datetime, float]:
    """The greatest obscuration while the sun is up and when: the maximum's if the sun is up then,
    else the end of a visible stretch nearest it (the obscuration falls away from the maximum)."""
    if any(a <= maximum <= b for a, b in visible):
        return maximum, obscuration
    best, best_fraction = maximum, 0.0
    for when in (edge for stretch in visible for edge in stretch):
        sun, moon = sun_and_moon(site, when)
        fraction = float(obscured_fraction(separation(sun, moon), sun.angular_radius, moon.angular_radius))
        if fraction > best_fraction:
            best, best_fraction = when, fraction
    return best, best_fraction
