"""The demo mesh tree of configs/mesh-tree.yaml and configs/mesh-obj.yaml, made by hand (issue 45).

    python benchmarks/make_mesh_tree.py [--out configs/assets/mesh-tree] [--leaves 700] [--seed 3]

No public tree model with alpha-cut leaf cards could be reached from this project's package registries
(docs/method.md, "Trees from mesh files"), so this one is drawn here: a tapered eight-sided trunk, six
branches, and ``--leaves`` leaf cards (two triangles each) around the branches' ends, each textured with
a lobed leaf whose alpha cuts it out of its square, drawn with numpy. Written, Y-up in metres, as

- ``tree.obj`` + ``tree.mtl`` + ``leaf.png`` (the leaf material's alpha in the PNG: blended), and
- ``tree.glb`` (the same geometry; the leaf material ``alphaMode: MASK`` at 0.5, written by trimesh).

The output is deterministic for a seed; the committed files are this script's output.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import numpy as np
from PIL import Image

TEXTURE = 128  # the leaf texture's side [texel]
LEAF_SIZE = (0.28, 0.19)  # a leaf card's length and width [m]
CROWN_CENTRE = np.array([0.0, 0.0, 4.3])  # x east, y north, z up [m]
CROWN_RADII = np.array([2.1, 2.1, 1.5])  # [m]


def leaf_rgba() -> np.ndarray:
    """The leaf texture (TEXTURE x TEXTURE RGBA, uint8): a lobed leaf along the image's rows (its stalk at the
    left, its tip at the right), alpha 255 inside and 0 outside, a one-texel soft edge."""
    y, x = (np.mgrid[0:TEXTURE, 0:TEXTURE] + 0.5) / TEXTURE
    along, across = (x - 0.08) / 0.9, np.abs(y - 0.5)
    lobes = 1.0 + 0.28 * np.abs(np.sin(3.5 * np.pi * np.clip(along, 0, 1)))
    half_width = 0.36 * np.sin(np.pi * np.clip(along, 0, 1)) ** 0.7 * lobes
    inside = half_width - across  # > 0 inside the blade [texture widths]
    stalk = (x < 0.12) & (across < 0.025)
    alpha = np.clip(0.5 + inside * TEXTURE, 0.0, 1.0)
    alpha = np.where((along >= 0) & (along <= 1), alpha, 0.0)
    alpha = np.maximum(alpha, stalk.astype(float))
    vein = (across < 0.012) | (np.abs(np.abs(y - 0.5) - 0.6 * (along % 0.22)) < 0.01)
    rgba = np.zeros((TEXTURE, TEXTURE, 4), np.uint8)
    rgba[..., 0] = np.where(vein, 120, 70)
    rgba[..., 1] = np.where(vein, 150, 125 + (40 * y).astype(int))
    rgba[..., 2] = np.where(vein, 60, 35)
    rgba[..., 3] = np.round(255 * alpha).astype(np.uint8)
    return rgba


def _prism(start: np.ndarray, end: np.ndarray, r0: float, r1: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A tapered prism from start to end (radii r0, r1), closed at the far end, faces wound outwards."""
    axis = (end - start) / np.linalg.norm(end - start)
    side = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    other = np.cross(axis, side)
    angle = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(angle)[:, None] * side + np.sin(angle)[:, None] * other
    points = np.concatenate([start + r0 * ring, end + r1 * ring, [end]])
    i = np.arange(sides)
    j = (i + 1) % sides
    faces = np.concatenate([np.column_stack([i, j, j + sides]), np.column_stack([i, j + sides, i + sides]),
                            np.column_stack([i + sides, j + sides, np.full(sides, 2 * sides)])])
    return points, faces


