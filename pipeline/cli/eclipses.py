"""``sunshade eclipses``: the solar eclipses a site sees over a span of years, and a ready config for
one of them (docs/method.md, "Finding the eclipses of a site"; README.md, "Commands")."""

from __future__ import annotations

import math
import os
import re
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import TYPE_CHECKING

from pipeline.core.errors import BadInput

if TYPE_CHECKING:
    import argparse

    from pipeline.sky.eclipse_search import SiteEclipse
    from pipeline.sky.ephemeris import Site

__all__ = ["YEARS", "SPAN_COVERED", "CLOSE_FOV", "CLOSE_SUN_CELLS", "run_eclipses", "parse_site", "parse_years",
           "parse_offset", "render_span", "config_text"]

YEARS = (1900, 2100)
"""The years ``--years`` may name: Delta T is measured or held near its measured value within them. [year]"""
SPAN_COVERED = 0.9
"""A written config of a total or annular eclipse starts before C2 and ends after C3 where the moon
covers this much of the sun (S = 0.1, as configs/eclipse-2026-burgos-sunset.yaml starts): the
crescents thin into totality and grow out of it. [1]"""
CLOSE_FOV = 25.0
"""Vertical field of view of a written config's camera where the sun stands above
``stages.framing.LOW_SUN`` at the span's middle (where the plan looks 50 degrees down at the deep
shade): half the default's, so that a crescent spans about 25 pixels of the preview's 320 x 180
and 100 of the full 1280 x 720 (docs/accuracy.md, "The eclipse finder against DE421"). [deg]"""
CLOSE_SUN_CELLS = 32
"""``render.sun_cells`` of such a config: its crescents, 100 pixels across, drawn from 32 cells
across the sun; the preview keeps 13 (``config.preview.preview_sun_cells``). [1]"""
_TWILIGHT_MARGIN = math.radians(0.05)  # [rad] above stages.resolve.MIN_SUN_ELEVATION
_LOW_SUN = math.radians(12.0)  # [rad] under it the wider sky square, the small tree of the Burgos config


