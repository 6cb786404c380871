"""What a still view keeps from frame to frame: a result computed at the same read-only arrays (a
still camera's rays and footprints) for the same key, kept from the second time it is asked for.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    import numpy as np

__all__ = ["POINTS_KEPT", "kept_at"]

_Result = TypeVar("_Result")

POINTS_KEPT = 3
"""How many (key, points) one ``kept_at`` store keeps: a frame's camera's reads of its ground's three
maps with a wall (the window's, the coarse ground's beyond it, the far ground's), or a frame's camera
and a second view."""


def kept_at(kept: dict[Any, Any], key: Hashable, points: np.ndarray | tuple[np.ndarray, ...],
            compute: Callable[[], _Result], *, read_only: bool = True,
            first: Callable[[], _Result] | None = None) -> _Result:
    """What ``compute()`` gives at read-only ``points`` for ``key``, kept in ``kept`` from the second
    time the same key and the same arrays (not others at reused addresses) are asked for, for the last
    ``POINTS_KEPT`` of them, read-only: a sky that moves asks once per key, and arrays kept for nothing
    are fresh memory to fill in the next frame (as ``sky.raster.kept_raster``'s ``again``).

    Parameters
    ----------
    kept : dict
        {(key, ids of the points): (points, the result or None when asked for once)}, written.
    key : hashable
        What the result depends on besides the points (a sky, a cloud layer, a mip map's geometry).
    points : numpy.ndarray or tuple of numpy.ndarray
        The read-only points (a still camera's rays; with their footprints).
    compute : callable
        ``compute()`` -> a numpy.ndarray or a tuple of them, the result at ``points``.
    read_only : bool
        Whether what is kept is made read-only; False for arrays that go to numba's loops, which
        compile read-only arrays as another signature (the callers then must not write to them).
    first : callable or None
        What the first ask gives instead of ``compute()`` (e.g. None, for a result that costs more
        to make than to do without once).

    Returns
    -------
    numpy.ndarray or tuple of numpy.ndarray
        ``compute()``'s (``first()``'s at the first ask, when given), read-only when kept and
        ``read_only``.
    """
    arrays = points if isinstance(points, tuple) else (points,)
    slot = (key, tuple(id(a) for a in arrays))
    found = kept.pop(slot, None)
    seen = found is not None and all(a is b for a, b in zip(found[0], arrays))
    if seen and found[1] is not None:
        kept[slot] = found
        return found[1]
    result = compute() if seen or first is None else first()
    if seen and read_only:
        arrays_made: tuple[Any, ...] = result if isinstance(result, tuple) else (result,)
        for array in arrays_made:
            array.setflags(write=False)
    while len(kept) >= POINTS_KEPT:
        kept.pop(next(iter(kept)))
    kept[slot] = (arrays, result if seen else None)
    return result
