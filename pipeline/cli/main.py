"""The ``sunshade`` command: its command line (every command's arguments in one place), the exit codes and the
one-line errors. The commands are in ``runs`` (check, render, report, figures, cache), ``pictures``
(ground, frame, mask, sky) and ``eclipses``, the flags they share checked in ``flags``; ``main``,
``runs``, ``pictures`` and ``eclipses`` are the only modules that print.

Exit codes: 0 done, 2 bad input (one line naming the key or file; nothing written),
1 an unexpected failure, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM, ``kill PID``).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import inspect
import re
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, NoReturn

from pipeline import __version__
from pipeline.cli.eclipses import run_eclipses
from pipeline.cli.pictures import run_frame, run_ground, run_mask, run_sky
from pipeline.cli.runs import run_cache, run_check, run_figures, run_render, run_report
from pipeline.config.vocabulary import PASSES
from pipeline.core.cores import CLUSTER_TIMEOUT
from pipeline.core.errors import BadInput, SunshadeError, WorkerError, one_line, one_line_warnings

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILURE", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "main"]

EXIT_BAD_INPUT = 2
EXIT_FAILURE = 1
EXIT_INTERRUPTED = 128 + signal.SIGINT
"""Ctrl-C (SIGINT): the shell's code for a command a signal ended."""
EXIT_TERMINATED = 128 + signal.SIGTERM
"""SIGTERM (``kill PID``, a job scheduler ending the job), ended as cleanly as Ctrl-C ends it."""


