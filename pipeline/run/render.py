"""A run: a config's animation rendered into a folder of frames, then its video, resumably.

The folder holds ``NAME.0000.exr`` (scene-linear) and ``NAME.0000.png`` (display) per frame,
``NAME.mp4`` (or ``.gif``), ``run.json`` and ``index.json``. Every file is written under a
temporary name and renamed into place, the PNG after the EXR, both carrying the config's hash.
When a frame's files are written, ``index.json`` records the config hash, the BLAKE2b digest,
size, inode and times of each file, and the cache items the frame was made from (their
checksums and files' identities; ``store.Cache.served``). A frame is done when its entry has
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
import functools
import json
import logging
import os
import threading
import time
import warnings
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import filelock
import joblib
import numpy as np

from pipeline.cache import store as cache
from pipeline.camera.composite import display_codes
from pipeline.canopy.rasteriser import compile_loops as rasteriser_compile_loops
from pipeline.canopy.rasteriser import loops_cached
from pipeline.config.settings import Config
from pipeline.core import io
from pipeline.core.cores import (
    CLUSTER_TIMEOUT,
    compiled_once,
    end_if_orphaned,
    jobs_and_threads,
    on_disk,
    scheduler_address,
)
from pipeline.core.errors import RunError, SunshadeError, portable
from pipeline.run.contents import exr_layers, frame_attributes, frame_picture, frame_record, in_working_space
from pipeline.run.folder import (
    INDEX_FILE,
    LOCK_FILE,
    frame_files,
    make_folder,
    remove_own_folders,
    remove_temporaries,
    video_file,
)
from pipeline.run.index import FrameWarning, check_frames, file_stamp, read_index, write_index
from pipeline.run.record import RunSummary, read_run_file, resolved_config, write_run_file
from pipeline.run.video import VideoStream, encode_video
from pipeline.stages.cycle import config_item_keys, cycle_phase, record_config_items
from pipeline.stages.frame import FrameResult, compile_loops, render_frame
from pipeline.stages.framing import framing_warnings
from pipeline.stages.lighting import with_exposures
from pipeline.stages.plan import RunPlan, check_inputs

if TYPE_CHECKING:
    from collections.abc import Callable, Generator, Iterable, Iterator

    from distributed import Client

    Progress = Callable[[str, int, int], None]
    Timings = dict[str, float | dict[str, float]]
    Starting = concurrent.futures.Future[None]

__all__ = ["render_run"]

def render_run(config: Config, *, frames: tuple[int, ...] | None = None, store: cache.Cache, jobs: int | None = None,
               scheduler: str | None = None, force: bool = False, progress: Progress | None = None,
               warn: Callable[[str], None] | None = None, cluster_timeout: float | None = None,
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
    store : store.Cache
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
        next resume (``record.nothing_to_do``).
    budget : int or None
        The cache's budget [B]: at the end the least recently used items that neither this run nor
        another live one uses are removed until the items total at most this (None: none removed;
        docs/runs.md, "The cache's budget").

    Returns
    -------
    record.RunSummary
        What the run did.

    Raises
    ------
    RunError, errors.ConfigError, io.ImageError
        Before any work.
    """
    started = time.perf_counter()
    run, plan = _planned(config, frames, store, jobs=jobs, scheduler=scheduler, progress=progress, warn=warn)
    mine = set(config_item_keys(plan))
    timings: Timings = {}
    made, lock = _lock(run.folder)
    try:
        with contextlib.ExitStack() as held:  # the steps' threads joined, then ``mine`` let go
            held.callback(_end_starting, starting := _start_workers(config, frames, jobs, scheduler))  # checked inputs
            held.enter_context(run.store.in_use(mine))  # no other run's budget removes them meanwhile
            found = _check_folder(run, force=force)
            timings["check"] = time.perf_counter() - started
            stream: VideoStream | None = None
            if found.todo:
                plan = with_exposures(plan, found.todo)
                with _backend(scheduler, cluster_timeout or CLUSTER_TIMEOUT):
                    _cycles(run, plan, found.todo, held, timings, starting)
                    stream = _frames(run, plan, found, timings)
            video: dict[str, Any] | None
            if stream:
                video = stream.finish(progress, timings)
            else:
                video = encode_video(config, run.digest, found.records, found.previous, force=found.remake_video,
                                     progress=progress, timings=timings)
            timings["total"] = time.perf_counter() - started
            _record(run, plan, found, video, timings, source_hash)
            pruned = tuple(run.store.prune(budget, keep=mine)) if budget is not None else ()
    except BaseException:
        remove_own_folders(made, lock_held=True)  # while the lock is held: nobody else's
        raise
    finally:
        lock.release()
    return RunSummary(tuple(found.todo), tuple(f for f in run.frames if f not in set(found.todo)), video_file(config)
                      if video else None, timings, pruned, sum(r is None for r in found.records.values()))


