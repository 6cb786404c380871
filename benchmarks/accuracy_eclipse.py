"""The eclipse sky against the published figures (docs/method.md, "The eclipse sky").

1. The light curve of configs/eclipse-2024-dallas-totality.yaml: for every --step-th frame the
   open ground's horizontal illuminance (the sky integrated over the hemisphere, the corona in
   it, plus the sun kernel's sum, which the moon cuts), log10 of it, S and the deep-eclipse
   weight b, with a log-scale bar; then beside it the published figures.
2. The sky at mid-totality (frame 122) from ``sunshade sky``'s equirectangular EXR (--width):
   horizontal illuminance, zenith luminance (above 85 degrees), the 0-10 degree band's luminance
   over the zenith's, and the band's red/blue ratio against the uneclipsed sky's.
3. configs/eclipse-2024-dallas.yaml from C1 up to 99.8% obscuration (every --step-th frame): the
   open ground's illuminance over the uneclipsed daylight's times S; the largest deviation.
4. With --calibration: for diffusion lengths of 20 to 80 km, the floor's factor k that puts the
   zenith at mid-totality at 1e-4 of the day's and the k that puts the light at second contact
   two decades under the light a minute before (the sky is linear in k: measured at k = 0 and
   1), and what each k gives (sky 512 px wide).

    python benchmarks/accuracy_eclipse.py [--step N] [--width W] [--calibration]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from dataclasses import replace
from datetime import timedelta
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky import eclipse, ephemeris
from pipeline.sky.equirect import EquirectSky
from pipeline.sky.sun_disc import MoonDisc, SunDisc
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.resolve import load
from pipeline.stages.scene import (
    load_sky,
    scene_at,
)

Y = np.asarray(REC709_LUMINANCE, dtype=np.float64)
TOTALITY = ROOT / "configs" / "eclipse-2024-dallas-totality.yaml"
PARTIAL = ROOT / "configs" / "eclipse-2024-dallas.yaml"
PUBLISHED = """published (docs/method.md, "The eclipse sky"):
  Sharp, Silverman & Lloyd 1971: sky = clear sky x S to >= 99.8% obscuration; zenith at
    totality about 1e-4 of its daytime value; horizontal illuminance about 1-5 lx (0.1-10 lx
    with the umbra's size and the site's place in it)
  2017 sky-quality meters: 12.4-13.3 mag/arcsec^2 at totality = 0.5-1.2 cd/m^2 at the zenith
  the light falls about 2.5 decades in the last minute before second contact
  a reddened band 0-8 degrees above the horizon all round"""


def open_ground(config, frame: int):
    """(lux, S, b) of the open ground at ``frame``: sky (with the corona) plus the sun kernel."""
    sky = load_sky(config.sky, scene_at(config, frame))
    sun = sun_irradiance(sky) if sky.sun_fraction() > 0 else np.zeros(3)
    return 1e3 * float((sky.sky_irradiance + sun) @ Y), sky.sun_fraction(), sky._deep, sky


def light_curve(step: int) -> None:
    config = load(TOTALITY)
    print(f"1. light curve of {TOTALITY.relative_to(ROOT)} (open ground, sky + sun)")
    print(" frame  UTC        S         b     lux        log10  (log scale, 1 mark = 1/4 decade)")
    for frame in range(0, config.animation.frames, step):
        lux, s, b, _sky = open_ground(config, frame)
        when = scene_at(config, frame).when
        bar = "#" * max(0, int(round(4 * (np.log10(lux) + 1))))
        print(f" {frame:5d}  {when:%H:%M:%S}  {s:.2e}  {b:4.2f}  {lux:9.3g}  {np.log10(lux):6.2f}  {bar}")
    print(PUBLISHED)


def totality_sky(width: int) -> None:
    config = load(TOTALITY)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "sky.exr"
        subprocess.run([sys.executable, "-m", "pipeline.cli", "sky", str(TOTALITY), "--frame", "122",
                        "-o", str(out), "--width", str(width)], check=True, cwd=ROOT, capture_output=True)
        image = io.read_image(out)[..., :3].astype(np.float64)
    sky = load_sky(config.sky, scene_at(config, 122))
    day = replace(sky, moon=None).equirect(width).astype(np.float64)
    height = image.shape[0]
    elevation = 90 - (np.arange(height) + 0.5) * 180 / height
    band, top = (elevation > 0) & (elevation < 10), elevation > 85
    lux = 1e3 * EquirectSky(image.astype(np.float32)).image_irradiance() @ Y
    zenith = 1e3 * (image[top] @ Y).mean()
    day_zenith = 1e3 * (day[top] @ Y).mean()
    ratio = (image[band] @ Y).mean() / (image[top] @ Y).mean()
    rb = image[band].reshape(-1, 3).mean(axis=0)
    day_rb = day[band].reshape(-1, 3).mean(axis=0)
    print(f"\n2. the sky at mid-totality (frame 122), sunshade sky --width {width}:")
    print(f"  horizontal illuminance {lux:.3g} lx (corona {1e3 * sky.corona_irradiance @ Y:.3g} lx); zenith "
          f"{zenith:.3g} cd/m^2 = {zenith / day_zenith:.3g} of the day's ({day_zenith:.4g} cd/m^2)")
    print(f"  0-10 degree band {ratio:.3g} x the zenith; its red/blue {rb[0] / rb[2]:.3g} "
          f"(uneclipsed: {day_rb[0] / day_rb[2]:.3g})")
    print(f"  model constants: SHARP_LIMIT {eclipse.SHARP_LIMIT}, k {eclipse.MULTIPLE_SCATTERING}, "
          f"diffusion length {eclipse.DIFFUSION_LENGTH / 1e3:g} km")


def partial_phase(step: int) -> None:
    config = load(PARTIAL)
    print(f"\n3. {PARTIAL.relative_to(ROOT)} up to 99.8% obscuration: open ground / (uneclipsed x S)")
    worst = 0.0
    for frame in range(0, config.animation.frames, step):
        lux, s, b, sky = open_ground(config, frame)
        if b > 0:
            break
        clear = replace(sky, moon=None)
        ratio = lux / (1e3 * float((clear.sky_irradiance + sun_irradiance(clear)) @ Y) * s)
        worst = max(worst, abs(ratio - 1))
        print(f"  frame {frame:3d}  S {s:.4f}  ratio {ratio:.4f}")
    print(f"  largest deviation {100 * worst:.2f}%")


def calibration() -> None:
    config = load(TOTALITY)
    s = config.sky.site
    site = ephemeris.Site(s.latitude, s.longitude, s.elevation)
    contacts = ephemeris.contact_times(site, s.start, s.end)

    def sky_at(when):
        sun, moon = ephemeris.sun_and_moon(site, when)
        scene = replace(scene_at(config, 0), when=when,
                        sun=SunDisc(sun.azimuth, sun.elevation, sun.angular_radius),
                        moon=MoonDisc(moon.azimuth, moon.elevation, moon.angular_radius))
        return load_sky(config.sky, scene)

    c2, c3 = contacts["C2"], contacts["C3"]
    middle = sky_at(c2 + (c3 - c2) / 2)
    before = sky_at(c2 - timedelta(seconds=60))
    minute = 1e3 * float((before.sky_irradiance + before.sun_fraction() * before.undimmed_sun_irradiance()) @ Y)
    day = replace(middle, moon=None).equirect(512).astype(np.float64)
    elevation = 90 - (np.arange(256) + 0.5) * 180 / 256
    band, top = (elevation > 0) & (elevation < 10), elevation > 85
    day_zenith = (day[top] @ Y).mean()
    print(f"\n4. calibration at Dallas (a minute before C2: {minute:.3g} lx); the sky is linear in k")
    kept = eclipse.DIFFUSION_LENGTH, eclipse.MULTIPLE_SCATTERING
    try:
        for length in (20e3, 35e3, 50e3, 80e3):
            eclipse.DIFFUSION_LENGTH = length
            measured = []
            for k in (0.0, 1.0):
                eclipse.MULTIPLE_SCATTERING = k
                sky = sky_at(c2 + (c3 - c2) / 2)
                image = sky.equirect(512).astype(np.float64)
                at_c2 = sky_at(c2)
                measured.append(np.array([(image[top] @ Y).mean() / day_zenith, 1e3 * sky.sky_irradiance @ Y,
                                          (image[band] @ Y).mean(), (image[top] @ Y).mean(),
                                          1e3 * at_c2.sky_irradiance @ Y, *image[band].reshape(-1, 3).mean(axis=0)]))
            zero, one = measured
            for target, k in (("zenith 1e-4", (1e-4 - zero[0]) / (one[0] - zero[0])),
                              ("two decades", (minute / 100 - zero[4]) / (one[4] - zero[4]))):
                v = zero + k * (one - zero)
                print(f"  {length / 1e3:3.0f} km, {target}: k {k:.3g}; zenith {v[0]:.2g} of the day's, mid-totality "
                      f"{v[1]:.3g} lx, band {v[2] / v[3]:.3g} x the zenith, C2 {v[4]:.3g} lx "
                      f"({np.log10(minute / v[4]):.2f} decades under), band red/blue {v[5] / v[7]:.2f}")
    finally:
        eclipse.DIFFUSION_LENGTH, eclipse.MULTIPLE_SCATTERING = kept


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step", type=int, default=8)
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--calibration", action="store_true")
    args = parser.parse_args()
    light_curve(args.step)
    totality_sky(args.width)
    partial_phase(args.step * 3)
    if args.calibration:
        calibration()


if __name__ == "__main__":
    main()
