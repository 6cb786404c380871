"""Whole runs through the real command: frames per second with --jobs 1 and 2, the share of each
stage, and a resume with nothing left to do. Baselines measured in the same run.

    python benchmarks/bench_render.py [CONFIG] [--frames 0-23]

CONFIG defaults to configs/eclipse.yaml, the default main job. Four runs of
``sunshade render CONFIG --frames ...`` in fresh folders:

1. --jobs 2 with an empty cache: the cycle phase of the cycle frames those frames use (cold);
2. --jobs 1 and 3. --jobs 2 with that cache warm: the frame phase, frames per second; with
   --jobs 1 the frame phase beside its stages' sum, so how much of the writing the next
   frame's rendering hides (docs/runs.md, "Writing");
4. the same command again with nothing left to do: its wall time (target: at most 1 s), beside
   the wall time of a bare ``python -c "import pipeline.cli.main"`` (the start-up every command pays).

The stage shares come from each run's run.json (seconds summed over the frames, as measured in
the workers: ground raster, camera resampling, compositing, writing). The ground stage is set
beside a bare rfft2 + irfft2 pair of the run's own FFT shapes with the threads of --jobs 1.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.fft

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.core.cores import default_workers
from pipeline.run.folder import parse_frames
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def sunshade(*args) -> float:
    """Wall seconds of one real ``sunshade`` process (it must succeed)."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pipeline.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(done.stderr)
    return time.perf_counter() - started


def bare_ffts(config) -> float:
    """Seconds of one rfft2 + irfft2 pair of three channels per FFT shape a frame's ground
    raster uses, on every core (as --jobs 1 does): the floor under the ground stage."""
    plan = plan_run(config)
    shapes = []
    for layer in plan.layers:
        shapes.append(getattr(layer.coarse, "fft_shape", None) or layer.coarse.tile_shape)
        if layer.sun is not None:
            shapes.append(layer.sun.fft_shape)
    total = 0.0
    for shape in shapes:
        data = np.random.default_rng(0).random((3, *shape), dtype=np.float32)
        best = np.inf
        for _ in range(3):
            t = time.perf_counter()
            spectrum = scipy.fft.rfft2(data, axes=(1, 2), workers=default_workers())
            scipy.fft.irfft2(spectrum, s=shape, axes=(1, 2), workers=default_workers())
            best = min(best, time.perf_counter() - t)
        total += best
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "eclipse.yaml"))
    parser.add_argument("--frames", default="0-23")
    args = parser.parse_args()
    config = load(args.config)
    count = len(parse_frames(args.frames, config.animation.frames))
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-render-"))
    try:
        cache = work / "cache"
        common = ["render", args.config, "--frames", args.frames, "--cache", cache]
        cold = sunshade(*common, "--jobs", "2", "--output", work / "cold")
        runs = {}
        for jobs in (1, 2):
            wall = sunshade(*common, "--jobs", jobs, "--output", work / f"jobs{jobs}")
            runs[jobs] = (wall, json.loads((work / f"jobs{jobs}" / "run.json").read_text())["timings"])
        resume = min(sunshade(*common, "--jobs", "2", "--output", work / "jobs2") for _ in range(3))
        started = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import pipeline.cli.main"], cwd=ROOT, check=True)
        startup = time.perf_counter() - started
        cold_timings = json.loads((work / "cold" / "run.json").read_text())["timings"]
        floor = bare_ffts(config)
    finally:
        shutil.rmtree(work, ignore_errors=True)

    width, height = config.camera.resolution
    print(f"{args.config}: frames {args.frames} ({count}), {width} x {height}, "
          f"cycle {config.canopy.cycle}, {len(config.canopy.layers)} layer(s)")
    print(f"cold cache, --jobs 2: cycle phase {cold_timings.get('cycle', 0):.1f} s for "
          f"{len({f % config.canopy.cycle for f in parse_frames(args.frames, config.animation.frames)})} "
          f"cycle frames; whole command {cold:.1f} s")
    print(f"{'jobs':>4} {'frame phase':>12} {'frames/s':>9} {'s/frame':>8} {'command':>8}")
    for jobs, (wall, timings) in runs.items():
        phase = timings["frames"]
        print(f"{jobs:>4} {phase:>10.1f} s {count / phase:>9.3f} {phase / count:>8.2f} {wall:>6.1f} s")
    print(f"speed-up of --jobs 2 over --jobs 1: {runs[1][1]['frames'] / runs[2][1]['frames']:.2f}")
    for jobs, (_, timings) in runs.items():
        stages = timings["frame_stages"]
        total = sum(stages.values())
        shares = ", ".join(f"{name} {value / count:.2f} s ({100 * value / total:.0f}%)"
                           for name, value in stages.items())
        print(f"stages per frame, --jobs {jobs}: {shares}")
    stages = runs[1][1]["frame_stages"]
    serial, phase = sum(stages.values()), runs[1][1]["frames"]
    print(f"--jobs 1: frame phase {phase:.1f} s against its stages one after another {serial:.1f} s "
          f"(writing {stages['write']:.1f} s): {100 * (serial - phase) / stages['write']:.0f}% of the "
          f"writing hidden behind the next frame's rendering")
    ground = stages["ground"] / count
    print(f"ground stage {ground:.3f} s per frame vs bare rfft2 + irfft2 of its FFT shapes "
          f"{floor:.3f} s: ratio {ground / floor:.1f}")
    if "video" in cold_timings:
        print(f"video of all {config.animation.frames} frames (cold run): {cold_timings['video']:.1f} s")
    print(f"resume with nothing to do: {resume:.2f} s (target <= 1 s); bare start-up "
          f"(python -c 'import pipeline.cli.main') {startup:.2f} s")


if __name__ == "__main__":
    main()
