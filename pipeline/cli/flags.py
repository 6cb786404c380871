"""The flags several ``sunshade`` commands share, checked before any work: paths, the cache folder and its
budget, the output file, the config read, frame numbers, threads and light passes. Each check raises BadInput
with one line naming the flag (docs/runs.md, "Errors")."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from pipeline.config.vocabulary import PASSES
from pipeline.core import paths
from pipeline.core.errors import BadInput

if TYPE_CHECKING:
    import argparse
    from collections.abc import Sequence

    from pipeline.cache.store import Cache
    from pipeline.config.settings import Config

__all__ = ["OUTPUT_SUFFIXES", "flag_path", "open_store", "budget_flag", "checked_output", "config_of", "check_threads",
           "check_frame", "passes_flag"]


OUTPUT_SUFFIXES = (".png", ".exr")
"""What ``-o`` may name: a display-referred PNG or a scene-linear EXR."""


def flag_path(flag: str, value: str | os.PathLike[str]) -> Path:
    """The path a flag (or an environment variable) gives, checked by ``paths.problem``;
    raises BadInput naming the flag.

    Parameters
    ----------
    flag : str
        The flag or variable, as the error names it.
    value : str or os.PathLike
        The path it gives.

    Returns
    -------
    pathlib.Path
        The path.
    """
    if problem := paths.problem(value):
        raise BadInput(f"{flag} {paths.shown(value)}: {problem}")
    return Path(value)


def open_store(explicit: str | None, *, writing: bool = True) -> Cache:
    """The cache at --cache, else $SUNSHADE_CACHE, else ./cache, its path checked first, and
    (``writing``) that it can be written, before any work (docs/runs.md, "Errors").

    Parameters
    ----------
    explicit : str or None
        The --cache flag's folder.
    writing : bool
        Check that the folder can be written.

    Returns
    -------
    Cache
        The cache.
    """
    from pipeline.cache.store import ENV_VAR, Cache, cache_dir

    flag, value = ("--cache", explicit) if explicit else (f"${ENV_VAR}", os.environ.get(ENV_VAR))
    if value:
        flag_path(flag, value)
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


def budget_flag(args: argparse.Namespace) -> int:
    """The cache's budget of --cache-size, else $SUNSHADE_CACHE_SIZE, else 20 GiB [B]; raises
    BadInput naming the flag or variable.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed (its ``cache_size``).

    Returns
    -------
    int
        The budget [B].
    """
    from pipeline.cache.store import BUDGET_ENV_VAR, cache_budget

    try:
        return cache_budget(args.cache_size)
    except ValueError as exc:
        raise BadInput(f"{'--cache-size' if args.cache_size is not None else '$' + BUDGET_ENV_VAR}: {exc}") from None


def checked_output(path: str, suffixes: tuple[str, ...] = OUTPUT_SUFFIXES) -> Path:
    """The output file of -o: one of ``suffixes``, not a folder, in a folder that can be written; raises BadInput
    naming it.

    Parameters
    ----------
    path : str
        The flag's value.
    suffixes : tuple of str
        The file name endings it may have.

    Returns
    -------
    pathlib.Path
        The output file.
    """
    out = flag_path("--output", path)
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


def config_of(args: argparse.Namespace, *, named_frames: bool = True, resolved: bool = True) -> Config:
    """The config of ``args.config`` read, validated and (``resolved``) resolved: every
    command's one loader (``named_frames``: see parse.load_config).

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed (its ``config``).
    named_frames : bool
        Passed to ``parse.load_config``.
    resolved : bool
        Resolve it (``resolve.resolve``).

    Returns
    -------
    Config
        The config.
    """
    from pipeline.api import load_config

    return load_config(args.config, named_frames=named_frames, resolved=resolved)


def check_threads(args: argparse.Namespace) -> None:
    """Raises BadInput unless --threads, where given, is at least 1.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed (its ``threads``).
    """
    if args.threads is not None and args.threads < 1:
        raise BadInput(f"--threads must be at least 1 (got {args.threads})")


def check_frame(frame: int, count: int, flag: str, key: str) -> None:
    """Raises BadInput naming ``flag`` and ``key`` unless 0 <= ``frame`` < ``count``.

    Parameters
    ----------
    frame : int
        The flag's value.
    count : int
        How many there are.
    flag : str
        The flag, as the error names it.
    key : str
        What gives the count, as the error names it.
    """
    if not 0 <= frame < count:
        raise BadInput(f"{flag} {frame} is outside 0..{count - 1} ({key} is {count})")


def passes_flag(value: str | None, valid: Sequence[str]) -> tuple[str, ...] | None:
    """The pass names of a ``--passes NAMES`` flag, in ``vocabulary.PASSES``' order (None: no
    flag); an unknown name is a one-line error naming the flag.

    Parameters
    ----------
    value : str or None
        The flag's value, comma-separated names.
    valid : tuple of str
        The names this command writes.

    Returns
    -------
    tuple of str or None
        The names, or None without the flag.
    """
    if value is None:
        return None
    names = [n.strip() for n in value.split(",") if n.strip()]
    for name in names:
        if name not in valid:
            raise BadInput(f"--passes: unknown pass {name!r}; valid: {', '.join(valid)}")
    return tuple(p for p in PASSES if p in names)
