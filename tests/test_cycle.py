import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from pipeline import cache, io
from pipeline.cycle import cycle_phase
from pipeline.ground import render_ground

from scenes import plan_of, tiny_grove

ROOT = Path(__file__).resolve().parents[1]


def run_cycle(data, base_dir, store):
    return cycle_phase(plan_of(data, base_dir), store, jobs=1)


def test_cycle_phase_is_computed_once_and_again_only_for_what_changes(tmp_path):
    """3 cycle frames: one layer's spectra and the trees' foreground passes each."""
    store = cache.Cache(tmp_path / "cache")
    assert run_cycle(tiny_grove(), tmp_path, store) == 6
    assert run_cycle(tiny_grove(), tmp_path, store) == 0
    # the sky's own settings and the exposure touch none of the canopy's products (the passes
    # are stored per unit irradiance)
    for change in ({"sky.turbidity": 5.0}, {"camera": {"exposure": 1.0}}):
        assert run_cycle(tiny_grove(**change), tmp_path, store) == 0, change
    for change, expected in (({"canopy.trees.leaves_per_tree": 401}, 6), ({"canopy.trees.seed": 4}, 6),
                             ({"ground.pixel": 0.125}, 3), ({"camera": {"fov": 40.0}}, 3),
                             ({"sky.sun": {"elevation": 50.0, "azimuth": 150.0}}, 6),
                             ({"canopy.flutter": {"cycle": 3, "swing": 5.0}}, 6)):
        assert run_cycle(tiny_grove(**change), tmp_path, store) == expected, change


def test_a_truncated_cycle_item_is_recomputed_not_used(tmp_path):
    store = cache.Cache(tmp_path / "cache")
    plan = plan_of(tiny_grove(), tmp_path)
    first = render_ground(plan, 4, store=store, workers=1).irradiance
    items = store.list()
    assert len(items) == 1
    spectrum = store.item_path(items[0].kind, items[0].key) / "fine.npy"
    with open(spectrum, "r+b") as f:
        f.truncate(spectrum.stat().st_size // 2)
    fresh = cache.Cache(tmp_path / "cache")
    again = render_ground(plan, 4, store=fresh, workers=1).irradiance
    assert fresh.repaired == 1
    np.testing.assert_array_equal(first, again)


def test_two_processes_rendering_the_same_frame_share_one_item(tmp_path):
    (tmp_path / "grove.yaml").write_text(yaml.safe_dump(tiny_grove()))
    env = {**os.environ, "SUNSHADE_CACHE": str(tmp_path / "cache")}
    runs = [subprocess.Popen([sys.executable, "-m", "pipeline.cli", "ground", str(tmp_path / "grove.yaml"),
                              "-o", str(tmp_path / f"g{i}.exr"), "--threads", "1"],
                             cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            for i in range(2)]
    for run in runs:
        _, err = run.communicate(timeout=120)
        assert run.returncode == 0, err.decode()
    store = cache.Cache(tmp_path / "cache")
    assert len(store.list()) == 1 and store.verify() == []
    np.testing.assert_array_equal(io.read_image(tmp_path / "g0.exr"), io.read_image(tmp_path / "g1.exr"))
