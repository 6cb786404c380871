"""Start-up: how long `sunshade --help` and a resume with nothing to do take beside the bare
interpreter's start, each a real process (issue 14, item 4; docs/accuracy.md, "Speed").

    python benchmarks/bench_startup.py [CONFIG] [--repeat 7]

CONFIG (default configs/eclipse.yaml) is rendered once with --preview into a temporary folder
(the first run takes its normal time), then run again, finding every frame done. Prints the
median of each over --repeat runs, and each minus the bare `python -c pass`.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def seconds(*argv) -> float:
    """Wall time of one process. [s]"""
    started = time.perf_counter()
    subprocess.run(argv, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "eclipse.yaml"))
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-startup-"))
    try:
        render = [sys.executable, "-m", "pipeline.cli", "render", args.config, "--preview",
                  "--cache", work / "cache", "--output", work / "out"]
        first = seconds(*render)
        times = {
            "bare interpreter (python -c pass)": [sys.executable, "-c", "pass"],
            "sunshade --help": [sys.executable, "-m", "pipeline.cli", "--help"],
            "resume, nothing to do": render,
        }
        medians = {name: statistics.median(seconds(*argv) for _ in range(args.repeat))
                   for name, argv in times.items()}
    finally:
        shutil.rmtree(work, ignore_errors=True)
    bare = medians["bare interpreter (python -c pass)"]
    print(f"{args.config} --preview: first render {first:.1f} s; medians of {args.repeat} runs:")
    for name, value in medians.items():
        print(f"  {name:<36} {value:6.3f} s   {value - bare:+.3f} s over the bare interpreter")


if __name__ == "__main__":
    main()
