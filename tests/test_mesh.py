"""Tree meshes from glTF, OBJ and PLY files: reading, placing, and their exact coverage of a layer's mask.

The files are written here by hand (not by trimesh, which reads them), so that a wrong axis, a flipped
texture row or a wrong alpha mode shows. The coverage is held to an independent estimate: 32 x 32
point samples a pixel, each looked up in the leaf texture (docs/method.md, "Trees from mesh files").
"""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipeline.canopy.mesh import MeshParams, read_mesh
from pipeline.canopy.mesh_coverage import alpha_weighted_area, mesh_layer_index, mesh_mask
from pipeline.core.errors import ImageError
from pipeline.core.geometry import Grid

SIDE = 0.8  # leaf cards' side [m]
TEXTURE = 256  # leaf texture's side [texel]
SUN = (0.3, -0.2)  # the sun's sky-plane point [tan]
PLANE = 5.0  # canopy plane [m]
GRID = Grid((-0.7, 1.55), 0.05, (36, 100))  # north-west corner [m], pixel [m], (rows, cols)


def _alpha() -> np.ndarray:
    """The leaf texture's alpha (rows from the image's top) [0, 255]: a soft-edged ellipse off centre, so that
    a flipped row or column shows, and an alpha cutoff moves its edge."""
    y, x = (np.mgrid[0:TEXTURE, 0:TEXTURE] + 0.5) / TEXTURE
    d2 = ((x - 0.42) / 0.38) ** 2 + ((y - 0.36) / 0.3) ** 2
    return np.round(255 * np.clip(2.0 * (1.0 - d2), 0.0, 1.0)).astype(np.uint8)


def _png() -> bytes:
    rgba = np.zeros((TEXTURE, TEXTURE, 4), np.uint8)
    rgba[..., 1], rgba[..., 3] = 160, _alpha()
    out = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(out, "PNG")
    return out.getvalue()


