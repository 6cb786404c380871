"""The config parser and its validation: every bad value refused with one line naming the key
(and the YAML line where there is one), the plan's limits and sun checks (``resolve.resolve``),
the names a config may give."""

from pathlib import Path

import pytest
from scenes import base_config, set_key, write_config, write_inputs

from pipeline.config.parse import load_config, parse_config
from pipeline.config.vocabulary import CIE_TYPE_RANGE, SKY_MODELS
from pipeline.core.errors import ConfigError
from pipeline.sky import base as sky
from pipeline.sky import clearsky
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import resolve

ROOT = Path(__file__).resolve().parents[1]


def refusal(data, folder) -> str:
    """The one line a config mapping is refused with, by the parser or the plan."""
    with pytest.raises(ConfigError) as caught:
        resolve(parse_config(data, folder))
    text = str(caught.value)
    assert "\n" not in text
    return text


BAD_CONFIGS = [
    ("unknown top-level key", "colour", 3, "colour: unknown key"),
    ("unknown canopy key", "canopy.hieght", 3.0, "canopy.hieght: unknown key"),
    ("negative height", "canopy.height", -1.0, "canopy.height: must be above 0"),
    ("zero height", "canopy.height", 0, "canopy.height: must be above 0"),
    ("height as text", "canopy.height", "tall", "canopy.height: must be a number"),
    ("alpha of 90", "sky.alpha", 90.0, "sky.alpha: must be below 90"),
    ("alpha above 90", "sky.alpha", 120.0, "sky.alpha: must be below 90"),
    ("misspelt model", "sky.model", "unifrom",
     "sky.model: unknown value 'unifrom'; valid: cie, preetham, uniform, hdri"),
    ("missing mask", "canopy.mask", "nope.png", "canopy.mask: no such file"),
    ("empty window", "ground.window", [1, 1, 1, 5], "ground.window: must be"),
    ("short window", "ground.window", [0, 0, 1], "ground.window: must be a list of 4 numbers"),
    ("negative pixel", "ground.pixel", -0.1, "ground.pixel: must be above 0"),
    ("huge window", "ground.pixel", 1e-5, "ground.pixel: the window would be"),
    ("bad layout", "canopy.layout", "tiled", "canopy.layout: unknown value"),
    ("negative radiance", "sky.radiance", [1, -1, 1], "sky.radiance: must lie in [0, 1e+30]"),
    ("overflowing radiance", "sky.radiance", 1e38, "sky.radiance: must lie in [0, 1e+30]"),
    ("rotation with uniform", "sky.rotation", 10.0, "sky.rotation: only used with model: hdri"),
    ("huge canopy", "canopy.size", [2000, 2000], "canopy.size: the canopy would be"),
    ("hdri key with uniform", "sky.hdri", "sky.exr", "sky.hdri: only used with model: hdri"),
    ("size of zero", "canopy.size", [0, 4], "canopy.size: both sides must be above 0"),
    ("NaN height", "canopy.height", float("nan"), "canopy.height: must be a finite number"),
    ("camera underground", "camera", {"position": [0, 0, -1]}, "camera.position: the camera must be above"),
    ("look_at and pitch", "camera", {"look_at": [0, 5, 0], "pitch": -10}, "camera.look_at: give either"),
    ("look_at the camera", "camera", {"position": [0, 0, 2], "look_at": [0, 0, 2]}, "camera.look_at: must differ"),
    ("fov of 180", "camera", {"fov": 180}, "camera.fov: must be below 170"),
    ("fractional resolution", "camera", {"resolution": [640.5, 360]}, "camera.resolution: must be two whole"),
    ("misspelt display", "camera", {"display": "filmc"}, "camera.display: unknown value 'filmc'; valid: srgb, filmic"),
    ("unknown white balance", "camera", {"white_balance": "tungsten"},
     "camera.white_balance: unknown value 'tungsten'; valid: daylight, shade, none"),
    ("trees foreground with masks", "foreground", {"model": "trees"}, "foreground.model: 'trees' renders"),
    ("passes files missing", "foreground", {"model": "passes", "sun": "no.exr", "sky": "no.exr",
                                            "alpha": "no.exr"}, "foreground.sun: no such file"),
    ("pass key without passes", "foreground", {"sun": "sky.exr"}, "foreground.sun: only used with model: passes"),
    ("missing albedo image", "ground.albedo", "grass.png", "ground.albedo: no such file"),
    ("negative haze", "sky.haze", -5, "sky.haze: must be at least 0"),
    ("skylight with uniform", "sky.skylight", 0.5, "sky.skylight: only used with model: cie or preetham"),
]


