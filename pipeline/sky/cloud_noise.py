"""The pattern of a cloud layer (docs/method.md, "The cloud layer"): a periodic fractal noise
lattice of zero mean and unit variance, its mip levels and their variances, its cubic B-spline
coefficients packed with the levels for the compiled reads (``kernels.tiling.cloud_field``), and the
knots that turn the noise into coverage: a smoothstep in rank space, so that the coverage is at
least 1/2 on a fraction ``cover`` of the plane whatever the noise's distribution (``coverage_knots``)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import ndimage

__all__ = ["fractal_noise"]


@lru_cache(maxsize=16)
def _noise(seed: int, texels: int, period: float, spectral_slope: float):
    """(texture, sorted values), both read-only float64 (texels, texels); see ``fractal_noise``."""
    n = int(texels)
    white = np.random.default_rng(seed).standard_normal((n, n))
    ky = np.fft.fftfreq(n, d=1.0 / n)[:, None]  # cycles per tile
    kx = np.fft.rfftfreq(n, d=1.0 / n)[None, :]
    k0 = 0.5 * float(period)  # 1 / (2 scale) in cycles per tile of period * scale
    amplitude = (kx * kx + ky * ky + k0 * k0) ** (-(spectral_slope + 1.0) / 4.0)
    amplitude[0, 0] = 0.0
    field = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(n, n))
    field -= field.mean()
    field /= field.std()
    ordered = np.sort(field, axis=None)
    field.setflags(write=False)
    ordered.setflags(write=False)
    return field, ordered


def fractal_noise(seed: int, texels: int = 1024, *, period: float = 16.0,
                  spectral_slope: float = 5.0 / 3.0) -> np.ndarray:
    """The periodic fractal noise lattice of a cloud layer (zero mean, unit variance).

    Cached: the same arguments return the same array.

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng`` for the white noise.
    texels : int, optional
        Lattice side; one tile is ``texels x texels`` [count].
    period : float, optional
        Tile side in units of the feature size ``scale`` [1].
    spectral_slope : float, optional
        beta, slope of the 1-D transect power spectrum ``k^-beta`` [1].

    Returns
    -------
    numpy.ndarray
        Read-only float64 (texels, texels), indexed [row, col] with col along +x and row along -y [1].
    """
    return _noise(int(seed), int(texels), float(period), float(spectral_slope))[0]


@lru_cache(maxsize=8)
def _noise_levels(seed: int, texels: int, period: float, spectral_slope: float) -> tuple:
    """The noise lattice and its 2 x 2 box-filtered levels down to one texel (a mip pyramid of
    a periodic texture: every level keeps the mean and tiles). Read-only float64."""
    levels = [_noise(seed, texels, period, spectral_slope)[0]]
    while min(levels[-1].shape) > 1 and all(n % 2 == 0 for n in levels[-1].shape):
        a = levels[-1]
        coarser = 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])
        coarser.setflags(write=False)
        levels.append(coarser)
    return tuple(levels)


@lru_cache(maxsize=8)
def _level_variances(seed: int, texels: int, period: float, spectral_slope: float) -> np.ndarray:
    """Variance of each mip level of the noise (level 0: 1): (levels,) float64, entry k that of
    the lattice's means over boxes of 2^k texels. [dimensionless]"""
    return np.array([level.var() for level in _noise_levels(seed, texels, period, spectral_slope)])


def lost_variance(key: tuple[int, int, float, float], along: np.ndarray, across: np.ndarray) -> np.ndarray:
    """The variance of the noise within a footprint of widths ``along`` x ``across`` (m,)
    [texel] about its mean: 1 - var(box mean) for a box of the footprint's area, from the mip
    levels' variances (log-linear between them); below 2 texels, the lost variance of a
    2-texel box times (width / 2)^2 (a smooth field varies linearly within a small box).
    [dimensionless]"""
    variances = _level_variances(*key)
    lost = 1.0 - variances
    width = np.sqrt(np.maximum(along * across, 1e-300))  # the box of the same area [texel]
    level = np.log2(np.maximum(width, 1e-300))
    big = np.interp(level, np.arange(len(lost)), lost)
    small = lost[1] * (width / 2.0) ** 2 if len(lost) > 1 else np.zeros_like(width)
    return np.clip(np.where(width >= 2.0, big, np.minimum(small, big)), 0.0, 1.0)


@lru_cache(maxsize=8)
def _spline(seed: int, texels: int, period: float, spectral_slope: float) -> np.ndarray:
    """Cubic B-spline coefficients of the noise lattice (periodic), read-only float64."""
    coefficients = ndimage.spline_filter(_noise(seed, texels, period, spectral_slope)[0], order=3,
                                         mode="grid-wrap")
    coefficients.setflags(write=False)
    return coefficients


@lru_cache(maxsize=8)
def packed_levels(seed: int, texels: int, period: float, spectral_slope: float) -> tuple:
    """What ``kernels.tiling.cloud_field`` reads: (every level in one flat float64 array, each level's offset
    in it, each level's side [texel]). Level 0 is the lattice's cubic B-spline coefficients
    (``_spline``), the coarser levels the box-filtered lattice (``_noise_levels``)."""
    levels = (_spline(seed, texels, period, spectral_slope), *_noise_levels(seed, texels, period, spectral_slope)[1:])
    sides = np.array([level.shape[0] for level in levels], dtype=np.intp)
    offsets = np.concatenate([[0], np.cumsum([level.size for level in levels])[:-1]]).astype(np.intp)
    flat = np.concatenate([level.reshape(-1) for level in levels])
    flat.setflags(write=False)
    return flat, offsets, sides


@lru_cache(maxsize=64)
def coverage_knots(seed: int, texels: int, period: float, spectral_slope: float, cover: float,
                   softness: float) -> tuple[np.ndarray, np.ndarray]:
    """Field values and coverages of the rank-space smoothstep (see the module docstring)."""
    ordered = _noise(seed, texels, period, spectral_slope)[1]
    u0 = 1.0 - cover
    h = softness * min(cover, 1.0 - cover)
    t = np.linspace(0.0, 1.0, 33)
    ranks = u0 - h + 2.0 * h * t
    values = np.interp(ranks * (ordered.size - 1), np.arange(ordered.size), ordered)
    if h <= 0.0 or not np.all(np.diff(values) > 0.0):
        values = np.array([values[16], values[16] + 1e-12])
        return values, np.array([0.0, 1.0])
    return values, t * t * (3.0 - 2.0 * t)