def _leaves() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two leaf cards in world axes (x east, y north, z up) [m]: one level at z 5, one tilted 30 degrees (its
    centre at z 5.4); their corner uv with v down from the image's top (glTF's convention); their triangles."""
    square = np.array([[0, 0, 0], [SIDE, 0, 0], [SIDE, SIDE, 0], [0, SIDE, 0]], float)
    tilt = np.radians(30.0)
    turned = square @ np.array([[1, 0, 0], [0, np.cos(tilt), np.sin(tilt)], [0, -np.sin(tilt), np.cos(tilt)]]).T
    corners = np.concatenate([square + [-0.6, 0.6, 5.0], turned + [0.8, 0.4, 5.6]])
    uv = np.tile(np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float), (2, 1))  # north edge at the image's top
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return corners, uv, faces


def _trunk() -> tuple[np.ndarray, np.ndarray]:
    """A box 0.3 x 0.3 m from the ground to 4 m at (2.6, 1.0), its faces wound outwards."""
    low, high = np.array([2.45, 0.85, 0.0]), np.array([2.75, 1.15, 4.0])
    corners = np.array([[(high if i & m else low)[k] for k, m in enumerate((1, 2, 4))] for i in range(8)])
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return corners, faces


def _to_y_up(points: np.ndarray) -> np.ndarray:
    """World (x, y, z) to a Y-up file's (x, z, -y): glTF's +Y up, +Z the front (south)."""
    return np.column_stack([points[:, 0], points[:, 2], -points[:, 1]])


def _write_glb(path: Path, mode: str = "MASK", lift: float = 1.0) -> None:
    """A binary glTF: the leaf cards (``mode``, cutoff 0.5) and the trunk (opaque), under a node lifted
    ``lift`` metres (glTF +Y)."""
    leaf_points, uv, leaf_faces = _leaves()
    trunk_points, trunk_faces = _trunk()
    leaf_points, trunk_points = leaf_points - [0, 0, lift], trunk_points - [0, 0, lift]
    blobs = [_to_y_up(leaf_points).astype("<f4"), uv.astype("<f4"), leaf_faces.astype("<u4"),
             _to_y_up(trunk_points).astype("<f4"), trunk_faces.astype("<u4"), np.frombuffer(_png(), np.uint8)]
    views, data = [], b""
    for blob in blobs:
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": blob.nbytes})
        data += blob.tobytes() + b"\0" * (-blob.nbytes % 4)
    accessor = lambda view, kind, count, ctype=5126: {"bufferView": view, "componentType": ctype,  # noqa: E731
                                                       "count": count, "type": kind}
    accessors = [accessor(0, "VEC3", 8), accessor(1, "VEC2", 8), accessor(2, "SCALAR", 12, 5125),
                 accessor(3, "VEC3", 8), accessor(4, "SCALAR", 36, 5125)]
    accessors[0].update(min=_to_y_up(leaf_points).min(0).tolist(), max=_to_y_up(leaf_points).max(0).tolist())
    accessors[3].update(min=_to_y_up(trunk_points).min(0).tolist(), max=_to_y_up(trunk_points).max(0).tolist())
    document = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [0.0, lift, 0.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0},
                                   {"attributes": {"POSITION": 3}, "indices": 4, "material": 1}]}],
        "materials": [{"name": "leaf", "alphaMode": mode, "alphaCutoff": 0.5, "doubleSided": True,
                       "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}},
                      {"name": "bark", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.2, 0.1, 1.0]}}],
        "textures": [{"source": 0}], "images": [{"bufferView": 5, "mimeType": "image/png"}],
        "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(data)}],
    }
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(data), 0x004E4942) + data
    path.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)


def _write_obj(folder: Path, texture: str = "leaf.png", extra: str = "") -> Path:
    """An OBJ + MTL of the same tree (Y-up, v up from the image's bottom), the leaves' texture blended."""
    (folder / "leaf.png").write_bytes(_png())
    (folder / "tree.mtl").write_text(f"newmtl leaf\nKd 0.2 0.6 0.2\nmap_Kd {texture}\n\nnewmtl bark\nKd 0.3 0.2 0.1\n")
    leaf_points, uv, leaf_faces = _leaves()
    trunk_points, trunk_faces = _trunk()
    lines = ["mtllib tree.mtl"]
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in _to_y_up(np.concatenate([leaf_points, trunk_points]))]
    lines += [f"vt {u:.17g} {1 - v:.17g}" for u, v in uv]
    lines += ["usemtl leaf"] + [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in leaf_faces]
    lines += ["usemtl bark"] + [f"f {a + 9} {b + 9} {c + 9}" for a, b, c in trunk_faces]
    path = folder / "tree.obj"
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def _write_ply(path: Path, points: np.ndarray, faces: np.ndarray) -> None:
    """An ASCII PLY (Z-up) of plain triangles."""
    head = ["ply", "format ascii 1.0", f"element vertex {len(points)}", "property float x", "property float y",
            "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    body = [" ".join(f"{c:.17g}" for c in p) for p in points] + [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(head + body) + "\n")


def _reference(mode: str, samples: int = 32) -> np.ndarray:
    """Transmittance on GRID, independently: samples x samples points a pixel, each in or out of every
    triangle (barycentric), a leaf's alpha looked up at its point (nearest texel; at the cutoff for
    MASK, as it is for blending); the sample's transmittance the product over what covers it."""
    rows, cols = GRID.shape
    offsets = (np.arange(samples) + 0.5) / samples
    sx = GRID.origin[0] + (np.arange(cols)[:, None] + offsets[None, :]).reshape(-1) * GRID.pixel
    sy = GRID.origin[1] - (np.arange(rows)[:, None] + offsets[None, :]).reshape(-1) * GRID.pixel
    light = np.ones((len(sy), len(sx)))
    alpha = _alpha() / 255.0
    alpha = (alpha >= 0.5).astype(float) if mode == "MASK" else alpha
    leaf_points, uv, leaf_faces = _leaves()
    trunk_points, trunk_faces = _trunk()
    for points, faces, leafy in ((leaf_points, leaf_faces, True), (trunk_points, trunk_faces, False)):
        flat = points[:, :2] - (points[:, 2:3] - PLANE) * np.asarray(SUN)
        for face in faces:
            (x0, y0), (x1, y1), (x2, y2) = flat[face]
            det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
            if abs(det) < 1e-14:
                continue
            box = (slice(np.searchsorted(-sy, -max(y0, y1, y2)), np.searchsorted(-sy, -min(y0, y1, y2))),
                   slice(np.searchsorted(sx, min(x0, x1, x2)), np.searchsorted(sx, max(x0, x1, x2))))
            px, py = np.meshgrid(sx[box[1]], sy[box[0]])
            seen = light[box]
            b1 = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / det
            b2 = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / det
            inside = (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1)
            if not leafy:
                seen[inside] = 0.0
                continue
            u = uv[face[0], 0] + b1 * (uv[face[1], 0] - uv[face[0], 0]) + b2 * (uv[face[2], 0] - uv[face[0], 0])
            v = uv[face[0], 1] + b1 * (uv[face[1], 1] - uv[face[0], 1]) + b2 * (uv[face[2], 1] - uv[face[0], 1])
            texel = alpha[np.clip((v * TEXTURE).astype(int), 0, TEXTURE - 1),
                          np.clip((u * TEXTURE).astype(int), 0, TEXTURE - 1)]
            seen[inside] *= 1.0 - texel[inside]
    return light.reshape(rows, samples, cols, samples).mean(axis=(1, 3))


