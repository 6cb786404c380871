"""Benchmark of one 3-channel ground raster against the bare FFT work it needs.

    python benchmarks/bench_shadow.py            # n = 512, 1024, 2048, 4096
    python benchmarks/bench_shadow.py --quick    # n = 512, 1024

For each n and both layouts (docs/method.md, "The correlation") it times, in the same run and interleaved
so that a noisy shared machine hits both alike:

- ground: one call of ``shadow.ground_periodic`` / ``shadow.ground_isolated`` on a 3-channel
  sky raster, with the mask spectrum and the sky raster built beforehand (not timed);
- bare FFT: ``rfft2`` of a (3, *fft_shape) float32 array and ``irfft2`` back, scipy.fft, same
  thread count: the floor the ground raster cannot beat;

and prints their ratio (target: at most 1.5 for n >= 1024). Then it times the brute-force
direct sum (paper, eq. 2) at n = 32 and 64 and extrapolates it by n^4 to n = 1024.

Cases:

- periodic: an n x n tile that is also the ground window; the sky square is about 2n cells
  wide (pixel 0.05 m, height 8 m, alpha = atan(n pixel / height)), so the fold does real work,
  capped by ``shadow.MAX_SKY_CELLS`` (at n = 4096 the square is 4999 cells wide).
- isolated: a canopy n/2 wide under a window n/2 + 1 wide, so that the padded transforms are
  n x n (c + w - 1 = n), with the sky square wide enough that the plan is exact.

Timing: one warm-up call, then the median of several (``perf_counter``); FFT threads = cores
available to this process.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import scipy
import scipy.fft as sfft

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.core import geometry
from pipeline.core.geometry import Grid
from pipeline.ground import shadow
from pipeline.sky.base import UniformSky

PIXEL = 0.05  # [m]
HEIGHT = 8.0  # [m]
TARGET = 1.5  # ground / bare FFT, for n >= TARGET_FROM
TARGET_FROM = 1024
SIZES = (512, 1024, 2048, 4096)
QUICK_SIZES = (512, 1024)
BRUTE_SIZES = (32, 64)
EXTRAPOLATE_TO = 1024


def repeats_for(n: int) -> int:
    """Timed repeats after the warm-up: at least 5 up to 2048, 3 at 4096."""
    if n <= 1024:
        return 7
    if n <= 2048:
        return 5
    return 3


def time_interleaved(functions, repeats: int) -> list[float]:
    """Median wall time [s] of each function, called once to warm up, then ``repeats`` times
    in turn (f0, f1, f0, f1, ...) so that machine noise falls on all of them alike."""
    for f in functions:
        f()
    times = [[] for _ in functions]
    for _ in range(repeats):
        for f, ts in zip(functions, times):
            t0 = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t0)
    return [float(np.median(ts)) for ts in times]


def bare_fft(shape: tuple[int, int], workers: int):
    """The FFT work of one ground raster: rfft2 of (3, *shape) float32 and irfft2 back."""
    x = np.random.default_rng(1).random((3, *tuple(shape)), dtype=np.float32)

    def run():
        spectrum = sfft.rfft2(x, axes=(-2, -1), workers=workers)
        return sfft.irfft2(spectrum, s=shape, axes=(-2, -1), workers=workers)

    return run


FOLD_MS: dict = {}


def _seconds(call) -> float:
    started = time.perf_counter()
    call()
    return time.perf_counter() - started


def periodic_case(n: int, workers: int):
    """(ground call, fft shape, sky shape) of an n x n periodic tile with a ~2n-wide sky."""
    max_half = (int(np.sqrt(shadow.MAX_SKY_CELLS)) - 1) // 2
    half = min(n, max_half)
    alpha = np.arctan(half * PIXEL / HEIGHT)
    tile = Grid((0.0, n * PIXEL), PIXEL, (n, n))
    plan = shadow.plan_periodic(tile, tile, height=HEIGHT, alpha=alpha)
    m = np.random.default_rng(0).random((n, n), dtype=np.float32)
    spectrum = shadow.transmittance_spectrum(m, workers=workers)
    sky = UniformSky(np.ones(3))
    raster = sky.raster(plan.sky, fold_period=plan.tile_shape)  # rasterized folded, as render does
    mean = float(m.mean(dtype=np.float64))
    _check_dtypes(spectrum, raster)
    unfolded = sky.raster(plan.sky).weighted  # what folding an unfolded sky would add per frame
    start = geometry.sky_offset(plan.sky)
    FOLD_MS[n] = 1e3 * float(np.median([_seconds(lambda: geometry.fold(unfolded, start, plan.tile_shape))
                                         for _ in range(3)]))

    def run():
        return shadow.ground_periodic(raster, spectrum, plan, mean, workers=workers)

    _check_output(run(), (n, n))
    return run, plan.tile_shape, plan.sky.shape


def isolated_case(n: int, workers: int):
    """(ground call, fft shape, sky shape) of a canopy n/2 wide under a window n/2 + 1 wide."""
    c = n // 2
    w = n - c + 1  # c + w - 1 = n
    window = Grid((0.0, w * PIXEL), PIXEL, (w, w))
    canopy = Grid((0.0, w * PIXEL), PIXEL, (c, c))
    alpha = np.arctan((max(c, w) + 1) * PIXEL / HEIGHT)
    plan = shadow.plan_isolated(window, canopy, height=HEIGHT, alpha=alpha)
    if not plan.exact:
        raise RuntimeError(f"isolated plan at n = {n} is not exact")
    o = np.random.default_rng(0).random((c, c), dtype=np.float32)
    spectrum = shadow.occlusion_spectrum(o, plan, workers=workers)
    raster = UniformSky(np.ones(3)).raster(plan.sky)
    _check_dtypes(spectrum, raster)

    def run():
        return shadow.ground_isolated(raster, spectrum, plan, workers=workers)

    _check_output(run(), (w, w))
    return run, plan.fft_shape, plan.sky.shape


def _check_dtypes(spectrum, raster):
    if spectrum.dtype != np.complex64 or raster.weighted.dtype != np.float32:
        raise RuntimeError(
            f"expected complex64 / float32, got {spectrum.dtype} / {raster.weighted.dtype}"
        )


def _check_output(g, shape):
    if g.dtype != np.float32 or g.shape != (3, *tuple(shape)):
        raise RuntimeError(f"ground raster is {g.dtype} {g.shape}, expected float32 (3, {shape})")


def brute_force(e: np.ndarray, m: np.ndarray) -> np.ndarray:
    """g[k] = sum_i e[i] m[(k + i) mod n], one channel, periodic, O(n^4): numpy over k, a
    Python loop over the n^2 offsets i (each a view of the doubled mask, no copies)."""
    rows, cols = m.shape
    m2 = np.tile(m, (2, 2))
    g = np.zeros(m.shape, dtype=np.float64)
    for ir in range(rows):
        for ic in range(cols):
            g += e[ir, ic] * m2[ir : ir + rows, ic : ic + cols]
    return g


def run_brute(workers: int):
    """[(n, seconds, max relative error against the FFT form)] of the direct sum."""
    results = []
    for n in BRUTE_SIZES:
        rng = np.random.default_rng(n)
        e = rng.random((n, n)).astype(np.float64)
        m = rng.random((n, n)).astype(np.float64)
        (seconds,) = time_interleaved([lambda: brute_force(e, m)], repeats=5 if n <= 32 else 3)
        direct = brute_force(e, m)
        fft = sfft.irfft2(np.conj(sfft.rfft2(e)) * sfft.rfft2(m), s=(n, n), workers=workers)
        error = float(np.max(np.abs(direct - fft)) / np.max(np.abs(direct)))
        results.append((n, seconds, error))
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only n = 512, 1024")
    parser.add_argument("--workers", type=int, default=None, help="FFT threads (default: cores)")
    args = parser.parse_args(argv)

    cores = len(os.sched_getaffinity(0))
    workers = args.workers or cores
    sizes = QUICK_SIZES if args.quick else SIZES
    print(f"machine: {platform.machine()}, {cores} cores available (os.cpu_count {os.cpu_count()}),"
          f" FFT workers {workers}")
    print(f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__};"
          f" FFT: scipy.fft (pocketfft)")
    print(f"pixel {PIXEL} m, height {HEIGHT} m; ground = one 3-channel raster, spectra and sky"
          f" raster precomputed; bare FFT = rfft2 + irfft2 of (3, fft shape) float32")
    print(f"times: median after one warm-up ({', '.join(f'{n}: {repeats_for(n)}' for n in sizes)}"
          f" repeats), ground and bare FFT interleaved")
    print()

    header = (f"{'n':>5}  {'layout':<8}  {'fft shape':>11}  {'sky cells':>11}  {'ground ms':>10}"
              f"  {'bare FFT ms':>11}  {'ratio':>6}  {'<= ' + str(TARGET):>7}")
    print(header)
    print("-" * len(header))
    ground_at = {}
    misses = []
    for n in sizes:
        for layout, case in (("periodic", periodic_case), ("isolated", isolated_case)):
            run, fft_shape, sky_shape = case(n, workers)
            ground, bare = time_interleaved([run, bare_fft(fft_shape, workers)], repeats_for(n))
            del run
            ratio = ground / bare
            ground_at[(n, layout)] = ground
            if n >= TARGET_FROM:
                verdict = "yes" if ratio <= TARGET else "NO"
                if ratio > TARGET:
                    misses.append((n, layout, ratio))
            else:
                verdict = "-"
            print(f"{n:>5}  {layout:<8}  {fft_shape[0]:>5}x{fft_shape[1]:<5}"
                  f"  {sky_shape[0]:>5}x{sky_shape[1]:<5}  {ground * 1e3:>10.1f}"
                  f"  {bare * 1e3:>11.1f}  {ratio:>6.2f}  {verdict:>7}", flush=True)
    print()
    print("periodic skies are rasterized folded onto the tile (sky.raster(..., fold_period=...));")
    print("folding an unfolded sky square instead would add: "
          + ", ".join(f"n={n} {ms:.1f} ms" for n, ms in FOLD_MS.items()))
    print()
    if misses:
        print(f"target missed (ratio > {TARGET}, n >= {TARGET_FROM}): "
              + ", ".join(f"n={n} {layout} {ratio:.2f}" for n, layout, ratio in misses))
    else:
        print(f"target met: ratio <= {TARGET} for every n >= {TARGET_FROM}")
    print()

    print(f"brute-force direct sum, one channel, periodic (numpy over pixels, loop over offsets);"
          f" extrapolated by (n'/n)^4 to n' = {EXTRAPOLATE_TO}")
    header = (f"{'n':>5}  {'measured s':>11}  {'rel. error vs FFT':>17}"
              f"  {f'extrapolated to {EXTRAPOLATE_TO}, 1 ch':>26}  {'x3 channels':>12}")
    print(header)
    print("-" * len(header))
    fft_ref = ground_at.get((EXTRAPOLATE_TO, "periodic"))
    for n, seconds, error in run_brute(workers):
        extrapolated = seconds * (EXTRAPOLATE_TO / n) ** 4
        print(f"{n:>5}  {seconds:>11.4f}  {error:>17.1e}  {_duration(extrapolated):>26}"
              f"  {_duration(3 * extrapolated):>12}")
        last = extrapolated
    if fft_ref is not None:
        print(f"(n = {BRUTE_SIZES[0]} is dominated by the per-offset Python overhead;"
              f" n = {BRUTE_SIZES[-1]} is the better basis)")
        print(f"FFT ground raster at n = {EXTRAPOLATE_TO} (periodic, 3 channels,"
              f" sky {2 * EXTRAPOLATE_TO + 1} wide): {fft_ref * 1e3:.1f} ms; speed-up over the"
              f" brute force extrapolated from n = {BRUTE_SIZES[-1]} (3 channels):"
              f" {3 * last / fft_ref:.2g}x")
    return 0


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


if __name__ == "__main__":
    raise SystemExit(main())
