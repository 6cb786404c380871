"""Daylight in absolute units: the clear sky's light against the standard clear-sky models, and
what it does to the shade of configs/eclipse.yaml.

1. For turbidity 2..6 and the sun at 5..90 degrees (sea level): the sky's direct horizontal
   illuminance (its sun kernel summed) and diffuse horizontal illuminance (its radiance
   integrated over the hemisphere, midpoint rule in theta and phi, 256 x 512) over pvlib's Ineichen
   clear sky turned into klx by ladybug-core's Perez et al. (1990) efficacies (W = 2 cm).
2. The default CIE type: each clear type's shape (11 to 15) against the Perez et al. (1993)
   all-weather sky of the same Ineichen irradiances (its clearness and brightness), both scaled
   to the same diffuse illuminance: the RMS of ln(L_cie / L_perez), weighted by cos(Z) d_omega,
   over TL 2..6 and the sun at 15..75 degrees.
3. Each shipped config's clear light at its middle frame (no cloud, no moon): direct and
   diffuse horizontal illuminance and their fleck-to-shade ratio (sun + sky) / sky, the
   contrast between open sunlit ground and ground that sees the whole sky but not the sun.
4. The ground of configs/eclipse.yaml at --frame (0), rendered by ``sunshade ground`` of the
   checkout at --root: the fleck-to-shade contrast (99.9th over 10th percentile of the ground's
   illuminance, Rec.709 luminance, over the sun window) and the mean colour of the shade (the
   pixels at or below the 10th percentile, RGB over their luminance).

    python benchmarks/accuracy_daylight.py [--root CHECKOUT] [--frame N] [--skip-table] [--skip-types] [--skip-configs]

Needs pvlib and ladybug-core (pip install -e '.[test]').
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
LUMA = np.array([0.2126, 0.7152, 0.0722])


def table() -> None:
    from test_sky import hemisphere_irradiance, reference_daylight

    from pipeline.sky.procedural import ProceduralSky
    from pipeline.sky.sun_disc import SunDisc
    from pipeline.sky.sun_kernel import sun_irradiance

    elevations = (5.0, 15.0, 30.0, 60.0, 90.0)
    print("| turbidity | sun elevation | direct horizontal, ratio | diffuse horizontal, ratio | diffuse klx (ref) |")
    print("|---|---|---|---|---|")
    for turbidity in (2.0, 3.0, 4.0, 5.0, 6.0):
        direct, diffuse, levels = [], [], []
        for elevation in elevations:
            sky = ProceduralSky(turbidity, SunDisc(np.radians(200.0), np.radians(elevation)))
            ref_direct, ref_diffuse = reference_daylight(elevation, turbidity, 0.0)
            direct.append(sun_irradiance(sky) @ LUMA / ref_direct)
            got = hemisphere_irradiance(sky.radiance, 256, 512) @ LUMA
            diffuse.append(got / ref_diffuse)
            levels.append(f"{got:.1f} ({ref_diffuse:.1f})")
        print(f"| {turbidity:g} | {' / '.join(f'{e:g}' for e in elevations)} deg "
              f"| {' / '.join(f'{r:.3f}' for r in direct)} | {' / '.join(f'{r:.3f}' for r in diffuse)} "
              f"| {' / '.join(levels)} |")


# Perez, Seals & Michalsky 1993, "All-weather model for sky luminance distribution", Solar Energy
# 50(3), 235-245, Table 1: for the clearness bins 6 (2.8-4.5), 7 (4.5-6.2) and 8 (> 6.2), the
# coefficients (x1, x2, x3, x4) of each of a..e = x1 + x2 Z + Delta (x3 + x4 Z).
PEREZ_1993 = {
    6: [(-1.0156, -0.3670, 1.0078, 1.4051), (0.2875, -0.5328, -3.8500, 3.3750), (14.0000, -0.9999, -7.1406, 7.5469),
        (-3.4000, -0.1078, -1.0750, 1.5702), (-0.0672, 0.4016, 0.3017, -0.4844)],
    7: [(-1.0000, 0.0211, 0.5025, -0.5119), (-0.3000, 0.1922, 0.7023, -1.6317), (19.0000, -5.0000, 1.2438, -1.9094),
        (-4.0000, 0.0250, 0.3844, 0.2656), (1.0468, -0.3788, -2.4517, 1.4656)],
    8: [(-1.0500, 0.0289, 0.4260, 0.3590), (-0.3250, 0.1156, 0.7781, 0.0025), (31.0625, -14.5000, -46.1148, 55.3750),
        (-7.2312, 0.4050, 13.3500, 0.6234), (1.5000, -0.6426, 1.8564, 0.5636)],
}


def cie_types() -> None:
    from pvlib import atmosphere

    from pipeline.sky.clearsky import cie_relative_luminance
    from pipeline.sky.daylight import clear_daylight, perez_efficacy

    n_z, n_a = 90, 180
    zenith = (np.arange(n_z) + 0.5) * (np.pi / 2 / n_z)
    azimuth = (np.arange(n_a) + 0.5) * (2 * np.pi / n_a)
    weight = (np.cos(zenith) * np.sin(zenith))[:, None] * np.ones(n_a)
    rms = {t: [] for t in range(11, 16)}
    for turbidity in (2.0, 3.0, 4.0, 5.0, 6.0):
        for elevation in (15.0, 30.0, 45.0, 60.0, 75.0):
            zs = np.radians(90.0 - elevation)
            light = clear_daylight(zs, turbidity)
            eff = perez_efficacy(zs, light.direct_normal_irradiance, light.diffuse_horizontal_irradiance,
                                 relative_airmass=float(atmosphere.get_relative_airmass(90.0 - elevation,
                                                                                        "kasten1966")))
            clearness, brightness = float(eff.clearness), float(eff.brightness)
            bin_ = 8 if clearness >= 6.2 else 7 if clearness >= 4.5 else 6
            a, b, c, d, e = (x1 + x2 * zs + brightness * (x3 + x4 * zs) for x1, x2, x3, x4 in PEREZ_1993[bin_])
            cos_gamma = (np.cos(zs) * np.cos(zenith)[:, None]
                         + np.sin(zs) * np.sin(zenith)[:, None] * np.cos(azimuth - np.pi)[None, :])
            gamma = np.arccos(np.clip(cos_gamma, -1, 1))
            perez = (1 + a * np.exp(b / np.cos(zenith)))[:, None] * (1 + c * np.exp(d * gamma) + e * cos_gamma**2)
            perez /= (perez * weight).sum()
            for t in rms:
                cie = cie_relative_luminance(np.cos(zenith)[:, None], gamma, sun_zenith=zs, cie_type=t)
                cie /= (cie * weight).sum()
                rms[t].append(np.sqrt((np.log(cie / perez) ** 2 * weight).sum() / weight.sum()))
    print("CIE type against the Perez (1993) all-weather sky of the same clear-sky irradiances, "
          "RMS of ln(L_cie / L_perez) over TL 2..6 and sun 15..75 deg (median, worst):")
    for t, values in rms.items():
        print(f"  type {t}: {np.median(values):.3f}, {np.max(values):.3f}")


def configs() -> None:
    from pipeline.stages.lighting import reference_lighting
    from pipeline.stages.plan import plan_run
    from pipeline.stages.resolve import load

    print("| config | sun elevation | direct horizontal klx | diffuse klx | (sun + sky) / sky |")
    print("|---|---|---|---|---|")
    for path in sorted((ROOT / "configs").glob("*.yaml")):
        config = load(path)
        if config.sky.model not in ("cie", "preetham"):
            continue
        light = reference_lighting(plan_run(config))
        direct = light.sun_irradiance * light.sun_direction[2] @ LUMA
        diffuse = light.sky_irradiance @ LUMA
        elevation = np.degrees(np.arcsin(light.sun_direction[2]))
        ratio = f"{(direct + diffuse) / diffuse:.1f}" if diffuse > 0 else "no sky light"
        print(f"| {path.name} | {elevation:.1f} | {direct:.1f} | {diffuse:.1f} | {ratio} |")


def shade(root: Path, frame: int) -> None:
    import OpenImageIO as oiio

    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "ground.exr"
        env = dict(os.environ, PYTHONPATH=str(root), SUNSHADE_CACHE=str(Path(folder) / "cache"))
        subprocess.run([sys.executable, "-m", "pipeline.cli", "ground", str(root / "configs/eclipse.yaml"),
                        "--frame", str(frame), "-o", str(out)], check=True, env=env, cwd=root,
                       stdout=subprocess.DEVNULL)
        image = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)
    luminance = image @ LUMA
    low, high = np.percentile(luminance, [10.0, 99.9])
    dark = image[luminance <= low]
    colour = dark.mean(axis=0) / (dark.mean(axis=0) @ LUMA)
    print(f"configs/eclipse.yaml frame {frame} ({root}): ground {image.shape[1]} x {image.shape[0]} px; "
          f"shade (10th percentile) {low:.2f} klx, flecks (99.9th) {high:.2f} klx, contrast {high / low:.2f}; "
          f"mean shade colour RGB / luminance = ({colour[0]:.3f}, {colour[1]:.3f}, {colour[2]:.3f}), "
          f"B/R {colour[2] / colour[0]:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout whose sunshade renders the ground")
    parser.add_argument("--frame", type=int, default=0)
    parser.add_argument("--skip-table", action="store_true")
    parser.add_argument("--skip-types", action="store_true")
    parser.add_argument("--skip-configs", action="store_true")
    args = parser.parse_args()
    if not args.skip_table:
        table()
    if not args.skip_types:
        cie_types()
    if not args.skip_configs:
        configs()
    shade(args.root.resolve(), args.frame)


if __name__ == "__main__":
    main()
