"""The ``sunshade`` command: the only module that prints.

Exit codes: 0 done, 2 bad input (one line naming the key or file; nothing written),
1 an unexpected failure.

Why one module: each command's arguments, checks of its flags and printing, and nothing
else (the work is in the stages); one place shows the whole command line.
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import inspect
import os
import sys
import time
import traceback
import types
from pathlib import Path
from typing import TYPE_CHECKING

from . import __version__, paths
from .cores import CLUSTER_TIMEOUT
from .errors import BadInput, SunshadeError, WorkerError, one_line, one_line_warnings
from .vocabulary import PASSES

SKY_PASSES = ("sun", "sky")
"""The light passes ``sunshade sky`` writes (the others need a ground and a camera)."""

if TYPE_CHECKING:
    from .cache import Cache

EXIT_BAD_INPUT = 2
EXIT_FAILURE = 1


def main(argv=None) -> int:
    one_line_warnings()
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        return _fail(str(exc), EXIT_BAD_INPUT)
    try:
        return args.run(args)
    except SunshadeError as exc:
        return _fail(str(exc), EXIT_BAD_INPUT, args.debug)
    except MemoryError:
        return _fail("not enough memory for this config; raise ground.pixel, or lower sky.alpha "
                     "or the canopy size", EXIT_BAD_INPUT, args.debug)
    except OSError as exc:
        return _fail(_os_error_line(exc), EXIT_BAD_INPUT, args.debug)
    except KeyboardInterrupt:
        print("sunshade: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: one line, the traceback only under --debug
        what = str(exc) if isinstance(exc, WorkerError) else f"{type(exc).__name__}: {exc}"
        return _fail(f"internal error ({what}); run again with --debug for the traceback, and "
                     "please report it", EXIT_FAILURE, args.debug)


def _fail(line: str, code: int, debug: bool = False) -> int:
    """Print ``line`` (the traceback before it under --debug); return ``code``."""
    if debug:
        traceback.print_exc()
        details = getattr(sys.exception(), "details", "")
        if details:
            print(f"the worker's traceback:\n{details}", file=sys.stderr, end="")
    print(f"sunshade: error: {one_line(line)}", file=sys.stderr)
    return code


def _os_error_line(exc: OSError) -> str:
    """One line for a failed file operation, naming the path where the error has one."""
    names = [str(p) for p in (exc.filename, exc.filename2) if p is not None]
    reason = exc.strerror or str(exc) or type(exc).__name__
    hint = ""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        hint = "; make room and run the same command again (done work is kept)"
    return f"{' -> '.join(names)}: {reason}{hint}" if names else f"{reason}{hint}"


class _UsageError(Exception):
    """A command line argparse refused: its one-line message."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors that name the flag (and the command to ask for help)."""

    def error(self, message):
        raise _UsageError(f"{message} (see {self.prog} --help)")


