"""The machines a run uses: how many frames are rendered at once, with how many FFT threads (and
threads for a frame's compiled loops), and how long a lost Dask cluster is waited for."""

from __future__ import annotations

import concurrent.futures
import contextlib
import contextvars
import os
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["on_disk", "MAX_JOBS_PER_CORE", "CLUSTER_TIMEOUT", "SCHEDULER_SCHEMES", "ORPHAN_CHECK", "scheduler_address",
           "default_workers", "jobs_and_threads", "loop_threads", "in_shares", "SHARES_PER_THREAD", "SMALLEST_SHARE",
           "end_if_orphaned", "compiled_once"]

MAX_JOBS_PER_CORE = 4
"""Most worker processes a local run starts per core (--jobs, render.jobs): each holds a
frame's rasters."""
CLUSTER_TIMEOUT = 30.0
"""How long a run waits for a lost Dask cluster (no scheduler, or no workers) before it ends
with one line saying how to resume. [s]"""


SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss")
"""The dask.distributed protocols of a --scheduler address, each HOST:PORT."""


def scheduler_address(text: str) -> tuple[str, int] | str:
    """(host, port) of a dask.distributed scheduler address, checked without connecting.

    Parameters
    ----------
    text : str
        ``tcp://HOST:PORT`` or ``HOST:PORT`` (tls://, ws:// and wss:// too: SCHEDULER_SCHEMES).

    Returns
    -------
    tuple of (str, int) or str
        (host, port) when the address is good; else what is wrong with it, in words.
    """
    from urllib.parse import urlsplit

    address = urlsplit(text if "://" in text else f"tcp://{text}")
    try:
        port = address.port
    except ValueError:  # not a number, or past 65535
        port = -1
    if address.scheme not in SCHEDULER_SCHEMES:
        return f"the protocol must be one of {', '.join(s + '://' for s in SCHEDULER_SCHEMES)}"
    if not address.hostname or port is None:
        return "must be an address HOST:PORT, e.g. tcp://127.0.0.1:8786"
    if not 1 <= port <= 65535:
        return "the port must be a whole number from 1 to 65535"
    return address.hostname, port


