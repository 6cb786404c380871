"""The run folder: its files' names, index.json and run.json, the checks of which frames are
done, and the resume that finds nothing to do (docs/runs.md, "The run folder", "Resume").

Nothing here imports numpy or a stage, so that a resume with nothing to do is decided in a
fraction of a second (``nothing_to_do``); ``run`` renders what is left.

Why one module: the folder's files (their names, index.json, run.json) and the checks of which
frames are done are one format, written by a render and read by the resume; split, each part
would import the others' names. Most of its length is its numpydoc docstrings.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import platform
import re
import time
import warnings
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path

import filelock

from . import __version__, paths
from .cache import Cache
from .settings import Config
from .cores import jobs_and_threads
from .errors import RunError

__all__ = ["RUN_FILE", "MAX_RUNS", "INDEX_FILE", "INDEX_FORMAT", "LOCK_FILE", "VERSIONED", "FrameWarning",
           "parse_frames", "frame_files", "video_file", "current_video", "file_digest", "file_stamp", "file_problem",
           "FrameCheck", "check_frames", "verify_run", "make_folder", "check_folder", "missing_folders",
           "remove_if_empty", "check_outputs", "remove_temporaries", "read_index", "write_index", "read_run_file",
           "resolved_config", "write_run_file", "RunSummary", "nothing_to_do"]

RUN_FILE = "run.json"
"""The run's record in its folder (docs/runs.md, "The run folder")."""
MAX_RUNS = 100
"""run.json keeps the record of this many latest renders of a config. [count]"""
INDEX_FILE = "index.json"
"""The done frames' record, written as each frame is done."""
INDEX_FORMAT = 1
"""index.json's format; an index of another is not read (its frames are rendered again)."""
LOCK_FILE = ".sunshade.lock"
"""The lock a run holds on its folder."""
VERSIONED = ("numpy", "scipy", "OpenImageIO", "joblib", "imageio", "imageio-ffmpeg", "PyYAML",
             "ephem", "filelock", "dask", "distributed")
"""The packages whose versions run.json records."""


class FrameWarning(UserWarning):
    """A frame found damaged, or made from a cache item found damaged since: rendered again."""


def parse_frames(text: str, count: int) -> tuple[int, ...]:
    """Frame indices from a list like ``0-47,100`` (ranges inclusive), sorted and unique.

    Parameters
    ----------
    text : str
        The list (--frames).
    count : int
        Frames in the animation; every index must lie in 0..count-1.

    Returns
    -------
    tuple of int
        The frames, sorted, each once.

    Raises
    ------
    RunError
        Naming the bad part.
    """
    frames = set()
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part[1:]:
                first, last = (int(v) for v in part.split("-", 1) if v.strip())
            else:
                first = last = int(part)
        except ValueError:
            raise RunError(f"--frames: {part!r} is not a frame or a range like 0-47") from None
        if last < first:
            raise RunError(f"--frames: the range {part} runs backwards")
        if first < 0 or last >= count:
            raise RunError(f"--frames: {part} is outside 0..{count - 1} (animation.frames is {count})")
        frames.update(range(first, last + 1))
    return tuple(sorted(frames))


def frame_files(config: Config, frame: int) -> tuple[Path, Path]:
    """(EXR, PNG) paths of an output frame: ``NAME.0007.exr``.

    The number is zero-padded to four digits or to the width of the last frame's number.

    Parameters
    ----------
    config : config.Config
        The run's config.
    frame : int
        The frame's index.

    Returns
    -------
    tuple of (pathlib.Path, pathlib.Path)
        The EXR's and the PNG's paths in ``output.folder``.
    """
    width = max(4, len(str(config.animation.frames - 1)))
    stem = f"{config.output.name}.{frame:0{width}d}"
    return config.output.folder / f"{stem}.exr", config.output.folder / f"{stem}.png"


def video_file(config: Config) -> Path | None:
    """The run's video file.

    Parameters
    ----------
    config : config.Config
        The run's config.

    Returns
    -------
    pathlib.Path or None
        ``NAME.VIDEO`` (``output.video`` the suffix) in ``output.folder``, or None when ``output.video`` is none.
    """
    if config.output.video == "none":
        return None
    return config.output.folder / f"{config.output.name}.{config.output.video}"


