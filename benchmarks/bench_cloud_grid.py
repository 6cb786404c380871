"""The clouds' field read on a grid (``kernels.tiling.cloud_grid``, as a ground's sky raster reads it)
against the same points read one by one (``kernels.tiling.cloud_field``), paired in one process.

    python benchmarks/bench_cloud_grid.py [CONFIG ...] [--side 1024] [--repeats 7]

For each config with clouds (default: every such one in configs/), its cloud layer at frame 1
read at a ``--side`` x ``--side`` grid of sky-plane points over its sky square (|x|, |y| <=
tan(alpha)), both ways, alternating which goes first, in one thread: the median CPU time of
each way, their ratio, and whether the two fields are the same to the bit.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", help="default: every config in configs/ with clouds")
    parser.add_argument("--side", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    paths = args.configs or sorted(str(p) for p in (ROOT / "configs").glob("*.yaml"))
    print(f"{'config':16s} {'grid':>9s} {'samples':>9s} {'ratio':>6s}  bits")
    for path in paths:
        plan = plan_run(load(path))
        if plan.sky.config.clouds is None:
            continue
        sky = plan.sky.at(plan.scenes[1])
        layer, when = sky.clouds, sky.time
        edge = math.tan(plan.sky.config.alpha)
        x = np.linspace(-edge, edge, args.side)
        s = np.stack(np.broadcast_arrays(x[None, :], x[::-1, None]), axis=-1)  # a raster's: rows from the north
        samples = s.reshape(-1, 2).copy()  # the same points, not a grid
        layer.field(s[:4, :4], when), layer.field(samples[:4], when)  # compiled
        times = {"grid": [], "samples": []}
        for k in range(args.repeats):
            for way in (("grid", "samples") if k % 2 == 0 else ("samples", "grid")):
                start = time.process_time()
                field = layer.field(s, when) if way == "grid" else layer.field(samples, when).reshape(s.shape[:2])
                times[way].append(time.process_time() - start)
                if way == "grid":
                    grid = field
                else:
                    apart = field
        grid_ms, samples_ms = (float(np.median(times[w])) * 1e3 for w in ("grid", "samples"))
        same = "same" if grid.tobytes() == apart.tobytes() else "DIFFER"
        print(f"{Path(path).stem:16s} {grid_ms:7.1f} ms {samples_ms:6.1f} ms {grid_ms / samples_ms:6.2f}  {same}",
              flush=True)


if __name__ == "__main__":
    main()
