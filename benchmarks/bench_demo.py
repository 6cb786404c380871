"""The README's demo, ``sunshade render CONFIG`` from an empty cache, as a new user runs it from a
fresh clone, beside the same command run by another revision in the same run.

    python benchmarks/bench_demo.py [--config configs/eclipse.yaml] [--baseline REV] [--repeats 1]

Each revision (this checkout's HEAD, and REV) is checked out in a temporary git worktree, so
that its compiled loops start with an empty numba cache as in a fresh clone; in each repeat the
render runs twice there, each time in a fresh output folder with a fresh cache: ``cold`` (the
first run of a fresh clone, which compiles the loops) and ``warm`` (numba's cache filled).
Revisions alternate, the baseline first. Prints the wall seconds, the CPU seconds of the command
and its workers, the stages' seconds from run.json (cycle, frames, video) and the load average
at the start of each run; medians over ``--repeats`` and the ratio to the baseline.
"""

from __future__ import annotations

import argparse
import json
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


def demo_run(tree: Path, config: str, work: Path) -> dict:
    """Seconds of one render of ``config`` by the code of ``tree``, run from ``tree``."""
    out, cache = work / "out", work / "cache"
    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(cache, ignore_errors=True)
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run([sys.executable, "-P", "-m", "pipeline.cli", "render", config, "--output", str(out),
                    "--cache", str(cache)], cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)},
                   check=True, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    timings = json.loads((out / "run.json").read_text())["timings"]
    return {"wall": wall, "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "cycle": timings.get("cycle", 0.0), "frames": timings.get("frames", 0.0),
            "video": timings.get("video", 0.0), "load": load}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="configs/eclipse.yaml")
    parser.add_argument("--baseline", help="a git revision to measure beside this checkout's HEAD")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    revisions = ([args.baseline] if args.baseline else []) + ["HEAD"]
    results = {(rev, kind): [] for rev in revisions for kind in ("cold", "warm")}
    with tempfile.TemporaryDirectory(prefix="sunshade-demo-") as temporary:
        work = Path(temporary)
        for _ in range(args.repeats):
            for rev in revisions:
                tree = work / f"tree-{len(results)}-{rev.replace('/', '_')}"
                subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), rev],
                               check=True)
                try:
                    for kind in ("cold", "warm"):
                        results[rev, kind].append(demo_run(tree, args.config, work))
                        print(f"{rev:>12} {kind}: " + ", ".join(
                            f"{k} {v:.1f}" for k, v in results[rev, kind][-1].items()), flush=True)
                finally:
                    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True)
    print(f"\n{args.config}, medians of {args.repeats} (seconds; load at the start of the runs)")
    print(f"{'revision':>12} {'run':>5} {'wall':>7} {'cpu':>7} {'cycle':>7} {'frames':>7} {'video':>7} {'load':>5}")
    for (rev, kind), runs in results.items():
        m = {k: float(np.median([r[k] for r in runs])) for k in runs[0]}
        ratio = ""
        if args.baseline and rev == "HEAD":
            base = float(np.median([r["wall"] for r in results[args.baseline, kind]]))
            ratio = f"  {base / m['wall']:.2f}x faster than {args.baseline}"
        print(f"{rev:>12} {kind:>5} {m['wall']:7.1f} {m['cpu']:7.1f} {m['cycle']:7.1f} {m['frames']:7.1f} "
              f"{m['video']:7.1f} {m['load']:5.1f}{ratio}")


if __name__ == "__main__":
    main()