@dataclass(frozen=True)
class _Run:
    """What the steps of one ``render_run`` share: ``config``, ``store`` (its root absolute: workers
    elsewhere resolve no relative path), ``folder`` (the output folder), ``digest`` (the config's hash), the
    ``frames`` asked for, ``jobs`` (processes at once) of ``threads`` (FFT threads) each, the
    ``scheduler``'s address (None: local processes), ``command`` (the process whose local workers
    end with it, ``cores.end_if_orphaned``; None on a cluster) and ``progress``."""

    config: Config
    store: cache.Cache
    folder: Path
    digest: str
    frames: tuple[int, ...]
    jobs: int
    threads: int
    scheduler: str | None
    command: int | None
    progress: Progress | None


@dataclass(frozen=True)
class _Found:
    """What the folder's check found (``_check_folder``): ``index`` ({frame as text: entry} of
    index.json) and ``records`` ({frame: its record, None when not done}, every frame of the
    animation), both updated as frames are written; ``todo`` (the frames to render, in the order
    asked); ``previous`` (the last run.json, empty when none); ``remake_video`` (make the video
    again even if current: ``force``, or a frame found damaged)."""

    index: dict[str, Any]
    records: dict[int, dict[str, Any] | None]
    todo: list[int]
    previous: dict[str, Any]
    remake_video: bool


def _planned(config: Config, frames: tuple[int, ...] | None, store: cache.Cache, *, jobs: int | None,
             scheduler: str | None, progress: Progress | None,
             warn: Callable[[str], None] | None) -> tuple[_Run, RunPlan]:
    """The run's plan, its inputs checked (``plan.check_inputs``) and its warnings said to ``warn``;
    the scheduler reached: what the later steps share."""
    store = cache.Cache(store.root.absolute())  # workers elsewhere resolve no relative path
    plan = check_inputs(config)
    if warn is not None:
        for line in framing_warnings(config, plan):
            warn(line)
    digest = config.digest()
    asked = tuple(range(config.animation.frames)) if frames is None else tuple(frames)
    if scheduler:
        _reach(scheduler)  # an unreachable scheduler fails before anything is written
    jobs, threads = jobs_and_threads(jobs or config.render.jobs, scheduler)
    command = None if scheduler else os.getpid()  # whose local workers end with it
    run = _Run(config, store, config.output.folder, digest, asked, jobs, threads, scheduler, command, progress)
    return run, plan


def _lock(folder: Path) -> tuple[tuple[Path, ...], filelock.FileLock]:
    """The output folder made and its lock held before anything is written in it: (the folders this
    process made, the lock). Where another render holds the lock: RunError, the folders this process
    made removed if they are empty (never the other's lock file or folder; docs/runs.md, "The run
    folder"). A folder that another failing render removed between the two steps is made again."""
    for _ in range(3):
        made = make_folder(folder)
        lock = filelock.FileLock(folder / LOCK_FILE, timeout=0)
        try:
            lock.acquire()
        except filelock.Timeout:
            remove_own_folders(made, lock_held=False)
            raise RunError(f"{folder}: another sunshade render is writing to this folder") from None
        except FileNotFoundError:
            continue  # removed by another render that failed, between the two steps: made again
        return made, lock
    raise RunError(f"{folder}: the output folder vanished three times while it was being locked")