def _parser():
    parser = _Parser(
        prog="sunshade",
        description="Sunlight and skylight through leaves (Max 1991, 'Unified sun and sky "
        "illumination for shadows under trees').",
    )
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    parser.add_argument("--version", action="version", version=f"sunshade {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # the options several commands share, each written once
    config = _shared("config", help="YAML config file")
    store = _shared("--cache", default=None, help="cache folder (default $SUNSHADE_CACHE or ./cache)")
    budget = _shared("--cache-size", default=None, metavar="SIZE", help="the cache's budget, e.g. 20G: "
                     "at the end of a render the least recently used items no live run uses are "
                     "removed down to it (default $SUNSHADE_CACHE_SIZE, else 20G)")
    threads = _shared("--threads", type=int, default=None, help="FFT threads (default: all cores)")
    png = _shared("--png", action="store_true", help="also write a tone-mapped PNG beside the EXR")
    moment = _shared("--frame", type=int, default=0, help="output frame (default 0): the sun, moon "
                     "and clouds of that moment, the canopy at frame mod cycle")
    picture = _shared("-o", "--output", required=True, help="output PNG or EXR file")
    debug = _shared("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)

    def command(run, parents):
        """The subcommand run by ``run`` (``_run_NAME``), its help the first paragraph of the
        function's docstring, its description the rest."""
        help, _, description = inspect.cleandoc(run.__doc__).partition("\n\n")
        sub = commands.add_parser(run.__name__.removeprefix("_run_"), parents=[*parents, debug],
                                  help=help, description=description)
        sub.set_defaults(run=run)
        return sub

    render = command(_run_render, [config, store, budget])
    render.add_argument("--frames", default=None, help="frames to render, e.g. 0-47,100 "
                        "(default: all)")
    render.add_argument("--jobs", type=int, default=None, help="frames rendered at once, each in "
                        "its own process (default: render.jobs, else one per core)")
    render.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="run the tasks on this dask.distributed scheduler (the cache and "
                        "the output folder must be on a file system every worker shares)")
    render.add_argument("--cluster-timeout", type=float, default=None, metavar="SECONDS",
                        help="with --scheduler: end the run (resumably) once the cluster has had "
                        f"no scheduler or no workers this long (default {CLUSTER_TIMEOUT:g})")
    render.add_argument("--output", default=None, help="output folder (default: output.folder)")
    render.add_argument("--force", action="store_true", help="render the frames and the video "
                        "again even if done")
    render.add_argument("--preview", action="store_true", help="small and fast, for a first "
                        "look: a quarter of the resolution, coarser rasters, in FOLDER/preview")
    render.add_argument("--verify", action="store_true", help="render nothing: report the "
                        "frames whose files are damaged or not made by this config (exit code "
                        "1 if any), reading every frame and the cache items they were made from")

    command(_run_check, [config, budget])

    ground = command(_run_ground, [config, moment, png, threads, store])
    ground.add_argument("-o", "--output", required=True, help="output EXR (scene-linear) or PNG "
                        "(tone-mapped) file")

    frame = command(_run_frame, [config, moment, picture, threads, store])
    frame.add_argument("--half", action="store_true", help="EXR: half floats instead of float32")
    frame.add_argument("--passes", nargs="?", const=",".join(PASSES), default=None, metavar="NAMES",
                       help="EXR: also the light passes as layers, comma-separated names of "
                       f"{', '.join(PASSES)} (default with the flag alone: all; without it: "
                       "output.passes)")

    mask = command(_run_mask, [config, picture])
    mask.add_argument("--frame", type=int, default=0, help="cycle frame (default 0)")
    mask.add_argument("--layer", type=int, default=0, help="canopy layer (default 0)")
    mask.add_argument("--fine", action="store_true", help="the fine mask of the sun window")

    sky = command(_run_sky, [config, moment, png])
    sky.add_argument("--width", type=int, default=2048, help="image width in pixels (default 2048)")
    sky.add_argument("--passes", nargs="?", const="sun,sky", default=None, metavar="NAMES",
                     help="EXR: also the sun disc and the sky without it as layers sun and sky "
                     "(names: sun, sky; default with the flag alone: both; without it: those of "
                     "output.passes)")
    sky.add_argument("-o", "--output", required=True, help="output EXR (radiance) or PNG "
                     "(tone-mapped) file")

    report = command(_run_report, [])
    report.add_argument("folder", help="a run's folder (output.folder), done, going or killed")

    figures = command(_run_figures, [store])
    figures.add_argument("--output", default="figures", help="folder (default ./figures)")
    figures.add_argument("--preview", action="store_true", help="small and fast")

    cache = command(_run_cache, [store])
    cache.add_argument("action", choices=("list", "verify", "clear", "prune"))
    cache.add_argument("config", nargs="?", default=None, help="list: only this config's items; "
                       "prune: remove only its items (all, or down to --max-size)")
    cache.add_argument("--max-size", default=None, help="prune: the most to keep, e.g. 2G (binary units)")
    cache.add_argument("--remove", action="store_true", help="verify: also remove broken items")
    return parser


DEBUG_HELP = "on an error, print the traceback too (for a bug report)"


def _shared(*flags, **options) -> argparse.ArgumentParser:
    """A parent parser (for ``parents=``) holding one argument shared by several commands."""
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(*flags, **options)
    return parent


OUTPUT_SUFFIXES = (".png", ".exr")
"""What ``-o`` may name: a display-referred PNG or a scene-linear EXR."""


def _flag_path(flag: str, value) -> Path:
    """The path a flag (or an environment variable) gives, checked by ``paths.problem``;
    raises BadInput naming the flag."""
    if problem := paths.problem(value):
        raise BadInput(f"{flag} {paths.shown(value)}: {problem}")
    return Path(value)


def _store(explicit, *, writing: bool = True) -> Cache:
    """The cache at --cache, else $SUNSHADE_CACHE, else ./cache, its path checked first, and
    (``writing``) that it can be written, before any work (docs/runs.md, "Errors")."""
    from .cache import ENV_VAR, Cache, cache_dir

    flag, value = ("--cache", explicit) if explicit else (f"${ENV_VAR}", os.environ.get(ENV_VAR))
    if value:
        _flag_path(flag, value)
    else:
        flag = "the cache folder"
    root = cache_dir(explicit)
    if root.exists() and not root.is_dir():
        raise BadInput(f"{flag} {root}: is a file, not a folder")
    store = Cache(root)
    if writing and (problem := store.writing_problem()):
        raise BadInput(f"{flag} {root}: {problem}; give a cache folder that can be written "
                       f"(--cache DIR or ${ENV_VAR})")
    return store


def _budget(args) -> int:
    """The cache's budget of --cache-size, else $SUNSHADE_CACHE_SIZE, else 20 GiB [B]; raises
    BadInput naming the flag or variable."""
    from .cache import BUDGET_ENV_VAR, cache_budget

    try:
        return cache_budget(args.cache_size)
    except ValueError as exc:
        raise BadInput(f"{'--cache-size' if args.cache_size is not None else '$' + BUDGET_ENV_VAR}: {exc}") from None


def _checked_output(path: str, suffixes=OUTPUT_SUFFIXES) -> Path:
    out = _flag_path("--output", path)
    if out.suffix.lower() not in suffixes:
        raise BadInput(f"{out}: the output must be a {' or '.join(suffixes)} file")
    if out.is_dir():
        raise BadInput(f"{out}: is a folder, not a file")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise BadInput(f"{out}: no such folder: {folder}")
    if not os.access(folder, os.W_OK):
        raise BadInput(f"{out}: cannot write to folder {folder}")
    return out


def _load(args, *, named_frames: bool = True, resolved: bool = True):
    """The config of ``args.config`` read, validated and (``resolved``) resolved: every
    command's one loader (``named_frames``: see config.load_config)."""
    from .config import load_config
    from .resolve import resolve

    config = load_config(args.config, named_frames=named_frames)
    return resolve(config) if resolved else config


def _check_threads(args) -> None:
    if args.threads is not None and args.threads < 1:
        raise BadInput(f"--threads must be at least 1 (got {args.threads})")


def _run_check(args) -> int:
    """check a config and every file it names, and do nothing else

    Read and check a config and every input file it names (masks, HDRI, albedo, foreground
    passes). Exit code 0 if a render would start, 2 with one line naming the key or file if
    not.
    """
    from .cycle import disk_needed
    from .plan import check_inputs
    from .runfolder import check_outputs

    budget = _budget(args)
    config = _load(args)
    plan = check_inputs(config)
    check_outputs(config)
    width, height = config.camera.resolution
    print(f"{args.config}: ok: {config.animation.frames} frames at {config.animation.fps:g} fps, "
          f"{width} x {height} px, a cycle of {config.canopy.cycle}, "
          f"{len(plan.layers)} canopy layer{'s' if len(plan.layers) > 1 else ''}; "
          f"config hash {config.digest()}")
    for line in _framing_lines(plan):
        print(line)
    for line in _eclipse_lines(config):
        print(line)
    frames, cycle = disk_needed(plan)
    print(f"  disk: about {_size(frames + cycle)} for a whole run: frames {_size(frames)}, "
          f"cache at most {_size(cycle)}, "
          + (f"within the cache's budget of {_size(budget)}" if cycle <= budget else
             f"over the cache's budget of {_size(budget)}: a run keeps its own items, and removes "
             "every other one; raise it with --cache-size or $SUNSHADE_CACHE_SIZE"))
    _warn(config, plan)
    return 0


def _eclipse_lines(config) -> list[str]:
    """The eclipse at a site-and-time config's place: contacts, greatest obscuration, the
    duration of totality or annularity, and whether the time span sees it."""
    site = config.sky.site if config.sky.model != "hdri" else None
    if site is None:
        return []
    from . import ephemeris

    found = ephemeris.circumstances(ephemeris.Site(site.latitude, site.longitude, site.elevation),
                                    site.start, site.end)
    if found.kind is None:
        return ["  eclipse: none within 4 h of the time span (sky.site, sky.time)"]

    def clock(when):
        return "-" if when is None else when.strftime("%H:%M:%S.") + f"{when.microsecond // 100000}"

    contacts = ", ".join(f"{name} {clock(when)}" for name, when in found.contacts.items())
    lines = [f"  eclipse: {found.kind}, {found.maximum:%Y-%m-%d}: {contacts} UTC; greatest obscuration "
             f"{100 * found.obscuration:.2f}% at {clock(found.maximum)}"
             + ("" if found.central is None else f"; {found.kind == 'total' and 'totality' or 'annularity'} "
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


def _framing_lines(plan) -> list[str]:
    """The resolved windows and camera, each marked (placed) where the plan placed it."""
    import numpy as np

    def mark(key):
        return " (placed)" if key in plan.auto else ""

    def box(grid):
        return "[" + ", ".join(f"{v:.2f}" for v in grid.extent) + "]"

    lines = [f"  ground.window: {box(plan.window)} m at {plan.window.pixel:g} m{mark('ground.window')}"]
    if plan.sun_window is not None:
        lines.append(f"  ground.sun_window: {box(plan.sun_window)} m at {plan.sun_window.pixel:.4g} m"
                     f"{mark('ground.sun_window')}")
    view = plan.camera
    lines.append(f"  camera: position [{', '.join(f'{v:.2f}' for v in view.position)}] m, "
                 f"yaw {np.degrees(view.yaw):.1f}, pitch {np.degrees(view.pitch):.1f} degrees{mark('camera')}")
    return lines


def _warn(config, plan) -> None:
    from .framing import framing_warnings

    for line in framing_warnings(config, plan):
        print(f"sunshade: warning: {line}", file=sys.stderr)


def _run_render(args) -> int:
    """render a config's animation: frames, video and run.json, resumably

    Render the animation of a config into output.folder (default renders/NAME): the cycle
    products (cached), then the frames NAME.0000.exr and .png, then the video once every
    frame is done, and run.json. Run it again to resume: done frames (their files complete
    and made by the same config) are skipped.
    """
    from dataclasses import replace

    from .cores import MAX_JOBS_PER_CORE, default_workers, scheduler_address
    from .preview import preview
    from .resolve import resolve, source_digest
    from .runfolder import check_outputs, nothing_to_do, parse_frames

    if args.jobs is not None and args.jobs < 1:
        raise BadInput(f"--jobs must be at least 1 (got {args.jobs})")
    if args.cluster_timeout is not None and not 0 < args.cluster_timeout < 1e6:
        raise BadInput(f"--cluster-timeout must be above 0 s (got {args.cluster_timeout})")
    if args.scheduler is not None and isinstance(problem := scheduler_address(args.scheduler), str):
        raise BadInput(f"--scheduler {paths.shown(args.scheduler)}: {problem}")
    budget = _budget(args)
    store = _store(args.cache)
    written = _load(args, resolved=False)  # resolved below, unless a resume has nothing to do
    if args.output is not None:
        folder = _flag_path("--output", args.output).expanduser().absolute()
        written = replace(written, output=replace(written.output, folder=folder))
    config = preview(written) if args.preview else written
    if args.preview:
        print(_preview_line(written, config), flush=True)

    def resolved():
        return preview(resolve(written)) if args.preview else resolve(written)

    frames = None if args.frames is None else parse_frames(args.frames, config.animation.frames)
    if args.verify:
        return _verify_run(resolved(), store)
    jobs, most = args.jobs or config.render.jobs, MAX_JOBS_PER_CORE * default_workers()
    if jobs and jobs > most and args.scheduler is None:
        raise BadInput(f"{'--jobs' if args.jobs else f'{args.config}: render.jobs'} {jobs} would "
                       f"start {jobs} processes on {default_workers()} cores; the most is {most} "
                       f"({MAX_JOBS_PER_CORE} a core)")
    check_outputs(config)
    source_hash = source_digest(config)
    summary = None if args.force else nothing_to_do(config, store, frames, jobs=args.jobs, scheduler=args.scheduler,
                                                    source_hash=source_hash)
    if summary is None:
        config = resolved()
        summary = _render_run(config, store, frames, args, source_hash, budget)
    made = f"; video {summary.video}" if summary.video else ""
    count = len(summary.rendered)
    print(f"sunshade: {count} frame{'' if count == 1 else 's'} rendered, {len(summary.skipped)} already done, "
          f"in {summary.timings['total']:.1f} s; {config.output.folder}{made}")
    if summary.pruned:
        print(f"sunshade: the cache was over its budget of {_size(budget)}: removed {len(summary.pruned)} "
              f"item{'' if len(summary.pruned) == 1 else 's'} ({_size(sum(i.bytes for i in summary.pruned))}) "
              f"that no live run uses, least recently used first; {store.root}")
    return 0


def _render_run(config, store, frames, args, source_hash, budget):
    """``run.render_run`` of the command's frames; the folders it made are removed if it fails
    and leaves them empty."""
    from .run import render_run
    from .runfolder import missing_folders, remove_if_empty

    new = missing_folders(config.output.folder)
    try:
        return render_run(config, frames=frames, store=store,
                          jobs=args.jobs, scheduler=args.scheduler, force=args.force,
                          cluster_timeout=args.cluster_timeout, source_hash=source_hash, budget=budget,
                          progress=_Progress(sys.stderr),
                          warn=lambda line: print(f"sunshade: warning: {line}", file=sys.stderr))
    except BaseException:
        remove_if_empty(new)
        raise


def _verify_run(config, store) -> int:
    from .runfolder import frame_files, verify_run

    checked = verify_run(config, store=store)
    for what, frames in (("damaged", checked.damaged), ("foreign", checked.foreign)):
        for frame, problem in sorted(frames.items()):
            print(f"{frame_files(config, frame)[0].stem}: {what}: {problem}")
    count = config.animation.frames
    absent = count - len(checked.done) - len(checked.damaged) - len(checked.foreign)
    print(f"sunshade: {len(checked.done)} of {count} frames whole, {len(checked.damaged)} "
          f"damaged, {len(checked.foreign)} foreign, {absent} not rendered; {config.output.folder}")
    return 1 if checked.damaged or checked.foreign else 0


def _preview_line(full, quick) -> str:
    """One line: what a preview changed from the full render."""
    changes = [f"{quick.camera.resolution[0]} x {quick.camera.resolution[1]} px",
               f"ground pixels {quick.ground.pixel:g} m (full: {full.ground.pixel:g})",
               f"the sun disc {quick.render.sun_cells} cells across (full: {full.render.sun_cells})"]
    if quick.canopy.cycle != full.canopy.cycle:
        changes.append(f"a flutter cycle of {quick.canopy.cycle} frames, faster (full: {full.canopy.cycle})")
    return f"sunshade: preview: {', '.join(changes)}; every leaf and the sky as in the full render"


class _Progress:
    """A run's progress on a stream: on a terminal one line redrawn in place (stage, a bar,
    count, time left), else a plain log line every 10 s and at the end of each stage. The time
    left is estimated from the rate since the stage's first item was done, once a second one
    is (the first carries the workers' start and, after an install, the loops' compiling)."""

    LABELS = {"cycle": "cycle products", "frames": "frames", "video": "video"}

    def __init__(self, stream):
        self.stream, self.tty = stream, stream.isatty()
        self.stage = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = time.monotonic()
        if stage != self.stage:
            self.stage, self.first, self.logged, self.mark = stage, done, None, None
        if not total or (done == self.first and done == total):
            return
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
        elif done == total or self.logged is None or now - self.logged >= 10.0:
            self.logged = now
            self.stream.write(f"sunshade: {label} {done}/{total}{left}\n")
            self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 \
        else f"{seconds // 60}:{seconds % 60:02d}"


def _run_ground(args) -> int:
    """write the ground irradiance under a canopy mask and a sky

    Write the ground irradiance (RGB float32, linear, radiance x sr) over ground.window at
    ground.pixel metres, north-up, as an EXR.
    """
    import numpy as np

    from . import io
    from .composite import display_ground
    from .ground import render_ground
    from .plan import plan_run

    output = _checked_output(args.output)
    exr = output if output.suffix.lower() == ".exr" else None
    png = output if exr is None else (_checked_output(str(output.with_suffix(".png"))) if args.png else None)
    _check_threads(args)
    config = _load(args, named_frames=False)
    _check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    digest = config.digest()
    started = time.perf_counter()
    store = _store(args.cache)
    result = render_ground(plan_run(config), args.frame, store=store, workers=args.threads)
    elapsed = time.perf_counter() - started
    if not np.all(np.isfinite(result.irradiance)):
        raise BadInput(f"{args.config}: the ground irradiance overflowed; lower the sky's radiance")
    if not result.exact:
        print(
            "sunshade: note: the sky square (sky.alpha) does not span the canopy from every "
            "ground point; light from beyond it is taken as unshadowed",
            file=sys.stderr,
        )
    attributes = {
        "sunshade:window": result.grid.extent,
        "sunshade:pixel_size": float(result.grid.pixel),
        "sunshade:config_hash": digest,
        "sunshade:version": __version__,
        "sunshade:frame": int(args.frame),
    }
    written = []
    if exr is not None:
        io.write_exr(exr, result.irradiance, attributes)
        written.append(exr)
    if png is not None:
        io.write_png(png, display_ground(result.irradiance, result.unshadowed))
        written.append(png)
    rows, cols = result.grid.shape
    print(
        f"sunshade: ground {cols} x {rows} px at {result.grid.pixel:g} m in {elapsed:.2f} s; "
        f"open-sky irradiance {', '.join(f'{v:.4g}' for v in result.unshadowed)}; "
        f"wrote {', '.join(str(p) for p in written)}"
    )
    return 0


def _run_frame(args) -> int:
    """render one finished frame: ground and sky in the camera, trees in front

    Render one finished frame (Max 1991, Fig. 10): the ground raster and the sky resampled
    in the camera, the haze, the foreground passes blended by the sun fraction S. A .png is
    exposed and display-transformed (camera.exposure, camera.display); an .exr stays scene-
    linear radiance with its metadata.
    """
    import numpy as np

    from . import io
    from .composite import display
    from .frame import render_frame
    from .plan import plan_run
    from .run import exr_layers, frame_attributes

    output = _checked_output(args.output)
    suffix = output.suffix.lower()
    _check_threads(args)
    if args.half and suffix != ".exr":
        raise BadInput("--half is for EXR output")
    passes = _passes_flag(args.passes, PASSES)
    if passes and suffix != ".exr":
        raise BadInput("--passes is for EXR output")
    config = _load(args, named_frames=False)
    if passes is not None:
        if passes and config.ground.brdf is not None:
            raise BadInput(f"--passes: the light passes are not made with a ground.brdf yet ({args.config})")
        config = dataclasses.replace(config, output=dataclasses.replace(config.output, passes=passes))
    _check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    started = time.perf_counter()
    result = render_frame(plan_run(config), args.frame, store=_store(args.cache), workers=args.threads,
                          passes=config.output.passes if suffix == ".exr" else ())
    elapsed = time.perf_counter() - started
    if not np.all(np.isfinite(result.radiance)):
        raise BadInput(f"{args.config}: the frame overflowed; lower the sky's radiance")
    if suffix == ".exr":
        io.write_exr(output, result.radiance, frame_attributes(config, result, config.digest()),
                     half=args.half, layers=exr_layers(result, args.half))
    else:
        io.write_png(output, display(result.radiance, exposure=result.exposure, transform=config.camera.display,
                                     balance=result.balance))
    rows, cols = result.radiance.shape[:2]
    print(f"sunshade: frame {args.frame}, {cols} x {rows} px, S = {result.sun_fraction:.4f}, "
          f"in {elapsed:.2f} s; wrote {output}")
    return 0


def _passes_flag(value, valid) -> tuple[str, ...] | None:
    """The pass names of a ``--passes NAMES`` flag, in ``vocabulary.PASSES``' order (None: no
    flag); an unknown name is a one-line error naming the flag."""
    if value is None:
        return None
    names = [n.strip() for n in value.split(",") if n.strip()]
    for name in names:
        if name not in valid:
            raise BadInput(f"--passes: unknown pass {name!r}; valid: {', '.join(valid)}")
    return tuple(p for p in PASSES if p in names)


def _check_frame(frame: int, count: int, flag: str, key: str) -> None:
    if not 0 <= frame < count:
        raise BadInput(f"{flag} {frame} is outside 0..{count - 1} ({key} is {count})")


def _run_mask(args) -> int:
    """write the canopy mask of a cycle frame (Max 1991, Fig. 4)

    Write the transmittance mask (1 = open sky) of one canopy layer at one cycle frame, the
    leaves projected along the sun onto the canopy plane, north-up: the coarse mask of the
    whole canopy, or with --fine the fine mask under the sun window.
    """
    from . import io
    from .cycle import layer_masks
    from .plan import plan_run

    output = _checked_output(args.output)
    suffix = output.suffix.lower()
    config = _load(args, named_frames=False)
    _check_frame(args.frame, config.canopy.cycle, "--frame", "the canopy's cycle")
    _check_frame(args.layer, len(config.canopy.layers), "--layer", "the number of canopy layers")
    plan = plan_run(config)
    layer = plan.layers[args.layer]
    if args.fine and layer.sun is None:
        raise BadInput(f"{args.config}: --fine needs a sky with a sun (sky.model: cie, preetham or hdri)")
    started = time.perf_counter()
    coarse, fine = layer_masks(plan, args.layer, args.frame)
    mask, grid = (fine, layer.sun.mask) if args.fine else (coarse, layer.canopy)
    elapsed = time.perf_counter() - started
    if suffix == ".exr":
        io.write_exr(output, mask[..., None], {"sunshade:window": grid.extent,
                                               "sunshade:pixel_size": float(grid.pixel)})
    else:
        io.write_png(output, mask[..., None])
    rows, cols = mask.shape
    x0, y0, x1, y1 = grid.extent
    print(f"sunshade: mask {cols} x {rows} px at {grid.pixel:g} m over x {x0:.2f}..{x1:.2f}, "
          f"y {y0:.2f}..{y1:.2f} m; mean transmittance {mask.mean():.3f}; {elapsed:.2f} s; "
          f"wrote {output}")
    return 0


def _run_sky(args) -> int:
    """write the sky of a frame as an equirectangular EXR

    Write the sky (sun, moon, clouds) of a frame as linear RGB radiance, equirectangular:
    top row at the zenith, centre column north, east at three quarters of the width; the
    lower half is below the horizon.
    """
    import numpy as np

    from . import io
    from .composite import display_sky
    from .scene import load_sky, scene_at

    output = _checked_output(args.output)
    exr = output if output.suffix.lower() == ".exr" else None
    png = output if exr is None else (_checked_output(str(output.with_suffix(".png"))) if args.png else None)
    if not 8 <= args.width <= 16384 or args.width % 2:
        raise BadInput(f"--width must be an even number from 8 to 16384 (got {args.width})")
    passes = _passes_flag(args.passes, SKY_PASSES)
    config = _load(args, named_frames=False)
    if passes is None:
        passes = tuple(p for p in config.output.passes if p in SKY_PASSES)
    _check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    scene = scene_at(config, args.frame)
    sky = load_sky(config.sky, scene)
    if not hasattr(sky, "equirect"):
        raise BadInput(f"{args.config}: sunshade sky writes the cie and preetham skies (sky.model is "
                       f"{config.sky.model}; an hdri sky is its image)")
    image, parts = sky.equirect(args.width, parts=True) if passes else (sky.equirect(args.width), None)
    attributes = {"sunshade:config_hash": config.digest(), "sunshade:frame": int(args.frame),
                  "sunshade:version": __version__}
    if scene.sun is not None:
        attributes["sunshade:sun_azimuth_elevation"] = (np.degrees(scene.sun.azimuth),
                                                        np.degrees(scene.sun.elevation))
    layers = None
    if passes:  # as a frame's: the standard attributes and the layers (docs/runs.md)
        from .frame import open_ground_light
        from .run import LAYER_CHANNELS, standard_attributes

        light = open_ground_light(sky, 1.0, None)
        attributes.update(standard_attributes(
            dataclasses.replace(config, output=dataclasses.replace(config.output, passes=passes)),
            types.SimpleNamespace(scene=scene, light=light)))
        attributes.pop("sunshade:camera_ev100", None)  # no camera here
        layers = {LAYER_CHANNELS[name]: (parts[name], "float") for name in passes}
    written = []
    if exr is not None:
        io.write_exr(exr, image, attributes, layers=layers)
        written.append(exr)
    if png is not None:
        io.write_png(png, display_sky(image))
        written.append(png)
    print(f"sunshade: sky {args.width} x {args.width // 2} px; wrote {', '.join(map(str, written))}")
    return 0


def _run_report(args) -> int:
    """write a run's light curve, contact sheet and light.csv into its folder

    Write light.csv (the open ground's light per done frame: lux from the sun and the sky, S,
    the sun's elevation and azimuth, EV100 and the camera's exposure, the white balance),
    light-curve.png and contact-sheet.png into a run's folder, from its index.json: a run
    still going or killed has them for the frames done so far (docs/runs.md, "The report").
    """
    from .report import write_report

    folder = _flag_path("FOLDER", args.folder)
    if not folder.is_dir():
        raise BadInput(f"{folder}: no such folder")
    started = time.perf_counter()
    written = write_report(folder)
    print(f"sunshade: report in {time.perf_counter() - started:.2f} s; wrote "
          f"{', '.join(str(p) for p in written)}")
    return 0


def _run_figures(args) -> int:
    """reproduce the paper's figures as PNGs

    Reproduce the figures of Max (1991) as PNGs: the mask (Fig. 4), the sky (5), the
    weighted sky raster (6), the ground raster (7), the finished frame (10), the same with a
    point sun and no sky light (11), the eclipsed ground and frame (12, 13), I0(alpha)/pi
    (16), S(t) through the 2024 eclipse at Dallas, and, beyond the paper, the ground's
    reflectance: Lambert beside the grass preset with the sun behind the camera.
    """
    from .figures import FIGURES, write_figures
    from .runfolder import check_folder

    folder = _flag_path("--output", args.output)
    check_folder(folder)
    folder.mkdir(parents=True, exist_ok=True)
    progress = _Progress(sys.stderr)
    started = time.perf_counter()
    written = write_figures(folder, store=_store(args.cache), preview=args.preview,
                            progress=lambda name, done, total: progress("figures", done, total))
    captions = dict(FIGURES)
    for path in written:
        print(f"{path}: {captions.get(path.name, '')}")
    print(f"sunshade: {len(written)} figures in {time.perf_counter() - started:.1f} s")
    return 0


def _run_cache(args) -> int:
    """look after the on-disk cache of cycle products

    The cache folder is --cache, else $SUNSHADE_CACHE, else ./cache.
    """
    from .cache import parse_size

    store = _store(args.cache, writing=False)
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
        from .cycle import config_item_keys
        from .plan import plan_run

        mine = config_item_keys(plan_run(_load(args)))
    if args.action == "list":
        return _print_lines(_cache_listing(store, args.config, mine))
    if args.action == "verify":
        count = len(store.list())
        broken = store.verify(remove=args.remove)
        strays = store.strays(remove=args.remove)
        removed = " (removed)" if args.remove else ""
        lines = [f"{item.kind} {item.key[:16]}: {problem}{removed}" for item, problem in broken]
        lines += [f"{path}: {problem}{removed}" for path, problem in strays]
        stray_count = f", {len(strays)} entr{'y' if len(strays) == 1 else 'ies'} not an item" if strays else ""
        _print_lines([*lines, f"{len(broken)} broken of {count} items{stray_count}"])
        return 1 if (broken or strays) and not args.remove else 0
    if mine is not None:
        removed = _prune_items(store, mine, limit)
    else:
        removed = store.clear() if args.action == "clear" else store.prune(limit)
    print(f"removed {len(removed)} items, {_size(sum(i.bytes for i in removed))}")
    return 0


def _cache_listing(store: Cache, config_file, mine) -> list[str]:
    """The cache's items grouped by the config that made them (as recorded by its renders), with
    their size and cycle frames; items of no recorded config grouped by kind. With a config:
    its items only."""
    from .cycle import recorded_configs

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
        frames = {item.params.get("frame") for item in own if item.params}
        used = max(item.last_used for item in own)
        lines.append(f"{entry['name']:<24} {_size(sum(i.bytes for i in own)):>10}  {len(own)} items "
                     f"({kinds}), cycle frames {len(frames)} of {entry['cycle']}, last used "
                     f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(used))}  {entry['config']}")
    for kind in sorted({item.kind for item in left.values()}):
        own = [item for item in left.values() if item.kind == kind]
        lines.append(f"{'(no recorded config)':<24} {_size(sum(i.bytes for i in own)):>10}  "
                     f"{len(own)} {kind} item{'' if len(own) == 1 else 's'}")
    lines.append(f"{len(items)} items, {_size(sum(i.bytes for i in items))} in {store.root}")
    return lines


def _prune_items(store: Cache, mine, limit):
    """Remove a config's items, least recently used first, until they total at most ``limit``
    bytes (None: all of them)."""
    from .cache import _remove

    own = sorted((item for item in store.list() if item.key in mine), key=lambda i: (i.last_used, i.key))
    total, removed = sum(item.bytes for item in own), []
    for item in own:
        if limit is not None and total <= limit:
            break
        if _remove(item.path):
            removed.append(item)
        total -= item.bytes
    return removed


def _print_lines(lines) -> int:
    """Print lines to stdout; a reader that stops early (``| head``) ends it quietly."""
    try:
        for line in lines:
            print(line)
        sys.stdout.flush()
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes at exit
    return 0


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024


if __name__ == "__main__":
    sys.exit(main())
