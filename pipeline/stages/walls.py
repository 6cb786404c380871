"""The walls of a config at a frame: their light (``receivers.walls``) and their place in the
camera's picture by depth (``receivers.view``); docs/method.md, "Receivers: walls and slopes"."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pipeline.cache import store as cache
from pipeline.camera.pinhole import Camera
from pipeline.canopy.masks import transmittance_from_image
from pipeline.config.receivers import WALL_ALBEDOS, WallConfig
from pipeline.core import io
from pipeline.core.cores import in_shares
from pipeline.core.errors import ImageError
from pipeline.core.geometry import Grid
from pipeline.receivers import view
from pipeline.receivers.ground_shade import SkyTable, hidden_sky, polygon_coverage, shadow_polygon, sky_table
from pipeline.receivers.hemisphere import ground_radiance, hemisphere_irradiance, world_radiance
from pipeline.receivers.plane import ReceiverPlane
from pipeline.receivers.sun import receiver_sun_irradiance, sun_incidence
from pipeline.receivers.walls import WallLight, kept_by_sky, wall_albedo_colour, wall_light, wall_light_from, wall_plane
from pipeline.sky import scattering
from pipeline.sky.base import Sky
from pipeline.sky.sun_kernel import sun_irradiance
from pipeline.stages.ground import FrameContext, GroundRaster, GroundResult
from pipeline.stages.inputs import albedo_mipmap
from pipeline.stages.plan import RunPlan
from pipeline.stages.wall_cycle import wall_grove, wall_item, wall_run_plan
from pipeline.texture import mipmap

__all__ = ["wall_lights", "wall_of_frame", "show_walls", "shade_ground", "FAR_PIXEL", "FAR_MARGIN",
           "OpenWall", "open_walls", "check_walls", "distance_haze"]


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
    """The irradiance of wall ``index`` at the context's frame, from its cycle products
    (``wall_cycle.wall_item``); drawn for the frame alone where its sun is not in the run's plan."""
    plan, sky = context.plan, context.sky
    albedo = albedo_mipmap(plan.ground).mean
    spectra = wall_item(plan, index, context.cycle_frame, context.store, workers=context.workers)
    light = wall_light_from(wall_run_plan(plan, index), spectra, sky, ground_radiance(albedo, _open_ground(sky)),
                            workers=context.workers)
    if light is not None:
        return light
    return wall_light(plan.receivers.walls[index], sky, ground_albedo=albedo, open_ground=_open_ground(sky),
                      grove=wall_grove(plan), cycle_frame=context.cycle_frame, where=f"receivers.walls[{index}]",
                      workers=context.workers)


def _open_ground(sky: Sky) -> np.ndarray:
    """The open ground's irradiance (3,), sky and sun, kept for the last few skies [radiance x sr]."""
    return np.array(kept_by_sky(_kept_open_ground, sky))


@functools.lru_cache(maxsize=4)
def _kept_open_ground(sky: Sky) -> np.ndarray:
    light = np.asarray(sky.sky_irradiance, dtype=np.float64) + sun_irradiance(sky)  # type: ignore[arg-type]
    light.setflags(write=False)
    return light


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
    scale = np.float32(1.0 / np.pi)
    for wall, light in zip(walls, lights):
        hits = _hits(camera, light.plane)
        if not hits.hit.any():
            continue
        points, taps, albedo = _looks(camera, light.plane, light.grid, wall.albedo, wall.albedo_size)
        view.show_points(radiance, distance, hits, points, light.irradiance, taps, albedo, scale)


