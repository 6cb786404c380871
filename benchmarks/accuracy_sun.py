"""Sun and sky under a leaf canopy with pinhole gaps: the two-scale ground raster against an
independent world-coordinate path tracer, during a partial eclipse.

    .venv/bin/python benchmarks/accuracy_sun.py [--points 200] [--sun-n 512] [--sky-rays 65536]

The scene: a seeded canopy of random elliptic leaves (6 cm to 12 cm, about 11% open, so many of
its gaps are pinholes for the sun) in an 18 m x 18 m mask image (a 6 m tile of 5 mm texels,
repeated 3 x 3) at h = 8 m; the procedural sky, turbidity 3, the sun at 60 degrees elevation,
azimuth 200, the moon 0.2 degrees right of it and 0.1 up (S = 0.48). It is rendered through
``stages.ground.render_ground`` from a YAML config (the sun resolved on a 1 m fine window, 16 cells
across the disc, 4.65 mm pixels; the sky on 20 mm pixels).

The reference (tests/reference.py; no code from pipeline.ground.shadow, no rasters) traces rays from
points stratified over each of ``--points`` fine ground pixels picked at random: the sun by
stratified sampling of its disc on the tangent plane (4 x 4 positions per pixel, each with its own
(n/4)^2 disc strata, so the canopy points x + h s stay stratified; the limb-darkened radiance cut
by the moon's disc, the pipeline's normal irradiance only setting its scale), the sky by
stratified cosine-weighted rays with the pipeline's ``ProceduralSky.radiance`` (no disc) as the
light; each ray meets the canopy plane at x + h (wx, wy) / wz and reads the mask image's texel
there. Two independent halves give the Monte Carlo noise of the reference's mean; the pipeline's
own error is then about sqrt(RMS^2 - noise^2).

Then the crescent check of tests/test_sun.py, printed: one 1 cm pinhole, the moon 0.15 degrees
to the sun's right, against a brute-force integral over the hole.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import test_sun
from reference import (
    angle_between,
    image_transmittance,
    monte_carlo_irradiance,
    monte_carlo_sun,
    offset_direction,
    pinhole_irradiance,
    sun_radiance_function,
    tangent_frame,
)

from pipeline.cache import store as cache
from pipeline.config.parse import parse_config
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky import ephemeris
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import LIMB_DARKENING, SunDisc
from pipeline.stages.ground import render_ground
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import resolve
from pipeline.stages.scene import (
    load_sky,
    scene_at,
)

HEIGHT, ELEVATION, AZIMUTH, MOON = 8.0, 60.0, 200.0, (0.2, 0.1)
TILE, TEXELS, REPEAT = 6.0, 1200, 3
SIZE = TILE * REPEAT


def leafy_mask(seed=11, open_fraction=0.12):
    """Transmittance (REPEAT TEXELS, REPEAT TEXELS) float32: 1 open, 0 leaf; random ellipses added
    to a TILE [m] square of TEXELS texels until about ``open_fraction`` of it is left open, the
    tile repeated REPEAT x REPEAT times (an 18 m canopy that hides most of the sky)."""
    rng = np.random.default_rng(seed)
    texel = TILE / TEXELS
    mask = np.ones((TEXELS, TEXELS), np.float32)
    while mask.mean() > open_fraction:
        for _ in range(2000):
            length = rng.uniform(0.06, 0.12) / texel
            width = 0.5 * length
            angle = rng.uniform(0, np.pi)
            r0, c0 = rng.uniform(0, TEXELS, 2)
            half = int(np.ceil(length / 2)) + 1
            r = np.arange(max(0, int(r0) - half), min(TEXELS, int(r0) + half + 1))
            c = np.arange(max(0, int(c0) - half), min(TEXELS, int(c0) + half + 1))
            dr, dc = r[:, None] + 0.5 - r0, c[None, :] + 0.5 - c0
            u = dc * np.cos(angle) + dr * np.sin(angle)
            v = -dc * np.sin(angle) + dr * np.cos(angle)
            inside = (u / (length / 2)) ** 2 + (v / (width / 2)) ** 2 <= 1
            block = mask[r[0]:r[-1] + 1, c[0]:c[-1] + 1]
            block[inside] = 0
    return np.tile(mask, (REPEAT, REPEAT))


def scene(folder):
    mask = leafy_mask()
    io.write_png(folder / "leaves.png", mask[..., None])
    mask = io.read_image(folder / "leaves.png")[..., 0]  # exactly what the pipeline reads
    cx, cy = (float(v) for v in -HEIGHT * test_sun.sun_point(ELEVATION, AZIMUTH))
    config = {
        "canopy": {"mask": "leaves.png", "size": [SIZE, SIZE], "center": [0, 0], "height": HEIGHT},
        "sky": {"model": "procedural", "turbidity": 3,
                "sun": {"elevation": ELEVATION, "azimuth": AZIMUTH},
                "moon": {"offset_start": list(MOON), "offset_end": list(MOON)}},
        "ground": {"window": [cx - 1, cy - 1, cx + 1, cy + 1], "pixel": 0.02,
                   "sun_window": [cx - 0.5, cy - 0.5, cx + 0.5, cy + 0.5]},
        "animation": {"frames": 1},
    }
    return resolve(parse_config(config, folder)), mask


def pixel_strata(points, rays, pixel, rng):
    """Offsets (points, rays, 2) [m] over a pixel: one jittered point in each of k x k strata
    (k^2 >= rays), shuffled independently per point so that they pair at random with the
    direction strata (a Latin-hypercube-like pairing: stratified in position and direction)."""
    k = int(np.ceil(np.sqrt(rays)))
    a, b = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    cells = np.stack([a.ravel(), b.ravel()], axis=1)
    out = np.empty((points, rays, 2))
    for i in range(points):
        chosen = cells[rng.permutation(k * k)[:rays]]
        out[i] = ((chosen + rng.random((rays, 2))) / k - 0.5) * pixel
    return out


def path_traced(config, mask, points, pixel, *, sun_n, sky_rays, rng):
    """Two independent estimates (2, points, 3) of the irradiance over each pixel. [klx]"""
    sky = load_sky(config.sky, scene_at(config, 0))
    sun = config.sky.sun
    centre, right, up = tangent_frame(sun.azimuth, sun.elevation)
    moon = offset_direction(sun.azimuth, sun.elevation, *np.radians(MOON))
    u = np.array(LIMB_DARKENING)
    plain = ProceduralSky(config.sky.turbidity, SunDisc(sun.azimuth, sun.elevation, sun.radius))
    centre_radiance = plain.sun_normal_irradiance / (np.pi * sun.radius**2 * (1 - u / 3))
    sun_radiance = sun_radiance_function(centre, sun.radius, centre_radiance, u, moon,
                                         config.sky.moon.radius)
    leaves = image_transmittance(mask, center=(0, 0), size=(SIZE, SIZE))

    def sky_radiance(az, zen):
        t = np.tan(zen)
        return sky.radiance(np.stack([t * np.sin(az), t * np.cos(az)], axis=-1))

    side = int(np.sqrt(sky_rays))
    halves = []
    for _ in range(2):
        # the sun: 4 x 4 jittered positions per pixel, each with its own stratified disc of
        # (sun_n / 4)^2 strata, so that the canopy points x + h s stay stratified
        sub = pixel_strata(len(points), 16, pixel, rng)
        e_sun = monte_carlo_sun((points[:, None, :] + sub).reshape(-1, 2), height=HEIGHT,
                                transmittance=leaves, radiance=sun_radiance, sun_direction=centre,
                                right=right, up=up, radius=sun.radius, n=max(1, sun_n // 4), rng=rng)
        e_sun = e_sun.reshape(len(points), 16, -1).mean(axis=1)
        e_sky = []
        for lo in range(0, len(points), 20):  # bounded memory
            part = points[lo:lo + 20]
            jitter = pixel_strata(len(part), side * side, pixel, rng)
            e_sky.append(monte_carlo_irradiance(part[:, None, :] + jitter, height=HEIGHT,
                                                transmittance=leaves, radiance=sky_radiance,
                                                rays=side * side, rng=rng))
        halves.append((e_sun, np.concatenate(e_sky)))
    return np.array(halves), sky  # (2 halves, sun / sky, points, 3)


def crescent_check(folder, store):
    """The pinhole crescent of tests/test_sun.py, with its figures."""
    test_sun.write_masks(folder)
    elevation, azimuth, dx = 35.0, 120.0, 0.15
    full, grid, config = test_sun.spot(folder, store, elevation=elevation, azimuth=azimuth, name="full")
    ecl, _, config_e = test_sun.spot(folder, store, elevation=elevation, azimuth=azimuth,
                                     moon=((dx, 0.0), (dx, 0.0)), name="eclipse")
    full, ecl = full[0][..., 1], ecl[0][..., 1]  # green
    x, y = test_sun.centres(grid)
    sun = config.sky.sun
    centre, right, _up = tangent_frame(sun.azimuth, sun.elevation)
    moon = offset_direction(sun.azimuth, sun.elevation, np.radians(dx), 0.0)
    R = config_e.sky.moon.radius
    points = np.stack([x.ravel(), y.ravel()], 1)
    u = np.array(LIMB_DARKENING)
    brute, brute_full = (
        pinhole_irradiance(points, height=HEIGHT, hole_points=test_sun.hole_points(),
                           hole_area=test_sun.HOLE_SIDE**2,
                           radiance=sun_radiance_function(centre, sun.radius, np.ones(3), u, *m))
        [:, 1].reshape(grid.shape) for m in ((moon, R), ()))
    mean_f, cov = test_sun.moments(full, x, y)
    values, vectors = np.linalg.eigh(cov)
    k = test_sun.limb_darkened_k(u[1])
    minor, major = 2 * np.sqrt((values - test_sun.HOLE_SIDE**2 / 12) / k)
    beta = sun.elevation
    print(f"pinhole (1 cm hole at h = {HEIGHT} m, sun {elevation} deg elevation, azimuth {azimuth}):")
    print(f"  spot minor axis {minor * 1e3:.2f} mm (h a_sun / sin(beta) = "
          f"{HEIGHT * 2 * sun.radius / np.sin(beta) * 1e3:.2f} mm), axis ratio {minor / major:.4f} "
          f"(sin(beta) = {np.sin(beta):.4f}), long axis at "
          f"{np.degrees(np.arctan2(vectors[0, 1], vectors[1, 1])) % 180:.2f} deg from north "
          f"(azimuth {azimuth % 180:.2f})")
    offset = test_sun.moments(ecl, x, y)[0] - mean_f
    ref = test_sun.moments(brute, x, y)[0] - test_sun.moments(brute_full, x, y)[0]

    def bearing(v):
        return np.degrees(np.arctan2(v[0], v[1])) % 360

    sep = angle_between(moon, centre)
    lit = 1 - ephemeris.obscured_fraction(sep, sun.radius, R)
    area = (ecl > 0.3 * full.max()).sum() / (full > 0.3 * full.max()).sum()
    area_ref = (brute > 0.3 * brute_full.max()).sum() / (brute_full > 0.3 * brute_full.max()).sum()
    shape = np.linalg.norm(ecl / ecl.sum() - brute / brute.sum()) / np.linalg.norm(brute / brute.sum())
    print(f"  crescent, moon {dx} deg right: centroid shift {np.hypot(*offset) * 1e3:.2f} mm towards "
          f"bearing {bearing(offset):.2f} deg; brute force {np.hypot(*ref) * 1e3:.2f} mm, "
          f"{bearing(ref):.2f} deg; the observer's right {bearing(right[:2]):.2f} deg")
    print(f"  lit power fraction {ecl.sum() / full.sum():.4f} (brute force "
          f"{brute.sum() / brute_full.sum():.4f}); lit area fraction {area:.4f} (brute force "
          f"{area_ref:.4f}, 1 - obscured_fraction {lit:.4f}); normalized shape error {shape:.4f}")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--points", type=int, default=200)
    parser.add_argument("--sun-n", type=int, default=512,
                        help="n x n sun strata per pixel: 4 x 4 positions, (n/4)^2 disc strata each")
    parser.add_argument("--sky-rays", type=int, default=256 * 256)
    args = parser.parse_args()
    print("command: .venv/bin/python benchmarks/accuracy_sun.py " + " ".join(sys.argv[1:]))
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        store = cache.Cache(folder / "cache")
        config, mask = scene(folder)
        t = time.perf_counter()
        result = render_ground(plan_run(config), store=store)
        render_s = time.perf_counter() - t
        grid = result.grid
        rng = np.random.default_rng(2024)
        pick = np.stack([rng.integers(0, grid.shape[0], args.points),
                         rng.integers(0, grid.shape[1], args.points)], 1)
        px, py = grid.ground_from_raster(pick[:, 0], pick[:, 1])
        points = np.stack([px, py], 1)
        t = time.perf_counter()
        halves, sky = path_traced(config, mask, points, grid.pixel, sun_n=args.sun_n,
                                  sky_rays=args.sky_rays, rng=rng)
        trace_s = time.perf_counter() - t
        ours = result.irradiance[pick[:, 0], pick[:, 1]].astype(np.float64)
        parts, halves = halves, halves.sum(axis=1)
        ref = halves.mean(axis=0)
        rms = np.sqrt(((ours - ref) ** 2).mean(axis=0)) / ref.mean(axis=0)
        noise = np.sqrt(((halves[0] - halves[1]) ** 2).mean(axis=0)) / 2 / ref.mean(axis=0)
        lum = REC709_LUMINANCE.astype(np.float64)
        rms_y = np.sqrt((((ours - ref) @ lum) ** 2).mean()) / (ref @ lum).mean()
        noise_y = np.sqrt((((halves[0] - halves[1]) @ lum) ** 2).mean()) / 2 / (ref @ lum).mean()
        bias = (ours - ref).mean(axis=0) / ref.mean(axis=0)
        print(f"canopy {SIZE:g} m of random leaves at {HEIGHT:g} m, {1 - mask.mean():.1%} covered; sun "
              f"{ELEVATION:g} deg elevation, azimuth {AZIMUTH:g}; moon offset {MOON} deg, sun fraction "
              f"S = {sky.sun_fraction():.4f}")
        print(f"fine sun window {grid.shape[1]} x {grid.shape[0]} pixels of {grid.pixel * 1e3:.2f} mm "
              f"(coarse {config.ground.pixel * 1e3:.0f} mm); render_ground {render_s:.2f} s; "
              f"path tracer {trace_s:.1f} s")
        print(f"{args.points} pixels x ({args.sun_n}^2 sun strata + {args.sky_rays} sky rays) x 2 halves, "
              f"stratified over each pixel; mean reference {ref.mean(axis=0).round(2)} klx (R, G, B)")
        print(f"relative RMS (ours - reference) / mean(reference): R {rms[0]:.4f}  G {rms[1]:.4f}  "
              f"B {rms[2]:.4f}  luminance {rms_y:.4f}   (target < 0.03)")
        print(f"Monte Carlo noise of the reference, same measure:   R {noise[0]:.4f}  G {noise[1]:.4f}  "
              f"B {noise[2]:.4f}  luminance {noise_y:.4f}")
        excess = np.sqrt(np.maximum(rms_y**2 - noise_y**2, 0.0))
        print(f"the pipeline's own error, sqrt(RMS^2 - noise^2), luminance: {excess:.4f}")
        for name, k in (("sun", 0), ("sky", 1)):
            part = parts[:, k, :, 1]
            print(f"  G, {name} part of the reference: mean {part.mean():.3f} klx, noise "
                  f"{np.sqrt(((part[0] - part[1]) ** 2).mean()) / 2 / ref[:, 1].mean():.4f} of the mean total")
        print(f"mean bias (ours - reference) / mean: {bias.round(4)}; max |rel| per pixel "
              f"{(np.abs(ours - ref) / ref).max():.3f}")
        crescent_check(folder, store)
    print(f"total {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
