"""The on-disk store of cycle products: named numpy arrays keyed by a hash of their inputs, written
atomically, checksummed, shared safely by concurrent processes (docs/runs.md, "The cache on
disk" and "The cache's checks").

Why one module: the layout on disk, the checks and the locking are one contract; split, its
invariants (an item folder that exists is complete or was damaged afterwards) would be spread
over several files.

numpy is imported in the functions that read or write arrays, so that checking a run's items by
their files' stamps (a resume with nothing to do) starts without it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import hashlib
import json
import math
import os
import re
import secrets
import shutil
import tempfile
import time
import warnings
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any

from filelock import FileLock, Timeout

if TYPE_CHECKING:
    import numpy as np

__all__ = ["CODE_VERSION", "FORMAT", "ENV_VAR", "BUDGET_ENV_VAR", "DEFAULT_BUDGET", "RUNS", "MAX_PARAM_ARRAY_SIZE",
           "CacheWarning", "forget_verified", "cache_dir", "cache_budget", "parse_size", "key_of", "CacheItem", "Cache"]

#: Mixed into every key. Change it whenever the code that computes any cached product changes
#: its result, so that old items are never read for new code (they age out through ``prune``).
CODE_VERSION = "sunshade-cycle-2"

#: Layout version of an item folder and its ``meta.json``; items of another format are broken.
FORMAT = 1

#: Environment variable naming the cache root when no explicit folder is given.
ENV_VAR = "SUNSHADE_CACHE"

#: Environment variable giving the cache's budget (``parse_size``) when --cache-size is not given.
BUDGET_ENV_VAR = "SUNSHADE_CACHE_SIZE"

#: The cache's budget when none is given: at the end of a run the least recently used items it
#: did not use are removed until the items total at most this. [B]
DEFAULT_BUDGET = 20 * 1024**3

#: Folder in the root where each run names the items it uses while it runs (a list and a lock
#: held as long as the run lives), so that no other run's budget removes them.
RUNS = ".runs"

#: Largest numpy array accepted inside ``params`` (elements); bigger ones must be described
#: by the parameters that made them instead.
MAX_PARAM_ARRAY_SIZE = 1024

#: An item folder's description: its arrays, their checksums and the parameters they were made from.
META = "meta.json"
#: Folder in the root of the keys' lock files.
LOCKS = "locks"
#: Folder in the root of the records of items found damaged (``Cache.recheck``).
DAMAGED = "damaged"
_TMP = ".tmp-"
_DEL = ".del-"
_KEY_RE = re.compile(r"^[0-9a-f]{64}$")
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
_ALLOWED_DTYPE_KINDS = "biufc"
_CRC_CHUNK = 1 << 24  # [B]
_META_CRC = "meta_crc32"

#: Items whose bytes this process has checked: item folder -> the signature of its files
#: (name, size, inode, modification and change time [ns]) when they were checked.
_VERIFIED: dict[str, tuple] = {}


class CacheWarning(RuntimeWarning):
    """A damaged cache item that was removed (it is computed again), or an item not stored."""


def forget_verified() -> None:
    """Forget which items this process has checked: the next read of each checks its bytes."""
    _VERIFIED.clear()


def cache_dir(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The cache root: ``explicit`` if given, else ``$SUNSHADE_CACHE`` if set and not empty, else ``./cache``.

    The folder is not created here; ``Cache`` creates what it writes.

    Parameters
    ----------
    explicit : str or os.PathLike, optional
        The folder asked for (--cache); None or empty: not given.

    Returns
    -------
    pathlib.Path
        The root, absolute (workers may run in another folder), ``~`` expanded.
    """
    if explicit is not None and str(explicit) != "":
        path = Path(explicit)
    elif os.environ.get(ENV_VAR):
        path = Path(os.environ[ENV_VAR])
    else:
        path = Path("cache")
    return path.expanduser().absolute()


def cache_budget(explicit: str | None = None) -> int:
    """The cache's budget: ``explicit`` (--cache-size), else ``$SUNSHADE_CACHE_SIZE``, else DEFAULT_BUDGET.

    ``$SUNSHADE_CACHE_SIZE`` counts when it is set and not empty.

    Parameters
    ----------
    explicit : str, optional
        The size asked for, as ``parse_size`` reads it.

    Returns
    -------
    int
        The budget [B].

    Raises
    ------
    ValueError
        Naming the text (``parse_size``).
    """
    text = explicit if explicit is not None else os.environ.get(BUDGET_ENV_VAR) or None
    return DEFAULT_BUDGET if text is None else parse_size(text)


