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
import json
import logging
import os
import threading
import time
import warnings
from concurrent.futures.process import BrokenProcessPool

import filelock
import joblib
import numpy as np

from pipeline import __version__
from pipeline.cache import store as cache
from pipeline.camera.composite import display_codes
from pipeline.config.settings import Config
from pipeline.core import io
from pipeline.core.cores import CLUSTER_TIMEOUT, end_if_orphaned, jobs_and_threads, scheduler_address
from pipeline.core.errors import RunError, SunshadeError, portable
from pipeline.run.folder import INDEX_FILE, LOCK_FILE, frame_files, make_folder, remove_temporaries, video_file
from pipeline.run.index import FrameWarning, check_frames, file_stamp, read_index, write_index
from pipeline.run.record import RunSummary, current_video, read_run_file, resolved_config, write_run_file
from pipeline.stages.cycle import config_item_keys, cycle_phase, record_config_items
from pipeline.stages.frame import compile_loops, render_frame
from pipeline.stages.framing import framing_warnings
from pipeline.stages.lighting import with_exposures
from pipeline.stages.plan import RunPlan, check_inputs

__all__ = ["frame_record", "frame_attributes", "REC709_CHROMATICITIES", "LAYER_CHANNELS", "standard_attributes",
           "exr_layers", "render_run"]

_RECORD = {"sunshade:config_hash": "config_hash", "sunshade:frame": "frame",
           "sunshade:sun_fraction": "sun_fraction", "sunshade:sun_azimuth_elevation": "sun",
           "sunshade:moon_azimuth_elevation": "moon", "sunshade:time_utc": "time_utc",
           "sunshade:exposure": "exposure"}


def frame_record(config: Config, frame: int, digest: str) -> dict | None:
    """What a done frame's EXR says of itself.

    Parameters
    ----------
    config : settings.Config
        The config.
    frame : int
        Output frame index.
    digest : str
        The config's hash both files must carry.

    Returns
    -------
    dict or None
        ``file`` (the EXR's stem), ``frame``, ``sun_fraction`` S [1], ``sun`` and ``moon``
        {azimuth, elevation} [deg], ``time_utc``, ``exposure`` [m^2/kcd]; None unless both its files
        are there and carry ``digest``.
    """
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
    """Metadata of a finished frame: what made it, and the sun and moon of that moment.

    Parameters
    ----------
    config : settings.Config
        The config.
    result : frame.FrameResult
        The finished frame.
    digest : str
        The config's hash.

    Returns
    -------
    dict
        EXR attributes under ``sunshade:`` (hash, version, frame, S [1], exposure [m^2/kcd], sun and
        moon (azimuth, elevation) [deg], UTC time), and ``standard_attributes`` with light passes.
    """
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
    if config.output.passes:  # only then: a frame without passes keeps its bytes
        attributes.update(standard_attributes(config, result))
    return attributes


REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
"""The working space's primaries and white (linear Rec.709, D65) as OpenEXR's chromaticities:
red x, y, green x, y, blue x, y, white x, y (ITU-R BT.709-6)."""

LAYER_CHANNELS = {"sun": ("sun.R", "sun.G", "sun.B"), "sky": ("sky.R", "sky.G", "sky.B"),
                  "alpha": ("alpha.A",), "illuminance": ("illuminance.Y",), "depth": ("depth.Z",)}
"""The EXR channels of each light pass, in the multi-layer convention (layer.channel)."""


def standard_attributes(config: Config, result) -> dict:
    """The EXR header of a frame with light passes (docs/runs.md, "Light passes"): OpenEXR's
    standard ``chromaticities``; for a site and time its ``latitude``, ``longitude`` [degrees]
    and ``altitude`` [m], and ``capDate`` (OpenImageIO's ``DateTime``, the frame's UTC time from
    the config, not the clock) with ``utcOffset`` 0 [s]; and under ``sunshade:`` the open
    ground's light (``frame.open_ground_light``) [lx, EV].

    Parameters
    ----------
    config : settings.Config
        The config.
    result : frame.FrameResult
        The finished frame, with its ``light``.

    Returns
    -------
    dict
        EXR attribute name -> value.
    """
    attributes = {"chromaticities": REC709_CHROMATICITIES}
    site = config.sky.site
    if site is not None:
        attributes.update({"latitude": float(np.degrees(site.latitude)),
                           "longitude": float(np.degrees(site.longitude)),
                           "altitude": float(site.elevation), "utcOffset": 0.0})
    if result.scene.when is not None:
        attributes["DateTime"] = result.scene.when.strftime("%Y:%m:%d %H:%M:%S")
    light = result.light
    attributes.update({"sunshade:sun_lux": light["sun_lux"], "sunshade:sky_lux": light["sky_lux"],
                       "sunshade:open_ground_lux": light["sun_lux"] + light["sky_lux"],
                       "sunshade:white_balance": tuple(light["white_balance"]),
                       "sunshade:passes": ",".join(config.output.passes)})
    for name in ("ev100", "camera_ev100"):
        if light[name] is not None:
            attributes[f"sunshade:{name}"] = light[name]
    return attributes


