"""The cycle phase of the default grove: masks and spectra for every cycle frame, cold and warm.

    python benchmarks/bench_cycle.py [--jobs 2] [--cycle 48]

Default grove (3 trees x 12,000 leaves), sun at 60 degrees; coarse ground window 1024^2 at
0.02 m, fine sun window 1536^2 at 0.005 m. Prints the cold time (empty cache), the warm time
(everything cached), the time to load one cycle frame's spectra, and the cache's size on
disk, beside the bare FFT work of one cycle frame measured in the same run.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.fft as sfft

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.cache import store as cache
from pipeline.config.parse import parse_config
from pipeline.stages.cycle import cycle_params, cycle_phase, layer_masks
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import resolve

CONFIG = {
    "canopy": {"height": 8.0, "layout": "isolated",
               "trees": {"count": 3, "seed": 7, "crown_radius": 4.0, "leaves_per_tree": 12000,
                         "leaf_length": 0.08},
               "flutter": {"cycle": 48, "swing": 12.0, "twist": 20.0}},
    "sky": {"model": "procedural", "turbidity": 3.0, "sun": {"elevation": 60.0, "azimuth": 180.0}},
    "ground": {"window": [-10.24, -10.24, 10.24, 10.24], "pixel": 0.02,
               "sun_window": [-3.84, -3.84, 3.84, 3.84], "sun_pixel": 0.005},
    "animation": {"frames": 48},
}


def bare_fft_seconds(shape, repeats=3) -> float:
    """rfft2 of one float32 raster of ``shape``, best of ``repeats``. [s]"""
    a = np.random.default_rng(0).random(shape, dtype=np.float32)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        sfft.rfft2(a, axes=(-2, -1), workers=1)
        best = min(best, time.perf_counter() - t)
    return best


def folder_bytes(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--cycle", type=int, default=48)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-"))
    try:
        CONFIG["canopy"]["flutter"]["cycle"] = args.cycle
        plan = plan_run(resolve(parse_config(CONFIG, work)))
        layer = plan.layers[0]
        store = cache.Cache(work / "cache")
        print(f"coarse window {plan.window.shape}, canopy mask {layer.canopy.shape} -> FFT "
              f"{layer.coarse.fft_shape}; fine window {plan.sun_window.shape}, fine mask "
              f"{layer.sun.mask.shape} -> FFT {layer.sun.fft_shape}")
        fft = bare_fft_seconds(layer.coarse.fft_shape) + bare_fft_seconds(layer.sun.fft_shape)
        t = time.perf_counter()
        layer_masks(plan, 0, 0)
        masks = time.perf_counter() - t
        print(f"one cycle frame, one process: masks {masks:.2f} s; bare rfft2 of both {fft * 1e3:.0f} ms")

        t = time.perf_counter()
        computed = cycle_phase(plan, store, jobs=args.jobs, workers=1)
        cold = time.perf_counter() - t
        t = time.perf_counter()
        again = cycle_phase(plan, store, jobs=args.jobs, workers=1)
        warm = time.perf_counter() - t
        print(f"cycle phase, {args.cycle} frames, --jobs {args.jobs}: cold {cold:.1f} s "
              f"({computed} items; target 60 s), warm {warm:.2f} s ({again} computed; target 2 s); "
              f"cold / (cycle x bare FFT) = {cold / (args.cycle * fft):.1f}")

        params = cycle_params(plan, 0, 1)
        t = time.perf_counter()
        item = store.get("spectra", params)
        total = sum(float(np.abs(a).sum()) for a in item.values())
        read = time.perf_counter() - t
        print(f"load one cycle frame's spectra and read them through: {read * 1e3:.1f} ms "
              f"({sum(a.nbytes for a in item.values()) / 2**20:.1f} MiB; checksum {total:.3g})")
        size = folder_bytes(work / "cache")
        print(f"cache on disk: {size / 2**20:.0f} MiB for {args.cycle} cycle frames "
              f"({size / 2**20 / args.cycle:.1f} MiB each)")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
