"""The light passes as EXR layers, their attributes, the frames' light in the run's records and
the report (docs/runs.md, "Light passes", "The report")."""

import csv
import json
import shutil

import numpy as np
import pytest
import yaml
from scenes import assert_refused, config_of, plan_of, tiny_grove, write_config

from pipeline.cache import store as cache
from pipeline.camera import pinhole as camera
from pipeline.cli.main import main
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.frame import render_frame

ALL = ("sun", "sky", "alpha", "illuminance", "depth")


def grove(**changes):
    """A tiny grove with its trees in front, seen from 8.5 m away, at a site and time."""
    config = tiny_grove(**changes)
    config["foreground"] = {"model": "trees"}
    config["camera"] = {"position": [6.0, -6.0, 1.7], "look_at": [0.0, 0.0, 2.0], "resolution": [64, 40]}
    return config


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A frame of the grove with every pass, under a hazy sky with clouds (the veil and the
    sky scale k are in play): (plan, FrameResult)."""
    folder = tmp_path_factory.mktemp("passes")
    config = grove(**{"sky.haze": 40.0})
    config["sky"]["clouds"] = {"cover": 0.5, "scale": 20.0, "altitude": 300.0, "wind": [5.0, 0.0]}
    plan = plan_of(config, folder)
    return plan, render_frame(plan, 2, store=cache.Cache(folder / "cache"), workers=1, passes=ALL)


def test_the_sun_and_sky_layers_sum_to_the_beauty(rendered):
    """sun + sky, each composited by S from its own part of the ground, is the beauty to float
    rounding; both carry light (neither is the whole)."""
    _, result = rendered
    beauty, sun, sky = result.radiance, result.layers["sun"], result.layers["sky"]
    assert 0.0 < result.sun_fraction < 1.0  # a cloud on the sun: S blends
    assert np.abs(sun + sky - beauty).max() <= 2e-6 * beauty.max()
    for part in (sun, sky):
        assert part.min() >= -1e-6 * beauty.max() and 0.05 < part.sum() / beauty.sum() < 0.95


def test_the_alpha_and_depth_layers_are_the_foreground_and_the_camera_s(rendered):
    plan, result = rendered
    alpha, depth = result.layers["alpha"][..., 0], result.layers["depth"][..., 0]
    assert 0.0 <= alpha.min() and alpha.max() <= 1.0 and alpha.max() > 0.5
    np.testing.assert_array_equal(depth, camera.ground_distance(plan.camera))
    # where the trees cover the pixel wholly, the sky layer holds only their sky pass
    assert np.all(result.layers["sky"][alpha == 1.0] >= 0)


def test_the_lux_layer_on_open_ground_is_the_sky_model_s_illuminance(tmp_path):
    """Far beyond the grove's shadow, the illuminance layer is 1000 x the luminance of the sky
    model's own horizontal irradiance (sky and sun, by its quadrature) within 0.5 %; under a
    uniform sky of radiance L it is 1000 pi L."""
    config = grove()
    plan = plan_of(config, tmp_path)
    result = render_frame(plan, 0, store=cache.Cache(tmp_path / "cache"), workers=1, passes=("illuminance", "depth"))
    lux, depth = result.layers["illuminance"][..., 0], result.layers["depth"][..., 0]
    far = np.isfinite(depth) & (depth > 25.0)  # beyond the 6 m window, well clear of the shadow
    assert far.sum() > 20
    sky = plan.sky.at(plan.scenes[0])
    expected = 1000.0 * float((sky.sky_irradiance + sun_irradiance(sky)) @ REC709_LUMINANCE)
    assert np.abs(lux[far] / expected - 1.0).max() < 0.005
    assert np.all(lux[~np.isfinite(depth)] == 0)

    uniform = grove()
    uniform["sky"] = {"model": "uniform", "radiance": 2.0, "alpha": 70.0}
    plan = plan_of(uniform, tmp_path)
    result = render_frame(plan, 0, store=cache.Cache(tmp_path / "cache"), workers=1, passes=("illuminance",))
    lux = result.layers["illuminance"][..., 0][far]
    np.testing.assert_allclose(lux, 1000.0 * np.pi * 2.0, rtol=0.005)


def test_without_passes_the_hash_and_the_frame_are_as_before(tmp_path):
    """An unset or empty output.passes hashes as a config that never had the key (and so
    resumes the frames it made); any pass hashes differently (its frames are made again)."""
    plain = config_of(grove(), tmp_path)
    assert config_of({**grove(), "output": {"passes": []}}, tmp_path).digest() == plain.digest()
    assert config_of({**grove(), "output": {"passes": ["depth"]}}, tmp_path).digest() != plain.digest()
    assert config_of({**grove(), "output": {"report": False}}, tmp_path).digest() == plain.digest()
    # the order a config names them in does not matter
    a = config_of({**grove(), "output": {"passes": ["sky", "sun"]}}, tmp_path)
    assert a.output.passes == ("sun", "sky") and a.digest() == config_of(
        {**grove(), "output": {"passes": ["sun", "sky"]}}, tmp_path).digest()


@pytest.mark.parametrize("value, message", [(["sun", "moon"], "unknown pass 'moon'"),
                                            (3, "must be a list of pass names"),
                                            (["sun", "sun"], "more than once")])
def test_a_bad_pass_name_is_refused_naming_the_key(inputs, capsys, value, message):
    folder, out = inputs
    config = write_config(folder, {**grove(), "output": {"passes": value}})
    assert_refused(config, out, capsys, message, commands=("check", "render"))
    assert main(["check", str(config)]) == 2
    assert "output.passes" in capsys.readouterr().err


def test_a_run_with_passes_writes_layers_attributes_light_and_report(tmp_path, capsys):
    """A render's EXRs hold the layers under their conventional names, read alike by
    OpenImageIO and by the OpenEXR bindings, with the standard attributes; run.json, light.csv
    and the pictures hold each frame's light; `sunshade report` remakes them for a killed run."""
    config = grove()
    config["sky"].pop("sun")
    config["sky"]["site"] = {"latitude": 32.78, "longitude": -96.8, "elevation": 130.0}
    config["sky"]["time"] = {"start": "2024-04-08T18:39:00Z", "end": "2024-04-08T18:42:00Z"}
    config["animation"] = {"frames": 4}
    config["output"] = {"folder": str(tmp_path / "run"), "passes": list(ALL), "video": "none"}
    path = write_config(tmp_path, config)
    assert main(["render", str(path), "--jobs", "1", "--cache", str(tmp_path / "cache")]) == 0
    run = tmp_path / "run"
    exr = run / "config.0001.exr"
    layers = io.read_layers(exr)
    assert set(layers) == {"R", "G", "B", "sun.R", "sun.G", "sun.B", "sky.R", "sky.G", "sky.B", "alpha.A",
                           "illuminance.Y", "depth.Z"}
    attributes = io.read_attributes(exr, ["chromaticities", "latitude", "longitude", "altitude", "DateTime",
                                          "utcOffset", "sunshade:ev100", "sunshade:sun_lux"])
    np.testing.assert_allclose(attributes["chromaticities"], (0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 0.329),
                               rtol=1e-6)
    assert attributes["latitude"] == pytest.approx(32.78, abs=1e-4) and attributes["altitude"] == 130.0
    assert attributes["DateTime"] == "2024:04:08 18:40:00"  # the config's time, frame 1 of 4
    for name in ("R", "G", "B"):  # half floats: the sum to half's rounding
        summed = layers[f"sun.{name}"] + layers[f"sky.{name}"]
        assert np.abs(summed - layers[name]).max() <= 2e-3 * layers[name].max()

    openexr = pytest.importorskip("OpenEXR")  # a second reader: the same names, the same pixels
    with openexr.File(str(exr), separate_channels=True) as second:
        channels = second.channels()
        assert set(channels) == set(layers)
        np.testing.assert_array_equal(channels["illuminance.Y"].pixels, layers["illuminance.Y"])
        header = second.header()
        assert header["capDate"] == "2024:04:08 18:40:00" and header["utcOffset"] == 0.0
        assert header["longitude"] == pytest.approx(-96.8, abs=1e-4)

    frames = json.loads((run / "run.json").read_text())["frames"]
    light = frames[1]["light"]
    assert light["sun_lux"] == pytest.approx(attributes["sunshade:sun_lux"], rel=1e-6)
    assert light["ev100"] == pytest.approx(np.log2((light["sun_lux"] + light["sky_lux"]) / 2.5))
    with open(run / "light.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [int(r["frame"]) for r in table] == [0, 1, 2, 3]
    assert float(table[1]["S"]) == pytest.approx(frames[1]["sun_fraction"])
    for picture in ("light-curve.png", "contact-sheet.png"):
        assert io.read_image(run / picture).shape[-1] in (3, 4)

    # killed after two frames: no run.json, index.json with the frames done so far
    killed = tmp_path / "killed"
    killed.mkdir()
    index = json.loads((run / "index.json").read_text())
    index["frames"] = {k: v for k, v in index["frames"].items() if k in ("0", "1")}
    (killed / "index.json").write_text(json.dumps(index))
    for f in ("config.0000.png", "config.0001.png"):
        shutil.copy(run / f, killed / f)
    capsys.readouterr()
    assert main(["report", str(killed)]) == 0
    with open(killed / "light.csv", newline="") as f:
        assert [int(r["frame"]) for r in csv.DictReader(f)] == [0, 1]
    assert (killed / "light-curve.png").is_file() and (killed / "contact-sheet.png").is_file()
    assert main(["report", str(tmp_path / "cache")]) == 2  # no run there: one line, exit 2
    assert "no run here" in capsys.readouterr().err


def test_frame_and_sky_commands_honour_the_passes(tmp_path, capsys):
    config = write_config(tmp_path, grove())
    out = tmp_path / "f.exr"
    assert main(["frame", str(config), "--frame", "1", "--passes", "sun,illuminance", "-o", str(out),
                 "--cache", str(tmp_path / "cache")]) == 0
    assert set(io.read_layers(out)) == {"R", "G", "B", "sun.R", "sun.G", "sun.B", "illuminance.Y"}
    assert main(["frame", str(config), "--passes", "shade", "-o", str(tmp_path / "g.exr")]) == 2
    assert "--passes: unknown pass 'shade'" in capsys.readouterr().err
    assert not (tmp_path / "g.exr").exists()

    sky = tmp_path / "sky.exr"
    assert main(["sky", str(config), "--width", "256", "--passes", "-o", str(sky)]) == 0
    layers = io.read_layers(sky)
    beauty = np.stack([layers[c] for c in "RGB"], axis=-1)
    parts = np.stack([layers[f"sun.{c}"] + layers[f"sky.{c}"] for c in "RGB"], axis=-1)
    assert np.abs(parts - beauty).max() <= 1e-6 * beauty.max()
    assert layers["sun.R"].max() > 100 * layers["sky.R"].max()  # the disc is in the sun layer


def test_output_report_must_be_true_or_false(inputs, capsys):
    folder, out = inputs
    config = write_config(folder, {**grove(), "output": {"report": "yes"}})
    assert_refused(config, out, capsys, "output.report", commands=("check", "render"))


def test_yaml_names_a_single_pass(tmp_path):
    config = config_of(yaml.safe_load("{}") | {**grove(), "output": {"passes": "depth"}}, tmp_path)
    assert config.output.passes == ("depth",)
