"""The artefacts a viewer notices first (issue 18), each checked in a small rendered picture:
a bright line at the horizon, the albedo's visible repetition, a seam at the sun window's edge,
periodic trees missing beyond the first tile."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from scenes import config_of

from pipeline.cache import store as cache
from pipeline.camera import pinhole as cameras
from pipeline.canopy import grove as grove_geometry
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.foreground import tree_detail
from pipeline.foreground import trees as foreground
from pipeline.stages.cycle import foreground_item
from pipeline.stages.frame import render_frame
from pipeline.stages.inputs import grove_of
from pipeline.stages.plan import plan_run


def _config(tmp_path, config):
    return config_of(config, tmp_path)


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


@pytest.mark.parametrize("sky", ["clear", "clouds", "hdri"])
def test_the_horizon_has_no_line_brighter_or_darker_than_the_sky_and_ground_beside_it(tmp_path, sky):
    """Down each column across the horizon the luminance stays within the range of the rows a
    few pixels above and below it (1% slack): no bright line (the hazed far ground tends to the
    sky just above the horizon) and no dark one (an HDRI's own ground, below its horizon, is not
    blended into the sky above ours)."""
    changes = {}
    if sky == "clouds":
        changes = {"sky.clouds": {"cover": 0.4, "scale": 800.0}}
    if sky == "hdri":  # an even sky over a dark ground, with no sun
        image = np.full((64, 128, 3), 2.0, np.float32)
        image[32:] = 0.1
        io.write_exr(tmp_path / "sky.exr", image)
        changes = {"sky": {"model": "hdri", "hdri": "sky.exr", "haze": 400.0}}
    config = _config(tmp_path, _lawn(**changes))
    frame = render_frame(plan_run(config), store=cache.Cache(tmp_path / "c"), workers=1)
    lum = frame.radiance @ REC709_LUMINANCE.astype(np.float32)
    horizon = config.camera.resolution[1] // 2  # a level camera: the horizon is the middle row's top
    middle = lum[horizon - 1 : horizon + 2]  # the last sky row and the first two ground rows
    ends = np.concatenate([lum[horizon - 5 : horizon - 1], lum[horizon + 2 : horizon + 6]])
    assert np.all(middle <= ends.max(axis=0) * 1.01 + 1e-6)
    assert np.all(middle >= ends.min(axis=0) * 0.99 - 1e-6)
    if sky == "hdri":  # the sky rows show the image's even sky down to the horizon
        np.testing.assert_allclose(lum[horizon - 8 : horizon], 2.0, rtol=0.01)


def test_a_periodic_forest_stands_on_every_tile_in_view():
    """One tree in a 10 m tile, the camera looking along a row of tiles: the trunk of every
    copy out to 60 m covers the image where the copy's trunk projects (independently, by
    pinhole.project_points), and the gaps between the copies' trunks stay open."""
    tile = 10.0
    grove = grove_geometry.grow_grove(grove_geometry.GroveParams(count=1, seed=4, crown_radius=2.0, leaves_per_tree=200,
                                                 height=6.0, layout="periodic", tile=tile))
    leaves = grove_geometry.leaves_at(grove, grove_geometry.FlutterParams(cycle=2), 0)
    foot = grove.bases[0, :2]
    view = cameras.Camera((foot[0] + 0.6, foot[1] - 3.0, 1.5), 0.0, 0.0, np.radians(40.0), 200, 120)
    copies, wood, _leaf_index, _wood_index = tree_detail.periodic_copies(
        leaves, grove.wood, view, period=tile, center=(0.0, 0.0), haze=400.0)
    assert len(wood.radius) > 10 * len(grove.wood.radius)
    passes = foreground.tree_passes(copies, wood, view, sun_direction=[0.0, 0.6, 0.8], sun_irradiance=1.0,
                                    sky_irradiance=1.0, leaf_sun_visibility=1.0, wood_sun_visibility=1.0,
                                    haze=400.0)
    for k in range(1, 7):  # the trunk of the copy k tiles north, at 1 m above the ground
        u, v, depth = cameras.project_points(view, np.array([foot[0], foot[1] + k * tile, 1.0]))
        assert depth > 0
        assert passes.alpha[int(v), int(u)] > 0.5, k
    # beside the trunks at their foot, halfway to the next column of trees, the ground shows
    u, v, _ = cameras.project_points(view, np.array([foot[0] + 0.5 * tile, foot[1] + 3 * tile, 0.3]))
    assert passes.alpha[int(v), int(u)] < 0.1
    # the haze veils the far copies more than the near ones
    near = cameras.project_points(view, np.array([foot[0], foot[1] + tile, 1.0]))
    far = cameras.project_points(view, np.array([foot[0], foot[1] + 6 * tile, 1.0]))
    assert passes.haze[int(far[1]), int(far[0])] > passes.haze[int(near[1]), int(near[0])] > 0


