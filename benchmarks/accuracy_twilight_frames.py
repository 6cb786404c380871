"""Frames through sunset into civil twilight: the ground the renderer makes, frame by frame.

One tree 6 m high (5000 leaves), Madrid (40.42 N, 3.70 W) on 2026-08-13 from 18:50 to 19:44
UTC, 12 frames: the sun from about 4 degrees to -6. Per frame: the sun's elevation, the band it
falls in (docs/method.md, "Twilight and a sun at the horizon": shadow, unshadowed, set), the
open ground's light the ground stage gives (the raster's unshadowed total, Rec.709 luminance)
beside the clear sky's global horizontal illuminance of ``daylight.sky_daylight`` (diffuse +
direct normal x sin(h), an independent sum), the mean and the 5th / 95th percentiles of the
ground raster's light, and whether any value is not finite.

    python benchmarks/accuracy_twilight_frames.py [--cache DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.cache.store import Cache
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky import daylight
from pipeline.stages.ground import render_ground
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load
from pipeline.stages.scene import sun_lights, sun_shades


def config(folder: Path) -> Path:
    io.write_png(folder / "grey.png", np.full((4, 4, 3), 0.5, np.float32))
    scene = {
        "canopy": {"height": 6.0, "trees": {"count": 1, "seed": 7, "crown_radius": 3.0,
                                            "leaves_per_tree": 5000, "leaf_length": 0.10},
                   "flutter": {"cycle": 1}},
        "sky": {"site": {"latitude": 40.42, "longitude": -3.70},
                "time": {"start": "2026-08-13T18:50:00Z", "end": "2026-08-13T19:44:00Z"}},
        "ground": {"pixel": 0.1, "albedo": "grey.png"},
        "render": {"sun_cells": 8},
        "camera": {"resolution": [160, 90], "exposure": "auto"},
        "foreground": {"model": "none"},
        "animation": {"frames": 12},
    }
    path = folder / "twilight.yaml"
    path.write_text(yaml.safe_dump(scene))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        plan = plan_run(load(config(Path(tmp))))
        store = Cache(args.cache or Path(tmp) / "cache")
        print(f"plan: window {[round(v, 1) for v in plan.window.extent]} m, sun window "
              f"{None if plan.sun_window is None else [round(v, 1) for v in plan.sun_window.extent]} m")
        print(" frame  sun [deg]  band        open [lx]  reference [lx]  ratio   mean [lx]  p5 [lx]  p95 [lx]  finite")
        for f, scene in enumerate(plan.scenes):
            sun = scene.sun
            band = "shadow" if sun_shades(sun) else "unshadowed" if sun_lights(sun) else "set"
            ground = render_ground(plan, f, store=store)
            light = 1000.0 * (ground.irradiance @ REC709_LUMINANCE)
            clear = daylight.sky_daylight(sun.elevation, plan.sky.config.turbidity, sun_radius=sun.angular_radius)
            reference = 1000.0 * (clear.diffuse_horizontal_illuminance + clear.direct_normal_illuminance
                                  * max(np.sin(sun.elevation), 0.0))
            open_ground = 1000.0 * float(ground.unshadowed @ REC709_LUMINANCE)
            p5, p95 = np.percentile(light, [5, 95])
            print(f"{f:6d}  {np.degrees(sun.elevation):9.2f}  {band:10s}  {open_ground:9.1f}  {reference:14.1f}  "
                  f"{open_ground / reference:5.3f}  {light.mean():9.1f}  {p5:7.1f}  {p95:8.1f}  "
                  f"{bool(np.all(np.isfinite(light)))}")


if __name__ == "__main__":
    main()
