"""Paths from the config and the command line, checked in one place before any use.

``problem`` says what is wrong with a path as text (a NUL byte, a name or path longer than the
system allows, a ``~user`` that names no user), so that the caller can report it in one line
naming its key or flag (docs/runs.md, "Errors").
"""

from __future__ import annotations

import os
from pathlib import Path

NAME_MAX = 255
"""Longest file or folder name, in bytes (Linux, macOS and Windows file systems). [byte]"""
PATH_MAX = 4095
"""Longest whole path, in bytes (Linux's PATH_MAX less its NUL). [byte]"""


def problem(text) -> str | None:
    """What keeps ``text`` from being a usable path, in a few words, or None if nothing."""
    if not isinstance(text, (str, os.PathLike)):
        return f"must be a path, not {type(text).__name__}"
    text = os.fspath(text)
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
    for part in Path(expanded).parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            return f"the name {part[:24]!r}... is {size} bytes long; the most is {NAME_MAX}"
    if len(whole) > PATH_MAX:
        return f"the path is {len(whole)} bytes long; the most is {PATH_MAX}"
    return None
