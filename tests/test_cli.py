import contextlib
import os
import re
import signal
import subprocess
import sys
import time
from datetime import timedelta
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from scenes import assert_refused, base_config, set_key, write_config
from test_run import TINY

from pipeline.cache.store import Cache
from pipeline.cli.main import main
from pipeline.cli.runs import _Progress
from pipeline.core import io

ROOT = Path(__file__).resolve().parents[1]


def test_ground_writes_exr_with_metadata_and_png(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, base_config())
    assert main(["ground", str(config), "-o", str(out / "g.exr"), "--png"]) == 0
    assert " klx (R, G, B); wrote" in capsys.readouterr().out  # the open sky's light, with its unit
    g = io.read_image(out / "g.exr")
    assert g.shape == (80, 80, 3) and g.dtype == np.float32
    attrs = io.read_attributes(out / "g.exr", ["sunshade:window", "sunshade:pixel_size",
                                               "sunshade:config_hash"])
    assert attrs["sunshade:window"] == pytest.approx((-4, -4, 4, 4))
    assert attrs["sunshade:pixel_size"] == pytest.approx(0.1)
    assert len(attrs["sunshade:config_hash"]) == 16
    assert g.max() <= np.pi * 1.001 and g.min() < 0.9 * np.pi
    png = io.read_image(out / "g.png")
    assert png.shape == (80, 80, 3)
    assert sorted(p.name for p in out.iterdir()) == ["g.exr", "g.png"]  # no temporaries left


def test_uniform_hdri_config_equals_uniform_model(inputs):
    folder, out = inputs
    uniform = write_config(folder, base_config(), "u.yaml")
    cfg = base_config()
    cfg["sky"] = {"model": "hdri", "hdri": "sky.exr", "alpha": 80.0}
    hdri = write_config(folder, cfg, "h.yaml")
    assert main(["ground", str(uniform), "-o", str(out / "u.exr")]) == 0
    assert main(["ground", str(hdri), "-o", str(out / "h.exr")]) == 0
    a, b = io.read_image(out / "u.exr"), io.read_image(out / "h.exr")
    assert np.abs(a / b - 1).max() < 0.005


def test_config_hash_follows_the_inputs(inputs):
    folder, out = inputs
    config = write_config(folder, base_config())
    main(["ground", str(config), "-o", str(out / "a.exr")])
    io.write_png(folder / "mask.png", np.ones((40, 40, 1), np.float32))  # same config, new mask
    main(["ground", str(config), "-o", str(out / "b.exr")])
    names = ["sunshade:config_hash"]
    assert io.read_attributes(out / "a.exr", names) != io.read_attributes(out / "b.exr", names)


def test_layers_multiply(inputs):
    folder, out = inputs
    cfg = base_config()
    cfg["canopy"]["layers"] = [{"height": 3.0}, {"height": 2.0, "center": [1.0, 0.0]}]
    assert main(["ground", str(write_config(folder, cfg)), "-o", str(out / "l.exr")]) == 0
    single = base_config()
    main(["ground", str(write_config(folder, single, "s.yaml")), "-o", str(out / "s.exr")])
    assert io.read_image(out / "l.exr").mean() < io.read_image(out / "s.exr").mean()


@pytest.mark.parametrize("key,value,message", [
    ("colour", 3, "colour: unknown key"),  # the parser
    ("ground.pixel", 1e-5, "ground.pixel: the window would be"),  # the plan's limits
    ("canopy.mask", "nope.png", "canopy.mask: no such file"),  # a file
])
def test_a_bad_config_exits_2_names_the_key_and_writes_nothing(inputs, capsys, key, value, message):
    """Every command refuses it in one line before writing anything (the parser's and the
    plan's checks themselves: tests/test_config.py)."""
    folder, out = inputs
    assert_refused(write_config(folder, set_key(base_config(), key, value)), out, capsys, message)


def test_a_config_error_names_the_yaml_line_through_the_command(inputs, capsys):
    folder, out = inputs
    text = "ground:\n  window: [-4, -4, 4, 4]\n  pixel: 0.1\ncanopy:\n  mask: mask.png\n  height: -2\n"
    config = write_config(folder, text)
    assert main(["ground", str(config), "-o", str(out / "g.exr")]) == 2
    assert f"{config}:6: canopy.height" in capsys.readouterr().err


