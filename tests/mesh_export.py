"""A procedural grove written as a glTF tree (for the round trip of tests/test_mesh_tree.py): each elliptical
leaf a card whose texture's alpha cuts the ellipse out (MASK), each wood capsule a closed capsule mesh of
32 x 32 sections (a group of its own: its sun-facing side covers its shadow once).

Written with trimesh (a test-only use: the reader, ``pipeline.canopy.mesh``, reads it back through its own
axes and materials)."""

import copy
from pathlib import Path

import numpy as np
from PIL import Image
from scenes import config_of

from pipeline.stages.inputs import grove_of

TEXTURE = 128
"""The leaf texture's side [texel]."""


def leaf_texture() -> Image.Image:
    """An RGBA leaf card image: the inscribed ellipse opaque, the rest clear; each texel by its centre."""
    t = (np.arange(TEXTURE) + 0.5) / TEXTURE * 2 - 1
    inside = (t[None, :] ** 2 + t[:, None] ** 2) <= 1.0
    rgba = np.zeros((TEXTURE, TEXTURE, 4), np.uint8)
    rgba[..., 1], rgba[..., 3] = 150, np.where(inside, 255, 0)
    return Image.fromarray(rgba, "RGBA")


def _y_up(points: np.ndarray) -> np.ndarray:
    """World (x east, y north, z up) to glTF's (x, y up, z south)."""
    return np.column_stack([points[:, 0], points[:, 2], -points[:, 1]])


def write_grove_gltf(path: Path, leaves, wood, sections: int = 32) -> None:
    """Write ``leaves`` (grove.Leaves) as alpha-masked cards and ``wood`` (grove.Wood) as capsules to a .glb.

    Parameters
    ----------
    path : Path
        The .glb written.
    leaves : grove.Leaves
        Centres and semi-axes [m].
    wood : grove.Wood
        Capsules [m].
    sections : int
        The capsules' sections about their axis and from pole to pole.
    """
    import trimesh
    from trimesh.visual.material import PBRMaterial
    from trimesh.visual.texture import TextureVisuals

    c, u, v = leaves.center, leaves.axis_u, leaves.axis_v
    corners = np.stack([c - u - v, c + u - v, c + u + v, c - u + v], axis=1).reshape(-1, 3)
    faces = (4 * np.arange(len(c))[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])[None]).reshape(-1, 3)
    uv = np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (len(c), 1))
    leaf_material = PBRMaterial(name="leaf", baseColorTexture=leaf_texture(), alphaMode="MASK", alphaCutoff=0.5,
                                doubleSided=True)
    card = trimesh.Trimesh(_y_up(corners), faces, process=False,
                           visual=TextureVisuals(uv=uv, material=leaf_material))
    pieces = []
    for a, b, r in zip(_y_up(wood.start), _y_up(wood.end), wood.radius):
        turn = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], b - a)
        turn[:3, 3] = 0.5 * (a + b)  # trimesh's capsule is centred on the origin
        piece = trimesh.creation.capsule(height=float(np.linalg.norm(b - a)), radius=float(r),
                                         count=[sections, sections], transform=turn)
        piece.vertices[:, 1] = np.maximum(piece.vertices[:, 1], 0.0)  # a trunk's foot is cut flat at the ground
        pieces.append(piece)
    bark = trimesh.util.concatenate(pieces)
    bark.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(name="bark", baseColorFactor=[90, 60, 40, 255]))
    scene = trimesh.Scene()
    scene.add_geometry(card, geom_name="leaves")
    scene.add_geometry(bark, geom_name="wood")
    Path(path).write_bytes(scene.export(file_type="glb"))


def mesh_twin(procedural: dict, folder: Path) -> tuple:
    """A config mapping with built-in trees (one tree) turned into its glTF twin: the grove's tree at rest
    written to ``folder``/tree.glb and drawn from it as ``canopy.mesh`` instead. Returns (the grove, the
    meshed mapping)."""
    tree, _ = grove_of(config_of(procedural, folder).canopy)
    write_grove_gltf(folder / "tree.glb", tree.leaves, tree.wood)
    meshed = copy.deepcopy(procedural)
    del meshed["canopy"]["trees"]
    meshed["canopy"].update(mesh={"file": "tree.glb"}, size=[6.0, 6.0])
    return tree, meshed
