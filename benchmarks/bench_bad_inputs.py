"""Every hostile config of tests/test_hostile.py through ``sunshade check`` and ``sunshade render``
as real processes, and the inputs of issue 33 that are files or flags (a folder name that is not
UTF-8, an image bomb, a cache that cannot be written, a scheduler address, an --output that is
not UTF-8): exit code, wall time, peak resident memory and stderr lines, beside a bare
``python -c "import pipeline.cli.main"`` (the start-up every command pays). Target (issues 16 and
33): exit 2, one line, nothing written, within 3 s and 300 MB. Issue 50 adds input images with a
NaN or infinite texel and a mask path that is a named pipe or a device.

    python benchmarks/bench_bad_inputs.py

The peak memory is measured by a small parent process (``PEAK`` in the tests): Linux counts a
forked child's peak from the process it was forked from.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np
import yaml
from scenes import base_config, write_inputs
from test_hostile import (
    CASES,
    NOT_UTF8,
    PEAK,
    a_png_header,
    albedo_with,
    half_mask_with,
    imported_pass_with,
    unwritable_folder,
)


def not_utf8_folder(folder: Path) -> list[str]:
    """The mask through a link into a folder whose name is not UTF-8."""
    (folder / NOT_UTF8).mkdir(exist_ok=True)
    (folder / NOT_UTF8 / "mask.png").write_bytes((folder / "mask.png").read_bytes())
    if not (folder / "link").is_symlink():
        (folder / "link").symlink_to(folder / NOT_UTF8)
    config = base_config()
    config["canopy"]["mask"] = "link/mask.png"
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    return []


def image_bomb(folder: Path) -> list[str]:
    a_png_header(folder / "mask.png", 30_000, 30_000)
    return []


def read_only_cache(folder: Path) -> list[str]:
    return ["--cache", str(unwritable_folder(folder) / "cache")]


def config_text(text: bytes):
    def make(folder: Path) -> list[str]:
        (folder / "config.yaml").write_bytes(text)
        return []
    return make


def bad_texel(make, value):
    """Issue 50: an input image (albedo, half-float mask, imported pass) with one NaN or infinite texel."""
    def made(folder: Path) -> list[str]:
        (folder / "config.yaml").write_text(yaml.safe_dump(make(folder, np.float32(value))))
        return []
    return made


def mask_at(path_of):
    """Issue 50: the mask's path names something that is not a regular file."""
    def made(folder: Path) -> list[str]:
        config = base_config()
        config["canopy"]["mask"] = str(path_of(folder))
        (folder / "config.yaml").write_text(yaml.safe_dump(config))
        return []
    return made


def named_pipe(folder: Path) -> Path:
    if not (folder / "pipe.png").exists():
        os.mkfifo(folder / "pipe.png")
    return folder / "pipe.png"


def flags(*args):
    return lambda folder: list(args)


FILE_CASES = [  # issue 33: the inputs that are files or flags; each makes them in the folder and
    # returns render's extra flags (its --cache replaces out/cache); check takes no flags, and
    # passes where only a flag is bad
    ("folder name not UTF-8", not_utf8_folder),
    ("image bomb 30000 x 30000", image_bomb),
    ("cache on a folder not writable", read_only_cache),
    ("scheduler port not a number", flags("--scheduler", "tcp://127.0.0.1:eighty")),
    ("--output not UTF-8", flags("--output", f"out/{NOT_UTF8}")),
    ("albedo EXR with a NaN texel", bad_texel(albedo_with, np.nan)),
    ("albedo EXR with an inf texel", bad_texel(albedo_with, np.inf)),
    ("half-float mask with a NaN texel", bad_texel(half_mask_with, np.nan)),
    ("imported pass with an inf texel", bad_texel(imported_pass_with, np.inf)),
    ("mask a named pipe", mask_at(named_pipe)),
    ("mask a device", mask_at(lambda folder: Path("/dev/null"))),
]


def measured(args, cwd) -> tuple[int, float, float, int]:
    """(exit code, wall time [s], peak memory [MB], stderr lines) of one command."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", PEAK, sys.executable, *args], cwd=cwd,
                          capture_output=True, text=True)
    code, peak = (int(v) for v in done.stdout.split()[-2:])
    return code, time.perf_counter() - started, peak / 1e6, len(done.stderr.strip().splitlines())


def main():
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        code, seconds, peak, _ = measured(["-c", "import pipeline.cli.main"], ROOT)
        print(f"{'bare start-up':<32} {seconds:5.2f} s {peak:5.0f} MB")
        worst = (0.0, 0.0)
        for name, make in [(name, config_text(text)) for name, text, _ in CASES] + FILE_CASES:
            write_inputs(folder)
            (folder / "config.yaml").write_text(yaml.safe_dump(base_config()))
            extra = make(folder)
            row = f"{name:<32}"
            for command in (["check", "config.yaml"],
                            ["render", "config.yaml", "--output", "out/run", "--cache", "out/cache", *extra]):
                code, seconds, peak, lines = measured(["-m", "pipeline.cli", *command], folder)
                worst = (max(worst[0], seconds), max(worst[1], peak))
                row += f" | {command[0]}: exit {code}, {seconds:4.2f} s, {peak:4.0f} MB, {lines} line"
            row += " | wrote nothing" if not (folder / "out").exists() else " | WROTE out/"
            print(row)
        print(f"worst: {worst[0]:.2f} s, {worst[1]:.0f} MB")


if __name__ == "__main__":
    main()