BAD_FILES = [
    ("corrupt mask", "canopy", {"mask": "corrupt.png"}, "corrupt.png"),
    ("mask out of range", "canopy", {"mask": "bright.exr"}, "mask values must lie in [0, 1]"),
    ("NaN in hdri", "sky", {"model": "hdri", "hdri": "nan.exr"}, "the sky image holds nan at row"),
    ("hdri not an image", "sky", {"model": "hdri", "hdri": "config.txt"}, "config.txt"),
    ("periodic tile not whole pixels", "canopy", {"layout": "periodic", "size": [4.05, 4.0]},
     "whole number of ground pixels"),
    ("duplicate key", None, "ground:\n  pixel: 0.1\n  pixel: 0.2\n", "duplicate key"),
    ("not a mapping", None, "- 1\n- 2\n", "must be a mapping"),
    ("invalid yaml", None, "canopy: [1, 2\n", "not valid YAML"),
    ("empty layers", "canopy", {"layers": []}, "canopy.layers: must be a non-empty list"),
]


@pytest.mark.parametrize("name,section,change,message", BAD_FILES, ids=[b[0] for b in BAD_FILES])
def test_bad_input_file_exits_2_and_writes_nothing(inputs, capsys, name, section, change, message):
    folder, out = inputs
    (folder / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 20)
    io.write_exr(folder / "bright.exr", np.full((8, 8, 1), 2.0, np.float32))
    nan = np.ones((16, 32, 3), np.float32)
    nan[3, 4, 1] = np.nan
    io.write_exr(folder / "nan.exr", nan)
    (folder / "config.txt").write_text("not an image")
    if section is None:
        config = write_config(folder, change)
    else:
        cfg = base_config()
        if section == "sky":
            cfg["sky"] = {"alpha": 80.0}
        cfg[section].update(change)
        config = write_config(folder, cfg)
    assert_refused(config, out, capsys, message)


BAD_RUNS = [
    ("frames out of range", {}, ["--frames", "0-3,120"], "--frames: 120 is outside 0..47"),
    ("frames backwards", {}, ["--frames", "5-2"], "--frames: the range 5-2 runs backwards"),
    ("frames not numbers", {}, ["--frames", "a-b"], "--frames: 'a-b' is not a frame"),
    ("no jobs", {}, ["--jobs", "0"], "--jobs must be at least 1"),
    ("output folder is a file", {}, ["--output", "{folder}/config.yaml/run"], "is a file, not a folder"),
    ("misspelt video", {"output": {"video": "mp5"}}, [], "output.video: unknown value 'mp5'; valid: mp4, gif, none"),
    ("output name with a slash", {"output": {"name": "a/b"}}, [], "output.name: must be a name"),
    ("half as text", {"output": {"half": "yes"}}, [], "output.half: must be true or false"),
    ("unknown render key", {"render": {"job": 2}}, [], "render.job: unknown key"),
    ("no render jobs", {"render": {"jobs": 0}}, [], "render.jobs: must be at least 1"),
    ("sun cells", {"render": {"sun_cells": 1}}, [], "render.sun_cells: must be at least 2"),
    ("frames of zero", {"animation": {"frames": 0}}, [], "animation.frames: must be at least 1"),
]


@pytest.mark.parametrize("name,change,args,message", BAD_RUNS, ids=[b[0] for b in BAD_RUNS])
def test_bad_render_exits_2_and_writes_nothing(inputs, capsys, name, change, args, message):
    folder, out = inputs
    config = write_config(folder, {**base_config(), **change})
    args = [a.format(folder=folder) for a in args]
    commands = ("render",) if args else ("check", "render")
    assert_refused(config, out, capsys, message, commands=commands, extra=args)


def test_unwritable_output_folder_writes_nothing(inputs, capsys):
    folder, out = inputs
    if os.geteuid() == 0:
        pytest.skip("root writes anywhere")
    locked = folder / "locked"
    locked.mkdir(mode=0o500)
    config = write_config(folder, base_config())
    assert main(["render", str(config), "--output", str(locked / "run"), "--cache", str(out / "cache")]) == 2
    assert "cannot write the output folder" in capsys.readouterr().err
    assert list(out.iterdir()) == [] and list(locked.iterdir()) == []


