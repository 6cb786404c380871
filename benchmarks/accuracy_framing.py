"""Figures of the automatic framing and of auto exposure (docs/accuracy.md, "Framing and auto
exposure"), with the scenes of tests/test_framing.py:

- per site (sun at about 65, 29 and 12 degrees), the 95th/5th percentile ratio of the ground's
  luminance in the frame, beside the most the sun and sky of that moment allow between open sun
  and open shade;
- the eclipse frame's shift against the uncut sun, measured and predicted (pixels);
- the mean display value of the Dallas frames with its auto exposure and with the fixed 1.5
  stops it had.

    python benchmarks/accuracy_framing.py
"""

import importlib.util
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.cache.store import Cache
from pipeline.camera import composite
from pipeline.camera import pinhole as camera
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.stages.frame import render_frame
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load
from pipeline.stages.scene import load_sky

spec = importlib.util.spec_from_file_location("test_framing", ROOT / "tests" / "test_framing.py")
scenes = importlib.util.module_from_spec(spec)
spec.loader.exec_module(scenes)


def main():
    folder = Path(tempfile.mkdtemp(prefix="framing-"))
    try:
        report(folder)
    finally:  # nothing left behind
        shutil.rmtree(folder, ignore_errors=True)


def report(folder: Path) -> None:
    """Print the figures, the scenes' configs and cache in ``folder``."""
    store = Cache(folder / "cache")
    for site in scenes.SITES:
        config = load(scenes.write(folder, scenes.dapple_scene(site), f"{site}.yaml"))
        plan = plan_run(config)
        result = render_frame(plan, store=store)
        *_, ground_fraction = camera.ground_hits(plan.camera)
        ground = (result.radiance @ REC709_LUMINANCE)[ground_fraction >= 1.0]
        p95, p5 = np.percentile(ground, [95, 5])
        sky = load_sky(config.sky, result.scene)
        open_ground = sky.sky_irradiance + result.sun_fraction * sky.undimmed_sun_irradiance()
        possible = float(open_ground @ REC709_LUMINANCE) / float(sky.sky_irradiance @ REC709_LUMINANCE)
        print(f"{site}: sun {np.degrees(result.scene.sun.elevation):.1f} deg, S {result.sun_fraction:.3f}, "
              f"p95/p5 {p95 / p5:.2f}, open sun / open shade {possible:.2f}; camera "
              f"{tuple(round(v, 2) for v in plan.camera.position)}, pitch {np.degrees(plan.camera.pitch):.0f}")

    measured, predicted = scenes.crescent_shift(folder)
    print(f"dallas-eclipse crescent shift against the uncut sun: measured {np.round(measured, 2)} px, "
          f"predicted {np.round(predicted, 2)} px (columns, rows)")

    config = yaml.safe_load((ROOT / "configs" / "eclipse-2024-dallas.yaml").read_text())
    config["canopy"]["flutter"]["cycle"] = 1
    config["camera"]["resolution"] = [160, 90]
    config["ground"]["albedo"] = str(ROOT / "configs" / "assets" / "sand.png")
    config["render"] = {"sun_cells": 6}
    auto = load(scenes.write(folder, config, "dallas.yaml"))
    fixed = load(scenes.write(folder, dict(config, camera=dict(config["camera"], exposure=1.5)),
                                     "fixed.yaml"))
    plan = plan_run(auto)
    for frame in (0, 80, 160, 200, 225, 232, 236, 237, 238):
        a = render_frame(plan, frame, store=store)
        b = render_frame(plan_run(fixed), frame, store=store)
        print(f"dallas frame {frame} ({a.scene.when:%H:%M:%S} UTC, S {a.sun_fraction:.4f}): mean display "
              f"auto {composite.display(a.radiance, exposure=a.exposure).mean():.3f}, fixed 1.5 stops "
              f"{composite.display(b.radiance, exposure=b.exposure).mean():.3f}")


if __name__ == "__main__":
    main()
