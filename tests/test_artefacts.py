"""The artefacts a viewer notices first (issue 18), each checked in a small rendered picture:
a bright line at the horizon, the albedo's visible repetition, a seam at the sun window's edge,
periodic trees missing beyond the first tile."""

import numpy as np
import pytest
import yaml

from pipeline import cache, render
from pipeline.composite import REC709_LUMINANCE
from pipeline.config import load_config


def _config(tmp_path, config, name="scene.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(config))
    return load_config(path)


def _lawn(**changes):
    """Open ground, no trees in view: a single far-off tree, a level camera at eye height."""
    config = {
        "canopy": {"height": 4.0, "trees": {"count": 1, "seed": 3, "crown_radius": 1.0,
                                             "leaves_per_tree": 100, "leaf_length": 0.15},
                   "flutter": {"cycle": 2}},
        "sky": {"model": "procedural", "sun": {"elevation": 40.0, "azimuth": 200.0}, "alpha": 70.0,
                "haze": 400.0},
        "ground": {"window": [-3, -3, 3, 3], "pixel": 0.1},
        "camera": {"position": [0.0, 40.0, 1.7], "yaw": 0.0, "pitch": 0.0, "fov": 20.0,
                   "resolution": [64, 96]},
        "foreground": {"model": "none"},
        "animation": {"frames": 1},
    }
    for key, value in changes.items():
        node = config
        *path, last = key.split(".")
        for part in path:
            node = node.setdefault(part, {})
        node[last] = value
    return config


@pytest.mark.parametrize("clouds", [None, {"cover": 0.4, "scale": 800.0}])
def test_the_horizon_has_no_line_brighter_than_the_sky_and_ground_beside_it(tmp_path, clouds):
    """Down each column across the horizon the luminance has no peak above its neighbours a
    few rows up and down: the hazed far ground tends to the sky just above the horizon."""
    config = _config(tmp_path, _lawn(**({"sky.clouds": clouds} if clouds else {})))
    frame = render.render_frame(config, store=cache.Cache(tmp_path / "c"), workers=1)
    lum = frame.radiance @ REC709_LUMINANCE.astype(np.float32)
    horizon = config.camera.resolution[1] // 2  # a level camera: the horizon crosses the middle row
    band = lum[horizon - 4 : horizon + 5]
    above, below = band[:4].max(axis=0), band[5:].max(axis=0)
    assert np.all(band[4] <= np.maximum(above, below) * 1.01 + 1e-6)
    assert np.all(band.max(axis=0) <= np.maximum(above, below) * 1.01 + 1e-6)
