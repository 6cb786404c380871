"""The procedural sky and the ground from golden hour to civil twilight, as pictures for the docs.

    python benchmarks/twilight_pictures.py docs/images

Writes three PNGs into the folder:

- ``twilight-skies.png``: five skies (CIE type 12, Linke turbidity 3, the sun at azimuth 270,
  elevations 10, 2, -1, -3 and -5 degrees), each the upper hemisphere of
  ``ProceduralSky.equirect`` (768 texels round) from azimuth 90 to 450 with the sun in the
  middle, stacked top to bottom, each exposed by ``composite.display_sky`` (its median luminance
  at 0.4): the level falls some 1000-fold from the first to the last (printed: the open ground's
  illuminance), the colours are the model's.
- ``golden-hour-flecks.png``: ``sunshade frame`` of a forest (``forest.yaml``'s canopy, 10 m up,
  18000 leaves a tree) with the sun at 10 degrees (azimuth 250), looking straight down from 6 m:
  the pinhole images are ellipses 0.54 m wide and 3.1 m long, drawn out across the picture
  (left-right: towards azimuth 70, away from the sun). White balance "shade", 2 stops over the
  default exposure, flat grey ground.
- ``civil-twilight.png``: ``sunshade frame`` at Madrid, 2026-08-13 19:28 UTC (the sun 3.1
  degrees down, azimuth 292), looking 25 degrees up towards the set sun (left) and away from it
  (right), exposed 1.8 stops under the config's default, flat grey ground.

The frames run in a temporary folder with their own cache; each takes a few seconds.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.camera.composite import display_sky
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc

ELEVATIONS = (10.0, 2.0, -1.0, -3.0, -5.0)
WIDTH = 768

TREE = "{count: 1, seed: 7, crown_radius: 3.0, leaves_per_tree: 3000, leaf_length: 0.10}"

GOLDEN_HOUR = """
canopy: {height: 10.0, layout: periodic, size: [20.0, 20.0],
         trees: {count: 7, seed: 8, crown_radius: 4.5, leaves_per_tree: 18000, leaf_length: 0.11}}
sky: {model: cie, turbidity: 3.0, sun: {elevation: 10.0, azimuth: 250.0}, alpha: 85.0}
ground: {window: [-10, -10, 10, 10], pixel: 0.05, sun_window: [-10, -10, 10, 10], sun_pixel: 0.04,
         albedo: ALBEDO, albedo_size: 2.0}
camera: {position: [0.0, 0.0, 6.0], yaw: 160.0, pitch: -89.0, fov: 70.0, resolution: [640, 360],
         white_balance: shade, exposure: 2.0}
foreground: {model: none}
animation: {frames: 1, fps: 24}
"""

TWILIGHT = f"""
canopy: {{height: 6.0, layout: isolated, trees: {TREE}}}
sky: {{model: cie, turbidity: 3.0, site: {{latitude: 40.42, longitude: -3.70, elevation: 650.0}},
      time: {{start: "2026-08-13T19:28:00Z", end: "2026-08-13T19:29:00Z"}}, alpha: 85.0}}
ground: {{window: [-20, -20, 20, 20], pixel: 0.1, sun_window: [-2, -2, 2, 2], sun_pixel: 0.05,
         albedo: ALBEDO, albedo_size: 2.0}}
camera: {{position: [0.0, 0.0, 1.7], yaw: YAW, pitch: 25.0, fov: 70.0, resolution: [480, 360], exposure: -1.8}}
foreground: {{model: none}}
animation: {{frames: 1, fps: 24}}
"""


def skies(out: Path) -> None:
    rows = []
    for h in ELEVATIONS:
        sky = ProceduralSky(3.0, SunDisc(np.radians(270.0), np.radians(h)))
        image = sky.equirect(WIDTH)
        image = np.roll(image, WIDTH // 4, axis=1)  # azimuth 270 (a quarter of the width) to the centre: the sun
        picture = display_sky(image)[: image.shape[0] // 2]
        rows.append(np.clip(np.asarray(picture) * 255.0 + 0.5, 0, 255).astype(np.uint8))
        lux = 1000.0 * float((sky.sky_irradiance + sky.undimmed_sun_irradiance()) @ REC709_LUMINANCE)
        print(f"sun {h:+5.1f} degrees: open ground {lux:9.1f} lx")
    Image.fromarray(np.concatenate(rows, axis=0)).save(out / "twilight-skies.png", optimize=True)


def frame(config: str, work: Path, name: str) -> Image.Image:
    path = work / f"{name}.yaml"
    path.write_text(config.replace("ALBEDO", str(work / "flat.png")))
    subprocess.run(["sunshade", "frame", str(path), "-o", str(work / f"{name}.png"), "--threads", "1",
                    "--cache", str(work / "cache")], check=True)
    return Image.open(work / f"{name}.png")


def main() -> None:
    out = Path(sys.argv[1])
    skies(out)
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        Image.new("RGB", (16, 16), (150, 150, 150)).save(work / "flat.png")
        frame(GOLDEN_HOUR, work, "golden").save(out / "golden-hour-flecks.png", optimize=True)
        towards, away = (frame(TWILIGHT.replace("YAW", yaw), work, name)
                         for yaw, name in (("292.0", "towards"), ("112.0", "away")))
        both = Image.new("RGB", (towards.width + away.width, towards.height))
        both.paste(towards, (0, 0))
        both.paste(away, (towards.width, 0))
        both.save(out / "civil-twilight.png", optimize=True)


if __name__ == "__main__":
    main()
