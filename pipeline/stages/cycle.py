"""The cycle stage: the products of each cycle frame (every canopy layer's mask spectra, the
built-in trees' foreground passes), their cache keys, and the cycle phase that computes the
missing ones in parallel (Max 1991, section 4; docs/method.md, "Cycle products and the
cache"). Every function takes the RunPlan."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import joblib
import numpy as np

from pipeline.cache import keys as cache_keys
from pipeline.cache import store as cache
from pipeline.canopy import grove as grove_geometry
from pipeline.canopy import masks as canopy
from pipeline.canopy import mesh_layers, rasteriser
from pipeline.canopy.mesh import MeshParams
from pipeline.canopy.mesh_coverage import OUTLINE_TEXELS_PER_PIXEL, TEXELS_PER_PIXEL
from pipeline.config.parse import FRAME_BYTES_PER_PIXEL
from pipeline.config.settings import CanopyConfig
from pipeline.core.cores import compiled_once, end_if_orphaned
from pipeline.core.errors import portable
from pipeline.core.mesh_files import mesh_files
from pipeline.foreground import models, tree_detail
from pipeline.foreground import trees as foreground
from pipeline.ground import shadow
from pipeline.stages.inputs import file_sha256, flutter_of, grove_of, load_mask
from pipeline.stages.plan import RunPlan
from pipeline.stages.wall_cycle import WALL_KIND, wall_index, wall_item, wall_params, wall_task

__all__ = ["LayerSpectra", "LayerMasks", "layer_masks", "cycle_params", "cycle_item", "cycle_phase", "DiskNeed",
           "disk_needed", "CONFIG_INDEX", "config_item_keys", "record_config_items", "recorded_configs",
           "foreground_params", "foreground_item", "ForegroundView", "foreground_views", "mesh_trees",
           "check_mesh_trees"]


@dataclass(frozen=True)
class LayerSpectra:
    """A canopy layer's cycle products at one cycle frame, as ``cycle_item`` reads them from the
    cache (whose item keeps the arrays ``coarse``, ``mean`` and ``fine``, memory-mapped, read-only).

    Attributes
    ----------
    coarse : ndarray, complex64
        The occlusion spectrum of an isolated layer (``shadow.occlusion_spectrum``), or the
        transmittance spectrum of a periodic layer's tile (``shadow.transmittance_spectrum``) [1].
    mean : float
        The mean transmittance of the layer's coarse mask (of a tile) [1].
    fine : ndarray, complex64, or None
        The fine mask's spectrum (``shadow.fine_mask_spectrum``), None without a sun kernel [1].
    """

    coarse: np.ndarray
    mean: float
    fine: np.ndarray | None = None

    @classmethod
    def from_item(cls, item: Mapping[str, np.ndarray]) -> LayerSpectra:
        """The spectra of a cache item.

        Parameters
        ----------
        item : mapping of str to ndarray
            The item's arrays: ``coarse``, ``mean`` (1,) [1] and, with a sun kernel, ``fine``.

        Returns
        -------
        LayerSpectra
            The same arrays, named; ``mean`` as a float [1].
        """
        return cls(item["coarse"], float(item["mean"][0]), item.get("fine"))


@dataclass(frozen=True)
class LayerMasks:
    """A canopy plane's transmittance masks at one cycle frame (``layer_masks``).

    Attributes
    ----------
    coarse : ndarray, shape (rows, cols), float32
        Transmittance [1] on the plane's coarse grid (``LayerPlan.canopy``).
    fine : ndarray, shape (rows, cols), float32, or None
        Transmittance [1] on its fine sun mask grid (``LayerPlan.sun.mask``), None without a sun
        kernel.
    """

    coarse: np.ndarray
    fine: np.ndarray | None = None


@dataclass(frozen=True)
class DiskNeed:
    """The disk a whole run writes (``disk_needed``).

    Attributes
    ----------
    frame_bytes : float
        The frames' bytes [B].
    cache_bytes : float
        The cycle products' bytes, at most [B].
    """

    frame_bytes: float
    cache_bytes: float


@dataclass(frozen=True)
class ForegroundView:
    """One of the built-in trees' cached foreground items that a run needs (``foreground_views``).

    Attributes
    ----------
    plan : plan.RunPlan
        The plan of an output frame that uses the item: the run's plan, or with a camera that
        follows the shadow, the frame's own (``RunPlan.at``).
    cycle_frame : int
        The flutter cycle's frame of the item [frame].
    """

    plan: RunPlan
    cycle_frame: int


def layer_masks(plan: RunPlan, layer_index: int, cycle_frame: int) -> LayerMasks:
    """Transmittance masks of one canopy plane at one cycle frame.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    layer_index : int
        The canopy plane, an index of ``plan.layers``.
    cycle_frame : int
        The flutter cycle's frame.

    Returns
    -------
    LayerMasks
        The coarse mask's transmittance [1] on the plane's coarse grid (``LayerPlan.canopy``), and
        the fine one's on its sun mask grid, None without a sun kernel.
    """
    c = plan.canopy
    layer, lp = c.layers[layer_index], plan.layers[layer_index]
    periodic = c.layout == "periodic"
    grids = [lp.canopy] + ([lp.sun.mask] if lp.sun else [])
    if c.meshes:
        heights = tuple(l.height for l in c.layers)
        masks = [mesh_layers.layer_transmittance(mesh_trees(c), flutter_of(c), cycle_frame, heights=heights,
                                                 layer=layer_index, sun=np.array(plan.projection), grid=g)
                 for g in grids]
    elif c.trees is None:
        image = load_mask(layer, cycle_frame)
        masks = [canopy.transmittance_on_grid(image, center=layer.center, size=layer.size,
                                              grid=g, periodic=periodic) for g in grids]
    else:
        grove, flutter = grove_of(c)
        heights = tuple(l.height for l in c.layers)
        leaf_layer, wood_layer = grove_geometry.layer_index(grove, heights)
        shapes = grove_geometry.project(
            grove_geometry.leaves_at(grove, flutter, cycle_frame), grove.wood,
            sun=np.array(plan.projection), plane_height=layer.height,
        ).subset(leaves=leaf_layer == layer_index, wood=wood_layer == layer_index)
        period = layer.size if periodic else None
        masks = [rasteriser.rasterize_transmittance(shapes, g, period=period) for g in grids]
    return LayerMasks(masks[0], masks[1] if lp.sun else None)


def cycle_params(plan: RunPlan, layer_index: int, cycle_frame: int) -> dict[str, Any]:
    """Everything a layer's cycle products at ``cycle_frame`` depend on: their cache key's params.

    See docs/runs.md, "Resume"; docs/method.md, "Cycle products and the cache".

    Parameters
    ----------
    plan, layer_index, cycle_frame
        As in ``layer_masks``.

    Returns
    -------
    dict
        JSON-able params (``keys.key_of``): the mask file's digest or the trees, the grids, the
        projection.
    """
    c = plan.canopy
    lp = plan.layers[layer_index]
    source: dict[str, Any]
    if c.meshes:
        source = {"meshes": [{**asdict(m), "files": [file_sha256(f) for f in mesh_files(m.file)]}
                             for m in c.meshes], "flutter": asdict(c.flutter), "heights": [l.height for l in c.layers],
                  "coverage": [TEXELS_PER_PIXEL, OUTLINE_TEXELS_PER_PIXEL]}
    elif c.trees is None:
        source = {"mask": file_sha256(c.layers[layer_index].mask[cycle_frame])}
    else:
        source = {"trees": asdict(c.trees), "flutter": asdict(c.flutter),
                  "heights": [l.height for l in c.layers]}
    layer = c.layers[layer_index]
    return {
        "source": source, "layout": c.layout, "layer": layer_index, "height": layer.height,
        "center": layer.center, "size": layer.size, "frame": cycle_frame,
        "projection": plan.projection, "canopy": asdict(lp.canopy),
        "fft": getattr(lp.coarse, "fft_shape", None),
        "sun": None if lp.sun is None else {"mask": asdict(lp.sun.mask), "fft": lp.sun.fft_shape},
    }


def mesh_trees(canopy_config: CanopyConfig) -> list[mesh_layers.MeshTree]:
    """The canopy's mesh trees (``canopy.mesh``), each read once per process.

    Parameters
    ----------
    canopy_config : settings.CanopyConfig
        The canopy.

    Returns
    -------
    list of mesh_layers.MeshTree
        One per mesh, in the config's order; empty without any.
    """
    return [mesh_layers.mesh_tree(MeshParams(m.file, m.scale, (*m.position, 0.0), m.rotation, m.up, m.leaves, m.wood,
                                             m.max_triangles), seed=m.seed, index=i)
            for i, m in enumerate(canopy_config.meshes)]


def check_mesh_trees(plan: RunPlan) -> None:
    """Refuse mesh trees whose shadow can fall beyond a plane's mask area, or that pass MAX_MESH_BYTES.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.

    Raises
    ------
    ImageError
        One line naming the mesh file (those of ``mesh.read_mesh`` too).
    """
    from pipeline.core.errors import ImageError

    meshes, trees = plan.canopy.meshes, mesh_trees(plan.canopy)
    cells = max((int(np.prod(g.shape)) for lp in plan.layers for g in (lp.canopy, *([lp.sun.mask] if lp.sun else ()))),
                default=0)
    need = sum(mesh_layers.mesh_bytes(tree, cells) for tree in trees)
    if trees and need > mesh_layers.MAX_MESH_BYTES:
        raise ImageError(meshes[0].file, f"the mesh trees' layers would take about {need / 1e9:.3g} GB a worker; "
                                         f"the most is {mesh_layers.MAX_MESH_BYTES / 1e9:.3g} GB: fewer triangles, "
                                         "a smaller canopy.size or a larger ground.pixel")
    for mesh, tree in zip(meshes, trees):
        for lp in plan.layers:
            x0, y0, x1, y1 = mesh_layers.shadow_bounds(tree, sun=plan.projection, plane_height=lp.height)
            g0, g1, g2, g3 = lp.canopy.extent
            if x0 < g0 or y0 < g1 or x1 > g2 or y1 > g3:
                raise ImageError(mesh.file, f"its shadow on the plane at {lp.height:g} m reaches x {x0:.2f} to "
                                 f"{x1:.2f}, y {y0:.2f} to {y1:.2f} m, beyond the canopy's mask (x {g0:.2f} to "
                                 f"{g2:.2f}, y {g1:.2f} to {g3:.2f} m): raise canopy.size or move canopy.center")


def cycle_item(plan: RunPlan, layer_index: int, cycle_frame: int, store: cache.Cache,
               *, workers: int = 1) -> LayerSpectra:
    """A layer's cached cycle products at ``cycle_frame``, computed on a miss.

    Parameters
    ----------
    plan, layer_index, cycle_frame
        The layer and the frame, as in ``layer_masks``.
    store : store.Cache
        The cache.
    workers : int
        FFT threads for a miss.

    Returns
    -------
    LayerSpectra
        The coarse spectrum (the occlusion or tile spectrum, complex64), the mean transmittance
        [1] and the fine mask spectrum (complex64, when there is a sun kernel). Memory-mapped,
        read-only; the cache's item keeps them as ``coarse``, ``mean`` (1,) and ``fine``.
    """
    lp = plan.layers[layer_index]

    def compute() -> dict[str, np.ndarray]:
        masks = layer_masks(plan, layer_index, cycle_frame)
        coarse, fine = masks.coarse, masks.fine
        if isinstance(lp.coarse, shadow.IsolatedPlan):
            spectrum = shadow.occlusion_spectrum(1.0 - coarse, lp.coarse, workers=workers)
        else:
            spectrum = shadow.transmittance_spectrum(coarse, workers=workers)
        item = {"coarse": spectrum.astype(np.complex64),
                "mean": np.array([coarse.mean(dtype=np.float64)])}
        if fine is not None and lp.sun is not None:  # a fine mask is made for a sun plan alone (layer_masks)
            item["fine"] = shadow.fine_mask_spectrum(fine, lp.sun, workers=workers).astype(np.complex64)
        return item

    return LayerSpectra.from_item(store.get_or_compute("spectra", cycle_params(plan, layer_index, cycle_frame),
                                                       compute))


def cycle_phase(plan: RunPlan, store: cache.Cache, *, jobs: int = 1, workers: int = 1,
                progress: Callable[[int, int], object] | None = None, cycle_frames: Iterable[int] | None = None,
                command: int | None = None) -> int:
    """Every cycle product for every cycle frame, computing the missing ones in parallel.

    Each layer's spectra and the foreground passes of built-in trees: those already stored are
    checked here, the missing ones computed in parallel over cycle frames by joblib processes
    (the backend is joblib's current one, Dask included).

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    store : store.Cache
        The cache.
    jobs : int
        Parallel joblib processes (at most one per missing item).
    workers : int
        FFT threads of each process.
    progress : callable or None
        ``progress(done, total)``, called as items finish [items].
    cycle_frames : iterable of int or None
        The cycle frames to make; None for all.
    command : int or None
        The PID whose worker processes end when it is gone (``cores.end_if_orphaned``).

    Returns
    -------
    int
        The number of items computed.
    """
    if plan.canopy.meshes:  # checked by plan.check_inputs too; the API may come here first
        check_mesh_trees(plan)
    frames = range(plan.canopy.cycle) if cycle_frames is None else sorted(set(cycle_frames))
    tasks: list[tuple[RunPlan, int | None, int]] = [
        (plan, layer, frame) for frame in frames  # a slope's frames read no level layer (stages.slope)
        for layer in range(len(plan.layers) if plan.receivers.slope is None else 0)]
    tasks += [(view.plan, None, view.cycle_frame) for view in foreground_views(plan, frames)]
    tasks += [(plan, wall_task(wall), frame) for frame in frames  # type: ignore[misc]  # each wall's layers
              for wall in range(len(plan.receivers.walls))]
    missing = [task for task in tasks if store.get(*_product_key(*task)) is None]
    done = len(tasks) - len(missing)
    if progress:
        progress(done, len(tasks))
    if not missing:
        return 0
    computed = 0
    results = joblib.Parallel(n_jobs=min(jobs, len(missing)), return_as="generator")(
        joblib.delayed(_cycle_task)(view, layer, frame, str(store.root), workers, command)
        for view, layer, frame in missing)
    for misses in results:
        computed += misses
        done += 1
        if progress:
            progress(done, len(tasks))
    return computed


def _product_key(plan: RunPlan, layer: int | None, frame: int) -> tuple[str, dict[str, Any]]:
    """(kind, params) of a cycle product: a layer's spectra, the foreground (layer None) or a wall's
    spectra (``wall_cycle.wall_task``)."""
    if wall_index(layer) is not None:
        return WALL_KIND, wall_params(plan, wall_index(layer), frame)  # type: ignore[arg-type]
    if layer is None:
        return "foreground", foreground_params(plan, frame)
    return "spectra", cycle_params(plan, layer, frame)


def foreground_views(plan: RunPlan, cycle_frames: Iterable[int]) -> list[ForegroundView]:
    """The built-in trees' passes a run needs: per item, the plan of a frame that uses it and its cycle frame.

    One per cycle frame; with a camera that follows the shadow, one per camera and cycle frame
    (``RunPlan.at``: the passes are drawn for the frame's own camera, docs/method.md, "Framing").

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    cycle_frames : iterable of int
        The cycle frames wanted.

    Returns
    -------
    list of ForegroundView
        Each item's plan and cycle frame; empty when the foreground has no cycle products of its own.
    """
    if not plan.foreground.cached:
        return []
    wanted = set(cycle_frames)
    if plan.follow is None:
        return [ForegroundView(plan, frame) for frame in sorted(wanted)]
    views: dict[str, ForegroundView] = {}
    for frame in range(plan.frames):
        cycle_frame = frame % plan.canopy.cycle
        if cycle_frame in wanted:
            view = plan.at(frame)
            views.setdefault(cache_keys.key_of("foreground", foreground_params(view, cycle_frame)),
                             ForegroundView(view, cycle_frame))
    return list(views.values())


def disk_needed(plan: RunPlan) -> DiskNeed:
    """The disk a whole run writes.

    The frames at FRAME_BYTES_PER_PIXEL, and the most the cycle products take: per layer and cycle
    frame the coarse spectrum (complex64 half spectrum of its FFT, or of one tile) and the fine one
    at their exact sizes, per cycle frame the built-in trees' passes (sun, sky: 3 float32, alpha
    and haze: 1) over the whole frame (they are stored cut to the pixels the trees touch:
    ``foreground.models.cut_to_trees``).

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan: its frames, camera, layers and cycle.

    Returns
    -------
    DiskNeed
        The frames' bytes and, at most, the cycle products' [B].
    """
    width, height = plan.camera.width, plan.camera.height
    frames = plan.frames * width * height * FRAME_BYTES_PER_PIXEL[plan.output.half]
    per_frame = 0
    for lp in plan.layers:
        coarse = lp.coarse
        rows, cols = coarse.fft_shape if isinstance(coarse, shadow.IsolatedPlan) else coarse.tile_shape
        per_frame += rows * (cols // 2 + 1) * 8
        if lp.sun is not None:
            rows, cols = lp.sun.fft_shape
            per_frame += rows * (cols // 2 + 1) * 8
    trees = len(foreground_views(plan, range(plan.canopy.cycle))) * 8 * 4 * width * height
    return DiskNeed(float(frames), float(per_frame * plan.canopy.cycle + trees))  # trees: float32 sun, sky, alpha, haze


CONFIG_INDEX = ".configs"
"""Folder in the cache root where each config that rendered records the keys of its cycle
products (``record_config_items``), so that ``sunshade cache list`` can name them."""


def config_item_keys(plan: RunPlan) -> dict[str, tuple[str, int]]:
    """Every cycle product a config's run needs.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan: its layers, foreground and cycle.

    Returns
    -------
    dict of str to tuple
        Cache key -> (kind, cycle frame).
    """
    products: list[tuple[RunPlan, int | None, int]] = [
        (plan, layer, frame) for frame in range(plan.canopy.cycle) for layer in range(len(plan.layers))]
    products += [(view.plan, None, view.cycle_frame) for view in foreground_views(plan, range(plan.canopy.cycle))]
    products += [(plan, wall_task(wall), frame) for frame in range(plan.canopy.cycle)  # type: ignore[misc]
                 for wall in range(len(plan.receivers.walls))]
    keys = {}
    for view, layer, frame in products:
        kind, params = _product_key(view, layer, frame)
        keys[cache_keys.key_of(kind, params)] = (kind, frame)
    return keys


def record_config_items(plan: RunPlan, store: cache.Cache) -> None:
    """Record in the cache which items are this config's, written atomically.

    ``CONFIG_INDEX``/<hash of its path>.json: its name, path and keys, those of earlier versions
    of it (a preview's among them) kept, and the longest cycle among them.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan (its source names the config).
    store : store.Cache
        The cache.
    """
    folder = store.root / CONFIG_INDEX
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{hashlib.sha256(str(plan.source).encode()).hexdigest()[:16]}.json"
    try:
        earlier = json.loads(path.read_text())
        keys, cycle = set(earlier.get("keys", [])), int(earlier.get("cycle", 0))
    except (OSError, ValueError, AttributeError, TypeError):
        keys, cycle = set(), 0
    keys |= set(config_item_keys(plan))
    temporary = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    temporary.write_text(json.dumps({"name": plan.output.name, "config": str(plan.source),
                                     "cycle": max(cycle, plan.canopy.cycle), "keys": sorted(keys)}))
    temporary.replace(path)


def recorded_configs(store: cache.Cache) -> list[dict]:
    """The configs recorded in a cache (``record_config_items``).

    Parameters
    ----------
    store : store.Cache
        The cache.

    Returns
    -------
    list of dict
        Each {name, config, cycle, keys}, by name (then path); unreadable records left out.
    """
    found = []
    for path in sorted((store.root / CONFIG_INDEX).glob("*.json")):
        try:
            entry = json.loads(path.read_text())
            found.append({"name": str(entry["name"]), "config": str(entry["config"]),
                          "cycle": int(entry.get("cycle", 0)), "keys": set(entry["keys"])})
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return sorted(found, key=lambda entry: (entry["name"], entry["config"]))


@portable
def _cycle_task(plan: RunPlan, layer: int | None, frame: int, root: str, workers: int,
                command: int | None = None) -> int:
    end_if_orphaned(command)
    store = cache.Cache(root)
    from pipeline.kernels import raster  # numba costs 0.3 s to import: a worker needs it anyway

    with compiled_once(raster.shapes):  # after an install, one worker compiles the rasteriser
        if wall_index(layer) is not None:
            wall_item(plan, wall_index(layer), frame, store, workers=workers)  # type: ignore[arg-type]
        elif layer is None:
            foreground_item(plan, frame, store)
        else:
            cycle_item(plan, layer, frame, store, workers=workers)
    return store.misses


def foreground_params(plan: RunPlan, cycle_frame: int) -> dict[str, Any]:
    """Everything the built-in trees' passes at ``cycle_frame`` depend on: their cache key's params.

    Not the light's strength or colour, since they are stored per unit irradiance.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    cycle_frame : int
        The flutter cycle's frame.

    Returns
    -------
    dict
        JSON-able params (``keys.key_of``).

    Raises
    ------
    ValueError
        For a canopy without built-in trees.
    """
    c = plan.canopy
    if c.trees is None:
        raise ValueError("the foreground's cycle products are the built-in trees' (canopy.trees)")
    return {"trees": asdict(c.trees), "flutter": asdict(c.flutter),
            "heights": [layer.height for layer in c.layers], "layout": c.layout,
            "center": c.layers[0].center, "size": c.layers[0].size,
            "camera": asdict(plan.camera),
            "frame": cycle_frame, "sun": None if plan.sun_window is None else plan.projection,
            "haze": plan.haze,
            "wood": {"tip": tree_detail.TIP_TAPER, "piece": tree_detail.TAPER_PIECE,  # the stems' cones and bark
                     "furrows": tree_detail.BARK_FURROWS, "contrast": tree_detail.BARK_CONTRAST,
                     "probe": foreground.STEM_PROBE},
            "stored": "cut to the trees",  # cut_to_trees
            "copies": None if c.layout != "periodic" else {  # how a periodic forest's tile is copied
                "detail": tree_detail.LEAF_PIXELS, "reach": tree_detail.HAZE_REACH,
                "most": tree_detail.MAX_FOREST_REACH, "stems": tree_detail.STEM_DETAIL_PIXELS},
            **({"slope": asdict(plan.receivers.slope)} if plan.receivers.slope else {})}  # trees standing on it


def foreground_item(plan: RunPlan, cycle_frame: int, store: cache.Cache) -> models.StoredTreePasses:
    """The built-in trees' foreground passes at ``cycle_frame``, cached, per unit irradiance.

    The shading is linear in each channel's light, so a frame scales them by the run's Lighting.

    Parameters
    ----------
    plan, cycle_frame
        As in ``foreground_params``.
    store : store.Cache
        The cache.

    Returns
    -------
    foreground.models.StoredTreePasses
        The sun's term for a normal irradiance of 1 in each channel, the sky's for a horizontal
        irradiance of 1 [1/sr], the coverage and the haze's share [1], all cut to the box of the
        pixels the trees touch (``foreground.models.cut_to_trees``). Memory-mapped, read-only; the
        cache's item keeps them as ``sun``, ``sky``, ``alpha``, ``box`` and maybe ``haze``.
    """
    c, trees = plan.canopy, plan.canopy.trees
    if trees is None:
        raise ValueError("the foreground's cycle products are the built-in trees' (canopy.trees)")

    def compute() -> dict[str, np.ndarray]:
        grove, flutter = grove_of(c, plan.receivers.slope)  # standing on a slope, if there is one
        leaves = grove_geometry.leaves_at(grove, flutter, cycle_frame)
        wood, owner = tree_detail.taper_wood(grove.wood)
        has_sun = plan.sun_window is not None
        sun_point = np.asarray(plan.projection)
        leaf_visibility = wood_visibility = None
        if has_sun:
            leaf_visibility, wood_visibility = foreground.stem_visibility(leaves, wood, sun_point=sun_point)
        view = plan.camera
        if c.layout == "periodic":  # the tile's trees on every tile in view
            layer = c.layers[0]
            leaves, wood, leaf_index, wood_index = tree_detail.periodic_copies(
                leaves, wood, view, period=layer.size[0], center=layer.center, haze=plan.haze,
                seed=trees.seed, coarse_wood=grove.wood)
            if leaf_visibility is not None and wood_visibility is not None:  # with a sun
                # a straight capsule gets the mean visibility of its pieces
                pieces = np.bincount(owner, minlength=len(grove.wood.radius))
                capsule = np.bincount(owner, weights=wood_visibility, minlength=len(pieces)) / np.maximum(pieces, 1)
                leaf_visibility = leaf_visibility[leaf_index]
                wood_visibility = np.concatenate([wood_visibility, capsule])[wood_index]
        direction = np.append(sun_point, 1.0) / np.linalg.norm(np.append(sun_point, 1.0))
        passes = foreground.tree_passes(
            leaves, wood, view, sun_direction=direction,
            sun_irradiance=np.ones(3) if has_sun else np.zeros(3), sky_irradiance=np.ones(3),
            leaf_sun_visibility=leaf_visibility, wood_sun_visibility=wood_visibility, haze=plan.haze)
        item = {"sun": passes.sun - passes.sky, "sky": passes.sky, "alpha": passes.alpha}
        if passes.haze is not None:
            item["haze"] = passes.haze
        return models.cut_to_trees(item)

    return models.StoredTreePasses.from_item(
        store.get_or_compute("foreground", foreground_params(plan, cycle_frame), compute))