def parse_size(text: str | int) -> int:
    """Bytes in a size such as ``"2G"``, ``"512M"``, ``"1.5GiB"`` or ``"1000"``.

    Units are binary, powers of 1024, whatever their spelling: K, M, G, T, optionally followed
    by ``iB`` or ``B`` (so ``"2GB"`` is also 2 * 1024**3, as in ``du -h``), case-insensitive;
    no unit or ``B`` means bytes. Fractions are rounded down to whole bytes.

    Parameters
    ----------
    text : str or int
        The size; a non-negative int is returned as it is.

    Returns
    -------
    int
        The size [B].

    Raises
    ------
    ValueError
        Naming the text if it is not a non-negative size.
    """
    import numpy as np  # not at the top: see the module docstring
    if isinstance(text, (int, np.integer)) and not isinstance(text, bool):
        if text < 0:
            raise ValueError(f"invalid size {text!r}: must not be negative")
        return int(text)
    if not isinstance(text, str):
        raise ValueError(f"invalid size {text!r}: expected text such as '2G'")
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kmgt]?)(i?b)?\s*", text, re.IGNORECASE)
    if match is None or (match.group(3) and match.group(3).lower() == "ib" and not match.group(2)):
        raise ValueError(
            f"invalid size {text!r}: expected a number with an optional unit K, M, G or T "
            "(powers of 1024), e.g. '2G'"
        )
    number, unit = float(match.group(1)), match.group(2).upper()
    return int(number * 1024 ** " KMGT".index(unit or " "))


