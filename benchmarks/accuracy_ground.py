"""Accuracy of the ground raster against a world-coordinate Monte Carlo path tracer.

    python benchmarks/accuracy_ground.py [--points 200] [--rays 65536]

The shipped 20 m canopy (configs/assets/leaves.png) at 8 m, isolated, ground pixel 0.05 m, under
a uniform sky and under a smooth gradient sky. The reference traces cosine-weighted rays from
ground points jittered over each chosen pixel, through the canopy image placed in the world
(tests/reference.py; it shares no code with pipeline.ground.shadow). Prints the relative RMS
difference, RMS(ours - reference) / mean(reference), and the Monte Carlo noise of that figure.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from reference import image_transmittance, monte_carlo_irradiance

from pipeline.canopy import masks as canopy
from pipeline.core import io
from pipeline.core.geometry import Grid
from pipeline.ground import shadow
from pipeline.sky.base import UniformSky
from pipeline.sky.equirect import EquirectSky


def gradient_sky(azimuth, zenith):
    """Brighter towards the horizon and the south-east, bluer overhead. [radiance]"""
    base = 0.6 + 0.8 * (1 - np.cos(zenith)) + 0.3 * np.sin(zenith) * np.cos(azimuth - np.radians(135))
    return np.stack([base, 1.1 * base, 1.4 * base], axis=-1)


def equirect(function, width=2048, height=1024):
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    zen, az = np.meshgrid(v * np.pi, (u - 0.5) * 2 * np.pi, indexing="ij")
    return function(az, zen).astype(np.float32)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--points", type=int, default=200)
    parser.add_argument("--rays", type=int, default=256 * 256)
    args = parser.parse_args()
    mask = io.read_image(ROOT / "configs/assets/leaves.png")[..., 0]
    h, p, alpha = 8.0, 0.05, np.radians(80.0)
    window = Grid.from_window((-20, -20, 20, 20), p)
    occlusion, grid = canopy.occlusion_on_lattice(mask, center=(0, 0), size=(20, 20), lattice=window)
    plan = shadow.plan_isolated(window, grid, height=h, alpha=alpha)
    spectrum = shadow.occlusion_spectrum(occlusion, plan, workers=2)
    leaves = image_transmittance(mask, center=(0, 0), size=(20, 20))
    rng = np.random.default_rng(2024)
    half_rays = int(np.sqrt(args.rays / 2)) ** 2  # each of two independent estimates, stratified
    # half the points under the canopy's shadow, half anywhere in the window
    under = rng.integers(100, 700, (args.points // 2, 2))
    anywhere = rng.integers(0, 800, (args.points - args.points // 2, 2))
    pick = np.concatenate([under, anywhere])
    print(f"canopy 20 m at {h} m, ground pixel {p} m, alpha 80 deg, exact plan: {plan.exact}")
    print(f"{args.points} ground pixels x {2 * half_rays} rays each, stratified, jittered over the pixel")
    print(f"{'sky':>10} {'ours ms':>8} {'rel. RMS':>9} {'MC noise':>9} {'max rel':>8}")
    for name, sky, radiance in (
        ("uniform", UniformSky(np.ones(3)), lambda az, zen: np.ones((*np.shape(az), 3))),
        ("gradient", EquirectSky(equirect(gradient_sky)), gradient_sky),
    ):
        start = time.perf_counter()
        g = shadow.ground_isolated(sky.raster(plan.sky), spectrum, plan, workers=2)
        ms = (time.perf_counter() - start) * 1e3
        cx, cy = window.ground_from_raster(pick[:, 0], pick[:, 1])
        chunks = []
        for lo in range(0, len(pick), 10):  # bounded memory
            centres = np.stack([cx[lo : lo + 10], cy[lo : lo + 10]], 1)[:, None, :]
            two = []
            for _ in range(2):
                jitter = rng.uniform(-p / 2, p / 2, (len(centres), half_rays, 2))
                two.append(monte_carlo_irradiance(centres + jitter, height=h, transmittance=leaves,
                                                  radiance=radiance, rays=half_rays, rng=rng))
            chunks.append(np.stack(two))
        halves = np.concatenate(chunks, axis=1)  # (2, points, 3): two independent estimates
        mc = halves.mean(axis=0)
        ours = g[:, pick[:, 0], pick[:, 1]].T
        rms = np.sqrt(np.mean((ours - mc) ** 2)) / mc.mean()
        noise = np.sqrt(np.mean((halves[0] - halves[1]) ** 2) / 4) / mc.mean()
        worst = np.abs(ours / mc - 1).max()
        print(f"{name:>10} {ms:8.1f} {rms:9.4%} {noise:9.4%} {worst:8.3%}")


if __name__ == "__main__":
    main()