def main(argv: Sequence[str] | None = None) -> int:
    """The ``sunshade`` command: parse the arguments and run the command they name.

    Parameters
    ----------
    argv : list of str or None
        The arguments; None for ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit code: 0 done, ``EXIT_FAILURE`` a failure, ``EXIT_BAD_INPUT`` bad input (one line
        naming the key, flag or file, nothing written).
    """
    one_line_warnings()
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        return _fail(str(exc), EXIT_BAD_INPUT)
    try:
        with _terminate_as_interrupt():
            return args.run(args)
    except SunshadeError as exc:
        return _fail(str(exc), EXIT_BAD_INPUT, args.debug)
    except MemoryError:
        return _fail("not enough memory for this config; raise ground.pixel, or lower sky.alpha "
                     "or the canopy size", EXIT_BAD_INPUT, args.debug)
    except OSError as exc:
        return _fail(_os_error_line(exc), EXIT_BAD_INPUT, args.debug)
    except _Terminated:
        print("sunshade: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print("sunshade: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # a bug: one line, the traceback only under --debug
        what = str(exc) if isinstance(exc, WorkerError) else f"{type(exc).__name__}: {exc}"
        return _fail(f"internal error ({what}); run again with --debug for the traceback, and "
                     "please report it", EXIT_FAILURE, args.debug)


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread: a KeyboardInterrupt, so that the command unwinds as after
    Ctrl-C (joblib ends the worker processes, the video's encoder ends and its temporary file is
    removed, the run's lock is let go; done frames are kept)."""


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises ``_Terminated`` in the main thread, once (a second SIGTERM
    meanwhile ends the process at once, as before); the previous handler is put back after. Before,
    SIGTERM ended the process where it stood: the video's encoder (a child process) wrote on into
    its temporary file, which stayed. Nothing changes outside the main thread (Python runs signal
    handlers only there)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    restore = previous if previous is not None else signal.SIG_DFL  # None: a handler not set from Python

    def terminated(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, restore)
        raise _Terminated

    signal.signal(signal.SIGTERM, terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, restore)


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

    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{message} (see {self.prog} --help)")


def _parser() -> _Parser:
    """The command line: the top's flags, then each command with its arguments, in the order of the help."""
    parser = _Parser(
        prog="sunshade",
        description="Sunlight and skylight through leaves (Max 1991, 'Unified sun and sky "
        "illumination for shadows under trees').",
    )
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    parser.add_argument("--version", action="version", version=f"sunshade {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    shared = _shared_options()
    _add_render(commands, shared)
    _command(commands, run_check, [shared.config, shared.budget], shared)
    _add_pictures(commands, shared)
    _add_upkeep(commands, shared)
    _add_eclipses(commands, shared)
    return parser


@dataclass(frozen=True)
class _Shared:
    """The options several commands share, each written once: a parent parser (for ``parents=``) each."""

    config: _Parser  # the YAML config file
    store: _Parser  # --cache
    budget: _Parser  # --cache-size
    threads: _Parser  # --threads
    png: _Parser  # --png
    moment: _Parser  # --frame, an output frame
    picture: _Parser  # -o/--output, a picture file
    debug: _Parser  # --debug, which every command takes


def _shared_options() -> _Shared:
    """The parent parsers of the options several commands share."""
    return _Shared(
        config=_shared("config", help="YAML config file"),
        store=_shared("--cache", default=None, help=STORE_HELP),
        budget=_shared("--cache-size", default=None, metavar="SIZE", help="the cache's budget, e.g. 20G: "
                       "at the end of a render the least recently used items no live run uses are "
                       "removed down to it (default $SUNSHADE_CACHE_SIZE, else 20G)"),
        threads=_shared("--threads", type=int, default=None, help="FFT threads (default: all cores)"),
        png=_shared("--png", action="store_true", help="also write a tone-mapped PNG beside the EXR"),
        moment=_shared("--frame", type=int, default=0, help="output frame (default 0): the sun, moon "
                       "and clouds of that moment, the canopy at frame mod cycle"),
        picture=_shared("-o", "--output", required=True, help="output PNG or EXR file"),
        debug=_shared("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP),
    )


def _command(commands: argparse._SubParsersAction[_Parser], run: Callable[[argparse.Namespace], int],
             parents: list[_Parser], shared: _Shared) -> _Parser:
    """The subcommand run by ``run`` (``run_NAME``), its help the first paragraph of the function's
    docstring, its description the rest up to its Parameters; it takes ``parents`` and --debug."""
    text = inspect.cleandoc(run.__doc__ or "").partition("\n\nParameters\n")[0]
    help, _, description = text.partition("\n\n")
    sub = commands.add_parser(run.__name__.removeprefix("run_"), parents=[*parents, shared.debug],
                              help=help, description=description)
    sub.set_defaults(run=run)
    return sub


def _add_render(commands: argparse._SubParsersAction[_Parser], shared: _Shared) -> None:
    """The ``render`` command and its arguments."""
    render = _command(commands, run_render, [shared.config, shared.store, shared.budget], shared)
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


def _add_pictures(commands: argparse._SubParsersAction[_Parser], shared: _Shared) -> None:
    """The commands that write one picture (``ground``, ``frame``, ``mask``, ``sky``) and their arguments."""
    ground = _command(commands, run_ground, [shared.config, shared.moment, shared.png, shared.threads,
                                             shared.store], shared)
    ground.add_argument("-o", "--output", required=True, help="output EXR (scene-linear) or PNG "
                        "(tone-mapped) file")
    ground.add_argument("--receiver", default=None, metavar="NAME", help="a wall's irradiance instead "
                        "(receivers.walls[].name), upright as one faces it")

    frame = _command(commands, run_frame, [shared.config, shared.moment, shared.picture, shared.threads,
                                           shared.store], shared)
    frame.add_argument("--half", action="store_true", help="EXR: half floats instead of float32")
    frame.add_argument("--passes", nargs="?", const=",".join(PASSES), default=None, metavar="NAMES",
                       help="EXR: also the light passes as layers, comma-separated names of "
                       f"{', '.join(PASSES)} (default with the flag alone: all; without it: "
                       "output.passes)")

    mask = _command(commands, run_mask, [shared.config, shared.picture], shared)
    mask.add_argument("--frame", type=int, default=0, help="cycle frame (default 0)")
    mask.add_argument("--layer", type=int, default=0, help="canopy layer (default 0)")
    mask.add_argument("--fine", action="store_true", help="the fine mask of the sun window")

    sky = _command(commands, run_sky, [shared.config, shared.moment, shared.png], shared)
    sky.add_argument("--width", type=int, default=2048, help="image width in pixels (default 2048)")
    sky.add_argument("--passes", nargs="?", const="sun,sky", default=None, metavar="NAMES",
                     help="EXR: also the sun disc and the sky without it as layers sun and sky "
                     "(names: sun, sky; default with the flag alone: both; without it: those of "
                     "output.passes)")
    sky.add_argument("-o", "--output", required=True, help="output EXR (radiance) or PNG "
                     "(tone-mapped) file")


def _add_upkeep(commands: argparse._SubParsersAction[_Parser], shared: _Shared) -> None:
    """The commands that look after runs and the cache (``report``, ``figures``, ``cache``) and their arguments."""
    report = _command(commands, run_report, [], shared)
    report.add_argument("folder", help="a run's folder (output.folder), done, going or killed")

    figures = _command(commands, run_figures, [shared.store], shared)
    figures.add_argument("--output", default="figures", help="folder (default ./figures)")
    figures.add_argument("--preview", action="store_true", help="small and fast")

    _add_cache(commands, shared)


CACHE_ACTIONS = {  # each action's line in ``sunshade cache --help``, in its order
    "list": "the items by the config that made them: name, size, cycle frames (CONFIG: its items only)",
    "verify": "read every item whole and name the broken ones (exit code 1 if any; --remove removes them)",
    "clear": "remove every item",
    "prune": "remove the least recently used items down to --max-size, or a CONFIG's items",
}
CACHE_ARGUMENTS = (  # (flags, options, {action taking it: its help}): the others parse it, its help hidden
    (("config",), {"nargs": "?", "default": None, "metavar": "CONFIG"},
     {"list": "only this config's items", "prune": "remove only its items (all, or down to --max-size)"}),
    (("--max-size",), {"default": None, "metavar": "SIZE"}, {"prune": "the most to keep, e.g. 2G (binary units)"}),
    (("--remove",), {"action": "store_true"}, {"verify": "also remove the broken items"}),
)


def _add_cache(commands: argparse._SubParsersAction[_Parser], shared: _Shared) -> None:
    """The ``cache`` command: an action of CACHE_ACTIONS, each a subcommand whose help shows the
    arguments it takes. Each parses all of CACHE_ARGUMENTS, so that ``run_cache`` says which action takes
    which, as before; --cache is taken before the action too (``sunshade cache --cache DIR list``)."""
    cache = _command(commands, run_cache, [shared.store], shared)
    cache.set_defaults(run=_cache_without_action)
    store = _shared("--cache", default=argparse.SUPPRESS, help=STORE_HELP)  # unset, it keeps the command's
    actions = cache.add_subparsers(dest="action", metavar="ACTION", title="actions", parser_class=_Parser)
    for name, line in CACHE_ACTIONS.items():
        action = actions.add_parser(name, parents=[store, shared.debug], help=line, description=f"{line}.")
        action.set_defaults(run=run_cache)
        for flags, options, helps in CACHE_ARGUMENTS:
            action.add_argument(*flags, **options, help=helps.get(name, argparse.SUPPRESS))


def _cache_without_action(args: argparse.Namespace) -> int:
    """``sunshade cache`` with no action: one line naming them."""
    *first, last = CACHE_ACTIONS
    raise BadInput(f"sunshade cache needs an action: {', '.join(first)} or {last} (see sunshade cache --help)")


def _add_eclipses(commands: argparse._SubParsersAction[_Parser], shared: _Shared) -> None:
    """The ``eclipses`` command and its arguments."""
    eclipses = _command(commands, run_eclipses, [], shared)
    # "--site -33.87,151.21": a value starting with a minus sign and a digit is a value, not a flag
    eclipses._negative_number_matcher = re.compile(r"^-\d")
    eclipses.add_argument("--site", required=True, metavar="LAT,LON[,ELEV_M]", help="degrees north, "
                          "degrees east, metres above sea level (default 0)")
    eclipses.add_argument("--years", required=True, metavar="Y1-Y2", help="the span, e.g. 2026-2030")
    eclipses.add_argument("--utc-offset", default=None, metavar="+HH:MM", help="local time's offset from "
                          "UTC (default: the site's mean solar time)")
    eclipses.add_argument("--write", default=None, metavar="NAME.yaml", help="write a config for one of "
                          "the eclipses (not over an existing file)")
    eclipses.add_argument("--pick", type=int, default=None, metavar="N", help="with --write: the N-th "
                          "eclipse of the list (default: the greatest obscuration seen)")


DEBUG_HELP = "on an error, print the traceback too (for a bug report)"
STORE_HELP = "cache folder (default $SUNSHADE_CACHE or ./cache)"


def _shared(*flags: str, **options: Any) -> _Parser:
    """A parent parser (for ``parents=``) holding one argument shared by several commands."""
    parent = _Parser(add_help=False)
    parent.add_argument(*flags, **options)
    return parent


if __name__ == "__main__":
    sys.exit(main())
