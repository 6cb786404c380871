"""A wall's cost: a frame with the ground and one wall over the same config's ground-only frame,
and the cycle phase with the wall over the ground-only cycle phase, paired in one run.

    python benchmarks/bench_walls.py [--config configs/wall-evening.yaml] [--cycle 8] [--repeats 3]
                                     [--jobs 2] [--threads 2]

The config as it stands (default configs/wall-evening.yaml: one wall, one fluttering tree, a
1280 x 720 camera) with its flutter cycle and its frames cut to ``--cycle``, against the same
mapping without ``receivers``. Issue 44 asks for at most 2.2 (frame) and 2 (cycle phase).

- **Frames:** after both cycle phases and one unmeasured frame each, frames 1 to cycle - 1 are
  rendered in turn, ground-only then with the wall (``render_frame``, no writing), as a run renders
  them in one process, ``--repeats`` times: the median of the per-frame ratios and of each's seconds.
- **Cycle phase:** after one unmeasured ground-only phase (the workers started), ``cycle_phase`` on
  an empty cache, ground-only then with the wall, ``--repeats`` times: the median ratio; then the
  wall config's again on its full cache (a second run reads it).

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
from pipeline.config.parse import parse_config
from pipeline.stages.cycle import cycle_phase
from pipeline.stages.frame import render_frame
from pipeline.stages.plan import RunPlan, plan_run
from pipeline.stages.resolve import resolve

ROOT = Path(__file__).resolve().parents[1]


def plans(config: Path, cycle: int) -> tuple[RunPlan, RunPlan]:
    """(with the wall, ground-only) plans of ``config`` cut to a ``cycle``-frame flutter and run."""
    mapping = yaml.safe_load(config.read_text())
    mapping["canopy"].setdefault("flutter", {})["cycle"] = cycle
    mapping.setdefault("animation", {})["frames"] = cycle
    ground = copy.deepcopy(mapping)
    ground.pop("receivers", None)
    return (plan_run(resolve(parse_config(mapping, config.parent, name="wall"))),
            plan_run(resolve(parse_config(ground, config.parent, name="ground"))))


def seconds(f) -> float:
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "wall-evening.yaml")
    parser.add_argument("--cycle", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    wall, ground = plans(args.config, args.cycle)
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-walls-"))
    try:
        cycle_phase(ground, cache.Cache(work / "warm-up"), jobs=args.jobs, workers=1)  # the workers started
        cycle_ratios, cycle_ground, cycle_wall = [], [], []
        for r in range(args.repeats):
            g = seconds(lambda: cycle_phase(ground, cache.Cache(work / f"g{r}"), jobs=args.jobs, workers=1))
            w = seconds(lambda: cycle_phase(wall, cache.Cache(work / f"w{r}"), jobs=args.jobs, workers=1))
            cycle_ground.append(g)
            cycle_wall.append(w)
            cycle_ratios.append(w / g)
        warm = seconds(lambda: cycle_phase(wall, cache.Cache(work / "w0"), jobs=args.jobs, workers=1))
        print(f"cycle phase, {args.cycle} cycle frames, --jobs {args.jobs}, {args.repeats} pairs: ground-only "
              f"{np.median(cycle_ground):.2f} s, with the wall {np.median(cycle_wall):.2f} s, ratio "
              f"{np.median(cycle_ratios):.2f} (min {min(cycle_ratios):.2f}, max {max(cycle_ratios):.2f}; "
              f"at most 2); the wall's again on its cache {warm:.2f} s")

        stores = cache.Cache(work / "g0"), cache.Cache(work / "w0")
        render_frame(ground, 0, store=stores[0], workers=args.threads)
        render_frame(wall, 0, store=stores[1], workers=args.threads)
        frame_ratios, frame_ground, frame_wall = [], [], []
        for _ in range(args.repeats):
            for frame in range(1, args.cycle):
                g = seconds(lambda: render_frame(ground, frame, store=stores[0], workers=args.threads))
                w = seconds(lambda: render_frame(wall, frame, store=stores[1], workers=args.threads))
                frame_ground.append(g)
                frame_wall.append(w)
                frame_ratios.append(w / g)
        print(f"frame, {len(frame_ratios)} pairs (frames 1-{args.cycle - 1} x {args.repeats}), --threads "
              f"{args.threads}: ground-only {np.median(frame_ground):.3f} s, with the wall "
              f"{np.median(frame_wall):.3f} s, ratio {np.median(frame_ratios):.2f} (min {min(frame_ratios):.2f}, "
              f"max {max(frame_ratios):.2f}; at most 2.2)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