def exr_layers(result, half: bool) -> dict | None:
    """``io.write_exr``'s layers of a frame's light passes.

    RGB passes in the beauty's format, single channels in float32 (lux pass half's 65504; depth is
    inf at the sky).

    Parameters
    ----------
    result : frame.FrameResult
        The finished frame, with its ``layers``.
    half : bool
        Whether the beauty is written in half floats.

    Returns
    -------
    dict or None
        {channel names: (pixels, "half" or "float")} (``LAYER_CHANNELS``); None without any pass.
    """
    if not result.layers:
        return None
    return {LAYER_CHANNELS[name]: (pixels, "half" if half and pixels.shape[-1] == 3 else "float")
            for name, pixels in result.layers.items()}


def render_run(config: Config, *, frames: tuple[int, ...] | None = None, store: cache.Cache,
               jobs: int | None = None, scheduler: str | None = None, force: bool = False,
               progress=None, warn=None, cluster_timeout: float | None = None,
               source_hash: str | None = None, budget: int | None = None) -> RunSummary:
    """Render ``frames`` (default: all) of the config's animation into ``config.output.folder``:
    the cycle products they need, the frames not done yet (all with ``force``), then the video
    once every frame of the animation is done, and ``run.json``.

    Parameters
    ----------
    config : settings.Config
        The resolved config.
    frames : tuple of int or None
        Output frame indices; None for all.
    store : cache.Cache
        The cache of the cycle products.
    jobs : int or None
        Processes at once (default ``render.jobs``, else one per core); each gets cores // jobs FFT
        threads (one on a cluster).
    scheduler : str or None
        A dask.distributed scheduler address (``tcp://host:8786``) to run the tasks on instead.
    force : bool
        Render the frames done already too.
    progress : callable or None
        Called as ``progress(stage, done, total)`` with stage ``cycle``, ``frames`` or ``video``.
    warn : callable or None
        Called with each one-line warning of the plan (``framing.framing_warnings``).
    cluster_timeout : float or None
        How long a lost cluster is waited for (default CLUSTER_TIMEOUT) [s].
    source_hash : str or None
        The hash of the config as written (``resolve.source_digest``), recorded in run.json for the
        next resume (``runrecord.nothing_to_do``).
    budget : int or None
        The cache's budget [B]: at the end the least recently used items that neither this run nor
        another live one uses are removed until the items total at most this (None: none removed;
        docs/runs.md, "The cache's budget").

    Returns
    -------
    runrecord.RunSummary
        What the run did.

    Raises
    ------
    RunError, errors.ConfigError, io.ImageError
        Before any work.
    """
    started = time.perf_counter()
    timings = {}
    store = cache.Cache(store.root.absolute())  # workers elsewhere resolve no relative path
    plan = check_inputs(config)
    for line in framing_warnings(config, plan) if warn else ():
        warn(line)
    digest = config.digest()
    frames = tuple(range(config.animation.frames)) if frames is None else tuple(frames)
    if scheduler:
        _reach(scheduler)  # an unreachable scheduler fails before anything is written
    folder = make_folder(config.output.folder)
    jobs, threads = jobs_and_threads(jobs or config.render.jobs, scheduler)
    lock = filelock.FileLock(folder / LOCK_FILE, timeout=0)
    try:
        lock.acquire()
    except filelock.Timeout:
        raise RunError(f"{folder}: another sunshade render is writing to this folder") from None
    compiling = None  # the thread of compile_loops, if started
    mine = set(config_item_keys(plan))
    held = contextlib.ExitStack()
    try:
        held.enter_context(store.in_use(mine))  # no other run's budget removes them meanwhile
        remove_temporaries(folder)
        if (folder / INDEX_FILE).is_dir():
            raise RunError(f"{folder / INDEX_FILE}: is a folder, not a file")
        index = read_index(folder)
        before = json.dumps(index, sort_keys=True)
        checked = check_frames(config, digest, store, index)
        for frame, problem in sorted(checked.damaged.items()):
            action = "rendering it again" if force or frame in frames else "not done"
            warnings.warn(f"{frame_files(config, frame)[0].stem}: {problem}; {action}",
                          FrameWarning, stacklevel=2)
        if json.dumps(index, sort_keys=True) != before:
            write_index(folder, index)
        records = {f: (checked.done[f]["record"] if f in checked.done else None)
                   for f in range(config.animation.frames)}
        todo = [f for f in frames if force or records[f] is None]
        previous, remake_video, stream = read_run_file(folder), force or bool(checked.damaged), None
        timings["check"] = time.perf_counter() - started
        if todo:
            plan = with_exposures(plan, todo)
            with _backend(scheduler, cluster_timeout or CLUSTER_TIMEOUT):
                mark = time.perf_counter()
                command = None if scheduler else os.getpid()  # whose local workers end with it
                if jobs > 1 and not scheduler:  # the frames' loops compiled meanwhile, here, once
                    compiling = threading.Thread(target=_compile_frame_loops, args=(plan,), daemon=True)
                    compiling.start()
                cycle_phase(plan, store, jobs=jobs, workers=threads, command=command,
                            cycle_frames={f % config.canopy.cycle for f in todo},
                            progress=progress and (lambda done, total: progress("cycle", done, total)))
                timings["cycle"] = time.perf_counter() - mark
                record_config_items(plan, store)
                mark = time.perf_counter()
                stages = timings["frame_stages"] = {}
                encoded = {}  # each index entry's JSON, as write_index made it
                stream = _VideoStream.start(config, digest, records, todo, previous, force=remake_video,
                                            in_process=jobs == 1 and not scheduler)
                if config.output.report:  # its drawing library imported meanwhile, not after the frames
                    from pipeline.run.report import import_drawing

                    threading.Thread(target=import_drawing, name="sunshade-report", daemon=True).start()
                try:
                    for frame, seconds, entry, caught, codes in _frame_phase(
                            config, plan, store, todo, digest, jobs=jobs, threads=threads, command=command,
                            progress=progress, codes=stream is not None):
                        for category, text in caught:  # raised in a worker: said here, once
                            warnings.warn(text, category, stacklevel=2)
                        index[str(frame)] = entry
                        encoded.pop(str(frame), None)
                        write_index(folder, index, encoded)
                        records[frame] = entry["record"]
                        for stage, value in seconds.items():
                            stages[stage] = stages.get(stage, 0.0) + value
                        if stream:
                            stream.add(frame, codes)
                except BaseException:
                    if stream:
                        stream.abort()
                    raise
                timings["frames"] = time.perf_counter() - mark
        if stream:
            video = stream.finish(progress, timings)
        else:
            video = _video(config, digest, records, previous, progress, timings, force=remake_video)
        timings["total"] = time.perf_counter() - started
        write_run_file(config, resolved_config(config, plan), digest, records, video, timings, jobs=jobs,
                       threads=threads, scheduler=scheduler, rendered=todo, source_hash=source_hash)
        if todo and config.output.report:  # the light curve and contact sheet (docs/runs.md, "The report")
            from pipeline.run.report import write_report

            try:
                write_report(folder)
            except Exception as exc:
                warnings.warn(f"{folder}: the report was not written ({exc}); `sunshade report {folder}` "
                              "writes it", FrameWarning, stacklevel=2)
        pruned = tuple(store.prune(budget, keep=mine)) if budget is not None else ()
    finally:
        if compiling is not None:  # never left writing numba's cache as the command ends
            compiling.join()
        held.close()
        lock.release()
    return RunSummary(tuple(todo), tuple(f for f in frames if f not in set(todo)),
                      video_file(config) if video else None, timings, pruned)


