"""Figures of the cloud tile's copies (docs/accuracy.md, "Pictures without tells", the cloud
tile's period), with configs/grove.yaml's cloud layer at t = 5 s:

- the mean coverage between 0.5 and 6 degrees of elevation per azimuth, each sample read with
  the footprint of a pixel of grove.yaml's camera (focal length 772 px): the lattice's x axis
  (90 degrees) beside its neighbours, and the layer's cover;
- the correlation of the field with itself one tile along the x axis, the y axis and the
  diagonal, for the layer of tests/test_clouds.py with seeds 0 to 5 (a repeating tile: 1);
- the clouds' transmittance over the sun's disc (2,500 directions), summed over all frames of
  grove.yaml and sun-and-shade.yaml (the sun's cloud, which sets S).

    python benchmarks/accuracy_clouds.py
"""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.sky.clouds import CloudLayer
from pipeline.stages.resolve import load

FOCAL = 772.0  # grove.yaml's camera [px]


def layer_of(config) -> CloudLayer:
    c = config.sky.clouds
    return CloudLayer(cover=c.cover, scale=c.scale, altitude=c.altitude, wind=c.wind,
                      thickness=c.thickness, seed=c.seed)


def horizon_coverage(layer: CloudLayer, azimuth_deg: float, time: float) -> float:
    elevation = np.radians(np.linspace(0.5, 6.0, 200))
    up, out = np.sin(elevation), np.cos(elevation)
    azimuth = np.radians(azimuth_deg)
    s = np.stack([out * np.sin(azimuth) / up, out * np.cos(azimuth) / up], -1)
    footprint = np.stack([1.0 / (FOCAL * up**2), 1.0 / (FOCAL * up)], -1)
    return float(layer.coverage(s, time, footprint=footprint).mean())


def main() -> None:
    grove = layer_of(load(ROOT / "configs" / "grove.yaml"))
    print(f"grove.yaml's layer, cover {grove.cover}: mean coverage 0.5-6 deg above the horizon")
    for azimuth in (80, 85, 88, 90, 92, 95, 100):
        print(f"  azimuth {azimuth:>3} deg: {horizon_coverage(grove, azimuth, 5.0):.3f}")
    print("field one tile along x, y, the diagonal: correlation with itself")
    for seed in range(6):
        layer = CloudLayer(cover=0.5, scale=400.0, altitude=1500.0, wind=(8.0, 2.0), thickness=8.0,
                           seed=seed, texels=256)
        period = layer.period * layer.scale / layer.altitude  # [tan]
        x = np.linspace(0.1, 0.1 + 6 * period, 6000, endpoint=False)
        found = []
        for y, shift in ((0.0, (period, 0.0)), (0.3 * period, (0.0, period)), (0.0, (period, period))):
            s = np.stack([x, np.full_like(x, y)], -1)
            found.append(np.corrcoef(layer.field(s, 5.0), layer.field(s + shift, 5.0))[0, 1])
        print(f"  seed {seed}: " + ", ".join(f"{c:+.3f}" for c in found))
    rim = np.linspace(0.0, 2.0 * np.pi, 50)
    for name in ("grove", "sun-and-shade"):
        config = load(ROOT / "configs" / f"{name}.yaml")
        layer, sun = layer_of(config), config.sky.sun
        s = np.array([np.sin(sun.azimuth), np.cos(sun.azimuth)]) / np.tan(sun.elevation)
        disc = sun.radius * np.sqrt(np.linspace(0, 1, 50))[:, None, None] * np.stack(
            [np.cos(rim), np.sin(rim)], -1)[None]
        points = s + disc.reshape(-1, 2) / np.sin(sun.elevation) ** 2
        total = sum(layer.transmittance(points, f / config.animation.fps).mean()
                    for f in range(config.animation.frames))
        print(f"{name}.yaml: the sun's disc, transmittance summed over {config.animation.frames} frames "
              f"{float(total)!r}")


if __name__ == "__main__":
    main()
