"""Colour through OpenColorIO: what output.colorspace and output.view add to writing a frame
(docs/runs.md, "Colour"; docs/accuracy.md, "Colour through OpenColorIO").

    python benchmarks/bench_colour.py [--repeat 7] [--size 1280x720]

On one frame of lognormal radiance: the built-in filmic curve to 8-bit codes (the baseline,
``composite.display_codes``), the EXR layers' conversion to ACEScg (``ocio.to_working``) and the
ACES 2.0 SDR sRGB view (``composite.display_view``), each the median of --repeat after one warm-up,
and their ratios to the baseline; then importing PyOpenColorIO in a fresh process beside a bare
``python -c pass`` (medians of --repeat).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.camera.composite import display_codes, display_view
from pipeline.core import ocio

VIEW = ("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)")


def median_seconds(call, repeat: int) -> float:
    """Median wall time of ``call()`` over ``repeat`` runs after one warm-up. [s]"""
    call()
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        call()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def process_seconds(code: str, repeat: int) -> float:
    """Median wall time of a fresh interpreter running ``code``. [s]"""
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True)
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--size", default="1280x720")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    radiance = np.random.default_rng(0).lognormal(-1.0, 1.0, (height, width, 3)).astype(np.float32)
    source = f"ocio://{ocio.config_name(ocio.BUILTIN_CONFIG)}"
    timed = {
        "filmic codes (baseline)": lambda: display_codes(radiance, exposure=1.0),
        "to ACEScg (EXR layer)": lambda: ocio.to_working(radiance, source, "ACEScg"),
        "ACES 2.0 sRGB view": lambda: display_view(radiance, exposure=1.0, source=source, view=VIEW),
    }
    print(f"{width} x {height} px, {source}, medians of {args.repeat}")
    seconds = {name: median_seconds(call, args.repeat) for name, call in timed.items()}
    base = seconds["filmic codes (baseline)"]
    for name, value in seconds.items():
        print(f"  {name:26s} {1000 * value:8.1f} ms  x{value / base:6.2f}")
    bare = process_seconds("pass", args.repeat)
    ocio_import = process_seconds("import PyOpenColorIO", args.repeat)
    print(f"  python -c pass {1000 * bare:.0f} ms; import PyOpenColorIO {1000 * ocio_import:.0f} ms "
          f"(+{1000 * (ocio_import - bare):.0f} ms)")


if __name__ == "__main__":
    main()
