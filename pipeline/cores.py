"""The machines a run uses: how many frames are rendered at once, with how many FFT threads,
and how long a lost Dask cluster is waited for."""

from __future__ import annotations

import os

MAX_JOBS_PER_CORE = 4
"""Most worker processes a local run starts per core (--jobs, render.jobs): each holds a
frame's rasters."""
CLUSTER_TIMEOUT = 30.0
"""How long a run waits for a lost Dask cluster (no scheduler, or no workers) before it ends
with one line saying how to resume. [s]"""


def default_workers() -> int:
    """FFT threads: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def jobs_and_threads(jobs: int | None, scheduler: str | None) -> tuple[int, int]:
    """(processes at once, FFT threads each): ``jobs`` (default one per core), each with an
    equal share of the cores, or one thread each on a cluster (``scheduler``)."""
    jobs = jobs or default_workers()
    return jobs, 1 if scheduler else max(1, default_workers() // jobs)
