import numpy as np
import pytest

from pipeline.canopy import occlusion_on_lattice, tile_on_lattice, transmittance_from_image
from pipeline.geometry import Grid

from reference import image_transmittance


def supersampled(f, grid, n=64):
    """Mean of f(x, y) [m] over each pixel of a grid, by n x n point samples."""
    rows, cols = grid.shape
    sub = (np.arange(n) + 0.5) / n - 0.5
    r = np.arange(rows)[:, None, None, None] + sub[None, None, :, None]
    c = np.arange(cols)[None, :, None, None] + sub[None, None, None, :]
    x, y = grid.ground_from_raster(r, c)
    return f(x, y).mean(axis=(2, 3))


def test_transmittance_from_image_channels_and_range():
    grey = np.full((2, 3, 1), 0.25, np.float32)
    assert np.allclose(transmittance_from_image(grey), 0.25)
    rgb = np.zeros((2, 3, 4), np.float32)
    rgb[..., 1] = 1.0  # pure green, alpha 0 ignored
    assert np.allclose(transmittance_from_image(rgb), 0.7152)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        transmittance_from_image(np.full((2, 2, 1), 2.0, np.float32))
    with pytest.raises(ValueError, match="finite"):
        transmittance_from_image(np.full((2, 2, 1), np.nan, np.float32))


def test_isolated_mask_is_area_averaged_onto_the_lattice():
    rng = np.random.default_rng(3)
    mask = (rng.random((37, 23)) > 0.5).astype(np.float32)
    center, size = (0.13, -0.41), (2.3, 3.7)  # texels 0.1 m, lattice 0.07 m, not aligned
    lattice = Grid.from_window((-3.0, -3.0, 3.0, 3.0), 0.07)
    occlusion, grid = occlusion_on_lattice(mask, center=center, size=size, lattice=lattice)
    # the grid covers the mask and sits on the lattice
    x0, y0, x1, y1 = grid.extent
    assert x0 <= center[0] - size[0] / 2 and x1 >= center[0] + size[0] / 2
    assert y0 <= center[1] - size[1] / 2 and y1 >= center[1] + size[1] / 2
    f = image_transmittance(mask, center=center, size=size, outside=1.0)
    reference = 1.0 - supersampled(f, grid)
    error = np.abs(occlusion - reference)  # the reference's point sampling errs ~1/64 per edge
    assert error.mean() < 0.004 and error.max() < 2.5 / 64
    # the occluded area is kept exactly
    texel_area = size[0] * size[1] / mask.size
    assert occlusion.sum() * 0.07**2 == pytest.approx((1 - mask).sum() * texel_area, rel=1e-5)


def test_periodic_tile_wraps_and_keeps_the_mean():
    rng = np.random.default_rng(4)
    mask = rng.random((16, 24)).astype(np.float32)
    center, size = (0.37, -0.12), (2.4, 1.6)  # 30 x 20 lattice pixels of 0.08 m
    lattice = Grid.from_window((-1.0, -1.0, 1.0, 1.0), 0.08)
    tile, grid = tile_on_lattice(mask, center=center, size=size, lattice=lattice)
    assert tile.shape == (20, 30)
    assert tile.mean() == pytest.approx(mask.mean(), rel=1e-5)
    f = image_transmittance(mask, center=center, size=size, periodic=True)
    error = np.abs(tile - supersampled(f, grid))
    assert error.mean() < 0.004 and error.max() < 2.5 / 64
