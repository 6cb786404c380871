"""A frame with its compiled loops shared among its threads (``cores.in_shares``) against the same
frame with them in one thread, paired in one process, the FFTs in the same threads both ways.

    python benchmarks/bench_loop_threads.py [CONFIG ...] [--threads 2] [--frames 8] [--cache DIR]

For each config (default: every one in configs/), frames 1 to ``--frames`` rendered twice each
after frame 0 (loads, compiles), the two ways alternating which goes first: the median wall time
of each way, their ratio, and whether the radiance is the same to the bit. On a shared machine
a frame timed against a separate baseline moved by half from one run to the next; timed in
pairs, the two ways meet the same load.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.cache import store as cache
from pipeline.stages import frame
from pipeline.stages.cycle import cycle_phase
from pipeline.stages.lighting import with_exposures
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", help="default: every config in configs/")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--cache", default=None, help="the cycle products' folder (default: a fresh one)")
    args = parser.parse_args()
    root = Path(args.cache or tempfile.mkdtemp(prefix="sunshade-bench-"))
    shared = frame.loop_threads
    ways = {"shared": shared, "one thread": lambda count: shared(1)}
    try:
        for path in args.configs or sorted(str(p) for p in (ROOT / "configs").glob("*.yaml")):
            plan = with_exposures(plan_run(load(path)), range(args.frames + 1))
            store = cache.Cache(root / Path(path).stem)
            cycle_phase(plan, store, jobs=2, workers=1,
                        cycle_frames={f % plan.canopy.cycle for f in range(args.frames + 1)})
            frame.render_frame(plan, 0, store=store, workers=args.threads)
            seconds, same = {name: [] for name in ways}, True
            for f in range(1, args.frames + 1):
                radiance = {}
                for name in (list(ways) if f % 2 else list(ways)[::-1]):
                    frame.loop_threads = ways[name]
                    start = time.perf_counter()
                    radiance[name] = frame.render_frame(plan, f, store=store, workers=args.threads).radiance
                    seconds[name].append(time.perf_counter() - start)
                same &= radiance["shared"].tobytes() == radiance["one thread"].tobytes()
            frame.loop_threads = shared
            a, b = (float(np.median(seconds[name])) for name in ways)
            print(f"{Path(path).stem}: loops shared {a * 1e3:.0f} ms, in one thread {b * 1e3:.0f} ms, ratio "
                  f"{a / b:.2f} (median of {args.frames} each, {args.threads} threads), "
                  f"{'the same' if same else 'DIFFERENT'} radiance", flush=True)
    finally:
        frame.loop_threads = shared
        if args.cache is None:  # a fresh folder of this run's: not left behind
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