@pytest.mark.parametrize("name,key,value,message", BAD_CONFIGS, ids=[b[0] for b in BAD_CONFIGS])
def test_a_bad_value_is_refused_naming_the_key(tmp_path, name, key, value, message):
    write_inputs(tmp_path)
    assert message in refusal(set_key(base_config(), key, value), tmp_path)


BAD_SKIES = [
    ("unknown cie_type", {"model": "cie", "cie_type": 16},
     "sky.cie_type: must be one of the CIE standard general skies 1..15"),
    ("cie_type zero", {"model": "cie", "cie_type": 0}, "sky.cie_type: must be at least 1"),
    ("cie_type with preetham", {"model": "preetham", "cie_type": 12}, "sky.cie_type: only used with model: cie"),
    ("auto without site", {"model": "cie", "turbidity": "auto"}, "sky.turbidity: auto needs sky.site and sky.time"),
    ("turbidity too low", {"model": "cie", "turbidity": 1.0}, "sky.turbidity: must be at least 1.5"),
    ("turbidity too high", {"model": "cie", "turbidity": 12.0}, "sky.turbidity: must be below 10"),
    ("turbidity as text", {"model": "cie", "turbidity": "hazy"}, "sky.turbidity: must be a number"),
]


@pytest.mark.parametrize("name,sky_keys,message", BAD_SKIES, ids=[b[0] for b in BAD_SKIES])
def test_a_bad_sky_is_refused_naming_the_key(tmp_path, name, sky_keys, message):
    write_inputs(tmp_path)
    config = {**base_config(), "sky": {**sky_keys, "alpha": 80.0}}
    assert message in refusal(config, tmp_path)


def test_an_error_names_the_yaml_line(tmp_path):
    write_inputs(tmp_path)
    text = "ground:\n  window: [-4, -4, 4, 4]\n  pixel: 0.1\ncanopy:\n  mask: mask.png\n  height: -2\n"
    path = write_config(tmp_path, text)
    with pytest.raises(ConfigError, match=f"{path}:6: canopy.height"):
        load_config(path)
    # and so do the plan's checks, from the lines the parser recorded
    text = "ground:\n  window: [-4, -4, 4, 4]\n  pixel: 0.00001\ncanopy:\n  mask: mask.png\n"
    with pytest.raises(ConfigError, match=f"{path}:3: ground.pixel: the window would be"):
        resolve(load_config(write_config(tmp_path, text)))


def test_layer_errors_name_the_layer_key(tmp_path):
    write_inputs(tmp_path)
    config = base_config()
    config["canopy"]["layers"] = [{"height": 3.0}, {"size": [0, 4]}]
    assert "canopy.layers[1].size: both sides must be above 0" in refusal(config, tmp_path)
    config = base_config()
    config["canopy"].update(layout="periodic", size=[1e-7, 1e-7])
    assert "whole number of ground pixels" in refusal(config, tmp_path)


@pytest.mark.parametrize("section,keys", [
    ("sky", {"model", "radiance", "hdri", "rotation", "alpha", "turbidity", "cie_type", "sun", "site",
             "time", "moon", "clouds", "skylight", "haze", "luminance"}),
    ("ground", {"window", "pixel", "sun_window", "sun_pixel", "albedo", "albedo_size", "brdf"}),
    ("camera", {"position", "look_at", "yaw", "pitch", "fov", "resolution", "exposure", "display",
                "white_balance", "follow"}),
])
def test_an_unknown_key_lists_every_valid_key_of_its_section(tmp_path, section, keys):
    """The keys the README's config documents for the section, whichever the parser read."""
    write_inputs(tmp_path)
    config = base_config()
    config.setdefault(section, {})["mooon"] = 1
    text = refusal(config, tmp_path)
    assert f"{section}.mooon: unknown key (valid here: " in text
    assert set(text.split("valid here: ")[1].rstrip(")").split(", ")) == keys


