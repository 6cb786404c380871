"""Tests of pipeline/texture/albedo.py: the procedural grass-and-soil texture."""

import numpy as np
import pytest
import reference

from pipeline.camera import pinhole as camera
from pipeline.texture import albedo
from pipeline.texture import mipmap as texture
from pipeline.texture.albedo import grass_albedo, stochastic_tiling


def test_grass_albedo_is_a_plausible_albedo_on_its_grid():
    image, grid = grass_albedo(size_px=256, period=2.0, seed=3)
    assert image.shape == (256, 256, 3) and image.dtype == np.float32
    assert np.all(image > 0) and np.all(image < 1)
    assert 0.12 <= image.mean() <= 0.2
    assert grid.shape == (256, 256) and grid.pixel == pytest.approx(2.0 / 256)
    x_min, y_min, x_max, y_max = grid.extent
    assert (x_max - x_min, y_max - y_min) == pytest.approx((2.0, 2.0))
    # green grass with patches of brown soil (red above green)
    soil = image[..., 0] > image[..., 1]
    assert 0.05 < soil.mean() < 0.5
    assert np.mean(image[~soil, 1] > image[~soil, 0]) == 1.0


def test_grass_albedo_tiles_seamlessly():
    image, _ = grass_albedo(size_px=256, period=2.0, seed=1)
    inside = np.abs(np.diff(image, axis=1)).mean()
    across_x = np.abs(image[:, 0] - image[:, -1]).mean()
    across_y = np.abs(image[0] - image[-1]).mean()
    assert across_x < 1.3 * inside and across_y < 1.3 * inside


def test_grass_albedo_is_deterministic_by_seed():
    a, _ = grass_albedo(size_px=64, seed=5)
    b, _ = grass_albedo(size_px=64, seed=5)
    c, _ = grass_albedo(size_px=64, seed=6)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.005
    with pytest.raises(ValueError):
        grass_albedo(size_px=64, period=0.0)


# ---- stochastic tiling (Heitz & Neyret 2018) ----------------------------------------------


def _tiled(size_px=256, period=4.0):
    image, grid = grass_albedo(size_px=size_px, period=period, seed=2)
    mip = texture.mipmap(image, grid, outside="periodic", period=(period, period))
    return mip, stochastic_tiling(mip, seed=5)


def _points(x, y, width):
    n = x.size
    return texture.Footprints(x.ravel(), y.ravel(), np.full(n, width), np.full(n, width), np.ones(n), np.zeros(n))


def test_stochastic_tiling_breaks_the_tile_period():
    """The correlation of the laid albedo with itself one tile period away (along x, along y
    and along the diagonal) is under 0.15, where the plain tile's is 1 by construction."""
    period = 4.0
    mip, tiling = _tiled(period=period)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-200.0, 200.0, (2, 40000))
    luminance = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    here = luminance @ tiling.sample(_points(x, y, 0.016), lod_bias=texture.LOD_BIAS)
    plain = luminance @ texture.sample_footprints(mip, _points(x, y, 0.016)).T
    for dx, dy in ((period, 0.0), (0.0, period), (period, period)):
        there = luminance @ tiling.sample(_points(x + dx, y + dy, 0.016), lod_bias=texture.LOD_BIAS)
        plain_there = luminance @ texture.sample_footprints(mip, _points(x + dx, y + dy, 0.016)).T
        assert np.corrcoef(plain, plain_there)[0, 1] > 0.999
        assert abs(np.corrcoef(here, there)[0, 1]) < 0.15


def test_stochastic_tiling_keeps_the_tiles_histogram_and_mean_at_every_scale():
    """Point reads have the plain tile's mean, spread and percentiles per channel; wide footprints
    (a far pixel) tend to the tile's mean, as the plain tile's do."""
    mip, tiling = _tiled()
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-100.0, 100.0, (2, 60000))
    tile = texture.sample_footprints(mip, _points(x, y, 0.01))  # the same bilinear reads, untiled
    laid = tiling.sample(_points(x, y, 0.01), lod_bias=texture.LOD_BIAS).T
    np.testing.assert_allclose(laid.mean(axis=0), tile.mean(axis=0), rtol=0.02)
    np.testing.assert_allclose(laid.std(axis=0), tile.std(axis=0), rtol=0.08)
    for q in (5, 50, 95):
        np.testing.assert_allclose(np.percentile(laid, q, axis=0), np.percentile(tile, q, axis=0), rtol=0.06)
    for width in (0.5, 8.0):
        plain = texture.sample_footprints(mip, _points(x[:5000], y[:5000], width))
        laid = tiling.sample(_points(x[:5000], y[:5000], width), lod_bias=texture.LOD_BIAS).T
        np.testing.assert_allclose(laid.mean(axis=0), plain.mean(axis=0), rtol=0.02)
        np.testing.assert_allclose(laid.std(axis=0), plain.std(axis=0), rtol=0.25, atol=1e-4)


def view_footprints(width=320, height=180):
    """The ground footprints of a camera 1.7 m up looking 30 degrees down: near pixels a few
    millimetres across, far ones metres long, up to the horizon."""
    view = camera.Camera.look_at((0.3, -2.0, 1.7), (1.0, 3.0, 0.0), vertical_fov=np.radians(60.0),
                                 width=width, height=height)
    rows, part = camera.rows_seeing_ground(view)
    *ellipses, _ = camera._row_footprints(view, rows, part)
    return texture.Footprints(*ellipses)


def test_compiled_tiling_matches_the_array_version(monkeypatch):
    """StochasticTiling.sample (compiled, one pass) against reference.tiling_sample_arrays (the former numpy
    code, kept as the reference), every read taken and with reads under SKIP_WEIGHT left out
    alike: the same albedo within float32 rounding."""
    _, tiling = _tiled(size_px=128, period=2.0)
    fp = view_footprints()
    for skip in (0.0, albedo.SKIP_WEIGHT):
        monkeypatch.setattr(albedo, "SKIP_WEIGHT", skip)
        got = tiling.sample(fp, lod_bias=texture.LOD_BIAS)
        want = reference.tiling_sample_arrays(tiling, fp, lod_bias=texture.LOD_BIAS, skip=skip)
        assert got.dtype == np.float32 and got.shape == want.shape == (3, len(fp))
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)


def test_skipping_light_reads_changes_the_albedo_by_little():
    """Reads of sharpened weight under SKIP_WEIGHT are left out: about two reads a pixel
    instead of three, and the albedo moves by under 4 % of its mean anywhere (measured 2.9 %)
    and by 0.1 % RMS (measured 0.06 %)."""
    _, tiling = _tiled(size_px=128, period=2.0)
    fp = view_footprints()
    _, w = tiling.weights(fp.x, fp.y)
    w = w**albedo.BLEND_SHARPNESS
    w /= w.sum(axis=0)
    assert 1.8 < np.mean(np.sum(w >= albedo.SKIP_WEIGHT, axis=0)) < 2.2
    every = reference.tiling_sample_arrays(tiling, fp, lod_bias=texture.LOD_BIAS, skip=0.0)
    skipped = tiling.sample(fp, lod_bias=texture.LOD_BIAS)
    difference = np.abs(skipped.astype(np.float64) - every)
    assert difference.max() < 0.04 * every.mean()
    assert np.sqrt(np.mean(difference**2)) < 1e-3 * every.mean()
    assert difference.max() > 0  # reads were left out
