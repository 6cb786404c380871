"""Make the ground albedo images beside this file, for configs/eclipse.yaml and
configs/sun-and-shade.yaml:

    python configs/assets/make_grounds.py

Both are 512 x 512 8-bit linear albedo (read with no colour conversion) and tile seamlessly.

sand.png : for ground.albedo_size 2 metres: pale dry sand (mean albedo 0.42, 0.36, 0.28) with a
    faint mottle some 35 cm across, a fine grain and a few darker grains. A smooth, light
    ground shows the crescent suns of an eclipse better than grass.
lawn.png : for ground.albedo_size 4 metres: a mown lawn (mean albedo 0.10, 0.18, 0.05), tufts
    and blades with only a faint large-scale mottle, so the tiles do not show towards the
    horizon and the dappled light reads clearly.
"""

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from pipeline.albedo import periodic_noise

HERE = Path(__file__).resolve().parent


def sand(size_px=512, period=2.0, seed=11):
    rng = np.random.default_rng(seed)
    mottle = periodic_noise(rng, size_px, period=period, wavelength=0.35)
    grain = periodic_noise(rng, size_px, period=period, wavelength=0.008)
    speck = periodic_noise(rng, size_px, period=period, wavelength=0.008)
    base = np.array([0.42, 0.36, 0.28])  # linear albedo of pale dry sand
    shade = 1.0 + 0.06 * mottle + 0.07 * grain
    pebbles = np.clip((speck - 2.2) / 0.6, 0.0, 1.0)  # a few darker grains
    image = base * shade[..., None] * (1.0 - 0.35 * pebbles[..., None])
    return np.clip(image, 0.02, 0.95)


def lawn(size_px=512, period=4.0, seed=5):
    rng = np.random.default_rng(seed)
    mottle = periodic_noise(rng, size_px, period=period, wavelength=0.9)
    tufts = periodic_noise(rng, size_px, period=period, wavelength=0.12)
    blades = periodic_noise(rng, size_px, period=period, wavelength=0.016)
    dark, light = np.array([0.06, 0.13, 0.035]), np.array([0.13, 0.22, 0.06])
    t = np.clip(0.5 + 0.05 * mottle + 0.12 * tufts + 0.18 * blades, 0.0, 1.0)[..., None]
    return np.clip(dark + t * (light - dark), 0.01, 0.95)


def write_png(path, image):
    pixels = np.round(image * 255).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], "uint8"))
    out.write_image(pixels)
    out.close()


if __name__ == "__main__":
    write_png(HERE / "sand.png", sand())
    write_png(HERE / "lawn.png", lawn())
