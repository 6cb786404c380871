"""Whether two run folders hold the same pictures: each frame's EXR pixels (bit for bit), PNG codes
and the video's bytes, to show that a change keeps a whole render's output.

    python benchmarks/compare_runs.py FOLDER_A FOLDER_B

The frames are matched by file name (``NAME.0000.exr``); the PNG files themselves may differ in
their ``sunshade:config_hash`` text, which holds the config's path. Exits 1 when anything differs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.core import io


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", type=Path)
    parser.add_argument("b", type=Path)
    args = parser.parse_args()
    exrs = sorted(p.name for p in args.a.glob("*.exr"))
    same_exr = sum(np.array_equal(io.read_image(args.a / n).view(np.uint32), io.read_image(args.b / n).view(np.uint32))
                   for n in exrs if (args.b / n).is_file())
    pngs = [n[:-4] + ".png" for n in exrs]
    same_png = sum(np.array_equal(io.read_codes(args.a / n), io.read_codes(args.b / n))
                   for n in pngs if (args.a / n).is_file() and (args.b / n).is_file())
    videos = sorted(p.name for p in args.a.glob("*.mp4"))
    same_video = sum((args.b / n).is_file() and (args.a / n).read_bytes() == (args.b / n).read_bytes() for n in videos)
    print(f"EXR pixels the same: {same_exr} of {len(exrs)}; PNG codes the same: {same_png} of {len(pngs)}; "
          f"videos the same: {same_video} of {len(videos)}")
    return 0 if (same_exr, same_png, same_video) == (len(exrs), len(pngs), len(videos)) else 1


if __name__ == "__main__":
    sys.exit(main())
