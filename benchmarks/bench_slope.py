"""A sloped ground's cost: a frame of a hillside config over the same scene on level ground, paired in
one run (docs/method.md, "A sloped ground"; issue 44).

    python benchmarks/bench_slope.py [--config configs/hillside-low-sun.yaml] [--cycle 4] [--repeats 3]
                                     [--threads 2] [--code DIR] [--baseline DIR [--rounds 3]]

The level version is the hillside turned into the slope's frame: the trees' centre, the camera
(``receivers.slope.camera_in_frame``) and the sun at their places in the slope's (u, w, n) axes, the
windows as given, no ``receivers``; so both draw the same trees over the same windows from the same
view. After both cycle phases (cut to ``--cycle`` frames) and one unmeasured frame each, frames 1 to
cycle - 1 are rendered in turn, level then slope (``render_frame``, no writing), ``--repeats``
times: the median of the per-frame ratios, of each's seconds and of its stages' (``timings``).
Then the low sun's contrast on the slope at frame 0: p95 / p5 of the slope's irradiance (luminance)
over the pixels that see it, against the open slope's (sun + sky) / sky (``sunshade check``'s bound).

``--code DIR`` imports ``pipeline`` from another tree (a worktree of another commit). ``--baseline
DIR`` pairs this tree against DIR's: the benchmark is run ``--rounds`` times in turn in fresh
processes, this tree's then DIR's, and prints each tree's median frame seconds, level and slope,
and the median of the rounds' ratios of this tree's slope frame over DIR's.

Prints the load average before and after.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
CODE = Path(sys.argv[sys.argv.index("--code") + 1]).resolve() if "--code" in sys.argv[:-1] else ROOT
sys.path.insert(0, str(CODE))

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
    parser.add_argument("--code", type=Path, default=ROOT, help="the tree to import pipeline from")
    parser.add_argument("--baseline", type=Path, help="a tree to pair this one against, process by process")
    parser.add_argument("--rounds", type=int, default=3, help="with --baseline: processes of each tree")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.baseline is not None:
        paired(args)
        print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        return
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
    if args.json:
        print(json.dumps({name: float(np.median(seconds[name])) for name in seconds}))
        return
    contrast(slope)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def paired(args: argparse.Namespace) -> None:
    """This tree against ``args.baseline``, a fresh process of each in turn, ``args.rounds`` times."""
    seconds: dict[str, dict[str, list[float]]] = {name: {"level": [], "slope": []} for name in ("this", "baseline")}
    ratios = []
    for _ in range(args.rounds):
        for name, code in (("this", ROOT), ("baseline", args.baseline)):
            out = subprocess.run([sys.executable, __file__, "--config", str(args.config), "--cycle", str(args.cycle),
                                  "--repeats", str(args.repeats), "--threads", str(args.threads), "--code", str(code),
                                  "--json"], check=True, capture_output=True, text=True).stdout
            for key, value in json.loads(out.strip().splitlines()[-1]).items():
                seconds[name][key].append(value)
        ratios.append(seconds["this"]["slope"][-1] / seconds["baseline"]["slope"][-1])
    for name in seconds:
        print(f"{name}: level frame {np.median(seconds[name]['level']):.2f} s, slope frame "
              f"{np.median(seconds[name]['slope']):.2f} s (medians of {args.rounds} processes); slope / level "
              f"{np.median(seconds[name]['slope']) / np.median(seconds[name]['level']):.2f}")
    print(f"this tree's slope frame / the baseline's: median {np.median(ratios):.2f} (min {min(ratios):.2f}, "
          f"max {max(ratios):.2f}, {len(ratios)} rounds)")


if __name__ == "__main__":
    main()
