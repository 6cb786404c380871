"""Every key of ``vocabulary.NUMBER_RANGES`` at both ends of its range, through ``sunshade check``
and then ``sunshade frame`` of a tiny grove with clouds (a moon where the key is the moon's): the
exit code, the seconds both took and the last line on stderr. Every row should read exit 0 (or
2 where another rule of the config refuses that value first, said in its line), never 1.

    python benchmarks/check_number_ranges.py

Windows are given one metre wide at the end of their range, lists of numbers with every item at
it; a range that starts at 0 is tried just above it where 0 itself is refused (above 0).
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from scenes import set_key, tiny_grove, write_inputs

from pipeline.cli.main import main
from pipeline.config.vocabulary import NUMBER_RANGES

LISTS = {"ground.window": 4, "ground.sun_window": 4, "canopy.center": 2, "sky.clouds.wind": 2,
         "camera.position": 3, "camera.look_at": 3, "sky.moon.offset_start": 2, "sky.moon.offset_end": 2}
"""The keys that take a list of numbers, and how many."""


def scene() -> dict:
    config = tiny_grove()
    config["sky"]["clouds"] = {"cover": 0.4}
    config["camera"] = {"resolution": [64, 36]}
    config["animation"]["frames"] = 3
    return config


def at(key: str, value: float) -> dict:
    """The scene with ``key`` at ``value`` (and what it needs beside it)."""
    config = scene()
    if key.startswith("sky.moon"):
        config["sky"]["moon"] = {"offset_start": [-0.6, 0.1], "offset_end": [0.1, 0.0]}
    if key == "canopy.trees.count" and value > 1:
        config["canopy"]["trees"]["leaves_per_tree"] = 1  # the leaf limit is another rule
    if key == "camera.position":
        config["camera"]["look_at"] = [0.0, 0.0, 0.0]
    if key == "camera.look_at":
        config["camera"]["position"] = [0.0, -10.0, 2.0]
    if key in LISTS:
        count = LISTS[key]
        value = ([value, value, value + 1, value + 1] if value < 0 else [value - 1, value - 1, value, value]) \
            if "window" in key else [value] * count
        if key == "camera.position":
            value[2] = max(value[2], 1.0)
    *parents, _ = key.split(".")
    node = config
    for part in parents:
        node = node.setdefault(part, {})
    return set_key(config, key, value)


def main_() -> None:
    with tempfile.TemporaryDirectory() as scratch, contextlib.chdir(scratch):
        write_inputs(Path(scratch))
        for key, (least, most, unit) in NUMBER_RANGES.items():
            if "[]" in key or key == "canopy.size":  # mask layers' keys: the canopy here is a grove
                continue
            for value in (least, most):
                if value == 0 and key in ("ground.pixel", "canopy.trees.crown_radius"):
                    value = 1e-9
                Path("c.yaml").write_text(yaml.safe_dump(at(key, value)))
                err, started = io.StringIO(), time.perf_counter()
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                    code = main(["check", "c.yaml"])
                    if code == 0:
                        code = main(["frame", "c.yaml", "--frame", "2", "-o", "f.png"])
                lines = err.getvalue().strip().splitlines()
                shown = value if isinstance(value, int) else f"{value:g}"
                print(f"{key} = {shown} {unit}: exit {code}, {time.perf_counter() - started:.1f} s"
                      f"{'; ' + lines[-1][:160] if lines and code else ''}", flush=True)


if __name__ == "__main__":
    main_()