def _check_folder(run: _Run, *, force: bool) -> _Found:
    """The folder's frames checked (docs/runs.md, "Resume"): a killed run's temporary files
    removed, each damaged frame said (a FrameWarning at ``render_run``'s caller), index.json
    written again where the check changed it; which frames are done, which to render."""
    folder, config = run.folder, run.config
    remove_temporaries(folder)
    if (folder / INDEX_FILE).is_dir():
        raise RunError(f"{folder / INDEX_FILE}: is a folder, not a file")
    index = read_index(folder)
    before = json.dumps(index, sort_keys=True)
    checked = check_frames(config, run.digest, run.store, index)
    for frame, problem in sorted(checked.damaged.items()):
        action = "rendering it again" if force or frame in run.frames else "not done"
        warnings.warn(f"{frame_files(config, frame)[0].stem}: {problem}; {action}",
                      FrameWarning, stacklevel=3)
    if json.dumps(index, sort_keys=True) != before:
        write_index(folder, index)
    records = {f: (checked.done[f]["record"] if f in checked.done else None)
               for f in range(config.animation.frames)}
    todo = [f for f in run.frames if force or records[f] is None]
    return _Found(index, records, todo, read_run_file(folder), force or bool(checked.damaged))


def _cycles(run: _Run, plan: RunPlan, todo: list[int], held: contextlib.ExitStack, timings: Timings,
            starting: Starting | None) -> None:
    """The cycle products the ``todo`` frames need (``cycle.cycle_phase``), then recorded as the
    config's; with local processes the frames' loops compiled meanwhile, here, once, by a thread
    that ``held`` joins as it closes, unless numba's cache holds them (``_frame_loops_cached``).
    The workers ``_start_workers`` started are waited for first (``_workers_started``)."""
    mark = time.perf_counter()
    if run.jobs > 1 and not run.scheduler and not _frame_loops_cached():
        compiling = threading.Thread(target=_compile_frame_loops, args=(plan,), daemon=True)
        compiling.start()
        held.callback(compiling.join)  # never left writing numba's cache as the command ends
    _workers_started(starting)
    cycle_phase(plan, run.store, jobs=run.jobs, workers=run.threads, command=run.command,
                cycle_frames={f % run.config.canopy.cycle for f in todo},
                progress=functools.partial(run.progress, "cycle") if run.progress else None)
    timings["cycle"] = time.perf_counter() - mark
    record_config_items(plan, run.store)


def _frames(run: _Run, plan: RunPlan, found: _Found, timings: Timings) -> VideoStream | None:
    """Render and write the ``found.todo`` frames (``_frame_phase``), each recorded in index.json
    as it lands and its worker's warnings said here, once (at ``render_run``'s caller); the
    video encoded meanwhile where it can be (``VideoStream``), returned to be finished."""
    mark = time.perf_counter()
    stages: dict[str, float] = {}
    timings["frame_stages"] = stages
    encoded: dict[str, str] = {}  # each index entry's JSON, as write_index made it
    stream = VideoStream.start(run.config, run.digest, found.records, found.todo, found.previous,
                               force=found.remake_video, in_process=run.jobs == 1 and not run.scheduler)
    if run.config.output.report:  # its drawing library imported meanwhile, not after the frames
        from pipeline.run.report import import_drawing

        threading.Thread(target=import_drawing, name="sunshade-report", daemon=True).start()
    phase = _frame_phase(run, plan, found.todo, codes=stream is not None)
    try:
        for written in phase:
            for category, text in written.caught:  # raised in a worker: said here, once
                warnings.warn(text, category, stacklevel=3)
            found.index[str(written.frame)] = written.entry
            encoded.pop(str(written.frame), None)
            write_index(run.folder, found.index, encoded)
            found.records[written.frame] = written.entry["record"]
            for stage, value in written.seconds.items():
                stages[stage] = stages.get(stage, 0.0) + value
            if stream and written.codes is not None:
                stream.add(written.frame, written.codes)
    except BaseException:
        phase.close()  # its workers ended (joblib's abort), then what one ended mid-write removed (the lock is ours)
        if stream:
            stream.abort()
        remove_temporaries(run.folder)
        raise
    timings["frames"] = time.perf_counter() - mark
    return stream


