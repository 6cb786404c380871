"""The run folder: the names of its files (the frames, the video, index.json, run.json, the lock),
and the folder made, checked and cleaned before and after a render (docs/runs.md, "The run folder").

Nothing here imports numpy or a stage, so that a resume with nothing to do is decided in a
fraction of a second (``record.nothing_to_do``).
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

from pipeline.config.settings import Config
from pipeline.core import paths
from pipeline.core.errors import RunError

__all__ = ["RUN_FILE", "INDEX_FILE", "LOCK_FILE", "parse_frames", "frame_files", "video_file", "make_folder",
           "check_folder", "missing_folders", "remove_own_folders", "check_outputs", "remove_temporaries"]

RUN_FILE = "run.json"
"""The run's record in its folder (docs/runs.md, "The run folder")."""
INDEX_FILE = "index.json"
"""The done frames' record, written as each frame is done."""
LOCK_FILE = ".sunshade.lock"
"""The lock a run holds on its folder."""


def parse_frames(text: str, count: int) -> tuple[int, ...]:
    """Frame indices from a list like ``0-47,100`` (ranges inclusive), sorted and unique.

    Parameters
    ----------
    text : str
        The list (--frames).
    count : int
        Frames in the animation; every index must lie in 0..count-1.

    Returns
    -------
    tuple of int
        The frames, sorted, each once.

    Raises
    ------
    RunError
        Naming the bad part.
    """
    frames: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part[1:]:
                first, last = (int(v) for v in part.split("-", 1) if v.strip())
            else:
                first = last = int(part)
        except ValueError:
            raise RunError(f"--frames: {part!r} is not a frame or a range like 0-47") from None
        if last < first:
            raise RunError(f"--frames: the range {part} runs backwards")
        if first < 0 or last >= count:
            raise RunError(f"--frames: {part} is outside 0..{count - 1} (animation.frames is {count})")
        frames.update(range(first, last + 1))
    return tuple(sorted(frames))


def frame_files(config: Config, frame: int) -> tuple[Path, Path]:
    """(EXR, PNG) paths of an output frame: ``NAME.0007.exr``.

    The number is zero-padded to four digits or to the width of the last frame's number.

    Parameters
    ----------
    config : settings.Config
        The run's config.
    frame : int
        The frame's index.

    Returns
    -------
    tuple of (pathlib.Path, pathlib.Path)
        The EXR's and the PNG's paths in ``output.folder``.
    """
    width = max(4, len(str(config.animation.frames - 1)))
    stem = f"{config.output.name}.{frame:0{width}d}"
    return config.output.folder / f"{stem}.exr", config.output.folder / f"{stem}.png"


def video_file(config: Config) -> Path | None:
    """The run's video file.

    Parameters
    ----------
    config : settings.Config
        The run's config.

    Returns
    -------
    pathlib.Path or None
        ``NAME.VIDEO`` (``output.video`` the suffix) in ``output.folder``, or None when ``output.video`` is none.
    """
    if config.output.video == "none":
        return None
    return config.output.folder / f"{config.output.name}.{config.output.video}"


def make_folder(folder: Path) -> tuple[Path, ...]:
    """Create the output folder (and its parents), saying which of them this call made.

    Each missing folder is made with ``mkdir`` that fails if it exists, outermost first, so that of
    two processes making the same new folder at once exactly one counts it as its own; only a
    process's own folders are ever removed by it (``remove_own_folders``).

    Parameters
    ----------
    folder : pathlib.Path
        The output folder to create.

    Returns
    -------
    tuple of pathlib.Path
        The folders this call created, innermost first (empty when ``folder`` existed).

    Raises
    ------
    RunError
        If it cannot be written (what this call made is removed again).
    """
    made: list[Path] = []
    try:
        for missing in reversed(missing_folders(folder)):
            try:
                missing.mkdir()
            except FileExistsError:
                continue  # another process made it: not ours
            made.insert(0, missing)
        probe = folder / f".probe-{os.getpid()}-{os.urandom(4).hex()}"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        remove_own_folders(tuple(made), lock_held=False)
        raise RunError(f"{folder}: cannot write the output folder ({exc.strerror or exc})") from None
    return tuple(made)


def check_folder(folder: Path) -> None:
    """Raise RunError unless ``folder`` could be created and written, touching nothing.

    The nearest folder that exists must be a writable folder.

    Parameters
    ----------
    folder : pathlib.Path
        The output folder.
    """
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise RunError(f"{folder}: is a file, not a folder" if existing == folder
                       else f"{folder}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise RunError(f"{folder}: cannot write the output folder ({existing} is not writable)")


def missing_folders(folder: Path) -> list[Path]:
    """``folder`` and those of its parents that do not exist yet, innermost first.

    Parameters
    ----------
    folder : pathlib.Path
        The output folder, which may not exist yet.

    Returns
    -------
    list of pathlib.Path
        The folders a run would create.
    """
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def remove_own_folders(folders: tuple[Path, ...], *, lock_held: bool) -> None:
    """Remove the folders that this process made (``make_folder``) and a failed run left empty.

    So that a failing run leaves nothing of its own behind, and never touches what another process
    holds or made: the lock file is removed only by the process that holds the lock (before it lets
    go), and a folder only while it is empty.

    Parameters
    ----------
    folders : tuple of pathlib.Path
        The folders this process made, innermost first (``make_folder``).
    lock_held : bool
        Whether this process holds the output folder's lock (the innermost folder's).
    """
    for folder in folders:
        with contextlib.suppress(OSError):
            if lock_held:
                (folder / LOCK_FILE).unlink(missing_ok=True)
            folder.rmdir()


def check_outputs(config: Config) -> None:
    """Raise RunError unless the run's files could be written, touching nothing.

    The folder (``check_folder``), every name within the system's limits (``paths.problem``), and no
    frame, video, lock or run.json name taken by a folder.

    Parameters
    ----------
    config : settings.Config
        The run's config.
    """
    folder = config.output.folder
    if problem := paths.problem(folder):
        raise RunError(f"{folder}: {problem}")
    check_folder(folder)
    video = video_file(config)
    names = {RUN_FILE, LOCK_FILE} | ({video.name} if video is not None else set())
    for path in (*frame_files(config, config.animation.frames - 1), *(folder / n for n in names)):
        if problem := paths.problem(path):
            raise RunError(f"{path}: {problem}")
    if folder.is_dir():
        frame = re.compile(rf"{re.escape(config.output.name)}\.\d+\.(exr|png)")
        for entry in os.scandir(folder):
            if (entry.name in names or frame.fullmatch(entry.name)) and entry.is_dir():
                raise RunError(f"{entry.path}: is a folder where the run writes a file; move it")


def remove_temporaries(folder: Path) -> None:
    """Remove the half-written files a killed run left (we hold the folder's lock).

    Parameters
    ----------
    folder : pathlib.Path
        The run folder.
    """
    for path in folder.glob(".*.tmp-*"):
        path.unlink(missing_ok=True)
