"""Cache items under one root folder, by kind and parameters: each written atomically, read back
checked (sizes, headers, CRC-32s), a damaged one removed and recorded, a missing one computed once
under its key's lock (docs/runs.md, "The cache on disk" and "The cache's checks"). An item folder
that exists is complete or was damaged afterwards.

numpy is imported in the functions that read or write arrays, so that checking a run's items by
their files' stamps (a resume with nothing to do) starts without it.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import tempfile
import time
import warnings
import zlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from filelock import FileLock

from pipeline.cache.keys import (
    ALLOWED_DTYPE_KINDS,
    CODE_VERSION,
    DAMAGED,
    KEY_PATTERN,
    LOCKS,
    NAME_PATTERN,
    canonical_value,
    check_name,
    key_of,
)

if TYPE_CHECKING:
    import numpy as np

__all__ = ["FORMAT", "CacheWarning", "forget_verified", "ItemStore"]

#: Layout version of an item folder and its ``meta.json``; items of another format are broken.
FORMAT = 1

#: An item folder's description: its arrays, their checksums and the parameters they were made from.
META = "meta.json"
TEMPORARY_PREFIX = ".tmp-"
TRASH_PREFIX = ".del-"
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


class BrokenItem(Exception):
    """An item folder that exists but cannot be trusted; the message says why."""


class ItemStore:
    """Items by kind and parameters under one root folder: read back checked, else computed and written.

    Cheap to create and to pickle (joblib workers). ``store.Cache`` adds what concerns the store as a
    whole: its listing, full checks, clearing and budget.

    Parameters
    ----------
    root : str or os.PathLike
        The cache folder, usually ``store.cache_dir(...)``; created on first write.

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
        return f"{type(self).__name__}({str(self.root)!r})"

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
            os.rmdir(tempfile.mkdtemp(prefix=TEMPORARY_PREFIX + "probe-", dir=folder))
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
        """(meta, arrays, stamp) of a complete item, None if absent; raises BrokenItem otherwise.

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
                raise BrokenItem(f"{META} is missing") from None
            return None
        except (OSError, ValueError) as e:
            raise BrokenItem(f"{META} is unreadable: {e}") from None
        try:
            if not isinstance(meta, dict):
                raise BrokenItem(f"{META} is not a JSON object")
            if verify and _META_CRC in meta and _meta_crc32(meta) != meta[_META_CRC]:
                raise BrokenItem(f"{META}: checksum mismatch (corrupted)")
            if meta.get("format") != FORMAT:
                raise BrokenItem(f"format {meta.get('format')!r}, expected {FORMAT}")
            if meta.get("key") != key or (kind is not None and meta.get("kind") != kind):
                raise BrokenItem(f"{META} names another item ({meta.get('kind')}/{meta.get('key')})")
            specs = meta["arrays"]
            stamp, signature = {}, []
            for name, spec in specs.items():
                if spec["file"] != f"{name}.npy":
                    raise BrokenItem(f"{META} names the file {spec['file']!r} for {name!r}")
                st = os.stat(path / spec["file"])
                if st.st_size != spec["file_bytes"]:
                    raise BrokenItem(f"{spec['file']} has {st.st_size} bytes, expected {spec['file_bytes']}")
                identity = [st.st_size, st.st_ino, st.st_mtime_ns, st.st_ctime_ns]
                stamp[spec["file"]] = [spec.get("file_crc32", spec["crc32"]), *identity,
                                       meta.get("created")]
                signature.append((spec["file"], *identity))
            check = verify and (fresh or _VERIFIED.get(str(path)) != tuple(signature))
            arrays = {}
            for name, spec in specs.items():
                if check and "file_crc32" in spec and _file_crc32(path / spec["file"]) != spec["file_crc32"]:
                    raise BrokenItem(f"{spec['file']}: checksum mismatch (corrupted)")
                a = np.load(path / spec["file"], mmap_mode="r", allow_pickle=False)
                if a.dtype.str != spec["dtype"] or list(a.shape) != spec["shape"] \
                        or not a.flags.c_contiguous:
                    raise BrokenItem(f"{spec['file']} holds {a.dtype.str} {list(a.shape)}, "
                                  f"expected {spec['dtype']} {spec['shape']}")
                if check and "file_crc32" not in spec and _crc32(a) != spec["crc32"]:
                    raise BrokenItem(f"{spec['file']}: checksum mismatch (corrupted data)")
                arrays[name] = a
        except BrokenItem:
            _VERIFIED.pop(str(path), None)
            raise
        except FileNotFoundError as e:
            _VERIFIED.pop(str(path), None)
            raise BrokenItem(f"{Path(e.filename).name} is missing") from None
        except Exception as e:  # whatever a damaged header makes numpy or json raise
            _VERIFIED.pop(str(path), None)
            raise BrokenItem(f"unreadable: {type(e).__name__}: {e}".splitlines()[0]) from None
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
            except BrokenItem as e:
                self._remove_broken(path, kind, key, str(e))
        finally:
            lock.release()

    def _remove_broken(self, path: Path, kind: str, key: str, problem: str) -> None:
        """Remove a broken item (the caller holds its lock) with a one-line CacheWarning."""
        self._bury(path, key, problem)
        remove_tree(path)
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
            records = [*self._damaged(key),
                       {"found": time.time(), "problem": problem, "inodes": inodes, "created": created}]
            folder = self.root / DAMAGED
            folder.mkdir(parents=True, exist_ok=True)
            temporary = folder / f"{TEMPORARY_PREFIX}{key}-{os.getpid()}-{secrets.token_hex(4)}"
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
        except BrokenItem as e:
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
        except BrokenItem:
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
            except BrokenItem as e:
                self._remove_broken(path, kind, key, str(e))
            self.misses += 1
            arrays = _normalize(compute(), kind)
            try:
                self._write(path, kind, key, params, arrays)
                found = self._open(path, kind, key, verify=True, fresh=True)
            except (OSError, BrokenItem) as e:
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
        if not NAME_PATTERN.fullmatch(kind) or not KEY_PATTERN.fullmatch(key):
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
        except BrokenItem as e:
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
        tmp = path.parent / f"{TEMPORARY_PREFIX}{key}-{os.getpid()}-{secrets.token_hex(4)}"
        for attempt in range(3):  # a prune may remove the empty <kind>/<xx> folder between the two
            path.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.mkdir(tmp)
                break
            except FileNotFoundError:
                if attempt == 2:
                    raise
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
                    "params": canonical_value(params, "params")}
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
                except BrokenItem:
                    pass
                remove_tree(path)
                os.rename(tmp, path)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def _normalize(arrays: Any, kind: str) -> dict[str, np.ndarray]:
    """Check what ``compute`` returned; arrays made C-contiguous (not copied if they are)."""
    import numpy as np  # not at the top: see the module docstring
    if not isinstance(arrays, Mapping) or not arrays:
        raise TypeError(f"compute for cache kind {kind!r} must return a non-empty dict of "
                        f"arrays, not {type(arrays).__name__}")
    out = {}
    for name, a in arrays.items():
        check_name(name, "array name")
        if name == META.removesuffix(".json"):
            raise ValueError(f"invalid array name {name!r}: reserved")
        if not isinstance(a, np.ndarray):
            raise TypeError(f"compute for {kind!r} returned {type(a).__name__} for {name!r}, "
                            "not a numpy array")
        if a.dtype.kind not in ALLOWED_DTYPE_KINDS:
            raise TypeError(f"array {name!r} has dtype {a.dtype}; only bool and numeric "
                            "arrays are stored")
        out[name] = a if a.flags.c_contiguous else np.array(a, order="C")
    return out


def remove_tree(path: Path) -> bool:
    """Remove an item folder: rename it to a ``.del-`` name (atomic), then delete it.
    False if it was not there (someone else removed it)."""
    trash = path.parent / f"{TRASH_PREFIX}{path.name}-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        os.rename(path, trash)
    except FileNotFoundError:
        return False
    shutil.rmtree(trash, ignore_errors=True)
    return True