def run_eclipses(args: argparse.Namespace) -> int:
    """list the solar eclipses a site sees over some years; write a config for one

    For --site LAT,LON[,ELEV_M] (degrees north and east, metres) and --years Y1-Y2: every solar
    eclipse seen there (the sun up for some of it), with its kind at the site, the contacts C1-C4
    and greatest eclipse in UTC and local time, the greatest obscuration, the length of totality
    or annularity, and the sun's elevation and azimuth at each, marked up or down (its centre
    above the horizon, no refraction). --write NAME.yaml writes a config for the eclipse with the
    greatest obscuration seen, or the --pick'th of the list: a span around totality or
    annularity, or the whole partial eclipse (down to the end of civil twilight where the sun
    rises or sets during it); camera and windows placed by the plan, exposure automatic.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: --site, --years, --utc-offset, --write, --pick.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    from pipeline.sky.eclipse_search import find_eclipses

    site = parse_site(args.site)
    first, last = parse_years(args.years)
    offset, offset_name = parse_offset(args.utc_offset, site)
    target = _checked_target(args.write, args.pick)
    eclipses = find_eclipses(site, datetime(first, 1, 1, tzinfo=UTC), datetime(last + 1, 1, 1, tzinfo=UTC))
    years = f"{first}" if first == last else f"{first}-{last}"
    if target is not None and not eclipses:
        raise BadInput(f"--site {args.site}: no solar eclipse is seen from there in {years}; nothing written")
    chosen = _chosen(eclipses, args.pick)
    print(f"{_place(site)}, {years}: {len(eclipses)} solar eclipse{'' if len(eclipses) == 1 else 's'} seen")
    print(f"  times UTC and {offset_name}; the sun up when its centre is above the horizon (no refraction)")
    for number, eclipse in enumerate(eclipses, 1):
        for line in _eclipse_lines(number, eclipse, offset):
            print(line)
    if target is not None and chosen is not None:
        text = config_text(site, eclipses[chosen - 1], target.name, _command_line(args))
        with open(target, "x", encoding="utf-8") as out:  # "x": never over a file made since the check
            out.write(text)
        why = f"--pick {chosen}" if args.pick is not None else "the greatest obscuration seen; --pick N for another"
        print(f"wrote {target}: eclipse {chosen} ({why}); render it with: sunshade render {target}")
    return 0


def parse_site(text: str) -> Site:
    """``--site LAT,LON[,ELEV_M]``: degrees north in [-90, 90], east in [-180, 180], metres in
    [-500, 10000); BadInput naming the flag otherwise.

    Parameters
    ----------
    text : str
        The flag's value.

    Returns
    -------
    Site
        The site [rad, m].
    """
    from pipeline.sky.ephemeris import Site

    parts = text.split(",")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        numbers = []
    if len(numbers) not in (2, 3) or not all(math.isfinite(x) for x in numbers):
        raise BadInput(f"--site {text}: give LAT,LON or LAT,LON,ELEV_M (degrees north and east, metres)")
    latitude, longitude, elevation = (*numbers, 0.0)[:3]
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 180.0 and -500.0 <= elevation < 10_000.0):
        raise BadInput(f"--site {text}: latitude must lie in [-90, 90] degrees, longitude in [-180, 180], "
                       "elevation in [-500, 10000) m")
    return Site.from_degrees(latitude, longitude, elevation)


def parse_years(text: str) -> tuple[int, int]:
    """``--years Y1-Y2`` (or one year): the first and the last year, in ``YEARS``, Y1 <= Y2.

    Parameters
    ----------
    text : str
        The flag's value.

    Returns
    -------
    first, last : int
        The years [year].
    """
    found = re.fullmatch(r"\s*(\d{4})\s*(?:-\s*(\d{4})\s*)?", text)
    if found is None:
        raise BadInput(f"--years {text}: give Y1-Y2, e.g. 2026-2030, or one year")
    first, last = int(found[1]), int(found[2] or found[1])
    if not YEARS[0] <= first <= last <= YEARS[1]:
        raise BadInput(f"--years {text}: the first year must not be after the last, both within "
                       f"{YEARS[0]}-{YEARS[1]}")
    return first, last


def parse_offset(text: str | None, site: Site) -> tuple[timezone, str]:
    """``--utc-offset +HH:MM`` as a time zone and its name; without it, the site's mean solar time
    (its longitude at 15 degrees an hour, to the second).

    Parameters
    ----------
    text : str or None
        The flag's value.
    site : Site
        The site [rad].

    Returns
    -------
    zone : datetime.timezone
        The local time's offset from UTC.
    name : str
        What it is, for the listing.
    """
    if text is None:
        seconds = round(math.degrees(site.longitude) * 240.0)
        zone = timezone(timedelta(seconds=seconds))
        return zone, f"local mean solar time (UTC{_offset_text(seconds)}, the site's longitude / 15 degrees an hour)"
    found = re.fullmatch(r"\s*([+-])(\d{1,2})(?::?(\d{2}))?\s*", text)
    if found is None or int(found[2]) > 14 or int(found[3] or 0) > 59:
        raise BadInput(f"--utc-offset {text}: give +HH:MM or -HH:MM, at most 14 hours")
    seconds = (1 if found[1] == "+" else -1) * (int(found[2]) * 3600 + int(found[3] or 0) * 60)
    return timezone(timedelta(seconds=seconds)), f"local time UTC{_offset_text(seconds)} (--utc-offset)"


def _offset_text(seconds: int) -> str:
    sign = "+" if seconds >= 0 else "-"
    hours, rest = divmod(abs(seconds), 3600)
    minutes, secs = divmod(rest, 60)
    return f"{sign}{hours:02d}:{minutes:02d}" + (f":{secs:02d}" if secs else "")


def _checked_target(write: str | None, pick: int | None) -> Path | None:
    """--write's file, checked before any work: a .yaml or .yml name, not there yet, in a folder that is."""
    from pipeline.cli.flags import flag_path

    if write is None:
        if pick is not None:
            raise BadInput(f"--pick {pick}: it chooses the eclipse --write writes; give --write NAME.yaml too")
        return None
    target = flag_path("--write", write)
    if target.suffix.lower() not in (".yaml", ".yml"):
        raise BadInput(f"--write {write}: name a .yaml file")
    if os.path.lexists(target):
        raise BadInput(f"--write {write}: {target} exists; remove it or name another file")
    if not target.parent.resolve().is_dir():
        raise BadInput(f"--write {write}: no folder {target.parent}")
    return target


