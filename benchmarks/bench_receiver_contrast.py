"""How far the flecks on each receiver demo's lit receiver stand above its shade, against the most its
light allows (issue 44, "Low sun"; docs/accuracy.md, "Receivers: framing and contrast").

For each config (default: every configs/*.yaml with ``receivers``), one frame is rendered (or read
from an EXR that ``sunshade frame`` wrote, --read) and, over the pixels of each receiver (a wall's:
all 3 x 3 points of the pixel on that wall, nearest of the walls, no tree in front; the ground's:
the rest that see the ground), the ratio of the 95th to the 5th percentile of the frame's
luminance is printed beside the bound ``sunshade check`` prints, (sun + sky) / sky of that
receiver's open light at the frame, and their ratio (the issue wants at least 90% on the lit
receiver; a slope's is the ground's, from ``stages.slope.open_slope``). Also: the share of the
picture each receiver fills, the share of its pixels the exposure clips (exposed luminance over 1),
and the level ground's bound under the same sky.

    python benchmarks/bench_receiver_contrast.py [CONFIG ...] [--frame N] [--cache DIR] [--read EXR]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.cache.store import Cache
from pipeline.camera import pinhole
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.receivers.slope import camera_in_frame, slope_plane
from pipeline.receivers.view import wall_hits
from pipeline.stages.frame import foreground_layer, render_frame
from pipeline.stages.ground import FrameContext
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load
from pipeline.stages.wall_framing import OpenLight, open_receivers, wall_planes


def receiver_configs() -> list[Path]:
    """Every shipped config with a ``receivers`` section."""
    return [p for p in sorted((ROOT / "configs").glob("*.yaml")) if "\nreceivers:" in p.read_text()]


def receiver_masks(plan, config, store, frame: int) -> dict[str, np.ndarray]:
    """Per receiver (``ground`` and each wall's name), the pixels that show it, no tree in front."""
    view = plan.camera
    free = np.ones((view.height, view.width), bool)
    fg = foreground_layer(plan, FrameContext.of(plan, frame, store=store).cycle_frame, store)
    if fg is not None:
        alpha = fg.alpha if fg.alpha.ndim == 2 else fg.alpha[..., 0]
        free[fg.region] &= alpha <= 0
    ground_view = view if config.receivers.slope is None else camera_in_frame(view, slope_plane(config.receivers.slope))
    depth = np.asarray(pinhole.ground_distance(ground_view), dtype=np.float64)  # the level ground, or the slope
    nearest = np.where(np.isfinite(depth), 0, -1)
    for i, plane in enumerate(wall_planes(config)):
        hits = wall_hits(view, plane)
        far = np.full(depth.shape, np.inf)
        all_in = np.zeros(depth.shape, bool)
        far[hits.region] = np.where(hits.hit.any(axis=0), hits.distance.min(axis=0), np.inf)
        all_in[hits.region] = hits.hit.all(axis=0)
        seen = far < depth
        nearest[seen], depth[seen] = i + 1, far[seen]
        nearest[seen & ~all_in] = -2  # a wall's edge: part wall, part what lies behind
    names = ["ground"] + [w.name for w in config.receivers.walls]
    return {name: (nearest == k) & free for k, name in enumerate(names)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", type=Path)
    parser.add_argument("--frame", type=int, default=0)
    parser.add_argument("--cache", type=Path, default=ROOT / "cache")
    parser.add_argument("--read", type=Path, default=None, help="an EXR of the frame (one config only)")
    args = parser.parse_args()
    configs = args.configs or receiver_configs()
    store = Cache(args.cache)
    print(" config                 receiver   share  clipped   p95/p5  bound  of bound   incidence [deg]")
    for path in configs:
        config = load(path)
        plan = plan_run(config)
        start = time.perf_counter()
        if args.read is not None:
            radiance = io.read_image(args.read)[..., :3]
            exposure = None
        else:
            result = render_frame(plan, args.frame, store=store)
            radiance, exposure = result.radiance, result.exposure
        took = time.perf_counter() - start
        luminance = np.asarray(radiance, dtype=np.float64) @ REC709_LUMINANCE
        lights = {light.name: light for light in open_receivers(config, plan.sky.at(plan.scenes[args.frame]))}
        level = lights["ground"].most
        if config.receivers.slope is not None:  # the ground is the slope: its own open light
            from pipeline.stages.slope import open_slope

            (s,) = open_slope(plan, [args.frame])
            sun, sky = (float(np.asarray(v) @ REC709_LUMINANCE) for v in (s.sun, s.sky))
            lights["ground"] = OpenLight("ground", s.incidence, sun, sky)
        for name, mask in receiver_masks(plan, config, store, args.frame).items():
            light = lights[name]
            angle = np.degrees(np.arccos(np.clip(light.incidence, -1.0, 1.0)))
            if mask.sum() < 100:
                print(f" {path.name:22s} {name:9s} {mask.mean():6.1%}        -        -  {light.most:5.2f}         -"
                      f"   {angle:5.1f}")
                continue
            y = luminance[mask]
            p5, p95 = np.percentile(y, [5.0, 95.0])
            clipped = "-" if exposure is None else f"{np.mean(y * exposure > 1.0):.1%}"
            print(f" {path.name:22s} {name:9s} {mask.mean():6.1%}  {clipped:>7s}  {p95 / p5:7.2f}  {light.most:5.2f}"
                  f"  {p95 / p5 / light.most:8.0%}   {angle:5.1f}")
        print(f"   (frame {args.frame}, rendered in {took:.1f} s; the level ground's bound under this sky {level:.2f})")


if __name__ == "__main__":
    main()