def test_a_misspelled_section_is_said_before_the_errors_of_other_sections(tmp_path):
    """A config copied away from the files it names, with a section misspelled: the misspelling
    is said first (it was said only once the missing file was mended)."""
    config = base_config()
    config["ground"]["albedo"] = "assets/sand.png"  # not beside the copy
    config["camra"] = config.pop("camera", {})
    assert "camra: unknown key (valid here: animation, camera, canopy" in refusal(config, tmp_path)
    del config["camra"]
    assert "ground.albedo: no such file" in refusal(config, tmp_path)


def test_a_config_named_with_dots_or_spaces_gets_a_valid_output_name(tmp_path):
    write_inputs(tmp_path)
    for name, expected in (("my.scene.yaml", "my_scene"), ("my eclipse.yaml", "my_eclipse")):
        assert load_config(write_config(tmp_path, base_config(), name)).output.name == expected
    named = {**base_config(), "output": {"name": "my.scene"}}
    assert "output.name: must be a name" in refusal(named, tmp_path)
    assert parse_config(named, tmp_path, named_frames=False).output.name == "config"


def test_a_mapping_and_its_yaml_file_give_the_same_config(tmp_path):
    write_inputs(tmp_path)
    from_file = load_config(write_config(tmp_path, base_config()))
    assert parse_config(base_config(), tmp_path) == from_file
    assert parse_config(base_config(), tmp_path).digest() == from_file.digest()


def test_shipped_example_config_is_valid():
    config = load_config(ROOT / "configs" / "ground.yaml")
    assert config.sky.model == "hdri" and config.canopy.layers[0].mask[0].is_file()


def test_the_names_a_config_gives_are_those_the_models_know(tmp_path):
    """The config's vocabulary (pipeline/config/vocabulary.py) is what the models act on: every CIE
    type of the range has its coefficients, every sky model a config may name is built."""
    assert set(clearsky.CIE_TYPES) == set(range(CIE_TYPE_RANGE[0], CIE_TYPE_RANGE[1] + 1))
    write_inputs(tmp_path)
    for model in SKY_MODELS:
        data = {**base_config(), "sky": {"model": model, **({"hdri": "sky.exr"} if model == "hdri" else {})}}
        plan = plan_run(resolve(parse_config(data, tmp_path)))
        assert isinstance(plan.sky.at(plan.scenes[0]), sky.Sky), model


def test_a_sky_model_is_one_module_and_one_registry_line(tmp_path):
    """The overcast sky (pipeline/sky/overcast.py and its line in vocabulary.SKIES; docs/design.md,
    "Models plug in"): its key is read and checked by the registry's entry, another model's key
    is refused naming its owners, and its frame is the uniform sky's of the same radiance, to
    the bit."""
    from pipeline.cache.store import Cache
    from pipeline.stages.frame import render_frame

    write_inputs(tmp_path)
    sky_of = {"camera": {"resolution": [32, 18]}}
    overcast = parse_config({**base_config(), **sky_of, "sky": {"model": "overcast", "luminance": 2.5}}, tmp_path)
    assert overcast.sky.params == (("luminance", 2.5),)
    assert "sky.luminance: must lie in [0, 1e+30] kcd/m^2 (got -1)" in refusal(
        {**base_config(), "sky": {"model": "overcast", "luminance": -1}}, tmp_path)
    assert "sky.radiance: only used with model: uniform (model is overcast)" in refusal(
        {**base_config(), "sky": {"model": "overcast", "radiance": 1}}, tmp_path)
    assert "sky.luminance: only used with model: overcast (model is cie)" in refusal(
        {**base_config(), "sky": {"luminance": 1}}, tmp_path)
    assert "unknown value 'overcst'" in refusal({**base_config(), "sky": {"model": "overcst"}}, tmp_path)
    uniform = parse_config({**base_config(), **sky_of, "sky": {"model": "uniform", "radiance": 2.5}}, tmp_path)
    frames = [render_frame(plan_run(resolve(c)), store=Cache(tmp_path / "cache")).radiance for c in (overcast, uniform)]
    assert frames[0].tobytes() == frames[1].tobytes() and frames[0].max() > 0