def _chosen(eclipses: list[SiteEclipse], pick: int | None) -> int | None:
    """The number (from 1) of the eclipse to write: --pick's, else the greatest obscuration seen."""
    if not eclipses:
        return None
    if pick is None:
        return 1 + max(range(len(eclipses)), key=lambda i: (eclipses[i].seen_obscuration, -i))
    if not 1 <= pick <= len(eclipses):
        raise BadInput(f"--pick {pick}: the list has {len(eclipses)} eclipse{'' if len(eclipses) == 1 else 's'} "
                       f"(1-{len(eclipses)}); nothing written")
    return pick


def _place(site: Site) -> str:
    lat, lon = math.degrees(site.latitude), math.degrees(site.longitude)
    return (f"{abs(lat):.4f} {'N' if lat >= 0 else 'S'}, {abs(lon):.4f} {'E' if lon >= 0 else 'W'}, "
            f"{site.elevation:g} m")


def _eclipse_lines(number: int, eclipse: SiteEclipse, zone: timezone) -> list[str]:
    """The listing of one eclipse: its kind, the moments in order with the sun at each, the horizon."""
    kind = eclipse.seen
    if eclipse.central is not None:
        phase = "totality" if eclipse.kind == "total" else "annularity"
        minutes, seconds = divmod(eclipse.central, 60.0)
        kind += f", {int(minutes)} min {seconds:.1f} s of {phase}"
        if eclipse.seen != eclipse.kind:
            kind += " (below the horizon)"
    lines = [f"{number}. {eclipse.maximum:%Y-%m-%d} {kind}; greatest obscuration {100 * eclipse.obscuration:.2f}%"]
    moments = [(name, when) for name, when in eclipse.contacts.items() if when is not None]
    moments.append(("max", eclipse.maximum))
    for name, when in sorted(moments, key=lambda m: m[1]):
        sun = eclipse.sun[name]
        local = when.astimezone(zone)
        lines.append(f"   {name:<3} {when:%H:%M:%S}.{when.microsecond // 100000} UTC  {local:%H:%M:%S} local"
                     f"{'' if local.date() == when.date() else f' ({local:%m-%d})'}  sun "
                     f"{'up  ' if sun.elevation >= 0 else 'down'} elevation {math.degrees(sun.elevation):5.1f}, "
                     f"azimuth {math.degrees(sun.azimuth):5.1f} deg")
    if eclipse.rises_eclipsed or eclipse.sets_eclipsed:
        how = []
        if eclipse.rises_eclipsed:
            how.append(f"the sun rises eclipsed at {eclipse.visible[0][0]:%H:%M:%S} UTC")
        if eclipse.sets_eclipsed:
            how.append(f"it sets eclipsed at {eclipse.visible[-1][1]:%H:%M:%S} UTC, before C4")
        lines.append(f"   {'; '.join(how)}; greatest obscuration seen {100 * eclipse.seen_obscuration:.2f}% "
                     f"at {eclipse.seen_maximum:%H:%M:%S} UTC")
    return lines


def _command_line(args: argparse.Namespace) -> str:
    parts = ["sunshade eclipses", f"--site {args.site}", f"--years {args.years}"]
    if args.utc_offset is not None:
        parts.append(f"--utc-offset {args.utc_offset}")
    parts.append(f"--write {args.write}")
    if args.pick is not None:
        parts.append(f"--pick {args.pick}")
    return " ".join(parts)


def _covered_at(site: Site, a: datetime, b: datetime, fraction: float) -> datetime:
    """The moment between ``a`` and ``b`` (a partial phase) when the moon covers ``fraction`` of the sun, to 0.5 s."""
    from scipy.optimize import brentq  # 0.3 s to import: only when asked

    from pipeline.sky.ephemeris import obscured_fraction, separation, sun_and_moon

    def excess(t: float) -> float:
        sun, moon = sun_and_moon(site, a + timedelta(seconds=t))
        return float(obscured_fraction(separation(sun, moon), sun.angular_radius, moon.angular_radius)) - fraction

    return a + timedelta(seconds=float(brentq(excess, 0.0, (b - a).total_seconds(), xtol=0.5)))


