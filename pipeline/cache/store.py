"""The cache as a whole: where it is and its budget, and ``Cache``, the store of items
(``items.ItemStore``) with its listing, full checks, clearing, pruning to the budget and the
keys live runs use (docs/runs.md, "The cache on disk" and "The cache's budget").

numpy is imported only where a size may be a numpy integer, so that checking a run's items by
their files' stamps (a resume with nothing to do) starts without it.
"""

from __future__ import annotations

import builtins
import contextlib
import json
import os
import re
import secrets
import shutil
from collections.abc import Collection, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout

from pipeline.cache.items import META, TEMPORARY_PREFIX, TRASH_PREFIX, BrokenItem, ItemStore, remove_tree
from pipeline.cache.keys import DAMAGED, KEY_PATTERN, LOCKS, NAME_PATTERN

__all__ = ["ENV_VAR", "BUDGET_ENV_VAR", "DEFAULT_BUDGET", "RUNS", "cache_dir", "cache_budget", "parse_size",
           "CacheItem", "Cache"]

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
    params: dict[str, Any] | None = None


class Cache(ItemStore):
    """The store under one root folder. Cheap to create and to pickle (joblib workers).

    Items are read, computed and written as ``items.ItemStore`` does; a Cache also lists, checks,
    clears and prunes them, and names those a run uses.

    Parameters
    ----------
    root : str or os.PathLike
        The cache folder, usually ``cache_dir(...)``; created on first write.

    Attributes
    ----------
    root, hits, misses, repaired, served
        As in ``items.ItemStore``.
    """

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
                    or not NAME_PATTERN.fullmatch(kind_dir.name):
                continue
            for prefix_dir in sorted(kind_dir.iterdir()):
                if not re.fullmatch(r"[0-9a-f]{2}", prefix_dir.name) or not prefix_dir.is_dir() \
                        or prefix_dir.is_symlink():
                    yield "stray", kind_dir.name, None, prefix_dir
                    continue
                for entry in sorted(prefix_dir.iterdir()):
                    name = entry.name
                    folder = entry.is_dir() and not entry.is_symlink()
                    if KEY_PATTERN.fullmatch(name) and name[:2] == prefix_dir.name and folder:
                        yield "item", kind_dir.name, name, entry
                    elif name.startswith((TEMPORARY_PREFIX, TRASH_PREFIX)) and folder:
                        key = name[5:69] if KEY_PATTERN.fullmatch(name[5:69]) else None
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

    def strays(self, *, remove: bool = False) -> builtins.list[tuple[Path, str]]:
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
                    remove_tree(path)
                elif remove:
                    path.unlink(missing_ok=True)
        return found

    def verify(self, *, remove: bool = False) -> builtins.list[tuple[CacheItem, str]]:
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
            except BrokenItem as e:
                problems.append((item, str(e)))
                if remove:
                    self._bury(item.path, item.key, str(e))
                    remove_tree(item.path)
        return problems

    def _remove_stale(self) -> None:
        """Remove ``.del-`` folders, and ``.tmp-`` folders whose key lock is free (their
        writer is dead: a live writer holds the lock until its rename)."""
        for what, _kind, key, path in list(self._walk()):
            (self.root / LOCKS).mkdir(exist_ok=True)
            if what == TRASH_PREFIX or (what == TEMPORARY_PREFIX and key is None):
                shutil.rmtree(path, ignore_errors=True)
            elif what == TEMPORARY_PREFIX:
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
            if kind_dir.name == LOCKS or not NAME_PATTERN.fullmatch(kind_dir.name) \
                    or not kind_dir.is_dir() or kind_dir.is_symlink():
                continue
            emptied = False
            for prefix_dir in kind_dir.iterdir():
                if re.fullmatch(r"[0-9a-f]{2}", prefix_dir.name) and prefix_dir.is_dir():
                    emptied |= _rmdir_if_empty(prefix_dir)
            if emptied:
                _rmdir_if_empty(kind_dir)

    def clear(self) -> builtins.list[CacheItem]:
        """Remove every item, leftover temporary folder and free lock file.

        Files in the root that are not the cache's (e.g. FFTW wisdom) are kept.

        Returns
        -------
        list of CacheItem
            The items removed.
        """
        self._remove_stale()
        removed = [item for item in self.list() if remove_tree(item.path)]
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

    def prune(self, max_bytes: int, *, keep: Collection[str] = frozenset()) -> builtins.list[CacheItem]:
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
            if remove_tree(item.path):
                removed.append(item)
            total -= item.bytes
        self._remove_empty_folders()
        return removed

    @contextlib.contextmanager
    def in_use(self, keys: Iterable[str]) -> Iterator[None]:
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
            temporary = folder / f"{TEMPORARY_PREFIX}{name}.json"
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


def _rmdir_if_empty(path: Path) -> bool:
    try:
        path.rmdir()
    except OSError:
        return False
    return True