def distance_haze(distance: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """The haze's transmittance T over the distances a frame's pixels see (``scattering.haze_transmittance``)
    and 1 - T, kept for the last distances (a still camera sees its walls where it saw them): read-only.

    Parameters
    ----------
    distance : numpy.ndarray
        (rows, cols) float32, what each pixel sees (the ground, a wall; inf: the sky) [m].
    length : float
        The haze's extinction length [m].

    Returns
    -------
    transmittance, veil : numpy.ndarray
        (rows, cols, 1) float32, T and 1 - T [1].
    """
    bits = distance.view(np.uint32) if distance.dtype == np.float32 and distance.flags.c_contiguous else None
    kept = _HAZE.get(length)
    if bits is not None and kept is not None and kept[0].shape == bits.shape and np.array_equal(kept[0], bits):
        return kept[1], kept[2]
    transmittance = scattering.haze_transmittance(distance, length)[..., None]
    veil = 1.0 - transmittance
    for array in (transmittance, veil):
        array.flags.writeable = False
    _HAZE.clear()
    if bits is not None:
        _HAZE[length] = (bits.copy(), transmittance, veil)
    return transmittance, veil


_HAZE: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


@functools.lru_cache(maxsize=8)
def _looks(camera: Camera, plane: ReceiverPlane, grid: Grid, albedo: str | tuple | Path,
           albedo_size: float) -> tuple[view.WallPoints, view.BilinearTaps, np.ndarray]:
    """The pixels' points that meet the wall (``view.wall_points``), where they read its raster, and
    their albedo, (3,) or (n, 3) float32 [1]: once per camera and wall (a run's camera stands still)."""
    points, u, w = view.wall_points(_hits(camera, plane))
    if isinstance(albedo, Path):
        colour = view.read_tiled(_albedo_image(albedo), albedo_size, u, w)
    else:
        colour = np.asarray(WALL_ALBEDOS[albedo] if isinstance(albedo, str) else albedo,
                            dtype=np.float64).astype(np.float32)
    return points, view.bilinear_taps(grid, u, w), colour


def shade_ground(context: FrameContext, ground: GroundResult,
                 lights: tuple[WallLight, ...]) -> tuple[GroundResult, mipmap.MipMap]:
    """The ground with each wall's sun shadow and the sky it hides, and the wall's own light in place
    of that sky (docs/method.md, "A wall on the ground"), in the window and beyond it.

    The sun's part times 1 - the shadow polygon's exact cover of each cell; the sky's part times
    1 - the hidden sky over the open ground's (the product rule, as for the canopy's layers), plus
    the wall's mean radiance over its view factor. Beyond the window, a raster of ``FAR_PIXEL``
    cells reaching ``FAR_MARGIN`` further carries the same for the camera to read where the
    window's rasters end: no seam at the window's edge.

    Parameters
    ----------
    context : ground.FrameContext
        The frame: its plan's walls and its sky.
    ground : ground.GroundResult
        The frame's ground with its ``sky_part`` (``ground_of_frame(parts=True)``).
    lights : tuple of receivers.walls.WallLight
        The walls' light at the frame (``wall_lights``).

    Returns
    -------
    shaded : ground.GroundResult
        The same rasters shaded, with its ``sky_part`` [radiance x sr].
    far : texture.mipmap.MipMap
        Over the window widened by ``FAR_MARGIN``; the open ground's light beyond [radiance x sr].
    """
    sky_part = ground.sky_part
    if sky_part is None:
        raise ValueError("the ground was made without its sky part (ground_of_frame(parts=True))")
    shade = _Shade.of(context, lights, np.asarray(sky_part.unshadowed, dtype=np.float64))
    far = _far_ground(context, ground, shade)
    sky, total = shade.raster(sky_part.irradiance, ground.irradiance, ground.grid)
    outer, sky_outer = None, None
    if ground.outer is not None and sky_part.outer is not None:
        so, to = shade.raster(sky_part.outer.irradiance, ground.outer.irradiance, ground.outer.grid)
        outer, sky_outer = GroundRaster(to, ground.outer.grid), GroundRaster(so, ground.outer.grid)
    shaded = replace(ground, irradiance=total, outer=outer, sky_part=replace(sky_part, irradiance=sky, outer=sky_outer))
    return shaded, far


FAR_PIXEL = 0.25
"""Cell of the raster that carries a wall's shadow and lost sky beyond the ground's window. [m]"""

FAR_MARGIN = 40.0
"""How far beyond the window that raster reaches; beyond it the open ground's light. [m]"""


def _far_ground(context: FrameContext, ground: GroundResult, shade: _Shade) -> mipmap.MipMap:
    """``shade_ground``'s ground beyond the window, from the unshaded ``ground``."""
    x0, y0, x1, y1 = context.plan.window.extent
    grid = Grid.from_window((x0 - FAR_MARGIN, y0 - FAR_MARGIN, x1 + FAR_MARGIN, y1 + FAR_MARGIN), FAR_PIXEL)
    open_sky = np.asarray(ground.sky_part.unshadowed, dtype=np.float64)  # type: ignore[union-attr]
    total = np.broadcast_to(np.asarray(ground.unshadowed, dtype=np.float32), grid.shape + (3,))
    sky = np.broadcast_to(open_sky.astype(np.float32), grid.shape + (3,))
    _, shaded = shade.raster(sky, total, grid)
    return mipmap.mipmap(shaded, grid, outside="constant", value=np.asarray(ground.unshadowed, dtype=np.float32))


@dataclass(frozen=True)
class _Shade:
    """What ``shade_ground`` needs at a frame: the walls, their light out, the sky's table and sun."""

    walls: tuple[tuple[ReceiverPlane, np.ndarray, np.ndarray], ...]
    table: SkyTable
    sun: np.ndarray | None
    open_sky: np.ndarray

    @classmethod
    def of(cls, context: FrameContext, lights: tuple[WallLight, ...], open_sky: np.ndarray) -> _Shade:
        sky = context.sky
        sun = np.asarray(sky.sun_direction, dtype=np.float64) if sky.sun is not None else None  # type: ignore[attr-defined]
        albedo = albedo_mipmap(context.plan.ground).mean
        walls = tuple((light.plane, *_wall_light_out(wall, light, sky, albedo))
                      for wall, light in zip(context.plan.receivers.walls, lights))
        return cls(walls, kept_by_sky(_sky_table, sky),
                   sun if sun is not None and sun[2] > 0.0 else None, np.maximum(open_sky, 1e-30))

    def raster(self, sky_light: np.ndarray, total: np.ndarray, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
        """A ground raster's sky part and total (rows, cols, 3) with every wall on it, float32: in
        float64 the sun's part ``total - sky``, then wall by wall ``sky (1 - hidden / open sky) +
        (front or back) x view factor`` and ``sun (1 - the shadow's cover)``."""
        cells = _cells_on(tuple(plane for plane, _, _ in self.walls), grid, self.table, self.open_sky, self.sun)
        front = np.array([f for _, f, _ in self.walls], dtype=np.float64).reshape(-1, 3)
        back = np.array([b for _, _, b in self.walls], dtype=np.float64).reshape(-1, 3)
        sky, shaded = np.empty(sky_light.shape, np.float32), np.empty(sky_light.shape, np.float32)
        from pipeline.kernels.arrays import walls_on_ground  # numba: imported when a wall is seen

        in_shares(grid.shape[0] * grid.shape[1], lambda start, stop: walls_on_ground(
            sky_light, total, cells.keep, cells.factor, cells.in_front, front, back, cells.sun_keep,
            self.sun is not None, sky, shaded, start, stop))
        return sky, shaded


def _wall_light_out(wall: WallConfig, light: WallLight, sky: Sky,
                    ground_albedo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The irradiance (3,) a wall sends a ground point per unit view factor, from its front (its
    raster's mean) and from its back (the open back's sun and sky): albedo x its mean irradiance."""
    albedo = _albedo_mean(wall.albedo) if isinstance(wall.albedo, Path) else wall_albedo_colour(wall)
    back = np.array(kept_by_sky(_back_light, sky, light.plane, tuple(np.broadcast_to(ground_albedo, (3,)).tolist())))
    cells = light.irradiance.reshape(-1, 3)
    if cells.dtype == np.float32 and cells.flags.c_contiguous:  # numpy's mean over the rows, compiled
        from pipeline.kernels.arrays import rows_sum  # numba: imported when a wall is seen

        front = (rows_sum(cells) / np.float32(len(cells))).astype(np.float64)
    else:
        front = cells.mean(axis=0).astype(np.float64)
    return albedo * front, albedo * back


@functools.lru_cache(maxsize=8)
def _albedo_mean(path: Path) -> np.ndarray:
    """A wall's albedo image's mean (3,) float64 [1]."""
    mean = _albedo_image(path).reshape(-1, 3).mean(axis=0).astype(np.float64)
    mean.setflags(write=False)
    return mean


@functools.lru_cache(maxsize=4)
def _sky_table(sky: Sky) -> SkyTable:
    """``ground_shade.sky_table`` of the sky alone (no light below the horizon)."""
    return sky_table(world_radiance(sky, np.zeros(3)))


@functools.lru_cache(maxsize=8)
def _back_light(sky: Sky, plane: ReceiverPlane, ground_albedo: tuple[float, ...]) -> np.ndarray:
    """The open back of a wall's light (3,), the sun's if it lights it and its hemisphere's with the
    open ground below [radiance x sr]."""
    p = plane
    behind = ReceiverPlane(p.origin, p.facing + np.pi, np.pi - p.zenith, p.width, p.height)
    ground = ground_radiance(np.array(ground_albedo), _open_ground(sky))
    back = receiver_sun_irradiance(sky, behind) + hemisphere_irradiance(world_radiance(sky, ground), behind)
    back.setflags(write=False)
    return back


@dataclass(frozen=True)
class _Cells:
    """What the walls do to a ground grid's cells at a sky and sun, stacked wall by wall (``_Shade.raster``)."""

    keep: np.ndarray  # (walls, rows, cols, 3) float64: 1 - the hidden sky over the open sky's [1]
    factor: np.ndarray  # (walls, rows, cols) float64: the view factor [1]
    in_front: np.ndarray  # (walls, rows, cols) bool: the cell's centre in front of the wall
    sun_keep: np.ndarray  # (walls, rows, cols) float64: 1 - the sun shadow's cover; (walls, 1, 1) without a sun [1]


_CELLS_KEPT = 6  # (walls, grid, sky) of _cells_on kept: a frame's three grids (window, beyond it, far), two skies
_CELLS: dict[tuple, tuple[SkyTable, _Cells]] = {}


def _cells_on(planes: tuple[ReceiverPlane, ...], grid: Grid, table: SkyTable, open_sky: np.ndarray,
              sun: np.ndarray | None) -> _Cells:
    """``_Cells`` of the walls on ``grid`` under the sky of ``table`` (the same object, or equal
    values) with ``open_sky`` (3,) and ``sun`` (3,) or None: kept for the last few, a still sun's
    frames sharing them."""
    key = (planes, grid, tuple(open_sky.tolist()), None if sun is None else tuple(sun.tolist()))
    found = _CELLS.get(key)
    if found is not None and (found[0] is table or np.array_equal(found[0].cumulative, table.cumulative)):
        return found[1]
    rows, cols = grid.shape
    x = grid.origin[0] + grid.pixel * (np.arange(cols) + 0.5)
    y = grid.origin[1] - grid.pixel * (np.arange(rows) + 0.5)
    points = np.stack(np.broadcast_arrays(x[None, :], y[:, None]), axis=-1).reshape(-1, 2)
    keep, factor, in_front, sun_keep = [], [], [], []
    for plane in planes:
        hidden, f = hidden_sky(plane, points, table)
        keep.append(1.0 - hidden.reshape(rows, cols, 3) / open_sky)
        factor.append(f.reshape(rows, cols))
        in_front.append(((points - np.asarray(plane.origin[:2])) @ plane.normal[:2] >= 0.0).reshape(rows, cols))
        sun_keep.append(np.ones((1, 1)) if sun is None else 1.0 - polygon_coverage(shadow_polygon(plane, sun), grid))
    cells = _Cells(np.stack(keep), np.stack(factor), np.stack(in_front), np.stack(sun_keep))
    _CELLS.pop(key, None)
    while len(_CELLS) >= _CELLS_KEPT:
        _CELLS.pop(next(iter(_CELLS)))
    _CELLS[key] = (table, cells)
    return cells