def render_span(site: Site, eclipse: SiteEclipse) -> tuple[datetime, datetime]:
    """The span a written config renders: from ``SPAN_COVERED`` before C2 to ``SPAN_COVERED`` after C3
    where totality or annularity is seen, else C1..C4; either cut to where the sun stands above the end of civil
    twilight (``stages.resolve.MIN_SUN_ELEVATION``), around the greatest obscuration seen.

    Parameters
    ----------
    site : Site
        The observer.
    eclipse : SiteEclipse
        The eclipse.

    Returns
    -------
    start, end : datetime.datetime
        Aware UTC datetimes, whole seconds.
    """
    from pipeline.sky.eclipse_search import sun_above
    from pipeline.stages.resolve import MIN_SUN_ELEVATION

    c = eclipse.contacts
    if eclipse.seen != "partial" and c["C2"] is not None and c["C3"] is not None:
        start = _covered_at(site, c["C1"], c["C2"], SPAN_COVERED)  # type: ignore[arg-type]
        end = _covered_at(site, c["C3"], c["C4"], SPAN_COVERED)  # type: ignore[arg-type]
    else:
        start, end = c["C1"], c["C4"]  # type: ignore[assignment]
    stretches = sun_above(site, start, end, MIN_SUN_ELEVATION + _TWILIGHT_MARGIN)
    middle = eclipse.seen_maximum

    def away(stretch: tuple[datetime, datetime]) -> float:
        return 0.0 if stretch[0] <= middle <= stretch[1] else min(abs((edge - middle).total_seconds())
                                                                   for edge in stretch)

    start, end = min(stretches, key=away)
    start = start.replace(microsecond=0) + timedelta(seconds=1 if start.microsecond else 0)
    return start, end.replace(microsecond=0)


_TREES = {  # the crowns of configs/eclipse-2024-dallas-totality.yaml and configs/eclipse-2026-burgos-sunset.yaml
    "high": ("12.0                # metres above the ground: pinhole images about 13 cm across",
             "# one dense crown, 6 m in radius: the sun comes through small gaps only, so the crescents\n"
             "  # stand apart\n"
             "  trees: {count: 1, seed: 7, crown_radius: 6.0, leaves_per_tree: 160000, leaf_length: 0.10}"),
    "low": ("5.0                 # metres above the ground: a small tree, so the low sun's shadow\n"
            "                              # lies tens of metres from it, not over a hundred as a 12 m crown's would",
            "trees: {count: 1, seed: 7, crown_radius: 3.0, leaves_per_tree: 12000, leaf_length: 0.10}"),
}


def _close_framing(middle: float) -> tuple[str, str]:
    """The camera's field of view and the sun's cells of a written config whose sun stands
    ``middle`` degrees high at the span's middle (``CLOSE_FOV``, ``CLOSE_SUN_CELLS``): YAML lines,
    empty below LOW_SUN, where the plan frames the shadow's rim 35 degrees down."""
    from pipeline.stages.framing import LOW_SUN

    if middle < LOW_SUN:
        return "", ""
    return (f"  fov: {CLOSE_FOV}                   # vertical, degrees: close on the flecks, each crescent some\n"
            "                              # 11 cm and 100 pixels across, a few dozen in the picture\n",
            f"render: {{sun_cells: {CLOSE_SUN_CELLS}}}     # cells across the sun's disc on its fine grid\n"
            "                              # (3.4 mm pixels): the close crescents sharp; --preview keeps 13\n")


