"""A mesh tree's masks (issue 45) against the procedural grove's with the same leaves, paired in one run.

    python benchmarks/bench_mesh_coverage.py [--leaves 100000] [--repeat 5] [--texture 64] [--frames 48]

The grove of configs/grove.yaml's kind (3 trees, 4 m crowns, 8 cm leaves) grown with ``--leaves``
leaves; each elliptical leaf also made a leaf card (two triangles over the ellipse's bounding
parallelogram) whose ``--texture``-square alpha texture holds the ellipse (alpha-masked), so the
mesh has 2 x ``--leaves`` triangles and draws the same leaves. Both are drawn, leaves only, on the
canopy plane at 8 m, sun point (0.4, 0.6), 0.025 m pixels:

- at rest, alternately ``--repeat`` times: ``rasteriser.rasterize_transmittance`` of the projected
  leaves (what ``grove_mask`` draws) and ``mesh_coverage.mesh_mask``; each one's median seconds, their
  ratio, and the RMS difference of the two masks over the pixels either covers;
- the cycle's mask work, frame by frame for ``--frames`` frames, alternately: ``grove_mask`` (flutter,
  projection, rasteriser) and ``mesh_flutter.mesh_at`` + ``mesh_mask`` (the tables made once, as
  ``mesh_layers.MeshTree`` holds them); each one's total and median seconds and the ratio of the totals,
  the one issue 45 bounds by 2.

The load average is printed before and after. Also the seconds to write the mesh as a .glb (trimesh)
and read it back (``mesh.read_mesh``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.canopy.grove import FlutterParams, GroveParams, grove_bounds, grow_grove, project
from pipeline.canopy.mesh import MeshMaterial, MeshParams, TreeMesh, read_mesh
from pipeline.canopy.mesh_coverage import coverage_tables, mesh_mask
from pipeline.canopy.mesh_flutter import leaf_motion, mesh_at
from pipeline.canopy.rasteriser import grove_mask, rasterize_transmittance
from pipeline.core.geometry import Grid

SUN = (0.4, 0.6)
PLANE = 8.0
PIXEL = 0.025


def leaf_cards(grove, texture: int) -> TreeMesh:
    """The grove's leaves as alpha-masked cards: corners centre +- U +- V, the texture's ellipse inscribed."""
    leaves = grove.leaves
    c, u, v = leaves.center, leaves.axis_u, leaves.axis_v
    corners = np.stack([c - u - v, c + u - v, c + u + v, c - u + v], axis=1).reshape(-1, 3)
    n = len(c)
    quad = 4 * np.arange(n)[:, None]
    triangles = np.concatenate([quad + [0, 1, 2], quad + [0, 2, 3]])
    corner_uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    uv = np.concatenate([np.broadcast_to(corner_uv[[0, 1, 2]], (n, 3, 2)),
                         np.broadcast_to(corner_uv[[0, 2, 3]], (n, 3, 2))])
    y, x = (np.mgrid[0:texture, 0:texture] + 0.5) / texture * 2 - 1
    coverage = (x**2 + y**2 <= 1).astype(np.float32)
    group = np.concatenate([np.arange(n), np.arange(n)])
    return TreeMesh(corners, triangles, uv, np.zeros(2 * n, np.int64),
                    (MeshMaterial("leaf", True, "mask", coverage, 0.5),), group, 0, Path("cards"))


def _glb_round_trip(mesh: TreeMesh, texture: int) -> tuple[float, float]:
    """Seconds to write the cards as a .glb with trimesh, and to read it with ``read_mesh``."""
    import trimesh
    from PIL import Image

    rgba = np.zeros((texture, texture, 4), np.uint8)
    rgba[..., 3] = 255 * mesh.materials[0].coverage.astype(np.uint8)
    material = trimesh.visual.material.PBRMaterial(name="leaf", baseColorTexture=Image.fromarray(rgba),
                                                  alphaMode="MASK", alphaCutoff=0.5, doubleSided=True)
    n = len(mesh.triangles) // 2
    uv = np.tile([[0, 0], [1, 0], [1, 1], [0, 1]], (n, 1)).astype(float)
    points = mesh.vertices[:, [0, 2, 1]] * [1, 1, -1]  # world to glTF's Y-up
    cards = trimesh.Trimesh(points, mesh.triangles, process=False,
                            visual=trimesh.visual.TextureVisuals(uv=uv, material=material))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "cards.glb"
        start = time.perf_counter()
        cards.export(str(path))
        written = time.perf_counter()
        read_mesh(MeshParams(path))
        return written - start, time.perf_counter() - written


def _at_rest(grove, mesh: TreeMesh, tables, grid: Grid, repeat: int) -> None:
    """Both masks at rest, alternately ``repeat`` times: the medians, their ratio, the masks' difference."""
    procedural = lambda: rasterize_transmittance(project(grove.leaves, sun=SUN, plane_height=PLANE), grid)  # noqa: E731
    cards = lambda: mesh_mask(mesh, sun=SUN, plane_height=PLANE, grid=grid, tables=tables)  # noqa: E731
    a, b = procedural(), cards()  # compiled, and the masks compared
    times: dict[str, list[float]] = {"procedural": [], "mesh": []}
    for _ in range(repeat):
        for name, draw in (("procedural", procedural), ("mesh", cards)):
            start = time.perf_counter()
            draw()
            times[name].append(time.perf_counter() - start)
    medians = {k: statistics.median(v) for k, v in times.items()}
    seen = (a < 1) | (b < 1)
    print("  at rest (one mask):")
    for name, value in medians.items():
        print(f"    {name:10s} median {value:.3f} s  ({', '.join(f'{t:.3f}' for t in times[name])})")
    print(f"    ratio mesh / procedural: {medians['mesh'] / medians['procedural']:.2f}")
    print(f"    RMS mask difference over {seen.sum()} covered pixels: {np.sqrt(np.mean((a - b)[seen] ** 2)):.4f}; "
          f"mean transmittance {a[seen].mean():.4f} procedural, {b[seen].mean():.4f} mesh")


