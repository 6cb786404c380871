"""The files a tree mesh reads: the mesh file's format by its ending, and the files it names.

``mesh_files`` lists them for the hashes that decide what is made again (the config's hash, the cycle
products' keys), so that a changed texture or material library is seen (docs/method.md, "Trees from mesh
files"). It only lists: ``canopy.mesh`` reads and checks the files, each error naming its file.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from urllib.parse import unquote

__all__ = ["MESH_FORMATS", "obj_libraries", "mesh_files"]

MESH_FORMATS = {".glb": "gltf", ".gltf": "gltf", ".obj": "obj", ".ply": "ply"}
"""The file name endings read, and their format."""


def obj_libraries(path: Path) -> list[str]:
    """The material libraries an OBJ names (``mtllib``), as written.

    Parameters
    ----------
    path : pathlib.Path
        The .obj file.

    Returns
    -------
    list of str
        The names, relative to the file's folder.
    """
    return [" ".join(line.split()[1:]) for line in Path(path).read_text(errors="replace").splitlines()
            if line.startswith("mtllib ")]


def mesh_files(path: Path) -> list[Path]:
    """The mesh file and every file it reads: OBJ's material libraries and their textures (``map_Kd``,
    ``map_d``), glTF's images and buffers beside it, PLY's texture (``comment TextureFile``).

    A file that cannot be read or parsed adds nothing more (reading the mesh reports it).

    Parameters
    ----------
    path : pathlib.Path
        The mesh file.

    Returns
    -------
    list of pathlib.Path
        The file first, then those it names that exist, each once.
    """
    path = Path(path)
    kind = MESH_FORMATS.get(path.suffix.lower())
    found = [path]
    try:
        if kind == "obj":
            for library in obj_libraries(path):
                mtl = path.parent / library
                found.append(mtl)
                if mtl.is_file():
                    found += [mtl.parent / words[-1] for words in map(str.split, mtl.read_text(errors="replace")
                                                                      .splitlines())
                              if len(words) > 1 and words[0].lower() in ("map_kd", "map_d")]
        elif kind == "gltf":
            document = _gltf_document(path.read_bytes())
            for entry in (*document.get("images", []), *document.get("buffers", [])):
                uri = entry.get("uri") if isinstance(entry, dict) else None
                if isinstance(uri, str) and not uri.startswith("data:"):
                    found.append(path.parent / unquote(uri))
        elif kind == "ply":
            for line in path.read_bytes()[:65536].split(b"end_header")[0].splitlines():
                words = line.decode("latin-1").split()
                if len(words) >= 3 and words[0] == "comment" and words[1].lower() == "texturefile":
                    found.append(path.parent / " ".join(words[2:]))
    except (OSError, ValueError, struct.error, AttributeError, TypeError):
        pass
    return list(dict.fromkeys(file for file in found if file.is_file()))


def _gltf_document(raw: bytes) -> dict:
    """A glTF's JSON: the whole file, or a binary glTF's JSON chunk (ValueError if neither)."""
    if raw[:4] == b"glTF":
        length = struct.unpack_from("<I", raw, 12)[0]
        raw = raw[20:20 + length]
    document = json.loads(raw)
    if not isinstance(document, dict):
        raise ValueError("not a glTF document")
    return document