def _canonical(value: Any, where: str) -> Any:
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
        return {"__enum__": type(value).__qualname__, "value": _canonical(value.value, where)}
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, Mapping):
        out = {}
        for k in value:
            if not isinstance(k, str):
                raise TypeError(f"{where}: keys must be str, not {type(k).__name__} ({k!r})")
            out[k] = _canonical(value[k], f"{where}[{k!r}]")
        return dict(sorted(out.items()))
    if isinstance(value, (list, tuple)):
        return [_canonical(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        if value.size > MAX_PARAM_ARRAY_SIZE or value.dtype.kind not in _ALLOWED_DTYPE_KINDS:
            raise TypeError(
                f"{where}: a {value.dtype} array of {value.size} elements is not a cache "
                f"parameter (at most {MAX_PARAM_ARRAY_SIZE} numbers); key on the parameters "
                "that made it"
            )
        values = _canonical(value.tolist(), where)
        return {"__ndarray__": value.dtype.str, "shape": list(value.shape), "values": values}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: _canonical(getattr(value, f.name), f"{where}.{f.name}")
                  for f in dataclasses.fields(value)}
        return {"__dataclass__": type(value).__qualname__, "fields": fields}
    raise TypeError(f"{where}: unsupported parameter type {type(value).__name__}")


def _check_name(text: str, what: str) -> None:
    if not isinstance(text, str) or not _NAME_RE.fullmatch(text):
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
    _check_name(kind, "cache kind")
    if kind in (LOCKS, DAMAGED):
        raise ValueError(f"invalid cache kind {kind!r}: reserved")
    if not isinstance(params, Mapping):
        raise TypeError(f"params must be a mapping, not {type(params).__name__}")
    document = {
        "code_version": CODE_VERSION,
        "kind": kind,
        "params": _canonical(params, "params"),
    }
    text = json.dumps(document, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                      allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def _crc32(array: np.ndarray) -> int:
    """CRC-32 of the bytes of a C-contiguous array (zlib.crc32, chunked)."""
    import numpy as np  # not at the top: see the module docstring
    return _crc32_of(array.reshape(-1).view(np.uint8))


def _crc32_of(buffer) -> int:
    """CRC-32 of a bytes-like object, in chunks of ``_CRC_CHUNK`` bytes (no copies)."""
    view = memoryview(buffer).cast("B")
    crc = 0
    for start in range(0, len(view), _CRC_CHUNK):
        crc = zlib.crc32(view[start:start + _CRC_CHUNK], crc)
    return crc


def _file_crc32(path: Path) -> int:
    """CRC-32 of a whole file's bytes, read in chunks (not through a memory map: an exception
    raised while a map's buffer is exported made its close raise BufferError instead)."""
    crc = 0
    with open(path, "rb") as f:
        while chunk := f.read(_CRC_CHUNK):
            crc = zlib.crc32(chunk, crc)
    return crc


def _meta_crc32(meta: Mapping) -> int:
    """CRC-32 of a meta.json document without its own checksum, in canonical JSON."""
    body = {k: v for k, v in meta.items() if k != _META_CRC}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return zlib.crc32(text.encode("ascii"))


@dataclass(frozen=True)
class CacheItem:
    """One item folder as found on disk.

    Attributes
    ----------
    kind : str
        The product kind (first folder level).
    key : str
        64 hex digits.
    path : pathlib.Path
        The item folder.
    bytes : int
        Total size of its files [B].
    created : float or None
        When it was written, from meta.json; None if unreadable [s since epoch].
    last_used : float
        Modification time of meta.json (of the folder if none) [s since epoch].
    params : dict or None
        The canonical parameters it was computed from (None if unreadable).
    """

    kind: str
    key: str
    path: Path
    bytes: int
    created: float | None
    last_used: float
    params: dict | None = None


class _Broken(Exception):
    """An item folder that exists but cannot be trusted; the message says why."""


class Cache:
    """The store under one root folder. Cheap to create and to pickle (joblib workers).

    Parameters
    ----------
    root : str or os.PathLike
        The cache folder, usually ``cache_dir(...)``; created on first write.

    Attributes
    ----------
    root : pathlib.Path
        The cache folder.
    hits, misses, repaired : int
        Count, in this process, the items read, computed (absent or broken) and of those the broken
        ones that were removed and recomputed.
    served : dict
        ``"kind/key"`` to the stamp of each item this store returned (see ``recheck``).
    """

    def __init__(self, root: str | os.PathLike[str]):
        self.root = Path(root)
        self.hits = 0
        self.misses = 0
        self.repaired = 0
        self.served: dict[str, dict] = {}

    def __repr__(self) -> str:
        return f"Cache({str(self.root)!r})"

    def writing_problem(self) -> str | None:
        """Why items cannot be written under the root, in words, or None.

        A folder is made and removed in the root (or, where the root does not exist yet, in the nearest
        folder above it), so that a read-only file system or a folder of no rights is found before any
        work.

        Returns
        -------
        str or None
            The problem, or None when items can be written.
        """
        folder = self.root
        while not folder.exists() and folder.parent != folder:
            folder = folder.parent
        if not folder.is_dir():
            return f"{folder} is not a folder"
        try:
            os.rmdir(tempfile.mkdtemp(prefix=_TMP + "probe-", dir=folder))
        except OSError as exc:
            return f"cannot write in {folder} ({exc.strerror or exc})"
        return None

    # -- paths -------------------------------------------------------------------------

    def item_path(self, kind: str, key: str) -> Path:
        """The folder of item ``key`` of ``kind`` (it may not exist).

        Parameters
        ----------
        kind : str
            The product kind.
        key : str
            Its key (``key_of``).

        Returns
        -------
        pathlib.Path
            ``root / kind / key[:2] / key``.
        """
        return self.root / kind / key[:2] / key

    def _lock(self, key: str) -> FileLock:
        return FileLock(str(self.root / LOCKS / f"{key}.lock"))

    # -- reading -----------------------------------------------------------------------

    def _open(self, path: Path, kind: str | None, key: str, *, verify: bool, fresh: bool = False):
        """(meta, arrays, stamp) of a complete item, None if absent; raises _Broken otherwise.

        verify : check the checksums of the files and of meta.json, unless this process
            checked these very files before (same size, inode and times); ``fresh`` checks
            them whatever this process saw. Without it, sizes and headers only.
        stamp : ``{file: [crc32, size, inode, mtime_ns, ctime_ns, created]}`` of the item's
            arrays (``created``: when this copy was written, from meta.json).
        """
        import numpy as np  # not at the top: see the module docstring
        meta_path = path / META
        try:
            with open(meta_path, "rb") as f:
                meta = json.loads(f.read())
        except FileNotFoundError:
            if path.is_dir():
                raise _Broken(f"{META} is missing") from None
            return None
        except (OSError, ValueError) as e:
            raise _Broken(f"{META} is unreadable: {e}") from None
        try:
            if not isinstance(meta, dict):
                raise _Broken(f"{META} is not a JSON object")
            if verify and _META_CRC in meta and _meta_crc32(meta) != meta[_META_CRC]:
                raise _Broken(f"{META}: checksum mismatch (corrupted)")
            if meta.get("format") != FORMAT:
                raise _Broken(f"format {meta.get('format')!r}, expected {FORMAT}")
            if meta.get("key") != key or (kind is not None and meta.get("kind") != kind):
                raise _Broken(f"{META} names another item ({meta.get('kind')}/{meta.get('key')})")
            specs = meta["arrays"]
            stamp, signature = {}, []
            for name, spec in specs.items():
                if spec["file"] != f"{name}.npy":
                    raise _Broken(f"{META} names the file {spec['file']!r} for {name!r}")
                st = os.stat(path / spec["file"])
                if st.st_size != spec["file_bytes"]:
                    raise _Broken(f"{spec['file']} has {st.st_size} bytes, expected {spec['file_bytes']}")
                identity = [st.st_size, st.st_ino, st.st_mtime_ns, st.st_ctime_ns]
                stamp[spec["file"]] = [spec.get("file_crc32", spec["crc32"]), *identity,
                                       meta.get("created")]
                signature.append((spec["file"], *identity))
            check = verify and (fresh or _VERIFIED.get(str(path)) != tuple(signature))
            arrays = {}
            for name, spec in specs.items():
                if check and "file_crc32" in spec and _file_crc32(path / spec["file"]) != spec["file_crc32"]:
                    raise _Broken(f"{spec['file']}: checksum mismatch (corrupted)")
                a = np.load(path / spec["file"], mmap_mode="r", allow_pickle=False)
                if a.dtype.str != spec["dtype"] or list(a.shape) != spec["shape"] \
                        or not a.flags.c_contiguous:
                    raise _Broken(f"{spec['file']} holds {a.dtype.str} {list(a.shape)}, "
                                  f"expected {spec['dtype']} {spec['shape']}")
                if check and "file_crc32" not in spec and _crc32(a) != spec["crc32"]:
                    raise _Broken(f"{spec['file']}: checksum mismatch (corrupted data)")
                arrays[name] = a
        except _Broken:
            _VERIFIED.pop(str(path), None)
            raise
        except FileNotFoundError as e:
            _VERIFIED.pop(str(path), None)
            raise _Broken(f"{Path(e.filename).name} is missing") from None
        except Exception as e:  # whatever a damaged header makes numpy or json raise
            _VERIFIED.pop(str(path), None)
            raise _Broken(f"unreadable: {type(e).__name__}: {e}".splitlines()[0]) from None
        if check:
            _VERIFIED[str(path)] = tuple(signature)
        return meta, arrays, stamp

    def _hit(self, kind: str, key: str, found: tuple) -> dict[str, np.ndarray]:
        self.hits += 1
        self.served[f"{kind}/{key}"] = found[2]
        try:
            os.utime(self.item_path(kind, key) / META)  # last use, for prune
        except OSError:
            pass  # a read-only or concurrently pruned cache still serves this hit
        return found[1]

    def _discard(self, path: Path, kind: str, key: str, problem: str) -> None:
        """Remove a broken item, under its lock, with a one-line CacheWarning; if it is sound
        again by the time the lock is held (another process repaired it), keep it."""
        lock = self._lock(key)
        try:
            (self.root / LOCKS).mkdir(parents=True, exist_ok=True)
            lock.acquire()
        except OSError as e:
            warnings.warn(f"cache item {kind}/{key[:12]} is damaged ({problem}) and cannot be "
                          f"removed: {e}", CacheWarning, stacklevel=3)
            return
        try:
            try:
                self._open(path, kind, key, verify=True, fresh=True)
            except _Broken as e:
                self._remove_broken(path, kind, key, str(e))
        finally:
            lock.release()

    def _remove_broken(self, path: Path, kind: str, key: str, problem: str) -> None:
        """Remove a broken item (the caller holds its lock) with a one-line CacheWarning."""
        self._bury(path, key, problem)
        _remove(path)
        self.repaired += 1
        warnings.warn(f"cache item {kind}/{key[:12]} was damaged ({problem}); removed, it is "
                      "computed again", CacheWarning, stacklevel=4)

    def _bury(self, path: Path, key: str, problem: str) -> None:
        """Record, before removing it, that the item at ``path`` was found damaged: when
        [s since epoch], why, the inodes of its .npy files and when the copy was written (from
        meta.json, if readable), so that what was made from this very copy of it can be told
        apart later (``recheck``). Best effort: a record
        that cannot be written is left out."""
        try:
            inodes = {e.name: e.inode() for e in os.scandir(path) if e.name.endswith(".npy")}
            try:
                created = json.loads((path / META).read_bytes()).get("created")
            except (OSError, ValueError, AttributeError):
                created = None  # unknown: any copy with these inodes counts
            records = self._damaged(key) + [{"found": time.time(), "problem": problem,
                                             "inodes": inodes, "created": created}]
            folder = self.root / DAMAGED
            folder.mkdir(parents=True, exist_ok=True)
            temporary = folder / f"{_TMP}{key}-{os.getpid()}-{secrets.token_hex(4)}"
            temporary.write_text(json.dumps(records))
            os.replace(temporary, folder / f"{key}.json")
        except OSError:
            pass

    def _damaged(self, key: str) -> list:
        """The records of ``_bury`` for ``key`` (empty if none or unreadable)."""
        try:
            records = json.loads((self.root / DAMAGED / f"{key}.json").read_bytes())
        except (OSError, ValueError):
            return []
        return records if isinstance(records, list) else []

    def get(self, kind: str, params: Mapping[str, Any], *, verify: bool = True
            ) -> dict[str, np.ndarray] | None:
        """The item's arrays, memory-mapped read-only, or None if it is absent or broken.

        Computes nothing; a broken item is removed (with a CacheWarning), so that the next
        ``get_or_compute`` computes it.

        Parameters
        ----------
        kind : str
            As for ``key_of``.
        params : Mapping
            As for ``key_of``.
        verify : bool, optional
            Check the checksums (as ``get_or_compute``); False checks sizes and headers only.

        Returns
        -------
        dict of str to numpy.memmap or None
            The arrays, or None.
        """
        key = key_of(kind, params)
        path = self.item_path(kind, key)
        try:
            found = self._open(path, kind, key, verify=verify)
        except _Broken as e:
            self._discard(path, kind, key, str(e))
            return None
        return None if found is None else self._hit(kind, key, found)

    def get_or_compute(self, kind: str, params: Mapping[str, Any],
                       compute: Callable[[], Mapping[str, np.ndarray]], *,
                       verify: bool = True) -> dict[str, np.ndarray]:
        """The item ``(kind, params)``: read back if stored and sound, else computed and stored.

        A broken item (truncated, corrupted, without meta) is removed with a one-line CacheWarning and
        recomputed. On a miss the key's file lock is held while computing, so concurrent processes
        compute each key once; the others wait and then read it. If the store cannot be written (disk
        full, read-only), a warning is issued and the computed arrays are returned as they are.
        Exceptions of ``compute`` propagate; nothing is stored.

        Parameters
        ----------
        kind : str
            As for ``key_of``.
        params : Mapping
            As for ``key_of``; it must name everything ``compute`` depends on.
        compute : callable
            Called with no arguments on a miss; returns ``{name: array}`` with names as for ``kind``
            and numeric or bool arrays (stored C-contiguous).
        verify : bool, optional
            Check the CRC-32 of every file on the first read in this process (about 4 ms per 16 MiB),
            and again whenever the files changed since; False checks sizes and headers only.

        Returns
        -------
        dict of str to numpy.ndarray
            ``{name: numpy.memmap}`` opened read-only (``mmap_mode='r'``), in the order ``compute``
            returned them (the computed arrays themselves when they could not be stored).
        """
        key = key_of(kind, params)
        path = self.item_path(kind, key)
        try:
            found = self._open(path, kind, key, verify=verify)
            if found is not None:
                return self._hit(kind, key, found)
        except _Broken:
            pass  # repaired below, under the lock, after a re-check
        lock = self._lock(key)
        try:
            (self.root / LOCKS).mkdir(parents=True, exist_ok=True)
            lock.acquire()
        except OSError as e:  # a read-only or unreachable cache: still render
            warnings.warn(f"cache item {kind}/{key[:12]} not stored: cannot lock in "
                          f"{self.root}: {e}", CacheWarning, stacklevel=2)
            self.misses += 1
            return _normalize(compute(), kind)
        try:
            try:
                found = self._open(path, kind, key, verify=verify)
                if found is not None:  # another process wrote it while we waited
                    return self._hit(kind, key, found)
            except _Broken as e:
                self._remove_broken(path, kind, key, str(e))
            self.misses += 1
            arrays = _normalize(compute(), kind)
            try:
                self._write(path, kind, key, params, arrays)
                found = self._open(path, kind, key, verify=True, fresh=True)
            except (OSError, _Broken) as e:
                warnings.warn(f"cache item {kind}/{key[:12]} not stored in {self.root}: {e}",
                              CacheWarning, stacklevel=2)
                return arrays
            self.served[f"{kind}/{key}"] = found[2]
            return found[1]
        finally:
            lock.release()

    def recheck(self, item: str, stamp: Mapping[str, list], *, fresh: bool = False,
                repair: bool = True) -> str | None:
        """Whether item ``"kind/key"`` is still the one ``stamp`` (from ``served``) describes.

        A sound item read here is recorded in ``served`` with its current stamp.

        Parameters
        ----------
        item : str
            ``"kind/key"``.
        stamp : Mapping
            ``{file: [crc32, size, inode, mtime_ns, ctime_ns, created]}``, as ``served`` records it.
        fresh : bool, optional
            Read and check the files whatever their sizes and times.
        repair : bool, optional
            Remove an item found damaged now, with a CacheWarning.

        Returns
        -------
        str or None
            None when its files have the same sizes, inodes and times (nothing is read), when they
            changed but hold the same checksums (the item was computed again), or when the item is
            absent (pruned: nothing says it was wrong). Otherwise the problem in words: the very copy
            read then (the same inodes) was found damaged and removed since, by any process; the item
            is damaged now; or it holds other bytes.
        """
        kind, _, key = item.partition("/")
        if not _NAME_RE.fullmatch(kind) or not _KEY_RE.fullmatch(key):
            return f"{item!r} is not a cache item"
        for record in self._damaged(key):
            inodes = record.get("inodes", {}) if isinstance(record, dict) else {}
            created = record.get("created") if isinstance(record, dict) else None
            if any(inodes.get(file) == values[2] and created in (None, values[5])
                   for file, values in stamp.items()):
                return f"cache item {kind}/{key[:12]}, found damaged since ({record.get('problem')})"
        path = self.item_path(kind, key)
        try:
            now = {file: [st.st_size, st.st_ino, st.st_mtime_ns, st.st_ctime_ns]
                   for file in stamp for st in [os.stat(path / file)]}
        except OSError:
            now = None
        if not fresh and now is not None and all(now[f] == list(stamp[f][1:5]) for f in stamp):
            return None
        try:
            found = self._open(path, kind, key, verify=True, fresh=fresh)
        except _Broken as e:
            if repair:
                self._discard(path, kind, key, str(e))
            return f"cache item {kind}/{key[:12]}, damaged since ({e})"
        if found is None:
            return None
        self.served[item] = found[2]
        if {file: v[0] for file, v in found[2].items()} != {file: v[0] for file, v in stamp.items()}:
            return f"cache item {kind}/{key[:12]} holds other bytes than when it was read"
        return None

    # -- writing -----------------------------------------------------------------------

    def _write(self, path: Path, kind: str, key: str, params, arrays: dict) -> None:
        """Write ``arrays`` as item ``path`` atomically: temp folder, arrays, meta, rename."""
        import numpy as np  # not at the top: see the module docstring
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.parent / f"{_TMP}{key}-{os.getpid()}-{secrets.token_hex(4)}"
        os.mkdir(tmp)
        try:
            specs = {}
            for name, a in arrays.items():
                file = f"{name}.npy"
                with open(tmp / file, "wb") as f:
                    np.lib.format.write_array(f, a, allow_pickle=False)
                    file_bytes = f.tell()
                specs[name] = {"file": file, "dtype": a.dtype.str, "shape": list(a.shape),
                               "nbytes": int(a.nbytes), "file_bytes": int(file_bytes),
                               "crc32": _crc32(a), "file_crc32": _file_crc32(tmp / file)}
            meta = {"format": FORMAT, "code_version": CODE_VERSION, "kind": kind, "key": key,
                    "created": time.time(), "checksum": "crc32", "arrays": specs,
                    "params": _canonical(params, "params")}
            meta[_META_CRC] = _meta_crc32(meta)
            with open(tmp / META, "w", encoding="ascii") as f:
                json.dump(meta, f, indent=1, allow_nan=False)
            try:
                os.rename(tmp, path)
            except OSError:
                # Only if an item appeared without the lock (a lock file removed by ``clear``
                # while held): keep a sound one, else replace it.
                try:
                    if self._open(path, kind, key, verify=False) is not None:
                        return
                except _Broken:
                    pass
                _remove(path)
                os.rename(tmp, path)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)

    # -- maintenance -------------------------------------------------------------------

    def _walk(self):
        """Yield ("item", kind, key, path), (".tmp-" or ".del-", kind, key or None, path) for
        temporary folders, and ("stray", kind, None, path) for anything else inside a kind's
        folder (a file where an item's folder should be, a folder of another name, a link);
        what is beside the kinds' folders in the root (the locks, the damaged items' records,
        FFTW wisdom, the config records) is not an item's place and is skipped."""
        if not self.root.is_dir():
            return
        for kind_dir in sorted(self.root.iterdir()):
            if kind_dir.name in (LOCKS, DAMAGED) or not kind_dir.is_dir() or kind_dir.is_symlink() \
                    or not _NAME_RE.fullmatch(kind_dir.name):
                continue
            for prefix_dir in sorted(kind_dir.iterdir()):
                if not re.fullmatch(r"[0-9a-f]{2}", prefix_dir.name) or not prefix_dir.is_dir() \
                        or prefix_dir.is_symlink():
                    yield "stray", kind_dir.name, None, prefix_dir
                    continue
                for entry in sorted(prefix_dir.iterdir()):
                    name = entry.name
                    folder = entry.is_dir() and not entry.is_symlink()
                    if _KEY_RE.fullmatch(name) and name[:2] == prefix_dir.name and folder:
                        yield "item", kind_dir.name, name, entry
                    elif name.startswith((_TMP, _DEL)) and folder:
                        key = name[5:69] if _KEY_RE.fullmatch(name[5:69]) else None
                        yield name[:5], kind_dir.name, key, entry
                    else:
                        yield "stray", kind_dir.name, None, entry

    def _info(self, kind: str, key: str, path: Path) -> CacheItem:
        size = 0
        try:
            for entry in os.scandir(path):
                if entry.is_file(follow_symlinks=False):
                    size += entry.stat(follow_symlinks=False).st_size
        except OSError:
            pass
        created = params = None
        try:
            last_used = os.stat(path / META).st_mtime
            with open(path / META, "rb") as f:
                meta = json.loads(f.read())
            created, params = float(meta["created"]), meta.get("params")
        except (OSError, ValueError, KeyError, TypeError):
            try:
                last_used = os.stat(path).st_mtime
            except OSError:
                last_used = 0.0
        return CacheItem(kind, key, path, size, created, last_used, params)

    def list(self) -> list[CacheItem]:
        """Every item folder, complete or not, by kind then key; temporary folders are left out.

        Returns
        -------
        list of CacheItem
            The items.
        """
        return [self._info(kind, key, path) for what, kind, key, path in self._walk()
                if what == "item"]

    def strays(self, *, remove: bool = False) -> list[tuple[Path, str]]:
        """Every entry inside a kind's folder that is not an item, nor a temporary folder.

        Parameters
        ----------
        remove : bool, optional
            Also remove them (nothing but the cache writes in its kinds' folders).

        Returns
        -------
        list of tuple of (pathlib.Path, str)
            Each entry with what it is in words: a file where an item's folder should be, say.
        """
        found = []
        for what, _kind, _key, path in list(self._walk()):
            if what == "stray":
                kind = "a link" if path.is_symlink() else "a folder" if path.is_dir() else "a file"
                found.append((path, f"{kind} that is not a cache item"))
                if remove and kind == "a folder":
                    _remove(path)
                elif remove:
                    path.unlink(missing_ok=True)
        return found

    def verify(self, *, remove: bool = False) -> list[tuple[CacheItem, str]]:
        """Check every item fully (sizes, headers, CRC-32 of all files and of meta.json).

        Reads the whole cache; ``strays`` lists what is not an item.

        Parameters
        ----------
        remove : bool, optional
            Also remove the broken ones (they would be recomputed when next needed anyway).

        Returns
        -------
        list of tuple of (CacheItem, str)
            The broken items, each with its problem in words.
        """
        problems = []
        for item in self.list():
            try:
                self._open(item.path, item.kind, item.key, verify=True, fresh=True)
            except _Broken as e:
                problems.append((item, str(e)))
                if remove:
                    self._bury(item.path, item.key, str(e))
                    _remove(item.path)
        return problems

    def _remove_stale(self) -> None:
        """Remove ``.del-`` folders, and ``.tmp-`` folders whose key lock is free (their
        writer is dead: a live writer holds the lock until its rename)."""
        for what, _kind, key, path in list(self._walk()):
            (self.root / LOCKS).mkdir(exist_ok=True)
            if what == _DEL or (what == _TMP and key is None):
                shutil.rmtree(path, ignore_errors=True)
            elif what == _TMP:
                lock = self._lock(key)
                try:
                    lock.acquire(timeout=0)
                except (Timeout, OSError):
                    continue
                try:
                    shutil.rmtree(path, ignore_errors=True)
                finally:
                    lock.release()

    def _remove_empty_folders(self) -> None:
        """Remove empty ``<kind>/<xx>`` folders, and kind folders they leave empty."""
        if not self.root.is_dir():
            return
        for kind_dir in self.root.iterdir():
            if kind_dir.name == LOCKS or not _NAME_RE.fullmatch(kind_dir.name) \
                    or not kind_dir.is_dir() or kind_dir.is_symlink():
                continue
            emptied = False
            for prefix_dir in kind_dir.iterdir():
                if re.fullmatch(r"[0-9a-f]{2}", prefix_dir.name) and prefix_dir.is_dir():
                    emptied |= _rmdir_if_empty(prefix_dir)
            if emptied:
                _rmdir_if_empty(kind_dir)

    def clear(self) -> list[CacheItem]:
        """Remove every item, leftover temporary folder and free lock file.

        Files in the root that are not the cache's (e.g. FFTW wisdom) are kept.

        Returns
        -------
        list of CacheItem
            The items removed.
        """
        self._remove_stale()
        removed = [item for item in self.list() if _remove(item.path)]
        locks = self.root / LOCKS
        if locks.is_dir():
            for path in locks.glob("*.lock"):
                lock = FileLock(str(path))
                try:
                    lock.acquire(timeout=0)
                except (Timeout, OSError):
                    continue  # in use by a writer
                try:
                    path.unlink(missing_ok=True)
                finally:
                    lock.release()
            _rmdir_if_empty(locks)
        self._remove_empty_folders()
        return removed

    def prune(self, max_bytes: int, *, keep=frozenset()) -> list[CacheItem]:
        """Remove leftover temporary folders, then the least recently used items down to a budget.

        Never an item whose key is in ``keep`` or in use by a live run (``in_use``).

        Parameters
        ----------
        max_bytes : int
            The items total at most this afterwards, but for those kept [B].
        keep : collection of str, optional
            Keys not to remove.

        Returns
        -------
        list of CacheItem
            The items removed, oldest first.

        Raises
        ------
        ValueError
            When ``max_bytes`` is negative.
        """
        if max_bytes < 0:
            raise ValueError(f"max_bytes must not be negative, got {max_bytes}")
        self._remove_stale()
        kept = set(keep) | self.keys_in_use()
        items = sorted(self.list(), key=lambda item: (item.last_used, item.key))
        total = sum(item.bytes for item in items)
        removed = []
        for item in items:
            if total <= max_bytes:
                break
            if item.key in kept:
                continue
            if _remove(item.path):
                removed.append(item)
            total -= item.bytes
        self._remove_empty_folders()
        return removed

    @contextlib.contextmanager
    def in_use(self, keys):
        """For the block, name ``keys`` as in use by this process.

        A list in ``RUNS`` and a lock held beside it, which ``keys_in_use`` of any other process reads,
        so that no prune removes them while the block runs (a killed process's lock is freed by the
        system, and its list counts no more).

        Parameters
        ----------
        keys : iterable of str
            The items' keys.

        Yields
        ------
        None
            While the block runs.
        """
        folder = self.root / RUNS
        folder.mkdir(parents=True, exist_ok=True)
        name = f"{os.getpid()}-{secrets.token_hex(4)}"
        lock = FileLock(str(folder / f"{name}.lock"))
        lock.acquire()
        try:
            listing = folder / f"{name}.json"
            temporary = folder / f"{_TMP}{name}.json"
            temporary.write_text(json.dumps(sorted(keys)))
            os.replace(temporary, listing)
            try:
                yield
            finally:
                listing.unlink(missing_ok=True)
        finally:
            lock.release()
            Path(lock.lock_file).unlink(missing_ok=True)

    def keys_in_use(self) -> set[str]:
        """The keys that live runs name as in use (``in_use``).

        The lists of runs that ended without removing them (killed) are removed.

        Returns
        -------
        set of str
            The keys.
        """
        folder = self.root / RUNS
        keys: set[str] = set()
        if not folder.is_dir():
            return keys
        for listing in sorted(folder.glob("*.json")):
            lock = FileLock(str(listing.with_suffix(".lock")))
            try:
                lock.acquire(timeout=0)
            except (Timeout, OSError):  # held: the run lives
                try:
                    keys |= set(json.loads(listing.read_text()))
                except (OSError, ValueError, TypeError):
                    pass
                continue
            try:
                listing.unlink(missing_ok=True)  # its run is gone
            finally:
                lock.release()
                Path(lock.lock_file).unlink(missing_ok=True)
        return keys


def _normalize(arrays: Any, kind: str) -> dict[str, np.ndarray]:
    """Check what ``compute`` returned; arrays made C-contiguous (not copied if they are)."""
    import numpy as np  # not at the top: see the module docstring
    if not isinstance(arrays, Mapping) or not arrays:
        raise TypeError(f"compute for cache kind {kind!r} must return a non-empty dict of "
                        f"arrays, not {type(arrays).__name__}")
    out = {}
    for name, a in arrays.items():
        _check_name(name, "array name")
        if name == META.removesuffix(".json"):
            raise ValueError(f"invalid array name {name!r}: reserved")
        if not isinstance(a, np.ndarray):
            raise TypeError(f"compute for {kind!r} returned {type(a).__name__} for {name!r}, "
                            "not a numpy array")
        if a.dtype.kind not in _ALLOWED_DTYPE_KINDS:
            raise TypeError(f"array {name!r} has dtype {a.dtype}; only bool and numeric "
                            "arrays are stored")
        out[name] = a if a.flags.c_contiguous else np.array(a, order="C")
    return out


def _remove(path: Path) -> bool:
    """Remove an item folder: rename it to a ``.del-`` name (atomic), then delete it.
    False if it was not there (someone else removed it)."""
    trash = path.parent / f"{_DEL}{path.name}-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        os.rename(path, trash)
    except FileNotFoundError:
        return False
    shutil.rmtree(trash, ignore_errors=True)
    return True


def _rmdir_if_empty(path: Path) -> bool:
    try:
        path.rmdir()
    except OSError:
        return False
    return True