YAML_NUMBERS = ["4e-2", "1E5", "1e-300", "2e+3", "1.5e3", "-.5", ".5e3", "-2.5e-3", "1.0e+3"]
"""Floats in YAML 1.2: all but the last two YAML 1.1 (PyYAML's own resolver) reads as text."""


def test_yaml_1_2_floats_are_numbers_and_the_rest_keeps_its_meaning(tmp_path):
    """``pixel: 4e-2`` was refused as the text '4e-2'; Python's float() is the reference."""
    import math

    import yaml

    from pipeline.config.yamlsafe import load_yaml

    lines = [f"n{i}: {token}" for i, token in enumerate(YAML_NUMBERS)]
    lines += ["quoted: '4e-2'", 'double: "1E5"', "seed: 7", "octal: 010", "zero_led: 08",
              "inf: .inf", "nan: .nan", "half: 0.5", "version: 1.2.3", "day: 2024-06-01"]
    _, data = load_yaml(write_config(tmp_path, "\n".join(lines) + "\n"))
    for i, token in enumerate(YAML_NUMBERS):
        assert type(data[f"n{i}"]) is float and data[f"n{i}"] == float(token), token
        assert isinstance(yaml.safe_load(token), str if i < 7 else float)  # yaml.SafeLoader as it was
    assert data["quoted"] == "4e-2" and data["double"] == "1E5"
    assert type(data["seed"]) is int and data["seed"] == 7 and data["octal"] == 8
    assert data["zero_led"] == "08" and data["version"] == "1.2.3" and str(data["day"]) == "2024-06-01"
    assert data["inf"] == math.inf and math.isnan(data["nan"])
    assert data["half"] == 0.5


def test_a_pixel_written_4e_2_is_the_pixel_0_04_and_quoted_stays_text(tmp_path):
    write_inputs(tmp_path)
    text = "ground:\n  window: [-4, -4, 4, 4]\n  pixel: {}\ncanopy:\n  mask: mask.png\n"
    exponent = load_config(write_config(tmp_path, text.format("4e-2"), "exponent.yaml"))
    decimal = load_config(write_config(tmp_path, text.format("0.04"), "decimal.yaml"))
    assert exponent.ground.pixel == 0.04 and exponent.digest() == decimal.digest()
    path = write_config(tmp_path, text.format("'4e-2'"), "quoted.yaml")
    with pytest.raises(ConfigError, match=f"{path}:3: ground.pixel: must be a number, not the text '4e-2'"):
        load_config(path)


def test_the_frame_rate_error_docs_runs_md_quotes_is_what_the_config_it_names_gets(tmp_path):
    import re

    doc = (ROOT / "docs" / "runs.md").read_text()
    given, quoted = re.search(r"\(`(animation: \{fps: [^`]+\})` gives\s+`([^`]+)`\)", doc).groups()
    path = write_config(tmp_path, given + "\n")
    with pytest.raises(ConfigError) as caught:
        resolve(load_config(path))
    assert str(caught.value).endswith(f"{path}:1: {quoted}")


@pytest.mark.parametrize("text", ["", "\n\n", "# a comment\n# another\n", "---\n", "~\n", "null\n"])
def test_an_empty_config_is_refused_naming_the_file(tmp_path, text):
    path = write_config(tmp_path, text, "empty.yaml")
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert str(caught.value) == (f"{path}: the config is empty; start from one of configs/*.yaml "
                                 "(an explicit {} renders every default)")


def test_an_explicit_empty_mapping_is_every_default(tmp_path):
    assert load_config(write_config(tmp_path, "{}\n", "config.yaml")) == parse_config({}, tmp_path)


def test_a_list_of_the_wrong_length_says_how_long_it_is(tmp_path):
    """ground.window with three numbers: the line says it got a list of 3, not just "a list"."""
    config = base_config()
    config["ground"] = {**config.get("ground", {}), "window": [-4, -4, 4]}
    with pytest.raises(ConfigError, match=r"ground\.window: must be a list of 4 numbers, not a list of 3$"):
        load_config(write_config(tmp_path, config))
