"""From scene-linear values to display: exposure and the sRGB display transform."""

from __future__ import annotations

import numpy as np

REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
"""Luminance weights of linear Rec.709 RGB."""


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of linear values, clipped to [0, 1]."""
    x = np.clip(np.asarray(linear, dtype=np.float32), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def display_ground(irradiance: np.ndarray, unshadowed: np.ndarray, *, white=1.25) -> np.ndarray:
    """Display-referred sRGB picture of a ground irradiance raster (rows, cols, 3).

    The open-sky irradiance maps to ``1 / white`` of full scale, grey-balanced by its luminance,
    so sunlit ground is a light grey and shade keeps its depth. [dimensionless]
    """
    unshadowed = np.asarray(unshadowed, dtype=np.float64)
    luminance = float(unshadowed @ REC709_LUMINANCE)
    scale = 1.0 / (white * luminance) if luminance > 0 else 1.0
    return srgb_encode(np.asarray(irradiance, dtype=np.float32) * np.float32(scale))


def display_sky(radiance: np.ndarray) -> np.ndarray:
    """Display-referred sRGB picture of an equirectangular sky (rows, cols, 3).

    Exposure puts the median luminance of the upper hemisphere at 0.4, then ``x / (1 + x)``
    compresses the sun and the glow around it instead of clipping them flat. [dimensionless]
    """
    radiance = np.asarray(radiance, dtype=np.float32)
    upper = radiance[: radiance.shape[0] // 2] @ REC709_LUMINANCE
    median = float(np.median(upper))
    exposed = radiance * np.float32(0.4 / median if median > 0 else 1.0)
    return srgb_encode(exposed / (1.0 + exposed))
