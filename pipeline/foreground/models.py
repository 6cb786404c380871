"""The foreground models a config may name (``foreground.model``), each a class that the
registry ``vocabulary.FOREGROUNDS`` makes from the config's ``foreground`` section, and the
frame's foreground as one named record (docs/design.md, "Models plug in")."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from pipeline.camera.pinhole import Camera
from pipeline.config.settings import ForegroundConfig
from pipeline.foreground.passes import imported_passes

__all__ = ["ForegroundLayer", "StoredTreePasses", "ForegroundModel", "TreesForeground", "ImportedForeground",
           "NoForeground", "cut_to_trees", "tree_box"]


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


@dataclass(frozen=True)
class StoredTreePasses:
    """The built-in trees' passes of one cycle frame as the cache holds them
    (``cycle.foreground_item``): per unit light, cut to the box of the pixels the trees touch
    (``cut_to_trees``), memory-mapped and read-only.

    Attributes
    ----------
    sun : numpy.ndarray
        (rows, cols, 3) the sun's term for a normal irradiance of 1 in each channel [1/sr].
    sky : numpy.ndarray
        (rows, cols, 3) the sky's term for a horizontal irradiance of 1 in each channel [1/sr].
    alpha : numpy.ndarray
        (rows, cols) coverage [1].
    region : tuple of slice
        The (rows, cols) slices of the frame the passes cover (``tree_box``).
    haze : numpy.ndarray or None
        (rows, cols) the share of the horizon's light veiling each pixel of the trees [1], or
        None without haze.
    """

    sun: np.ndarray
    sky: np.ndarray
    alpha: np.ndarray
    region: tuple[slice, slice]
    haze: np.ndarray | None = None

    @classmethod
    def from_item(cls, item: Mapping[str, np.ndarray]) -> StoredTreePasses:
        """The passes of a cache item.

        Parameters
        ----------
        item : mapping of str to ndarray
            The item's arrays, as ``cut_to_trees`` gives them: ``sun``, ``sky``, ``alpha``,
            ``box`` and maybe ``haze``.

        Returns
        -------
        StoredTreePasses
            The same arrays, named; ``box`` as the region it covers.
        """
        return cls(item["sun"], item["sky"], item["alpha"], tree_box(item), item.get("haze"))


class ForegroundModel(Protocol):
    """What the stages ask of a config's foreground. A class of this shape, its module and one
    line in ``vocabulary.FOREGROUNDS`` add a foreground model."""

    cached: bool
    """Whether its passes are cycle products, stored per unit light: those of the built-in trees,
    which ``cycle.foreground_item`` renders (docs/design.md, "Models plug in")."""

    def layer(self, cycle_frame: int, *, view: Camera, item: StoredTreePasses | None, sun_irradiance: np.ndarray,
              sky_irradiance: np.ndarray, sun_down: np.ndarray, bounce: np.ndarray) -> ForegroundLayer | None:
        """The foreground at a cycle frame, lit by the frame's light.

        Parameters
        ----------
        cycle_frame : int
            The flutter cycle's frame.
        view : Camera
            The run's camera.
        item : StoredTreePasses or None
            Its cycle product when ``cached`` (per unit light), else None.
        sun_irradiance : ndarray, shape (3,)
            The sun's normal irradiance [klx].
        sky_irradiance : ndarray, shape (3,)
            The sky's horizontal irradiance [klx].
        sun_down : ndarray, shape (3,)
            The sun's horizontal irradiance [klx].
        bounce : ndarray, shape (3,)
            The share of the ground's light that reaches the trees' undersides, per channel [1].

        Returns
        -------
        ForegroundLayer or None
            The passes [kcd/m^2], or None: nothing in front of the ground.
        """

    def check(self, view: Camera, cycle: int) -> None:
        """Read and check the files of every cycle frame.

        Parameters
        ----------
        view : Camera
            The run's camera (the passes' size must be its image's).
        cycle : int
            The flutter cycle's number of frames [1].

        Raises
        ------
        io.ImageError
            Naming the file.
        """


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

    def layer(self, cycle_frame: int, *, view: Camera, item: StoredTreePasses | None, sun_irradiance: np.ndarray,
              sky_irradiance: np.ndarray, sun_down: np.ndarray, bounce: np.ndarray) -> ForegroundLayer:
        """See ``ForegroundModel.layer``.

        Parameters
        ----------
        cycle_frame, view, sun_irradiance, sky_irradiance, sun_down, bounce
            As in ``ForegroundModel.layer``.
        item : StoredTreePasses or None
            The cycle product, per unit light.

        Returns
        -------
        ForegroundLayer
            The trees lit [kcd/m^2], cut to their box (``tree_box``).

        Raises
        ------
        ValueError
            Without the cycle product.
        """
        if item is None:
            raise ValueError("the built-in trees are lit from their cycle product (cycle.foreground_item)")
        # light bounced off the ground reaches the trees' undersides as more diffuse light: half
        # the ground's radiosity, its sun part following S with the sun pass
        sky = item.sky * (sky_irradiance * (1.0 + bounce)).astype(np.float32)
        sun = item.sun * sun_irradiance.astype(np.float32) + item.sky * (bounce * sun_down).astype(np.float32)
        return ForegroundLayer(sky + sun, sky, item.alpha, item.region, item.haze)

    def check(self, view: Camera, cycle: int) -> None:
        """See ``ForegroundModel.check``: nothing to read, the trees are rendered here.

        Parameters
        ----------
        view, cycle
            As in ``ForegroundModel.check`` (not used).
        """
        pass


@dataclass(frozen=True)
class ImportedForeground:
    """Passes rendered elsewhere and read from files, one set per cycle frame
    (``foreground.sun``, ``sky``, ``alpha``), over the whole frame.

    Parameters
    ----------
    config : ForegroundConfig
        The config's ``foreground`` section, naming the files.
    """

    config: ForegroundConfig
    cached = False

    def layer(self, cycle_frame: int, *, view: Camera, item: StoredTreePasses | None, sun_irradiance: np.ndarray,
              sky_irradiance: np.ndarray, sun_down: np.ndarray, bounce: np.ndarray) -> ForegroundLayer:
        """See ``ForegroundModel.layer``: the passes read (``passes.imported_passes``).

        Parameters
        ----------
        cycle_frame, view
            As in ``ForegroundModel.layer``.
        item : StoredTreePasses or None
            The cycle product (None: not cached).
        sun_irradiance, sky_irradiance, sun_down, bounce
            Not used: the passes are lit.

        Returns
        -------
        ForegroundLayer
            The passes read [kcd/m^2], over the whole frame.
        """
        passes = imported_passes(self.config, view, cycle_frame)
        return ForegroundLayer(passes.sun, passes.sky, passes.alpha, (slice(None), slice(None)))

    def check(self, view: Camera, cycle: int) -> None:
        """See ``ForegroundModel.check``: each cycle frame's passes read.

        Parameters
        ----------
        view, cycle
            As in ``ForegroundModel.check``.
        """
        for cycle_frame in range(cycle):
            imported_passes(self.config, view, cycle_frame)


@dataclass(frozen=True)
class NoForeground:
    """Nothing in front of the ground and sky.

    Parameters
    ----------
    config : ForegroundConfig
        The config's ``foreground`` section (not used).
    """

    config: ForegroundConfig
    cached = False

    def layer(self, cycle_frame: int, **light: object) -> None:
        """See ``ForegroundModel.layer``.

        Parameters
        ----------
        cycle_frame : int
            The flutter cycle's frame (not used).
        **light
            ``view``, ``item`` and the light (not used).

        Returns
        -------
        None
            Nothing in front of the ground.
        """
        return None

    def check(self, view: Camera, cycle: int) -> None:
        """See ``ForegroundModel.check``: nothing to read.

        Parameters
        ----------
        view, cycle
            Not used.
        """
        pass


def cut_to_trees(passes: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
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


def tree_box(item: Mapping[str, np.ndarray]) -> tuple[slice, slice]:
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
