"""``sunshade render CONFIG --preview`` from an empty cache: seconds to the first frame and to the
end, beside the same command run by another revision of the code in the same run.

    python benchmarks/bench_preview.py [CONFIG ...] [--baseline REV] [--repeats 1]

CONFIG defaults to every config in configs/. Each run is a real process in a fresh output
folder with a fresh cache; the first frame counts as shown when its PNG is in place. With
``--baseline REV`` (e.g. ``main``) the revision is checked out in a temporary git worktree and
the same command runs with its ``pipeline`` package first on PYTHONPATH; the ratio is printed.
Prints wall seconds (median over ``--repeats``), the CPU seconds of the process and its
workers, and the load average, which says how busy the machine was.

Before the timed runs of a config, each revision renders its frame 0 once, untimed, in a
throw-away folder: numba compiles the loops a config needs into the revision's own
``__pycache__`` on its first run (several seconds in each worker), which a fresh checkout of the
baseline would otherwise pay inside its timing and this tree, already warm, would not.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.stages.resolve import load


def command(config: Path, work: Path, *extra: str) -> list[str]:
    """The preview command of ``config`` into ``work``/out with the cache in ``work``/cache."""
    return [sys.executable, "-m", "pipeline.cli", "render", str(config), "--preview", "--output",
            str(work / "out"), "--cache", str(work / "cache"), *extra]


def warm(config: Path, code: Path) -> None:
    """Render frame 0 of the preview once with ``code``, untimed, so that numba's cache of the
    loops the config needs is filled (see the module docstring)."""
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-preview-warm-"))
    try:
        subprocess.run(command(config, work, "--frames", "0"), cwd=work, env={**os.environ, "PYTHONPATH": str(code)},
                       check=True, capture_output=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def preview_run(config: Path, code: Path, work: Path) -> tuple[float, float, float]:
    """(seconds to the first frame's PNG, seconds to the end, CPU seconds) of one preview."""
    name = load(config).output.name
    out = work / "out"
    env = {**os.environ, "PYTHONPATH": str(code)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    process = subprocess.Popen(command(config, work), cwd=work, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    first = None
    while process.poll() is None:
        if first is None and any((out / "preview").glob(f"{name}.[0-9][0-9][0-9][0-9].png")):
            first = time.perf_counter() - started
        time.sleep(0.05)
    total = time.perf_counter() - started
    _stdout, stderr = process.communicate()
    if process.returncode:
        raise SystemExit(f"{config}: {stderr}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return first if first is not None else total, total, cpu


def measure(config: Path, code: Path, repeats: int) -> tuple[float, float, float]:
    runs = []
    for _ in range(repeats):
        work = Path(tempfile.mkdtemp(prefix="sunshade-bench-preview-"))
        try:
            runs.append(preview_run(config, code, work))
        finally:
            shutil.rmtree(work, ignore_errors=True)
    return tuple(float(np.median(column)) for column in zip(*runs))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=sorted(str(p) for p in (ROOT / "configs").glob("*.yaml")))
    parser.add_argument("--baseline", help="a git revision to measure beside this tree")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    baseline = None
    if args.baseline:
        baseline = Path(tempfile.mkdtemp(prefix="sunshade-baseline-")) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(baseline), args.baseline], cwd=ROOT,
                       check=True, capture_output=True)
    try:
        for config in map(Path, args.configs):
            for code in (ROOT,) if baseline is None else (ROOT, baseline):
                warm(config.resolve(), code)
            load = os.getloadavg()[0]
            first, total, cpu = measure(config.resolve(), ROOT, args.repeats)
            line = (f"{config.name}: first frame {first:.1f} s, done {total:.1f} s, CPU {cpu:.1f} s "
                    f"(load {load:.1f})")
            if baseline is not None:
                b_first, b_total, b_cpu = measure(config.resolve(), baseline, args.repeats)
                line += (f"; {args.baseline}: first frame {b_first:.1f} s, done {b_total:.1f} s, CPU "
                         f"{b_cpu:.1f} s; ratio {b_first / first:.1f} (first), {b_total / total:.1f} (done)")
            print(line, flush=True)
    finally:
        if baseline is not None:
            subprocess.run(["git", "worktree", "remove", "--force", str(baseline)], cwd=ROOT, capture_output=True)
            shutil.rmtree(baseline.parent, ignore_errors=True)  # the temporary folder that held it


if __name__ == "__main__":
    main()