def config_text(site: Site, eclipse: SiteEclipse, name: str, command: str) -> str:
    """A config for ``eclipse`` at ``site``, written as configs/*.yaml are: commented, in flow style.

    The span ``render_span``; the tree of configs/eclipse-2024-dallas-totality.yaml, or the small
    one of configs/eclipse-2026-burgos-sunset.yaml (and a wider sky square) where the sun stands
    under 12 degrees during it; no camera place and no windows (the plan places them), the
    camera's field of view ``CLOSE_FOV`` and ``CLOSE_SUN_CELLS`` where the sun stands above
    ``stages.framing.LOW_SUN`` at the span's middle; automatic exposure; the built-in grass
    albedo, so that the file renders wherever it is.

    Parameters
    ----------
    site : Site
        The observer [rad, m].
    eclipse : SiteEclipse
        The eclipse.
    name : str
        The file's name, for the comments.
    command : str
        The command line that wrote it, for the comments.

    Returns
    -------
    str
        The YAML text.
    """
    from pipeline.sky.ephemeris import sun_and_moon

    start, end = render_span(site, eclipse)
    heights = [math.degrees(sun_and_moon(site, start + (end - start) * (k / 8))[0].elevation) for k in range(9)]
    low = min(heights) < math.degrees(_LOW_SUN)
    height, trees = _TREES["low" if low else "high"]
    fov, cells = _close_framing(heights[len(heights) // 2])
    c = eclipse.contacts
    contacts = ", ".join(f"{key} {when:%H:%M:%S}" for key, when in c.items() if when is not None)
    what = {"total": "through totality", "annular": "through annularity"}.get(eclipse.seen, "the whole partial eclipse")
    lat, lon = math.degrees(site.latitude), math.degrees(site.longitude)
    horizon = ""
    if min(heights) < 0.0:
        horizon = ("\n# The sun is below the horizon for part of the span (down to the end of civil twilight, 6\n"
                   "# degrees under it): there the twilight sky alone lights the ground.")
    limits = "[-4, 11]" if eclipse.seen == "total" or min(heights) < 0.0 else "[-4, 10]"
    seconds = (end - start).total_seconds()
    date, film = f"{eclipse.maximum:%Y-%m-%d}", f"{seconds / 60:.1f} minutes in 10 s of film"
    sun = f"the sun {min(heights):.1f} to {max(heights):.1f} degrees high over the span"
    return f"""# The {eclipse.kind} solar eclipse of {date} seen from {lat:.4f}, {lon:.4f} (degrees north, east),
# {what}: {start:%H:%M:%S} to {end:%H:%M:%S} UTC, {film} ({seconds / 240:.2f} s a frame).
# At this site {contacts} UTC; greatest eclipse {eclipse.maximum:%H:%M:%S} UTC,
# obscuration {100 * eclipse.obscuration:.2f}%; {sun}.{horizon}
# Written by
#   {command}
# The camera's place and the windows are left out: the plan places them on the tree's shadow
# (docs/method.md, "Framing"). Contacts, camera and light at the site: sunshade check {name}
# Render it:
#   sunshade render {name}
# or a first look:
#   sunshade render {name} --preview
canopy:
  height: {height}
  layout: isolated
  {trees}
  flutter: {{cycle: 48, swing: 12.0, twist: 20.0}}   # frames (2 s), degrees
sky:
  model: cie
  turbidity: auto            # the Linke turbidity climatology of the site and month
  site: {{latitude: {lat:.4f}, longitude: {lon:.4f}, elevation: {site.elevation:.1f}}}   # degrees north, east; metres
  time: {{start: "{start:%Y-%m-%dT%H:%M:%SZ}", end: "{end:%Y-%m-%dT%H:%M:%SZ}"}}   # UTC
  alpha: {85.0 if low else 80.0}                 # half-angle of the sky square, degrees
ground:
  pixel: 0.04                 # metres: sky light is smooth
  # albedo: the built-in grass; crescents show best on pale sand: albedo: PATH/configs/assets/sand.png
  # with albedo_size: 2.0
camera:
{fov}  resolution: [1280, 720]
  # auto exposure: follows the open ground's light down into the eclipse and back, 0.75 stops over it
  exposure: {{mode: auto, stops: 0.75, time_constant: 0.05, limits: {limits}}}
  white_balance: shade         # the skylit shade neutral, the crescents warm
foreground: {{model: none}}     # the crown is out of the picture: no tree passes
{cells}animation: {{frames: 240, fps: 24}}
"""