def _record(run: _Run, plan: RunPlan, found: _Found, video: dict[str, Any] | None, timings: Timings,
            source_hash: str | None) -> None:
    """run.json, then, where the config asks for it and frames were rendered, the report (the
    light curve and contact sheet: docs/runs.md, "The report"; one that fails is a FrameWarning
    at ``render_run``'s caller)."""
    config = run.config
    write_run_file(config, resolved_config(config, plan), run.digest, found.records, video, timings,
                   jobs=run.jobs, threads=run.threads, scheduler=run.scheduler, rendered=found.todo,
                   source_hash=source_hash)
    if found.todo and config.output.report:
        from pipeline.run.report import write_report

        try:
            write_report(run.folder)
        except Exception as exc:
            warnings.warn(f"{run.folder}: the report was not written ({exc}); `sunshade report {run.folder}` "
                          "writes it", FrameWarning, stacklevel=3)


@dataclass(frozen=True)
class _RenderedFrame:
    """A frame rendered, its files not yet written (``_render_task``): ``frame`` (output frame
    index), ``result``, ``seconds`` ({stage: seconds [s]}), ``served`` (the cache items it was made
    from, ``store.Cache.served``) and ``caught`` (the warnings raised meanwhile, as (category, text))."""

    frame: int
    result: FrameResult
    seconds: dict[str, float]
    served: dict[str, Any]
    caught: tuple[tuple[type[Warning], str], ...]


@dataclass(frozen=True)
class _WrittenFrame:
    """A frame whose EXR and PNG are written, as the frame phase yields it (``_frame_task``):
    ``frame`` (output frame index), ``seconds`` ({stage: seconds [s]}, writing and digesting
    included), ``entry`` (its index.json entry), ``caught`` (the warnings raised meanwhile, as
    (category, text): a worker's are said by the process that runs the command) and ``codes``
    (the PNG's 8-bit codes (rows, cols, 3) [0..255] for the video encoded meanwhile,
    ``VideoStream``; None unless asked)."""

    frame: int
    seconds: dict[str, float]
    entry: dict[str, Any]
    caught: tuple[tuple[type[Warning], str], ...]
    codes: np.ndarray | None


def _frame_phase(run: _Run, plan: RunPlan, todo: list[int], *, codes: bool) -> Generator[_WrittenFrame, None, None]:
    """Render the ``todo`` frames in parallel; yields each as its files are written. With one
    local job the frames render here, one after another, and each frame's files are written by
    a thread while the next frame renders (``_frames_here``)."""
    if run.progress:
        run.progress("frames", 0, len(todo))
    results: Iterable[_WrittenFrame]
    if run.jobs == 1 and run.command is not None:
        results = _frames_here(run.config, plan, run.store, todo, run.digest, run.threads, codes)
    else:
        tasks = (joblib.delayed(_frame_task)(run.config, plan, frame, str(run.store.root), run.digest, run.threads,
                                             run.command, codes) for frame in todo)
        results = joblib.Parallel(n_jobs=min(run.jobs, len(todo)), return_as="generator_unordered")(tasks)
    for done, result in enumerate(results, 1):
        yield result
        if run.progress:
            run.progress("frames", done, len(todo))


