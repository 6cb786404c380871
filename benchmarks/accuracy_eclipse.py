"""The eclipse sky against the published figures (docs/method.md, "The eclipse sky").

1. The light curve of the totality demo, configs/eclipse-2024-dallas-totality.yaml: each frame's
   sky light as the report's light.csv gives it (``sky_lux``, ``lighting.open_ground_light`` of
   the frame's sky), S and the deep-eclipse weight b for the frames around the blend, and the
   largest second difference of ln(sky light) per frame between S = 0.01 and 0.0005 on each side
   of totality (required: at most 0.015). With --render A-B: those frames rendered with
   ``sunshade render --preview`` and their light.csv read back against the same numbers.
2. Mid-totality at each calibration site (``SITES``): the zenith's luminance [cd/m^2] and its
   ratio to the uneclipsed zenith's, the open ground's illuminance [lx] (the sky and its corona),
   the zenith's colour (correlated colour temperature and Duv, the distance from the Planckian
   locus, with colour-science, when installed, and its blue/red against the day's zenith's), and
   the 0-8 degree band's red/blue against the day's (required: at least BAND_REDDENING times);
   each against its published band.
3. configs/eclipse-2024-dallas.yaml from C1 up to 99.8% obscuration (every --step-th frame): the
   open ground's illuminance over the uneclipsed daylight's times S; the largest deviation.
4. With --calibration: for diffusion lengths of 60 to 120 km, the factor k that puts the
   zenith at the Idaho 2017 meters' 0.78 cd/m^2, and what they give at the two calibration
   sites (the sky is linear in k: measured at k = 0 and 1): the zenith, the open ground, the
   fall in the last minute before C2, the zenith's colour shift in mired (published: Dandekar &
   Turtle 1971) and the band's reddening.

    python benchmarks/accuracy_eclipse.py [--step N] [--render A-B] [--calibration]
    pip install colour-science   # for the zenith's CCT (not a dependency; without it: blue/red only)
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky import daylight, eclipse, ephemeris
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import MoonDisc, SunDisc, angle_to
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.lighting import open_ground_light
from pipeline.stages.resolve import load
from pipeline.stages.scene import load_sky, scene_at

Y = np.asarray(REC709_LUMINANCE, dtype=np.float64)
TOTALITY = ROOT / "configs" / "eclipse-2024-dallas-totality.yaml"
PARTIAL = ROOT / "configs" / "eclipse-2024-dallas.yaml"
SMOOTH_RANGE = (0.0005, 0.01)
"""S between which the light curve's second difference is held (docs/accuracy.md). [1]"""
SMOOTH_LIMIT = 0.015
"""The most second difference of ln(sky light) per frame allowed there. [1]"""
COLOUR_SHIFT = 1e6 / 11_000 - 1e6 / 9_000
"""The zenith's reciprocal colour temperature at totality less the day's: 11,000 K against
9,000 K (Dandekar & Turtle 1971). [1/MK, mired]"""
METER_ZENITH = 0.78
"""cd/m^2 of 12.85 mag/arcsec^2, the middle of the Idaho 2017 sky-quality meters' 12.4-13.3. [cd/m^2]"""
BAND_REDDENING = 2.5
"""The least red/blue of the 0-8 degree band at mid-totality over the day's band's (a reddened,
sunset-like band; docs/method.md, "The eclipse sky", says where the figure comes from). [1]"""


@dataclass(frozen=True)
class Calibration:
    """A total eclipse seen from a site: a name, latitude and longitude [deg], elevation [m], an
    hour within an hour of mid-totality (UTC), and whether the published bands (measured with
    the sun 45-65 degrees up) apply."""

    name: str
    latitude: float
    longitude: float
    elevation: float
    near: datetime
    banded: bool


SITES = (
    Calibration("Dallas 2024 (configs/eclipse-2024-dallas*.yaml)", 32.78, -96.80, 140.0,
                datetime(2024, 4, 8, 18, 40, tzinfo=UTC), True),
    Calibration("Stanley, Idaho 2017", 44.22, -114.94, 1900.0, datetime(2017, 8, 21, 17, 30, tzinfo=UTC), True),
    Calibration("Luxor 2027 (high sun)", 25.69, 32.64, 80.0, datetime(2027, 8, 2, 10, 0, tzinfo=UTC), False),
    Calibration("Burgos 2026 (low sun)", 42.34, -3.70, 860.0, datetime(2026, 8, 12, 18, 27, tzinfo=UTC), False),
)
"""The calibration sites (docs/method.md, "The eclipse sky"): the first two fix the constants."""


