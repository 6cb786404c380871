"""The two-scale sun per frame: the fine sun correlation and the whole ground raster, beside
the bare FFT work they need, measured in the same run.

    python benchmarks/bench_sun.py [--frames 6] [--threads 2]

Default grove under a procedural sky with a partial eclipse; coarse ground window 1024^2 at
0.02 m, fine sun window 1536^2 at 0.005 m. The cycle products are computed first (not
timed); each frame then loads its cached spectra, rasterizes its sky and sun kernel and
correlates. Bare FFT: a 3-channel rfft2 + irfft2 round trip at each plan's transform size.
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

from bench_cycle import CONFIG

from pipeline.cache import store as cache
from pipeline.config.parse import parse_config
from pipeline.ground import shadow
from pipeline.sky.sun_kernel import sun_kernel
from pipeline.stages.cycle import cycle_item, cycle_phase
from pipeline.stages.ground import render_ground
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import resolve
from pipeline.stages.scene import (
    load_sky,
    scene_at,
)


def round_trip_seconds(shape, workers, repeats=3) -> float:
    """Best time of rfft2 + irfft2 of a (3, *shape) float32 stack. [s]"""
    a = np.random.default_rng(0).random((3, *tuple(shape)), dtype=np.float32)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        sfft.irfft2(sfft.rfft2(a, axes=(-2, -1), workers=workers), s=shape, axes=(-2, -1),
                    workers=workers)
        best = min(best, time.perf_counter() - t)
    return best


def median_seconds(f, repeats) -> float:
    times = []
    for i in range(repeats):
        t = time.perf_counter()
        f(i)
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-"))
    try:
        config_dict = dict(CONFIG)
        config_dict["sky"] = {**CONFIG["sky"], "moon": {"offset_start": [0.3, 0.1],
                                                         "offset_end": [0.1, 0.0]}}
        config_dict["canopy"] = {**CONFIG["canopy"], "flutter": {"cycle": args.frames}}
        config_dict["animation"] = {"frames": args.frames}
        config = resolve(parse_config(config_dict, work))
        plan = plan_run(config)
        layer = plan.layers[0]
        store = cache.Cache(work / "cache")
        cycle_phase(plan, store, jobs=2, workers=1)
        print(f"coarse window {plan.window.shape} (FFT {layer.coarse.fft_shape}); fine window "
              f"{plan.sun_window.shape} (fine mask {layer.sun.mask.shape}, FFT {layer.sun.fft_shape})")

        bare_fine = round_trip_seconds(layer.sun.fft_shape, args.threads)
        bare_coarse = round_trip_seconds(layer.coarse.fft_shape, args.threads)
        q = plan.sun_window.pixel / layer.height
        items = [cycle_item(plan, 0, f, store) for f in range(args.frames)]
        skies = [load_sky(config.sky, scene_at(config, f)) for f in range(args.frames)]
        kernels = [sun_kernel(s, q) for s in skies]

        def fine(i):
            shadow.ground_sun(kernels[i], items[i].fine, layer.sun, workers=args.threads)

        def kernel(i):
            sun_kernel(skies[i], q)

        def whole(i):
            render_ground(plan, i, store=store, workers=args.threads)

        t_fine = median_seconds(fine, args.frames)
        t_kernel = median_seconds(kernel, args.frames)
        t_whole = median_seconds(whole, args.frames)
        print(f"fine sun correlation: {t_fine * 1e3:.0f} ms; bare 3-channel round trip at "
              f"{layer.sun.fft_shape}: {bare_fine * 1e3:.0f} ms; ratio {t_fine / bare_fine:.2f}")
        print(f"sun kernel rasterization: {t_kernel * 1e3:.1f} ms ({kernels[0].weighted.shape[1:]} cells)")
        bare = bare_fine + bare_coarse
        print(f"whole ground raster per frame: {t_whole * 1e3:.0f} ms; bare FFT work (coarse "
              f"{bare_coarse * 1e3:.0f} + fine {bare_fine * 1e3:.0f} ms) {bare * 1e3:.0f} ms; "
              f"ratio {t_whole / bare:.2f}  ({args.threads} FFT threads, median of {args.frames} frames)")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