def _frames_here(config: Config, plan: RunPlan, store: cache.Cache, todo: list[int], digest: str, threads: int,
                 codes: bool) -> Iterator[_WrittenFrame]:
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
                command: int | None = None, codes: bool = False) -> _WrittenFrame:
    """Render one frame and write its EXR, then its PNG, with the PNG's 8-bit codes if ``codes``
    (for the video the command's process encodes meanwhile, ``VideoStream``)."""
    end_if_orphaned(command)
    with compiled_once(_last_frame_loop()):  # while the command compiles the loops: wait, then load them
        return _write_task(config, _render_task(plan, frame, root, threads), digest, codes)


def _start_workers(config: Config, frames: tuple[int, ...] | None, jobs: int | None,
                   scheduler: str | None) -> Starting | None:
    """With local workers: have joblib start them now, from a thread, once the run's inputs are
    checked and its folder locked (a worker still starting as a command that failed ends prints
    loky's traceback), while this process checks the folder and meters the exposures, instead of
    when a phase first asks for them. Each imports what a task needs (0.6 s of CPU), and where numba's cache lacks the
    cycle products' loops (the built-in trees), one of them compiles them (``rasteriser.compile_loops``;
    docs/accuracy.md, "Compiling after an install"). The phases reuse them (joblib's reusable
    executor, the same size: one per frame asked, at most ``jobs``). Returns what ends when they
    are started (``_workers_started``); None where nothing was started: on a cluster, with one
    job, or for one frame."""
    count = min(jobs_and_threads(jobs or config.render.jobs, scheduler)[0],
                config.animation.frames if frames is None else len(frames))
    if scheduler or count < 2:
        return None
    trees = config.canopy.trees is not None and not config.canopy.meshes
    starting: Starting = concurrent.futures.Future()
    threading.Thread(target=_ready_workers, args=(starting, count, trees and not loops_cached(), os.getpid()),
                     name="sunshade-workers", daemon=True).start()
    return starting


def _ready_workers(starting: Starting, count: int, compile_cycle: bool, command: int) -> None:
    """``_ready_worker`` in each of the ``count`` local worker processes, the first compiling the cycle
    products' loops if ``compile_cycle``; ``starting`` ends with what it raised, if anything."""
    try:
        joblib.Parallel(n_jobs=count)(joblib.delayed(_ready_worker)(command, compile_cycle and k == 0)
                                      for k in range(count))
    except BaseException as exc:
        starting.set_exception(exc)
    else:
        starting.set_result(None)


def _ready_worker(command: int, compile_cycle: bool) -> None:
    """A worker process started and its modules imported (by loading this task), its end with the
    command ``command`` watched (``cores.end_if_orphaned``), its memory kept from being taken for a
    leak (``_keep_worker``); the cycle products' loops compiled (or loaded) if ``compile_cycle``."""
    end_if_orphaned(command)
    _keep_worker()
    if compile_cycle:
        rasteriser_compile_loops()


def _keep_worker() -> None:
    """Keep this worker process through the run: joblib's workers (loky's) measure their memory
    after their first task and end themselves, to be started again, where it has grown by 300 MB
    since. After ``_ready_worker``, a small first task, the first frame or cycle product grows it by
    more (a frame's rasters and caches), so the worker was ended there: started, imported and loaded
    again (2 s of CPU) and the command printed "A worker stopped while some jobs were given to the
    executor" (docs/accuracy.md, "A run's start and end"). Where loky has no such check (no
    psutil, or another version), nothing is done."""
    with contextlib.suppress(ImportError):
        from joblib.externals.loky import process_executor  # type: ignore[import-untyped]

        if getattr(process_executor, "_USE_PSUTIL", None) is True:
            process_executor._USE_PSUTIL = False  # its one switch: read by the worker's loop after each task


def _workers_started(starting: Starting | None) -> None:
    """Wait for ``_start_workers``'s workers (None: nothing). One that died meanwhile (killed, out of
    memory) raises BrokenProcessPool, which ends the run with ``_backend``'s line, as in a phase,
    instead of a phase starting another unseen; any other error is left to the phases."""
    if starting is not None and isinstance(error := starting.exception(), BrokenProcessPool):
        raise error


