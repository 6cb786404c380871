"""The procedural sky from golden hour to the end of civil twilight, as one picture for the docs.

    python benchmarks/twilight_pictures.py OUT.jpg

Four skies (CIE type 12, Linke turbidity 3, the sun at azimuth 270, elevations 10, 2, -2 and -5
degrees), each the upper hemisphere of ``ProceduralSky.equirect`` (1024 texels round) from
azimuth 90 to 450 with the sun in the middle, stacked top to bottom. Each row is exposed by
``composite.display_sky`` (its median luminance at 0.4): the level falls some 4000-fold from
the first to the last (printed: the open ground's illuminance), the colours are the model's.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.colour import REC709_LUMINANCE  # noqa: E402
from pipeline.composite import display_sky  # noqa: E402
from pipeline.sky import ProceduralSky  # noqa: E402
from pipeline.sun_disc import SunDisc  # noqa: E402

ELEVATIONS = (10.0, 2.0, -2.0, -5.0)


def main() -> None:
    rows = []
    for h in ELEVATIONS:
        sky = ProceduralSky(3.0, SunDisc(np.radians(270.0), np.radians(h)))
        image = sky.equirect(1024)
        image = np.roll(image, 256, axis=1)  # azimuth 270 (a quarter of the width) to the centre: the sun
        picture = display_sky(image)[: image.shape[0] // 2]
        rows.append(np.clip(np.asarray(picture) * 255.0 + 0.5, 0, 255).astype(np.uint8))
        lux = 1000.0 * float((sky.sky_irradiance + sky.undimmed_sun_irradiance()) @ REC709_LUMINANCE)
        print(f"sun {h:+5.1f} degrees: open ground {lux:9.1f} lx")
    Image.fromarray(np.concatenate(rows, axis=0)).save(sys.argv[1], quality=85)


if __name__ == "__main__":
    main()
