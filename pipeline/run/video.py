"""A run's video: encoded from the frames' PNGs once every frame of the animation is done, or
while the frames render, from the codes their workers hand back (docs/runs.md, "The video"),
tagged with the colour of the frames' display (``video_colour``).
The encoder writes under a temporary name: a run that fails or is killed leaves no video.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.config.settings import Config
from pipeline.core import io, ocio
from pipeline.core.errors import RunError
from pipeline.run.folder import frame_files, video_file
from pipeline.run.record import current_video

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Iterator

    import numpy as np

    Progress = Callable[[str, int, int], None]

__all__ = ["video_colour", "encode_video", "VideoStream"]


def video_colour(config: Config) -> str | None:
    """The colour tags of the run's MP4 (docs/runs.md, "Colour"): 'bt709' for the built-in sRGB
    curves and for an OCIO view of an sRGB or Rec.709 display; None (untagged) for other displays.

    Parameters
    ----------
    config : settings.Config
        The run's config (``output.view``, ``output.ocio_config``).

    Returns
    -------
    str or None
        The ffmpeg name of the primaries, transfer and matrix (``io.write_video``'s ``colour``).
    """
    view = config.output.view
    return ocio.video_tags(config.output.ocio_config, view[0] if view else None)


def encode_video(config: Config, digest: str, records: dict[int, dict[str, Any] | None], previous: dict[str, Any],
                 *, force: bool, progress: Progress | None, timings: dict[str, Any]) -> dict[str, Any] | None:
    """Encode the video from the PNG frames once every frame of the animation is done.

    Unless the ``previous`` run.json says the video on disk is of this config (``current_video``).

    Parameters
    ----------
    config : settings.Config
        The run's config.
    digest : str
        The config's hash.
    records : dict
        {frame: its record, None when not done}, every frame of the animation.
    previous : dict
        The previous run.json (empty when none).
    force : bool
        Make the video again even if the one on disk is current.
    progress : callable or None
        Called as ``progress("video", done, total)`` first with 0, then as each frame is read.
    timings : dict
        Receives ``video``: the encoding's seconds [s].

    Returns
    -------
    dict or None
        The video's run.json entry: ``file``, ``config_hash``, ``frames`` and ``bytes`` [B]; None when
        the config makes no video or a frame is not done yet.
    """
    path = video_file(config)
    if path is None:
        return None
    made = current_video(config, digest, previous, force=force)
    if made is not None:
        return made
    if any(record is None for record in records.values()):
        return None
    mark = time.perf_counter()
    count = config.animation.frames

    def pictures() -> Iterator[np.ndarray]:
        if progress:
            progress("video", 0, count)  # the stage's first call, as the others' (docs/api.md, "Progress")
        for frame in range(count):
            yield io.read_codes(frame_files(config, frame)[1])
            if progress:
                progress("video", frame + 1, count)

    io.write_video(path, pictures(), fps=config.animation.fps, colour=video_colour(config))
    timings["video"] = time.perf_counter() - mark
    return _video_entry(config, digest, path)


def _video_entry(config: Config, digest: str, path: Path) -> dict[str, Any]:
    """run.json's entry of the video just written at ``path``."""
    return {"file": path.name, "config_hash": digest, "frames": config.animation.frames,
            "bytes": path.stat().st_size}


class VideoStream:
    """The video encoded while the frames are rendered, when the run ends with every frame done.

    A thread hands the encoder each frame's codes in order as soon as it and every frame before
    it are done, those rendered now as their workers return them (``add``), those done before
    read from their PNGs; the same frames in the same order as ``encode_video`` reads, so the
    same bytes.

    Parameters
    ----------
    config, digest
        As ``encode_video`` takes them.
    path : pathlib.Path
        The video file.
    fresh : iterable of int
        The frames rendered now, handed over by ``add``.
    """

    def __init__(self, config: Config, digest: str, path: Path, fresh: Iterable[int]):
        self.config, self.digest, self.path, self.fresh = config, digest, path, set(fresh)
        self.arrived: dict[int, np.ndarray] = {}
        self.fed, self.aborted = 0, False
        self.error: BaseException | None = None
        self.ready = threading.Condition()
        self.thread = threading.Thread(target=self._encode, name="sunshade-video", daemon=True)
        self.thread.start()

    @classmethod
    def start(cls, config: Config, digest: str, records: dict[int, dict[str, Any] | None], todo: Iterable[int],
              previous: dict[str, Any], *, force: bool, in_process: bool) -> VideoStream | None:
        """A stream if the run makes a video and ends with every frame done, else None.

        None too when the frames render ``in_process``: the encoder is a forked process, and a fork
        while this process's FFT threads take work ends the FFT ("Work item submitted after
        shutdown": scipy's pocketfft stops its thread pool at every fork), so the video is then
        encoded after the frames (``encode_video``).

        Parameters
        ----------
        config, digest, records, previous, force
            As in ``encode_video``.
        todo : iterable of int
            The frames the run renders now.
        in_process : bool
            Whether they render in this process.

        Returns
        -------
        VideoStream or None
            The stream, its encoder started.
        """
        fresh, path = set(todo), video_file(config)
        if (in_process or path is None
                or current_video(config, digest, previous, force=force) is not None
                or any(records[f] is None and f not in fresh for f in range(config.animation.frames))):
            return None
        return cls(config, digest, path, fresh)

    def add(self, frame: int, codes: np.ndarray) -> None:
        """Hand the encoder a frame rendered now: its PNG's 8-bit codes (rows, cols, 3) [0..255]."""
        if not self.thread.is_alive():  # the encoder failed: finish() says why; keep nothing
            return
        with self.ready:
            self.arrived[frame] = codes
            self.ready.notify()

    def abort(self) -> None:
        """Stop the encoder and leave no video."""
        with self.ready:
            self.aborted = True
            self.ready.notify()
        self.thread.join()

    def finish(self, progress: Progress | None, timings: dict[str, Any]) -> dict[str, Any]:
        """Wait for the encoder, its progress said as ``video`` and its seconds [s] put in ``timings``.

        Returns the video's run.json entry, as ``encode_video``; raises what stopped the encoder.
        """
        mark, count = time.perf_counter(), self.config.animation.frames
        try:
            while self.thread.is_alive():
                if progress:
                    progress("video", self.fed, count)
                self.thread.join(0.25)
        except BaseException:  # Ctrl-C or SIGTERM while the last frames are encoded: no video left
            self.abort()
            raise
        if self.error is not None:
            raise self.error
        if progress:
            progress("video", count, count)
        timings["video"] = time.perf_counter() - mark
        return _video_entry(self.config, self.digest, self.path)

    def _pictures(self) -> Iterator[np.ndarray]:
        for frame in range(self.config.animation.frames):
            if self.aborted:  # read unlocked: a bool, set once
                raise RunError("the video was abandoned with its run")
            if frame in self.fresh:
                with self.ready:
                    while frame not in self.arrived and not self.aborted:
                        self.ready.wait()
                    if self.aborted:
                        raise RunError("the video was abandoned with its run")
                    codes = self.arrived.pop(frame)
            else:
                codes = io.read_codes(frame_files(self.config, frame)[1])
            yield codes
            self.fed = frame + 1

    def _encode(self) -> None:
        try:
            io.write_video(self.path, self._pictures(), fps=self.config.animation.fps, colour=video_colour(self.config))
        except BaseException as error:  # said by finish(), in the command's thread
            self.error = error
