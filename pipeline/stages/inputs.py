"""The config's inputs as the stages use them: mask images, the grove of built-in trees, the
ground's albedo and imported foreground passes, each read and checked once per process
(docs/design.md, "Stages")."""

from __future__ import annotations

import functools
import hashlib
import os

import numpy as np

from pipeline.canopy import grove, masks
from pipeline.config.receivers import SlopeConfig
from pipeline.config.settings import CanopyConfig, CanopyLayer, GroundConfig
from pipeline.core import io
from pipeline.core.geometry import Grid
from pipeline.receivers.slope import grove_on_slope, slope_plane
from pipeline.texture import albedo, mipmap

__all__ = ["load_mask", "grove_of", "flutter_of", "isolated_grove", "file_sha256", "albedo_mipmap", "ground_albedo"]


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
def grove_of(canopy_config: CanopyConfig, slope: SlopeConfig | None = None) -> tuple[grove.Grove, grove.FlutterParams]:
    """The grove of a canopy config and its flutter, grown once per process.

    Parameters
    ----------
    canopy_config : settings.CanopyConfig
        A canopy with built-in ``trees``.
    slope : config.receivers.SlopeConfig or None, optional
        A sloped ground the trees stand on (``receivers.slope.grove_on_slope``); None: level.

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
    grown = grove.grow_grove(params)
    if slope is not None:
        grown = grove_on_slope(grown, slope_plane(slope))
    return grown, flutter_of(canopy_config)


def flutter_of(canopy_config: CanopyConfig) -> grove.FlutterParams:
    """The canopy's flutter, for built-in trees and mesh trees alike.

    Parameters
    ----------
    canopy_config : settings.CanopyConfig
        Its ``flutter``.

    Returns
    -------
    grove.FlutterParams
        The cycle [frames], swing and twist [rad].
    """
    f = canopy_config.flutter
    return grove.FlutterParams(cycle=f.cycle, swing=f.swing, twist=f.twist)


def isolated_grove(canopy_config: CanopyConfig) -> tuple[grove.Grove, grove.FlutterParams] | None:
    """The grove of an isolated canopy of built-in trees (``grove_of``), else None.

    Parameters
    ----------
    canopy_config : settings.CanopyConfig
        Its ``trees`` and ``layout`` decide.

    Returns
    -------
    (grove.Grove, grove.FlutterParams) or None
        The grove at rest and its flutter; None for mask images or a periodic forest.
    """
    c = canopy_config
    return grove_of(c) if c.trees is not None and c.layout == "isolated" else None


def file_sha256(path: os.PathLike[str] | str) -> str:
    """SHA-256 of a file's bytes, kept per (path, size, modification time): a changed file is hashed again.

    Parameters
    ----------
    path : path-like
        The file.

    Returns
    -------
    str
        The hex digest.
    """
    stat = os.stat(path)
    return _stamped_sha256(str(path), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _stamped_sha256(path: str, size: int, modified: int) -> str:
    """SHA-256 of a file's bytes; the size [B] and modification time [ns] make the cache's key."""
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


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


