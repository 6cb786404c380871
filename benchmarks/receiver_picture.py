"""Leaf shadows on a white wall in the evening sun, as a picture of the wall's irradiance raster.

    python benchmarks/receiver_picture.py OUT.png [--elevation 12] [--frame 0]

A wall 4 m wide and 3 m high faces the sun (azimuth 250, clear procedural sky, turbidity 3); one
tree of the procedural grove (crown radius 1.6 m at 2.6 m, 9000 leaves) stands 3 m in front of
it. Its leaves are turned into the wall's frame and drawn into one layer 3 m out, projected along the sun
(``receivers.layers``), correlated with the wall's hemisphere (the sky, and the open ground of
albedo 0.2 below the horizon) and the sun's kernel at its incidence on a 3 mm window over the whole
wall (``receivers.light``). The picture is the raster as one faces the wall, upright, its light over
the open wall's times 0.85 through the sRGB curve (the sun's warm colour kept: green scaled). Printed:
the open wall's sky and sun light, (sun + sky) / sky, the raster's p95 / p5 and the time.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.canopy.grove import FlutterParams, GroveParams, grow_grove
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import Grid
from pipeline.core.io import write_png
from pipeline.receivers.hemisphere import ground_radiance, world_radiance
from pipeline.receivers.layers import grove_in_frame, grove_layers
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import wall
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc
from pipeline.sky.sun_kernel import sun_irradiance

DEG = np.pi / 180
AZIMUTH = 250 * DEG


def srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB curve on linear values in [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--elevation", type=float, default=12.0, help="the sun's elevation [deg]")
    parser.add_argument("--frame", type=int, default=0, help="the flutter frame")
    args = parser.parse_args()
    start = time.perf_counter()
    sky = ProceduralSky(3.0, SunDisc(AZIMUTH, args.elevation * DEG))
    plane = wall((0.0, 0.0, 0.0), facing=AZIMUTH, width=4.0, height=3.0)
    trunk = 3.0 * plane.normal[:2] + 0.3 * plane.across[:2]
    grove = grow_grove(GroveParams(count=1, crown_radius=1.6, leaves_per_tree=9000, leaf_length=0.09,
                                   leaves_per_cluster=30, height=2.6, center=(float(trunk[0]), float(trunk[1]))))
    s, _ = plane.sky_plane(sky.sun_direction)
    layers = grove_layers(grove_in_frame(grove, plane), FlutterParams(), args.frame, distances=(3.0,),
                          sun=s)
    radiance = world_radiance(sky, ground_radiance(0.2, sky.sky_irradiance + sun_irradiance(sky)))
    window = Grid.from_window((-2.0, 0.0, 2.0, 3.0), 0.02)
    sun_window = Grid.from_window((-2.0, 0.0, 2.0, 3.0), 0.003)
    light = receiver_light(radiance, sky, plane, window, layers, sun_window=sun_window, workers=2)
    assert light.total is not None
    open_wall = light.sky_unshadowed + light.sun_unshadowed
    picture = srgb(0.85 * light.total / open_wall[1]).transpose(1, 2, 0)
    write_png(args.out, picture)
    y = np.tensordot(REC709_LUMINANCE, light.total, axes=1)
    p5, p95 = np.percentile(y, [5, 95])
    sky_y, sun_y = light.sky_unshadowed @ REC709_LUMINANCE, light.sun_unshadowed @ REC709_LUMINANCE
    print(f"sun {args.elevation:g} deg: the open wall's sky {sky_y:.2f} klx, sun {sun_y:.2f} klx, "
          f"(sun + sky) / sky {(sun_y + sky_y) / sky_y:.2f}; the raster's p95/p5 {p95 / p5:.2f}, "
          f"min {y.min():.2f} max {y.max():.2f} klx; {sun_window.shape} pixels in {time.perf_counter() - start:.1f} s "
          f"-> {args.out}")


if __name__ == "__main__":
    main()
