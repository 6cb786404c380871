"""Tests of pipeline/albedo.py: the procedural grass-and-soil texture."""

import numpy as np
import pytest

from pipeline.albedo import grass_albedo


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
