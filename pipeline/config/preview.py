"""The preview: a config made small and fast for a first look (``sunshade render --preview``).

Coarser rasters and fewer pixels, every leaf and the sky kept, so that the crescents and flecks
of the full render show (docs/accuracy.md, "Speed: preview and cycle phase").
"""

from __future__ import annotations

from dataclasses import replace

from pipeline.config.settings import Config

__all__ = ["PREVIEW_CYCLE", "PREVIEW_SCALE", "PREVIEW_SUN_CELLS", "preview"]

PREVIEW_SCALE = 4
"""A preview's camera has this many times fewer pixels across, its ground pixels are this many
times larger."""
PREVIEW_SUN_CELLS = 6
"""Cells across the sun disc's diameter on its fine grid in a preview."""
PREVIEW_CYCLE = 8
"""A preview's procedural leaves flutter through at most this many cycle frames (faster than in
the full render): the cycle phase, a mask and its spectra per cycle frame, shrinks with it."""


def preview(config: Config) -> Config:
    """The config made small and fast for a first look.

    A quarter of the camera's resolution, ground pixels four times larger (less where a
    periodic tile must stay a whole number of them), the sun disc 6 cells across (imported
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
    sun_pixel = None
    if ground.sun_pixel is not None:
        sun_pixel = min(ground.sun_pixel * 16 / PREVIEW_SUN_CELLS, pixel)
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
        render=replace(config.render, sun_cells=PREVIEW_SUN_CELLS),
        output=replace(config.output, folder=config.output.folder / "preview"))