def wood(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trunk and six branches (x east, y north, z up) [m]: points, faces, and each branch's far end."""
    parts = [_prism(np.zeros(3), np.array([0.0, 0.0, 3.2]), 0.17, 0.10, 8)]
    ends = []
    for k in range(6):
        turn = 2 * np.pi * k / 6 + rng.uniform(-0.3, 0.3)
        start = np.array([0.0, 0.0, rng.uniform(2.3, 3.1)])
        end = CROWN_CENTRE + np.array([1.5 * np.cos(turn), 1.5 * np.sin(turn), rng.uniform(-0.4, 0.6)])
        parts.append(_prism(start, end, 0.07, 0.03, 6))
        ends.append(end)
    points, faces, offset = [], [], 0
    for p, f in parts:
        points.append(p)
        faces.append(f + offset)
        offset += len(p)
    return np.concatenate(points), np.concatenate(faces), np.array(ends)


def leaf_cards(rng: np.random.Generator, count: int, ends: np.ndarray) -> np.ndarray:
    """``count`` leaf cards (count, 4, 3) [m]: corners stalk-left, stalk-right, tip-right, tip-left, the
    stalks near the branches' ends and the crown, each card turned at random with its tip outwards."""
    towards = ends[rng.integers(0, len(ends), count)]
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    stalk = 0.35 * towards + 0.65 * (CROWN_CENTRE + direction * CROWN_RADII * rng.uniform(0.35, 1.0, (count, 1)))
    outward = stalk - CROWN_CENTRE + rng.normal(scale=0.6, size=(count, 3))
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    across = np.cross(outward, rng.normal(size=(count, 3)))
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    length, width = LEAF_SIZE
    half = 0.5 * width * across
    tip = stalk + length * outward
    return np.stack([stalk - half, stalk + half, tip + half, tip - half], axis=1)


def _to_y_up(points: np.ndarray) -> np.ndarray:
    """World (x east, y north, z up) to a Y-up file's (x, z, -y), as glTF and most OBJ exporters write."""
    return np.column_stack([points[:, 0], points[:, 2], -points[:, 1]])


def write_obj(folder: Path, cards: np.ndarray, wood_points: np.ndarray, wood_faces: np.ndarray, png: bytes) -> None:
    """tree.obj, tree.mtl and leaf.png; millimetre coordinates."""
    (folder / "leaf.png").write_bytes(png)
    (folder / "tree.mtl").write_text("# sunshade demo tree (benchmarks/make_mesh_tree.py), CC0\n"
                                     "newmtl leaf\nKd 0.3 0.55 0.2\nmap_Kd leaf.png\n\n"
                                     "newmtl bark\nKd 0.35 0.27 0.2\n")
    leaf_points = _to_y_up(cards.reshape(-1, 3))
    lines = ["# sunshade demo tree (benchmarks/make_mesh_tree.py), CC0: Y-up, metres", "mtllib tree.mtl"]
    lines += [f"v {x:.3f} {y:.3f} {z:.3f}" for x, y, z in np.concatenate([leaf_points, _to_y_up(wood_points)])]
    lines += ["vt 0 0", "vt 0 1", "vt 1 1", "vt 1 0"]  # stalk at the image's left (u = 0), the tip at its right
    lines += ["o leaves", "usemtl leaf"]
    for k in range(len(cards)):
        a = 4 * k + 1
        lines += [f"f {a}/1 {a + 1}/2 {a + 2}/3", f"f {a}/1 {a + 2}/3 {a + 3}/4"]
    lines += ["o wood", "usemtl bark"]
    offset = len(leaf_points) + 1
    lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in wood_faces]
    (folder / "tree.obj").write_text("\n".join(lines) + "\n")


def write_glb(path: Path, cards: np.ndarray, wood_points: np.ndarray, wood_faces: np.ndarray, rgba: np.ndarray) -> None:
    """tree.glb: the leaves alpha-masked (cutoff 0.5), double-sided; the wood opaque."""
    import trimesh

    count = len(cards)
    quad = 4 * np.arange(count)[:, None]
    faces = np.concatenate([quad + [0, 1, 2], quad + [0, 2, 3]])
    uv = np.tile([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]], (count, 1))
    leaf = trimesh.visual.material.PBRMaterial(name="leaf", baseColorTexture=Image.fromarray(rgba, "RGBA"),
                                               alphaMode="MASK", alphaCutoff=0.5, doubleSided=True)
    bark = trimesh.visual.material.PBRMaterial(name="bark", baseColorFactor=[90, 70, 50, 255])
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.Trimesh(_to_y_up(cards.reshape(-1, 3)), faces, process=False,
                                       visual=trimesh.visual.TextureVisuals(uv=uv, material=leaf)), "leaves")
    scene.add_geometry(trimesh.Trimesh(_to_y_up(wood_points), wood_faces,
                                       process=False, visual=trimesh.visual.TextureVisuals(material=bark)), "wood")
    path.write_bytes(scene.export(file_type="glb"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "configs/assets/mesh-tree")
    parser.add_argument("--leaves", type=int, default=700)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    wood_points, wood_faces, ends = wood(rng)
    cards = leaf_cards(rng, args.leaves, ends)
    rgba = leaf_rgba()
    png = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(png, "PNG", optimize=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_obj(args.out, cards, wood_points, wood_faces, png.getvalue())
    write_glb(args.out / "tree.glb", cards, wood_points, wood_faces, rgba)
    for name in ("tree.obj", "tree.mtl", "leaf.png", "tree.glb"):
        print(f"{args.out / name}: {(args.out / name).stat().st_size} bytes")


if __name__ == "__main__":
    main()
