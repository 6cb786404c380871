"""Mesh trees in a config (``canopy.mesh``): their flutter, cache keys, ``check`` and ``mask``, bad input, and the
round trip of a procedural tree through a glTF file (docs/method.md, "Trees from mesh files")."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from mesh_export import mesh_twin, write_grove_gltf
from scenes import config_of, plan_of, tiny_grove

from pipeline.api import functions as api
from pipeline.canopy import grove, mesh_layers, rasteriser
from pipeline.canopy.mesh import MeshParams, read_mesh
from pipeline.canopy.mesh_coverage import mesh_mask
from pipeline.canopy.mesh_flutter import leaf_motion, mesh_at
from pipeline.cli.main import main
from pipeline.core import io
from pipeline.core.errors import ConfigError
from pipeline.core.geometry import Grid
from pipeline.core.mesh_files import mesh_files
from pipeline.stages.cycle import cycle_params, layer_masks

FLUTTER = grove.FlutterParams(cycle=48, swing=np.radians(12.0), twist=np.radians(20.0))


def _small_tree(folder: Path, leaves: int = 12) -> Path:
    """A procedural tree of a few leaves written as tree.glb in ``folder``."""
    tree = grove.grow_grove(grove.GroveParams(count=1, seed=5, crown_radius=1.0, leaves_per_tree=leaves,
                                              leaf_length=0.3, leaves_per_cluster=1, height=3.0))
    path = folder / "tree.glb"
    write_grove_gltf(path, tree.leaves, tree.wood, sections=8)
    return path


def _areas(mesh) -> np.ndarray:
    """Each triangle's area [m^2]."""
    c = mesh.vertices[mesh.triangles]
    return 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)


def _mesh_config(folder: Path, **mesh) -> dict:
    """The tiny grove's scene with tree.glb for its trees, on a 6 x 6 m mask area."""
    config = tiny_grove()
    del config["canopy"]["trees"]
    config["canopy"].update(mesh={"file": "tree.glb", **mesh}, size=[6.0, 6.0])
    return config


def _write(folder: Path, config: dict) -> Path:
    path = folder / "tree.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def test_the_config_reads_mesh_trees(tmp_path):
    """One mapping or a list; degrees to radians; refused beside trees or masks, periodic, over the limit."""
    _small_tree(tmp_path)
    config = config_of(_mesh_config(tmp_path, scale=2.0, rotation=90.0, position=[1.0, -2.0], leaves=["leaf"]),
                       tmp_path)
    (mesh,) = config.canopy.meshes
    assert mesh.file == tmp_path / "tree.glb" and mesh.scale == 2.0 and mesh.position == (1.0, -2.0)
    assert mesh.rotation == pytest.approx(np.pi / 2) and mesh.leaves == ("leaf",) and mesh.seed == 7
    assert config.canopy.trees is None and config.canopy.cycle == 3 and config.foreground.model == "none"
    listed = _mesh_config(tmp_path)
    listed["canopy"]["mesh"] = [{"file": "tree.glb"}, {"file": "tree.glb", "position": [2.0, 0.0]}]
    assert len(config_of(listed, tmp_path).canopy.meshes) == 2
    for key, value, message in [("trees", {"count": 1}, "canopy.mesh: mesh trees beside procedural trees"),
                                ("layout", "periodic", "canopy.mesh: mesh trees stand in an isolated canopy"),
                                ("mesh", {"file": "tree.glb", "max_triangles": 10**7}, "must be at most"),
                                ("mesh", {"file": "tree.glb", "colour": 1}, "canopy.mesh.colour: unknown key"),
                                ("receivers", {"slope": {"tilt": 10.0, "facing": 180.0}},
                                 "canopy.mesh: mesh trees shade the level ground alone")]:
        bad = _mesh_config(tmp_path)
        (bad if key == "receivers" else bad["canopy"])[key] = value
        with pytest.raises(ConfigError, match=message):
            config_of(bad, tmp_path)


