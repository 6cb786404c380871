import numpy as np
import pytest

from pipeline import ephemeris
from pipeline.render import _offset_direction


@pytest.mark.parametrize("azimuth,elevation", [(180.0, 60.0), (95.0, 20.0), (300.0, 75.0)])
def test_moon_offsets_invert_the_ephemeris_tangent_plane(azimuth, elevation):
    """An explicit moon offset from the sun lands where ephemeris.moon_offset_from_sun,
    an independent forward map, says it is."""
    sun = ephemeris.BodyPosition(np.radians(azimuth), np.radians(elevation), 0.0047)
    for dx, dy in [(0.01, 0.0), (-0.004, 0.007), (0.0, -0.009)]:
        az, el = _offset_direction(sun.azimuth, sun.elevation, dx, dy)
        moon = ephemeris.BodyPosition(az, el, 0.0047)
        assert ephemeris.moon_offset_from_sun(sun, moon) == pytest.approx((dx, dy), abs=1e-12)


import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import yaml  # noqa: E402

from pipeline import cache, render  # noqa: E402
from pipeline.config import load_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def tiny_grove(**changes):
    """A small grove under a procedural sun: a few hundred leaves, coarse pixels."""
    config = {
        "canopy": {"height": 4.0, "trees": {"count": 1, "seed": 3, "crown_radius": 1.5,
                                             "leaves_per_tree": 400, "leaf_length": 0.15},
                   "flutter": {"cycle": 3}},
        "sky": {"model": "procedural", "sun": {"elevation": 55.0, "azimuth": 150.0},
                "alpha": 70.0},
        "ground": {"window": [-3, -3, 3, 3], "pixel": 0.1, "sun_window": [-1, -1, 1, 1],
                   "sun_pixel": 0.04},
        "animation": {"frames": 6},
    }
    for key, value in changes.items():
        node = config
        *path, last = key.split(".")
        for part in path:
            node = node[part]
        node[last] = value
    return config


