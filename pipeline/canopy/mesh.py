"""Tree meshes read from glTF 2.0, OBJ + MTL and PLY files: triangles in metres on the ground, leaves and wood.

``read_mesh`` reads a file with trimesh (imported on first use), converts its axes, scales,
turns and places it (``MeshParams``), sorts its materials into leaves and wood and keeps each leaf
material's alpha as a coverage table; ``mesh_coverage.py`` draws it into a layer's mask
(docs/method.md, "Trees from mesh files").
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.core.errors import ImageError
from pipeline.core.mesh_files import MESH_FORMATS, obj_libraries

__all__ = ["FORMAT_UP", "GLTF_ALPHA_CUTOFF", "MeshParams", "MeshMaterial", "TreeMesh", "read_mesh",
           "leaf_groups"]

FORMAT_UP = {"gltf": "y", "obj": "y", "ply": "z"}
"""Each format's up axis: glTF's by its specification (+Y up, +Z the asset's front); OBJ's as Blender's, Maya's
and most exporters write it (the format names none); PLY's as scanners and Blender's PLY exporter write it."""

GLTF_ALPHA_CUTOFF = 0.5
"""glTF 2.0's default ``alphaCutoff`` for ``alphaMode: MASK`` [1]."""


@dataclass(frozen=True)
class MeshParams:
    """A tree mesh file and where it stands.

    Attributes
    ----------
    path : pathlib.Path
        The file: .glb, .gltf, .obj (with its .mtl) or .ply.
    scale : float
        Metres per file unit [m].
    position : tuple of 3 float
        Where the file's origin stands: (x east, y north, z up) [m].
    rotation : float
        Turn about the vertical, anticlockwise seen from above (east towards north) [rad].
    up : str or None
        The file's up axis, "y" or "z"; None for the format's own (``FORMAT_UP``).
    leaves : tuple of str or None
        Names of the leaf materials; None finds them (alpha-masked or blended, or an alpha texture).
    wood : tuple of str
        Names of materials that are wood whatever their alpha.
    max_triangles : int or None
        The most triangles the file may hold (zero-area ones counted); None for no limit.
    """

    path: Path
    scale: float = 1.0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: float = 0.0
    up: str | None = None
    leaves: tuple[str, ...] | None = None
    wood: tuple[str, ...] = ()
    max_triangles: int | None = None


@dataclass(frozen=True)
class MeshMaterial:
    """One material of a tree mesh, as its shadow needs it.

    Attributes
    ----------
    name : str
        The material's name in the file.
    leaf : bool
        Whether it is leaves (else wood, opaque).
    mode : str
        "opaque" (wood, or leaves without alpha), "mask" (alpha at a cutoff) or "blend" (alpha as it is).
    coverage : numpy.ndarray
        (rows, cols) float32 in [0, 1]: the coverage of each texel of its texture, row 0 at the top of
        the image (v = 1), its alpha (times the material's own) at the cutoff for "mask"; (1, 1) without
        a texture [1].
    cutoff : float or None
        The alpha cutoff of "mask" [1].
    """

    name: str
    leaf: bool
    mode: str
    coverage: np.ndarray
    cutoff: float | None = None


@dataclass(frozen=True)
class TreeMesh:
    """A tree mesh on the ground, in metres.

    Attributes
    ----------
    vertices : numpy.ndarray
        (n, 3) float64 (x east, y north, z up) [m].
    triangles : numpy.ndarray
        (m, 3) int64 vertex indices, zero-area triangles left out.
    uv : numpy.ndarray
        (m, 3, 2) float64 texture coordinates of each corner (u to the right, v up: v = 1 is the top
        row of the image) [1].
    material : numpy.ndarray
        (m,) int64 index into ``materials``.
    materials : tuple of MeshMaterial
        The materials.
    group : numpy.ndarray
        (m,) int64: triangles joined by shared corners (by position) form a group; leaf groups are the
        leaves, numbered first, then the groups of wood.
    skipped : int
        Zero-area triangles left out [count].
    path : pathlib.Path
        The file.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray
    material: np.ndarray
    materials: tuple[MeshMaterial, ...]
    group: np.ndarray
    skipped: int
    path: Path

    @property
    def leaf(self) -> np.ndarray:
        """(m,) bool: which triangles are leaves."""
        return np.array([m.leaf for m in self.materials], dtype=bool)[self.material]


def read_mesh(params: MeshParams) -> TreeMesh:
    """Read a tree mesh file, its axes converted, scaled, turned and placed.

    Parameters
    ----------
    params : MeshParams
        The file, its scale [m per unit], position [m], rotation [rad], up axis and materials.

    Returns
    -------
    TreeMesh
        The tree in metres, its materials sorted into leaves and wood.

    Raises
    ------
    ImageError
        One line naming the file: not a mesh, a missing or unreadable texture, vertices that are not
        finite, no leaves found, an unknown material name, more triangles than ``max_triangles``.
    """
    path = Path(params.path)
    kind = MESH_FORMATS.get(path.suffix.lower())
    if kind is None:
        raise ImageError(path, f"not a mesh file: expected one of {', '.join(MESH_FORMATS)}")
    if not path.is_file():
        raise ImageError(path, "no such mesh file")
    up = params.up or FORMAT_UP[kind]
    if up not in ("y", "z"):
        raise ImageError(path, f"the up axis must be 'y' or 'z', not {up!r}")
    textures = _texture_files(path, kind)
    parts = _load_parts(path)
    count = sum(len(p[1]) for p in parts)
    if params.max_triangles is not None and count > params.max_triangles:
        raise ImageError(path, f"{count:,} triangles, over the limit of {params.max_triangles:,} (max_triangles)")
    vertices = np.concatenate([p[0] for p in parts])
    bad = int(np.count_nonzero(~np.isfinite(vertices).all(axis=1)))
    if bad:
        raise ImageError(path, f"{bad} vertices are not finite numbers (NaN or infinite)")
    offsets = np.cumsum([0] + [len(p[0]) for p in parts])
    triangles = np.concatenate([p[1] + offset for p, offset in zip(parts, offsets, strict=False)])
    uv = np.concatenate([p[2] for p in parts])
    names: list[str] = []
    materials: list[MeshMaterial] = []
    per_part: list[np.ndarray] = []
    for _, faces, _, source in parts:
        name = _material_name(source, len(names))
        if name not in names:
            names.append(name)
            materials.append(_material(path, source, name, textures, params))
        per_part.append(np.full(len(faces), names.index(name), dtype=np.int64))
    _check_names(path, params, names)
    if not any(m.leaf for m in materials):
        raise ImageError(path, "no leaves found: no material is alpha-masked or blended (glTF alphaMode MASK or "
                               "BLEND) or has an alpha texture (OBJ map_d or an alpha channel); name the leaf "
                               f"materials among: {', '.join(names)}")
    vertices = _placed(vertices, up, params)
    kept = _nonzero_area(vertices, triangles)
    if not np.isfinite(uv[kept]).all():
        raise ImageError(path, "texture coordinates that are not finite numbers (NaN or infinite)")
    triangles, uv, material = triangles[kept], uv[kept], np.concatenate(per_part)[kept]
    leaf = np.array([m.leaf for m in materials], dtype=bool)[material]
    return TreeMesh(vertices, triangles, np.nan_to_num(uv), material, tuple(materials),
                    leaf_groups(vertices, triangles, leaf), int(np.count_nonzero(~kept)), path)


def _load_parts(path: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, Any]]:
    """Each triangle mesh of the file's scene in the file's own axes: (vertices (n, 3), faces (m, 3),
    corner uv (m, 3, 2), trimesh material or None)."""
    import trimesh

    try:
        scene: Any = trimesh.load(str(path), force="scene", process=False)
        placed = [(scene.graph[node][0], scene.geometry[scene.graph[node][1]])
                  for node in scene.graph.nodes_geometry]
    except Exception as error:  # trimesh raises many kinds on files it cannot parse
        raise ImageError(path, f"not a mesh that trimesh can read ({type(error).__name__}: "
                               f"{str(error).splitlines()[0] if str(error) else 'no detail'})") from None
    parts = []
    for transform, geometry in placed:
        faces = np.asarray(getattr(geometry, "faces", np.zeros((0, 3))), dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            continue  # points, paths: no triangles
        points = np.asarray(geometry.vertices, dtype=np.float64)
        vertices = points @ np.asarray(transform)[:3, :3].T + np.asarray(transform)[:3, 3]
        visual = getattr(geometry, "visual", None)
        texture_uv = getattr(visual, "uv", None)
        if texture_uv is not None and len(texture_uv) == len(points):
            uv = np.asarray(texture_uv, dtype=np.float64)[faces]
        else:
            uv = np.zeros((len(faces), 3, 2))
        parts.append((vertices, faces, uv, getattr(visual, "material", None)))
    if not parts:
        raise ImageError(path, "holds no triangles")
    return parts


def _material_name(source: Any, index: int) -> str:
    """The material's name in the file, or 'material_<index>' for a nameless one."""
    name = getattr(source, "name", None)
    return str(name) if name else f"material_{index}"


def _check_names(path: Path, params: MeshParams, names: Sequence[str]) -> None:
    """ImageError for a leaf or wood material name the file does not hold."""
    for name in (*(params.leaves or ()), *params.wood):
        if name not in names:
            raise ImageError(path, f"no material named {name!r}; the file's materials: {', '.join(names)}")


def _material(path: Path, source: Any, name: str, textures: dict[str, dict[str, Any]],
              params: MeshParams) -> MeshMaterial:
    """A trimesh material sorted into leaves or wood, with its coverage table."""
    mode, cutoff, alpha = "opaque", None, None
    if hasattr(source, "alphaMode"):  # glTF's metallic-roughness material
        mode = {"MASK": "mask", "BLEND": "blend"}.get(str(source.alphaMode).upper(), "opaque")
        cutoff = GLTF_ALPHA_CUTOFF if source.alphaCutoff is None else float(source.alphaCutoff)
        factor = source.baseColorFactor
        alpha = _image_alpha(source.baseColorTexture)
        alpha = (1.0 if factor is None else float(np.asarray(factor)[3]) / 255.0) * \
            (np.ones((1, 1), np.float32) if alpha is None else alpha)
    elif source is not None:  # OBJ's MTL (or PLY's texture): alpha from map_d, the image's alpha, d
        alpha = _mtl_alpha(path, textures.get(name, {}), source)
        mode = "blend" if alpha is not None else "opaque"
    found = mode != "opaque"
    leaf = name not in params.wood and (found if params.leaves is None else name in params.leaves)
    if not leaf or alpha is None or mode == "opaque":
        return MeshMaterial(name, leaf, "opaque", np.ones((1, 1), np.float32))
    coverage = (alpha >= cutoff) if mode == "mask" else np.clip(alpha, 0.0, 1.0)
    return MeshMaterial(name, leaf, mode, np.ascontiguousarray(coverage, dtype=np.float32),
                        cutoff if mode == "mask" else None)


def _image_alpha(image: Any) -> np.ndarray | None:
    """A PIL image's alpha channel (rows, cols) float32 in [0, 1], or None without one."""
    if image is None:
        return None
    if image.mode == "P" and "transparency" in image.info:
        image = image.convert("RGBA")
    if "A" not in image.getbands():
        return None
    return np.asarray(image.getchannel("A"), dtype=np.float32) / 255.0


def _mtl_alpha(path: Path, entry: dict[str, Any], source: Any) -> np.ndarray | None:
    """An MTL material's alpha: its map_d (first channel), else its map_Kd's alpha channel, times d;
    None where all is opaque."""
    from PIL import Image

    alpha = None
    if "map_d" in entry:
        with Image.open(entry["map_d"]) as matte:
            alpha = np.asarray(matte.convert("L"), dtype=np.float32) / 255.0
    else:
        image = entry.get("map_Kd")
        if image is not None:
            with Image.open(image) as diffuse:
                alpha = _image_alpha(diffuse)
        else:
            alpha = _image_alpha(getattr(source, "image", None))
        if alpha is not None and float(alpha.min()) >= 1.0:
            alpha = None
    dissolve = float(entry.get("d", 1.0))
    if dissolve < 1.0:
        alpha = dissolve * (np.ones((1, 1), np.float32) if alpha is None else alpha)
    return alpha


def _placed(vertices: np.ndarray, up: str, params: MeshParams) -> np.ndarray:
    """File coordinates to the world's (x east, y north, z up) [m]: a Y-up file turned +90 degrees about x
    (its +Y up, its +Z, the front, to the south), scaled, turned about the vertical, moved."""
    points = vertices[:, [0, 2, 1]] * [1.0, -1.0, 1.0] if up == "y" else vertices
    c, s = np.cos(params.rotation), np.sin(params.rotation)
    points = params.scale * points
    turned = np.column_stack([c * points[:, 0] - s * points[:, 1], s * points[:, 0] + c * points[:, 1], points[:, 2]])
    return turned + np.asarray(params.position, dtype=np.float64)


def _nonzero_area(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(m,) bool: triangles whose area exceeds 1e-12 of the mesh's bounding box diagonal squared."""
    corners = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    diagonal = float(np.linalg.norm(np.ptp(vertices, axis=0))) if len(vertices) else 0.0
    return area > 1e-12 * diagonal**2


def leaf_groups(vertices: np.ndarray, triangles: np.ndarray, leaf: np.ndarray) -> np.ndarray:
    """Connected groups of triangles: leaves joined to leaves, wood to wood, by corners at the same position.

    Corners closer than 1e-9 of the bounding box diagonal count as one, so that a leaf card whose
    vertices are split at a texture seam stays one leaf.

    Parameters
    ----------
    vertices : numpy.ndarray
        (n, 3) [m].
    triangles : numpy.ndarray
        (m, 3) int vertex indices.
    leaf : numpy.ndarray
        (m,) bool.

    Returns
    -------
    numpy.ndarray
        (m,) int64 group of each triangle: the leaf groups 0 .. L - 1, then the wood groups.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    group = np.zeros(len(triangles), dtype=np.int64)
    if len(triangles) == 0:
        return group
    step = max(float(np.linalg.norm(np.ptp(vertices, axis=0))), 1e-300) * 1e-9
    _, same = np.unique(np.round((vertices - vertices.min(axis=0)) / step), axis=0, return_inverse=True)
    corners = same.reshape(-1)[triangles]
    offset = 0
    for kind in (leaf, ~leaf):
        chosen = corners[kind]
        if len(chosen) == 0:
            continue
        n = int(same.max()) + 1
        edges = coo_matrix((np.ones(2 * len(chosen)), (np.concatenate([chosen[:, 0], chosen[:, 1]]),
                                                        np.concatenate([chosen[:, 1], chosen[:, 2]]))), shape=(n, n))
        _, label = connected_components(edges, directed=False)
        _, number = np.unique(label[chosen[:, 0]], return_inverse=True)
        group[kind] = offset + number
        offset += int(number.max()) + 1
    return group


def _texture_files(path: Path, kind: str) -> dict[str, dict[str, Any]]:
    """The textures the file names, each checked to exist and decode (ImageError naming it otherwise):
    for OBJ each MTL material's {'map_Kd': Path, 'map_d': Path, 'd': float}; glTF's and PLY's are
    checked and not returned."""
    if kind == "obj":
        return _mtl_entries(path)
    if kind == "gltf":
        for name, data in _gltf_images(path):
            _check_image(path, name, data)
    if kind == "ply":
        for line in path.read_bytes()[:65536].split(b"end_header")[0].splitlines():
            words = line.decode("latin-1").split()
            if len(words) >= 3 and words[0] == "comment" and words[1].lower() == "texturefile":
                texture = path.parent / " ".join(words[2:])
                _check_image(path, str(texture), texture)
    return {}


def _check_image(path: Path, name: str, data: bytes | Path) -> None:
    """ImageError naming ``name`` (a texture of the mesh ``path``) if it is missing or does not decode."""
    import io

    from PIL import Image

    if isinstance(data, Path) and not data.is_file():
        raise ImageError(path, f"texture {name} is missing")
    try:
        with Image.open(data if isinstance(data, Path) else io.BytesIO(data)) as image:
            image.load()
    except Exception as error:  # Pillow raises several kinds on bad image data
        raise ImageError(path, f"texture {name} cannot be read ({type(error).__name__})") from None


def _mtl_entries(path: Path) -> dict[str, dict[str, Any]]:
    """Each material of the OBJ's MTL libraries: its map_Kd and map_d files (checked) and its d."""
    entries: dict[str, dict[str, Any]] = {}
    for library in obj_libraries(path):
        mtl = path.parent / library
        if not mtl.is_file():
            raise ImageError(path, f"material library {library} is missing")
        entry: dict[str, Any] = {}
        for line in mtl.read_text(errors="replace").splitlines():
            words = line.split()
            if not words:
                continue
            key = words[0].lower()
            if key == "newmtl":
                entry = entries.setdefault(" ".join(words[1:]), {})
            elif key in ("map_kd", "map_d") and len(words) > 1:
                texture = mtl.parent / words[-1]  # options (-clamp on, ...) come before the file name
                _check_image(path, words[-1], texture)
                entry["map_Kd" if key == "map_kd" else "map_d"] = texture
            elif key == "d" and len(words) > 1:
                entry["d"] = float(words[1])
            elif key == "tr" and len(words) > 1:
                entry["d"] = 1.0 - float(words[1])
    return entries


def _gltf_images(path: Path) -> list[tuple[str, bytes | Path]]:
    """The images a glTF file names: (name, encoded bytes or the file)."""
    raw = path.read_bytes()
    chunk = b""
    if raw[:4] == b"glTF":  # binary glTF: header, then the JSON chunk, then the binary one
        try:
            length = struct.unpack_from("<I", raw, 12)[0]
            document = json.loads(raw[20:20 + length])
            if len(raw) >= 28 + length:
                chunk_length = struct.unpack_from("<I", raw, 20 + length)[0]
                chunk = raw[28 + length:28 + length + chunk_length]
        except (struct.error, ValueError):
            raise ImageError(path, "not a glTF file: its JSON chunk cannot be read") from None
    else:
        try:
            document = json.loads(raw)
        except ValueError:
            raise ImageError(path, "not a glTF file: not JSON") from None
    images: list[tuple[str, bytes | Path]] = []
    for i, image in enumerate(document.get("images", []) if isinstance(document, dict) else []):
        name = str(image.get("name") or image.get("uri", f"image {i}"))[:200]
        uri = image.get("uri")
        if isinstance(uri, str) and uri.startswith("data:"):
            images.append((f"image {i}", base64.b64decode(uri.split(",", 1)[-1])))
        elif isinstance(uri, str):
            from urllib.parse import unquote

            images.append((uri, path.parent / unquote(uri)))
        elif "bufferView" in image:
            view = document["bufferViews"][image["bufferView"]]
            start = int(view.get("byteOffset", 0))
            data = _gltf_buffer(path, document["buffers"][int(view.get("buffer", 0))], chunk)
            images.append((name, data[start:start + int(view["byteLength"])]))
    return images


def _gltf_buffer(path: Path, buffer: dict[str, Any], chunk: bytes) -> bytes:
    """A glTF buffer's bytes: the binary chunk, a data URI or a file beside ``path``."""
    uri = buffer.get("uri")
    if not isinstance(uri, str):
        return chunk
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[-1])
    from urllib.parse import unquote

    file = path.parent / unquote(uri)
    if not file.is_file():
        raise ImageError(path, f"buffer {uri[:200]} is missing")
    return file.read_bytes()