def test_flutter_keeps_each_leaf_its_area_and_attachment(tmp_path):
    """Every leaf turns rigidly about its pivot (its corner nearest the wood near it): each leaf's
    area and its pivot stay, the wood stays, the leaves move, the cycle closes, the seed fixes the bytes."""
    mesh = read_mesh(MeshParams(_small_tree(tmp_path)))
    motion = leaf_motion(mesh, seed=7)
    leaf = mesh.leaf
    corners = mesh.vertices[mesh.triangles]
    groups = int(mesh.group[leaf].max()) + 1
    assert groups == 12 and len(motion.pivot) == 12
    pieces = corners[~leaf]  # the wood's corners, edge midpoints and centroids
    wood = np.concatenate([pieces.reshape(-1, 3), (0.5 * (pieces + pieces[:, [1, 2, 0]])).reshape(-1, 3),
                           pieces.mean(axis=1)])
    for g in range(groups):  # the pivot: the leaf's corner nearest the wood nearest its middle (brute force)
        points = mesh.vertices[np.unique(mesh.triangles[leaf & (mesh.group == g)])]
        anchor = wood[np.argmin(np.linalg.norm(wood - points.mean(axis=0), axis=1))]
        np.testing.assert_array_equal(motion.pivot[g], points[np.argmin(np.linalg.norm(points - anchor, axis=1))])
    rest = np.bincount(mesh.group[leaf], _areas(mesh)[leaf])
    for frame in (0, 7, 30):
        moved = mesh_at(mesh, motion, FLUTTER, frame)
        after = moved.vertices[moved.triangles]
        np.testing.assert_allclose(np.bincount(moved.group[leaf], _areas(moved)[leaf]), rest, rtol=1e-12)
        np.testing.assert_array_equal(after[~leaf], corners[~leaf])
        for g in range(groups):  # the pivot's corner stays where it was
            at = np.linalg.norm(corners[leaf & (mesh.group == g)] - motion.pivot[g], axis=2) == 0.0
            np.testing.assert_allclose(after[leaf & (mesh.group == g)][at], np.broadcast_to(motion.pivot[g],
                                       (at.sum(), 3)), atol=1e-12)
        assert np.abs(after[leaf] - corners[leaf]).max() > 0.01
    np.testing.assert_array_equal(mesh_at(mesh, motion, FLUTTER, 5).vertices,
                                  mesh_at(mesh, motion, FLUTTER, 53).vertices)
    again = mesh_at(mesh, leaf_motion(read_mesh(MeshParams(tmp_path / "tree.glb")), seed=7), FLUTTER, 5)
    assert again.vertices.tobytes() == mesh_at(mesh, motion, FLUTTER, 5).vertices.tobytes()
    other = mesh_at(mesh, leaf_motion(mesh, seed=8), FLUTTER, 5)
    assert other.vertices.tobytes() != again.vertices.tobytes()


