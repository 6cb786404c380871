"""Seconds of compiling before a render's first frame after an install, and numba's seconds loop by loop.

    python benchmarks/bench_compile.py [CONFIG] [--repeats 2] [--code TREE] [--top 12] [--no-render]

First (unless --no-render) the figure issue 49 asks for: ``sunshade render CONFIG`` into a new
output folder with a new render cache, timed from its start to its first frame's PNG (then
ended), with numba's cache (``NUMBA_CACHE_DIR``) in a new empty folder (``cold``: the first run
of an install, which compiles the loops) and right after it with that cache filled (``warm``).
``compiling before the first frame`` is the median of cold minus warm over ``--repeats``; the
CPU seconds of the command and its workers until then beside them. TREE (default: this
checkout) is the ``pipeline`` package run, from this checkout's folder, so that a baseline
worktree can be measured in the same run.

Then, in this process, with numba's cache in another new empty folder: ``frame.compile_loops``
(the frame phase's loops, as a render's warm-up thread compiles them), ``rasteriser.compile_loops``
(the cycle products' loops, as a render's worker compiles them while the command plans; skipped
where this checkout lacks it) and one cycle product (which then compiles
nothing, or, without that warm-up, the leaf rasteriser), wall and CPU seconds, and each
compiled function's own seconds from numba's compile events (its nested compiles not counted
in it), the largest first. Default CONFIG: configs/eclipse.yaml.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]


def first_frame(config: str, tree: Path, numba: Path, work: Path) -> tuple[float, float]:
    """(wall, CPU) seconds from a render's start to its first frame's PNG, the command and its
    workers then ended; numba's cache in ``numba``, the render's folders new under ``work``."""
    out, store = work / "out", work / "cache"
    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(store, ignore_errors=True)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(numba), "PYTHONPATH": str(tree)}
    log = (work / "render.log").open("w+")  # a file, not a pipe: a full pipe would stop the render
    started = time.perf_counter()
    command = subprocess.Popen([sys.executable, "-P", "-m", "pipeline.cli", "render", config, "--output", str(out),
                                "--cache", str(store)], cwd=ROOT, env=env, start_new_session=True,
                               stdout=log, stderr=subprocess.STDOUT)
    process, seen = psutil.Process(command.pid), {}
    try:
        while command.poll() is None:
            try:  # CPU of the command and each worker, as last seen (a worker may end first)
                for p in [process, *process.children(recursive=True)]:
                    times = p.cpu_times()
                    seen[p.pid] = times.user + times.system + times.children_user + times.children_system
            except psutil.Error:
                pass
            if out.is_dir() and any(not p.name.startswith(".") for p in out.glob("*.png")):
                return time.perf_counter() - started, sum(seen.values())
            time.sleep(0.02)
        log.seek(0)
        raise SystemExit(f"the render ended without a frame: {log.read()[-2000:]}")
    finally:
        if command.poll() is None:
            os.killpg(command.pid, signal.SIGKILL)  # its own session: the command and its workers
        command.wait()
        log.close()


def before_first_frame(config: str, tree: Path, repeats: int) -> None:
    """Print the cold and warm first frames of each repeat and the median compiling before it."""
    waits, cpus = [], []
    for repeat in range(repeats):
        with tempfile.TemporaryDirectory(prefix="sunshade-compile-") as folder:
            work = Path(folder)
            load = os.getloadavg()[0]
            cold, cold_cpu = first_frame(config, tree, work / "numba", work)
            warm, warm_cpu = first_frame(config, tree, work / "numba", work)
            print(f"  repeat {repeat + 1}: first frame {cold:.2f} s cold, {warm:.2f} s warm; CPU {cold_cpu:.1f} s, "
                  f"{warm_cpu:.1f} s (load average {load:.1f})", flush=True)
            waits.append(cold - warm)
            cpus.append(cold_cpu - warm_cpu)
    print(f"compiling before the first frame: {np.median(waits):.2f} s of wall, {np.median(cpus):.1f} s of CPU "
          f"(median of {repeats}; {tree})", flush=True)


def loop_by_loop(config: str, top: int) -> None:
    """numba's compiling of the frame phase's loops and of one cycle product, in this process."""
    scratch = Path(tempfile.mkdtemp(prefix="sunshade-compile-"))
    os.environ["NUMBA_CACHE_DIR"] = str(scratch / "numba")  # before numba is imported
    sys.path.insert(0, str(ROOT))
    from numba.core import event

    from pipeline.cache import store as cache
    from pipeline.stages.cycle import cycle_item
    from pipeline.stages.frame import compile_loops
    from pipeline.stages.plan import plan_run
    from pipeline.stages.resolve import load

    own: dict[str, float] = {}
    stack: list[list] = []  # [name, start, nested seconds]

    class Compiles(event.Listener):
        def on_start(self, ev):
            function = ev.data["dispatcher"].py_func
            stack.append([f"{function.__module__}.{function.__qualname__}", time.perf_counter(), 0.0])

        def on_end(self, ev):
            name, start, nested = stack.pop()
            seconds = time.perf_counter() - start
            own[name] = own.get(name, 0.0) + seconds - nested
            if stack:
                stack[-1][2] += seconds

    event.register("numba:compile", Compiles())
    from pipeline.canopy import rasteriser

    plan = plan_run(load(config))
    print(f"loop by loop (load average {os.getloadavg()[0]:.1f}):", flush=True)
    steps = [("frame phase (compile_loops)", lambda: compile_loops(plan))]
    if hasattr(rasteriser, "compile_loops"):
        steps.append(("cycle warm-up (rasteriser.compile_loops)", rasteriser.compile_loops))
    steps.append(("cycle product (one)", lambda: cycle_item(plan, 0, 0, cache.Cache(scratch / "cache"))))
    for what, run in steps:
        own.clear()
        start, cpu = time.perf_counter(), time.process_time()
        run()
        print(f"{what}: {time.perf_counter() - start:.2f} s, {time.process_time() - cpu:.2f} s of CPU, "
              f"{len(own)} functions compiled", flush=True)
        for name, s in sorted(own.items(), key=lambda kv: -kv[1])[:top]:
            print(f"  {s:6.2f} s  {name}")
    shutil.rmtree(scratch, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "eclipse.yaml"))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--code", type=Path, default=ROOT, help="the tree whose pipeline package renders")
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--no-render", action="store_true", help="only the loop-by-loop seconds")
    args = parser.parse_args()
    config = str(Path(args.config).resolve())
    if not args.no_render:
        before_first_frame(config, args.code.resolve(), args.repeats)
    loop_by_loop(config, args.top)


if __name__ == "__main__":
    main()
