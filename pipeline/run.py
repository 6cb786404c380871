"""A run: a config's animation rendered into a folder of frames, then its video, resumably.

The folder holds ``NAME.0000.exr`` (scene-linear) and ``NAME.0000.png`` (display) per frame,
``NAME.mp4`` (or ``.gif``), ``run.json`` and ``index.json``. Every file is written under a
temporary name and renamed into place, the PNG after the EXR, both carrying the config's hash.
When a frame's files are written, ``index.json`` records the config hash, the BLAKE2b digest,
size, inode and times of each file, and the cache items the frame was made from (their
checksums and files' identities; ``cache.Cache.served``). A frame is done when its entry has
the hash of the config being run, both files are as recorded and its cache items have not been
found damaged since (docs/runs.md, Resume). A re-run skips done frames and the cached cycle
products, so a run killed at any point and run again ends with the same bytes.

Parallel: joblib over cycle frames and over output frames, each task with ``threads`` FFT
threads; with a scheduler address the same tasks run on a dask.distributed cluster through
joblib's Dask backend (the cache and the output folder on a file system all workers share).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import hashlib
import json
import logging
import os
import platform
import re
import threading
import time
import warnings
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path

import filelock
import joblib
import numpy as np

from . import __version__, cache, io, paths
from .composite import display
from .config import Config
from .errors import RunError, SunshadeError, portable
from .cycle import cycle_phase, record_config_items
from .frame import render_frame
from .framing import framing_warnings
from .lighting import with_exposures
from .plan import RunPlan, check_inputs, default_workers

MAX_JOBS_PER_CORE = 4
"""Most worker processes a local run starts per core (--jobs, render.jobs): each holds a
frame's rasters."""
RUN_FILE = "run.json"
MAX_RUNS = 100
"""run.json keeps the record of this many latest renders of a config."""
INDEX_FILE = "index.json"
INDEX_FORMAT = 1
LOCK_FILE = ".sunshade.lock"
VERSIONED = ("numpy", "scipy", "OpenImageIO", "joblib", "imageio", "imageio-ffmpeg", "PyYAML",
             "ephem", "filelock", "dask", "distributed")


class FrameWarning(UserWarning):
    """A frame found damaged, or made from a cache item found damaged since: rendered again."""


def parse_frames(text: str, count: int) -> tuple[int, ...]:
    """Frame indices from a list like ``0-47,100`` (ranges inclusive), sorted and unique; every
    one must lie in 0..count-1. Raises RunError naming the bad part."""
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
    """(EXR, PNG) paths of output ``frame``: ``NAME.0007.exr``, the number zero-padded to four
    digits or to the width of the last frame's number."""
    width = max(4, len(str(config.animation.frames - 1)))
    stem = f"{config.output.name}.{frame:0{width}d}"
    return config.output.folder / f"{stem}.exr", config.output.folder / f"{stem}.png"


def video_file(config: Config) -> Path | None:
    """The run's video file, or None when ``output.video`` is none."""
    if config.output.video == "none":
        return None
    return config.output.folder / f"{config.output.name}.{config.output.video}"


_RECORD = {"sunshade:config_hash": "config_hash", "sunshade:frame": "frame",
           "sunshade:sun_fraction": "sun_fraction", "sunshade:sun_azimuth_elevation": "sun",
           "sunshade:moon_azimuth_elevation": "moon", "sunshade:time_utc": "time_utc"}


def frame_record(config: Config, frame: int, digest: str) -> dict | None:
    """What a done frame's EXR says of itself (frame, S, sun and moon azimuth and elevation in
    degrees, UTC time), or None unless both its files are there and carry ``digest``."""
    exr, png = frame_files(config, frame)
    if not (exr.is_file() and png.is_file()):
        return None
    try:
        found = io.read_attributes(exr, list(_RECORD))
        png_hash = io.read_attributes(png, ["sunshade:config_hash"])["sunshade:config_hash"]
    except io.ImageError:
        return None
    if found["sunshade:config_hash"] != digest or png_hash != digest or found["sunshade:frame"] != frame:
        return None
    record = {_RECORD[k]: v for k, v in found.items() if v is not None}
    for key in ("sun", "moon"):
        if key in record:
            record[key] = {"azimuth": float(record[key][0]), "elevation": float(record[key][1])}
    record.pop("config_hash")
    return {"file": exr.stem, **record}