def test_a_leaf_without_wood_pivots_at_its_end(tmp_path):
    """Without wood a leaf pivots at the end of its long axis nearer the tree's middle."""
    points = np.array([[1.0, 0, 5], [1.6, 0, 5], [1.6, 0.2, 5], [1.0, 0.2, 5],
                       [-1.0, 0, 5], [-1.6, 0, 5], [-1.6, 0.2, 5], [-1.0, 0.2, 5]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]])
    head = ["ply", "format ascii 1.0", f"element vertex {len(points)}", "property float x", "property float y",
            "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    body = [" ".join(f"{c:g}" for c in p) for p in points] + [f"3 {a} {b} {c}" for a, b, c in faces]
    (tmp_path / "cards.ply").write_text("\n".join(head + body) + "\n")
    mesh = read_mesh(MeshParams(tmp_path / "cards.ply", leaves=("material_0",)))
    motion = leaf_motion(mesh, seed=1)
    assert sorted(np.abs(motion.pivot[:, 0]).tolist()) == [1.0, 1.0]
    assert np.allclose(np.abs(motion.length_axis[:, 0]), 1.0) and np.allclose(motion.swing_axis[:, 2], 0.0)


def test_cycle_masks_keys_check_and_mask(tmp_path, capsys):
    """A mesh tree's layer masks come out of the cycle stage, fluttering, keyed on the file's content; ``check``
    prints its figures, ``mask`` writes its mask."""
    content = _small_tree(tmp_path).read_bytes()
    config = _mesh_config(tmp_path)
    plan = plan_of(config, tmp_path)
    masks = layer_masks(plan, 0, 1)
    assert masks.coarse.min() < 0.5 and masks.coarse.max() == 1.0
    assert not np.array_equal(layer_masks(plan, 0, 2).coarse, masks.coarse)  # the leaves flutter
    key = cycle_params(plan, 0, 1)
    (tmp_path / "tree.glb").write_bytes(content + b"\0" * 4)  # its content changes
    assert cycle_params(plan, 0, 1)["source"] != key["source"]
    (tmp_path / "tree.glb").write_bytes(content)
    path = _write(tmp_path, config)
    assert main(["check", str(path)]) == 0
    said = capsys.readouterr()
    assert "mesh tree.glb: " in said.out and "12 leaves of 24 triangles" in said.out
    assert "triangles per layer: " in said.out and " at 4 m" in said.out
    out = tmp_path / "mask.exr"
    assert main(["mask", str(path), "--frame", "1", "-o", str(out)]) == 0
    np.testing.assert_array_equal(io.read_image(out)[..., 0], masks.coarse)


def test_the_files_a_mesh_reads_are_in_its_key(tmp_path):
    """An OBJ's content hash covers its material library and the textures it names, each once."""
    Image = pytest.importorskip("PIL.Image")
    Image.new("RGBA", (4, 4)).save(tmp_path / "leaf.png")
    (tmp_path / "tree.mtl").write_text("newmtl leaf\nmap_Kd leaf.png\nmap_d -clamp on leaf.png\n")
    (tmp_path / "tree.obj").write_text("mtllib tree.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl leaf\nf 1 2 3\n")
    assert mesh_files(tmp_path / "tree.obj") == [tmp_path / "tree.obj", tmp_path / "tree.mtl", tmp_path / "leaf.png"]


def test_bad_mesh_trees_are_one_line_naming_the_file(tmp_path, capsys, monkeypatch):
    """``check`` refuses, one line naming the file, writing nothing: not a mesh, a missing texture, vertices not
    finite, no leaves, over the triangle limit, a shadow beyond the masks, over the memory limit."""
    _small_tree(tmp_path)
    (tmp_path / "junk.glb").write_bytes(b"no mesh here")
    (tmp_path / "opaque.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                         "property float y\nproperty float z\nelement face 1\n"
                                         "property list uchar int vertex_indices\nend_header\n0 0 3\n1 0 3\n0 1 3\n"
                                         "3 0 1 2\n")
    (tmp_path / "tree.mtl").write_text("newmtl leaf\nmap_Kd gone.png\n")
    obj = "mtllib tree.mtl\nv 0 0 3\nv 1 0 3\nv 0 {} 3\nusemtl leaf\nf 1 2 3\n"
    (tmp_path / "gone.obj").write_text(obj.format(1))
    (tmp_path / "nan.obj").write_text(obj.format("nan").replace("mtllib tree.mtl\n", ""))
    cases = [({"file": "junk.glb"}, {}, "junk.glb: not a glTF file"),
             ({"file": "gone.obj"}, {}, "gone.obj: texture gone.png is missing"),
             ({"file": "nan.obj"}, {}, "nan.obj: 1 vertices are not finite numbers"),
             ({"file": "opaque.ply"}, {}, "opaque.ply: no leaves found"),
             ({"max_triangles": 100}, {}, "tree.glb: .* triangles, over the limit of 100"),
             ({}, {"size": [2.0, 2.0]}, "tree.glb: its shadow on the plane at 4 m reaches")]
    for mesh, canopy, message in cases:
        config = _mesh_config(tmp_path, **mesh)
        config["canopy"].update(canopy)
        config["output"] = {"folder": str(tmp_path / "out")}
        assert main(["check", str(_write(tmp_path, config))]) == 2
        said = capsys.readouterr().err.strip()
        assert len(said.splitlines()) == 1 and re.search(message, said), said
    monkeypatch.setattr(mesh_layers, "MAX_MESH_BYTES", 1e5)  # the limit lowered, not the estimate
    assert main(["check", str(_write(tmp_path, _mesh_config(tmp_path)))]) == 2
    assert re.search(r"tree.glb: the mesh trees' layers would take about 0.0\d+ GB a worker; the most is 0.0001 GB",
                     capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


def test_a_procedural_tree_through_gltf_renders_the_same_ground(tmp_path):
    """The round trip: the tiny grove's tree, at rest, written as a glTF (cards with an elliptical alpha, capsules
    of wood, the trunk's foot cut flat at the ground) and read back, lights the ground within 1 % RMS of the tree
    itself under a sun at the zenith and 55 degrees up; under the oblique sun its leaves' mask is within 0.5 % RMS
    of the grove's (geometry, alpha and axes)."""
    for elevation in (90.0, 55.0):
        procedural = tiny_grove(**{"canopy.flutter.swing": 0.0, "canopy.flutter.twist": 0.0,
                                   "sky.sun.elevation": elevation})
        tree, meshed = mesh_twin(procedural, tmp_path)
        want = api.ground_irradiance(config_of(procedural, tmp_path), 0, cache=tmp_path / "cache", threads=1)
        got = api.ground_irradiance(config_of(meshed, tmp_path), 0, cache=tmp_path / "cache", threads=1)
        assert got.extent == want.extent and want.irradiance.min() < 0.5 * want.irradiance.max()
        error = np.sqrt(np.mean((got.irradiance - want.irradiance) ** 2)) / np.mean(want.irradiance)
        assert 0 < error < 0.01, elevation
    sun, grid = (0.35, -0.61), Grid((-2.5, 2.5), 0.04, (125, 125))  # 55 degrees up, from the south-south-east
    mesh = read_mesh(MeshParams(tmp_path / "tree.glb"))
    leaves = grove.project(tree.leaves, sun=sun, plane_height=4.0)
    reference = rasteriser.rasterize_transmittance(leaves, grid)
    drawn = mesh_mask(mesh, sun=sun, plane_height=4.0, grid=grid, select=mesh.leaf)
    assert reference.min() < 0.2 and np.sqrt(np.mean((drawn - reference) ** 2)) < 0.005


def test_a_resumed_run_renders_again_when_a_texture_changes(tmp_path, capsys):
    """The config's hash holds every file the mesh reads: a run resumed after its OBJ's leaf texture changed
    renders its frames again (their shadow changes), and one resumed with nothing changed renders none."""
    Image = pytest.importorskip("PIL.Image")
    rgba = np.zeros((8, 8, 4), np.uint8)
    rgba[:, :4, 3] = 255  # the card's west half covers
    Image.fromarray(rgba, "RGBA").save(tmp_path / "leaf.png")
    (tmp_path / "tree.mtl").write_text("newmtl leaf\nmap_Kd leaf.png\n")
    (tmp_path / "tree.obj").write_text("mtllib tree.mtl\nv -0.5 3 0.5\nv 0.5 3 0.5\nv 0.5 3 -0.5\nv -0.5 3 -0.5\n"
                                       "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl leaf\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    config = _mesh_config(tmp_path, file="tree.obj")
    config["canopy"].update(size=[5.0, 5.0], height=3.0)
    config["ground"] = {"window": [-1.5, -1.5, 1.5, 1.5], "pixel": 0.1, "sun_window": [-0.5, -0.5, 0.5, 0.5],
                        "sun_pixel": 0.05}
    config["animation"] = {"frames": 1}
    config["output"] = {"folder": str(tmp_path / "run"), "video": "none"}
    path = _write(tmp_path, config)
    render = ["render", str(path), "--cache", str(tmp_path / "cache"), "--jobs", "1"]
    assert main(render) == 0
    first = (tmp_path / "run" / "tree.0000.exr").read_bytes()
    assert main(render) == 0
    assert "0 frames rendered, 1 already done" in capsys.readouterr().out, "nothing changed: nothing rendered"
    rgba[:, :4, 3], rgba[:, 4:, 3] = 0, 255  # now its east half
    Image.fromarray(rgba, "RGBA").save(tmp_path / "leaf.png")
    assert main(render) == 0
    assert "1 frame rendered, 0 already done" in capsys.readouterr().out
    assert (tmp_path / "run" / "tree.0000.exr").read_bytes() != first


def test_a_tree_file_rewritten_in_the_same_process_is_read_again(tmp_path):
    """A process keeps a tree it has read only while its file stays as it was: a tree written again at the same
    path (another grove's) is the new tree, as a fresh process reads it."""
    kept = []
    for leaves in (400, 120):
        mesh_twin(tiny_grove(**{"canopy.trees.leaves_per_tree": leaves}), tmp_path)
        kept.append(mesh_layers.mesh_tree(MeshParams(tmp_path / "tree.glb"), seed=0))
        assert kept[-1].mesh.triangles.shape[0] == read_mesh(MeshParams(tmp_path / "tree.glb")).triangles.shape[0]
    assert kept[0].mesh.triangles.shape[0] != kept[1].mesh.triangles.shape[0]
