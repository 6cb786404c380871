"""A YAML file read safely, with the line of each key.

The one place a config's YAML is read: UTF-8 text of at most MAX_CONFIG_BYTES, nested at most
MAX_YAML_DEPTH deep, at most MAX_YAML_VALUES values once its aliases are expanded, no key twice
in a mapping; each limit is checked before anything big is built. Numbers are YAML 1.1's and
YAML 1.2's floats (``4e-2``); an empty config is refused (docs/runs.md, "Errors").
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from pipeline.core import paths
from pipeline.core.errors import ConfigError

__all__ = ["MAX_CONFIG_BYTES", "MAX_YAML_DEPTH", "MAX_YAML_VALUES", "load_yaml"]

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file read. [byte]"""
MAX_YAML_VALUES = 100_000
"""Most keys, values and list items a config may hold, its aliases expanded."""
MAX_YAML_DEPTH = 32
"""Deepest nesting of mappings and lists in a config."""
_TOO_DEEP = f"nested too deep; the most is {MAX_YAML_DEPTH} levels"
_EMPTY = ("the config is empty; start from one of configs/*.yaml (an explicit {} renders every "
          "default)")


class _ConfigLoader(yaml.SafeLoader):
    """PyYAML's safe loader (YAML 1.1) that also reads YAML 1.2's floats: ``4e-2``, ``1E5``,
    ``1.5e3``, ``-.5``, which YAML 1.1 leaves as text (its floats need a dot and a signed
    exponent). Digits alone keep their YAML 1.1 meaning: ``7`` an int, ``08`` text."""


_ConfigLoader.add_implicit_resolver(  # tried after YAML 1.1's own, so 1.1's ints stay ints
    "tag:yaml.org,2002:float",
    re.compile(r"^(?=.*[.eE])[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?$"),
    list("-+.0123456789"))


def load_yaml(path: str | os.PathLike[str]) -> tuple[yaml.Node, Any]:
    """Read a YAML file, the one place YAML is read, within the limits of this module.

    Parameters
    ----------
    path : str or path-like
        The file: UTF-8 text of at most MAX_CONFIG_BYTES, at most MAX_YAML_DEPTH deep and
        MAX_YAML_VALUES values with its aliases expanded, not empty.

    Returns
    -------
    node : yaml.Node
        The document's node tree, with each node's line.
    data : object
        The values it holds (``4e-2`` a float, as in YAML 1.2).

    Raises
    ------
    ConfigError
        Naming the file (and line) of the first problem, before anything big is built; for
        an empty file, one holding only comments, or a bare null.
    """
    if problem := paths.problem(path):
        raise ConfigError(paths.shown(path), f"bad config path: {problem}")
    path = Path(path)
    try:
        with open(path, "rb") as file:
            raw = file.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(str(path), f"cannot read the config ({exc.strerror or exc})") from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(str(path), f"the config is over {MAX_CONFIG_BYTES} bytes; the most is "
                          f"{MAX_CONFIG_BYTES} (is it a config?)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ConfigError(f"{path}:{line}", f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at "
                          f"offset {exc.start}); save the config as UTF-8") from None
    loader = _ConfigLoader(text)
    try:
        depth = 0
        for event in yaml.parse(text, Loader=_ConfigLoader):  # flat: no recursion
            depth += (isinstance(event, yaml.CollectionStartEvent)
                      - isinstance(event, yaml.CollectionEndEvent))
            if depth > MAX_YAML_DEPTH:
                raise ConfigError(f"{path}:{event.start_mark.line + 1}", _TOO_DEEP)
        node = loader.get_single_node()
        if node is None:  # no document, or only comments: almost always a mistake
            raise ConfigError(str(path), _EMPTY)
        _expanded_size(node, 0, set(), {}, path)
        data = loader.construct_document(node)
        if data is None:  # a bare ``~`` or ``null``
            raise ConfigError(str(path), _EMPTY)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark else str(path)
        raise ConfigError(where, f"not valid YAML ({getattr(exc, 'problem', None) or exc})") from None
    except ConfigError:
        raise
    except (ValueError, OverflowError, TypeError) as exc:  # a value YAML parsed but cannot build
        raise ConfigError(str(path), f"not valid YAML ({exc})") from None
    finally:
        loader.dispose()
    return node, data


def _expanded_size(node, depth, holders, sizes, path) -> int:
    """Values under ``node`` with every alias expanded (``sizes`` by node id, ``holders`` the
    nodes above it). Raises ConfigError past MAX_YAML_DEPTH or MAX_YAML_VALUES, or for an alias
    inside what it names."""
    where = f"{path}:{node.start_mark.line + 1}"
    if depth > MAX_YAML_DEPTH:
        raise ConfigError(where, _TOO_DEEP)
    if id(node) in holders:
        raise ConfigError(where, "an alias refers to a mapping or list that holds it")
    if id(node) not in sizes:
        if isinstance(node, yaml.ScalarNode):
            return 1
        children = node.value if isinstance(node, yaml.SequenceNode) else \
            [n for pair in node.value for n in pair]
        holders.add(id(node))
        total = 1
        for child in children:
            total += _expanded_size(child, depth + 1, holders, sizes, path)
            if total > MAX_YAML_VALUES:
                raise ConfigError(where, f"holds over {MAX_YAML_VALUES} values, its aliases "
                                  f"expanded; the most is {MAX_YAML_VALUES}")
        holders.discard(id(node))
        sizes[id(node)] = total
    return sizes[id(node)]


@dataclass(frozen=True)
class KeyContext:
    """A config file's path and the YAML line of each key path (``{key path: line}``), for
    messages that name them."""

    path: Path
    lines: dict[str, int]

    def where(self, key: str) -> str:
        line = self.lines.get(key)
        location = f"{self.path}:{line}" if line else str(self.path)
        return f"{location}: {key}" if key else location


def key_lines(node: yaml.Node | None, prefix: str, lines: dict[str, int], path: str | os.PathLike[str]) -> None:
    """Record the YAML line of every key path; reject duplicate keys."""
    if isinstance(node, yaml.MappingNode):
        seen: set[str] = set()
        for key_node, value_node in node.value:
            key = f"{prefix}.{key_node.value}" if prefix else str(key_node.value)
            if key in seen:
                raise ConfigError(f"{path}:{key_node.start_mark.line + 1}: {key}", "duplicate key")
            seen.add(key)
            lines[key] = key_node.start_mark.line + 1
            key_lines(value_node, key, lines, path)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            key = f"{prefix}[{i}]"
            lines[key] = item.start_mark.line + 1
            key_lines(item, key, lines, path)