def uncovered(sky: ProceduralSky) -> float:
    """u, the sun's uncovered area fraction (1 - ``ephemeris.obscured_fraction``) that the sky's
    deep-eclipse weight b = ``eclipse.deep_weight(u)`` is of; 1 without a moon. [1]"""
    if sky.moon is None:
        return 1.0
    separation = float(angle_to(sky.moon_direction, sky.sun_direction))
    return 1.0 - float(ephemeris.obscured_fraction(separation, sky.sun.angular_radius, sky.moon.angular_radius))


def sky_light_curve(config, frames):
    """(frames, S, b, sky lux, u) of ``frames``: the report's ``sky_lux`` of each (light.csv)."""
    rows = []
    for frame in frames:
        sky = load_sky(config.sky, scene_at(config, frame))
        u = uncovered(sky)
        rows.append((frame, sky.sun_fraction(), eclipse.deep_weight(u), open_ground_light(sky, 1.0, None)["sky_lux"],
                     u))
    return np.array(rows)


def worst_bend(curve) -> list[tuple[float, int]]:
    """The largest |second difference| of ln(sky lux) per frame with S in SMOOTH_RANGE, and its
    frame, on each side of totality (frames where S falls, then where it rises)."""
    out = []
    frame, s, _b, lux, _u = curve.T
    log = np.log(lux)
    bend = log[2:] - 2 * log[1:-1] + log[:-2]
    middle = s[1:-1]
    falling = np.arange(len(middle)) < np.argmin(s)
    for side in (falling, ~falling):
        inside = side & (middle >= SMOOTH_RANGE[0]) & (middle <= SMOOTH_RANGE[1])
        i = np.flatnonzero(inside)[np.argmax(np.abs(bend[inside]))]
        out.append((float(abs(bend[i])), int(frame[i + 1])))
    return out


def light_curve(render: str | None) -> None:
    config = load(TOTALITY)
    frames = range(config.animation.frames)
    curve = sky_light_curve(config, frames)
    print(f"1. the sky light of {TOTALITY.relative_to(ROOT)} (light.csv's sky_lux), ln per frame")
    print(" frame  covered   S         b      sky lux   d ln   d2 ln")
    log = np.log(curve[:, 3])
    for i, (frame, s, b, lux, u) in enumerate(curve):
        if 0 < i < len(curve) - 1 and (0 < b < 1 or abs(u - eclipse.SHARP_LIMIT) < 8e-4):
            print(f" {int(frame):5d}  {100 * (1 - u):.3f}%  {s:.2e}  {b:5.3f}  {lux:8.3f}  {log[i] - log[i - 1]:+.3f}  "
                  f"{log[i + 1] - 2 * log[i] + log[i - 1]:+.4f}")
    for (bend, frame), side in zip(worst_bend(curve), ("before C2", "after C3")):
        print(f"  {side}: largest second difference of ln(sky lux) with S in {SMOOTH_RANGE}: {bend:.4f} "
              f"(frame {frame}; at most {SMOOTH_LIMIT})")
    if render:
        check_render(config, render, curve)


def check_render(config, frames: str, curve) -> None:
    """Render ``frames`` (A-B) with --preview and compare light.csv's sky_lux with the curve."""
    first, last = (int(v) for v in frames.split("-"))
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "pipeline.cli", "render", str(TOTALITY), "--preview", "--frames",
                        frames, "--output", tmp, "--cache", str(Path(tmp) / "cache")], check=True, cwd=ROOT,
                       capture_output=True)
        table = next(Path(tmp).rglob("light.csv"))
        with table.open() as f:
            read = {int(r["frame"]): float(r["sky_lux"]) for r in csv.DictReader(f) if r["sky_lux"]}
    worst = max(abs(read[n] / curve[n, 3] - 1) for n in range(first, last + 1))
    print(f"  rendered frames {frames} (--preview): light.csv's sky_lux against the curve: largest "
          f"relative difference {worst:.2e}")


def site_sky(site: ephemeris.Site, when: datetime, turbidity: float, moon: bool = True) -> ProceduralSky:
    """The procedural CIE sky at ``site`` and ``when``, with or without the moon."""
    sun, m = ephemeris.sun_and_moon(site, when)
    return ProceduralSky(turbidity, SunDisc(sun.azimuth, sun.elevation, sun.angular_radius),
                         moon=MoonDisc(m.azimuth, m.elevation, m.angular_radius) if moon else None,
                         altitude=site.elevation)


def at_totality(calibration: Calibration):
    """(site, C2, mid-totality, turbidity) of a calibration site."""
    site = ephemeris.Site.from_degrees(calibration.latitude, calibration.longitude, calibration.elevation)
    contacts = ephemeris.contact_times(site, calibration.near - timedelta(hours=1),
                                       calibration.near + timedelta(hours=1))
    middle = contacts["C2"] + (contacts["C3"] - contacts["C2"]) / 2
    return site, contacts["C2"], middle, daylight.linke_turbidity(middle, site.latitude, site.longitude)


