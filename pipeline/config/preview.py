"""The preview: a config made small and fast for a first look (``sunshade render --preview``).

Coarser rasters and fewer pixels, every leaf and the sky kept, so that the crescents and flecks
of the full render show (docs/accuracy.md, "Speed: preview and cycle phase").
"""

from __future__ import annotations

import math
from dataclasses import replace

from pipeline.config.settings import CameraConfig, Config

__all__ = ["PREVIEW_CYCLE", "PREVIEW_SCALE", "PREVIEW_SUN_CELLS", "preview", "preview_sun_cells"]

PREVIEW_SCALE = 4
"""A preview's camera has this many times fewer pixels across, its ground pixels are this many
times larger."""
PREVIEW_SUN_CELLS = 6
"""Cells across the sun disc's diameter on its fine grid in a preview whose camera has the
default field of view (more for a narrower one: ``preview_sun_cells``)."""
PREVIEW_CYCLE = 8
"""A preview's procedural leaves flutter through at most this many cycle frames (faster than in
the full render): the cycle phase, a mask and its spectra per cycle frame, shrinks with it."""


def preview(config: Config) -> Config:
    """The config made small and fast for a first look.

    A quarter of the camera's resolution, ground pixels four times larger (less where a
    periodic tile must stay a whole number of them), the sun disc 6 cells across, more under a
    narrower field of view (``preview_sun_cells``; imported
    foreground passes keep the camera's resolution), walls' pixels four times larger, a flutter
    cycle of at most 8 frames for procedural trees (not with imported passes, one per cycle
    frame), the run in the
    ``preview`` folder inside the output folder. Everything else, every leaf and the sky
    included, is kept.

    Parameters
    ----------
    config : Config
        The full render's config.

    Returns
    -------
    Config
        The preview's config.
    """
    ground = config.ground
    factor = PREVIEW_SCALE
    if config.canopy.layout == "periodic":
        sides = [side / ground.pixel for layer in config.canopy.layers for side in layer.size]
        factor = next(f for f in range(PREVIEW_SCALE, 0, -1)
                      if all(abs(n / f - round(n / f)) < 1e-6 * n for n in sides))
    pixel = ground.pixel * factor
    cells = preview_sun_cells(config)
    sun_pixel = None
    if ground.sun_pixel is not None:
        sun_pixel = min(ground.sun_pixel * 16 / cells, pixel)
    width, height = config.camera.resolution
    if config.foreground.model != "passes":  # imported passes keep their size
        width, height = max(2, width // PREVIEW_SCALE), max(2, height // PREVIEW_SCALE)
    canopy = config.canopy
    if canopy.trees is not None and config.foreground.model != "passes":
        canopy = replace(canopy, flutter=replace(canopy.flutter, cycle=min(canopy.flutter.cycle, PREVIEW_CYCLE)))
    walls = tuple(replace(wall, pixel=wall.pixel * PREVIEW_SCALE) for wall in config.receivers.walls)
    return replace(
        config,
        canopy=canopy,
        receivers=replace(config.receivers, walls=walls),
        ground=replace(ground, pixel=pixel, sun_pixel=sun_pixel),
        camera=replace(config.camera, resolution=(width, height)),
        render=replace(config.render, sun_cells=cells),
        output=replace(config.output, folder=config.output.folder / "preview"))


def preview_sun_cells(config: Config) -> int:
    """Cells across the sun disc in the preview of ``config``: ``PREVIEW_SUN_CELLS`` at the default
    field of view or a wider one; under a narrower one as many more as the sun's pinhole images
    are larger in the picture (``tan`` of the default half-angle over that of the camera's), up
    to the config's own ``render.sun_cells``.

    A camera framed close on the flecks (``sunshade eclipses --write``: 25 degrees) shows each
    crescent some 25 preview pixels across; at 6 cells the crescent, thinner than a cell,
    blurs to a blob (docs/accuracy.md, "The eclipse finder against DE421").

    Parameters
    ----------
    config : Config
        The full render's config.

    Returns
    -------
    int
        Cells across the sun disc's diameter [1].
    """
    ratio = math.tan(CameraConfig.fov / 2.0) / math.tan(config.camera.fov / 2.0)
    return max(PREVIEW_SUN_CELLS, min(config.render.sun_cells, round(PREVIEW_SUN_CELLS * ratio)))