def default_workers() -> int:
    """FFT threads: the cores this process may use.

    Returns
    -------
    int
        The cores in this process's affinity mask (the machine's cores where there is none), at
        least 1 [count].
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def jobs_and_threads(jobs: int | None, scheduler: str | None) -> tuple[int, int]:
    """(processes at once, FFT threads each) of a run.

    Parameters
    ----------
    jobs : int or None
        Frames rendered at once (--jobs, render.jobs); None: one per core.
    scheduler : str or None
        The Dask scheduler's address on a cluster, None for a local run.

    Returns
    -------
    tuple of (int, int)
        ``jobs`` and the FFT threads of each: an equal share of the cores, or one thread each on
        a cluster [count].
    """
    jobs = jobs or default_workers()
    return jobs, 1 if scheduler else max(1, default_workers() // jobs)


SHARES_PER_THREAD = 8
"""Shares a loop is cut into per thread (``in_shares``): its items cost unequally (a sky pixel near
the horizon reads 16 taps, one overhead a few), so equal halves would leave one thread idle."""
SMALLEST_SHARE = 16384
"""Fewest items worth a share of their own (``in_shares``): below it a thread costs more than it
saves. [items]"""
_LOOP_THREADS = contextvars.ContextVar("sunshade_loop_threads", default=1)
# (process, threads): the executor of in_shares
_pools: dict[tuple[int, int], concurrent.futures.ThreadPoolExecutor] = {}


@contextlib.contextmanager
def loop_threads(count: int) -> Iterator[None]:
    """Within the ``with`` (in this thread), ``in_shares`` runs loops in ``count`` threads, as
    scipy.fft's ``workers`` runs the FFTs: a frame's compiled loops then use the cores its FFTs use
    (``frame.render_frame``; a run of one frame per core gives each frame one thread, the loops
    running as before).

    Parameters
    ----------
    count : int
        Threads [count].

    Yields
    ------
    None
        While the block runs.
    """
    token = _LOOP_THREADS.set(max(1, int(count)))
    try:
        yield
    finally:
        _LOOP_THREADS.reset(token)


def in_shares(count: int, loop: Callable[[int, int], object]) -> None:
    """``loop(start, stop)`` over items [0, count), cut into shares run in the threads of
    ``loop_threads`` (SHARES_PER_THREAD shares each, none under SMALLEST_SHARE items); in this
    thread alone outside one, or for few items. Each item's result is the same whichever share
    holds it, so the bits do not depend on the threads.

    Parameters
    ----------
    count : int
        Items [count].
    loop : callable
        ``loop(start, stop)`` does items start to stop - 1; a compiled loop that releases the GIL
        (``nogil=True``), or the threads wait on each other.
    """
    threads = min(_LOOP_THREADS.get(), count // SMALLEST_SHARE)
    if threads <= 1:
        loop(0, count)
        return
    shares = min(threads * SHARES_PER_THREAD, count // SMALLEST_SHARE)
    bounds = [count * k // shares for k in range(shares + 1)]
    key = (os.getpid(), threads)  # a forked process makes its own: its parent's threads are not in it
    if key not in _pools:
        _pools[key] = concurrent.futures.ThreadPoolExecutor(threads, thread_name_prefix="sunshade-loop")
    for _ in _pools[key].map(lambda k: loop(bounds[k], bounds[k + 1]), range(shares)):
        pass


def end_if_orphaned(command: int | None) -> None:
    """End this process (exit code 1) when it is a worker process of a command that is gone.

    The command may be gone killed even by SIGKILL: the worker's parent is then another process,
    and nothing would record what it renders. Called as each task starts; the first call also
    leaves a thread that looks once a second (ORPHAN_CHECK), for a worker that waits for tasks that
    will not come. Nothing happens in the command's own process (``--jobs 1``) or on a cluster.

    Parameters
    ----------
    command : int or None
        The process ID of the ``sunshade`` command that started the workers; None on a cluster.
    """
    global _watched
    if command is None or os.getpid() == command:
        return
    if os.getppid() != command:
        os._exit(1)
    if _watched != command:
        _watched = command
        threading.Thread(target=_watch, args=(command,), daemon=True, name="sunshade-orphan-check").start()


ORPHAN_CHECK = 1.0
"""How often a worker process looks whether its command is still there. [s]"""
_watched: int | None = None


def _watch(command: int) -> None:
    while os.getppid() == command:
        time.sleep(ORPHAN_CHECK)
    os._exit(1)


_ran_loops: set[str] = set()  # the compiled loops this process has run (compiled, or loaded from numba's cache)


def on_disk(loop: Any) -> bool:
    """Whether numba's cache on disk holds a compiled loop, so that a process loads it instead of
    compiling it (docs/runs.md, "Compiled loops").

    Parameters
    ----------
    loop : numba dispatcher
        A function compiled with ``cache=True``.

    Returns
    -------
    bool
        The index file of its cache exists; False where numba keeps no cache of it.
    """
    try:
        return os.path.exists(loop._cache._cache_file._index_path)  # numba's FunctionCache: its index file
    except AttributeError:
        return False


@contextlib.contextmanager
def compiled_once(loop: Any) -> Iterator[None]:
    """Hold off the machine's other processes while this one first runs a compiled loop that numba's
    cache on disk lacks, so that one process compiles it and the others load it from that cache.

    After an install the cycle phase's workers each compiled the same leaf rasteriser (3.7 s of CPU
    for configs/eclipse.yaml); now the first to start compiles it while the others wait for it (docs/runs.md,
    "Compiled loops"). A lock file beside numba's cache of ``loop``; nothing is held once this process
    has run the loop, when numba's cache has it, or where numba keeps no cache of it.

    Parameters
    ----------
    loop : numba dispatcher
        A function compiled with ``cache=True`` that the work inside the ``with`` runs first.

    Yields
    ------
    None
        While the block runs.
    """
    name = f"{loop.py_func.__module__}.{loop.py_func.__qualname__}"
    lock = None
    if name not in _ran_loops:
        try:
            if not on_disk(loop):
                cached = loop._cache  # numba's FunctionCache: its folder
                from filelock import FileLock

                os.makedirs(cached._cache_path, exist_ok=True)
                lock = FileLock(os.path.join(cached._cache_path, f"{name}.compiling.lock"))
                lock.acquire()
        except (AttributeError, OSError):  # no cache, or none that can be written: each compiles
            lock = None
    try:
        yield
        _ran_loops.add(name)
    finally:
        if lock is not None:
            lock.release()