def band_directions() -> np.ndarray:
    """Sky-plane points 4 degrees up at 24 azimuths: the 0-8 degree band. [tan]"""
    azimuth = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    reach = 1 / np.tan(np.radians(4.0))
    return np.stack([reach * np.sin(azimuth), reach * np.cos(azimuth)], axis=-1)


def correlated_colour_temperature(rgb, duv: bool = False):
    """CCT [K] of a linear Rec.709 colour (Ohno 2013, colour-science), None without colour-science;
    with ``duv``, (CCT, Duv) (Duv: the distance from the Planckian locus in CIE 1960 uv, positive
    towards green)."""
    try:
        import colour
    except ImportError:
        return None
    xyz = colour.models.RGB_COLOURSPACE_BT709.matrix_RGB_to_XYZ @ np.asarray(rgb, dtype=np.float64)
    uv = colour.xy_to_UCS_uv(xyz[:2] / xyz.sum())
    cct, distance = (float(v) for v in colour.uv_to_CCT(uv, method="Ohno 2013"))
    return (cct, distance) if duv else cct


def totality_figures(calibration: Calibration) -> dict:
    """The sky at mid-totality at a site and the day's there: zenith [cd/m^2], its ratio, open
    ground [lx], the zenith's colours (CCT, Duv) and blue/red, the band's red/blue."""
    site, _c2, middle, turbidity = at_totality(calibration)
    sky = site_sky(site, middle, turbidity)
    day = replace(sky, moon=None)
    zenith, day_zenith = (s.clear_radiance(np.zeros((1, 2)))[0] for s in (sky, day))
    band, day_band = (s.clear_radiance(band_directions()).mean(axis=0) for s in (sky, day))
    return dict(sun=float(np.degrees(sky.sun.elevation)), turbidity=turbidity, when=middle,
                zenith=1e3 * float(zenith @ Y), ratio=float(zenith @ Y / (day_zenith @ Y)),
                lux=1e3 * float(sky.sky_irradiance @ Y), corona=1e3 * float(sky.corona_irradiance @ Y),
                cct=correlated_colour_temperature(zenith), day_cct=correlated_colour_temperature(day_zenith),
                duv=correlated_colour_temperature(zenith, duv=True), day_duv=correlated_colour_temperature(day_zenith,
                                                                                                     duv=True),
                shift=float(zenith[2] / zenith[0] / (day_zenith[2] / day_zenith[0])),
                band_red_blue=float(band[0] / band[2]), day_band_red_blue=float(day_band[0] / day_band[2]))


def mark(value: float, low: float, high: float) -> str:
    return "in" if low <= value <= high else "OUT of"


def totality_sites() -> None:
    print("\n2. mid-totality at the calibration sites (bands: published at a 45-65 degree sun)")
    for calibration in SITES:
        v = totality_figures(calibration)
        cct = "" if v["cct"] is None else f"CCT {v['cct']:.0f} K against the day's {v['day_cct']:.0f} K; "
        note = "" if calibration.banded else " (outside the bands' sun elevations: shown, not held)"
        print(f"  {calibration.name}: {v['when']:%Y-%m-%d %H:%M:%S} UTC, sun {v['sun']:.1f} deg, turbidity "
              f"{v['turbidity']:.2f}{note}")
        print(f"    zenith {v['zenith']:.3g} cd/m^2 ({mark(v['zenith'], 0.5, 1.2)} 0.5-1.2), {v['ratio']:.3g} of "
              f"the day's ({mark(v['ratio'], 0.8e-4, 4e-4)} 0.8e-4 to 4e-4)")
        print(f"    open ground {v['lux']:.3g} lx (corona {v['corona']:.3g} lx; {mark(v['lux'], 1, 5)} 1-5 lx)")
        mired = "" if v["cct"] is None else f" ({1e6 / v['cct'] - 1e6 / v['day_cct']:+.1f} mired; published 11,000 K " \
            f"against 9,000 K: {COLOUR_SHIFT:+.1f})"
        print(f"    zenith colour: {cct}blue/red {v['shift']:.3g} x the day's{mired}: "
              f"{'bluer' if v['shift'] > 1 and (v['cct'] is None or v['cct'] > v['day_cct']) else 'NOT bluer'}")
        if v["duv"] is not None:
            print(f"    zenith Duv {v['duv'][1]:+.4f} against the day's {v['day_duv'][1]:+.4f} (the daylight locus: "
                  "about 0; positive: greener)")
        reddening = v["band_red_blue"] / v["day_band_red_blue"]
        held = mark(reddening, BAND_REDDENING, np.inf) if calibration.banded else "shown, not held:"
        print(f"    0-8 degree band red/blue {v['band_red_blue']:.3g} against the day's "
              f"{v['day_band_red_blue']:.3g}: x{reddening:.2f} ({held} at least x{BAND_REDDENING})")


