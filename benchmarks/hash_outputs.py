"""SHA-256 of what the shipped configs make, to show that a refactor keeps every output's bytes.

    python benchmarks/hash_outputs.py OUT [--code TREE] [CONFIG ...]

For each config (default: every one in configs/): `sunshade mask --frame 3`, `sunshade ground
--frame 5`, `sunshade frame --frame 5` as EXR and as PNG, run with the `pipeline` package of
TREE (default: this checkout) from this checkout's folder, so that the configs' hashes, which
include their files' paths, are the same for any TREE; then the SHA-256 of each file (bytes and
decoded pixels) and of every cache .npy they made, written to OUT/hashes.txt. Run it with two
trees (e.g. a `git worktree add` of the commit before) and `diff` the two files.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.core import io

COMMANDS = (("mask", "--frame", "3", "-o", "mask.exr"),
            ("ground", "--frame", "5", "--threads", "2", "--cache", "cache", "-o", "ground.exr"),
            ("frame", "--frame", "5", "--threads", "2", "--cache", "cache", "-o", "frame.exr"),
            ("frame", "--frame", "5", "--threads", "2", "--cache", "cache", "-o", "frame.png"))


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--code", type=Path, default=ROOT, help="the tree whose pipeline package runs")
    parser.add_argument("configs", nargs="*", type=Path)
    args = parser.parse_intermixed_args()
    configs = args.configs or sorted((ROOT / "configs").glob("*.yaml"))
    env = {**os.environ, "PYTHONPATH": str(args.code.resolve())}
    lines = []
    for config in configs:
        folder = (args.out / config.stem).resolve()
        folder.mkdir(parents=True, exist_ok=True)
        for command, *options in COMMANDS:
            options = [str(folder / o) if o in ("cache", "mask.exr", "ground.exr", "frame.exr", "frame.png")
                       else o for o in options]
            # -P: the package of --code, not the one in the current folder
            subprocess.run([sys.executable, "-P", "-m", "pipeline.cli", command, str(config.resolve()), *options],
                           cwd=ROOT, env=env, capture_output=True, text=True)
        for path in sorted(folder.glob("*.exr")) + sorted(folder.glob("*.png")):
            pixels = np.ascontiguousarray(io.read_image(path)).tobytes()
            lines.append(f"{config.stem}/{path.name} file={sha(path.read_bytes())} pixels={sha(pixels)}")
        for path in sorted((folder / "cache").rglob("*.npy")):
            lines.append(f"{config.stem} {path.relative_to(folder)} {sha(path.read_bytes())}")
        print(f"{config.stem}: done", flush=True)
    (args.out / "hashes.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
