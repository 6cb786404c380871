"""The key of a cache item: SHA-256 of its kind, its parameters in canonical JSON and
``CODE_VERSION``, the same in any process and on any machine; and the names a kind or an array
may take (docs/runs.md, "The cache on disk").

numpy is imported in the function that reads numpy values, so that checking a run's items by
their files' stamps (a resume with nothing to do) starts without it.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import math
import re
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

__all__ = ["CODE_VERSION", "MAX_PARAM_ARRAY_SIZE", "key_of"]

#: Mixed into every key. Change it whenever the code that computes any cached product changes
#: its result, so that old items are never read for new code (they age out through ``prune``).
CODE_VERSION = "sunshade-cycle-2"

#: Largest numpy array accepted inside ``params`` (elements); bigger ones must be described
#: by the parameters that made them instead.
MAX_PARAM_ARRAY_SIZE = 1024

# The root's own folders, which no kind may be named.
#: Folder in the root of the keys' lock files.
LOCKS = "locks"
#: Folder in the root of the records of items found damaged (``Cache.recheck``).
DAMAGED = "damaged"
KEY_PATTERN = re.compile(r"^[0-9a-f]{64}$")
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
ALLOWED_DTYPE_KINDS = "biufc"


def canonical_value(value: Any, where: str) -> Any:
    """A JSON-able, canonical form of a parameter value; ``where`` names it in errors."""
    import numpy as np  # not at the top: see the module docstring
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        # float64 repr round-trips exactly; float32 values widen exactly. NaN and infinities
        # are spelled as strings so that the JSON stays standard.
        v = float(value)
        return v if math.isfinite(v) else {"__float__": repr(v)}
    if isinstance(value, enum.Enum):
        return {"__enum__": type(value).__qualname__, "value": canonical_value(value.value, where)}
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, Mapping):
        out = {}
        for k in value:
            if not isinstance(k, str):
                raise TypeError(f"{where}: keys must be str, not {type(k).__name__} ({k!r})")
            out[k] = canonical_value(value[k], f"{where}[{k!r}]")
        return dict(sorted(out.items()))
    if isinstance(value, (list, tuple)):
        return [canonical_value(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        if value.size > MAX_PARAM_ARRAY_SIZE or value.dtype.kind not in ALLOWED_DTYPE_KINDS:
            raise TypeError(
                f"{where}: a {value.dtype} array of {value.size} elements is not a cache "
                f"parameter (at most {MAX_PARAM_ARRAY_SIZE} numbers); key on the parameters "
                "that made it"
            )
        values = canonical_value(value.tolist(), where)
        return {"__ndarray__": value.dtype.str, "shape": list(value.shape), "values": values}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: canonical_value(getattr(value, f.name), f"{where}.{f.name}")
                  for f in dataclasses.fields(value)}
        return {"__dataclass__": type(value).__qualname__, "fields": fields}
    raise TypeError(f"{where}: unsupported parameter type {type(value).__name__}")


def check_name(text: str, what: str) -> None:
    if not isinstance(text, str) or not NAME_PATTERN.fullmatch(text):
        raise ValueError(
            f"invalid {what} {text!r}: use letters, digits, '_', '-' or '.', "
            "starting with a letter or digit"
        )


def key_of(kind: str, params: Mapping[str, Any]) -> str:
    """The cache key of an item: SHA-256 of its kind, params and CODE_VERSION.

    The same inputs give the same key in any process and on any machine.

    Parameters
    ----------
    kind : str
        The product's name, also its folder: letters, digits, ``_ - .``; not ``locks``.
    params : Mapping
        Everything the product depends on, as str-keyed mappings, lists or tuples (the same key),
        str, bool, int, float (exact: 0.1 and the next float differ, and so do 1 and 1.0), None,
        numpy scalars (as their Python values), Paths, enums, dataclasses (such as
        ``geometry.Grid``) and numpy arrays of at most ``MAX_PARAM_ARRAY_SIZE`` numbers.

    Returns
    -------
    str
        64 hex digits.

    Raises
    ------
    TypeError
        For a value of another type, naming its place in ``params``.
    ValueError
        For a bad or reserved kind.
    """
    check_name(kind, "cache kind")
    if kind in (LOCKS, DAMAGED):
        raise ValueError(f"invalid cache kind {kind!r}: reserved")
    if not isinstance(params, Mapping):
        raise TypeError(f"params must be a mapping, not {type(params).__name__}")
    document = {
        "code_version": CODE_VERSION,
        "kind": kind,
        "params": canonical_value(params, "params"),
    }
    text = json.dumps(document, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                      allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()
