"""Every hostile config of tests/test_hostile.py through ``sunshade check`` and ``sunshade render``
as real processes: exit code, wall time, peak resident memory and stderr lines, beside a bare
``python -c "import pipeline.cli"`` (the start-up every command pays). Target (issue 16): exit
2, one line, nothing written, within 3 s and 300 MB.

    python benchmarks/bench_bad_inputs.py

The peak memory is measured by a small parent process (``PEAK`` in the tests): Linux counts a
forked child's peak from the process it was forked from.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from scenes import write_inputs  # noqa: E402
from test_hostile import CASES, PEAK  # noqa: E402


def measured(args, cwd) -> tuple[int, float, float, int]:
    """(exit code, wall time [s], peak memory [MB], stderr lines) of one command."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", PEAK, sys.executable, *args], cwd=cwd,
                          capture_output=True, text=True)
    code, peak = (int(v) for v in done.stdout.split()[-2:])
    return code, time.perf_counter() - started, peak / 1e6, len(done.stderr.strip().splitlines())


def main():
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        code, seconds, peak, _ = measured(["-c", "import pipeline.cli"], ROOT)
        print(f"{'bare start-up':<28} {seconds:5.2f} s {peak:5.0f} MB")
        worst = (0.0, 0.0)
        for name, text, _ in CASES:
            write_inputs(folder)
            (folder / "config.yaml").write_bytes(text)
            row = f"{name:<28}"
            for command in (["check", "config.yaml"],
                            ["render", "config.yaml", "--output", "out/run", "--cache", "out/cache"]):
                code, seconds, peak, lines = measured(["-m", "pipeline.cli", *command], folder)
                worst = (max(worst[0], seconds), max(worst[1], peak))
                row += f" | {command[0]}: exit {code}, {seconds:4.2f} s, {peak:4.0f} MB, {lines} line"
            row += " | wrote nothing" if not (folder / "out").exists() else " | WROTE out/"
            print(row)
        print(f"worst: {worst[0]:.2f} s, {worst[1]:.0f} MB")


if __name__ == "__main__":
    main()
