"""index.json and the checks of which frames are done: each frame file's stamp (size, inode, times,
BLAKE2b digest) recorded as it is written, and compared, with the cache items the frame was made from,
when a run resumes or verifies (docs/runs.md, "Resume").

Nothing here imports numpy or a stage (``record.nothing_to_do`` decides a resume from it).
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

from pipeline.cache.store import Cache
from pipeline.config.parse import Config
from pipeline.core.errors import RunError
from pipeline.run.folder import INDEX_FILE, frame_files

__all__ = ["INDEX_FORMAT", "FrameWarning", "file_digest", "file_stamp", "file_problem", "FrameCheck", "check_frames",
           "verify_run", "read_index", "write_index"]

INDEX_FORMAT = 1
"""index.json's format; an index of another is not read (its frames are rendered again)."""


class FrameWarning(UserWarning):
    """A frame found damaged, or made from a cache item found damaged since: rendered again."""


def file_digest(path: str | os.PathLike[str]) -> str:
    """BLAKE2b (16 bytes, hex) of a file's bytes.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    str
        32 hex digits.
    """
    with open(path, "rb") as f:
        return hashlib.file_digest(f, lambda: hashlib.blake2b(digest_size=16)).hexdigest()


def file_stamp(path: Path) -> dict:
    """What index.json records of a frame file just written.

    Unchanged inode and times, the file is taken as it was (``file_problem``).

    Parameters
    ----------
    path : pathlib.Path
        The file.

    Returns
    -------
    dict
        ``name``, ``bytes`` (its size [B]), ``blake2b`` (``file_digest``) and ``stat``: its inode and
        modification and change times [ns].
    """
    digest = file_digest(path)
    st = os.stat(path)
    return {"name": path.name, "bytes": st.st_size, "blake2b": digest,
            "stat": [st.st_ino, st.st_mtime_ns, st.st_ctime_ns]}