def _frame_phase(config, plan, store, todo, digest, *, jobs, threads, progress, command=None, codes=False):
    """Render the ``todo`` frames in parallel; yields what ``_frame_task`` returns as each
    frame is written. With one job the frames render here, one after another, and each frame's
    files are written by a thread while the next frame renders (``_frames_here``)."""
    if progress:
        progress("frames", 0, len(todo))
    if jobs == 1 and command is not None:
        results = _frames_here(config, plan, store, todo, digest, threads, codes)
    else:
        tasks = (joblib.delayed(_frame_task)(config, plan, frame, str(store.root), digest, threads, command, codes)
                 for frame in todo)
        results = joblib.Parallel(n_jobs=min(jobs, len(todo)), return_as="generator_unordered")(tasks)
    for done, result in enumerate(results, 1):
        yield result
        if progress:
            progress("frames", done, len(todo))


def _frames_here(config, plan, store, todo, digest, threads, codes):
    """``_frame_task`` over ``todo`` in this process, its writing overlapped with the next
    frame's rendering: a thread writes frame k's EXR and PNG while frame k + 1 renders, so the
    writing costs no wall time where a core is free (docs/runs.md, "Writing"). Yields each
    frame as its files are written, in order; at most one frame waits to be written. Where a
    frame's rendering fails (or is interrupted), the frame before it is written and yielded
    first, so it is recorded as it was before the overlap."""
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="sunshade-write") as writer:
        writing = None
        for frame in todo:
            try:
                rendered = _render_task(plan, frame, str(store.root), threads)
            except BaseException:
                if writing is not None:
                    yield writing.result()
                raise
            if writing is not None:
                yield writing.result()
            writing = writer.submit(_write_task, config, rendered, digest, codes)
        if writing is not None:
            yield writing.result()


