"""The ``sunshade`` commands over a run and its folders: ``check`` (a config before a render), ``render`` (the
frames, the video and run.json, resumably, with --verify), ``report`` (a run folder's light curve), ``figures``
(the paper's) and ``cache`` (the store of cycle products a run keeps), with a run's progress on stderr. Each
command's stages are imported inside it, so that a resume with nothing to do starts without numpy."""

from __future__ import annotations

import os
import sys
import time
from typing import TYPE_CHECKING, ClassVar, TextIO

from pipeline.cli.flags import budget_flag, config_of, flag_path, open_store
from pipeline.core import paths
from pipeline.core.errors import BadInput

if TYPE_CHECKING:
    import argparse
    from collections.abc import Iterable

    from pipeline.cache.store import Cache, CacheItem
    from pipeline.config.settings import Config
    from pipeline.run.record import RunSummary
    from pipeline.stages.plan import RunPlan

__all__ = ["run_check", "run_render", "run_report", "run_figures", "run_cache"]


def run_check(args: argparse.Namespace) -> int:
    """check a config and every file it names, and do nothing else

    Read and check a config and every input file it names (masks, HDRI, albedo, foreground
    passes). Exit code 0 if a render would start, 2 with one line naming the key or file if
    not.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the config and --cache-size.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    from pipeline.run.folder import check_outputs
    from pipeline.stages.cycle import disk_needed
    from pipeline.stages.plan import check_inputs

    budget = budget_flag(args)
    config = config_of(args)
    plan = check_inputs(config)
    check_outputs(config)
    width, height = config.camera.resolution
    print(f"{args.config}: ok: {config.animation.frames} frames at {config.animation.fps:g} fps, "
          f"{width} x {height} px, a cycle of {config.canopy.cycle}, "
          f"{len(plan.layers)} canopy layer{'s' if len(plan.layers) > 1 else ''}; "
          f"config hash {config.digest()}")
    for line in _framing_lines(plan, config):
        print(line)
    for line in _eclipse_lines(config):
        print(line)
    for line in _light_lines(plan):
        print(line)
    for line in _receiver_lines(plan, config):
        print(line)
    for line in _slope_lines(plan):
        print(line)
    for line in _mesh_lines(plan):
        print(line)
    need = disk_needed(plan)
    frames, cycle = need.frame_bytes, need.cache_bytes
    print(f"  disk: about {_size(frames + cycle)} for a whole run: frames {_size(frames)}, "
          f"cache at most {_size(cycle)}, "
          + (f"within the cache's budget of {_size(budget)}" if cycle <= budget else
             f"over the cache's budget of {_size(budget)}: a run keeps its own items, and removes "
             "every other one; raise it with --cache-size or $SUNSHADE_CACHE_SIZE"))
    _warn(config, plan)
    return 0


def _eclipse_lines(config: Config) -> list[str]:
    """The eclipse at a site-and-time config's place: contacts, greatest obscuration, the
    duration of totality or annularity, and whether the time span sees it."""
    site = config.sky.site if config.sky.model != "hdri" else None
    if site is None:
        return []
    from pipeline.sky import ephemeris

    found = ephemeris.circumstances(ephemeris.Site(site.latitude, site.longitude, site.elevation),
                                    site.start, site.end)
    if found.kind is None:
        return ["  eclipse: none within 4 h of the time span (sky.site, sky.time)"]

    def clock(when):
        return "-" if when is None else when.strftime("%H:%M:%S.") + f"{when.microsecond // 100000}"

    contacts = ", ".join(f"{name} {clock(when)}" for name, when in found.contacts.items())
    lines = [f"  eclipse: {found.kind}, {found.maximum:%Y-%m-%d}: {contacts} UTC; greatest obscuration "
             f"{100 * found.obscuration:.2f}% at {clock(found.maximum)}"
             + ("" if found.central is None else f"; {(found.kind == 'total' and 'totality') or 'annularity'} "
                f"{int(found.central // 60)} min {found.central % 60:.1f} s")]
    c1 = found.contacts["C1"] or site.start
    c4 = found.contacts["C4"] or site.end
    if site.end < c1 or site.start > c4:
        lines.append(f"  eclipse: the time span {site.start:%H:%M:%S}-{site.end:%H:%M:%S} UTC misses it "
                     "altogether (sky.time)")
    else:
        inside = [name for name, when in found.contacts.items() if when is not None and site.start <= when <= site.end]
        lines.append(f"  eclipse: the time span {site.start:%H:%M:%S}-{site.end:%H:%M:%S} UTC holds "
                     f"{', '.join(inside) if inside else 'no contact (it lies between two)'}")
    return lines


def _light_lines(plan: RunPlan) -> list[str]:
    """A procedural sky's light on open ground at the first, middle and last frames: how far a sun
    fleck can stand above open shade ((sun + sky) / sky), and the frames whose sun gives no direct
    light (set, or not wholly up)."""
    import numpy as np

    from pipeline.sky.models import ProceduralModel
    from pipeline.stages.lighting import open_ground_light
    from pipeline.stages.scene import sun_lights

    if not isinstance(plan.sky, ProceduralModel):
        return []
    shown = []
    for frame in sorted({0, plan.frames // 2, plan.frames - 1}):
        scene = plan.scenes[frame]
        light = open_ground_light(plan.sky.at(scene), 1.0, None)
        sun, sky = light["sun_lux"] if sun_lights(scene.sun) else 0.0, light["sky_lux"]
        elevation = "" if scene.sun is None else f" (sun {np.degrees(scene.sun.elevation):.1f} degrees)"
        ratio = f", a fleck at most {(sun + sky) / sky:.2f} x open shade" if sky > 0 else ""
        shown.append(f"frame {frame}{elevation}: sun {sun:.0f} lx, sky {sky:.0f} lx{ratio}")
    lines = ["  light on open ground: " + "; ".join(shown)]
    dark = [sc.frame for sc in plan.scenes if not sun_lights(sc.sun)]
    if dark:
        from pipeline.stages.framing import frame_ranges

        lines.append(f"  the sun gives no direct light (set, or not wholly up) in {len(dark)} of {plan.frames} "
                     f"frames ({frame_ranges(dark)}): the sky alone lights them")
    return lines


def _receiver_lines(plan: RunPlan, config: Config) -> list[str]:
    """With walls, each receiver (the level ground, then each wall) at the first, middle and last frames:
    the sun's angle off its normal, its open sun and sky light and how far a sun fleck can stand above
    its shade ((sun + sky) / sky, luminance; ``wall_framing.open_receivers``), and the share of the
    picture it fills; the walls' files read."""
    import numpy as np

    from pipeline.receivers.walls import sky_key
    from pipeline.stages.wall_framing import (
        EXPOSURE_SHARE,
        exposure_stops,
        open_receivers,
        receiver_shares,
        wall_planes,
    )
    from pipeline.stages.walls import check_walls

    if not plan.receivers.walls:
        return []
    check_walls(plan)
    frames = sorted({0, plan.frames // 2, plan.frames - 1})
    found, by_light = [], {}  # each light once: a still sun's frames share it (its exact sun, ~1 s)
    for f in frames:
        sky = plan.sky.at(plan.scenes[f])
        key: object = sky_key(sky)
        try:
            hash(key)
        except TypeError:  # a sky that cannot be a key (an HDRI's arrays): each frame its own
            key = f
        if key not in by_light:
            by_light[key] = open_receivers(config, sky)
        found.append(by_light[key])
    shares = receiver_shares(plan.camera, wall_planes(config))
    names = ["the level ground"] + [f"wall {w.name}" for w in plan.receivers.walls]
    looked = int(np.argmax(shares))
    lines = [f"  receivers: {', '.join(f'{n} ({100 * f:.0f}% of the picture)' for n, f in zip(names, shares))}; "
             f"the camera{' (placed)' if 'camera' in plan.auto else ''} sees most of {names[looked]}"]
    for k, name in enumerate(names):
        shown = []
        for frame, lights in zip(frames, found):
            light = lights[k]
            angle = np.degrees(np.arccos(np.clip(light.incidence, -1.0, 1.0)))
            ratio = f", a fleck at most {light.most:.2f} x its shade" if light.sky > 0 else ""
            shown.append(f"frame {frame}: sun {angle:.0f} degrees off its normal, sun {light.sun:.1f} klx, "
                         f"sky {light.sky:.1f} klx{ratio}")
        wall = plan.receivers.walls[k - 1] if k else None
        what = "" if wall is None else (f" ({wall.width:g} x {wall.height:g} m, facing "
                                        f"{np.degrees(wall.facing) % 360:.0f} degrees)")
        lines.append(f"  {name}{what}: " + "; ".join(shown))
    stops = exposure_stops(config, plan.sky.at(plan.scenes[plan.frames // 2]), plan.camera)
    if stops:
        lines.append(f"  exposure: {stops:+.2f} stops from the open ground's, for the brightest receiver that fills "
                     f"at least {100 * EXPOSURE_SHARE:.0f}% of the picture (camera.exposure adds to it)")
    return lines


def _mesh_lines(plan: RunPlan) -> list[str]:
    """Each mesh tree's triangles, leaves, leaf area, bounding box, the layers it falls in and the memory a
    worker takes; a warning where the camera sees it (its foreground passes are not drawn yet)."""
    import numpy as np

    from pipeline.camera.pinhole import project_points
    from pipeline.canopy.mesh_layers import MAX_MESH_BYTES, mesh_bytes, mesh_summary
    from pipeline.stages.cycle import mesh_trees

    lines = []
    heights = [lp.height for lp in plan.layers]
    cells = max(int(np.prod(g.shape)) for lp in plan.layers for g in (lp.canopy, *([lp.sun.mask] if lp.sun else ())))
    for mesh, tree in zip(plan.canopy.meshes, mesh_trees(plan.canopy)):
        got = mesh_summary(tree, heights)
        x0, y0, z0, x1, y1, z1 = got.box
        layers = ", ".join(f"{n:,} at {h:g} m" for n, h in zip(got.layers, heights) if n)
        lines.append(f"  mesh {mesh.file.name}: {got.triangles:,} triangles ({got.skipped:,} of zero area left "
                     f"out), {got.leaves:,} leaves of {got.leaf_triangles:,} triangles, leaf area "
                     f"{got.leaf_area:.3g} m^2; x {x0:.2f} to {x1:.2f}, y {y0:.2f} to {y1:.2f}, z {z0:.2f} to "
                     f"{z1:.2f} m; triangles per layer: {layers}; about {_size(mesh_bytes(tree, cells))} a "
                     f"worker (the most {_size(MAX_MESH_BYTES)})")
        corners = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)] +
                           [[(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2]])
        u, v, depth = project_points(plan.camera, corners)
        seen = (depth > 0) & (u >= 0) & (u <= plan.camera.width) & (v >= 0) & (v <= plan.camera.height)
        if seen.any():
            print(f"sunshade: warning: the mesh tree {mesh.file.name} stands in the camera's view, and a mesh "
                  "tree is not drawn in the picture yet (its shadow is): docs/method.md, \"Trees from mesh files\"",
                  file=sys.stderr)
    return lines


def _framing_lines(plan: RunPlan, config: Config) -> list[str]:
    """The resolved windows and camera, each marked (placed) where the plan placed it, and a window
    that the config gave and the plan laid on whole pixels with the config's numbers beside it."""
    import numpy as np

    def box(values):
        return "[" + ", ".join(f"{v:.2f}" for v in values) + "]"

    def mark(key, grid=None, given=None):
        if key in plan.auto:
            return " (placed)"
        if given is not None and box(given) != box(grid.extent):  # a difference the line shows
            return f" (the config's {box(given)} on whole pixels)"
        return ""

    lines = [f"  ground.window: {box(plan.window.extent)} m at {plan.window.pixel:g} m"
             f"{mark('ground.window', plan.window, config.ground.window)}"]
    if plan.sun_window is not None:
        lines.append(f"  ground.sun_window: {box(plan.sun_window.extent)} m at {plan.sun_window.pixel:.4g} m"
                     f"{mark('ground.sun_window', plan.sun_window, config.ground.sun_window)}")
    view = plan.camera
    walk = ""
    if plan.follow is not None:  # camera.follow: the camera above is the middle shading frame's
        first, last = plan.at(0).camera.position, plan.at(plan.frames - 1).camera.position
        walk = f"; follows the shadow, walking {np.hypot(last[0] - first[0], last[1] - first[1]):.1f} m"
    lines.append(f"  camera: position [{', '.join(f'{v:.2f}' for v in view.position)}] m, "
                 f"yaw {np.degrees(view.yaw):.1f}, pitch {np.degrees(view.pitch):.1f} degrees{mark('camera')}{walk}")
    return lines


def _slope_lines(plan: RunPlan) -> list[str]:
    """With a slope, its open light at the first, middle and last frames: the sun's angle off its
    normal, its sun and sky light and how far a fleck can stand above its shade ((sun + sky) / sky)."""
    import numpy as np

    from pipeline.core.colour import REC709_LUMINANCE
    from pipeline.stages.slope import open_slope

    slope = plan.receivers.slope
    if slope is None:
        return []
    shown = []
    for light in open_slope(plan, sorted({0, plan.frames // 2, plan.frames - 1})):
        sun, sky = (float(np.asarray(v) @ REC709_LUMINANCE) for v in (light.sun, light.sky))
        angle = np.degrees(np.arccos(np.clip(light.incidence, -1.0, 1.0)))
        ratio = f", a fleck at most {(sun + sky) / sky:.2f} x its shade" if sky > 0 else ""
        shown.append(f"frame {light.frame}: sun {angle:.0f} degrees off its normal, sun {sun:.1f} klx, "
                     f"sky {sky:.1f} klx{ratio}")
    return [f"  slope ({np.degrees(slope.tilt):g} degrees, falling towards {np.degrees(slope.facing) % 360:.0f} "
            "degrees): " + "; ".join(shown)]


def _warn(config: Config, plan: RunPlan) -> None:
    from pipeline.stages.framing import framing_warnings

    if plan.receivers.slope is not None:  # the framing's warnings are the level ground's
        return
    for line in framing_warnings(config, plan):
        print(f"sunshade: warning: {line}", file=sys.stderr)


def run_render(args: argparse.Namespace) -> int:
    """render a config's animation: frames, video and run.json, resumably

    Render the animation of a config into output.folder (default renders/NAME): the cycle
    products (cached), then the frames NAME.0000.exr and .png, then the video once every
    frame is done, and run.json. Run it again to resume: done frames (their files complete
    and made by the same config) are skipped.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the config, --output, --frames, --jobs, --scheduler, --cluster-timeout,
        --preview, --verify, --force, --cache and --cache-size.

    Returns
    -------
    int
        The exit code: 0 done (--verify: 1 if a frame is damaged or foreign).
    """
    from dataclasses import replace

    from pipeline.api.functions import check_jobs
    from pipeline.config.preview import preview
    from pipeline.core.cores import scheduler_address
    from pipeline.run.folder import check_outputs, parse_frames
    from pipeline.run.record import nothing_to_do
    from pipeline.stages.resolve import resolve, source_digest

    if args.jobs is not None and args.jobs < 1:
        raise BadInput(f"--jobs must be at least 1 (got {args.jobs})")
    if args.cluster_timeout is not None and not 0 < args.cluster_timeout < 1e6:
        raise BadInput(f"--cluster-timeout must be above 0 s (got {args.cluster_timeout})")
    if args.scheduler is not None and isinstance(problem := scheduler_address(args.scheduler), str):
        raise BadInput(f"--scheduler {paths.shown(args.scheduler)}: {problem}")
    budget = budget_flag(args)
    store = open_store(args.cache)
    written = config_of(args, resolved=False)  # resolved below, unless a resume has nothing to do
    if args.output is not None:
        folder = flag_path("--output", args.output).expanduser().absolute()
        written = replace(written, output=replace(written.output, folder=folder))
    config = preview(written) if args.preview else written
    banner = _preview_line(written, config) if args.preview else None  # said once the config holds

    def resolved():
        return preview(resolve(written)) if args.preview else resolve(written)

    frames = None if args.frames is None else parse_frames(args.frames, config.animation.frames)
    if args.verify:
        return _verify_run(resolved(), store)
    if args.scheduler is None:
        check_jobs(args.jobs, config)
    check_outputs(config)
    source_hash = source_digest(config)
    summary = None if args.force else nothing_to_do(config, store, frames, jobs=args.jobs, scheduler=args.scheduler,
                                                    source_hash=source_hash)
    if summary is None:
        config = resolved()
        if banner:
            print(banner, flush=True)
        summary = _render_run(config, store, frames, args, source_hash, budget)
    elif banner:
        print(banner, flush=True)
    made = f"; video {summary.video}" if summary.video else ""
    if not summary.video and summary.waiting and config.output.video != "none":
        made = f"; the video waits for the other {summary.waiting} frame{'' if summary.waiting == 1 else 's'}"
    count = len(summary.rendered)
    print(f"sunshade: {count} frame{'' if count == 1 else 's'} rendered, {len(summary.skipped)} already done, "
          f"in {summary.timings['total']:.1f} s; {config.output.folder}{made}")
    if summary.pruned:
        print(f"sunshade: the cache was over its budget of {_size(budget)}: removed {len(summary.pruned)} "
              f"item{'' if len(summary.pruned) == 1 else 's'} ({_size(sum(i.bytes for i in summary.pruned))}) "
              f"that no live run uses, least recently used first; {store.root}")
    return 0


def _render_run(config: Config, store: Cache, frames: tuple[int, ...] | None, args: argparse.Namespace,
                source_hash: str, budget: int) -> RunSummary:
    """``render.render_run`` of the command's frames (a failing run removes the folders it made, if
    they are empty)."""
    from pipeline.run.render import render_run

    return render_run(config, frames=frames, store=store,
                      jobs=args.jobs, scheduler=args.scheduler, force=args.force,
                      cluster_timeout=args.cluster_timeout, source_hash=source_hash, budget=budget,
                      progress=_Progress(sys.stderr),
                      warn=lambda line: print(f"sunshade: warning: {line}", file=sys.stderr))


def _verify_run(config: Config, store: Cache) -> int:
    from pipeline.run.folder import frame_files
    from pipeline.run.index import verify_run

    checked = verify_run(config, store=store)
    for what, frames in (("damaged", checked.damaged), ("foreign", checked.foreign)):
        for frame, problem in sorted(frames.items()):
            print(f"{frame_files(config, frame)[0].stem}: {what}: {problem}")
    count = config.animation.frames
    absent = count - len(checked.done) - len(checked.damaged) - len(checked.foreign)
    print(f"sunshade: {len(checked.done)} of {count} frames whole, {len(checked.damaged)} "
          f"damaged, {len(checked.foreign)} foreign, {absent} not rendered; {config.output.folder}")
    return 1 if checked.damaged or checked.foreign else 0


def _preview_line(full: Config, quick: Config) -> str:
    """One line: what a preview changed from the full render."""
    changes = [f"{quick.camera.resolution[0]} x {quick.camera.resolution[1]} px",
               f"ground pixels {quick.ground.pixel:g} m (full: {full.ground.pixel:g})",
               f"the sun disc {quick.render.sun_cells} cells across (full: {full.render.sun_cells})"]
    if quick.canopy.cycle != full.canopy.cycle:
        changes.append(f"a flutter cycle of {quick.canopy.cycle} frames, faster (full: {full.canopy.cycle})")
    return f"sunshade: preview: {', '.join(changes)}; every leaf and the sky as in the full render"


class _Progress:
    """A run's progress on a stream: on a terminal one line redrawn in place (stage, a bar,
    count, time left), else a plain log line at the start and end of each stage, every
    LOG_EVERY seconds, and where a quarter of the stage is passed (at most one a QUARTER_GAP
    seconds: a 10 s preview says 0, 30, 60, 90 and 120 of 120, not 0 and 120). The time
    left is estimated from the rate since the stage's first item was done, once a second one
    is (the first carries the workers' start and, after an install, the loops' compiling)."""

    LABELS: ClassVar[dict[str, str]] = {"cycle": "cycle products", "frames": "frames", "video": "video"}
    LOG_EVERY = 10.0  # [s]
    QUARTER_GAP = 2.0  # [s]

    def __init__(self, stream: TextIO):
        self.stream, self.tty = stream, stream.isatty()
        self.stage: str | None = None  # the stage now, and the last whose end was said
        self.ended: str | None = None
        self.first = 0  # the stage's count when first said
        self.logged: tuple[float, int] | None = None  # (time [s], count) of the last log line
        self.mark: tuple[float, int] | None = None  # (time [s], count) from which the rate counts

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = time.monotonic()
        if stage != self.stage:
            self.stage, self.first, self.logged, self.mark = stage, done, None, None
        if not total or (done == self.first and done == total) or (done == total and self.ended == stage):
            return  # nothing to do, or the stage's end already said
        if done == total:
            self.ended = stage
        if self.mark is None and done > self.first:  # the stage's first item done: the rate counts
            self.mark = (now, done)  # from here, without the workers' start and the loops' compiling
        rate = 0.0
        if self.mark is not None and done > self.mark[1]:
            rate = (done - self.mark[1]) / max(now - self.mark[0], 1e-9)
        left = f", {_clock((total - done) / rate)} left" if 0 < done < total and rate > 0 else ""
        label = self.LABELS.get(stage, stage)
        if self.tty:
            filled = int(24 * done / total)
            end = "\n" if done == total else ""
            self.stream.write(f"\r{label:<15} [{'#' * filled}{'.' * (24 - filled)}] "
                              f"{done}/{total}{left}\033[K{end}")
            self.stream.flush()
        elif (done == total or self.logged is None or now - self.logged[0] >= self.LOG_EVERY
              or (4 * done // total > 4 * self.logged[1] // total and now - self.logged[0] >= self.QUARTER_GAP)):
            self.logged = (now, done)
            self.stream.write(f"sunshade: {label} {done}/{total}{left}\n")
            self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 \
        else f"{seconds // 60}:{seconds % 60:02d}"


def run_report(args: argparse.Namespace) -> int:
    """write a run's light curve, contact sheet and light.csv into its folder

    Write light.csv (the open ground's light per done frame: lux from the sun and the sky, S,
    the sun's elevation and azimuth, EV100 and the camera's exposure, the white balance),
    light-curve.png and contact-sheet.png into a run's folder, from its index.json: a run
    still going or killed has them for the frames done so far (docs/runs.md, "The report").

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: FOLDER.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    from pipeline.run.report import write_report

    folder = flag_path("FOLDER", args.folder)
    if not folder.is_dir():
        raise BadInput(f"{folder}: no such folder")
    started = time.perf_counter()
    written = write_report(folder)
    print(f"sunshade: report in {time.perf_counter() - started:.2f} s; wrote "
          f"{', '.join(str(p) for p in written)}")
    return 0


def run_figures(args: argparse.Namespace) -> int:
    """reproduce the paper's figures as PNGs

    Reproduce the figures of Max (1991) as PNGs: the mask (Fig. 4), the sky (5), the
    weighted sky raster (6), the ground raster (7), the finished frame (10), the same with a
    point sun and no sky light (11), the eclipsed ground and frame (12, 13), I0(alpha)/pi
    (16), S(t) through the 2024 eclipse at Dallas, and, beyond the paper, the ground's
    reflectance: Lambert beside the grass preset with the sun behind the camera.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: --output, --preview and --cache.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    from pipeline.cli.figures import FIGURES, write_figures
    from pipeline.run.folder import check_folder

    folder = flag_path("--output", args.output)
    check_folder(folder)
    folder.mkdir(parents=True, exist_ok=True)
    progress = _Progress(sys.stderr)
    started = time.perf_counter()
    written = write_figures(folder, store=open_store(args.cache), preview=args.preview,
                            progress=lambda name, done, total: progress("figures", done, total))
    captions = dict(FIGURES)
    for path in written:
        print(f"{path}: {captions.get(path.name, '')}")
    print(f"sunshade: {len(written)} figures in {time.perf_counter() - started:.1f} s")
    return 0


def run_cache(args: argparse.Namespace) -> int:
    """look after the on-disk cache of cycle products

    The cache folder is --cache, else $SUNSHADE_CACHE, else ./cache.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the action, CONFIG, --max-size, --remove and --cache.

    Returns
    -------
    int
        The exit code: 0 done (verify: 1 if an item is broken and kept).
    """
    from pipeline.cache.store import parse_size

    store = open_store(args.cache, writing=False)
    root = store.root
    if args.config is not None and args.action not in ("list", "prune"):
        raise BadInput(f"cache {args.action} takes no CONFIG (list and prune do)")
    limit = None
    if args.action == "prune":
        if args.max_size is None and args.config is None:
            raise BadInput("cache prune needs --max-size, e.g. --max-size 2G (or a CONFIG whose items to remove)")
        if args.max_size is not None:
            try:
                limit = parse_size(args.max_size)
            except ValueError as exc:
                raise BadInput(f"--max-size: {exc}") from None
    elif args.max_size is not None:
        raise BadInput("--max-size is only for cache prune")
    if not root.is_dir():
        if args.cache is not None or os.environ.get("SUNSHADE_CACHE"):
            raise BadInput(f"--cache {root}: no such cache folder" if args.cache is not None
                           else f"$SUNSHADE_CACHE {root}: no such cache folder")
        print(f"0 items: no cache folder yet at {root}")
        return 0
    mine = None
    if args.config is not None:
        from pipeline.stages.cycle import config_item_keys
        from pipeline.stages.plan import plan_run

        mine = config_item_keys(plan_run(config_of(args)))
    if args.action == "list":
        return _print_lines(_cache_listing(store, args.config, mine))
    if args.action == "verify":
        count = len(store.list())
        broken = store.verify(remove=args.remove)
        strays = store.strays(remove=args.remove)
        said = " (removed)" if args.remove else ""
        lines = [f"{item.kind} {item.key[:16]}: {problem}{said}" for item, problem in broken]
        lines += [f"{path}: {problem}{said}" for path, problem in strays]
        stray_count = f", {len(strays)} entr{'y' if len(strays) == 1 else 'ies'} not an item" if strays else ""
        _print_lines([*lines, f"{len(broken)} broken of {count} items{stray_count}"])
        return 1 if (broken or strays) and not args.remove else 0
    if mine is not None:
        removed = _prune_items(store, mine, limit)
    elif limit is not None:  # cache prune --max-size
        removed = store.prune(limit)
    else:  # cache clear (a prune without --max-size or CONFIG is refused above)
        removed = store.clear()
    print(f"removed {len(removed)} items, {_size(sum(i.bytes for i in removed))}")
    return 0


def _cache_listing(store: Cache, config_file: str | None, mine: dict[str, tuple[str, int]] | None) -> list[str]:
    """The cache's items grouped by the config that made them (as recorded by its renders), with
    their size and cycle frames; items of no recorded config grouped by kind. With a config:
    its items only."""
    from pipeline.stages.cycle import recorded_configs

    items = store.list()
    if mine is not None:
        own = [item for item in items if item.key in mine]
        frames = {mine[item.key][1] for item in own}
        cycle = len({frame for _, frame in mine.values()})
        return [f"{config_file}: {len(own)} of {len(mine)} items, {_size(sum(i.bytes for i in own))}, "
                f"cycle frames {len(frames)} of {cycle} in {store.root}"]
    lines, left = [], {item.key: item for item in items}
    for entry in recorded_configs(store):
        own = [item for item in items if item.key in entry["keys"]]
        if not own:
            continue
        for item in own:
            left.pop(item.key, None)
        kinds = ", ".join(f"{sum(i.kind == k for i in own)} {k}" for k in sorted({i.kind for i in own}))
        seen = {item.params.get("frame") for item in own if item.params}
        used = max(item.last_used for item in own)
        lines.append(f"{entry['name']:<24} {_size(sum(i.bytes for i in own)):>10}  {len(own)} items "
                     f"({kinds}), cycle frames {len(seen)} of {entry['cycle']}, last used "
                     f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(used))}  {entry['config']}")
    for kind in sorted({item.kind for item in left.values()}):
        own = [item for item in left.values() if item.kind == kind]
        lines.append(f"{'(no recorded config)':<24} {_size(sum(i.bytes for i in own)):>10}  "
                     f"{len(own)} {kind} item{'' if len(own) == 1 else 's'}")
    lines.append(f"{len(items)} items, {_size(sum(i.bytes for i in items))} in {store.root}")
    return lines


def _prune_items(store: Cache, mine: dict[str, tuple[str, int]], limit: int | None) -> list[CacheItem]:
    """Remove a config's items, least recently used first, until they total at most ``limit``
    bytes (None: all of them)."""
    from pipeline.cache.items import remove_tree

    own = sorted((item for item in store.list() if item.key in mine), key=lambda i: (i.last_used, i.key))
    total, removed = sum(item.bytes for item in own), []
    for item in own:
        if limit is not None and total <= limit:
            break
        if remove_tree(item.path):
            removed.append(item)
        total -= item.bytes
    return removed


def _print_lines(lines: Iterable[str]) -> int:
    """Print lines to stdout; a reader that stops early (``| head``) ends it quietly."""
    try:
        for line in lines:
            print(line)
        sys.stdout.flush()
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes at exit
    return 0


def _size(n: float) -> str:
    """``n`` bytes [B] as a line shows them: in B, KiB, MiB or GiB."""
    for unit in ("B", "KiB", "MiB"):
        if n < 1024:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"