def file_problem(path: Path, stamp: dict, *, full: bool) -> tuple[str | None, dict | None]:
    """What is wrong with a frame file against its stamp, and its fresh stamp.

    The digest is computed only when the size, inode or times differ from ``stamp``, or with
    ``full``.

    Parameters
    ----------
    path : pathlib.Path
        The file.
    stamp : dict
        Its entry in index.json (``file_stamp``).
    full : bool
        Compare the digest whatever the stamp says.

    Returns
    -------
    tuple of (str or None, dict or None)
        The problem in words or None; and the stamp with the file's current inode and times when
        its bytes were read and found as recorded under another inode or times, else None.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "is missing", None
    except OSError as exc:
        return f"is unreadable ({exc.strerror or exc})", None
    if st.st_size != stamp["bytes"]:
        return f"has {st.st_size} bytes, not the {stamp['bytes']} written (truncated or replaced)", None
    identity = [st.st_ino, st.st_mtime_ns, st.st_ctime_ns]
    if not full and identity == stamp["stat"]:
        return None, None
    try:
        digest = file_digest(path)
    except OSError as exc:
        return f"is unreadable ({exc.strerror or exc})", None
    if digest != stamp["blake2b"]:
        return "holds other bytes than those written (corrupted or replaced)", None
    return None, (None if identity == stamp["stat"] else {**stamp, "stat": identity})


@dataclass(frozen=True)
class FrameCheck:
    """The frames of a run folder for one config (``check_frames``). Other frames have no files yet.

    Attributes
    ----------
    done : dict
        {frame: its index.json entry}: files as written, by this config, from sound cache items.
    damaged : dict
        {frame: problem}: files not as written (truncated, corrupted, replaced, missing,
        unreadable), or made from a cache item found damaged since.
    foreign : dict
        {frame: why}: files there but not recorded for this config (made by another config, or
        not in index.json).
    """

    done: dict
    damaged: dict
    foreign: dict


def check_frames(config: Config, digest: str, store: Cache, index: dict, *,
                 full: bool = False, repair: bool = True) -> FrameCheck:
    """Check every frame of the animation against the frames of index.json.

    A file whose size, inode and times are as recorded is taken as written (nothing is read);
    otherwise, or with ``full``, its BLAKE2b digest is compared. Each cache item a done frame
    was made from is looked at the same way (``store.Cache.recheck``; fully with ``full``).
    Entries whose files or items were read and found as recorded get their new stamps in ``index``.

    Parameters
    ----------
    config : settings.Config
        The run's config.
    digest : str
        The resolved config's hash (``Config.digest``).
    store : store.Cache
        The cache the frames were made from.
    index : dict
        {frame as text: entry} of index.json (``read_index``); updated in place.
    full : bool, optional
        Compare every digest, of files and cache items.
    repair : bool, optional
        Remove cache items found damaged, so that they are computed again.

    Returns
    -------
    FrameCheck
        The done, damaged and foreign frames.
    """
    done, damaged, foreign = {}, {}, {}
    items = {}  # (item, stamp as JSON) -> problem or None, each looked at once
    for frame in range(config.animation.frames):
        files = frame_files(config, frame)
        entry = index.get(str(frame))
        try:
            if entry is None or entry["config_hash"] != digest:
                if any(path.exists() for path in files):
                    foreign[frame] = ("not recorded in index.json" if entry is None
                                      else "made by another config")
                continue
            problem = None
            for path, kind in zip(files, ("exr", "png")):
                problem, fresh = file_problem(path, entry["files"][kind], full=full)
                if problem:
                    problem = f"{path.name} {problem}"
                    break
                if fresh:
                    entry["files"][kind] = fresh
            for item, stamp in entry["items"].items():
                if problem:
                    break
                tag = (item, json.dumps(stamp, sort_keys=True))
                if tag not in items:
                    items[tag] = store.recheck(item, stamp, fresh=full, repair=repair)
                if items[tag]:
                    problem = f"made from {items[tag]}"
                elif item in store.served:
                    entry["items"][item] = store.served[item]
        except (KeyError, IndexError, TypeError, AttributeError, ValueError):
            problem = "its entry in index.json is unreadable"
        if problem:
            damaged[frame] = problem
        else:
            done[frame] = entry
    return FrameCheck(done, damaged, foreign)


def verify_run(config: Config, *, store: Cache) -> FrameCheck:
    """Check a run folder without writing anything.

    Every frame file's digest and every cache item the frames were made from, fully.

    Parameters
    ----------
    config : settings.Config
        The run's config.
    store : store.Cache
        The cache the frames were made from.

    Returns
    -------
    FrameCheck
        The done, damaged and foreign frames.
    """
    index = read_index(config.output.folder)
    return check_frames(config, config.digest(), store, index, full=True, repair=False)


def read_index(folder: Path) -> dict:
    """The frames recorded in the folder's index.json.

    Parameters
    ----------
    folder : pathlib.Path
        The run folder.

    Returns
    -------
    dict
        {frame as text: entry}; empty when there is no index, or, with a FrameWarning, when it is
        unreadable or of another format (its frames are then rendered again).
    """
    path = folder / INDEX_FILE
    try:
        document = json.loads(path.read_bytes())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        document = exc
    if not (isinstance(document, dict) and document.get("format") == INDEX_FORMAT
            and isinstance(document.get("frames"), dict)):
        warnings.warn(f"{path} is unreadable or of another format; its frames are not taken "
                      "as done", FrameWarning, stacklevel=3)
        return {}
    return document["frames"]


def write_index(folder: Path, index: dict, encoded: dict | None = None) -> None:
    """index.json, written atomically (a temporary name, then renamed).

    Parameters
    ----------
    folder : pathlib.Path
        The run folder.
    index : dict
        {frame as text: entry}.
    encoded : dict, optional
        {frame as text: its entry's JSON}, kept by a caller that writes the index again as each
        frame lands, so that each entry is encoded once (the whole index encoded at each of 240
        frames took 2.7 s of the command's CPU): an entry not in it is encoded and added. A caller
        that replaces an entry removes its text. The file's bytes are the same either way.

    Raises
    ------
    RunError
        Naming the file if it cannot be written.
    """
    path = folder / INDEX_FILE
    temporary = path.with_name(f".{INDEX_FILE}.tmp-{os.getpid()}")
    try:
        encoded = {} if encoded is None else encoded
        for key, entry in index.items():
            if key not in encoded:
                encoded[key] = json.dumps(entry, separators=(",", ":"))
        # json.dumps({"format": INDEX_FORMAT, "frames": index}, separators=(",", ":")), entry by entry
        frames = ",".join(f"{json.dumps(key)}:{encoded[key]}" for key in index)
        temporary.write_text(f'{{"format":{json.dumps(INDEX_FORMAT)},"frames":{{{frames}}}}}\n')
        temporary.replace(path)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise RunError(f"{path}: cannot write ({exc.strerror or exc})") from None