def partial_phase(step: int) -> None:
    config = load(PARTIAL)
    print(f"\n3. {PARTIAL.relative_to(ROOT)} up to 99.8% obscuration: open ground / (uneclipsed x S)")
    worst = 0.0
    for frame in range(0, config.animation.frames, step):
        sky = load_sky(config.sky, scene_at(config, frame))
        if eclipse.deep_weight(uncovered(sky)) > 0:
            break
        clear = replace(sky, moon=None)
        lux = float((sky.sky_irradiance + sun_irradiance(sky)) @ Y)
        ratio = lux / (float((clear.sky_irradiance + sun_irradiance(clear)) @ Y) * sky.sun_fraction())
        worst = max(worst, abs(ratio - 1))
        print(f"  frame {frame:3d}  S {sky.sun_fraction():.4f}  ratio {ratio:.4f}")
    print(f"  largest deviation {100 * worst:.2f}%")


def linear_parts(calibration: Calibration) -> dict:
    """The mid-totality zenith (3,) and day zenith [kcd/m^2], open ground and C2's sky [lx] and
    the light a minute before C2 [lx] at k = 0 and 1 (the sky is linear in k)."""
    site, c2, middle, turbidity = at_totality(calibration)
    before = site_sky(site, c2 - timedelta(seconds=60), turbidity)
    parts = dict(minute=1e3 * float((before.sky_irradiance + before.sun_fraction() * before.undimmed_sun_irradiance())
                                    @ Y),
                 day=site_sky(site, middle, turbidity, moon=False).clear_radiance(np.zeros((1, 2)))[0])
    kept = eclipse.UMBRA_SCATTERING
    try:
        for k in (0.0, 1.0):
            eclipse.UMBRA_SCATTERING = k
            sky = site_sky(site, middle, turbidity)
            parts[k] = (sky.clear_radiance(np.zeros((1, 2)))[0], 1e3 * float(sky.sky_irradiance @ Y),
                        1e3 * float(site_sky(site, c2, turbidity).sky_irradiance @ Y))
    finally:
        eclipse.UMBRA_SCATTERING = kept
    return parts


def colour_and_band(calibration: Calibration) -> tuple[float | None, float]:
    """The zenith's reciprocal CCT at mid-totality less the day's [mired] (None without
    colour-science) and the band's red/blue over the day's [1], at the current constants."""
    v = totality_figures(calibration)
    shift = None if v["cct"] is None else 1e6 / v["cct"] - 1e6 / v["day_cct"]
    return shift, v["band_red_blue"] / v["day_band_red_blue"]


def calibration() -> None:
    print(f"\n4. calibration: k for Stanley's zenith at {METER_ZENITH} cd/m^2, per diffusion length (the way in's "
          "length and the sideways kernel's)")
    fixing = [c for c in SITES if c.banded]
    kept = eclipse.DIFFUSION_LENGTH, eclipse.UMBRA_SCATTERING
    try:
        for length in (60e3, 80e3, 100e3, 120e3):
            eclipse.DIFFUSION_LENGTH = length
            parts = [linear_parts(c) for c in fixing]
            idaho = parts[1]
            z0, z1 = (1e3 * float(idaho[k][0] @ Y) for k in (0.0, 1.0))
            k = (METER_ZENITH - z0) / (z1 - z0)
            eclipse.UMBRA_SCATTERING = k
            line = f"  {length / 1e3:3.0f} km: k {k:.4f};"
            for c, p in zip(fixing, parts):
                zenith = p[0.0][0] + k * (p[1.0][0] - p[0.0][0])
                lux = p[0.0][1] + k * (p[1.0][1] - p[0.0][1])
                c2 = p[0.0][2] + k * (p[1.0][2] - p[0.0][2])
                shift, band = colour_and_band(c)
                mired = "" if shift is None else f"zenith {shift:+.1f} mired, "
                line += (f" {c.name.split(' (')[0]}: zenith {1e3 * zenith @ Y:.3g} cd/m^2 = "
                         f"{zenith @ Y / (p['day'] @ Y):.3g}, {lux:.3g} lx, C2 {np.log10(p['minute'] / c2):.2f} "
                         f"decades under a minute before, {mired}band x{band:.2f};")
            print(line)
    finally:
        eclipse.DIFFUSION_LENGTH, eclipse.UMBRA_SCATTERING = kept


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step", type=int, default=24)
    parser.add_argument("--render", metavar="A-B", help="also render these frames (--preview) and read light.csv")
    parser.add_argument("--calibration", action="store_true")
    args = parser.parse_args()
    light_curve(args.render)
    totality_sites()
    partial_phase(args.step)
    if args.calibration:
        calibration()


if __name__ == "__main__":
    main()
