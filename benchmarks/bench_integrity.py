"""What the integrity checks cost: cache items checked on read against the frame phase, the
digest of each frame written, and a resume that checks the frames it skips.

    python benchmarks/bench_integrity.py [CONFIG] [--frames 0,1,2] [--repeat 5]
    python benchmarks/bench_integrity.py CONFIG --run FOLDER --cache DIR [--repeat 5]

1. Cache checks (issue 16). In one process, with the cycle products of the frames in a fresh
   cache: each frame rendered (``frame.render_frame``) with its cache items already checked
   in this process (the baseline: sizes, headers and a stat, what every later read costs) and
   with ``items.forget_verified()`` before it (every item's CRC-32 computed again: the worst
   case; a run checks each item once per worker process, so once per ``cycle`` frames), the
   two alternated ``--repeat`` times, in turn first; beside them the checksums alone of the
   items a frame reads. Medians over frames and repeats.
2. Frame digests (issue 19): the BLAKE2b of the EXR and PNG a frame writes, beside the frame.
3. With ``--run FOLDER`` (a finished ``sunshade render CONFIG --output FOLDER``): the wall time
   of a resume with nothing to do (sizes, inodes and times against index.json), of one after
   every frame file was touched (every frame hashed again, as after a copy), of
   ``--verify`` (every frame and cache item read), beside a bare ``import pipeline.cli.main``.
   Medians of ``--repeat`` processes; ``--cache`` names the run's cache.

CONFIG defaults to configs/sun-and-shade.yaml: its cache items per frame (the canopy's spectra
and the foreground passes at 1280 x 720) are the most bytes to check of the configs.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.cache import items as cache_store
from pipeline.cache import store as cache
from pipeline.core.cores import default_workers
from pipeline.run.folder import parse_frames
from pipeline.run.index import file_digest
from pipeline.run.render import _frame_task
from pipeline.stages.cycle import cycle_phase
from pipeline.stages.frame import render_frame
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def seconds(call) -> float:
    started = time.perf_counter()
    call()
    return time.perf_counter() - started


def sunshade(*args) -> float:
    """Wall seconds of one real ``sunshade`` process (exit code 0 or 1)."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pipeline.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True)
    if done.returncode not in (0, 1):
        raise SystemExit(done.stderr)
    return time.perf_counter() - started


def cache_checks(config, frames, repeat) -> None:
    plan = plan_run(config)
    store = cache.Cache(cache.cache_dir(None))
    workers = default_workers()
    cycle_phase(plan, store, jobs=1, workers=workers,
                cycle_frames={f % config.canopy.cycle for f in frames})
    trusted, checked, sums, size = [], [], [], 0
    for turn in range(repeat):
        for frame in frames:
            reader = cache.Cache(store.root)
            for forget in ((False, True) if turn % 2 == 0 else (True, False)):  # both orders
                if forget:
                    cache_store.forget_verified()
                (checked if forget else trusted).append(seconds(
                    lambda: render_frame(plan, frame, store=reader, workers=workers)))
            sums.append(seconds(lambda: [reader.recheck(item, stamp, fresh=True, repair=False)
                                         for item, stamp in reader.served.items()]))
            size = sum(reader.item_path(*item.split("/")).joinpath(file).stat().st_size
                       for item, stamp in reader.served.items() for file in stamp)
    base, worst, crc = (statistics.median(v) for v in (trusted, checked, sums))
    paired = statistics.median(c - t for c, t in zip(checked, trusted))
    print(f"cache checks, {config.path.name}, frames {','.join(map(str, frames))}, "
          f"{len(trusted)} renders each, {workers} FFT threads:")
    print(f"  frame, items checked before (baseline) : {base * 1e3:8.1f} ms (median)")
    print(f"  frame, every item checked on this read : {worst * 1e3:8.1f} ms (median), "
          f"{100 * (worst - base) / base:+.1f} % of the baseline; median of the paired "
          f"differences {paired * 1e3:+.1f} ms, {100 * paired / base:+.1f} %")
    print(f"  the checksums alone, {size / 2**20:.1f} MiB of items : {crc * 1e3:8.1f} ms (median), "
          f"{100 * crc / base:.1f} % of the baseline frame; a run checks each item once per "
          f"worker: {100 * crc / base / config.canopy.cycle:.2f} % per frame over a cycle")


def frame_digests(config, frames, repeat) -> None:
    plan = plan_run(config)
    folder = Path(tempfile.mkdtemp(prefix="sunshade-bench-digest-"))
    from dataclasses import replace

    config = replace(config, output=replace(config.output, folder=folder))
    root = str(cache.cache_dir(None))
    totals, digests = [], []
    for _ in range(repeat):
        for frame in frames:
            start = time.perf_counter()
            entry = _frame_task(config, plan, frame, root, config.digest(), default_workers()).entry
            totals.append(time.perf_counter() - start)
            paths = [folder / entry["files"][k]["name"] for k in ("exr", "png")]
            digests.append(seconds(lambda: [file_digest(p) for p in paths]))
    shutil.rmtree(folder, ignore_errors=True)
    total, digest = statistics.median(totals), statistics.median(digests)
    print(f"frame digests: a frame rendered and written {total * 1e3:.1f} ms (median), BLAKE2b of "
          f"its EXR and PNG {digest * 1e3:.2f} ms: {100 * digest / total:.2f} %")


def resumes(config_path, folder, cache_root, repeat) -> None:
    args = ("render", config_path, "--output", folder, "--cache", cache_root)
    files = sorted(p for p in folder.iterdir() if p.suffix in (".exr", ".png"))
    bare = statistics.median(seconds(lambda: subprocess.run([sys.executable, "-c", "import pipeline.cli.main"],
                                                            cwd=ROOT, check=True))
                             for _ in range(repeat))
    noop = statistics.median(sunshade(*args) for _ in range(repeat))
    touched = []
    for _ in range(repeat):
        for path in files:
            os.utime(path)
        touched.append(sunshade(*args))
    verify = statistics.median(sunshade(*args, "--verify") for _ in range(repeat))
    print(f"resume of {folder} ({len(files)} frame files, {sum(p.stat().st_size for p in files) / 2**20:.0f} MiB), "
          f"median of {repeat} processes:")
    print(f"  bare 'import pipeline.cli.main'                : {bare:6.2f} s")
    print(f"  nothing to do (stat against index.json)   : {noop:6.2f} s")
    print(f"  every frame file touched (all hashed)     : {statistics.median(touched):6.2f} s")
    print(f"  render --verify (frames and items read)   : {verify:6.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "sun-and-shade.yaml"))
    parser.add_argument("--frames", default="0,1,2")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--run", default=None, help="a finished run folder of CONFIG: time resumes")
    parser.add_argument("--cache", default=None, help="with --run: the run's cache folder")
    args = parser.parse_args()
    config = load(args.config)
    if args.run:
        resumes(Path(args.config).absolute(), Path(args.run).absolute(),
                cache.cache_dir(args.cache), args.repeat)
        return
    frames = parse_frames(args.frames, config.animation.frames)
    scratch = None if cache.ENV_VAR in os.environ else tempfile.mkdtemp(prefix="sunshade-bench-cache-")
    os.environ.setdefault(cache.ENV_VAR, scratch or "")
    try:
        cache_checks(config, frames, args.repeat)
        frame_digests(config, frames, max(1, args.repeat // 2))
    finally:  # nothing of ours left behind
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
