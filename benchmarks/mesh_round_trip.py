"""The round trip of a procedural tree through a glTF file: how far its ground light is from the tree's own.

    python benchmarks/mesh_round_trip.py

The tiny grove of tests/scenes.py (one tree, 400 leaves, flutter off) is written as a .glb by
tests/mesh_export.py (alpha-masked leaf cards, capsule meshes of wood) and rendered as `canopy.mesh`;
printed: the RMS and largest difference of the ground irradiance at frame 0, relative to its mean,
for a sun at the zenith and 55 degrees up, with one canopy plane and with two (docs/accuracy.md,
"Trees from mesh files").
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from mesh_export import mesh_twin
from scenes import config_of, tiny_grove

from pipeline.api import functions as api


def main() -> None:
    for elevation in (90.0, 55.0):
        for planes in (None, [{"height": 3.6}, {"height": 4.4}]):
            with tempfile.TemporaryDirectory() as folder:
                base = Path(folder)
                procedural = tiny_grove(**{"canopy.flutter.swing": 0.0, "canopy.flutter.twist": 0.0,
                                           "sky.sun.elevation": elevation})
                if planes:
                    procedural["canopy"]["layers"] = planes
                _, meshed = mesh_twin(procedural, base)
                want = api.ground_irradiance(config_of(procedural, base), 0, cache=base / "cache", threads=1)
                got = api.ground_irradiance(config_of(meshed, base), 0, cache=base / "cache", threads=1)
                difference = got.irradiance.astype(np.float64) - want.irradiance
                mean = float(np.mean(want.irradiance))
                print(f"sun {elevation:g} deg up, {len(planes or [1])} plane(s): ground RMS "
                      f"{100 * np.sqrt(np.mean(difference**2)) / mean:.2f} % of its mean, largest "
                      f"{100 * np.abs(difference).max() / mean:.1f} %")


if __name__ == "__main__":
    main()
