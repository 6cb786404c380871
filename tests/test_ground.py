import numpy as np
import pytest
from scenes import plan_of, tiny_grove

from pipeline.cache import store as cache
from pipeline.ground.shadow import resample_bilinear
from pipeline.stages.ground import render_ground


@pytest.mark.parametrize("layout", ["isolated", "periodic"])
def test_outer_raster_with_a_coarse_sun_matches_the_fine_one(tmp_path, layout):
    """Beyond a small sun window a camera sees the coarse raster with the sun at the coarse
    cell: on the sun window its 0.4 m block means agree with the two-scale raster, and outside
    it the grove's shadow is there."""
    changes = {"ground.sun_window": [-1.2, -1.2, 1.2, 1.2]}
    if layout == "periodic":
        changes.update({"canopy.layout": "periodic", "canopy.size": [3.0, 3.0]})
    result = render_ground(plan_of(tiny_grove(**changes), tmp_path), 0, store=cache.Cache(tmp_path / "c"),
                           outer=True)
    outer, grid = result.outer.irradiance, result.outer.grid
    assert grid.shape == (60, 60) and result.grid.pixel == 0.04
    on_fine = np.moveaxis(resample_bilinear(np.moveaxis(outer, -1, 0), grid, result.grid), 0, -1)
    blocks = lambda a: a[:60, :60].reshape(6, 10, 6, 10, 3).mean(axis=(1, 3))  # noqa: E731
    # the coarse sun errs by a share of the sun's light (in deep shade a large share of little
    # light): measured against the open ground's light
    rel = np.abs(blocks(on_fine) - blocks(result.irradiance)) / result.unshadowed
    assert rel.mean() < 0.02 and rel.max() < 0.06, (rel.mean(), rel.max())
    assert outer.min() < 0.6 * result.unshadowed.min()
    whole = render_ground(plan_of(tiny_grove(**{**changes, "ground.sun_window": [-3, -3, 3, 3]}), tmp_path),
                          0, store=cache.Cache(tmp_path / "c"), outer=True)
    assert whole.outer is None  # the sun window covers the window: nothing to add
