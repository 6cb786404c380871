"""One cycle product's CPU seconds with this checkout's ``pipeline`` against another tree's, alternated.

    python benchmarks/bench_cycle_product.py --code TREE [CONFIG] [--rounds 5] [--products 5]

Each round starts a new process per tree (``PYTHONPATH`` the tree, this checkout first, then TREE):
it plans CONFIG (default configs/eclipse.yaml), makes one cycle product (``cycle.cycle_item``, layer
0, cycle frame 0: it loads the compiled loops), then times the next ``--products`` (cycle frames 1,
2, ..., each into a new render cache) with ``time.process_time`` and prints their median. Prints
each round with the load average, then the medians over the rounds and their ratio, and whether
both trees drew the same masks (SHA-256 of every layer's masks at cycle frame 1).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import hashlib, statistics, sys, tempfile, time
from pathlib import Path
from pipeline.cache import store as cache
from pipeline.stages.cycle import cycle_item, layer_masks
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load
plan = plan_run(load(sys.argv[1]))
store = cache.Cache(Path(tempfile.mkdtemp(prefix="sunshade-product-")))
cycle_item(plan, 0, 0, store)
cpus = []
for frame in range(1, int(sys.argv[2]) + 1):
    cpu = time.process_time()
    cycle_item(plan, 0, frame, store)
    cpus.append(time.process_time() - cpu)
digest = hashlib.sha256()
for index in range(len(plan.layers)):
    made = layer_masks(plan, index, 1)
    for mask in (made.coarse, made.fine):
        if mask is not None:
            digest.update(mask.tobytes())
print(statistics.median(cpus), digest.hexdigest()[:16])
"""


def product(tree: Path, config: str, products: int) -> tuple[float, str]:
    """(median CPU seconds of a cycle product, digest of the masks) with ``tree``'s pipeline."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-P", "-c", CHILD, config, str(products)], env=env, cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), out[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "eclipse.yaml"))
    parser.add_argument("--code", type=Path, required=True, help="the baseline tree")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--products", type=int, default=5)
    args = parser.parse_args()
    trees = {"this checkout": ROOT, "baseline": args.code.resolve()}
    seconds: dict[str, list[float]] = {name: [] for name in trees}
    digests: dict[str, set[str]] = {name: set() for name in trees}
    for round_ in range(args.rounds):
        for name, tree in trees.items():
            cpu, digest = product(tree, args.config, args.products)
            seconds[name].append(cpu)
            digests[name].add(digest)
            print(f"round {round_ + 1}: {name:14s} {cpu * 1e3:7.1f} ms of CPU a product "
                  f"(load {os.getloadavg()[0]:.1f})", flush=True)
    new, old = (statistics.median(seconds[name]) for name in trees)
    print(f"medians: this checkout {new * 1e3:.1f} ms, baseline {old * 1e3:.1f} ms, ratio {new / old:.3f}")
    same = digests["this checkout"] == digests["baseline"] and len(digests["baseline"]) == 1
    print("masks (cycle frame 1):", "the same bytes" if same else f"DIFFER {digests}")


if __name__ == "__main__":
    main()
