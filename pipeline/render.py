"""The orchestrator: reads a config's inputs and runs the stages in order.

For now one product: the ground irradiance raster (Max 1991, Fig. 7) of ``sunshade ground``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from . import canopy, io, shadow
from .config import MAX_RADIANCE, CanopyLayer, Config, SkyConfig
from .geometry import Grid
from .sky import EquirectSky, UniformSky


@dataclass(frozen=True)
class GroundResult:
    """irradiance : (rows, cols, 3) float32 [radiance x sr]; grid : its ground Grid [m];
    unshadowed : (3,) irradiance of the open sky; exact : whether every ray that meets the
    canopy lies inside the sky square (else light from beyond it was taken as unshadowed)."""

    irradiance: np.ndarray
    grid: Grid
    unshadowed: np.ndarray
    exact: bool


def default_workers() -> int:
    """FFT threads: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def load_sky(sky: SkyConfig):
    """The sky model of a config, its image read and checked (negative radiance is taken as 0).
    Raises io.ImageError."""
    if sky.model == "uniform":
        return UniformSky(np.asarray(sky.radiance, dtype=np.float64))
    image = io.read_image(sky.hdri)
    if image.shape[2] < 3:
        image = np.repeat(image[..., :1], 3, axis=2)
    image = image[..., :3]
    if not np.all(np.isfinite(image)):
        raise io.ImageError(sky.hdri, "the sky image holds NaN or infinite values")
    if image.max() > MAX_RADIANCE:
        raise io.ImageError(sky.hdri, f"radiance {image.max():.3g} is above the most, {MAX_RADIANCE:g}")
    return EquirectSky(np.maximum(image, 0.0), sky.rotation)


def load_mask(layer: CanopyLayer) -> np.ndarray:
    """Transmittance (rows, cols) of a layer's mask image. Raises io.ImageError."""
    image = io.read_image(layer.mask)
    try:
        return canopy.transmittance_from_image(image)
    except ValueError as exc:
        raise io.ImageError(layer.mask, str(exc)) from None


def render_ground(config: Config, *, workers: int | None = None) -> GroundResult:
    """Ground irradiance of every canopy layer under the sky, layers combined by the paper's
    product rule."""
    workers = workers or default_workers()
    window = Grid.from_window(config.ground.window, config.ground.pixel)
    sky = load_sky(config.sky)
    masks = [load_mask(layer) for layer in config.canopy.layers]
    grounds, totals, exact = [], [], True
    for layer, mask in zip(config.canopy.layers, masks):
        g, total, layer_exact = _ground_of_layer(
            layer, mask, sky, window, config.canopy.layout, config.sky.alpha, workers
        )
        grounds.append(g)
        totals.append(total)
        exact &= layer_exact
    combined = shadow.combine_layers(grounds, totals[0])
    return GroundResult(np.moveaxis(combined, 0, -1), window, totals[0], exact)


def _ground_of_layer(layer, mask, sky, window, layout, alpha, workers):
    if layout == "isolated":
        occlusion, grid = canopy.occlusion_on_lattice(
            mask, center=layer.center, size=layer.size, lattice=window
        )
        plan = shadow.plan_isolated(window, grid, height=layer.height, alpha=alpha)
        sky_grid = plan.sky or shadow.sky_grid((0, 0), (1, 1), window.pixel / layer.height)
        raster = sky.raster(sky_grid)  # a 1 x 1 stand-in when no ray reaches the canopy
        spectrum = shadow.occlusion_spectrum(occlusion, plan, workers=workers)
        g = shadow.ground_isolated(raster, spectrum, plan, workers=workers)
        return g, raster.total, plan.exact
    tile, grid = canopy.tile_on_lattice(mask, center=layer.center, size=layer.size, lattice=window)
    plan = shadow.plan_periodic(window, grid, height=layer.height, alpha=alpha)
    raster = sky.raster(plan.sky, fold_period=plan.tile_shape)
    spectrum = shadow.transmittance_spectrum(tile, workers=workers)
    g = shadow.ground_periodic(raster, spectrum, plan, float(tile.mean()), workers=workers)
    return g, raster.total, True