@pytest.mark.parametrize("mode", ["MASK", "BLEND"])
def test_glb_coverage_against_point_samples(tmp_path, mode):
    """A glTF's mask against 1024 point samples a pixel: within 0.5 % RMS of the open fraction."""
    _write_glb(tmp_path / "tree.glb", mode)
    mesh = read_mesh(MeshParams(tmp_path / "tree.glb"))
    assert [m.name for m in mesh.materials] == ["leaf", "bark"] and mesh.leaf.sum() == 4
    mask = mesh_mask(mesh, sun=SUN, plane_height=PLANE, grid=GRID)
    reference = _reference(mode)
    assert reference.min() == 0.0 and (reference < 0.99).mean() > 0.1  # the window holds the shadows
    assert np.sqrt(np.mean((mask - reference) ** 2)) < 0.005


def test_obj_blended_coverage_and_leaf_area(tmp_path):
    """An OBJ + MTL (its texture's alpha blended) against the point samples; its leaves' alpha-weighted
    area, and their shadow under a high sun, within 0.5 % of the texture's own."""
    mesh = read_mesh(MeshParams(_write_obj(tmp_path)))
    assert {m.name: m.mode for m in mesh.materials} == {"leaf": "blend", "bark": "opaque"}
    mask = mesh_mask(mesh, sun=SUN, plane_height=PLANE, grid=GRID)
    assert np.sqrt(np.mean((mask - _reference("BLEND")) ** 2)) < 0.005
    own = (_alpha() / 255.0).mean() * SIDE**2  # each card's area times its texture's mean alpha
    assert alpha_weighted_area(mesh) == pytest.approx(2 * own, rel=0.005)
    shadow = mesh_mask(mesh, sun=(0.0, 0.0), plane_height=PLANE, grid=GRID, select=mesh.leaf)
    projected = own * (1 + np.cos(np.radians(30.0)))
    assert np.sum(1.0 - shadow.astype(np.float64)) * GRID.pixel**2 == pytest.approx(projected, rel=0.005)


def test_alpha_masked_outline_keeps_the_leaf_area(tmp_path):
    """An alpha-masked leaf is drawn by its alpha's outline (docs/method.md, "Trees from mesh files"): under a
    high sun its cards' shadow is the texture's own covered area to 1e-6, at every outline level; each card is
    the sum of its two triangles drawn alone (clipped to the card, its diagonal is not drawn)."""
    _write_glb(tmp_path / "tree.glb", "MASK")
    mesh = read_mesh(MeshParams(tmp_path / "tree.glb"))
    own = (_alpha() >= 128).mean() * SIDE**2
    projected = own * (1 + np.cos(np.radians(30.0)))
    for pixel in (0.05, 0.01, 0.2):  # 16, 3.2 and 64 texels a pixel: different outline levels
        grid = Grid(GRID.origin, pixel, (int(36 * 0.05 / pixel), int(100 * 0.05 / pixel)))
        shadow = mesh_mask(mesh, sun=(0.0, 0.0), plane_height=PLANE, grid=grid, select=mesh.leaf)
        assert np.sum(1.0 - shadow.astype(np.float64)) * pixel**2 == pytest.approx(projected, rel=1e-6)
    together = mesh_mask(mesh, sun=SUN, plane_height=PLANE, grid=GRID, select=mesh.leaf).astype(np.float64)
    alone = [mesh_mask(mesh, sun=SUN, plane_height=PLANE, grid=GRID, select=np.arange(len(mesh.leaf)) == t)
             for t in np.flatnonzero(mesh.leaf)]  # (the two cards' shadows do not meet)
    assert (together < 0.5).any() and np.allclose(1.0 - together, sum(1.0 - m.astype(np.float64) for m in alone),
                                                   atol=2e-6)


