"""Several canopy layers' light on a receiver combined: the paper's product rule for uncorrelated
layers, applied to the sky's light and to the sun's apart (docs/method.md, "Several canopy
layers")."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["combine_layers", "combine_lights"]


def combine_layers(grounds: Iterable[np.ndarray], unshadowed: ArrayLike) -> np.ndarray:
    """Several canopy layers, assumed uncorrelated: the product of the layers' ground rasters over ``I0^(n - 1)``.

    Max 1991, "Extensions to multiple shadow casting planes".

    Parameters
    ----------
    grounds : sequence of numpy.ndarray
        (channels, rows, cols) rasters [radiance x sr].
    unshadowed : numpy.ndarray
        (channels,) irradiance of the open sky [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (channels, rows, cols) [radiance x sr].
    """
    layers = list(grounds)
    i0 = np.asarray(unshadowed, dtype=np.float32)[:, None, None]
    out = layers[0].copy()
    for g in layers[1:]:
        out *= np.divide(g, i0, out=np.zeros_like(g), where=i0 > 0)  # a dark channel stays 0
    return out


def combine_lights(grounds: list[np.ndarray], skies: list[np.ndarray], unshadowed: ArrayLike,
                   sky_total: ArrayLike) -> np.ndarray:
    """Several canopy layers' ground rasters combined by the paper's product rule for uncorrelated
    layers (``combine_layers``), the sky's light and the sun's apart.

    The sky's light (the layers' sky parts ``skies``, over ``sky_total``) and the sun's (the rest of
    each raster, over ``unshadowed - sky_total``) each by the rule, then added (one layer: its raster,
    copied, as ``combine_layers`` gives it):
    where every layer hides the sun, the sky's light is not scaled down by the sun's share of the
    open-sky total, as the rule on the sum does (docs/method.md, "Several canopy layers").

    Parameters
    ----------
    grounds : list of numpy.ndarray
        (channels, rows, cols) each layer's ground, sky and sun [radiance x sr].
    skies : list of numpy.ndarray
        (channels, rows, cols) each layer's sky part on the same grid [radiance x sr].
    unshadowed : array_like
        (channels,) the open-sky total of ``grounds`` [radiance x sr].
    sky_total : array_like
        (channels,) the open-sky total of ``skies`` [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (channels, rows, cols) float32 [radiance x sr].
    """
    if len(grounds) == 1:
        return combine_layers(grounds, unshadowed)
    sun_total = np.asarray(unshadowed, dtype=np.float64) - np.asarray(sky_total, dtype=np.float64)
    light = combine_layers(skies, sky_total)
    light += combine_layers([g - sky for g, sky in zip(grounds, skies)], sun_total)
    return light