def _cycle(grove, mesh: TreeMesh, tables, grid: Grid, frames: int) -> None:
    """The cycle's mask work, frame by frame, the grove's and the mesh's alternately: totals, medians, ratio."""
    flutter = FlutterParams()
    motion = leaf_motion(mesh, seed=0)
    procedural = lambda f: grove_mask(grove, flutter, f, sun=SUN, plane_height=PLANE, grid=grid)  # noqa: E731
    cards = lambda f: mesh_mask(mesh_at(mesh, motion, flutter, f), sun=SUN, plane_height=PLANE,  # noqa: E731
                                grid=grid, tables=tables)
    procedural(1), cards(1)  # compiled
    times: dict[str, list[float]] = {"procedural": [], "mesh": []}
    for frame in range(frames):
        for name, draw in (("procedural", procedural), ("mesh", cards)):
            start = time.perf_counter()
            draw(frame)
            times[name].append(time.perf_counter() - start)
    totals = {k: sum(v) for k, v in times.items()}
    print(f"  a {frames}-frame cycle's masks (flutter, projection, drawing), frame by frame:")
    for name, value in totals.items():
        print(f"    {name:10s} total {value:.2f} s, median {statistics.median(times[name]):.3f} s a frame")
    print(f"    ratio mesh / procedural (issue 45: at most 2): {totals['mesh'] / totals['procedural']:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--leaves", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--texture", type=int, default=64)
    parser.add_argument("--frames", type=int, default=48)
    args = parser.parse_args()
    grove = grow_grove(GroveParams(count=3, leaves_per_tree=args.leaves // 3, leaf_length=0.08))
    mesh = leaf_cards(grove, args.texture)
    x0, y0, x1, y1 = grove_bounds(grove, sun=SUN, plane_height=PLANE)
    grid = Grid((x0, y1), PIXEL, (int(np.ceil((y1 - y0) / PIXEL)), int(np.ceil((x1 - x0) / PIXEL))))
    start = time.perf_counter()
    tables = coverage_tables(mesh)
    made = time.perf_counter() - start
    print(f"{len(grove.leaves.center)} leaves, {len(mesh.triangles)} triangles, grid {grid.shape}, "
          f"texture {args.texture}^2, load average {os.getloadavg()[0]:.2f}; tables made in {made:.2f} s")
    _at_rest(grove, mesh, tables, grid, args.repeat)
    if args.frames:
        _cycle(grove, mesh, tables, grid, args.frames)
    write, read = _glb_round_trip(mesh, args.texture)
    print(f"  .glb written by trimesh {write:.2f} s, read by read_mesh {read:.2f} s; "
          f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
