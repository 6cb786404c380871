"""One layer or four: how Max's product rule over several layers darkens the shade of one crown,
on a wall and on the level ground alike (docs/accuracy.md, "Receivers: walls and slopes").

    python benchmarks/accuracy_receiver_layers.py

One tree (crown radius 1.6 m at 2.6 m, 9000 leaves), clear procedural sky (turbidity 3). Cases: a
wall facing a 12-degree sun with the tree 3 m in front of it, and the level ground under a 40- and
a 12-degree sun. Each is lit through the crown drawn into one layer (at its middle) and into four
layers, each holding about a quarter of the leaves (the wall: 1.8, 2.6, 3.4 and 4.2 m out; the
ground: 2.26, 2.44, 2.69 and 2.92 m up, the crown being flat), by the same code path
(``receivers.light``; for the level ground it is ``ground.shadow``'s, tests/test_receivers.py).
Printed, over the deep shade (the pixels where the one-layer sun is hidden): the median light as
the pipeline combines it (the sky's light and the sun's each by the product rule,
``ground.layers.combine_lights``; before, the rule on their sum), the sky's part alone by its own
product, and sun and sky each by its own product, computed here; by how many of the four
layers hide the sun; and the sun's transmittance with one layer against the product of four
(the layers' masks against the one layer's: a layer drawing leaves of another would darken it).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.canopy.grove import FlutterParams, GroveParams, grow_grove
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import Grid
from pipeline.ground.shadow import resample_bilinear
from pipeline.receivers.hemisphere import ground_radiance, world_radiance
from pipeline.receivers.layers import grove_in_frame, grove_layers
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import level_ground, wall
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc
from pipeline.sky.sun_kernel import sun_irradiance

DEG = np.pi / 180
TREE = dict(count=1, crown_radius=1.6, leaves_per_tree=9000, leaf_length=0.09, leaves_per_cluster=30, height=2.6)


def luminance(a: np.ndarray) -> np.ndarray:
    return np.tensordot(REC709_LUMINANCE, a, axes=1)


def split(plane, grove, sky, distances, window, sun_window):
    """The light through the layers at ``distances``: as combined, and each layer's sky and sun parts."""
    radiance = world_radiance(sky, ground_radiance(0.2, sky.sky_irradiance + sun_irradiance(sky)))
    s, _ = plane.sky_plane(sky.sun_direction)
    layers = grove_layers(grove_in_frame(grove, plane), FlutterParams(), 0, distances=distances, sun=s)
    combined = receiver_light(radiance, sky, plane, window, layers, sun_window=sun_window, workers=2)
    each = [receiver_light(radiance, sky, plane, window, [layer], sun_window=sun_window, workers=2)
            for layer in layers]
    skies = [resample_bilinear(e.sky, window, sun_window) for e in each]
    suns = [e.total - s for e, s in zip(each, skies)]
    return combined, skies, suns, [int(layer.select[0].sum()) for layer in layers]


def case(name, plane, grove, sky, one, four, window, sun_window):
    results = {}
    for label, distances in (("1", one), ("4", four)):
        combined, skies, suns, counts = split(plane, grove, sky, distances, window, sun_window)
        S = combined.sky_unshadowed[:, None, None]
        U = combined.sun_unshadowed[:, None, None]
        sky_part = S * np.prod([s / S for s in skies], axis=0)
        sun_part = U * np.prod([s / U for s in suns], axis=0)
        open_sun = float(luminance(combined.sun_unshadowed))
        results[label] = dict(total=luminance(combined.total), sky=luminance(sky_part),
                              both=luminance(sky_part) + luminance(sun_part),
                              sun_t=luminance(sun_part) / open_sun, counts=counts,
                              hidden=np.sum([luminance(s) / open_sun < 0.02 for s in suns], axis=0),
                              S=float(luminance(combined.sky_unshadowed)), U=open_sun)
    shade = results["1"]["sun_t"] < 0.02
    r1, r4 = results["1"], results["4"]
    print(f"{name}: open sky {r1['S']:.2f} klx, open sun {r1['U']:.2f} klx, (S / (S + U))^3 = "
          f"{(r1['S'] / (r1['S'] + r1['U'])) ** 3:.4f}; deep shade {shade.mean():.1%} of the window")
    for label, r in results.items():
        print(f"  {label} layer(s), leaves {r['counts']}: shade median {np.median(r['total'][shade]):6.3f} klx "
              f"(sky alone {np.median(r['sky'][shade]):.3f}, sun and sky by their own products "
              f"{np.median(r['both'][shade]):.3f}); window min {r['total'].min():.3f}")
    for n in range(5):
        where = r4["hidden"][shade] == n
        if where.any():
            print(f"    {n} of 4 layers hide the sun: {where.mean():4.0%} of the deep shade, 4-layer median "
                  f"{np.median(r4['total'][shade][where]):6.3f} klx (by their own products "
                  f"{np.median(r4['both'][shade][where]):.3f})")
    print(f"  sun transmittance, 1 layer against the product of 4: mean |difference| "
          f"{np.abs(r1['sun_t'] - r4['sun_t']).mean():.4f} (means {r1['sun_t'].mean():.4f}, {r4['sun_t'].mean():.4f})")


def main() -> None:
    start = time.perf_counter()
    azimuth = 250 * DEG
    plane = wall((0.0, 0.0, 0.0), facing=azimuth, width=4.0, height=3.0)
    trunk = 3.0 * plane.normal[:2] + 0.3 * plane.across[:2]
    grove = grow_grove(GroveParams(**TREE, center=(float(trunk[0]), float(trunk[1]))))
    case("wall facing a 12-degree sun", plane, grove, ProceduralSky(3.0, SunDisc(azimuth, 12 * DEG)), (3.0,),
         (1.8, 2.6, 3.4, 4.2), Grid.from_window((-2.0, 0.0, 2.0, 3.0), 0.02),
         Grid.from_window((-2.0, 0.0, 2.0, 3.0), 0.01))
    grove = grow_grove(GroveParams(**TREE, center=(0.0, 0.0)))
    for elevation, half in ((40, 4.0), (12, 9.0)):
        x = 2.6 / np.tan(elevation * DEG)  # the crown's shadow, east of the tree
        case(f"level ground, a {elevation}-degree sun in the west", level_ground(), grove,
             ProceduralSky(3.0, SunDisc(270 * DEG, elevation * DEG)), (2.6,), (2.26, 2.44, 2.69, 2.92),
             Grid.from_window((x - half, -2.5, x + half, 2.5), 0.04),
             Grid.from_window((x - half, -2.5, x + half, 2.5), 0.01))
    print(f"{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