def test_bad_output_paths(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, base_config())
    assert main(["ground", str(config), "-o", str(folder / "missing" / "g.exr")]) == 2
    assert "no such folder" in capsys.readouterr().err
    for command in ("ground", "frame", "sky"):  # one message naming every suffix they take
        extra = ["--frame", "0"] if command != "ground" else []
        assert main([command, str(config), *extra, "-o", str(out / "g.jpg")]) == 2
        assert "must be a .png or .exr file" in capsys.readouterr().err
    assert main(["ground", str(folder / "absent.yaml"), "-o", str(out / "g.exr")]) == 2
    assert "cannot read the config" in capsys.readouterr().err
    if os.geteuid() != 0:  # root writes anywhere
        locked = folder / "locked"
        locked.mkdir(mode=0o500)
        assert main(["ground", str(config), "-o", str(locked / "g.exr")]) == 2
    assert list(out.iterdir()) == []


def test_console_script_runs_as_a_real_process(inputs):
    folder, out = inputs
    config = write_config(folder, base_config())
    done = subprocess.run([sys.executable, "-m", "pipeline.cli", "ground", str(config), "-o",
                           str(out / "g.exr")], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    bad = write_config(folder, set_key(base_config(), "canopy.height", -1), "bad.yaml")
    done = subprocess.run([sys.executable, "-m", "pipeline.cli", "ground", str(bad), "-o",
                           str(out / "h.exr")], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and "canopy.height" in done.stderr
    assert not (out / "h.exr").exists()


def test_cache_command_lists_verifies_and_prunes(tmp_path, capsys):
    store = Cache(tmp_path / "c")
    for seed in range(3):
        store.get_or_compute("spectrum", {"seed": seed}, lambda: {"a": np.zeros(4096, np.float32)})
    assert main(["cache", "list", "--cache", str(tmp_path / "c")]) == 0
    assert "3 items" in capsys.readouterr().out
    item = store.list()[0]
    npy = next(item.path.glob("*.npy"))
    npy.write_bytes(npy.read_bytes()[:-100])  # truncate one item
    assert main(["cache", "verify", "--cache", str(tmp_path / "c")]) == 1
    out = capsys.readouterr().out
    assert "1 broken of 3 items" in out and item.key[:16] in out
    assert main(["cache", "prune", "--max-size", "20K", "--cache", str(tmp_path / "c")]) == 0
    assert len(store.list()) == 1
    assert main(["cache", "prune", "--max-size", "2X", "--cache", str(tmp_path / "c")]) == 2
    assert "--max-size" in capsys.readouterr().err
    assert main(["cache", "clear", "--cache", str(tmp_path / "c")]) == 0
    assert store.list() == []


def test_output_that_is_a_folder_writes_nothing(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, base_config())
    (out / "g.png").mkdir()
    assert main(["ground", str(config), "-o", str(out / "g.exr"), "--png"]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["g.png"]


def test_mask_alpha_is_ignored_not_premultiplied(inputs):
    folder, out = inputs

    rgba = np.zeros((40, 40, 4), np.uint8)
    rgba[..., :3] = 255  # open sky everywhere, alpha 0: a painter's transparent layer
    spec = oiio.ImageSpec(40, 40, 4, "uint8")
    spec.attribute("oiio:UnassociatedAlpha", 1)
    image = oiio.ImageOutput.create(str(folder / "rgba.png"))
    image.open(str(folder / "rgba.png"), spec)
    image.write_image(rgba)
    image.close()
    cfg = base_config()
    cfg["canopy"]["mask"] = "rgba.png"
    assert main(["ground", str(write_config(folder, cfg)), "-o", str(out / "g.exr")]) == 0
    assert np.allclose(io.read_image(out / "g.exr"), np.pi, rtol=1e-4)


def test_layers_with_a_dark_channel_stay_finite(inputs):
    folder, out = inputs
    cfg = base_config()
    cfg["sky"]["radiance"] = [1.0, 0.0, 0.0]
    cfg["canopy"]["layers"] = [{"height": 3.0}, {"height": 2.0}]
    assert main(["ground", str(write_config(folder, cfg)), "-o", str(out / "g.exr")]) == 0
    g = io.read_image(out / "g.exr")
    assert np.all(np.isfinite(g)) and np.all(g[..., 1:] == 0) and g[..., 0].max() > 3.0


def grove_config():
    return {
        "canopy": {"height": 4.0, "trees": {"count": 1, "seed": 3, "crown_radius": 1.5,
                                             "leaves_per_tree": 300, "leaf_length": 0.15},
                   "flutter": {"cycle": 4}},
        "sky": {"model": "procedural", "sun": {"elevation": 50.0, "azimuth": 90.0}, "alpha": 70.0},
        "ground": {"window": [-3, -3, 3, 3], "pixel": 0.1, "sun_window": [-1, -1, 1, 1],
                   "sun_pixel": 0.05},
        "animation": {"frames": 4},
    }


def test_mask_writes_the_cycle_frame_mask(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, grove_config())
    assert main(["mask", str(config), "--frame", "1", "-o", str(out / "m.png")]) == 0
    assert "mean transmittance" in capsys.readouterr().out
    m = io.read_image(out / "m.png")
    assert m.ndim == 3 and 0.05 < m.mean() < 0.999 and m.max() == 1.0
    assert main(["mask", str(config), "--frame", "1", "--fine", "-o", str(out / "f.exr")]) == 0
    fine = io.read_image(out / "f.exr")
    attrs = io.read_attributes(out / "f.exr", ["sunshade:pixel_size"])
    assert attrs["sunshade:pixel_size"] == pytest.approx(0.05)
    assert fine.shape[0] > 40  # the 2 m sun window at 0.05 m, grown by the sun's offsets


def test_mask_frame_outside_the_cycle_is_refused(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, grove_config())
    assert main(["mask", str(config), "--frame", "4", "-o", str(out / "m.png")]) == 2
    assert "--frame 4 is outside 0..3" in capsys.readouterr().err
    assert list(out.iterdir()) == []


def test_sky_writes_an_equirect_with_the_sun_in_the_east(inputs):
    folder, out = inputs
    config = write_config(folder, grove_config())
    assert main(["sky", str(config), "--width", "256", "-o", str(out / "s.exr"), "--png"]) == 0
    sky = io.read_image(out / "s.exr")
    assert sky.shape == (128, 256, 3)
    row, col = np.unravel_index(np.argmax(sky[..., 1]), sky.shape[:2])
    assert abs(col - 0.75 * 256) <= 2  # azimuth 90 degrees: three quarters of the width
    assert abs(row - (90 - 50) / 180 * 128) <= 2  # elevation 50 degrees
    assert sky[64:].max() == 0  # nothing below the horizon
    assert (out / "s.png").is_file()


def test_ground_frame_outside_the_animation_is_refused(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, grove_config())
    assert main(["ground", str(config), "--frame", "9", "-o", str(out / "g.exr")]) == 2
    assert "--frame 9 is outside 0..3 (animation.frames is 4)" in capsys.readouterr().err
    assert list(out.iterdir()) == []


def small_camera(config):
    config["camera"] = {"position": [0.0, -6.0, 1.7], "look_at": [0.0, 0.0, 1.0], "resolution": [64, 36]}
    return config


def test_frame_writes_a_png_and_a_scene_linear_exr_with_metadata(inputs, capsys):
    folder, out = inputs
    config = small_camera(base_config())
    config["sky"] = {"model": "procedural", "sun": {"elevation": 40.0, "azimuth": 120.0}}
    config["render"] = {"sun_cells": 6}  # a preview's: the sun's shadow over the window in a fifth of the time
    path = write_config(folder, config)
    assert main(["frame", str(path), "--frame", "0", "-o", str(out / "f.png")]) == 0
    assert main(["frame", str(path), "--frame", "0", "-o", str(out / "f.exr")]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["f.exr", "f.png"]
    png, exr = io.read_image(out / "f.png"), io.read_image(out / "f.exr")
    assert png.shape == (36, 64, 3) and exr.shape == (36, 64, 3)
    assert 0.05 < png.mean() < 0.95
    names = ["sunshade:config_hash", "sunshade:frame", "sunshade:sun_fraction", "sunshade:sun_azimuth_elevation"]
    attributes = io.read_attributes(out / "f.exr", names)
    assert attributes["sunshade:frame"] == 0 and attributes["sunshade:sun_fraction"] == pytest.approx(1.0)
    assert tuple(attributes["sunshade:sun_azimuth_elevation"]) == pytest.approx((120.0, 40.0))
    assert len(attributes["sunshade:config_hash"]) == 16
    assert "S = 1.0000" in capsys.readouterr().out


def test_frame_with_imported_passes_of_the_wrong_size_names_the_file(inputs, capsys):
    folder, out = inputs
    for name in ("sun", "sky", "alpha"):
        io.write_exr(folder / f"fg_{name}.exr", np.ones((10, 10, 3), np.float32))
    config = small_camera(base_config())
    config["foreground"] = {"model": "passes", "sun": "fg_sun.exr", "sky": "fg_sky.exr", "alpha": "fg_alpha.exr"}
    assert main(["frame", str(write_config(folder, config)), "-o", str(out / "f.png")]) == 2
    err = capsys.readouterr().err
    assert "fg_sun.exr" in err and "10 x 10" in err and "64 x 36" in err
    assert list(out.iterdir()) == []


def test_frame_with_imported_passes_composites_them(inputs):
    """Alpha 1 and S = 0 under a uniform sky (no sun): the frame is the sky pass."""
    folder, out = inputs
    sky_pass = np.random.default_rng(2).random((36, 64, 3)).astype(np.float32)
    io.write_exr(folder / "fg_sun.exr", 5 * sky_pass)
    io.write_exr(folder / "fg_sky.exr", sky_pass)
    io.write_exr(folder / "fg_alpha.exr", np.ones((36, 64, 1), np.float32))
    config = small_camera(base_config())
    config["foreground"] = {"model": "passes", "sun": "fg_sun.exr", "sky": "fg_sky.exr", "alpha": "fg_alpha.exr"}
    assert main(["frame", str(write_config(folder, config)), "-o", str(out / "f.exr")]) == 0
    np.testing.assert_allclose(io.read_image(out / "f.exr"), sky_pass, rtol=1e-6)


class _Stream(__import__("io").StringIO):
    def __init__(self, tty):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


def test_progress_is_a_bar_on_a_terminal_and_log_lines_elsewhere():
    terminal, log = _Stream(True), _Stream(False)
    for stream in (terminal, log):
        progress = _Progress(stream)
        for done in range(0, 5):
            progress("frames", done, 4)
    bar = terminal.getvalue()
    assert bar.count("\r") == 5 and "frames" in bar and "[" + "#" * 24 + "] 4/4" in bar
    assert "left" in bar and bar.endswith("\n")
    lines = log.getvalue().splitlines()
    assert lines[0] == "sunshade: frames 0/4" and lines[-1] == "sunshade: frames 4/4"
    assert "\r" not in log.getvalue() and len(lines) == 2  # at most one line per 10 s between


def test_a_config_named_with_dots_or_spaces_gets_a_valid_output_name(inputs, capsys):
    folder, out = inputs
    for name, expected in (("my.scene.yaml", "my_scene"), ("my eclipse.yaml", "my_eclipse")):
        path = write_config(folder, base_config(), name)
        assert main(["check", str(path)]) == 0, capsys.readouterr().err
        assert main(["ground", str(path), "-o", str(out / f"{expected}.exr")]) == 0
    # a name no frame file can carry: refused by check and render, ignored by the commands that
    # write no named frames
    config = base_config()
    config["output"] = {"name": "my.scene"}
    path = write_config(folder, config, "named.yaml")
    assert main(["check", str(path)]) == 2
    assert "output.name: must be a name" in capsys.readouterr().err
    assert main(["ground", str(path), "-o", str(out / "named.exr")]) == 0
    assert main(["mask", str(path), "-o", str(out / "named-mask.png")]) == 0


def test_sky_and_ground_write_a_png_alone(inputs):
    folder, out = inputs
    config = write_config(folder, base_config())
    assert main(["ground", str(config), "-o", str(out / "g.png")]) == 0
    procedural = base_config()
    procedural["sky"] = {"model": "procedural", "sun": {"elevation": 40.0, "azimuth": 90.0}}
    assert main(["sky", str(write_config(folder, procedural, "p.yaml")), "--width", "64",
                 "-o", str(out / "s.png")]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["g.png", "s.png"]
    assert io.read_image(out / "s.png").shape == (32, 64, 3)


def test_cache_list_groups_items_by_config_and_takes_one(tmp_path, capsys):
    """Two configs rendered into one cache: the listing names each with its items, size and
    cycle frames; with a config, only its items; prune with a config removes only its."""
    cache = tmp_path / "cache"
    configs = []
    for name, seed in (("first", 3), ("second", 4)):
        config = {**TINY, "canopy": {**TINY["canopy"], "trees": {**TINY["canopy"]["trees"], "seed": seed}},
                  "animation": {"frames": 2, "fps": 12}, "output": {"video": "none"}}
        configs.append(write_config(tmp_path, config, f"{name}.yaml"))
        assert main(["render", str(configs[-1]), "--jobs", "1", "--output", str(tmp_path / name),
                     "--cache", str(cache)]) == 0
    capsys.readouterr()
    assert main(["cache", "list", "--cache", str(cache)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines[:2]] == ["first", "second"]
    assert all("cycle frames 2 of 3" in line and "items (" in line for line in lines[:2])
    assert lines[-1].startswith("8 items")  # 2 cycle frames x (spectra, foreground) x 2 configs
    assert main(["cache", "list", str(configs[0]), "--cache", str(cache)]) == 0
    assert "4 of 6 items" in capsys.readouterr().out
    assert main(["cache", "prune", str(configs[0]), "--cache", str(cache)]) == 0
    assert "removed 4 items" in capsys.readouterr().out
    assert main(["cache", "list", "--cache", str(cache)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[0] == "second" and lines[-1].startswith("4 items")


def test_cache_list_into_a_closed_pipe_and_a_missing_cache_folder(tmp_path):
    store = Cache(tmp_path / "c")
    for seed in range(400):
        store.get_or_compute("spectrum", {"seed": seed}, lambda: {"a": np.zeros(4, np.float32)})
    done = subprocess.run(f"{sys.executable} -m pipeline.cli cache list --cache {tmp_path / 'c'} | head -2",
                          shell=True, capture_output=True, text=True, cwd=ROOT)
    assert done.stdout.count("\n") == 2 and "Traceback" not in done.stderr, done.stderr
    done = subprocess.run([sys.executable, "-m", "pipeline.cli", "cache", "list", "--cache",
                           str(tmp_path / "absent")], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and "no such cache folder" in done.stderr
    assert not (tmp_path / "absent").exists()


def test_check_tells_the_eclipse_at_the_site_and_a_span_that_misses_it():
    from dataclasses import replace as swap

    from pipeline.cli.runs import _eclipse_lines
    from pipeline.stages.resolve import load

    config = load(Path(__file__).resolve().parents[1] / "configs" / "eclipse-2024-dallas-totality.yaml")
    lines = _eclipse_lines(config)
    assert "total" in lines[0] and "C2 18:40:41.7" in lines[0] and "totality 3 min 55.2 s" in lines[0]
    assert lines[1].endswith("holds C2, C3")
    site = config.sky.site
    late = swap(config, sky=swap(config.sky, site=swap(site, start=site.start + timedelta(hours=2),
                                                          end=site.end + timedelta(hours=2))))
    assert "misses it altogether" in _eclipse_lines(late)[1]


def test_time_left_leaves_out_the_slow_first_item(monkeypatch):
    """The first item of a stage carries the workers' start (and after an install the loops'
    compiling): 20 s for it, then one a second, 8 to go, is 8 s left, not 80."""
    import pipeline.cli.runs as cli_runs

    clock = iter([0.0, 20.0, 21.0])
    monkeypatch.setattr(cli_runs.time, "monotonic", lambda: next(clock))
    stream = _Stream(True)
    progress = _Progress(stream)
    for done in (0, 1, 2):
        progress("cycle", done, 10)
    lines = stream.getvalue().split("\r")
    assert "left" not in lines[2] and lines[3].rstrip("\x1b[K").endswith("2/10, 0:08 left"), lines


def test_log_lines_mark_each_quarter_of_a_short_stage(monkeypatch):
    """Off a terminal a 10 s preview of 120 frames (one every 1/12 s) says each quarter, not only
    its start and end; a quarter passed within QUARTER_GAP of the last line waits for the next."""
    import pipeline.cli.runs as cli_runs

    now = [0.0]
    monkeypatch.setattr(cli_runs.time, "monotonic", lambda: now[0])
    stream = _Stream(False)
    progress = _Progress(stream)
    for done in range(121):
        now[0] = done / 12.0
        progress("frames", done, 120)
    counts = re.findall(r"(\d+/\d+)", stream.getvalue())
    assert counts == ["0/120", "30/120", "60/120", "90/120", "120/120"], counts
    stream = _Stream(False)
    progress = _Progress(stream)
    for done in range(9):  # a quarter every second: lines 2 s apart at least
        now[0] = float(done)
        progress("cycle", done, 8)
    counts = re.findall(r"(\d+/\d+)", stream.getvalue())
    assert counts == ["0/8", "2/8", "4/8", "6/8", "8/8"], counts


@pytest.mark.parametrize("tty", [True, False])
def test_a_stages_end_is_said_once(tty):
    """The video's encoder says 240/240 while it finishes the file and again once it has: one line."""
    stream = _Stream(tty)
    progress = _Progress(stream)
    for done in (0, 120, 240, 240):
        progress("video", done, 240)
    assert stream.getvalue().count("240/240") == 1, stream.getvalue()


def test_check_shows_a_window_laid_on_whole_pixels_beside_the_configs(tmp_path, capsys):
    """A window that is no whole number of pixels is laid on whole ones: ``check`` prints the
    window used and, beside it, the config's; a window of whole pixels is printed alone."""
    config = write_config(tmp_path, {**TINY, "ground": {**TINY["ground"], "window": [-4, -4, 4, 4.03]}})
    assert main(["check", str(config)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "ground.window:" in x)
    assert line.endswith("(the config's [-4.00, -4.00, 4.00, 4.03] on whole pixels)"), line
    assert main(["check", str(write_config(tmp_path, TINY, "whole.yaml"))]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "ground.window:" in x)
    assert line.endswith("[-4.00, -4.00, 4.00, 4.00] m at 0.05 m"), line


@pytest.mark.parametrize("text", ["", "# only a comment\n\n"])
def test_an_empty_config_exits_2_in_one_line_and_writes_nothing(tmp_path, capsys, monkeypatch, text):
    """``: > empty.yaml; sunshade render empty.yaml`` once rendered the whole default animation
    (205 MB of frames, 446 MB of cache); now every command refuses it naming the file, and a
    render with no flags makes neither ./renders nor ./cache."""
    folder = tmp_path / "work"
    out = tmp_path / "out"
    folder.mkdir()
    out.mkdir()
    config = write_config(folder, text, "empty.yaml")
    message = "empty.yaml: the config is empty; start from one of configs/*.yaml (an explicit {} renders every default)"
    assert_refused(config, out, capsys, message)
    monkeypatch.chdir(folder)
    monkeypatch.delenv("SUNSHADE_CACHE", raising=False)
    assert main(["render", "empty.yaml"]) == 2
    assert capsys.readouterr().err.strip() == f"sunshade: error: {message}"
    assert sorted(p.name for p in folder.iterdir()) == ["empty.yaml"]


def test_cache_help_says_what_each_action_does_and_a_missing_action_is_named(tmp_path, capsys, monkeypatch):
    """``sunshade cache --help`` gives each action a line, ``cache ACTION --help`` shows the arguments
    that action takes, and a bare ``sunshade cache`` names the actions (it said "required: action", a
    word not in its usage line)."""
    monkeypatch.setenv("COLUMNS", "200")  # argparse's width: a line per action
    with pytest.raises(SystemExit) as done:
        main(["cache", "--help"])
    out = capsys.readouterr().out
    assert done.value.code == 0
    lines = {line.split()[0]: line for line in out.splitlines() if re.match(r"    \S", line)}
    assert list(lines) == ["list", "verify", "clear", "prune"], out
    assert "remove every item" in lines["clear"] and "--max-size" in lines["prune"], out
    helps = {}
    for action in ("list", "verify", "clear", "prune"):
        with pytest.raises(SystemExit):
            main(["cache", action, "--help"])
        helps[action] = capsys.readouterr().out
        assert helps[action].startswith(f"usage: sunshade cache {action} "), helps[action]
    assert "--max-size" in helps["prune"] and "CONFIG" in helps["prune"] and "--remove" not in helps["prune"]
    assert "--remove" in helps["verify"] and "--max-size" not in helps["verify"] and "CONFIG" not in helps["verify"]
    assert "CONFIG" in helps["list"] and "--max-size" not in helps["clear"] and "CONFIG" not in helps["clear"]
    assert main(["cache"]) == 2
    assert capsys.readouterr().err == ("sunshade: error: sunshade cache needs an action: list, verify, clear or "
                                       "prune (see sunshade cache --help)\n")
    (tmp_path / "c").mkdir()
    for argv in (["cache", "--cache", str(tmp_path / "c"), "list"], ["cache", "list", "--cache", str(tmp_path / "c")]):
        assert main(argv) == 0  # --cache before the action or after it
        assert capsys.readouterr().out == f"0 items, 0 B in {tmp_path / 'c'}\n"
    assert main(["cache", "verify", "x.yaml", "--cache", str(tmp_path / "c")]) == 2
    assert capsys.readouterr().err == "sunshade: error: cache verify takes no CONFIG (list and prune do)\n"


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="finds the command's child processes in /proc")
def test_sigterm_ends_a_render_as_cleanly_as_ctrl_c(tmp_path):
    """``kill PID`` (SIGTERM) to a render while its two workers render and its video is encoded: one
    line and exit code 143, as Ctrl-C's ``sunshade: interrupted`` and 130; the workers and the encoder
    (ffmpeg) have ended when the command ends, its temporary video is gone, and the frames done are
    kept. Before, the command died where it stood (exit code -15, no word, loky's warnings), its
    workers and encoder outlived it, and the encoder's hidden ``.tmp-`` video stayed."""
    from test_failures import children, state

    config = write_config(tmp_path, {**TINY, "animation": {"frames": 40, "fps": 12}}, "tiny.yaml")
    run = tmp_path / "run"
    args = ["render", str(config), "--jobs", "2", "--output", str(run), "--cache", str(tmp_path / "cache")]
    process = subprocess.Popen([sys.executable, "-m", "pipeline.cli", *args], cwd=ROOT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(run.glob(".tiny.tmp-*.mp4")) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)  # the first frame is in the encoder
    started = {}
    for pid in children(process.pid):
        with contextlib.suppress(OSError), open(f"/proc/{pid}/cmdline") as cmdline:
            started[pid] = cmdline.read()

    def alive(pids):
        return [started[pid] for pid in pids if (state(pid) or ("Z",))[0] != "Z"]

    process.send_signal(signal.SIGTERM)
    process.wait(timeout=60)  # not communicate(): a worker left alive would hold the pipes open
    at_exit = alive([pid for pid, line in started.items() if "popen_loky" in line or "ffmpeg" in line])
    err = process.stderr.read()
    process.stdout.close()
    process.stderr.close()
    assert len([line for line in started.values() if "popen_loky" in line]) == 2, started
    assert process.returncode == 143, err
    assert [line for line in err.splitlines() if not re.match(r"sunshade: (cycle products|frames) \d+/\d+", line)] == [
        "sunshade: terminated"], err
    assert at_exit == []
    deadline = time.monotonic() + 5.0  # joblib's resource tracker ends once the command is gone
    while alive(started) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert alive(started) == []
    assert not list(run.glob(".*tmp-*"))
    time.sleep(0.5)
    assert not list(run.glob(".*tmp-*")) and not (run / "tiny.mp4").exists()
    assert (run / "tiny.0000.png").is_file()  # the frames done are kept (a resume renders the others)
