"""The walls' cycle products: each wall's layers (its masks and the grove in front of it) drawn at
each flutter cycle frame and transformed, cached like the ground's layer spectra and computed in
the cycle phase (docs/method.md, "Receivers: walls and slopes"). Every function takes the RunPlan."""

from __future__ import annotations

import functools
from dataclasses import asdict
from typing import Any

import numpy as np

from pipeline.cache import store as cache
from pipeline.receivers.walls import WallPlan, WallSpectra, wall_plan, wall_spectra
from pipeline.sky.base import Sky
from pipeline.stages.inputs import file_sha256, isolated_grove
from pipeline.stages.plan import RunPlan

__all__ = ["WALL_KIND", "wall_task", "wall_index", "wall_run_plan", "wall_params", "wall_item", "wall_grove"]

WALL_KIND = "wall-spectra"
"""The cache kind of a wall's layers' spectra at a cycle frame."""

_TASK = "wall:"


def wall_task(index: int) -> str:
    """The cycle phase's name of wall ``index``'s products (``wall_index`` reads it back).

    Parameters
    ----------
    index : int
        An index of ``plan.receivers.walls``.

    Returns
    -------
    str
        ``"wall:<index>"``.
    """
    return f"{_TASK}{index}"


def wall_index(task: object) -> int | None:
    """The wall a cycle-phase task names (``wall_task``), or None for another product.

    Parameters
    ----------
    task : object
        A task's layer field: an int (a canopy layer), None (the foreground) or a wall's name.

    Returns
    -------
    int or None
        The wall's index.
    """
    return int(task[len(_TASK):]) if isinstance(task, str) and task.startswith(_TASK) else None


def wall_grove(plan: RunPlan) -> tuple | None:
    """The grove the walls are shaded by: an isolated canopy's built-in trees, else None.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.

    Returns
    -------
    (canopy.grove.Grove, canopy.grove.FlutterParams) or None
        The grove at rest and its flutter.
    """
    return isolated_grove(plan.canopy)


def wall_run_plan(plan: RunPlan, index: int) -> WallPlan:
    """Wall ``index``'s plan for the run: the grove projected along the middle frame's sun (as the
    ground's canopy, ``stages.plan``), the fine plans holding every frame's sun kernel.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    index : int
        An index of ``plan.receivers.walls``.

    Returns
    -------
    receivers.walls.WallPlan
        Made once per process for a run's walls, canopy, scenes and sky.
    """
    return _run_plan(plan.receivers, plan.canopy, plan.scenes, plan.sky, index)  # type: ignore[arg-type]


@functools.lru_cache(maxsize=16)
def _run_plan(receivers: Any, canopy: Any, scenes: tuple, sky_model: Any, index: int) -> WallPlan:
    suns: dict[Any, Sky] = {}
    for scene in scenes:  # one sky per sun: the kernel's place follows the sun alone
        if scene.sun not in suns:
            suns[scene.sun] = sky_model.at(scene)
    middle = sky_model.at(scenes[len(scenes) // 2])
    return wall_plan(receivers.walls[index], middle, grove=isolated_grove(canopy), suns=tuple(suns.values()),
                     where=f"receivers.walls[{index}]")


def wall_params(plan: RunPlan, index: int, cycle_frame: int) -> dict[str, Any]:
    """Everything wall ``index``'s products at ``cycle_frame`` depend on: their cache key's params.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    index : int
        An index of ``plan.receivers.walls``.
    cycle_frame : int
        The flutter cycle's frame.

    Returns
    -------
    dict
        JSON-able params (``keys.key_of``): the wall (its plane, pixel, masks and their files'
        SHA-256), the trees and their flutter, the wall's plan (grids, distances, correlation plans,
        the sun's projection), the frame.
    """
    wall = plan.receivers.walls[index]
    c = plan.canopy
    trees = None
    if c.trees is not None and wall_grove(plan) is not None:
        trees = {"trees": asdict(c.trees), "flutter": asdict(c.flutter), "heights": [l.height for l in c.layers]}
    masks = [file_sha256(m.image) for m in wall.masks]
    return {"wall": asdict(wall), "masks": masks, "trees": trees, "plan": wall_run_plan(plan, index),
            "frame": cycle_frame}


def wall_item(plan: RunPlan, index: int, cycle_frame: int, store: cache.Cache, *, workers: int = 1) -> WallSpectra:
    """Wall ``index``'s cached layer spectra at ``cycle_frame``, computed on a miss.

    Parameters
    ----------
    plan, index, cycle_frame
        As in ``wall_params``.
    store : store.Cache
        The cache.
    workers : int, optional
        FFT threads for a miss.

    Returns
    -------
    receivers.walls.WallSpectra
        complex64, memory-mapped, read-only; the item keeps them as ``coarse<i>`` and ``fine<i>``.
    """
    wplan = wall_run_plan(plan, index)

    def compute() -> dict[str, np.ndarray]:
        spectra = wall_spectra(plan.receivers.walls[index], wplan, grove=wall_grove(plan), cycle_frame=cycle_frame,
                               where=f"receivers.walls[{index}]", workers=workers)
        item = {f"coarse{i}": np.asarray(a, dtype=np.complex64) for i, a in enumerate(spectra.coarse)}
        item.update({f"fine{i}": np.asarray(a, dtype=np.complex64)
                     for i, a in enumerate(spectra.fine) if a is not None})
        return item

    item = store.get_or_compute(WALL_KIND, wall_params(plan, index, cycle_frame), compute)
    count = len(wplan.layers)
    return WallSpectra(tuple(item[f"coarse{i}"] for i in range(count)),
                       tuple(item.get(f"fine{i}") for i in range(count)))
