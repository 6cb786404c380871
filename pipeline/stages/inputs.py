"""The config's inputs as the stages use them: mask images, the grove of built-in trees, the
ground's albedo and imported foreground passes, each read and checked once per process
(docs/design.md, "Stages")."""

from __future__ import annotations

import functools

import numpy as np

from pipeline.canopy import grove, masks
from pipeline.config.settings import CanopyConfig, CanopyLayer, GroundConfig
from pipeline.core import io
from pipeline.core.geometry import Grid
from pipeline.texture import albedo, mipmap

__all__ = ["load_mask", "grove_of", "albedo_mipmap", "ground_albedo"]


def load_mask(layer: CanopyLayer, frame: int = 0) -> np.ndarray:
    """The transmittance of a layer's mask image at ``frame`` of its sequence.

    Parameters
    ----------
    layer : settings.CanopyLayer
        The canopy plane; its ``mask`` is a sequence of image files.
    frame : int
        The cycle frame; the sequence repeats.

    Returns
    -------
    ndarray, shape (rows, cols)
        Transmittance [1] (``masks.transmittance_from_image``).

    Raises
    ------
    io.ImageError
        Naming the file.
    """
    path = layer.mask[frame % len(layer.mask)]
    image = io.read_finite_image(path, "mask")
    try:
        return masks.transmittance_from_image(image)
    except ValueError as exc:
        raise io.ImageError(path, str(exc)) from None


@functools.lru_cache(maxsize=4)
def grove_of(canopy_config: CanopyConfig) -> tuple[grove.Grove, grove.FlutterParams]:
    """The grove of a canopy config and its flutter, grown once per process.

    Parameters
    ----------
    canopy_config : settings.CanopyConfig
        A canopy with built-in ``trees``.

    Returns
    -------
    grove : grove.Grove
        The grove at rest.
    flutter : grove.FlutterParams
        Its flutter: the cycle [frames], swing and twist.

    Raises
    ------
    ValueError
        For a canopy of mask images (no ``trees``).
    """
    trees, layer0 = canopy_config.trees, canopy_config.layers[0]
    if trees is None:
        raise ValueError("the canopy has no built-in trees to grow: its planes are mask images")
    params = grove.GroveParams(
        count=trees.count, seed=trees.seed, crown_radius=trees.crown_radius,
        leaves_per_tree=trees.leaves_per_tree, leaf_length=trees.leaf_length,
        height=max(layer.height for layer in canopy_config.layers),
        layout=canopy_config.layout,
        tile=layer0.size[0] if canopy_config.layout == "periodic" else None,
        center=layer0.center, spread=trees.spread)
    f = canopy_config.flutter
    return grove.grow_grove(params), grove.FlutterParams(cycle=f.cycle, swing=f.swing, twist=f.twist)


@functools.lru_cache(maxsize=4)
def albedo_mipmap(ground: GroundConfig) -> mipmap.MipMap:
    """The ground's albedo as a periodic MipMap: the procedural grass, or a tileable image.

    Parameters
    ----------
    ground : settings.GroundConfig
        The ground; its image or ``grass`` covers ``albedo_size`` [m] a side.

    Returns
    -------
    mipmap.MipMap
        The albedo (rows, cols, 3) [1], periodic over ``albedo_size`` [m].
    """
    if ground.albedo == "grass":
        image, grid = albedo.grass_albedo(period=ground.albedo_size)
    else:
        image = io.read_finite_image(ground.albedo, "albedo")
        image = np.repeat(image[..., :1], 3, axis=2) if image.shape[2] < 3 else image[..., :3]
        rows, cols = image.shape[:2]
        grid = Grid((0.0, ground.albedo_size), ground.albedo_size / cols, (rows, cols))
    return mipmap.mipmap(image, grid, outside="periodic",
                          period=(grid.pixel * grid.shape[1], grid.pixel * grid.shape[0]))


@functools.lru_cache(maxsize=4)
def ground_albedo(ground: GroundConfig) -> albedo.StochasticTiling:
    """The ground's albedo as the camera reads it.

    The tile of ``albedo_mipmap`` laid by stochastic tiling (Heitz & Neyret 2018,
    ``albedo.StochasticTiling``), so that its period does not show in rows to the horizon.

    Parameters
    ----------
    ground : settings.GroundConfig
        The ground.

    Returns
    -------
    albedo.StochasticTiling
        The tiled albedo [1].
    """
    return albedo.stochastic_tiling(albedo_mipmap(ground))


