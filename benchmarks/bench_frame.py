"""The frame phase beyond the ground raster at 1280 x 720: resampling ground and sky in the
camera, haze and compositing, writing; and the foreground passes per cycle frame. Each beside
a baseline measured in the same run.

    python benchmarks/bench_frame.py [--frames 4] [--threads 2] [--config configs/eclipse.yaml --cache DIR]
    python benchmarks/bench_frame.py --table configs/*.yaml [--cache DIR] [--frames 3]

``--table``: for each config, its frame (``render_frame`` on the plan with its exposures metered, as a run
meters them before its frames; no writing; median of the first
``--frames`` frames after one unmeasured) over its bare FFT work (the median of its measures, one
just after each frame: on a shared machine a single measure moved by half), one Markdown row each (the
table of docs/accuracy.md, "Each config's frame over its FFT work"), after the bare 2048^2
rfft2 + irfft2 round trip of the same moment and the load average. Two measures of the FFT work:
the round trips at each layer's fine and coarse FFT shapes (below), and the frame's own FFT calls,
recorded as it makes them and made again bare (the same functions, shapes and threads on random
values: with a sun window a layer's coarse grid is correlated twice, the sky and the sun beyond the
window; an eclipse's sky adds its own). Beside them, the medians of the frame's stages (the ground
raster, the camera's resampling of ground and sky, haze and compositing) and the camera stage
over the frame's own FFT calls: where that alone passes 4, no saving in the ground raster brings
the frame within 4 of its FFTs.

Default grove (bench_cycle.CONFIG) with drifting clouds, the camera placed by default, 1280 x
720; or the first frames of ``--config`` as it stands (its cycle products in ``--cache``).
The ground is read as frames read it (the albedo laid by stochastic tiling). Baselines: one
bilinear lookup per pixel of a 2048^2 RGB raster with scipy.ndimage.map_coordinates (order 1,
no filtering); the bare FFT work of the ground raster (rfft2 + irfft2 of a 3-channel float32
stack at each layer's fine and coarse FFT shapes, as bench_sun); writing the same pixels as
raw .npy bytes.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import fft as sfft
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import reference
from bench_cycle import CONFIG
from bench_sun import median_seconds, round_trip_seconds

from pipeline.cache import store as cache
from pipeline.camera import composite
from pipeline.camera import pinhole as camera
from pipeline.canopy import grove as grove_geometry
from pipeline.config.parse import parse_config
from pipeline.core import io
from pipeline.foreground import trees as foreground
from pipeline.run.contents import frame_attributes
from pipeline.stages.cycle import cycle_phase
from pipeline.stages.frame import foreground_layer, irradiance_maps, render_frame
from pipeline.stages.ground import render_ground
from pipeline.stages.inputs import ground_albedo, grove_of
from pipeline.stages.lighting import reference_lighting, with_exposures
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load, resolve


def bilinear_baseline(view: camera.Camera, repeats=3) -> float:
    """Best time of one unfiltered bilinear lookup per pixel in a 2048^2 RGB raster. [s]"""
    raster = np.random.default_rng(0).random((3, 2048, 2048), dtype=np.float32)
    v, u = np.mgrid[0:view.height, 0:view.width]
    coords = np.stack([v * 2048.0 / view.height, u * 2048.0 / view.width]).astype(np.float32)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        for channel in raster:
            ndimage.map_coordinates(channel, coords, order=1)
        best = min(best, time.perf_counter() - t)
    return best


def bare_fft_seconds(plan, threads: int) -> float:
    """The bare FFT work of a plan's ground raster: rfft2 + irfft2 of a 3-channel float32 stack
    at each layer's fine and coarse FFT shapes (bench_sun's round trip), summed. [s]"""
    shapes = [getattr(part, "fft_shape", None) for layer in plan.layers for part in (layer.sun, layer.coarse)]
    return sum(round_trip_seconds(shape, threads) for shape in shapes if shape is not None)


FFT_CALLS = ("rfft2", "irfft2", "rfftn", "irfftn", "rfft", "irfft", "fft", "ifft", "fft2", "ifft2")
"""The scipy.fft functions whose calls ``frame_fft_calls`` records."""


def frame_fft_calls(render) -> list:
    """The FFTs ``render()`` calls: (scipy.fft function name, its array's shape and dtype, its other
    arguments), in order, recorded by wrapping the functions of scipy.fft for the call."""
    calls, originals = [], {name: getattr(sfft, name) for name in FFT_CALLS}

    def recorder(name):
        def record(x, *args, **kwargs):
            calls.append((name, np.shape(x), np.asarray(x).dtype, args, kwargs))
            return originals[name](x, *args, **kwargs)
        return record

    try:
        for name in FFT_CALLS:
            setattr(sfft, name, recorder(name))
        render()
    finally:
        for name, function in originals.items():
            setattr(sfft, name, function)
    return calls


def fft_calls_seconds(calls, repeats=3) -> float:
    """The bare work of recorded FFT calls (``frame_fft_calls``): each made again as it was (the same
    function, shape, dtype and arguments, threads included) on random values, best of ``repeats``,
    summed. [s]"""
    rng = np.random.default_rng(0)
    total = 0.0
    for name, shape, dtype, args, kwargs in calls:
        x = rng.random(shape).astype(dtype)
        if np.iscomplexobj(x):
            x += 1j * rng.random(shape).astype(x.real.dtype)
        function = getattr(sfft, name)
        total += min(timed(lambda: function(x, *args, **kwargs)) for _ in range(repeats))
    return total


STAGES = ("ground", "camera", "composite")
"""``render_frame``'s stages, as its ``timings`` name them (the table's medians of each)."""


def timed(f) -> float:
    """Seconds ``f()`` takes. [s]"""
    started = time.perf_counter()
    f()
    return time.perf_counter() - started


def table(paths, cache_root: Path, frames: int, threads: int) -> None:
    """Print a Markdown row per config: its frame over its bare FFT work."""
    plane = np.random.default_rng(0).random((2048, 2048), dtype=np.float32)
    trip = min(timed(lambda: sfft.irfft2(sfft.rfft2(plane, workers=threads), s=plane.shape, workers=threads))
               for _ in range(5))
    print(f"load average {os.getloadavg()[0]:.1f}; bare rfft2 + irfft2 of one float32 2048^2 plane "
          f"({threads} workers, best of 5): {trip * 1e3:.1f} ms", flush=True)
    print("| config | camera | frame, median [ms] | bare FFT work [ms] | frame / bare FFT | its FFT calls [ms] "
          "| frame / its FFT calls | ground, camera, composite [ms] | camera / its FFT calls | load |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        config = load(path)
        plan = plan_run(config)
        store = cache.Cache(cache_root / Path(path).stem)
        cycle_phase(plan, store, jobs=2, workers=1,
                    cycle_frames={f % config.canopy.cycle for f in range(frames + 1)})
        plan = with_exposures(plan, range(frames + 1))  # a run meters its frames once, before them
        render_frame(plan, 0, store=store, workers=threads)  # loads, compiles: not measured
        each, bares, own, stages = [], [], [], []
        for i in range(frames):  # each frame's bare FFT work timed just after it, under the same load
            stages.append({})
            calls = frame_fft_calls(lambda i=i: each.append(timed(lambda: render_frame(
                plan, i + 1, store=store, workers=threads, timings=stages[-1]))))
            bares.append(bare_fft_seconds(plan, threads))
            own.append(fft_calls_seconds(calls))
        whole, best, bare, mine = float(np.median(each)), min(each), float(np.median(bares)), float(np.median(own))
        ground, view, composite = (float(np.median([s.get(k, 0.0) for s in stages])) for k in STAGES)
        print(f"| {Path(path).stem} | {plan.camera.width} x {plan.camera.height} | {whole * 1e3:.0f} "
              f"(best {best * 1e3:.0f}) | {bare * 1e3:.0f} | {whole / bare:.1f} (best {best / bare:.1f}) | "
              f"{mine * 1e3:.0f} ({len(calls)} calls) | {whole / mine:.1f} (best {best / mine:.1f}) | "
              f"{ground * 1e3:.0f}, {view * 1e3:.0f}, {composite * 1e3:.0f} | {view / mine:.1f} | "
              f"{os.getloadavg()[0]:.1f} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--config", default=None, help="a config to time instead of the grove")
    parser.add_argument("--cache", default=None, help="its cache folder (default: a fresh one)")
    parser.add_argument("--table", nargs="+", metavar="CONFIG", help="a row per config: frame / bare FFT")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sunshade-bench-"))
    if args.table:
        try:
            table(args.table, Path(args.cache) if args.cache else work, args.frames, args.threads)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        return
    try:
        config_dict = dict(CONFIG)
        config_dict["sky"] = {**CONFIG["sky"], "clouds": {"cover": 0.4}}
        config_dict["canopy"] = {**CONFIG["canopy"], "flutter": {"cycle": args.frames}}
        config_dict["animation"] = {"frames": args.frames}
        config = load(args.config) if args.config else resolve(parse_config(config_dict, work))
        plan = plan_run(config)
        store = cache.Cache(Path(args.cache) if args.cache and args.config else work / "cache")
        cycle_phase(plan, store, jobs=2, workers=1)
        view = plan.camera
        light = reference_lighting(plan)
        print(f"camera {view.width} x {view.height}; ground raster {plan.sun_window.shape} at "
              f"{plan.sun_window.pixel} m, coarse {plan.window.shape} at {plan.window.pixel} m")

        skies = [plan.sky.at(plan.scenes[f]) for f in range(args.frames)]
        grounds = [render_ground(plan, f, store=store, workers=args.threads, sky=skies[f], outer=True)
                   for f in range(args.frames)]
        albedo = ground_albedo(config.ground)  # as render_frame reads it
        backgrounds = {}

        def resample(i):
            backgrounds[i] = camera.background(view, irradiance=irradiance_maps(plan, grounds[i]),
                                               albedo=albedo, sky=skies[i])

        frames = {}

        def blend(i):
            background, distance = backgrounds[i]
            rays = camera.pixel_rays(view)
            rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
            t, sky_haze, atmosphere = reference.aerial_perspective(
                distance, rays, length=config.sky.haze, sun_direction=light.sun_direction,
                sun_irradiance=light.sun_irradiance, sky_irradiance=light.sky_irradiance)
            fg = foreground_layer(plan, i, store, light)
            if fg is None:  # no trees in front (as render_frame)
                empty = np.zeros_like(background)
                sun, sky, alpha, region = empty, empty, empty[..., 0], (slice(None), slice(None))
            else:
                sun, sky, alpha, region = fg.sun, fg.sky, fg.alpha, fg.region
            behind = t[..., None] * background + sky_haze
            frames[i] = behind + np.float32(0.0)
            frames[i][region] = composite.composite_frame(behind[region], sun_pass=sun, sky_pass=sky, alpha=alpha,
                                                          sun_fraction=0.7, atmosphere=atmosphere[region])

        result = render_frame(plan, 0, store=store, workers=args.threads)

        def write(i):
            io.write_exr(work / f"f.{i:04d}.exr", frames[i], frame_attributes(config, result, config.digest()),
                         half=True)
            io.write_png(work / f"f.{i:04d}.png", composite.display_codes(frames[i], exposure=result.exposure))

        def write_raw(i):
            np.save(work / f"raw.{i}.npy", frames[i])

        def ground(i):
            render_ground(plan, i, store=store, workers=args.threads, sky=skies[i], outer=True)

        def whole(i):
            render_frame(plan, i, store=store, workers=args.threads)

        grove, flutter = grove_of(config.canopy)

        def passes(i):
            leaves = grove_geometry.leaves_at(grove, flutter, i)
            leaf_v, wood_v = foreground.sun_visibility(leaves, grove.wood, sun_point=np.array(plan.projection))
            foreground.tree_passes(leaves, grove.wood, view, sun_direction=light.sun_direction,
                                   sun_irradiance=np.ones(3), sky_irradiance=np.ones(3),
                                   leaf_sun_visibility=leaf_v, wood_sun_visibility=wood_v)

        n = args.frames
        t_resample, t_blend, t_write = (median_seconds(f, n) for f in (resample, blend, write))
        t_raw, t_ground, t_whole = (median_seconds(f, n) for f in (write_raw, ground, whole))
        t_passes = median_seconds(passes, n) if config.foreground.model == "trees" else float("nan")
        base = bilinear_baseline(view)
        bare = bare_fft_seconds(plan, args.threads)
        t_exr = median_seconds(lambda i: io.write_exr(work / f"e.{i:04d}.exr", frames[i], half=True), n)
        t_png = median_seconds(lambda i: io.write_png(
            work / f"p.{i:04d}.png", composite.display_codes(frames[i], exposure=result.exposure)), n)
        t_codes = median_seconds(lambda i: composite.display_codes(frames[i], exposure=result.exposure), n)
        t_array = median_seconds(lambda i: io.half_dither(frames[i].shape) + composite.display(
            frames[i], exposure=result.exposure), n)
        print(f"resampling ground and sky: {t_resample * 1e3:.0f} ms; unfiltered bilinear lookup "
              f"of a 2048^2 RGB raster: {base * 1e3:.0f} ms; ratio {t_resample / base:.1f}")
        print(f"haze and compositing: {t_blend * 1e3:.0f} ms")
        print(f"display codes: compiled {t_codes * 1e3:.1f} ms; the array display and a dither's sum "
              f"{t_array * 1e3:.1f} ms")
        print(f"writing half EXR + PNG: {t_write * 1e3:.0f} ms (EXR {t_exr * 1e3:.0f}, PNG with display "
              f"{t_png * 1e3:.0f}); raw .npy of the same pixels: {t_raw * 1e3:.1f} ms; ratio {t_write / t_raw:.0f}")
        print(f"ground raster: {t_ground * 1e3:.0f} ms; whole frame (no writing): {t_whole * 1e3:.0f} ms "
              f"(median of {n} frames, {args.threads} FFT threads); bare FFT work of the ground raster "
              f"{bare * 1e3:.0f} ms: frame / bare FFT {t_whole / bare:.1f}, beyond the ground raster "
              f"{(t_whole - t_ground) / bare:.1f}")
        print(f"foreground passes per cycle frame (sun visibility + passes, "
              f"{len(grove.leaves.center)} leaves): {t_passes:.3f} s")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
