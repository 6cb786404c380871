"""Foreground passes as data: the trees' ``sun``, ``sky`` and ``alpha`` images of one cycle frame, checked
against the camera, or read from files (docs/method.md, "The foreground passes").
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from pipeline.camera.pinhole import Camera
from pipeline.config.settings import ForegroundConfig
from pipeline.core.io import ImageError, read_finite_image

__all__ = ["ForegroundPasses", "check_passes_size", "read_passes", "imported_passes"]


@dataclass(frozen=True)
class ForegroundPasses:
    """The trees of one cycle frame, premultiplied scene-linear.

    Attributes
    ----------
    sun : numpy.ndarray
        (rows, cols, 3) float32, lit by the clear sun and the sky [kcd/m^2].
    sky : numpy.ndarray
        (rows, cols, 3) float32, lit by the sky alone [kcd/m^2].
    alpha : numpy.ndarray
        (rows, cols) float32 coverage in [0, 1] [1].
    haze : numpy.ndarray or None
        (rows, cols) float32, the share of the pixel that the haze in front of the trees veils, sum
        over fragments of weight (1 - T): a frame adds it times the sky at the horizon
        (Koschmieder, as the ground); the sun and sky passes hold T times the trees' light. None: no
        haze [1].

    Raises
    ------
    ValueError
        When alpha is not (rows, cols) or a pass is not (rows, cols, 3).
    """

    sun: np.ndarray
    sky: np.ndarray
    alpha: np.ndarray
    haze: np.ndarray | None = None

    def __post_init__(self) -> None:
        if np.ndim(self.alpha) != 2:
            raise ValueError(f"alpha must be (rows, cols), got shape {np.shape(self.alpha)}")
        rows, cols = np.shape(self.alpha)
        for name in ("sun", "sky"):
            if np.shape(getattr(self, name)) != (rows, cols, 3):
                raise ValueError(f"the {name} pass is {np.shape(getattr(self, name))}, "
                                 f"expected {(rows, cols, 3)} to go with alpha {(rows, cols)}")

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the passes. [pixel]"""
        return tuple(np.shape(self.alpha))


def check_passes_size(passes: ForegroundPasses, camera: Camera) -> None:
    """Raise ValueError unless the passes are the camera's image size.

    Parameters
    ----------
    passes : ForegroundPasses
        The passes.
    camera : pinhole.Camera
        The camera whose image they go in: (height, width) [pixel].
    """
    rows, cols = passes.shape
    if (rows, cols) != (camera.height, camera.width):
        raise ValueError(f"the foreground passes are {cols} x {rows} pixels but the camera's image "
                         f"is {camera.width} x {camera.height}")


def read_passes(sun_path: str | os.PathLike[str], sky_path: str | os.PathLike[str],
                alpha_path: str | os.PathLike[str]) -> ForegroundPasses:
    """Foreground passes from image files (EXR, premultiplied, scene-linear).

    Parameters
    ----------
    sun_path, sky_path : str or os.PathLike
        RGB images [kcd/m^2] (channels past the third are ignored; one or two channels are taken as
        grey from the first).
    alpha_path : str or os.PathLike
        The coverage [1]: the A channel of a 4-channel image, else its first channel.

    Returns
    -------
    ForegroundPasses
        The passes, alpha clipped to [0, 1].

    Raises
    ------
    io.ImageError
        Naming the file: unreadable, non-finite values, alpha outside [0, 1] (beyond 1e-3) or a size
        that differs from the sun pass's.
    """
    images: list[np.ndarray] = []
    for path in (sun_path, sky_path, alpha_path):
        image = read_finite_image(path, "pass")
        if images and image.shape[:2] != images[0].shape[:2]:
            (rows, cols), (want_rows, want_cols) = image.shape[:2], images[0].shape[:2]
            raise ImageError(path, f"its size {cols} x {rows} differs from {want_cols} x {want_rows} "
                                   f"of the sun pass {sun_path}")
        images.append(image)
    sun, sky, alpha = images
    sun, sky = (im[..., :3] if im.shape[2] >= 3 else np.repeat(im[..., :1], 3, axis=2) for im in (sun, sky))
    alpha = alpha[..., 3] if alpha.shape[2] == 4 else alpha[..., 0]
    low, high = float(alpha.min(initial=0.0)), float(alpha.max(initial=0.0))
    if low < -1e-3 or high > 1 + 1e-3:
        raise ImageError(alpha_path, f"alpha must lie in [0, 1]; found {low:.4g} to {high:.4g}")
    return ForegroundPasses(np.ascontiguousarray(sun, dtype=np.float32),
                            np.ascontiguousarray(sky, dtype=np.float32),
                            np.clip(alpha, 0.0, 1.0).astype(np.float32))


def imported_passes(fg: ForegroundConfig, view: Camera, cycle_frame: int) -> ForegroundPasses:
    """The imported passes of a cycle frame, read and checked against the camera's size.

    Parameters
    ----------
    fg : settings.ForegroundConfig
        The ``foreground`` section: per cycle frame its ``sun``, ``sky`` and ``alpha`` files.
    view : pinhole.Camera
        The run's camera; the passes must be its image's size.
    cycle_frame : int
        The flutter cycle's frame.

    Returns
    -------
    ForegroundPasses
        The sun and sky passes [kcd/m^2] and alpha [1].

    Raises
    ------
    ImageError
        Naming the file.
    """
    passes = read_passes(fg.sun[cycle_frame], fg.sky[cycle_frame], fg.alpha[cycle_frame])
    try:
        check_passes_size(passes, view)
    except ValueError as exc:
        raise ImageError(fg.sun[cycle_frame], str(exc)) from None
    return passes
