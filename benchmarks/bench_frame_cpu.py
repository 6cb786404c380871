"""CPU per frame of each config's ``render_frame`` in one process, and a digest of the frames'
radiance, with this checkout's ``pipeline`` or another tree's (to set two revisions side by side).

    python benchmarks/bench_frame_cpu.py [CONFIG ...] [--code TREE] [--frames 8] [--cache DIR] [--write]
        [--profile]

For each config (default: every one in configs/): the plan with its exposures metered (as a run
meters them), the cycle products of the frames made first (``--cache``, default a fresh folder,
not timed), frame 0 rendered once untimed (loads, compiles), then frames 1 to ``--frames``
rendered one after another in this process with one FFT thread: their mean CPU seconds per frame,
and the SHA-256 of their radiance. Frames in one process are where what a still sky keeps from
one frame to the next (docs/accuracy.md, "What a still sky keeps") is used, so equal digests from
two trees show that keeping it changes no pixel. ``--code TREE`` imports ``pipeline`` from TREE
(e.g. a ``git worktree add`` of an older commit); the configs are read from this checkout.
``--write`` also writes each frame's files as a run writes them (``render._write_task``: the EXR,
the display codes and the PNG, and their stamps for index.json) into a fresh folder, and gives
that CPU apart, with the SHA-256 of the PNGs' bytes. ``--profile`` runs the timed frames' rendering
under cProfile and prints its 15 costliest functions by their own time (the CPU figure then
includes the profiler's overhead).
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import os
import pstats
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", help="default: every config in configs/")
    parser.add_argument("--code", default=str(ROOT), help="the tree whose pipeline package runs")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--cache", default=None, help="the cycle products' folder (default: a fresh one)")
    parser.add_argument("--write", action="store_true", help="also time writing each frame's files")
    parser.add_argument("--profile", action="store_true", help="profile the timed frames' rendering")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(args.code).resolve()))
    from pipeline.cache import store as cache
    from pipeline.run.folder import frame_files
    from pipeline.run.render import _RenderedFrame, _write_task
    from pipeline.stages.cycle import cycle_phase
    from pipeline.stages.frame import render_frame
    from pipeline.stages.lighting import with_exposures
    from pipeline.stages.plan import plan_run
    from pipeline.stages.resolve import load

    root = Path(args.cache or tempfile.mkdtemp(prefix="sunshade-bench-"))
    paths = args.configs or sorted(str(p) for p in (ROOT / "configs").glob("*.yaml"))
    print(f"pipeline from {args.code}; load average {os.getloadavg()[0]:.1f}", flush=True)
    for path in paths:
        config = load(path)
        plan = plan_run(config)
        frames = list(range(1, args.frames + 1))
        plan = with_exposures(plan, [0, *frames])
        store = cache.Cache(root / Path(path).stem)
        cycle_phase(plan, store, jobs=2, workers=1, cycle_frames={f % plan.canopy.cycle for f in [0, *frames]})
        render_frame(plan, 0, store=store, workers=1)
        digest, written, rendering, writing = hashlib.sha256(), hashlib.sha256(), 0.0, 0.0
        config = replace(config, output=replace(config.output, folder=Path(tempfile.mkdtemp(prefix="sunshade-bench-"))))
        profile = cProfile.Profile() if args.profile else None
        for frame in frames:
            cpu = time.process_time()
            if profile:
                profile.enable()
            result = render_frame(plan, frame, store=store, workers=1)
            if profile:
                profile.disable()
            rendering += time.process_time() - cpu
            digest.update(result.radiance.tobytes())
            if args.write:
                cpu = time.process_time()
                _write_task(config, _RenderedFrame(frame, result, {}, {}, ()), "bench", False)
                writing += time.process_time() - cpu
                written.update(frame_files(config, frame)[1].read_bytes())
        print(f"{Path(path).stem}: {rendering / len(frames) * 1e3:.0f} ms of CPU a frame (frames 1-{args.frames}), "
              f"radiance {digest.hexdigest()[:16]}, load {os.getloadavg()[0]:.1f}", flush=True)
        shutil.rmtree(config.output.folder)
        if profile:
            pstats.Stats(profile).sort_stats("tottime").print_stats(15)
        if args.write:
            print(f"{Path(path).stem}: writing {writing / len(frames) * 1e3:.0f} ms of CPU a frame, "
                  f"PNGs {written.hexdigest()[:16]}", flush=True)
    if args.cache is None:  # a fresh folder of this run's: not left behind
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
