"""Seconds numba spends compiling the loops of a render after an install, loop by loop.

    python benchmarks/bench_compile.py [CONFIG] [--top 12]

With numba's cache in a new empty folder (``NUMBA_CACHE_DIR``, set before numba is imported),
times ``frame.compile_loops`` (the frame phase's loops, as a render's warm-up thread compiles
them) and then one cycle product (the leaf rasteriser, as the first cycle worker compiles it),
and prints each compiled function's seconds from numba's compile events, the largest first.
Default CONFIG: configs/eclipse.yaml.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "eclipse.yaml"))
    parser.add_argument("--top", type=int, default=12)
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="sunshade-compile-"))
    os.environ["NUMBA_CACHE_DIR"] = str(scratch / "numba")
    sys.path.insert(0, str(ROOT))
    from numba.core import event

    from pipeline.cache import store as cache
    from pipeline.stages.cycle import cycle_item
    from pipeline.stages.frame import compile_loops
    from pipeline.stages.plan import plan_run
    from pipeline.stages.resolve import load

    seconds, stack = {}, []

    class Compiles(event.Listener):
        def on_start(self, ev):
            stack.append((ev.data["dispatcher"].py_func.__qualname__, time.perf_counter()))

        def on_end(self, ev):
            name, start = stack.pop()
            seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - start

    event.register("numba:compile", Compiles())
    plan = plan_run(load(args.config))
    print(f"load average {os.getloadavg()[0]:.1f}", flush=True)
    for what, run in (("frame phase (compile_loops)", lambda: compile_loops(plan)),
                      ("cycle product (one)", lambda: cycle_item(plan, 0, 0, cache.Cache(scratch / "cache")))):
        seconds.clear()
        start = time.perf_counter()
        run()
        print(f"{what}: {time.perf_counter() - start:.2f} s", flush=True)
        for name, s in sorted(seconds.items(), key=lambda kv: -kv[1])[:args.top]:
            print(f"  {s:6.2f} s  {name}")
    shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
