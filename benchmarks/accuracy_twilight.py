"""Low sun and civil twilight: the procedural sky's open-ground light against the USNO curve, and
the overcast types' colour.

1. For the sun at 10 down to -6 degrees, each degree, and Linke turbidity 2, 3 and 4.5: the
   horizontal illuminance of open ground (the sky integrated by its quadrature plus the sun's
   E_n cos(zenith)) beside the sun illuminance curve of Janiczek & DeYoung (1987, USNO
   Circular 171), that curve with its fall capped (``daylight.twilight_illuminance``), the
   model's ratio to the USNO curve, and what pvlib's Ineichen clear sky with the Perez et al.
   (1990) efficacies alone gives (the model above 10 degrees).
2. The smallest ratio of the modelled light at a tenth of a degree to its neighbour's above, -6
   to 10 degrees (issue 31 asks at least 0.9), and the USNO curve's own.
3. The whole sky's chromaticity xy (sun left out) of each CIE type, sun at 30 degrees, TL 3,
   beside D65 and D75 of the CIE 15 table.
4. The twilight sky's colour (CIE type 12, TL 3, ``clearsky.relative_sky``): xy of the zenith, of
   the horizon under the sun (2 degrees up) and opposite it (2, 5, 12 and 20 degrees up), sun
   at 0 down to -6 degrees.

    python benchmarks/accuracy_twilight.py
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.core.colour import REC709_LUMINANCE, XYZ_TO_REC709
from pipeline.sky.clearsky import relative_sky
from pipeline.sky.daylight import clear_daylight, sky_daylight, twilight_illuminance, usno_illuminance
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc

TURBIDITIES = (2.0, 3.0, 4.5)


def open_ground(h: float, turbidity: float) -> float:
    sky = ProceduralSky(turbidity, SunDisc(np.radians(250.0), np.radians(h)))
    return 1000.0 * float((sky.sky_irradiance + sky.undimmed_sun_irradiance()) @ REC709_LUMINANCE)


def ineichen_perez(h: float, turbidity: float) -> float:
    if h <= 0:
        return 0.0
    d = clear_daylight(np.radians(90.0 - h), turbidity)
    return 1000.0 * (d.direct_normal_illuminance * np.sin(np.radians(h)) + d.diffuse_horizontal_illuminance)


def global_lux(h: float, turbidity: float) -> float:
    d = sky_daylight(np.radians(h), turbidity)
    return 1000.0 * (d.direct_normal_illuminance * max(np.sin(np.radians(h)), 0.0) + d.diffuse_horizontal_illuminance)


def xy(rgb) -> np.ndarray:
    X, Y, Z = np.linalg.solve(XYZ_TO_REC709, np.asarray(rgb, dtype=np.float64))
    return np.array([X, Y]) / (X + Y + Z)


def main() -> None:
    warnings.simplefilter("ignore")  # pvlib's divisions at the horizon
    head = "  h [deg]   USNO [lx] capped [lx]"
    head += "".join(f" | TL {t:g}: model [lx] ratio  I-P [lx]" for t in TURBIDITIES)
    print(head)
    for h in range(10, -7, -1):
        usno = float(usno_illuminance(h))
        row = f"  {h:7d} {usno:11.1f} {float(twilight_illuminance(h)):12.1f}"
        for t in TURBIDITIES:
            model = open_ground(h, t)
            row += f" | {model:16.1f} {model / usno:5.2f} {ineichen_perez(h, t):9.1f}"
        print(row)
    tenths = np.arange(-60, 101) / 10.0
    curve = usno_illuminance(tenths)
    print("\nsmallest ratio of a tenth of a degree's light to its neighbour's above, -6 to 10 degrees:")
    for t in TURBIDITIES:
        light = np.array([global_lux(h, t) for h in tenths])
        ratio = light[:-1] / light[1:]
        i = int(np.argmin(ratio))
        print(f"  TL {t:g}: {ratio[i]:.4f} at {tenths[i]:+.1f} (the USNO curve: {np.min(curve[:-1] / curve[1:]):.4f} "
              f"at {tenths[int(np.argmin(curve[:-1] / curve[1:]))]:+.1f})")
    print("\nwhole-sky chromaticity, sun 30 degrees, TL 3 (CIE 15: D65 0.3127 0.3290, D75 0.2990 0.3149):")
    for cie_type in range(1, 16):
        x, y = xy(ProceduralSky(3.0, SunDisc(np.radians(200.0), np.radians(30.0)),
                                cie_type=cie_type).clear_sky_irradiance)
        print(f"  type {cie_type:2d}: x {x:.4f} y {y:.4f}")
    print("\ntwilight sky xy, CIE type 12, TL 3 (elevation, azimuth from the sun's) [deg]:")
    views = ((90.0, 0.0), (2.0, 0.0), (2.0, 180.0), (5.0, 180.0), (12.0, 180.0), (20.0, 180.0))
    print("  sun [deg] " + "".join(f" | ({e:g}, {a:g})   " for e, a in views))
    for h in (0.0, -1.0, -2.0, -3.0, -4.0, -5.0, -6.0):
        row = f"  {h:9.1f} "
        for e, a in views:
            ev, av, hs = np.radians([e, a, h])
            view = np.array([np.cos(ev) * np.cos(av), np.cos(ev) * np.sin(av), np.sin(ev)])
            gamma = np.arccos(np.clip(view @ np.array([np.cos(hs), 0.0, np.sin(hs)]), -1.0, 1.0))
            x, y = xy(relative_sky(np.sin(ev), gamma, sun_zenith=np.pi / 2 - hs, turbidity=3.0, cie_type=12))
            row += f" | {x:.3f} {y:.3f}"
        print(row)


if __name__ == "__main__":
    main()
