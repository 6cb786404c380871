import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml
from scenes import plan_of, tiny_grove

from pipeline.cache import store as cache
from pipeline.core import io
from pipeline.foreground.models import cut_to_trees, tree_box
from pipeline.stages.cycle import config_item_keys, cycle_phase, record_config_items, recorded_configs
from pipeline.stages.ground import render_ground

ROOT = Path(__file__).resolve().parents[1]


def run_cycle(data, base_dir, store):
    return cycle_phase(plan_of(data, base_dir), store, jobs=1)


SMALL_CAMERA = {"resolution": [96, 54]}
"""A camera of few pixels: the trees' foreground passes cost what their pixels cost (the default
1280 x 720 took 30 times as long), which items a change makes again does not depend on it."""


def small_grove(**changes):
    """``tiny_grove`` seen by SMALL_CAMERA; a ``camera`` change is laid over it."""
    camera = {**SMALL_CAMERA, **changes.pop("camera", {})}
    return tiny_grove(camera=camera, **changes)


def test_cycle_phase_is_computed_once_and_again_only_for_what_changes(tmp_path):
    """3 cycle frames: one layer's spectra and the trees' foreground passes each."""
    store = cache.Cache(tmp_path / "cache")
    assert run_cycle(small_grove(), tmp_path, store) == 6
    assert run_cycle(small_grove(), tmp_path, store) == 0
    # the sky's own settings and the exposure touch none of the canopy's products (the passes
    # are stored per unit irradiance)
    for change in ({"sky.turbidity": 5.0}, {"camera": {"exposure": 1.0}}):
        assert run_cycle(small_grove(**change), tmp_path, store) == 0, change
    for change, expected in (({"canopy.trees.leaves_per_tree": 401}, 6), ({"canopy.trees.seed": 4}, 6),
                             ({"ground.pixel": 0.125}, 3), ({"camera": {"fov": 40.0}}, 3),
                             ({"sky.sun": {"elevation": 50.0, "azimuth": 150.0}}, 6),
                             ({"canopy.flutter": {"cycle": 3, "swing": 5.0}}, 6)):
        assert run_cycle(small_grove(**change), tmp_path, store) == expected, change


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


def test_passes_cut_to_the_trees_lose_nothing():
    """Pasted back into a frame of zeros, the cut passes are the passes, bit for bit; passes
    that touch no pixel keep an empty box."""
    rng = np.random.default_rng(5)
    passes = {"sun": np.zeros((40, 60, 3), np.float32), "sky": np.zeros((40, 60, 3), np.float32),
              "alpha": np.zeros((40, 60), np.float32), "haze": np.zeros((40, 60), np.float32)}
    passes["alpha"][12:20, 30:41] = rng.random((8, 11))
    passes["sun"][25, 7] = 0.5  # a lone lit pixel outside the trees' coverage is kept too
    cut = cut_to_trees(passes)
    assert list(cut["box"]) == [12, 26, 7, 41]
    for name, full in passes.items():
        again = np.zeros_like(full)
        again[tree_box(cut)] = cut[name]
        np.testing.assert_array_equal(again, full)
    empty = cut_to_trees({name: np.zeros_like(values) for name, values in passes.items()})
    assert list(empty["box"]) == [0, 0, 0, 0] and empty["alpha"].size == 0


def test_a_config_recorded_twice_keeps_its_longest_cycle(tmp_path):
    """A preview (a shorter flutter cycle) recorded after the full run keeps both runs' items
    and the full cycle, so that `cache list` says 'cycle frames 3 of 3', not '3 of 1'."""
    store = cache.Cache(tmp_path / "cache")
    full = plan_of(tiny_grove(), tmp_path)
    quick = plan_of(tiny_grove(**{"canopy.flutter": {"cycle": 1}}), tmp_path)
    record_config_items(full, store)
    record_config_items(quick, store)
    (entry,) = recorded_configs(store)
    assert entry["cycle"] == 3
    assert entry["keys"] == set(config_item_keys(full)) | set(config_item_keys(quick))


_COMPILING = """
import json, os, sys, time
sys.path.insert(0, sys.argv[1])
from pipeline.core.cores import compiled_once
import loops
open(os.path.join(sys.argv[1], "ready-" + sys.argv[2]), "w").close()
while len([n for n in os.listdir(sys.argv[1]) if n.startswith("ready-")]) < 2:  # both start at once
    time.sleep(0.01)
with compiled_once(loops.step):
    loops.step(1.0)
print(json.dumps([loops.step.stats.cache_hits.get(s, 0) for s in loops.step.signatures]))
"""


def test_one_process_compiles_a_loop_the_others_load_it(tmp_path):
    """Two processes that first run the same compiled loop at once, numba's cache empty: inside
    ``cores.compiled_once`` one compiles it and the other loads it from numba's cache (without the
    lock both compiled it: the cycle phase's workers after an install)."""
    (tmp_path / "loops.py").write_text("from numba import njit\n\n\n@njit(cache=True)\ndef step(x):\n"
                                       "    return x + 1.0\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PYTHONPATH=str(Path.cwd()))
    runs = [subprocess.Popen([sys.executable, "-c", _COMPILING, str(tmp_path), str(k)], env=env,
                             stdout=subprocess.PIPE, text=True) for k in range(2)]
    hits = sorted(sum(json.loads(run.communicate(timeout=120)[0])) for run in runs)
    assert hits == [0, 1]
