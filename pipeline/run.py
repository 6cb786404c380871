"""A run: a config's animation rendered into a folder of frames, then its video, resumably.

The folder holds ``NAME.0000.exr`` (scene-linear) and ``NAME.0000.png`` (display) per frame,
``NAME.mp4`` (or ``.gif``) and ``run.json``. Every file is written under a temporary name and
renamed into place, the PNG after the EXR, both carrying the config's hash. A frame is done when
both files are there with the hash of the config being run; a re-run skips done frames and the
cached cycle products, so a run killed at any point and run again ends with the same bytes.

Parallel: joblib over cycle frames and over output frames, each task with ``threads`` FFT
threads; with a scheduler address the same tasks run on a dask.distributed cluster through
joblib's Dask backend (the cache and the output folder on a file system all workers share).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import json
import logging
import os
import platform
import re
import threading
import time
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
from .render import RunPlan, check_inputs, cycle_phase, default_workers, render_frame

MAX_JOBS_PER_CORE = 4
"""Most worker processes a local run starts per core (--jobs, render.jobs): each holds a
frame's rasters."""
RUN_FILE = "run.json"
LOCK_FILE = ".sunshade.lock"
VERSIONED = ("numpy", "scipy", "OpenImageIO", "joblib", "imageio", "imageio-ffmpeg", "PyYAML",
             "ephem", "filelock", "dask", "distributed")


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


@dataclass(frozen=True)
class RunSummary:
    """What a run did: frames rendered and skipped, the video (None: not made), timings [s]."""

    rendered: tuple[int, ...]
    skipped: tuple[int, ...]
    video: Path | None
    timings: dict


def render_run(config: Config, *, frames: tuple[int, ...] | None = None, store: cache.Cache,
               jobs: int | None = None, scheduler: str | None = None, force: bool = False,
               progress=None, cluster_timeout: float | None = None) -> RunSummary:
    """Render ``frames`` (default: all) of the config's animation into ``config.output.folder``:
    the cycle products they need, the frames not done yet (all with ``force``), then the video
    once every frame of the animation is done, and ``run.json``.

    jobs : processes at once (default ``render.jobs``, else one per core); each gets
        cores // jobs FFT threads (one on a cluster). scheduler : a dask.distributed scheduler
        address (``tcp://host:8786``) to run the tasks on instead. cluster_timeout : how long
        a lost cluster is waited for (default CLUSTER_TIMEOUT). [s]
    progress : called as ``progress(stage, done, total)`` with stage ``cycle``, ``frames`` or
        ``video``. Raises RunError, config.ConfigError, io.ImageError before any work.
    """
    started = time.perf_counter()
    timings = {}
    store = cache.Cache(store.root.absolute())  # workers elsewhere resolve no relative path
    plan = check_inputs(config)
    digest = config.digest()
    frames = tuple(range(config.animation.frames)) if frames is None else tuple(frames)
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
        records = {f: frame_record(config, f, digest) for f in range(config.animation.frames)}
        todo = [f for f in frames if force or records[f] is None]
        timings["check"] = time.perf_counter() - started
        if todo:
            with _backend(scheduler, cluster_timeout or CLUSTER_TIMEOUT):
                mark = time.perf_counter()
                cycle_phase(config, plan, store, jobs=jobs, workers=threads,
                            cycle_frames={f % config.canopy.cycle for f in todo},
                            progress=progress and (lambda done, total: progress("cycle", done, total)))
                timings["cycle"] = time.perf_counter() - mark
                mark = time.perf_counter()
                stages = timings["frame_stages"] = {}
                for frame, seconds in _frame_phase(config, plan, store, todo, digest, jobs=jobs,
                                                   threads=threads, progress=progress):
                    records[frame] = frame_record(config, frame, digest)
                    for stage, value in seconds.items():
                        stages[stage] = stages.get(stage, 0.0) + value
                timings["frames"] = time.perf_counter() - mark
        video = _video(config, digest, records, _read_run_file(folder), progress, timings, force=force)
        timings["total"] = time.perf_counter() - started
        _write_run_file(config, digest, records, video, timings, jobs=jobs, threads=threads,
                        scheduler=scheduler)
    finally:
        lock.release()
    return RunSummary(tuple(todo), tuple(f for f in frames if f not in set(todo)),
                      video_file(config) if video else None, timings)


def _frame_phase(config, plan, store, todo, digest, *, jobs, threads, progress):
    """Render the ``todo`` frames in parallel; yields (frame, stage seconds) as each is
    written."""
    if progress:
        progress("frames", 0, len(todo))
    tasks = (joblib.delayed(_frame_task)(config, plan, frame, str(store.root), digest, threads)
             for frame in todo)
    results = joblib.Parallel(n_jobs=min(jobs, len(todo)), return_as="generator_unordered")(tasks)
    for done, result in enumerate(results, 1):
        yield result
        if progress:
            progress("frames", done, len(todo))


@portable
def _frame_task(config: Config, plan: RunPlan, frame: int, root: str, digest: str, threads: int):
    """Render one frame and write its EXR, then its PNG. Returns (frame, stage seconds)."""
    timings = {}
    result = render_frame(config, frame=frame, store=cache.Cache(root), plan=plan,
                          workers=threads, timings=timings)
    mark = time.perf_counter()
    if not np.all(np.isfinite(result.radiance)):
        raise io.ImageError(config.path, f"frame {frame} overflowed; lower the sky's radiance")
    exr, png = frame_files(config, frame)
    io.write_exr(exr, result.radiance, frame_attributes(config, result, digest), half=config.output.half)
    picture = display(result.radiance, exposure=result.exposure, transform=config.camera.display)
    io.write_png(png, picture, {"sunshade:config_hash": digest, "sunshade:frame": str(frame)})
    timings["write"] = time.perf_counter() - mark
    return frame, timings


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


def _read_run_file(folder: Path) -> dict:
    try:
        return json.loads((folder / RUN_FILE).read_text())
    except (OSError, ValueError):
        return {}


def _write_run_file(config, digest, records, video, timings, *, jobs, threads, scheduler):
    """run.json: the resolved config and its hash, versions, the command's settings, timings,
    and per done frame S and the sun and moon (degrees), written atomically."""
    versions = {"python": platform.python_version(), "sunshade": __version__}
    for name in VERSIONED:
        with contextlib.suppress(metadata.PackageNotFoundError):
            versions[name] = metadata.version(name)
    document = {
        "config_file": str(config.path),
        "config_hash": digest,
        "config": asdict(config),
        "versions": versions,
        "settings": {"jobs": jobs, "threads": threads, "scheduler": scheduler},
        "timings": timings,
        "frames": [record for record in records.values() if record is not None],
        "video": video,
    }
    path = config.output.folder / RUN_FILE
    temporary = path.with_name(f".{RUN_FILE}.tmp-run")
    temporary.write_text(json.dumps(document, indent=1, default=str) + "\n")
    temporary.replace(path)