@portable
def _frame_task(config: Config, plan: RunPlan, frame: int, root: str, digest: str, threads: int,
                command: int | None = None, codes: bool = False):
    """Render one frame and write its EXR, then its PNG. Returns (frame, stage seconds [s],
    its index.json entry, the warnings raised meanwhile as (category, text), the PNG's 8-bit
    codes if ``codes`` else None): a worker's warnings are said by the process that runs the
    command, and the codes go to the video it encodes meanwhile (``_VideoStream``)."""
    end_if_orphaned(command)
    return _write_task(config, _render_task(plan, frame, root, threads), digest, codes)


def _compile_frame_loops(plan: RunPlan) -> None:
    """``frame.compile_loops``, and the display codes' loops of the writing (``display_codes`` of a
    tiny picture): the frames' workers then load them from numba's cache on disk."""
    compile_loops(plan)
    with contextlib.suppress(Exception):  # only a head start: a frame meets the same error itself
        display_codes(np.zeros((2, 2, 3), dtype=np.float32), exposure=1.0)


def _render_task(plan: RunPlan, frame: int, root: str, threads: int):
    """Render one frame: (frame, its ``FrameResult``, stage seconds [s], the cache items it
    was made from (``cache.Cache.served``), the warnings raised meanwhile as (category, text))."""
    timings, store = {}, cache.Cache(root)
    with warnings.catch_warnings(record=True) as caught:
        result = render_frame(plan, frame, store=store, workers=threads, timings=timings)
    return frame, result, timings, dict(store.served), [(w.category, str(w.message)) for w in caught]


def _write_task(config: Config, rendered, digest: str, codes: bool):
    """Write a frame that ``_render_task`` rendered: its EXR, then its PNG. Returns what
    ``_frame_task`` returns."""
    frame, result, timings, served, caught = rendered
    mark = time.perf_counter()
    if not np.all(np.isfinite(result.radiance)):
        raise io.ImageError(config.path, f"frame {frame} overflowed; lower the sky's radiance")
    exr, png = frame_files(config, frame)
    io.write_exr(exr, result.radiance, frame_attributes(config, result, digest), half=config.output.half,
                 layers=exr_layers(result, config.output.half))
    picture = display_codes(result.radiance, exposure=result.exposure, transform=config.camera.display,
                            balance=result.balance)
    written = io.write_png(png, picture, {"sunshade:config_hash": digest, "sunshade:frame": str(frame)})
    timings["write"] = time.perf_counter() - mark
    mark = time.perf_counter()
    entry = {"config_hash": digest, "files": {"exr": file_stamp(exr), "png": file_stamp(png)},
             "items": served, "record": frame_record(config, frame, digest)}
    if entry["record"] is not None and result.light is not None:  # the report's light curve
        entry["record"]["light"] = {"time_s": float(result.scene.time), "exposure": float(result.exposure),
                                    **result.light}
    timings["digest"] = time.perf_counter() - mark
    return frame, timings, entry, caught, written if codes else None


