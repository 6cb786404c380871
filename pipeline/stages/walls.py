"""The walls of a config at a frame: their light (``receivers.walls``) and their place in the
camera's picture by depth (``receivers.view``); docs/method.md, "Receivers: walls and slopes"."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.cache import store as cache
from pipeline.camera.pinhole import Camera
from pipeline.canopy.masks import transmittance_from_image
from pipeline.config.receivers import WallConfig
from pipeline.core import io
from pipeline.core.errors import ImageError
from pipeline.receivers import view
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, world_radiance
from pipeline.receivers.plane import ReceiverPlane
from pipeline.receivers.sun import receiver_sun_irradiance, sun_incidence
from pipeline.receivers.walls import WallLight, wall_albedo_colour, wall_light, wall_plane
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.ground import FrameContext
from pipeline.stages.inputs import albedo_mipmap, grove_of
from pipeline.stages.plan import RunPlan

__all__ = ["wall_lights", "wall_of_frame", "show_walls", "OpenWall", "open_walls", "check_walls"]


def wall_lights(context: FrameContext) -> tuple[WallLight, ...]:
    """Every wall's irradiance at the context's frame, under its masks and the isolated grove.

    Parameters
    ----------
    context : ground.FrameContext
        The frame: its plan (with ``receivers``), sky, cycle frame and threads.

    Returns
    -------
    tuple of receivers.walls.WallLight
        One per ``receivers.walls``, in order [radiance x sr].
    """
    return tuple(_wall_light(context, i) for i in range(len(context.plan.receivers.walls)))


def _wall_light(context: FrameContext, index: int) -> WallLight:
    """The irradiance of wall ``index`` at the context's frame."""
    plan, sky = context.plan, context.sky
    c = plan.canopy
    grove = grove_of(c) if c.trees is not None and c.layout == "isolated" else None
    open_ground = np.asarray(sky.sky_irradiance, dtype=np.float64) + sun_irradiance(sky)  # type: ignore[arg-type]
    return wall_light(plan.receivers.walls[index], sky, ground_albedo=albedo_mipmap(plan.ground).mean,
                      open_ground=open_ground, grove=grove, cycle_frame=context.cycle_frame,
                      where=f"receivers.walls[{index}]", workers=context.workers)


def wall_of_frame(plan: RunPlan, frame: int, name: str, *, store: cache.Cache | None = None,
                  workers: int | None = None) -> WallLight:
    """One wall's irradiance at an output frame (``sunshade ground --receiver NAME``).

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    frame : int
        Output frame index.
    name : str
        The wall's name (``receivers.walls[].name``).
    store : store.Cache or None
        The frame's cache (``ground.FrameContext``); None: the default cache.
    workers : int or None
        FFT threads; None: ``cores.default_workers``.

    Returns
    -------
    receivers.walls.WallLight
        Over the whole wall at its ``pixel`` [radiance x sr].

    Raises
    ------
    KeyError
        For a name no wall has.
    """
    names = [wall.name for wall in plan.receivers.walls]
    if name not in names:
        raise KeyError(name)
    return _wall_light(FrameContext.of(plan, frame, store=store, workers=workers), names.index(name))


@dataclass(frozen=True)
class OpenWall:
    """A wall's open light at a frame, before any shade (``sunshade check``).

    Attributes
    ----------
    name : str
        The wall.
    frame : int
        Output frame index.
    incidence : float
        cos of the sun's angle from its normal, s.n (negative: behind it; 0 without a sun) [1].
    sun, sky : numpy.ndarray
        (3,) the open wall's light from the sun (zeros where it does not light it) and from its
        hemisphere (the sky, and the open ground below the horizon) [radiance x sr].
    """

    name: str
    frame: int
    incidence: float
    sun: np.ndarray
    sky: np.ndarray


def open_walls(plan: RunPlan, frames: Iterable[int]) -> list[OpenWall]:
    """Every wall's open light at each of ``frames``.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    frames : iterable of int
        Output frame indices.

    Returns
    -------
    list of OpenWall
        Wall by wall, frame by frame.
    """
    found = []
    albedo = albedo_mipmap(plan.ground).mean
    for frame in frames:
        sky = plan.sky.at(plan.scenes[frame])
        ground = ground_radiance(albedo, np.asarray(sky.sky_irradiance, dtype=np.float64)
                                 + sun_irradiance(sky))  # type: ignore[arg-type]
        for i, wall in enumerate(plan.receivers.walls):
            plane = wall_plane(wall, f"receivers.walls[{i}]")
            found.append(OpenWall(wall.name, frame, sun_incidence(sky, plane), receiver_sun_irradiance(sky, plane),
                                  hemisphere_irradiance(world_radiance(sky, ground), plane)))
    return found


def check_walls(plan: RunPlan) -> None:
    """Read and check every wall's albedo image and masks, as a run would.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.

    Raises
    ------
    ImageError
        Naming the file.
    ConfigError
        Naming the key of a mask whose values are not transmittances.
    """
    for wall in plan.receivers.walls:
        if isinstance(wall.albedo, Path) and (_albedo_image(wall.albedo).min() < 0):
            raise ImageError(wall.albedo, "albedo must not be negative")
        for m in wall.masks:
            try:
                transmittance_from_image(io.read_finite_image(m.image, "mask"))
            except ValueError as exc:
                raise ImageError(m.image, str(exc)) from None


@functools.lru_cache(maxsize=8)
def _hits(camera: Camera, plane: ReceiverPlane) -> view.WallHits:
    """``view.wall_hits``, once per camera and wall (a run's camera stands still)."""
    return view.wall_hits(camera, plane)


@functools.lru_cache(maxsize=8)
def _albedo_image(path: Path) -> np.ndarray:
    """A wall's albedo image, (rows, cols, 3) [1]."""
    image = io.read_finite_image(path, "albedo")
    return np.repeat(image[..., :1], 3, axis=2) if image.shape[2] < 3 else image[..., :3]


def show_walls(camera: Camera, walls: tuple[WallConfig, ...], lights: tuple[WallLight, ...], radiance: np.ndarray,
               distance: np.ndarray) -> None:
    """The walls put into a picture in place, each where it is nearer than what the pixel saw:
    radiance albedo x irradiance / pi.

    Parameters
    ----------
    camera : camera.pinhole.Camera
        The frame's camera.
    walls : tuple of config.receivers.WallConfig
        The walls.
    lights : tuple of receivers.walls.WallLight
        Their light at the frame (``wall_lights``).
    radiance : numpy.ndarray
        (height, width, 3) float32, the ground and sky; changed [radiance].
    distance : numpy.ndarray
        (height, width) float32, the ground's distance (inf: none); changed to the walls' where
        they are seen [m].
    """
    for wall, light in zip(walls, lights):
        hits = _hits(camera, light.plane)
        if not hits.hit.any():
            continue
        view.show_wall(radiance, distance, hits, functools.partial(_radiance, wall, light))


def _radiance(wall: WallConfig, light: WallLight, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The wall's radiance (n, 3) at its points (u, w) (n,): albedo x irradiance / pi [radiance]."""
    irradiance = view.read_bilinear(light.grid, light.irradiance, u, w)
    if isinstance(wall.albedo, Path):
        albedo = view.read_tiled(_albedo_image(wall.albedo), wall.albedo_size, u, w)
    else:
        albedo = wall_albedo_colour(wall).astype(np.float32)
    return irradiance * albedo * np.float32(1.0 / np.pi)
