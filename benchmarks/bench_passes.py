"""The cost of the light passes per frame (docs/runs.md, "Light passes"): a frame rendered and
written without passes and with all five, alternately, on the same plan and cache.

    python benchmarks/bench_passes.py [--config configs/eclipse.yaml] [--frames 5,120] [--repeats 5] [--threads 2]

Each repeat renders each frame with ``passes=()`` and with every pass, in turn, and writes
each as the run does (EXR with its layers and attributes, half floats as output.half says);
the medians over repeats and frames are printed with the load average. The cycle products are
made once first (in a temporary cache), so the figures are the frame phase's.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.cache import store as cache
from pipeline.config.vocabulary import PASSES
from pipeline.core import io
from pipeline.run.contents import exr_layers, frame_attributes
from pipeline.stages.frame import render_frame
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="configs/eclipse.yaml")
    parser.add_argument("--frames", default="5,120")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    config = load(args.config)
    config = replace(config, output=replace(config.output, passes=PASSES))
    frames = [int(f) for f in args.frames.split(",")]
    plan = plan_run(config)
    seconds = {(kind, stage): [] for kind in ("off", "on") for stage in ("render", "write")}
    with tempfile.TemporaryDirectory() as tmp:
        store = cache.Cache(Path(tmp) / "cache")
        for frame in frames:  # cycle products, compiled loops, lru caches: once, not timed
            render_frame(plan, frame, store=store, workers=args.threads, passes=PASSES)
        for _ in range(args.repeats):
            for frame in frames:
                for kind, passes in (("off", ()), ("on", PASSES)):
                    start = time.perf_counter()
                    result = render_frame(plan, frame, store=store, workers=args.threads, passes=passes)
                    seconds[kind, "render"].append(time.perf_counter() - start)
                    start = time.perf_counter()
                    on = replace(config, output=replace(config.output, passes=passes))
                    io.write_exr(Path(tmp) / f"{kind}.exr", result.radiance, frame_attributes(on, result, "0" * 16),
                                 half=config.output.half, layers=exr_layers(result, config.output.half))
                    seconds[kind, "write"].append(time.perf_counter() - start)
        sizes = {kind: (Path(tmp) / f"{kind}.exr").stat().st_size for kind in ("off", "on")}
    rows, cols = result.radiance.shape[:2]
    print(f"{args.config}: frames {args.frames}, {cols} x {rows} px, {args.repeats} repeats, "
          f"{args.threads} threads; load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    for stage in ("render", "write"):
        off, on = (statistics.median(seconds[k, stage]) for k in ("off", "on"))
        print(f"  {stage:6s}: {off * 1000:7.0f} ms without passes, {on * 1000:7.0f} ms with all five "
              f"(+{(on - off) * 1000:.0f} ms, x{on / off:.2f}); medians")
    print(f"  EXR: {sizes['off'] / 1e6:.2f} MB without, {sizes['on'] / 1e6:.2f} MB with (the last frame)")


if __name__ == "__main__":
    main()