def current_video(config: Config, digest: str, previous: dict, *, force: bool = False) -> dict | None:
    """The previous run.json's video entry if the video on disk is of this config and all its frames.

    Parameters
    ----------
    config : config.Config
        The run's config.
    digest : str
        The resolved config's hash (``Config.digest``).
    previous : dict
        The previous run.json (empty when there is none).
    force : bool, optional
        Take no video as current (it is made again).

    Returns
    -------
    dict or None
        The entry, or None when the video must be made (also when the config makes no video).
    """
    path, made = video_file(config), previous.get("video") or {}
    if (path is not None and not force and made.get("config_hash") == digest
            and made.get("frames") == config.animation.frames
            and path.is_file() and path.stat().st_size == made.get("bytes")):
        return made
    return None


def file_digest(path) -> str:
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
    was made from is looked at the same way (``cache.Cache.recheck``; fully with ``full``).
    Entries whose files or items were read and found as recorded get their new stamps in ``index``.

    Parameters
    ----------
    config : config.Config
        The run's config.
    digest : str
        The resolved config's hash (``Config.digest``).
    store : cache.Cache
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
    config : config.Config
        The run's config.
    store : cache.Cache
        The cache the frames were made from.

    Returns
    -------
    FrameCheck
        The done, damaged and foreign frames.
    """
    index = read_index(config.output.folder)
    return check_frames(config, config.digest(), store, index, full=True, repair=False)


def make_folder(folder: Path) -> Path:
    """Create the output folder (and its parents).

    Parameters
    ----------
    folder : pathlib.Path
        The output folder.

    Returns
    -------
    pathlib.Path
        ``folder``.

    Raises
    ------
    RunError
        If it cannot be written.
    """
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe-{id(folder)}"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        raise RunError(f"{folder}: cannot write the output folder ({exc.strerror or exc})") from None
    return folder


def check_folder(folder: Path) -> None:
    """Raise RunError unless ``folder`` could be created and written, touching nothing.

    The nearest folder that exists must be a writable folder.

    Parameters
    ----------
    folder : pathlib.Path
        The output folder.
    """
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise RunError(f"{folder}: is a file, not a folder" if existing == folder
                       else f"{folder}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise RunError(f"{folder}: cannot write the output folder ({existing} is not writable)")


def missing_folders(folder: Path) -> list[Path]:
    """``folder`` and those of its parents that do not exist yet, innermost first.

    Parameters
    ----------
    folder : pathlib.Path
        The output folder.

    Returns
    -------
    list of pathlib.Path
        The folders a run would create.
    """
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def remove_if_empty(folders: list[Path]) -> None:
    """Remove the folders that a failed run made and left empty but for its lock file.

    So that a failing run leaves nothing new behind.

    Parameters
    ----------
    folders : list of pathlib.Path
        The folders the run made, innermost first (``missing_folders``).
    """
    for folder in folders:
        with contextlib.suppress(OSError):
            (folder / LOCK_FILE).unlink(missing_ok=True)
            folder.rmdir()


def check_outputs(config: Config) -> None:
    """Raise RunError unless the run's files could be written, touching nothing.

    The folder (``check_folder``), every name within the system's limits (``paths.problem``), and no
    frame, video, lock or run.json name taken by a folder.

    Parameters
    ----------
    config : config.Config
        The run's config.
    """
    folder = config.output.folder
    if problem := paths.problem(folder):
        raise RunError(f"{folder}: {problem}")
    check_folder(folder)
    names = {RUN_FILE, LOCK_FILE} | ({video_file(config).name} if video_file(config) else set())
    for path in (*frame_files(config, config.animation.frames - 1), *(folder / n for n in names)):
        if problem := paths.problem(path):
            raise RunError(f"{path}: {problem}")
    if folder.is_dir():
        frame = re.compile(rf"{re.escape(config.output.name)}\.\d+\.(exr|png)")
        for entry in os.scandir(folder):
            if (entry.name in names or frame.fullmatch(entry.name)) and entry.is_dir():
                raise RunError(f"{entry.path}: is a folder where the run writes a file; move it")


def remove_temporaries(folder: Path) -> None:
    """Remove the half-written files a killed run left (we hold the folder's lock).

    Parameters
    ----------
    folder : pathlib.Path
        The run folder.
    """
    for path in folder.glob(".*.tmp-*"):
        path.unlink(missing_ok=True)


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


def write_index(folder: Path, index: dict) -> None:
    """index.json, written atomically (a temporary name, then renamed).

    Parameters
    ----------
    folder : pathlib.Path
        The run folder.
    index : dict
        {frame as text: entry}.

    Raises
    ------
    RunError
        Naming the file if it cannot be written.
    """
    path = folder / INDEX_FILE
    temporary = path.with_name(f".{INDEX_FILE}.tmp-{os.getpid()}")
    try:
        temporary.write_text(json.dumps({"format": INDEX_FORMAT, "frames": index},
                                        separators=(",", ":")) + "\n")
        temporary.replace(path)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise RunError(f"{path}: cannot write ({exc.strerror or exc})") from None


def read_run_file(folder: Path) -> dict:
    """The folder's run.json.

    Parameters
    ----------
    folder : pathlib.Path
        The run folder.

    Returns
    -------
    dict
        Its document; empty when it is missing or unreadable.
    """
    try:
        return json.loads((folder / RUN_FILE).read_text())
    except (OSError, ValueError):
        return {}


def resolved_config(config: Config, plan) -> dict:
    """The config as run, so that run.json says what was rendered.

    With the ground windows and the camera the plan placed where the config left them out.

    Parameters
    ----------
    config : config.Config
        The run's config.
    plan : plan.RunPlan
        The run's plan (its windows, camera and ``auto``).

    Returns
    -------
    dict
        The config's values as JSON-ready dicts (``dataclasses.asdict``), windows [m] and camera
        (position [m], yaw and pitch) as placed, and ``placed``: what the plan placed.
    """
    values = asdict(config)
    values.pop("lines")
    values["ground"]["window"] = list(plan.window.extent)
    if plan.sun_window is not None:
        values["ground"]["sun_window"] = list(plan.sun_window.extent)
        values["ground"]["sun_pixel"] = plan.sun_window.pixel
    view = plan.camera
    values["camera"].update(position=list(view.position), yaw=view.yaw, pitch=view.pitch,
                            look_at=None if "camera" in plan.auto else values["camera"]["look_at"])
    values["placed"] = list(plan.auto)
    return values


def write_run_file(config, resolved: dict, digest, records, video, timings, *, jobs, threads, scheduler,
                   rendered, source_hash=None):
    """run.json, written atomically.

    It holds the resolved config (windows and camera as placed: ``resolved_config``) and its hash,
    the hash of the config as written (``resolve.source_digest``; None: not known), versions, the
    command's settings, timings, per done frame S and the sun and moon (degrees), and ``runs``: one
    entry (time, frames rendered, settings, timings) per render that did work, the earlier ones
    kept (MAX_RUNS), so that a re-run that finds every frame done leaves the record of the runs
    that made them.

    Parameters
    ----------
    config : config.Config
        The run's config.
    resolved : dict
        The config as run (``resolved_config``).
    digest : str
        The resolved config's hash.
    records : dict
        {frame: its record, or None when not done}.
    video : dict or None
        The video's entry, None when none was made.
    timings : dict
        {phase: seconds [s]}.
    jobs : int
        Processes at once.
    threads : int
        FFT threads each.
    scheduler : str or None
        The Dask scheduler's address, None for a local run.
    rendered : sequence of int
        The frames this render made.
    source_hash : str, optional
        ``resolve.source_digest`` of the config as written.
    """
    versions = {"python": platform.python_version(), "sunshade": __version__}
    for name in VERSIONED:
        with contextlib.suppress(metadata.PackageNotFoundError):
            versions[name] = metadata.version(name)
    previous = read_run_file(config.output.folder)
    runs = previous.get("runs", []) if previous.get("config_hash") == digest else []
    if not runs and previous.get("config_hash") == digest and "timings" in previous:
        runs = [{"frames": None, "settings": previous.get("settings"), "timings": previous["timings"]}]
    runs = (runs + [{"finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                     "frames": len(rendered), "video": "video" in timings,
                     "settings": {"jobs": jobs, "threads": threads, "scheduler": scheduler},
                     "timings": timings}])[-MAX_RUNS:]
    worked = [run for run in runs if run["frames"] is None or run["frames"] or run.get("video")]
    last = worked[-1] if worked else runs[-1]
    document = {
        "config_file": str(config.path),
        "config_hash": digest,
        "source_hash": source_hash,
        "config": resolved,
        "versions": versions,
        "settings": last["settings"],
        "timings": last["timings"],
        "runs": runs,
        "frames": [record for record in records.values() if record is not None],
        "video": video,
    }
    path = config.output.folder / RUN_FILE
    temporary = path.with_name(f".{RUN_FILE}.tmp-run")
    temporary.write_text(json.dumps(document, indent=1, default=str) + "\n")
    temporary.replace(path)


@dataclass(frozen=True)
class RunSummary:
    """What a run did.

    Attributes
    ----------
    rendered : tuple of int
        Frames rendered.
    skipped : tuple of int
        Frames found done.
    video : pathlib.Path or None
        The video, None when not made.
    timings : dict
        {phase: seconds [s]}.
    pruned : tuple
        The cache items the cache's budget removed at the end of the run (``Cache.prune``).
    """

    rendered: tuple[int, ...]
    skipped: tuple[int, ...]
    video: Path | None
    timings: dict
    pruned: tuple = ()
    """The cache items the cache's budget removed at the end of the run (``Cache.prune``)."""


def nothing_to_do(config: Config, store: Cache, frames=None, *, jobs=None, scheduler=None,
                  source_hash: str | None = None) -> RunSummary | None:
    """A resume with nothing to do, decided from the files' stamps alone (no numpy, no plan).

    When every frame of ``frames`` is done for this config (``check_frames``, nothing found damaged)
    and the video is made or not due yet, the run is recorded in run.json as ``run.render_run``
    records a render that found everything done, and its RunSummary returned.

    ``config`` may be the config as written, not resolved, with its ``source_hash``
    (``resolve.source_digest``): when run.json records that same hash, the resolved config's
    hash is the one it records beside it, and nothing is resolved (no ephemeris, no pvlib).

    Parameters
    ----------
    config : config.Config
        The run's config, resolved or as written (with ``source_hash``).
    store : cache.Cache
        The cache the frames were made from.
    frames : iterable of int, optional
        The frames asked for; default all.
    jobs : int, optional
        Processes at once, recorded in run.json (default ``render.jobs``, else one per core).
    scheduler : str, optional
        The Dask scheduler's address, recorded in run.json.
    source_hash : str, optional
        ``resolve.source_digest`` of the config as written.

    Returns
    -------
    RunSummary or None
        What the run did; None when there is anything else to do or to say (work, damage, a busy
        folder, no run.json of this config yet): ``run.render_run`` then does it.
    """
    started = time.perf_counter()
    folder = config.output.folder
    previous = read_run_file(folder)
    digest = config.digest()
    if source_hash is not None and previous.get("source_hash") == source_hash:
        digest = previous.get("config_hash")
    if previous.get("config_hash") != digest or "config" not in previous:
        return None
    count = config.animation.frames
    frames = tuple(range(count)) if frames is None else tuple(frames)
    lock = filelock.FileLock(folder / LOCK_FILE, timeout=0)
    try:
        lock.acquire()
    except filelock.Timeout:
        return None
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            index = read_index(folder)
            before = json.dumps(index, sort_keys=True)
            checked = check_frames(config, digest, store, index, repair=False)
        if (caught or checked.damaged or any(f not in checked.done for f in frames)
                or json.dumps(index, sort_keys=True) != before):
            return None
        made = current_video(config, digest, previous)
        if video_file(config) is not None and made is None and len(checked.done) == count:
            return None  # the video is due
        jobs, threads = jobs_and_threads(jobs or config.render.jobs, scheduler)
        records = {f: checked.done[f]["record"] if f in checked.done else None for f in range(count)}
        timings = {"check": time.perf_counter() - started}
        timings["total"] = timings["check"]
        write_run_file(config, previous["config"], digest, records, made, timings,
                       jobs=jobs, threads=threads, scheduler=scheduler, rendered=(),
                       source_hash=previous.get("source_hash"))
    finally:
        lock.release()
    return RunSummary((), frames, video_file(config) if made else None, timings)
