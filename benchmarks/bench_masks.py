"""One cycle frame's leaf masks and their spectra: the compiled rasteriser against the array
rasteriser it replaced (kept in tests/test_canopy.py as the reference), in the same process.

    python benchmarks/bench_masks.py [CONFIG ...] [--frames 5] [--preview]

CONFIG defaults to configs/eclipse.yaml (160,000 leaves). For each config with trees, every
layer's coarse and fine masks and their spectra (what ``cycle.cycle_item`` computes on a miss)
for cycle frames 0, 1, ... with either rasteriser, one process, one FFT thread. Prints the
median wall and CPU seconds per cycle frame of each, their ratio, and the largest difference
between the two masks. The first call, which loads the compiled loops, is timed apart.
``--preview`` measures the config as ``sunshade render --preview`` makes it. ``--opencv`` also
draws the first config's fine mask with OpenCV's ``fillPoly`` (``LINE_AA``, 4 bits of sub-pixel
shift, each leaf a 24-gon; needs opencv-python-headless) and compares single leaves' coverage.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_canopy import reference_rasterize

from pipeline.canopy import grove as grove_geometry
from pipeline.canopy import rasteriser
from pipeline.config.preview import preview
from pipeline.ground import shadow
from pipeline.stages.cycle import layer_masks
from pipeline.stages.inputs import grove_of
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def cycle_frame(config, plan, frame):
    """Every layer's masks and spectra at ``frame``; returns the masks."""
    masks = []
    for index, lp in enumerate(plan.layers):
        made = layer_masks(plan, index, frame)
        coarse, fine = made.coarse, made.fine
        if isinstance(lp.coarse, shadow.IsolatedPlan):
            shadow.occlusion_spectrum(1.0 - coarse, lp.coarse, workers=1)
        else:
            shadow.transmittance_spectrum(coarse, workers=1)
        if fine is not None:
            shadow.fine_mask_spectrum(fine, lp.sun, workers=1)
        masks += [coarse] + ([fine] if fine is not None else [])
    return masks


def timed(config, plan, frames, rasterize):
    """(median wall s, median CPU s, masks of every frame) with ``rasterize`` in place."""
    rasteriser.rasterize_transmittance, saved = rasterize, rasteriser.rasterize_transmittance
    try:
        walls, cpus, masks = [], [], []
        for frame in frames:
            wall, cpu = time.perf_counter(), time.process_time()
            masks.append(cycle_frame(config, plan, frame))
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
    finally:
        rasteriser.rasterize_transmittance = saved
    return float(np.median(walls)), float(np.median(cpus)), masks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=[str(ROOT / "configs" / "eclipse.yaml")])
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--preview", action="store_true")
    parser.add_argument("--opencv", action="store_true")
    args = parser.parse_args()
    for path in args.configs:
        config = load(path)
        config = preview(config) if args.preview else config
        if config.canopy.trees is None:
            print(f"{Path(path).name}: no trees, nothing to rasterise")
            continue
        plan = plan_run(config)
        grove_of(config.canopy)  # grown once per process in a run too
        t = time.perf_counter()
        cycle_frame(config, plan, config.canopy.cycle - 1)
        first = time.perf_counter() - t
        frames = range(min(args.frames, config.canopy.cycle))
        new_wall, new_cpu, new = timed(config, plan, frames, rasteriser.rasterize_transmittance)
        old_wall, old_cpu, old = timed(config, plan, frames, reference_rasterize)
        diff = max(float(np.abs(a - b).max()) for m, n in zip(new, old) for a, b in zip(m, n))
        leaves = config.canopy.trees.count * config.canopy.trees.leaves_per_tree
        shapes = ", ".join(f"{lp.canopy.shape}" + (f" + fine {lp.sun.mask.shape}" if lp.sun else "")
                           for lp in plan.layers)
        print(f"{Path(path).name}: {leaves} leaves, masks {shapes}; per cycle frame (median of "
              f"{len(frames)}): array rasteriser {old_wall:.3f} s wall, {old_cpu:.3f} s CPU; compiled "
              f"{new_wall:.3f} s wall, {new_cpu:.3f} s CPU; ratio {old_wall / new_wall:.1f} wall, "
              f"{old_cpu / new_cpu:.1f} CPU; first call {first:.2f} s; max |difference| {diff:.1e}")
        if args.opencv and path == args.configs[0]:
            compare_opencv(config, plan)


def opencv_mask(shapes, grid, sides=24, shift=4):
    """Transmittance of the ellipses of ``shapes`` by cv2.fillPoly with anti-aliasing (8-bit)."""
    import cv2

    t = 2 * np.pi * np.arange(sides) / sides
    points = (shapes.center[:, None, :] + np.cos(t)[None, :, None] * shapes.axis_a[:, None, :]
              + np.sin(t)[None, :, None] * shapes.axis_b[:, None, :])
    u = (points[..., 0] - grid.origin[0]) / grid.pixel - 0.5  # OpenCV's pixel centres are integers
    v = (grid.origin[1] - points[..., 1]) / grid.pixel - 0.5
    polygons = list(np.round(np.stack([u, v], -1) * (1 << shift)).astype(np.int32))
    image = np.zeros(grid.shape, np.uint8)
    cv2.fillPoly(image, polygons, 255, cv2.LINE_AA, shift)
    return 1.0 - image / 255.0


def compare_opencv(config, plan) -> None:
    from test_canopy import random_leaves

    from pipeline.core.geometry import Grid

    grove, flutter = grove_of(config.canopy)
    lp = plan.layers[0]
    shapes = grove_geometry.project(grove_geometry.leaves_at(grove, flutter, 0), sun=np.array(plan.projection),
                            plane_height=config.canopy.layers[0].height)
    grid = lp.sun.mask if lp.sun else lp.canopy
    cpus = {}
    for name, draw in (("opencv", opencv_mask), ("compiled", rasteriser.rasterize_transmittance)):
        draw(shapes, grid)
        times = []
        for _ in range(3):
            t = time.process_time()
            draw(shapes, grid)
            times.append(time.process_time() - t)
        cpus[name] = float(np.median(times))
    leaves = random_leaves(np.random.default_rng(0), 200, low=0.3, high=2.7, pixel=0.1)
    grid = Grid((0.0, 3.0), 0.1, (30, 30))
    worst = [np.abs(opencv_mask(one, grid) - rasteriser.rasterize_transmittance(one, grid)).max()
             for one in (leaves.subset(leaves=[i], wood=[]) for i in range(200))]
    print(f"fillPoly LINE_AA: mask {lp.sun.mask.shape if lp.sun else lp.canopy.shape} "
          f"{cpus['opencv']:.3f} s CPU against "
          f"{cpus['compiled']:.3f} s compiled; 200 single leaves: largest coverage difference per leaf, "
          f"median {np.median(worst):.2f}, max {np.max(worst):.2f} of a pixel's area")


if __name__ == "__main__":
    main()