def frame_attributes(config: Config, result, digest: str) -> dict:
    """Metadata of a finished frame: what made it, and the sun and moon of that moment."""
    attributes = {
        "sunshade:config_hash": digest,
        "sunshade:version": __version__,
        "sunshade:frame": int(result.scene.frame),
        "sunshade:sun_fraction": float(result.sun_fraction),
        "sunshade:exposure": float(result.exposure),
    }
    for name, disc in (("sun", result.scene.sun), ("moon", result.scene.moon)):
        if disc is not None:
            attributes[f"sunshade:{name}_azimuth_elevation"] = (np.degrees(disc.azimuth),
                                                                np.degrees(disc.elevation))
    if result.scene.when is not None:
        attributes["sunshade:time_utc"] = result.scene.when.isoformat()
    return attributes


def file_digest(path) -> str:
    """BLAKE2b (16 bytes, hex) of a file's bytes."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, lambda: hashlib.blake2b(digest_size=16)).hexdigest()


def _file_stamp(path: Path) -> dict:
    """What index.json records of a frame file just written: name, size [B], digest, and its
    inode and modification and change times [ns] (unchanged, the file is taken as it was)."""
    digest = file_digest(path)
    st = os.stat(path)
    return {"name": path.name, "bytes": st.st_size, "blake2b": digest,
            "stat": [st.st_ino, st.st_mtime_ns, st.st_ctime_ns]}


def _file_problem(path: Path, stamp: dict, *, full: bool) -> tuple[str | None, dict | None]:
    """(problem in words or None, the stamp with the file's current inode and times when its
    bytes were read and found as recorded). The digest is computed only when the size,
    inode or times differ from ``stamp``, or with ``full``."""
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
    """The frames of a run folder for one config.

    done : {frame: its index.json entry} -- files as written, by this config, from sound
        cache items. damaged : {frame: problem} -- files not as written (truncated, corrupted,
        replaced, missing, unreadable), or made from a cache item found damaged since.
    foreign : {frame: why} -- files there but not recorded for this config (made by another
        config, or not in index.json). Other frames have no files yet.
    """

    done: dict
    damaged: dict
    foreign: dict


def check_frames(config: Config, digest: str, store: cache.Cache, index: dict, *,
                 full: bool = False, repair: bool = True) -> FrameCheck:
    """Check every frame of the animation against ``index`` (the frames of index.json).

    A file whose size, inode and times are as recorded is taken as written (nothing is read);
    otherwise, or with ``full``, its BLAKE2b digest is compared. Each cache item a done frame
    was made from is looked at the same way (``cache.Cache.recheck``; fully with ``full``).
    ``repair``: remove cache items found damaged, so that they are computed again. Entries
    whose files or items were read and found as recorded get their new stamps in ``index``.
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
                problem, fresh = _file_problem(path, entry["files"][kind], full=full)
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


def verify_run(config: Config, *, store: cache.Cache) -> FrameCheck:
    """Check a run folder without writing anything: every frame file's digest and every
    cache item the frames were made from, fully."""
    index = _read_index(config.output.folder)
    return check_frames(config, config.digest(), store, index, full=True, repair=False)


@dataclass(frozen=True)
class RunSummary:
    """What a run did: frames rendered and skipped, the video (None: not made), timings [s]."""

    rendered: tuple[int, ...]
    skipped: tuple[int, ...]
    video: Path | None
    timings: dict


