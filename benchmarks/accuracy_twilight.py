"""Low sun and civil twilight: the procedural sky's open-ground light against the USNO curve, and
the overcast types' colour.

1. For the sun at 10 down to -6 degrees, each degree, and Linke turbidity 2, 3 and 4.5: the
   horizontal illuminance of open ground (the sky integrated by its quadrature plus the sun's
   E_n cos(zenith)) beside the sun illuminance curve of Janiczek & DeYoung (1987, USNO
   Circular 171), their ratio, and what pvlib's Ineichen clear sky with the Perez et al. (1990)
   efficacies alone gives (the model above 10 degrees).
2. The largest change of the modelled light between neighbouring tenths of a degree, -6 to 10
   degrees, and the curve's own there.
3. The whole sky's chromaticity xy (sun left out) of each CIE type, sun at 30 degrees, TL 3,
   beside D65 and D75 of the CIE 15 table.

    python benchmarks/accuracy_twilight.py
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.colour import REC709_LUMINANCE, XYZ_TO_REC709  # noqa: E402
from pipeline.daylight import clear_daylight, sky_daylight, usno_illuminance  # noqa: E402
from pipeline.sky import ProceduralSky  # noqa: E402
from pipeline.sun_disc import SunDisc  # noqa: E402

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
    head = "  h [deg]   USNO [lx]" + "".join(f" | TL {t:g}: model [lx] ratio  I-P [lx]" for t in TURBIDITIES)
    print(head)
    for h in range(10, -7, -1):
        usno = float(usno_illuminance(h))
        row = f"  {h:7d} {usno:11.1f}"
        for t in TURBIDITIES:
            model = open_ground(h, t)
            row += f" | {model:16.1f} {model / usno:5.2f} {ineichen_perez(h, t):9.1f}"
        print(row)
    tenths = np.arange(-60, 101) / 10.0
    curve = np.diff(np.log(usno_illuminance(tenths)))
    print("\nlargest change between neighbouring tenths, -6 to 10 degrees (model; curve's own):")
    for t in TURBIDITIES:
        steps = np.diff(np.log([global_lux(h, t) for h in tenths]))
        i = int(np.argmax(np.abs(steps)))
        upper = tenths[:-1] >= -3.3
        j = int(np.argmax(np.abs(np.where(upper, steps, 0.0))))
        print(f"  TL {t:g}: {np.expm1(abs(steps[i])):.3f} at {tenths[i]:+.1f} (curve {np.expm1(abs(curve[i])):.3f}); "
              f"above -3.3: {np.expm1(abs(steps[j])):.3f} at {tenths[j]:+.1f}; most beyond the curve's own: "
              f"{np.expm1(np.max(np.abs(steps - curve))):.4f}")
    print("\nwhole-sky chromaticity, sun 30 degrees, TL 3 (CIE 15: D65 0.3127 0.3290, D75 0.2990 0.3149):")
    for cie_type in range(1, 16):
        x, y = xy(ProceduralSky(3.0, SunDisc(np.radians(200.0), np.radians(30.0)),
                                cie_type=cie_type).clear_sky_irradiance)
        print(f"  type {cie_type:2d}: x {x:.4f} y {y:.4f}")


if __name__ == "__main__":
    main()
