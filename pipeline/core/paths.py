"""Paths from the config and the command line, checked in one place before any use.

``problem`` says what is wrong with a path as text (a NUL byte, bytes that are not UTF-8, a
name or path longer than the system allows, a ``~user`` that names no user), so that the
caller can report it in one line naming its key or flag; ``shown`` writes any path or name for
such a line (docs/runs.md, "Errors").
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["NAME_MAX", "PATH_MAX", "SHOWN_MAX", "problem", "not_a_file", "shown"]

NAME_MAX = 255
"""Longest file or folder name, in bytes (Linux, macOS and Windows file systems). [byte]"""
PATH_MAX = 4095
"""Longest whole path, in bytes (Linux's PATH_MAX less its NUL). [byte]"""
SHOWN_MAX = 120
"""Longest path or name a message shows whole; a longer one is cut in the middle. [character]"""


def problem(text: object) -> str | None:
    """What keeps ``text`` from being a usable path, in a few words, or None if nothing.

    The whole path is checked as it will be used (made absolute against the working folder):
    a folder name of bytes that are not UTF-8 (from an old archive, say) is refused here,
    since the image library takes only UTF-8 names. A ``~user`` that names no user, a NUL byte,
    a name over NAME_MAX or a path over PATH_MAX bytes are refused too.

    Parameters
    ----------
    text : object
        The path as given (a str or os.PathLike is expected; anything else is itself the problem).

    Returns
    -------
    str or None
        The problem, to follow the key or flag in a one-line message (docs/runs.md, "Errors"), or
        None when the path is usable.
    """
    if not isinstance(text, (str, os.PathLike)):
        return f"must be a path, not {type(text).__name__}"
    text = os.fspath(text)
    if isinstance(text, bytes):
        return "must be a path, not bytes"
    if "\x00" in text:
        return "contains a NUL byte"
    if not text:
        return "is empty"
    expanded = os.path.expanduser(text)
    if expanded.startswith("~"):
        return f"cannot resolve {expanded.split(os.sep)[0]!r} (no such user or home folder)"
    try:
        whole = os.fsencode(os.path.abspath(expanded))
    except UnicodeError:
        return "is not a valid file name in this system's encoding"
    try:
        whole.decode("utf-8")
    except UnicodeDecodeError as exc:
        return (f"{shown(whole)} holds a byte that is not UTF-8 (0x{whole[exc.start]:02x}); "
                "rename the file or folder")
    for part in Path(expanded).parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            return f"the name {part[:24]!r}... is {size} bytes long; the most is {NAME_MAX}"
    if len(whole) > PATH_MAX:
        return f"the path is {len(whole)} bytes long; the most is {PATH_MAX}"
    return None


def not_a_file(path: Path) -> str | None:
    """Why ``path`` cannot be read as an input file, or None for a regular file (links followed).

    Parameters
    ----------
    path : pathlib.Path
        A path that should name a regular file.

    Returns
    -------
    str or None
        "no such file", or what it is instead ("a folder", "a named pipe", "a device", "a socket",
        each "not a regular file"); None when it is a regular file.
    """
    try:
        mode = path.stat().st_mode
    except OSError:
        return "no such file"
    if stat.S_ISREG(mode):
        return None
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a device"),
             (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"))
    kind = next((name for test, name in kinds if test(mode)), "not a file")
    return f"{kind}, not a regular file"


def shown(text: str | bytes | os.PathLike[str] | os.PathLike[bytes], most: int = SHOWN_MAX) -> str:
    """``text`` (a path, a name, bytes) as a message shows it.

    Bytes that are not UTF-8 come out as ``\\xe9``, a NUL as ``\\0``, and past ``most`` characters
    the text is cut in the middle with its length: ``/a/very/lo...ng/name (4000 characters)``.

    Parameters
    ----------
    text : str, bytes or os.PathLike
        What to show.
    most : int, optional
        Longest text shown whole [character]; SHOWN_MAX by default.

    Returns
    -------
    str
        The text to put in a message.
    """
    if isinstance(text, os.PathLike):
        text = os.fspath(text)
    if isinstance(text, str):
        text = os.fsencode(text) if _encodes(text) else text.encode("utf-8", "backslashreplace")
    text = text.decode("utf-8", "backslashreplace").replace("\x00", "\\0")
    if len(text) <= most:
        return text
    half = (most - 3) // 2
    return f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


def _encodes(text: str) -> bool:
    try:
        os.fsencode(text)
        return True
    except UnicodeError:
        return False
