"""Make the example inputs beside this file: ``leaves.png`` and ``sky.exr``.

    python configs/assets/make_assets.py

leaves.png : 800 x 800 8-bit transparency (1 = open sky) of a clump of three trees, 20 m across.
sky.exr : 512 x 256 equirectangular float sky: a blue gradient and a sun at 55 degrees
    elevation, azimuth 200 degrees (south-south-west), carrying about 8 times the sky's irradiance.
"""

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

HERE = Path(__file__).resolve().parent


def leaves(size_px=800, extent_m=20.0, seed=7, oversample=4):
    rng = np.random.default_rng(seed)
    n = size_px * oversample
    px = extent_m / n
    open_sky = np.ones((n, n), dtype=bool)
    yy, xx = np.mgrid[0:n, 0:n]
    x = (xx + 0.5) * px - extent_m / 2
    y = extent_m / 2 - (yy + 0.5) * px
    for cx, cy, radius in ((-3.5, 2.0, 5.0), (4.0, 3.0, 4.0), (1.0, -4.5, 4.5)):
        for _ in range(5):  # branches from the trunk
            a = rng.uniform(0, 2 * np.pi)
            t = (x - cx) * np.cos(a) + (y - cy) * np.sin(a)
            d = np.abs(-(x - cx) * np.sin(a) + (y - cy) * np.cos(a))
            open_sky &= ~((t > 0) & (t < radius * 0.8) & (d < 0.09 * (1 - t / radius)))
        for _ in range(120):  # leaf clusters
            r = radius * np.sqrt(rng.uniform(0.0, 1.0))
            a = rng.uniform(0, 2 * np.pi)
            ccx, ccy = cx + r * np.cos(a), cy + r * np.sin(a)
            for _ in range(22):  # leaves, as ellipses
                lx, ly = ccx + rng.normal(0, 0.35), ccy + rng.normal(0, 0.35)
                length, width = rng.uniform(0.08, 0.16), rng.uniform(0.04, 0.08)
                angle = rng.uniform(0, np.pi)
                c0 = int((lx + extent_m / 2 - length) / px)
                r0 = int((extent_m / 2 - ly - length) / px)
                span = int(2 * length / px) + 2
                rs = slice(max(r0, 0), max(min(r0 + span, n), 0))
                cs = slice(max(c0, 0), max(min(c0 + span, n), 0))
                u = (x[rs, cs] - lx) * np.cos(angle) + (y[rs, cs] - ly) * np.sin(angle)
                v = -(x[rs, cs] - lx) * np.sin(angle) + (y[rs, cs] - ly) * np.cos(angle)
                open_sky[rs, cs] &= (u / length) ** 2 + (v / width) ** 2 > 1.0
    coverage = open_sky.reshape(size_px, oversample, size_px, oversample).mean(axis=(1, 3))
    return coverage.astype(np.float32)


def sky(width=512, height=256, sun_elevation=55.0, sun_azimuth=200.0, sun_to_sky=8.0):
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    zenith = v[:, None] * np.pi + 0 * u[None, :]
    azimuth = (u[None, :] - 0.5) * 2 * np.pi + 0 * v[:, None]
    elevation = np.pi / 2 - zenith
    blue = np.array([0.35, 0.55, 1.0])
    haze = np.array([0.9, 0.92, 1.0])
    t = np.clip(1 - np.abs(elevation) / (np.pi / 2), 0, 1)[..., None] ** 3
    image = (1 - t) * blue + t * haze
    image[elevation < 0] = np.array([0.15, 0.13, 0.1])  # ground, ignored by sunshade
    sun = np.array([np.cos(np.radians(sun_elevation)) * np.sin(np.radians(sun_azimuth)),
                    np.cos(np.radians(sun_elevation)) * np.cos(np.radians(sun_azimuth)),
                    np.sin(np.radians(sun_elevation))])
    d = np.stack([np.sin(zenith) * np.sin(azimuth), np.sin(zenith) * np.cos(azimuth), np.cos(zenith)], -1)
    angle = np.degrees(np.arccos(np.clip(d @ sun, -1, 1)))
    image += (0.6 * np.exp(-angle / 6.0))[..., None] * np.array([1.0, 0.95, 0.85])  # glow
    # irradiance weights of texels: cos(theta) d_omega
    th0, th1 = np.arange(height)[:, None] * np.pi / height, (np.arange(height)[:, None] + 1) * np.pi / height
    w = np.where(th1 <= np.pi / 2, 0.5 * (np.sin(th1) ** 2 - np.sin(th0) ** 2), 0.0) * 2 * np.pi / width
    w = np.broadcast_to(w, (height, width))
    sky_irradiance = float((image.mean(axis=2) * w).sum())
    disc = angle < 0.6
    disc_irradiance = float(w[disc].sum())
    image[disc] = np.array([1.0, 0.97, 0.92]) * sun_to_sky * sky_irradiance / disc_irradiance
    return image.astype(np.float32)


def write(path, pixels, fmt):
    pixels = np.ascontiguousarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
    if str(path).endswith(".exr"):
        spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()


if __name__ == "__main__":
    write(HERE / "leaves.png", np.round(leaves() * 255).astype(np.uint8), "uint8")
    write(HERE / "sky.exr", sky(), "float")
    print("wrote", HERE / "leaves.png", HERE / "sky.exr")