def _end_starting(starting: Starting | None) -> None:
    """Wait for ``_start_workers``'s thread to end, whatever it raised (None: nothing)."""
    if starting is not None:
        starting.exception()


def _compile_frame_loops(plan: RunPlan) -> None:
    """``frame.compile_loops``, and the display codes' loops of the writing (``display_codes`` of a
    tiny picture): the frames' workers then load them from numba's cache on disk. The lock of
    ``cores.compiled_once`` is held meanwhile, so that a worker whose first frame comes before
    they are cached waits for them instead of compiling them too (docs/accuracy.md, "Compiling
    after an install")."""
    with compiled_once(_last_frame_loop()):
        compile_loops(plan)
        with contextlib.suppress(Exception):  # only a head start: a frame meets the same error itself
            display_codes(np.zeros((2, 2, 3), dtype=np.float32), exposure=1.0)


def _frame_loops_cached() -> bool:
    """Whether numba's cache on disk holds the frames' loops (its index of ``_last_frame_loop``
    exists), so that the workers load them: loading them here too only took a core from the
    workers' first frames (1 to 2 s of CPU for configs/eclipse.yaml). After an install it does not,
    and ``_compile_frame_loops`` compiles them once; after an edit of a kernel the workers each
    compile what changed, as they would without this."""
    return on_disk(_last_frame_loop())


def _last_frame_loop() -> Any:
    """The frame loop that ``_compile_frame_loops`` compiles last (the display codes'): once numba's
    cache holds it, it holds the others."""
    from pipeline.kernels import arrays  # numba costs 0.3 s to import: a frame's worker needs it anyway

    return arrays.display_codes


def _render_task(plan: RunPlan, frame: int, root: str, threads: int) -> _RenderedFrame:
    """Render one frame, the warnings raised meanwhile caught."""
    timings: dict[str, float] = {}
    store = cache.Cache(root)
    with warnings.catch_warnings(record=True) as caught:
        result = render_frame(plan, frame, store=store, workers=threads, timings=timings)
    return _RenderedFrame(frame, result, timings, dict(store.served),
                          tuple((w.category, str(w.message)) for w in caught))


def _write_task(config: Config, rendered: _RenderedFrame, digest: str, codes: bool) -> _WrittenFrame:
    """Write a frame that ``_render_task`` rendered: its EXR, then its PNG."""
    frame, result, timings = rendered.frame, rendered.result, rendered.seconds
    mark = time.perf_counter()
    if not np.all(np.isfinite(result.radiance)):
        raise io.ImageError(config.path, f"frame {frame} overflowed; lower the sky's radiance")
    exr, png = frame_files(config, frame)
    io.write_exr(exr, in_working_space(config.output, result.radiance), frame_attributes(config, result, digest),
                 half=config.output.half, layers=exr_layers(result, config.output.half, config.output))
    picture = frame_picture(config, result)
    written = io.write_png(png, picture, {"sunshade:config_hash": digest, "sunshade:frame": str(frame)})
    timings["write"] = time.perf_counter() - mark
    mark = time.perf_counter()
    record = frame_record(config, frame, digest)
    if record is not None and result.light is not None:  # the report's light curve
        record["light"] = {"time_s": float(result.scene.time), "exposure": float(result.exposure), **result.light}
    entry = {"config_hash": digest, "files": {"exr": file_stamp(exr), "png": file_stamp(png)},
             "items": rendered.served, "record": record}
    timings["digest"] = time.perf_counter() - mark
    return _WrittenFrame(frame, timings, entry, rendered.caught, written if codes else None)



@contextlib.contextmanager
def _backend(scheduler: str | None, timeout: float = CLUSTER_TIMEOUT) -> Iterator[None]:
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

    def __init__(self, client: Client, timeout: float):
        self.client, self.timeout = client, timeout
        self.lost: str | None = None
        self.stop = threading.Event()

    def __enter__(self) -> _Watchdog:
        self.thread = threading.Thread(target=self._watch, name="sunshade-watchdog", daemon=True)
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join()

    def _watch(self) -> None:
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
