"""The errors sunshade reports in one line (exit code 2), and how they cross process boundaries.

Each error's text is the whole line shown to the user. Every one pickles and unpickles as it
was (a worker process sends it back to the run), and ``portable`` makes any other failure of a
worker task come back as a WorkerError rather than break the process pool (docs/runs.md).
"""

from __future__ import annotations

import functools
import os
import pickle
import sys
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import ParamSpec, TypeVar

from pipeline.core.paths import SHOWN_MAX, shown

__all__ = ["LINE_MAX", "SunshadeError", "ConfigError", "ImageError", "RunError", "BadInput", "WorkerError",
           "one_line", "one_line_warnings", "portable"]

_Parameters = ParamSpec("_Parameters")
_Result = TypeVar("_Result")

LINE_MAX = 1000
"""Longest line an error or warning shows; past it the line is cut in the middle. [character]"""


class SunshadeError(Exception):
    """Bad input, or a run that cannot go on: ``str(error)`` is the one line to show.

    It pickles and unpickles as it was, its attributes included, so that a worker process can send
    it back to the run (docs/runs.md).
    """

    def __reduce__(self):
        return _rebuild, (type(self), self.args, dict(self.__dict__))


def _rebuild(cls, args, state):
    error = cls.__new__(cls, *args)
    error.args = args
    error.__dict__.update(state)
    return error


class ConfigError(SunshadeError, ValueError):
    """A bad configuration.

    Parameters
    ----------
    where : str
        Where in the config: 'file:line: key.path' or 'file: key.path'; kept as ``where``.
    message : str
        What is wrong, in words; the error's line is ``f"{where}: {message}"``.
    """

    def __init__(self, where: str, message: str):
        super().__init__(f"{where}: {message}")
        self.where = where


class ImageError(SunshadeError, ValueError):
    """An image that cannot be read or written.

    Parameters
    ----------
    path : str or os.PathLike
        The file; kept as ``path`` (a ``pathlib.Path``).
    message : str
        What is wrong with it; the error's line is ``f"{path}: {message}"``.
    """

    def __init__(self, path: str | os.PathLike[str], message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = Path(path)


class RunError(SunshadeError):
    """A run that cannot start or go on: a bad frame list, a busy or unwritable folder, no
    scheduler, a lost cluster."""


class BadInput(SunshadeError):
    """Bad input found by the command itself: a flag, a path."""


class WorkerError(Exception):
    """An unexpected failure in a worker process whose exception could not be sent back as it was.

    Parameters
    ----------
    message : str
        Its type and message, ``"TypeName: message"``: ``str(error)``.
    details : str, optional
        The worker's traceback as text; kept as ``details``.
    """

    def __init__(self, message: str, details: str = ""):
        super().__init__(message, details)
        self.details = details

    def __str__(self):
        return self.args[0]


def one_line(text: str) -> str:
    """``text`` as one line for the user.

    White space is folded, every word (a path, a name) over SHOWN_MAX characters and the whole line
    over LINE_MAX cut in the middle with its length (``paths.shown``), so that no input can make a
    message long.

    Parameters
    ----------
    text : object
        The message (anything ``str`` takes).

    Returns
    -------
    str
        One line of at most about LINE_MAX characters.
    """
    words = [shown(word) if len(word) > SHOWN_MAX else word for word in str(text).split()]
    return shown(" ".join(words), LINE_MAX)


def one_line_warnings() -> None:
    """Show warnings in this process as one line each, ``sunshade: warning: ...``.

    Without the source line Python adds, on standard error (also where a caller records warnings).
    """
    warnings.formatwarning = lambda message, *_, **__: f"sunshade: warning: {one_line(message)}\n"
    warnings.showwarning = _show_warning


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"sunshade: warning: {one_line(message)}", file=file or sys.stderr)


def portable(task: Callable[_Parameters, _Result]) -> Callable[_Parameters, _Result]:
    """``task`` made safe to run in another process.

    An exception that does not survive pickling is raised as a WorkerError (its type, message and
    traceback as text) instead, so the run reports it as it would have in one process. The wrapper
    also makes the worker show warnings in one line (``one_line_warnings``).

    Parameters
    ----------
    task : callable
        The function a worker process runs.

    Returns
    -------
    callable
        ``task`` wrapped, with its name and docstring (``functools.wraps``).
    """

    @functools.wraps(task)
    def run(*args: _Parameters.args, **kwargs: _Parameters.kwargs) -> _Result:
        one_line_warnings()
        try:
            return task(*args, **kwargs)
        except Exception as exc:
            try:
                pickle.loads(pickle.dumps(exc))
            except Exception:
                failure = WorkerError(f"{type(exc).__name__}: {exc}", traceback.format_exc())
            else:
                raise
        # raised outside the handler, so it carries no __context__: tblib (which Dask installs)
        # pickles an exception's context too, and this one's would not pickle
        raise failure

    return run
