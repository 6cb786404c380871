"""The ground's reflectance (issue 28) on a shipped config: the frame's time with the config's
``ground.brdf`` beside the same config with ``lambert``, the view bands chosen, and the hot spot
measured in the frame.

    python benchmarks/bench_brdf.py [--config configs/lawn-hotspot.yaml] [--frame 0] [--repeats 3]

Times: ``render_frame``'s stages (ground, camera, composite) and the process's CPU time
(``cpu``, both workers'), each frame rendered ``repeats`` times per reflectance, alternately,
after one warm-up of each (cycle products in a temporary cache); medians, and the load average.
Hot spot: the rendered radiance with the BRDF over the
Lambertian radiance at the same pixel (the albedo texture, haze and foreground cancel nearly),
at sunlit ground pixels (ground irradiance at least 0.9 of the open ground's) whose view
vector lies within 2 degrees of the sun's direction (the antisolar point) and at those 39-41
degrees from it; their medians' ratio beside the model's prediction for open ground,
[s(V, L_sun) E_sun + sum_i e_i s(V, L_i)] / (E_sun + E_sky) at those pixels' views.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.cache import store as cache
from pipeline.camera import brdf_view as brdf_camera
from pipeline.camera import pinhole as camera
from pipeline.ground import brdf as reflect
from pipeline.ground import brdf_bands
from pipeline.stages.frame import render_frame
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="configs/lawn-hotspot.yaml")
    parser.add_argument("--frame", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    config = load(args.config)
    if config.ground.brdf is None:
        raise SystemExit(f"{args.config} has no ground.brdf to compare with lambert")
    plans = {"brdf": plan_run(config), "lambert": plan_run(replace(config, ground=replace(config.ground, brdf=None)))}
    times = {name: [] for name in plans}
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        store = cache.Cache(Path(folder))
        for name, plan in plans.items():  # warm-up: cycle products, compiled loops
            results[name] = render_frame(plan, args.frame, store=store, workers=2)
        for _ in range(args.repeats):
            for name, plan in plans.items():
                stages: dict = {}
                cpu = time.process_time()
                render_frame(plan, args.frame, store=store, workers=2, timings=stages)
                stages["cpu"] = time.process_time() - cpu  # both workers' CPU time: steadier under load
                times[name].append(stages)
    load_average = os.getloadavg()
    print(f"{args.config} frame {args.frame}, {args.repeats} repeats, load average "
          + " ".join(f"{v:.2f}" for v in load_average))
    wall = lambda r: sum(v for k, v in r.items() if k != "cpu")  # noqa: E731
    for name, runs in times.items():
        stages = {k: float(np.median([r[k] for r in runs])) for k in runs[0]}
        total = float(np.median([wall(r) for r in runs]))
        print(f"  {name:8s} frame {total:6.2f} s (median)   " + "  ".join(f"{k} {v:.2f}" for k, v in stages.items()))
    pairs = list(zip(times["lambert"], times["brdf"]))
    ratio = float(np.median([wall(b) / wall(a) for a, b in pairs]))
    cpu_ratio = float(np.median([b["cpu"] / a["cpu"] for a, b in pairs]))
    print(f"  brdf / lambert frame time: {ratio:.2f} wall, {cpu_ratio:.2f} CPU (medians of the paired repeats)")
    hot_spot(plans["brdf"], args.frame, results)


def hot_spot(plan, frame: int, results) -> None:
    """Print the bands and the hot spot's measured and predicted ratios."""
    view = plan.camera
    model = plan.ground.brdf
    sky = plan.sky.at(plan.scenes[frame])
    chooser = plan.layers[0].coarse.sky
    raster = sky.raster(chooser)
    views = brdf_camera.view_vectors(view)
    bands = brdf_bands.choose_bands(model, brdf_bands.summed_blocks(raster, brdf_bands.band_factor(plan)),
                                    views)  # as the frame chooses them (frame.brdf_background)
    print(f"  view bands: {bands.count}, at view zenith/azimuth "
          + ", ".join(f"{np.degrees(z):.1f}/{np.degrees(a):+.0f}" for z, a in zip(bands.zeniths, bands.azimuths))
          + f" deg; bound of the blend's error under shading over sampled pixels {bands.error:.4f}")
    rows, _ = camera.rows_seeing_ground(view)
    ratio = (results["brdf"].radiance[rows] / np.maximum(results["lambert"].radiance[rows], 1e-12))[..., 1].reshape(-1)
    fp, _ = camera.view_footprints(view)
    ground = results["lambert"].ground
    r, c = ground.grid.raster_from_ground(fp.x, fp.y)
    inside = (r >= 0) & (c >= 0) & (r <= ground.grid.shape[0] - 1) & (c <= ground.grid.shape[1] - 1)
    e = np.full(len(fp.x), np.nan)
    e[inside] = ground.irradiance[np.round(r[inside]).astype(int), np.round(c[inside]).astype(int), 1]
    open_light = sky.undimmed_sun_irradiance()[1] + raster.irradiance[1]
    sunlit = e >= 0.9 * open_light
    angle = np.degrees(np.arccos(np.clip(views @ sky.sun_direction, -1.0, 1.0)))
    near, away = sunlit & (angle <= 2.0), sunlit & (np.abs(angle - 40.0) <= 1.0)
    if not near.any() or not away.any():
        print(f"  hot spot: no sunlit pixels near the antisolar point ({near.sum()}) or 40 deg away ({away.sum()})")
        return
    dirs = reflect.cell_directions(raster.grid).reshape(-1, 3)
    e_cells = raster.weighted[1].reshape(-1).astype(np.float64)
    e_sun = sky.undimmed_sun_irradiance()[1]

    def predicted(v):
        return (reflect.shape(model, v, sky.sun_direction) * e_sun + reflect.shape(model, v, dirs) @ e_cells) \
            / (e_sun + e_cells.sum())

    measured = np.median(ratio[near]) / np.median(ratio[away])
    model_near = np.median([predicted(v) for v in views[near][:: max(1, near.sum() // 64)]])
    model_away = np.median([predicted(v) for v in views[away][:: max(1, away.sum() // 64)]])
    sun_only = np.median(reflect.shape(model, views[near], sky.sun_direction)) \
        / np.median(reflect.shape(model, views[away], sky.sun_direction))
    print(f"  hot spot: sunlit ground within 2 deg of the antisolar direction ({near.sum()} px) over sunlit "
          f"ground 39-41 deg away ({away.sum()} px): measured {measured:.3f}; the model predicts "
          f"{model_near / model_away:.3f} (sun and sky), {sun_only:.3f} (sun alone)")


if __name__ == "__main__":
    t = time.perf_counter()
    main()
    print(f"  ({time.perf_counter() - t:.0f} s in all)")