def _video(config: Config, digest: str, records: dict, previous: dict, progress, timings, *,
           force) -> dict | None:
    """Encode the video from the PNG frames once every frame of the animation is done
    (``records`` has them all), unless the ``previous`` run.json says the video on disk is of
    this config. Returns its run.json entry."""
    path = video_file(config)
    if path is None:
        return None
    made = current_video(config, digest, previous, force=force)
    if made is not None:
        return made
    if any(record is None for record in records.values()):
        return None
    mark = time.perf_counter()
    count = config.animation.frames

    def pictures():
        for frame in range(count):
            yield io.read_codes(frame_files(config, frame)[1])
            if progress:
                progress("video", frame + 1, count)

    io.write_video(path, pictures(), fps=config.animation.fps)
    timings["video"] = time.perf_counter() - mark
    return _video_entry(config, digest)


def _video_entry(config: Config, digest: str) -> dict:
    """run.json's entry of the video just written."""
    path = video_file(config)
    return {"file": path.name, "config_hash": digest, "frames": config.animation.frames,
            "bytes": path.stat().st_size}


class _VideoStream:
    """The video encoded while the frames are rendered, when this run ends with every frame
    done (docs/runs.md, "The video"): a thread hands the encoder each frame's codes in order as
    soon as it and every frame before it are done, those rendered now as their workers return
    them (``add``), those done before read from their PNGs; the same frames in the same order
    as ``_video`` reads, so the same bytes. The encoder writes under a temporary name: a run
    that fails or is killed leaves no video."""

    def __init__(self, config: Config, digest: str, fresh):
        self.config, self.digest, self.fresh = config, digest, set(fresh)
        self.arrived, self.fed, self.aborted, self.error = {}, 0, False, None
        self.ready = threading.Condition()
        self.thread = threading.Thread(target=self._encode, name="sunshade-video", daemon=True)
        self.thread.start()

    @classmethod
    def start(cls, config: Config, digest: str, records: dict, todo, previous: dict, *, force, in_process):
        """A stream if the run makes a video and ends with every frame done, else None; None
        too when the frames render ``in_process``: the encoder is a forked process, and a fork
        while this process's FFT threads take work ends the FFT ("Work item submitted after
        shutdown": scipy's pocketfft stops its thread pool at every fork), so the video is
        then encoded after the frames."""
        fresh = set(todo)
        if (in_process or video_file(config) is None
                or current_video(config, digest, previous, force=force) is not None
                or any(records[f] is None and f not in fresh for f in range(config.animation.frames))):
            return None
        return cls(config, digest, fresh)

    def add(self, frame: int, codes: np.ndarray) -> None:
        if not self.thread.is_alive():  # the encoder failed: finish() says why; keep nothing
            return
        with self.ready:
            self.arrived[frame] = codes
            self.ready.notify()

    def abort(self) -> None:
        """Stop the encoder and leave no video."""
        with self.ready:
            self.aborted = True
            self.ready.notify()
        self.thread.join()

    def finish(self, progress, timings) -> dict:
        """Wait for the encoder (its progress said as ``video``); the video's run.json entry."""
        mark, count = time.perf_counter(), self.config.animation.frames
        while self.thread.is_alive():
            if progress:
                progress("video", self.fed, count)
            self.thread.join(0.25)
        if self.error is not None:
            raise self.error
        if progress:
            progress("video", count, count)
        timings["video"] = time.perf_counter() - mark
        return _video_entry(self.config, self.digest)

    def _pictures(self):
        for frame in range(self.config.animation.frames):
            if frame in self.fresh:
                with self.ready:
                    while frame not in self.arrived and not self.aborted:
                        self.ready.wait()
                    if self.aborted:
                        raise RunError("the video was abandoned with its run")
                    codes = self.arrived.pop(frame)
            else:
                codes = io.read_codes(frame_files(self.config, frame)[1])
            yield codes
            self.fed = frame + 1

    def _encode(self) -> None:
        try:
            io.write_video(video_file(self.config), self._pictures(), fps=self.config.animation.fps)
        except BaseException as error:  # said by finish(), in the command's thread
            self.error = error


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
    """Raise RunError unless the scheduler's address is one (``cores.scheduler_address``) and it
    answers: a TCP connection to its host and port (refused at once, or 10 s for a host that
    does not answer)."""
    import socket

    address = scheduler_address(scheduler)
    if isinstance(address, str):
        raise RunError(f"--scheduler {scheduler}: {address}")
    try:
        socket.create_connection(address, timeout=10.0).close()
    except OSError as exc:
        raise RunError(f"--scheduler {scheduler}: cannot reach the scheduler "
                       f"({exc.strerror or exc})") from None
