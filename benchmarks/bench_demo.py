"""The README's demo, ``sunshade render CONFIG`` from an empty cache, as a new user runs it from a
fresh clone, beside the same command run by another revision in the same run.

    python benchmarks/bench_demo.py [--config configs/eclipse.yaml] [--baseline REV] [--repeats 1]
        [--trees TREE ...] [--runs cold,warm]

Each revision (this checkout's HEAD, and REV) is checked out in a temporary git worktree, so
that its compiled loops start with an empty numba cache as in a fresh clone; with ``--trees``,
each TREE (a folder holding ``pipeline``, e.g. a baseline worktree and this checkout with its
changes not committed) is copied instead (the files that git tracks or would track: a clone's)
and run with this environment's packages. In each repeat the render runs there as ``--runs``
lists: ``cold`` (a fresh output folder and cache: the first run of a fresh clone, which compiles
the loops), ``warm`` (the same with numba's cache filled) and ``force`` (``--force`` into the
folders of the run before it: every frame rendered again, the caches warm, as the README's
figures after the demo). Revisions alternate, the baseline first. Prints the wall seconds, the
CPU seconds of the command and its workers, the stages' seconds from run.json (cycle, frames,
video), the load average at the start of each run and the bare rfft2 + irfft2 round trip of one
float32 2048^2 plane (2 workers, best of 5) just before it [ms]; medians over ``--repeats``, the
ratio to the baseline and each tree's cold over force.
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
import scipy.fft as sfft

ROOT = Path(__file__).resolve().parents[1]


def bare_fft_ms() -> float:
    """rfft2 + irfft2 of one float32 2048^2 plane, 2 workers, best of 5 [ms]: how fast the shared machine is now."""
    plane = np.random.default_rng(0).random((2048, 2048), dtype=np.float32)
    best = np.inf
    for _ in range(5):
        start = time.perf_counter()
        sfft.irfft2(sfft.rfft2(plane, workers=2), s=plane.shape, workers=2)
        best = min(best, time.perf_counter() - start)
    return 1000 * best


def demo_run(tree: Path, config: str, work: Path, force: bool = False) -> dict:
    """Seconds of one render of ``config`` by the code of ``tree``, run from ``tree``; with ``force``,
    ``--force`` into the folders of the run before it, else into new ones."""
    out, cache = work / "out", work / "cache"
    if not force:
        shutil.rmtree(out, ignore_errors=True)
        shutil.rmtree(cache, ignore_errors=True)
    fft = bare_fft_ms()
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run([sys.executable, "-P", "-m", "pipeline.cli", "render", config, "--output", str(out),
                    "--cache", str(cache), *(["--force"] if force else [])], cwd=tree,
                   env={**os.environ, "PYTHONPATH": str(tree)}, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    timings = json.loads((out / "run.json").read_text())["timings"]
    return {"wall": wall, "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "cycle": timings.get("cycle", 0.0), "frames": timings.get("frames", 0.0),
            "video": timings.get("video", 0.0), "load": load, "fft": fft}


def fresh_tree(name: str, tree: Path | None, work: Path) -> Path:
    """A fresh copy of ``tree`` (the files git tracks or would, not those it ignores: no numba cache, no
    render cache), or a git worktree of revision ``name``."""
    target = work / f"tree-{name.replace('/', '_')}"
    shutil.rmtree(target, ignore_errors=True)
    if tree is None:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(target), name], check=True)
    else:
        if not (tree / ".git").exists():  # not a checkout: all but numba's cache files
            shutil.copytree(tree, target, ignore=shutil.ignore_patterns("__pycache__"))
            return target
        files = subprocess.run(["git", "-C", str(tree), "ls-files", "--cached", "--others", "--exclude-standard"],
                               check=True, capture_output=True, text=True).stdout.split()
        for name in files:  # what a clone of the tree, its changes committed, would hold
            if (tree / name).is_file():
                (target / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(tree / name, target / name)
    return target


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="configs/eclipse.yaml")
    parser.add_argument("--baseline", help="a git revision to measure beside this checkout's HEAD")
    parser.add_argument("--trees", nargs="+", type=Path, help="folders to copy and measure instead of revisions")
    parser.add_argument("--runs", default="cold,warm", help="the runs of each repeat: cold, warm, force")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    config = str(Path(args.config).resolve())
    kinds = args.runs.split(",")
    if args.trees:
        sources = {str(t): t.resolve() for t in args.trees}
    else:
        sources = {rev: None for rev in ([args.baseline] if args.baseline else []) + ["HEAD"]}
    names = list(sources)
    results = {(name, kind): [] for name in names for kind in kinds}
    with tempfile.TemporaryDirectory(prefix="sunshade-demo-") as temporary:
        work = Path(temporary)
        for _ in range(args.repeats):
            for name in names:
                tree = fresh_tree(name, sources[name], work)
                try:
                    for kind in kinds:
                        results[name, kind].append(demo_run(tree, config, work, force=kind == "force"))
                        print(f"{Path(name).name or name:>12} {kind}: " + ", ".join(
                            f"{k} {v:.1f}" for k, v in results[name, kind][-1].items()), flush=True)
                finally:
                    if sources[name] is None:
                        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                                       check=True)
                    else:
                        shutil.rmtree(tree, ignore_errors=True)
    print(f"\n{args.config}, medians of {args.repeats} (seconds; load and bare FFT [ms] at the start of the runs)")
    print(f"{'tree':>12} {'run':>5} {'wall':>7} {'cpu':>7} {'cycle':>7} {'frames':>7} {'video':>7} {'load':>5} "
          f"{'fft':>5}")
    for (name, kind), runs in results.items():
        m = {k: float(np.median([r[k] for r in runs])) for k in runs[0]}
        ratio = ""
        if len(names) > 1 and name == names[-1]:
            base = float(np.median([r["wall"] for r in results[names[0], kind]]))
            ratio = f"  {base / m['wall']:.2f}x faster than {names[0]}"
        if kind == "force" and "cold" in kinds:
            cold = float(np.median([r["wall"] for r in results[name, "cold"]]))
            ratio += f"  cold / force {cold / m['wall']:.2f}"
        label = Path(name).name or name
        print(f"{label:>12} {kind:>5} {m['wall']:7.1f} {m['cpu']:7.1f} {m['cycle']:7.1f} {m['frames']:7.1f} "
              f"{m['video']:7.1f} {m['load']:5.1f} {m['fft']:5.0f}{ratio}")


if __name__ == "__main__":
    main()
