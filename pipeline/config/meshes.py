"""The ``canopy.mesh`` key of a config: trees read from mesh files (docs/method.md, "Trees from mesh files").

Parsed with the errors of the rest of the config (the key named, nothing written); the files are read by
``pipeline.canopy.mesh``. Angles are degrees in the YAML and radians in the values.
"""

from __future__ import annotations

import math

from pipeline.config.sections import Section, kind_of
from pipeline.config.settings import MeshConfig

__all__ = ["MAX_MESH_TRIANGLES", "parse_meshes"]

MAX_MESH_TRIANGLES = 1_000_000
"""Most triangles of one mesh tree (``canopy.mesh[].max_triangles``, its default and its most). [count]"""


def parse_meshes(s: Section, layout: str, images: bool) -> tuple[MeshConfig, ...]:
    """``canopy.mesh``: one mapping or a list of them; refused beside trees or mask images and in a
    periodic layout (not built yet).

    Parameters
    ----------
    s : sections.Section
        The ``canopy`` section.
    layout : str
        The canopy's layout.
    images : bool
        Whether the canopy has mask images.

    Returns
    -------
    tuple of settings.MeshConfig
        The trees, in order; empty without the key.

    Raises
    ------
    ConfigError
        Naming the key.
    """
    if not s.has("mesh"):
        return ()
    for key, what in (("trees", "procedural trees"), ("mask", "mask images")):
        if s.has(key) or (key == "mask" and images):
            s.fail("mesh", f"mesh trees beside {what} are not drawn yet: give one or the other")
    if layout == "periodic":
        s.fail("mesh", "mesh trees stand in an isolated canopy: give canopy.layout: isolated")
    items = [s.raw("mesh")] if isinstance(s.raw("mesh"), dict) else s.raw("mesh")
    if not isinstance(items, list) or not items:
        s.fail("mesh", f"must be a mapping or a non-empty list of mappings, not {kind_of(items)}")
    meshes = []
    for i, item in enumerate(items):
        ms = Section(item, s.key(f"mesh[{i}]" if len(items) > 1 else "mesh"), s.ctx)
        meshes.append(MeshConfig(
            file=ms.file("file"), scale=ms.number("scale", 1.0, above=0.0),
            position=ms.numbers("position", 2, (0.0, 0.0)),
            rotation=math.radians(ms.number("rotation", 0.0)),
            up=ms.choice("up", ("y", "z")) if ms.has("up") else None, wood=_names(ms, "wood") if ms.has("wood") else (),
            leaves=_names(ms, "leaves") if ms.has("leaves") else None,
            max_triangles=ms.integer("max_triangles", MAX_MESH_TRIANGLES, at_least=1),
            seed=ms.integer("seed", 7, at_least=0)))
        if meshes[-1].max_triangles > MAX_MESH_TRIANGLES:
            ms.fail("max_triangles", f"must be at most {MAX_MESH_TRIANGLES} (got {meshes[-1].max_triangles})")
        ms.done()
    return tuple(meshes)


def _names(s: Section, name: str) -> tuple[str, ...]:
    """A list of material names (or one name)."""
    value = [s.raw(name)] if isinstance(s.raw(name), str) else s.raw(name)
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        s.fail(name, f"must be a list of material names, not {kind_of(value)}")
    return tuple(value)