def render_run(config: Config, *, frames: tuple[int, ...] | None = None, store: cache.Cache,
               jobs: int | None = None, scheduler: str | None = None, force: bool = False,
               progress=None, warn=None, cluster_timeout: float | None = None) -> RunSummary:
    """Render ``frames`` (default: all) of the config's animation into ``config.output.folder``:
    the cycle products they need, the frames not done yet (all with ``force``), then the video
    once every frame of the animation is done, and ``run.json``.

    jobs : processes at once (default ``render.jobs``, else one per core); each gets
        cores // jobs FFT threads (one on a cluster). scheduler : a dask.distributed scheduler
        address (``tcp://host:8786``) to run the tasks on instead. cluster_timeout : how long
        a lost cluster is waited for (default CLUSTER_TIMEOUT). [s]
    progress : called as ``progress(stage, done, total)`` with stage ``cycle``, ``frames`` or
        ``video``. warn : called with each one-line warning of the plan
        (``framing.framing_warnings``). Raises RunError, config.ConfigError, io.ImageError
        before any work.
    """
    started = time.perf_counter()
    timings = {}
    store = cache.Cache(store.root.absolute())  # workers elsewhere resolve no relative path
    plan = check_inputs(config)
    for line in framing_warnings(plan) if warn else ():
        warn(line)
    digest = config.digest()
    frames = tuple(range(config.animation.frames)) if frames is None else tuple(frames)
    if scheduler:
        _reach(scheduler)  # an unreachable scheduler fails before anything is written
    folder = _make_folder(config.output.folder)
    jobs = jobs or config.render.jobs or default_workers()
    threads = 1 if scheduler else max(1, default_workers() // jobs)
    lock = filelock.FileLock(folder / LOCK_FILE, timeout=0)
    try:
        lock.acquire()
    except filelock.Timeout:
        raise RunError(f"{folder}: another sunshade render is writing to this folder") from None
    try:
        _remove_temporaries(folder)
        if (folder / INDEX_FILE).is_dir():
            raise RunError(f"{folder / INDEX_FILE}: is a folder, not a file")
        index = _read_index(folder)
        before = json.dumps(index, sort_keys=True)
        checked = check_frames(config, digest, store, index)
        for frame, problem in sorted(checked.damaged.items()):
            action = "rendering it again" if force or frame in frames else "not done"
            warnings.warn(f"{frame_files(config, frame)[0].stem}: {problem}; {action}",
                          FrameWarning, stacklevel=2)
        if json.dumps(index, sort_keys=True) != before:
            _write_index(folder, index)
        records = {f: (checked.done[f]["record"] if f in checked.done else None)
                   for f in range(config.animation.frames)}
        todo = [f for f in frames if force or records[f] is None]
        timings["check"] = time.perf_counter() - started
        if todo:
            plan = with_exposures(plan, todo)
            with _backend(scheduler, cluster_timeout or CLUSTER_TIMEOUT):
                mark = time.perf_counter()
                cycle_phase(plan, store, jobs=jobs, workers=threads,
                            cycle_frames={f % config.canopy.cycle for f in todo},
                            progress=progress and (lambda done, total: progress("cycle", done, total)))
                timings["cycle"] = time.perf_counter() - mark
                record_config_items(plan, store)
                mark = time.perf_counter()
                stages = timings["frame_stages"] = {}
                for frame, seconds, entry, caught in _frame_phase(
                        plan, store, todo, digest, jobs=jobs, threads=threads,
                        progress=progress):
                    for category, text in caught:  # raised in a worker: said here, once
                        warnings.warn(text, category, stacklevel=2)
                    index[str(frame)] = entry
                    _write_index(folder, index)
                    records[frame] = entry["record"]
                    for stage, value in seconds.items():
                        stages[stage] = stages.get(stage, 0.0) + value
                timings["frames"] = time.perf_counter() - mark
        video = _video(config, digest, records, _read_run_file(folder), progress, timings,
                       force=force or bool(checked.damaged))
        timings["total"] = time.perf_counter() - started
        _write_run_file(config, plan, digest, records, video, timings, jobs=jobs, threads=threads,
                        scheduler=scheduler, rendered=todo)
    finally:
        lock.release()
    return RunSummary(tuple(todo), tuple(f for f in frames if f not in set(todo)),
                      video_file(config) if video else None, timings)


def _frame_phase(plan, store, todo, digest, *, jobs, threads, progress):
    """Render the ``todo`` frames in parallel; yields what ``_frame_task`` returns as each
    frame is written."""
    if progress:
        progress("frames", 0, len(todo))
    tasks = (joblib.delayed(_frame_task)(plan, frame, str(store.root), digest, threads)
             for frame in todo)
    results = joblib.Parallel(n_jobs=min(jobs, len(todo)), return_as="generator_unordered")(tasks)
    for done, result in enumerate(results, 1):
        yield result
        if progress:
            progress("frames", done, len(todo))


@portable
def _frame_task(plan: RunPlan, frame: int, root: str, digest: str, threads: int):
    """Render one frame and write its EXR, then its PNG. Returns (frame, stage seconds [s],
    its index.json entry, the warnings raised meanwhile as (category, text)): a worker's
    warnings are said by the process that runs the command."""
    config, timings = plan.config, {}
    store = cache.Cache(root)
    with warnings.catch_warnings(record=True) as caught:
        result = render_frame(plan, frame, store=store, workers=threads, timings=timings)
    mark = time.perf_counter()
    if not np.all(np.isfinite(result.radiance)):
        raise io.ImageError(config.path, f"frame {frame} overflowed; lower the sky's radiance")
    exr, png = frame_files(config, frame)
    io.write_exr(exr, result.radiance, frame_attributes(config, result, digest), half=config.output.half)
    picture = display(result.radiance, exposure=result.exposure, transform=config.camera.display,
                      balance=result.balance)
    io.write_png(png, picture, {"sunshade:config_hash": digest, "sunshade:frame": str(frame)})
    timings["write"] = time.perf_counter() - mark
    mark = time.perf_counter()
    entry = {"config_hash": digest, "files": {"exr": _file_stamp(exr), "png": _file_stamp(png)},
             "items": dict(store.served), "record": frame_record(config, frame, digest)}
    timings["digest"] = time.perf_counter() - mark
    return frame, timings, entry, [(w.category, str(w.message)) for w in caught]


def _video(config: Config, digest: str, records: dict, previous: dict, progress, timings, *,
           force) -> dict | None:
    """Encode the video from the PNG frames once every frame of the animation is done
    (``records`` has them all), unless the ``previous`` run.json says the video on disk is of
    this config. Returns its run.json entry."""
    path = video_file(config)
    if path is None:
        return None
    count = config.animation.frames
    made = previous.get("video") or {}
    if (not force and made.get("config_hash") == digest and made.get("frames") == count
            and path.is_file() and path.stat().st_size == made.get("bytes")):
        return made
    if any(record is None for record in records.values()):
        return None
    mark = time.perf_counter()

    def pictures():
        for frame in range(count):
            yield io.read_image(frame_files(config, frame)[1])
            if progress:
                progress("video", frame + 1, count)

    io.write_video(path, pictures(), fps=config.animation.fps)
    timings["video"] = time.perf_counter() - mark
    return {"file": path.name, "config_hash": digest, "frames": count, "bytes": path.stat().st_size}


CLUSTER_TIMEOUT = 30.0
"""How long a run waits for a lost Dask cluster (no scheduler, or no workers) before it ends
with one line saying how to resume. [s]"""


@contextlib.contextmanager
def _backend(scheduler: str | None, timeout: float = CLUSTER_TIMEOUT):
    """joblib's Dask backend on the cluster at ``scheduler`` for the block; local processes
    without one. A worker process that dies, or a cluster lost for ``timeout`` seconds [s]
    (``_Watchdog``), ends the block with a RunError saying how to resume."""
    if scheduler is None:
        try:
            yield
        except BrokenProcessPool as exc:
            raise RunError("a worker process died (killed, or out of memory?); done frames are "
                           "kept: run the same command again to resume") from exc
        return
    try:
        from distributed import Client
    except ImportError:
        raise RunError("--scheduler needs Dask: pip install 'sunshade[distributed]'") from None
    muted = logging.root.manager.disable  # Dask logs its reconnection errors: more lines
    logging.disable(logging.ERROR)
    try:
        try:
            client = Client(scheduler, timeout=f"{timeout}s")
        except Exception as exc:  # not an address, refused, timed out: said in many types
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise RunError(f"--scheduler {scheduler}: cannot reach the scheduler ({reason})") from None
        watchdog = _Watchdog(client, timeout)
        with client, joblib.parallel_config(backend="dask", wait_for_workers_timeout=timeout), \
                watchdog:
            try:
                yield
            except Exception as exc:
                lost = watchdog.lost or (client.status != "running" and "the scheduler is gone") \
                    or (isinstance(exc, concurrent.futures.CancelledError) and "tasks cancelled") \
                    or ("has no worker" in str(exc) and f"no workers for {timeout:g} s")
                if not lost or isinstance(exc, SunshadeError):
                    raise  # a worker's own error (a full disk, say): reported as with --jobs 1
                raise RunError(f"--scheduler {scheduler}: lost the cluster ({lost}); done frames "
                               "are kept: start the scheduler and workers and run the same "
                               "command again to resume") from None
    finally:
        logging.disable(muted)


class _Watchdog:
    """A thread that watches a Dask client for the block: after ``timeout`` seconds [s] with no
    workers or no scheduler, it records why in ``lost`` and closes the client, which cancels
    the tasks the run waits on."""

    def __init__(self, client, timeout: float):
        self.client, self.timeout, self.lost = client, timeout, None
        self.stop = threading.Event()

    def __enter__(self):
        self.thread = threading.Thread(target=self._watch, name="sunshade-watchdog", daemon=True)
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()

    def _watch(self):
        since = time.monotonic()
        while not self.stop.wait(0.5):
            try:
                alive = self.client.status == "running" and bool(
                    self.client.scheduler_info(n_workers=1)["workers"])
            except Exception:
                alive = False
            if alive:
                since = time.monotonic()
            elif time.monotonic() - since > self.timeout:
                self.lost = (f"no workers for {self.timeout:g} s" if self.client.status == "running"
                             else f"no scheduler for {self.timeout:g} s")
                with contextlib.suppress(Exception):
                    self.client.close(timeout=2)
                return


def _reach(scheduler: str) -> None:
    """Raise RunError unless the scheduler answers: a TCP connection to a ``tcp://host:port``
    address (refused at once, or 10 s for a host that does not answer), a client for others."""
    import socket
    from urllib.parse import urlsplit

    address = urlsplit(scheduler if "://" in scheduler else f"tcp://{scheduler}")
    if address.scheme != "tcp" or not address.hostname or not address.port:
        with _backend(scheduler):
            return
    try:
        socket.create_connection((address.hostname, address.port), timeout=10.0).close()
    except OSError as exc:
        raise RunError(f"--scheduler {scheduler}: cannot reach the scheduler "
                       f"({exc.strerror or exc})") from None


def _make_folder(folder: Path) -> Path:
    """Create the output folder (and its parents). Raises RunError if it cannot be written."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe-{id(folder)}"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        raise RunError(f"{folder}: cannot write the output folder ({exc.strerror or exc})") from None
    return folder


def check_folder(folder: Path) -> None:
    """Raise RunError unless ``folder`` could be created and written, touching nothing: the
    nearest folder that exists must be a writable folder."""
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise RunError(f"{folder}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise RunError(f"{folder}: cannot write the output folder ({existing} is not writable)")


def missing_folders(folder: Path) -> list[Path]:
    """``folder`` and those of its parents that do not exist yet, innermost first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def remove_if_empty(folders: list[Path]) -> None:
    """Remove the ``folders`` (innermost first) that a failed run made and left empty but for
    its lock file, so that a failing run leaves nothing new behind."""
    for folder in folders:
        with contextlib.suppress(OSError):
            (folder / LOCK_FILE).unlink(missing_ok=True)
            folder.rmdir()


def check_outputs(config: Config) -> None:
    """Raise RunError unless the run's files could be written, touching nothing: the folder
    (``check_folder``), every name within the system's limits (``paths.problem``), and no
    frame, video, lock or run.json name taken by a folder."""
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


def _remove_temporaries(folder: Path) -> None:
    """Remove the half-written files a killed run left (we hold the folder's lock)."""
    for path in folder.glob(".*.tmp-*"):
        path.unlink(missing_ok=True)


def _read_index(folder: Path) -> dict:
    """The frames recorded in the folder's index.json ({frame as text: entry}); empty, with a
    FrameWarning, if it is unreadable (its frames are then rendered again)."""
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


def _write_index(folder: Path, index: dict) -> None:
    """index.json, written atomically (a temporary name, then renamed). Raises RunError naming
    the file if it cannot be written."""
    path = folder / INDEX_FILE
    temporary = path.with_name(f".{INDEX_FILE}.tmp-{os.getpid()}")
    try:
        temporary.write_text(json.dumps({"format": INDEX_FORMAT, "frames": index},
                                        separators=(",", ":")) + "\n")
        temporary.replace(path)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise RunError(f"{path}: cannot write ({exc.strerror or exc})") from None


def _read_run_file(folder: Path) -> dict:
    try:
        return json.loads((folder / RUN_FILE).read_text())
    except (OSError, ValueError):
        return {}


def resolved_config(config: Config, plan: RunPlan) -> dict:
    """The config as run: with the ground windows and the camera the plan placed where the
    config left them out, so that run.json says what was rendered."""
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


def _write_run_file(config, plan, digest, records, video, timings, *, jobs, threads, scheduler,
                    rendered):
    """run.json: the resolved config (windows and camera as placed) and its hash, versions,
    the command's settings, timings, per done frame S and the sun and moon (degrees), and
    ``runs``: one entry (time, frames rendered, settings, timings) per render that did work, the
    earlier ones kept, so that a re-run that finds every frame done leaves the record of the
    runs that made them. Written atomically."""
    versions = {"python": platform.python_version(), "sunshade": __version__}
    for name in VERSIONED:
        with contextlib.suppress(metadata.PackageNotFoundError):
            versions[name] = metadata.version(name)
    previous = _read_run_file(config.output.folder)
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
        "config": resolved_config(config, plan),
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