@pytest.mark.parametrize("mask_value", [0.5, None])
def test_no_seam_at_the_sun_windows_edge(tmp_path, mask_value):
    """A uniform canopy (an even grey mask, or even white noise) in a periodic layout, the
    camera straight down over the sun window's west edge, white ground, no haze: along each
    row, the largest step between neighbouring pixels within 4 pixels of the edge is no larger
    than the largest step inside either side (the fine sun-resolved ground and the coarse one)."""
    rng = np.random.default_rng(7)
    mask = np.full((60, 60, 1), mask_value, np.float32) if mask_value else rng.random((60, 60, 1)).astype(np.float32)
    io.write_exr(tmp_path / "mask.exr", mask)
    io.write_exr(tmp_path / "white.exr", np.ones((4, 4, 3), np.float32))
    config = _config(tmp_path, {
        "canopy": {"mask": "mask.exr", "size": [6.0, 6.0], "height": 4.0, "layout": "periodic"},
        "sky": {"model": "procedural", "sun": {"elevation": 60.0, "azimuth": 180.0}, "alpha": 70.0,
                "haze": 0.0},
        "ground": {"window": [-3, -3, 3, 3], "pixel": 0.1, "sun_window": [-1.0, -1.5, 2.0, 1.5],
                   "sun_pixel": 0.02, "albedo": "white.exr"},
        "camera": {"position": [-1.0, 0.0, 3.0], "yaw": 0.0, "pitch": -90.0, "fov": 40.0,
                   "resolution": [80, 40]},  # x from -3.2 to 1.2 m: the west edge, not the east
        "foreground": {"model": "none"},
        "animation": {"frames": 1},
    })
    frame = render_frame(plan_run(config), store=cache.Cache(tmp_path / "c"), workers=1)
    lum = (frame.radiance @ REC709_LUMINANCE.astype(np.float32)).astype(np.float64)
    edge = config.camera.resolution[0] // 2  # x = -1 m is the middle column's left side
    steps = np.abs(np.diff(lum, axis=1))  # steps[:, j] is between columns j and j + 1
    at_edge = steps[:, edge - 5 : edge + 4].max(axis=1)
    coarse_side = steps[:, 2 : edge - 8].max(axis=1)
    fine_side = steps[:, edge + 8 : -2].max(axis=1)
    assert np.all(at_edge <= np.maximum(coarse_side, fine_side) + 1e-4 * lum.mean())


def test_forest_yaml_has_its_trees_on_the_tiles_around_the_camera(tmp_path):
    """configs/forest.yaml with few leaves and a small image: the trunk of every tree of every
    tile whose foot lies in view within 25 m covers the image where it projects, at 1 m above
    the ground; before, only the trees of the first tile stood."""
    root = Path(__file__).resolve().parents[1]
    data = yaml.safe_load((root / "configs" / "forest.yaml").read_text())
    data["canopy"]["trees"]["leaves_per_tree"] = 300
    data["camera"]["resolution"] = [320, 180]
    data["ground"]["albedo"] = str(root / "configs" / "assets" / "lawn.png")
    config = _config(tmp_path, data)
    plan = plan_run(config)
    item = foreground_item(plan, 0, cache.Cache(tmp_path / "c"))
    alpha = np.zeros((plan.camera.height, plan.camera.width), np.float32)
    alpha[item.region] = item.alpha
    grove, _ = grove_of(config.canopy)
    view = plan.camera
    tile = config.canopy.layers[0].size[0]
    checked = 0
    for i in range(-3, 4):
        for j in range(-3, 4):
            for foot in grove.bases[:, :2] + [i * tile, j * tile]:
                point = np.array([foot[0], foot[1], 1.0])
                u, v, depth = cameras.project_points(view, point)
                far = np.linalg.norm(point - np.asarray(view.position))
                if depth > 1.0 and far < 25.0 and 2 <= u < 318 and 2 <= v < 178:
                    checked += 1
                    assert alpha[int(v), int(u)] > 0.5, (i, j, foot)
    assert checked >= 8
