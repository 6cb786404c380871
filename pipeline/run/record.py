"""run.json, the record of the renders into a run folder (the config as run, versions, settings,
timings, the frames and the video), and the resume that finds nothing to do and only adds its
record there (docs/runs.md, "The run folder", "Resume").

Nothing here imports numpy or a stage, so that a resume with nothing to do is decided in a
fraction of a second (``nothing_to_do``); ``render`` renders what is left.
"""

from __future__ import annotations

import contextlib
import json
import platform
import time
import warnings
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import filelock

from pipeline import __version__
from pipeline.cache.store import Cache, CacheItem
from pipeline.config.parse import Config
from pipeline.config.receivers import ReceiversConfig
from pipeline.core.cores import jobs_and_threads
from pipeline.run.folder import LOCK_FILE, RUN_FILE, video_file
from pipeline.run.index import check_frames, read_index

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from pipeline.stages.plan import RunPlan

__all__ = ["MAX_RUNS", "VERSIONED", "current_video", "read_run_file", "resolved_config", "write_run_file",
           "RunSummary", "nothing_to_do"]

MAX_RUNS = 100
"""run.json keeps the record of this many latest renders of a config. [count]"""
VERSIONED = ("numpy", "scipy", "OpenImageIO", "joblib", "imageio", "imageio-ffmpeg", "PyYAML",
             "ephem", "filelock", "dask", "distributed")
"""The packages whose versions run.json records."""


def current_video(config: Config, digest: str, previous: dict, *, force: bool = False) -> dict | None:
    """The previous run.json's video entry if the video on disk is of this config and all its frames.

    Parameters
    ----------
    config, digest
        As in ``index.check_frames``.
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


def read_run_file(folder: Path) -> dict:
    """The folder's run.json.

    Parameters
    ----------
    folder : pathlib.Path
        The run folder, where run.json is.

    Returns
    -------
    dict
        Its document; empty when it is missing or unreadable.
    """
    try:
        return json.loads((folder / RUN_FILE).read_text())
    except (OSError, ValueError):
        return {}


def resolved_config(config: Config, plan: RunPlan) -> dict[str, Any]:
    """The config as run, so that run.json says what was rendered.

    With the ground windows and the camera the plan placed where the config left them out.

    Parameters
    ----------
    config : settings.Config
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
    if not values["sky"]["params"]:  # a sky the parser reads itself records as it always did
        values["sky"].pop("params")
    if config.receivers == ReceiversConfig():  # the level ground alone records as it always did
        values.pop("receivers")
    values["ground"]["window"] = list(plan.window.extent)
    if plan.sun_window is not None:
        values["ground"]["sun_window"] = list(plan.sun_window.extent)
        values["ground"]["sun_pixel"] = plan.sun_window.pixel
    view = plan.camera
    values["camera"].update(position=list(view.position), yaw=view.yaw, pitch=view.pitch,
                            look_at=None if "camera" in plan.auto else values["camera"]["look_at"])
    values["placed"] = list(plan.auto)
    return values


def write_run_file(config: Config, resolved: dict[str, Any], digest: str, records: dict[int, dict[str, Any] | None],
                   video: dict[str, Any] | None, timings: dict[str, Any], *, jobs: int, threads: int,
                   scheduler: str | None, rendered: Sequence[int], source_hash: str | None = None) -> None:
    """run.json, written atomically.

    It holds the resolved config (windows and camera as placed: ``resolved_config``) and its hash,
    the hash of the config as written (``resolve.source_digest``; None: not known), versions, the
    command's settings, timings, per done frame S and the sun and moon (degrees), and ``runs``: one
    entry (time, frames rendered, settings, timings) per render that did work, the earlier ones
    kept (MAX_RUNS), so that a re-run that finds every frame done leaves the record of the runs
    that made them.

    Parameters
    ----------
    config : settings.Config
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
    runs = [*runs, {"finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "frames": len(rendered),
                    "video": "video" in timings,
                    "settings": {"jobs": jobs, "threads": threads, "scheduler": scheduler},
                    "timings": timings}][-MAX_RUNS:]
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
    waiting : int
        Frames of the animation not done yet: the video waits for them [frames].
    """

    rendered: tuple[int, ...]
    skipped: tuple[int, ...]
    video: Path | None
    timings: dict[str, Any]
    pruned: tuple[CacheItem, ...] = ()
    """The cache items the cache's budget removed at the end of the run (``Cache.prune``)."""
    waiting: int = 0
    """Frames of the animation not done yet: the video waits for them [frames]."""


def nothing_to_do(config: Config, store: Cache, frames: Iterable[int] | None = None, *, jobs: int | None = None,
                  scheduler: str | None = None, source_hash: str | None = None) -> RunSummary | None:
    """A resume with nothing to do, decided from the files' stamps alone (no numpy, no plan).

    When every frame of ``frames`` is done for this config (``check_frames``, nothing found damaged)
    and the video is made or not due yet, the run is recorded in run.json as ``render.render_run``
    records a render that found everything done, and its RunSummary returned.

    ``config`` may be the config as written, not resolved, with its ``source_hash``
    (``resolve.source_digest``): when run.json records that same hash, the resolved config's
    hash is the one it records beside it, and nothing is resolved (no ephemeris, no pvlib).

    Parameters
    ----------
    config : settings.Config
        The run's config, resolved or as written (with ``source_hash``).
    store : store.Cache
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
        folder, no run.json of this config yet): ``render.render_run`` then does it.
    """
    started = time.perf_counter()
    folder = config.output.folder
    previous = read_run_file(folder)
    digest: str | None = config.digest()
    if source_hash is not None and previous.get("source_hash") == source_hash:
        digest = previous.get("config_hash")
    if digest is None or previous.get("config_hash") != digest or "config" not in previous:
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
    return RunSummary((), frames, video_file(config) if made else None, timings,
                      waiting=count - len(checked.done))
