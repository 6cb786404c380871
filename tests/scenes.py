"""Small scenes the tests share, as config mappings (what a YAML file would hold), and the
files they name."""

from pathlib import Path

import numpy as np
import yaml

from pipeline.cli.main import main
from pipeline.config.parse import parse_config
from pipeline.core import io
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import resolve

ROOT = Path(__file__).resolve().parents[1]
"""The repository."""


def tiny_grove(**changes):
    """A small grove under a procedural sun: a few hundred leaves, coarse pixels. ``changes``:
    dotted key -> value."""
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


def config_of(data: dict, base_dir):
    """The resolved Config of a mapping, its files relative to ``base_dir``."""
    return resolve(parse_config(data, base_dir))


def plan_of(data: dict, base_dir):
    """The RunPlan of a mapping, its files relative to ``base_dir``."""
    return plan_run(config_of(data, base_dir))


def write_inputs(folder: Path):
    """A small leafy mask PNG and a uniform sky EXR in ``folder``."""
    rng = np.random.default_rng(0)
    mask = np.where(rng.random((40, 40)) < 0.4, 0.0, 1.0).astype(np.float32)[..., None]
    io.write_png(folder / "mask.png", mask)
    io.write_exr(folder / "sky.exr", np.ones((32, 64, 3), np.float32))


def base_config():
    return {
        "canopy": {"mask": "mask.png", "size": [4.0, 4.0], "center": [0.0, 0.0], "height": 3.0,
                   "layout": "isolated"},
        "sky": {"model": "uniform", "radiance": 1.0, "alpha": 80.0},
        "ground": {"window": [-4, -4, 4, 4], "pixel": 0.1},
    }


def write_config(folder: Path, config, name="config.yaml") -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(config) if not isinstance(config, str) else config)
    return path


def assert_refused(config, out, capsys, message, *, commands=("ground", "check", "render"), extra=()):
    """Every command refuses the config with exit 2 and one line holding ``message``, before
    writing anything (no output file, no run folder, no cache)."""
    for command in commands:
        argv = {"ground": ["ground", str(config), "-o", str(out / "g.exr"), "--png"],
                "check": ["check", str(config)],
                "render": ["render", str(config), "--output", str(out / "run"),
                           "--cache", str(out / "cache"), *extra]}[command]
        assert main(argv) == 2, command
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, (command, err)
        assert list(out.iterdir()) == [], command


DELETE = object()
"""What ``set_key`` sets to delete a key."""


def set_key(config, dotted, value):
    """``config`` with the key at ``dotted`` set to ``value`` (or deleted)."""
    node = config
    keys = dotted.split(".")
    for key in keys[:-1]:
        node = node[key]
    if value is DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return config