def test_placed_and_layered(tmp_path):
    """Scale, turn and position move the file's origin as asked; the glTF node's lift and Y-up are
    converted; each leaf falls whole into its nearest layer, the trunk by its triangles."""
    _write_glb(tmp_path / "tree.glb")
    leaf_points = _leaves()[0]
    mesh = read_mesh(MeshParams(tmp_path / "tree.glb", scale=2.0, rotation=np.pi / 2, position=(10.0, 0.0, 1.0)))
    expected = np.column_stack([-2 * leaf_points[:, 1] + 10.0, 2 * leaf_points[:, 0], 2 * leaf_points[:, 2] + 1.0])
    got = mesh.vertices[np.unique(mesh.triangles[mesh.leaf])]
    assert np.allclose(np.sort(got, axis=0), np.sort(expected, axis=0), atol=1e-5)
    layer = mesh_layer_index(read_mesh(MeshParams(tmp_path / "tree.glb")), [2.0, 4.9, 5.3])
    leaf = read_mesh(MeshParams(tmp_path / "tree.glb")).leaf
    assert list(layer[leaf]) == [1, 1, 2, 2] and set(layer[~leaf]) == {0, 1}


def test_ply_leaves_named_and_skipped_triangles(tmp_path):
    """A PLY (Z-up) of bare triangles: leaves only when named; a zero-area triangle skipped and counted;
    an opaque leaf triangle's shadow is its exact area."""
    points = np.array([[0, 0, 5], [0.5, 0, 5], [0, 0.5, 5], [1, 1, 5], [1, 1, 5], [1, 1, 5]], float)
    _write_ply(tmp_path / "leaf.ply", points, np.array([[0, 1, 2], [3, 4, 5]]))
    with pytest.raises(ImageError, match=r"leaf\.ply: no leaves found"):
        read_mesh(MeshParams(tmp_path / "leaf.ply"))
    with pytest.raises(ImageError, match=r"leaf\.ply: no material named 'leaf'; the file's materials: material_0"):
        read_mesh(MeshParams(tmp_path / "leaf.ply", leaves=("leaf",)))
    mesh = read_mesh(MeshParams(tmp_path / "leaf.ply", leaves=("material_0",)))
    assert mesh.skipped == 1 and len(mesh.triangles) == 1
    mask = mesh_mask(mesh, sun=(0.0, 0.0), plane_height=5.0, grid=Grid((-0.1, 0.6), 0.03, (30, 30)))
    assert np.sum(1.0 - mask.astype(np.float64)) * 0.03**2 == pytest.approx(0.125, rel=1e-6)


def test_bad_mesh_files(tmp_path):
    """Each bad file is one line naming it."""
    (tmp_path / "junk.glb").write_bytes(b"not a mesh at all")
    cases = [(tmp_path / "junk.glb", "junk.glb: not a"), (tmp_path / "none.obj", "none.obj: no such mesh file")]
    missing = tmp_path / "missing"
    missing.mkdir()
    cases.append((_write_obj(missing, texture="gone.png"), "tree.obj: texture gone.png is missing"))
    nan = tmp_path / "nan"
    nan.mkdir()
    cases.append((_write_obj(nan, extra="v nan 0 0\nv 0 1 0\nv 0 0 1\nf 17 18 19\n"), "tree.obj: 1 vertices are not"))
    (tmp_path / "tree.stl").write_text("solid x\nendsolid x\n")
    cases.append((tmp_path / "tree.stl", "tree.stl: not a mesh file"))
    for path, message in cases:
        with pytest.raises(ImageError, match=message) as caught:
            read_mesh(MeshParams(path))
        assert "\n" not in str(caught.value)
