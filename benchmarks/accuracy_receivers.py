"""The low sun on walls and slopes: the most a fleck can stand above the shade, (sun + sky) / sky, on
an open receiver (docs/method.md, "Receivers: walls and slopes"; issue 44).

For the clear procedural sky (turbidity 3, CIE default type) with the sun at each elevation, each
receiver's sky light is its hemisphere's (the sky above the horizon, the open ground's radiance
albedo x (sky + sun) / pi below it) and its sun light the two-scale sun's kernel sum at its own
incidence. Luminance (Rec.709 Y) of each. Then one shadowed case: a sun-facing wall behind a grille
at a 10-degree sun, its p95 / p5 against the bound; and the time of the receiver's hemisphere
raster against the procedural sky's own raster on the same sky-plane grid (medians of --repeat,
paired in this run).

    python benchmarks/accuracy_receivers.py [--albedo 0.2] [--repeat 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import Grid
from pipeline.ground.shadow import plan_isolated
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, hemisphere_raster, world_radiance
from pipeline.receivers.layers import mask_layer
from pipeline.receivers.light import covering_alpha, receiver_light
from pipeline.receivers.plane import level_ground, slope, wall
from pipeline.receivers.sun import receiver_sun_irradiance, sun_incidence
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc
from pipeline.sky.sun_kernel import sun_irradiance

DEG = np.pi / 180
SUN_AZIMUTH = 250 * DEG  # a western evening sun


def bound(sky: ProceduralSky, plane, albedo: float) -> tuple[float, float, float]:
    """(sun klx, sky klx, (sun + sky) / sky) on the open receiver, luminance."""
    radiance = world_radiance(sky, ground_radiance(albedo, sky.sky_irradiance + sun_irradiance(sky)))
    e_sky = float(hemisphere_irradiance(radiance, plane) @ REC709_LUMINANCE)
    e_sun = float(receiver_sun_irradiance(sky, plane) @ REC709_LUMINANCE)
    return e_sun, e_sky, (e_sun + e_sky) / e_sky


def grille(n=60, bars=6):
    t = np.ones((n, n), np.float32)
    t[:, ::bars] = 0.0
    t[::bars, :] = 0.0
    return t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--albedo", type=float, default=0.2, help="the open ground's albedo below the horizon")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(f"clear sky, turbidity 3, sun azimuth {np.degrees(SUN_AZIMUTH):.0f}, ground albedo {args.albedo}")
    print(f"{'sun elev':>8} {'receiver':<34} {'cos(inc)':>8} {'sun klx':>8} {'sky klx':>8} {'(sun+sky)/sky':>14}")
    cases = []
    for elevation in (5, 10, 15):
        cases += [(elevation, "level ground", level_ground()),
                  (elevation, "wall facing the sun", wall((0, 0, 0), facing=SUN_AZIMUTH, width=4, height=3)),
                  (elevation, "wall facing 45 deg off the sun",
                   wall((0, 0, 0), facing=SUN_AZIMUTH - 45 * DEG, width=4, height=3)),
                  (elevation, "hillside 15 deg facing the sun", slope(tilt=15 * DEG, facing=SUN_AZIMUTH)),
                  (elevation, "hillside 30 deg facing the sun", slope(tilt=30 * DEG, facing=SUN_AZIMUTH)),
                  (elevation, "hillside 40 deg facing the sun", slope(tilt=40 * DEG, facing=SUN_AZIMUTH))]
    for elevation, name, plane in cases:
        sky = ProceduralSky(3.0, SunDisc(SUN_AZIMUTH, elevation * DEG))
        e_sun, e_sky, ratio = bound(sky, plane, args.albedo)
        print(f"{elevation:>8} {name:<34} {sun_incidence(sky, plane):8.3f} {e_sun:8.2f} {e_sky:8.2f} {ratio:14.2f}")
    # a sun-facing wall behind a grille at a 10-degree sun: p95 / p5 against the bound, and the time
    sky = ProceduralSky(3.0, SunDisc(SUN_AZIMUTH, 10 * DEG))
    plane = wall((0, 0, 0), facing=SUN_AZIMUTH, width=4, height=3)
    radiance = world_radiance(sky, ground_radiance(args.albedo, sky.sky_irradiance + sun_irradiance(sky)))
    layer = mask_layer(grille(), center=(0.0, 1.5), size=(3.0, 3.0), distance=0.5)
    window = Grid.from_window((-0.5, 1.0, 0.5, 2.0), 0.01)
    sun_window = Grid.from_window((-0.25, 1.25, 0.25, 1.75), 0.0005)
    wall_light = receiver_light(radiance, sky, plane, window, [layer], sun_window=sun_window)
    y = np.tensordot(REC709_LUMINANCE, wall_light.total, axes=1)
    p5, p95 = np.percentile(y, [5, 95])
    most = float((wall_light.sky_unshadowed + wall_light.sun_unshadowed) @ REC709_LUMINANCE
                 / (wall_light.sky_unshadowed @ REC709_LUMINANCE))
    print(f"wall behind a grille (bars 5 cm every 30 cm, 0.5 m out), 10-degree sun: p95/p5 {p95 / p5:.2f}, "
          f"bound {most:.2f}, {p95 / p5 / most:.0%} of it (the bars hide sky from the shade too)")
    # the cost of the receiver's hemisphere raster against the sky's own raster on the same grid (level ground)
    _, cells = layer.occlusion_on(window)
    grid = plan_isolated(window, cells, height=layer.distance, alpha=covering_alpha(window, cells, 0.5)).sky
    timings: dict[str, list[float]] = {"ProceduralSky.raster": [], "hemisphere_raster, level": [],
                                       "hemisphere_raster, wall": []}
    for i in range(args.repeat):  # a sky moved by a nano-radian each time: nothing kept from the last
        fresh = ProceduralSky(3.0, SunDisc(SUN_AZIMUTH + 1e-9 * (i + 1), 10 * DEG))
        light = world_radiance(fresh, ground_radiance(args.albedo, sky.sky_irradiance + sun_irradiance(sky)))
        for name, make in (("ProceduralSky.raster", lambda: fresh.raster(grid)),
                           ("hemisphere_raster, level", lambda: hemisphere_raster(light, level_ground(), grid)),
                           ("hemisphere_raster, wall", lambda: hemisphere_raster(light, plane, grid))):
            start = time.perf_counter()
            make()
            timings[name].append(time.perf_counter() - start)
    base = float(np.median(timings["ProceduralSky.raster"]))
    for name, values in timings.items():
        print(f"{name:<26} {grid.shape} cells: {np.median(values) * 1e3:7.1f} ms (median of {args.repeat}), "
              f"{np.median(values) / base:.2f} x the sky's raster")


if __name__ == "__main__":
    main()
