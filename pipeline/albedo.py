"""Procedural ground albedo: a seamlessly tileable texture of grass and soil.

Periodic noise is white noise from ``numpy.random.default_rng(seed)`` low-pass filtered in the
Fourier domain (a Gaussian of the spatial frequency), so every field tiles exactly with the
texture's period. Albedo is the fraction of light reflected (Lambertian), per linear Rec.709
channel. [1]
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from .geometry import Grid

GRASS_DARK = (0.08, 0.16, 0.05)
GRASS_LIGHT = (0.15, 0.25, 0.08)
SOIL = (0.20, 0.15, 0.10)
"""Albedos of shaded and sunny blades of grass and of bare dry soil (linear Rec.709). [1]"""


def periodic_noise(rng: np.random.Generator, size_px: int, *, period: float, wavelength: float) -> np.ndarray:
    """Zero-mean, unit-variance noise (size_px, size_px) float64 that tiles with ``period`` [m],
    its features about ``wavelength`` [m] across (Gaussian low-pass of white noise)."""
    white = rng.standard_normal((size_px, size_px))
    fy = sfft.fftfreq(size_px, d=period / size_px)[:, None]  # [cycles / m]
    fx = sfft.rfftfreq(size_px, d=period / size_px)[None, :]
    gain = np.exp(-0.5 * (fx * fx + fy * fy) * wavelength**2 * (2.0 * np.pi) ** 2 / 4.0)
    field = sfft.irfft2(sfft.rfft2(white) * gain, s=white.shape)
    field -= field.mean()
    return field / max(field.std(), 1e-12)


def grass_albedo(*, size_px: int = 1024, period: float = 4.0, seed: int = 0):
    """A tileable grass-and-soil albedo texture.

    size_px : texels a side. [pixel]
    period : side of the square texture; it tiles the plane with this period. [m]
    seed : seed of ``numpy.random.default_rng``.
    Returns (image (size_px, size_px, 3) float32 albedo in (0, 1) [1], Grid of the texture with
    its north-west corner at (0, period) [m]). Patches of soil (about a fifth of the area, some
    tens of centimetres across) in grass whose shade varies in tufts and blades; the mean
    albedo is about 0.15.
    """
    if size_px < 8:
        raise ValueError(f"size_px must be at least 8, got {size_px}")
    if not period > 0:
        raise ValueError(f"period must be positive [m], got {period}")
    rng = np.random.default_rng(seed)
    patches = periodic_noise(rng, size_px, period=period, wavelength=0.6)
    tufts = periodic_noise(rng, size_px, period=period, wavelength=0.08)
    blades = periodic_noise(rng, size_px, period=period, wavelength=min(0.012, 4 * period / size_px))
    soil = np.clip((patches + 0.3 * tufts - 0.8) / 0.4, 0.0, 1.0)
    soil = soil * soil * (3.0 - 2.0 * soil)  # smoothstep: soft edges
    shade = np.clip(0.5 + 0.2 * tufts + 0.25 * blades, 0.0, 1.0)[..., None]
    grass = np.asarray(GRASS_DARK) + shade * (np.asarray(GRASS_LIGHT) - np.asarray(GRASS_DARK))
    dirt = np.asarray(SOIL) * (1.0 + 0.15 * np.clip(tufts + 0.5 * blades, -2.0, 2.0))[..., None]
    image = grass + soil[..., None] * (dirt - grass)
    image = np.clip(image, 0.01, 0.99).astype(np.float32)
    return image, Grid((0.0, float(period)), float(period) / size_px, (size_px, size_px))