def load(tmp_path, config, name="grove.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(config))
    return load_config(path)


def run_cycle(config, store):
    return render.cycle_phase(config, render.plan_run(config), store, jobs=1)


def test_cycle_phase_is_computed_once_and_again_only_for_what_changes(tmp_path):
    """3 cycle frames: one layer's spectra and the trees' foreground passes each."""
    store = cache.Cache(tmp_path / "cache")
    base = load(tmp_path, tiny_grove())
    assert run_cycle(base, store) == 6
    assert run_cycle(base, store) == 0
    # the sky's own settings and the exposure touch none of the canopy's products (the passes
    # are stored per unit irradiance)
    for change in ({"sky.turbidity": 5.0}, {"camera": {"exposure": 1.0}}):
        assert run_cycle(load(tmp_path, tiny_grove(**change)), store) == 0, change
    for change, expected in (({"canopy.trees.leaves_per_tree": 401}, 6), ({"canopy.trees.seed": 4}, 6),
                             ({"ground.pixel": 0.125}, 3), ({"camera": {"fov": 40.0}}, 3),
                             ({"sky.sun": {"elevation": 50.0, "azimuth": 150.0}}, 6),
                             ({"canopy.flutter": {"cycle": 3, "swing": 5.0}}, 6)):
        assert run_cycle(load(tmp_path, tiny_grove(**change)), store) == expected, change


def test_a_truncated_cycle_item_is_recomputed_not_used(tmp_path):
    store = cache.Cache(tmp_path / "cache")
    config = load(tmp_path, tiny_grove())
    first = render.render_ground(config, frame=4, store=store, workers=1).irradiance
    items = store.list()
    assert len(items) == 1
    spectrum = store.item_path(items[0].kind, items[0].key) / "fine.npy"
    with open(spectrum, "r+b") as f:
        f.truncate(spectrum.stat().st_size // 2)
    fresh = cache.Cache(tmp_path / "cache")
    again = render.render_ground(config, frame=4, store=fresh, workers=1).irradiance
    assert fresh.repaired == 1
    np.testing.assert_array_equal(first, again)


def test_two_processes_rendering_the_same_frame_share_one_item(tmp_path):
    load(tmp_path, tiny_grove())
    env = {**__import__("os").environ, "SUNSHADE_CACHE": str(tmp_path / "cache")}
    runs = [subprocess.Popen([sys.executable, "-m", "pipeline.cli", "ground", str(tmp_path / "grove.yaml"),
                              "-o", str(tmp_path / f"g{i}.exr"), "--threads", "1"],
                             cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            for i in range(2)]
    for run in runs:
        _, err = run.communicate(timeout=120)
        assert run.returncode == 0, err.decode()
    store = cache.Cache(tmp_path / "cache")
    assert len(store.list()) == 1 and store.verify() == []
    from pipeline import io
    np.testing.assert_array_equal(io.read_image(tmp_path / "g0.exr"), io.read_image(tmp_path / "g1.exr"))


def test_scene_moves_the_moon_across_the_frames(tmp_path):
    config = load(tmp_path, tiny_grove(**{"sky.moon": {"offset_start": [-0.6, 0.0],
                                                       "offset_end": [0.6, 0.0]}}))
    first, middle, last = (render.scene_at(config, f) for f in (0, 3, 5))
    sun = ephemeris.BodyPosition(first.sun.azimuth, first.sun.elevation, 0.0)

    def offset(scene):
        moon = ephemeris.BodyPosition(scene.moon.azimuth, scene.moon.elevation, 0.0)
        return np.degrees(ephemeris.moon_offset_from_sun(sun, moon))

    assert offset(first) == pytest.approx((-0.6, 0.0), abs=1e-9)
    assert offset(last) == pytest.approx((0.6, 0.0), abs=1e-9)
    assert offset(middle)[0] == pytest.approx(-0.6 + 1.2 * 3 / 5, abs=1e-9)
    assert last.time == pytest.approx(5 / 24)


@pytest.mark.parametrize("layout", ["isolated", "periodic"])
def test_outer_raster_with_a_coarse_sun_matches_the_fine_one(tmp_path, layout):
    """Beyond a small sun window a camera sees the coarse raster with the sun at the coarse
    cell: on the sun window its 0.4 m block means agree with the two-scale raster, and outside
    it the grove's shadow is there."""
    changes = {"ground.sun_window": [-1.2, -1.2, 1.2, 1.2]}
    if layout == "periodic":
        changes.update({"canopy.layout": "periodic", "canopy.size": [3.0, 3.0]})
    config = load(tmp_path, tiny_grove(**changes))
    result = render.render_ground(config, frame=0, store=cache.Cache(tmp_path / "c"), outer=True)
    outer, grid = result.outer
    assert grid.shape == (60, 60) and result.grid.pixel == 0.04
    from pipeline.shadow import resample_bilinear
    on_fine = np.moveaxis(resample_bilinear(np.moveaxis(outer, -1, 0), grid, result.grid), 0, -1)
    blocks = lambda a: a[:60, :60].reshape(6, 10, 6, 10, 3).mean(axis=(1, 3))  # noqa: E731
    # the coarse sun errs by a share of the sun's light (in deep shade a large share of little
    # light): measured against the open ground's light
    rel = np.abs(blocks(on_fine) - blocks(result.irradiance)) / result.unshadowed
    assert rel.mean() < 0.02 and rel.max() < 0.06, (rel.mean(), rel.max())
    assert outer.min() < 0.6 * result.unshadowed.min()
    whole = render.render_ground(load(tmp_path, tiny_grove(**{**changes, "ground.sun_window": [-3, -3, 3, 3]})),
                                 frame=0, store=cache.Cache(tmp_path / "c"), outer=True)
    assert whole.outer is None  # the sun window covers the window: nothing to add


def test_a_camera_looking_straight_down_sees_the_ground_raster(tmp_path):
    """No foreground, no haze, a white albedo: a camera straight above the sun window whose
    pixels fall on the raster's pixels shows radiance E / pi of the ground raster, north up."""
    from pipeline import io

    io.write_exr(tmp_path / "white.exr", np.ones((4, 4, 3), np.float32))
    height = 2.0
    fov = float(np.degrees(2 * np.arctan(1.0 / height)))  # 2 m across at 2 m: one 0.04 m texel per pixel
    config = load(tmp_path, tiny_grove(**{
        "ground.albedo": "white.exr", "sky.haze": 0.0, "foreground": {"model": "none"},
        "camera": {"position": [0.0, 0.0, height], "yaw": 0.0, "pitch": -90.0, "fov": fov,
                   "resolution": [50, 50]}}))
    result = render.render_frame(config, frame=0, store=cache.Cache(tmp_path / "c"))
    ground = result.ground.irradiance
    assert ground.shape == (50, 50, 3)
    if result.ground.outer:  # within the blend band the fine raster gives way to the coarse one
        ground = render.blend_band(ground, result.ground.grid, *result.ground.outer)
    np.testing.assert_allclose(result.radiance, ground / np.pi, rtol=2e-3)
    assert result.sun_fraction == pytest.approx(1.0)
