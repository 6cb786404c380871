"""A sloped ground's cost: a frame of a hillside config over the same scene on level ground, paired in
one run (docs/method.md, "A sloped ground"; issue 44).

    python benchmarks/bench_slope.py [--config configs/hillside-low-sun.yaml] [--cycle 4] [--repeats 3]
                                     [--threads 2]

The level version is the hillside turned into the slope's frame: the trees' centre, the camera
(``receivers.slope.camera_in_frame``) and the sun at their places in the slope's (u, w, n) axes, the
windows as given, no ``receivers``; so both draw the same trees over the same windows from the same
view. After both cycle phases (cut to ``--cycle`` frames) and one unmeasured frame each, frames 1 to
cycle - 1 are rendered in turn, level then slope (``render_frame``, no writing), ``--repeats``
times: the median of the per-frame ratios, of each's seconds and of its stages' (``timings``).
Then the low sun's contrast on the slope at frame 0: p95 / p5 of the slope's irradiance (luminance)
over the pixels that see it, against the open slope's (sun + sky) / sky (``sunshade check``'s bound).

Prints the load average before and after.
"""

from __future__ import annotations

import argparse
import copy
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.cache import store as cache
from pipeline.camera import pinhole
from pipeline.config.parse import parse_config
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.receivers.slope import camera_in_frame, slope_plane
from pipeline.stages.cycle import cycle_phase
from pipeline.stages.frame import irradiance_maps, render_frame
from pipeline.stages.ground import FrameContext
from pipeline.stages.plan import RunPlan, plan_run
from pipeline.stages.resolve import resolve
from pipeline.stages.slope import open_slope, slope_ground

ROOT = Path(__file__).resolve().parents[1]


def plans(config: Path, cycle: int) -> tuple[RunPlan, RunPlan]:
    """(slope, level) plans of ``config`` cut to a ``cycle``-frame flutter and run."""
    mapping = yaml.safe_load(config.read_text())
    mapping["canopy"].setdefault("flutter", {})["cycle"] = cycle
    mapping.setdefault("animation", {})["frames"] = cycle
    slope = plan_run(resolve(parse_config(mapping, config.parent, name="slope")))
    plane = slope_plane(slope.receivers.slope)
    level = copy.deepcopy(mapping)
    level.pop("receivers")
    centre = plane.local_points([*mapping["canopy"]["layers"][0]["center"], 0.0])
    level["canopy"]["layers"][0]["center"] = [float(centre[0]), float(centre[1])]
    view = camera_in_frame(slope.camera, plane)
    forward = view.basis[2]
    level["camera"]["position"] = [float(v) for v in view.position]
    level["camera"]["look_at"] = [float(v) for v in np.asarray(view.position) + 10 * forward]
    sun = mapping["sky"]["sun"]
    e, a = np.radians(sun["elevation"]), np.radians(sun["azimuth"])
    local = plane.local_directions([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])
    level["sky"]["sun"] = {"elevation": float(np.degrees(np.arcsin(local[2]))),
                           "azimuth": float(np.degrees(np.arctan2(local[0], local[1])) % 360)}
    return slope, plan_run(resolve(parse_config(level, config.parent, name="level")))


def contrast(plan: RunPlan) -> None:
    """Print the slope's p95 / p5 in the picture at frame 0 and its open (sun + sky) / sky."""
    view = camera_in_frame(plan.camera, slope_plane(plan.receivers.slope))
    ground = slope_ground(FrameContext.of(plan, 0))
    seen = pinhole.ground_irradiance(view, irradiance=irradiance_maps(plan, ground)) @ REC709_LUMINANCE
    values = seen[pinhole.ground_fraction_rows(view) >= 1].ravel()
    p95, p5 = np.percentile(values, [95, 5])
    (open_light,) = open_slope(plan, [0])
    sun, sky = (float(np.asarray(v) @ REC709_LUMINANCE) for v in (open_light.sun, open_light.sky))
    print(f"slope at frame 0: p95 / p5 {p95 / p5:.3f} over {values.size} pixels; (sun + sky) / sky "
          f"{(sun + sky) / sky:.3f}; the ratio of the two {p95 / p5 / ((sun + sky) / sky):.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "hillside-low-sun.yaml")
    parser.add_argument("--cycle", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    slope, level = plans(args.config, args.cycle)
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-slope-"))
    try:
        stores = {name: cache.Cache(work / name) for name in ("slope", "level")}
        for name, plan in (("level", level), ("slope", slope)):
            cycle_phase(plan, stores[name], jobs=1, workers=1)
            render_frame(plan, 0, store=stores[name], workers=args.threads)
        ratios, seconds, stages = [], {"level": [], "slope": []}, {"level": [], "slope": []}
        for _ in range(args.repeats):
            for frame in range(1, args.cycle):
                pair = {}
                for name, plan in (("level", level), ("slope", slope)):
                    timings: dict = {}
                    t = time.perf_counter()
                    render_frame(plan, frame, store=stores[name], workers=args.threads, timings=timings)
                    pair[name] = time.perf_counter() - t
                    seconds[name].append(pair[name])
                    stages[name].append(timings)
                ratios.append(pair["slope"] / pair["level"])
        for name in ("level", "slope"):
            parts = {k: float(np.median([s[k] for s in stages[name]])) for k in stages[name][0]}
            print(f"{name}: a frame {np.median(seconds[name]):.2f} s (median of {len(seconds[name])}; "
                  + ", ".join(f"{k} {v:.2f} s" for k, v in parts.items()) + ")")
        print(f"slope / level, a frame: median {np.median(ratios):.2f} (min {min(ratios):.2f}, max {max(ratios):.2f}, "
              f"{len(ratios)} pairs)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    contrast(slope)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
