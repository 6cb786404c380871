"""The foreground models a config may name (``foreground.model``), each a class that the
registry ``vocabulary.FOREGROUNDS`` makes from the config's ``foreground`` section, and the
frame's foreground as one named record (docs/design.md, "Models plug in")."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .camera import Camera
from .settings import ForegroundConfig
from .inputs import imported_passes

__all__ = ["ForegroundLayer", "ForegroundModel", "TreesForeground", "ImportedForeground", "NoForeground",
           "cut_to_trees", "tree_box"]


@dataclass(frozen=True)
class ForegroundLayer:
    """A frame's foreground, to be blended by S and composited over the background.

    Attributes
    ----------
    sun : numpy.ndarray
        F_sun (rows, cols, 3) float32: the foreground lit by sun and sky [kcd/m^2].
    sky : numpy.ndarray
        F_sky (rows, cols, 3) float32: lit by the sky alone [kcd/m^2].
    alpha : numpy.ndarray
        (rows, cols) coverage [1].
    region : tuple of slice
        The (rows, cols) slices of the frame the passes cover.
    haze : numpy.ndarray or None
        (rows, cols) the share of the horizon's light veiling each pixel of the trees [1], or
        None (no haze, or imported passes).
    """

    sun: np.ndarray
    sky: np.ndarray
    alpha: np.ndarray
    region: tuple[slice, slice]
    haze: np.ndarray | None = None


class ForegroundModel(Protocol):
    """What the stages ask of a config's foreground. A class of this shape, its module and one
    line in ``vocabulary.FOREGROUNDS`` add a foreground model."""

    cached: bool
    """Whether its passes are cycle products (``cycle.foreground_item``), stored per unit light."""

    def layer(self, cycle_frame: int, *, view: Camera, item: dict | None, sun_irradiance: np.ndarray,
              sky_irradiance: np.ndarray, sun_down: np.ndarray, bounce: float) -> ForegroundLayer | None:
        """The foreground at ``cycle_frame`` (None: nothing in front of the ground): ``item``
        its cycle product when ``cached``; ``sun_irradiance`` the sun's normal irradiance and
        ``sky_irradiance`` the sky's horizontal one (3,) [klx], ``sun_down`` the sun's
        horizontal irradiance (3,) [klx], ``bounce`` the share of the ground's light that
        reaches the trees' undersides [1]."""

    def check(self, view: Camera, cycle: int) -> None:
        """Read and check the files of every cycle frame. Raises io.ImageError naming the file."""


@dataclass(frozen=True)
class TreesForeground:
    """The built-in trees, rendered per cycle frame per unit light (``cycle.foreground_item``)
    and lit by the run's light.

    Parameters
    ----------
    config : ForegroundConfig
        The config's ``foreground`` section.
    """

    config: ForegroundConfig
    cached = True

    def layer(self, cycle_frame, *, view, item, sun_irradiance, sky_irradiance, sun_down, bounce):
        # light bounced off the ground reaches the trees' undersides as more diffuse light: half
        # the ground's radiosity, its sun part following S with the sun pass
        sky = item["sky"] * (sky_irradiance * (1.0 + bounce)).astype(np.float32)
        sun = item["sun"] * sun_irradiance.astype(np.float32) + item["sky"] * (bounce * sun_down).astype(np.float32)
        return ForegroundLayer(sky + sun, sky, item["alpha"], tree_box(item), item.get("haze"))

    def check(self, view, cycle):
        pass


@dataclass(frozen=True)
class ImportedForeground:
    """Passes rendered elsewhere and read from files, one set per cycle frame
    (``foreground.sun``, ``sky``, ``alpha``), over the whole frame.

    Parameters
    ----------
    config : ForegroundConfig
        The config's ``foreground`` section.
    """

    config: ForegroundConfig
    cached = False

    def layer(self, cycle_frame, *, view, item, sun_irradiance, sky_irradiance, sun_down, bounce):
        passes = imported_passes(self.config, view, cycle_frame)
        return ForegroundLayer(passes.sun, passes.sky, passes.alpha, (slice(None), slice(None)))

    def check(self, view, cycle):
        for cycle_frame in range(cycle):
            imported_passes(self.config, view, cycle_frame)


@dataclass(frozen=True)
class NoForeground:
    """Nothing in front of the ground and sky.

    Parameters
    ----------
    config : ForegroundConfig
        The config's ``foreground`` section.
    """

    config: ForegroundConfig
    cached = False

    def layer(self, cycle_frame, **light):
        return None

    def check(self, view, cycle):
        pass


def cut_to_trees(passes: dict) -> dict:
    """Full-frame passes cut to the box of the pixels where any of them is not 0: outside it a
    frame is its background, so nothing is lost, and a grove that fills a tenth of the picture
    is stored in about a tenth of the bytes.

    Parameters
    ----------
    passes : dict
        {name: (rows, cols[, 3]) array}, ``alpha`` among them.

    Returns
    -------
    dict
        The passes cut, with ``box`` (row_start, row_stop, col_start, col_stop) [pixel].
    """
    touched = np.zeros(passes["alpha"].shape, dtype=bool)
    for values in passes.values():
        touched |= values.reshape(*touched.shape, -1).any(axis=-1)
    rows, cols = np.flatnonzero(touched.any(axis=1)), np.flatnonzero(touched.any(axis=0))
    box = (rows[0], rows[-1] + 1, cols[0], cols[-1] + 1) if len(rows) else (0, 0, 0, 0)
    cut = {name: np.ascontiguousarray(values[box[0]:box[1], box[2]:box[3]]) for name, values in passes.items()}
    return {**cut, "box": np.array(box, dtype=np.int64)}


def tree_box(item: dict) -> tuple[slice, slice]:
    """The part of the frame that passes cut by ``cut_to_trees`` cover.

    Parameters
    ----------
    item : dict
        Passes with their ``box``.

    Returns
    -------
    tuple of slice
        (rows, cols).
    """
    r0, r1, c0, c1 = (int(v) for v in item["box"])
    return slice(r0, r1), slice(c0, c1)
