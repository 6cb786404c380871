"""The library's functions (docs/api.md): each takes a config as a file, a mapping or a ``Config``
and raises a ``SunshadeError`` whose text is the one line the command prints. numpy and the
stages are imported inside the functions, so that importing the API (and the command) stays cheap.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import numbers
import os
import re
import weakref
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline import __version__
from pipeline.config.settings import Config
from pipeline.config.vocabulary import PASSES
from pipeline.core.errors import BadInput, RunError, SunshadeError
from pipeline.core.paths import shown

if TYPE_CHECKING:
    import numpy as np

    from pipeline.cache.store import Cache
    from pipeline.run.record import RunSummary
    from pipeline.sky.ephemeris import Circumstances
    from pipeline.stages.frame import FrameResult

__all__ = ["ConfigLike", "Frame", "Ground", "load_config", "render_frame", "render_run", "ground_irradiance",
           "eclipse", "check_jobs"]

ConfigLike = Config | str | os.PathLike[str] | Mapping[str, Any]
"""What every function takes as its config: a YAML file, a mapping (what the file would hold) or a
``Config`` (``load_config``'s)."""

MAPPING_NAME = "config (a mapping)"
"""What an error calls a config given as a mapping, in place of the file it is parsed as if read
from (``base_dir/config.yaml``, which need not exist; docs/api.md, "Errors")."""

_from_mappings: weakref.WeakValueDictionary[int, Config] = weakref.WeakValueDictionary()
# the Configs load_config made of a mapping, by id: their errors too say MAPPING_NAME


def load_config(source: ConfigLike, *, base_dir: str | os.PathLike[str] | None = None,
                named_frames: bool = True, resolved: bool = True) -> Config:
    """A config read, validated and resolved, as every command reads it.

    Parameters
    ----------
    source : str, os.PathLike, mapping or Config
        A YAML file; or a mapping of what such a file holds; a ``Config`` is returned as it is.
    base_dir : str or os.PathLike, optional
        For a mapping, the folder its file paths are relative to (default: the current folder).
    named_frames : bool, default True
        False where no named frames are written (one frame, the ground): an ``output.name`` that is
        no valid name then takes the default.
    resolved : bool, default True
        Check the compute limits and the sun's path, and look up ``turbidity: auto``
        (``stages.resolve.resolve``).

    Returns
    -------
    settings.Config
        The frozen config; ``Config.digest()`` is its hash.

    Raises
    ------
    SunshadeError
        A ``ConfigError`` naming the file, the key and its line, as ``sunshade check`` prints it.
    """
    from pipeline.config.parse import load_config as load_file
    from pipeline.config.parse import parse_config

    if isinstance(source, Config):
        return source
    if not isinstance(source, (Mapping, str, os.PathLike)):
        raise BadInput(f"config: {_shown(source)} is not a config: give a YAML file, a mapping or a Config")
    with _naming(source, base_dir):
        if isinstance(source, Mapping):
            config = parse_config(dict(source), _mapping_file(base_dir).parent, named_frames=named_frames)
        else:
            config = load_file(source, named_frames=named_frames)
        if resolved:
            from pipeline.stages.resolve import resolve

            config = resolve(config)
    if isinstance(source, Mapping):
        _from_mappings[id(config)] = config
    return config


def _shown(value: object) -> str:
    """``repr(value)`` as a message shows it, cut in the middle if long (``paths.shown``)."""
    return shown(repr(value))


def _mapping_file(base_dir: str | os.PathLike[str] | None) -> Path:
    """The file a mapping is parsed as if read from: ``base_dir/config.yaml``, absolute."""
    if base_dir is not None and not isinstance(base_dir, (str, os.PathLike)):
        raise BadInput(f"base_dir: {_shown(base_dir)} is not a folder")
    return Path(base_dir if base_dir is not None else Path.cwd()).absolute() / "config.yaml"


@contextlib.contextmanager
def _naming(source: object, base_dir: str | os.PathLike[str] | None = None) -> Iterator[None]:
    """Errors raised inside call a config given as a mapping (or a ``Config`` made of one)
    MAPPING_NAME instead of the file it was parsed as if read from, which does not exist."""
    if isinstance(source, Mapping):
        file = _mapping_file(base_dir)
        made_up = {str(file), str(file.resolve())}
    elif isinstance(source, Config) and _from_mappings.get(id(source)) is source:
        made_up = {str(source.path)}
    else:
        yield
        return
    try:
        yield
    except SunshadeError as error:
        names = "|".join(re.escape(name) for name in sorted(made_up, key=len, reverse=True))
        said = re.compile(rf"(?<![^\s(])(?:{names})(?=[\s:),]|$)")  # the whole path, not a part of one
        renamed = copy.copy(error)  # its class and attributes (SunshadeError pickles as it was)
        renamed.args = tuple(said.sub(MAPPING_NAME, a) if isinstance(a, str) else a for a in error.args)
        if renamed.args == error.args:
            raise
        if isinstance(where := getattr(error, "where", None), str):
            renamed.where = said.sub(MAPPING_NAME, where)  # type: ignore[attr-defined]
        raise renamed.with_traceback(error.__traceback__) from None


def _whole(value: object) -> bool:
    """Whether ``value`` is a whole number: an int or a numpy integer, not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _count(name: str, value: object) -> int | None:
    """``value`` (None, or a count from the caller: jobs, threads) checked to be at least 1."""
    if value is None:
        return None
    if not _whole(value):
        raise BadInput(f"{name} must be a whole number, at least 1 (got {_shown(value)})")
    if value < 1:  # type: ignore[operator]
        raise BadInput(f"{name} must be at least 1 (got {value})")
    return int(value)  # type: ignore[call-overload]


def _frame_number(frame: object, config: Config) -> int:
    """An output frame from the caller, checked: an int in 0..animation.frames-1 (the words of
    the commands' ``--frame``)."""
    count = config.animation.frames
    if not _whole(frame):
        raise BadInput(f"--frame {_shown(frame)} is not a frame: give an int in 0..{count - 1}")
    if not 0 <= frame < count:  # type: ignore[operator]
        raise BadInput(f"--frame {frame} is outside 0..{count - 1} (animation.frames is {count})")
    return int(frame)  # type: ignore[call-overload]


def _frames_chosen(frames: object, config: Config) -> tuple[int, ...] | None:
    """The output frames a caller chose (None: all), sorted, each once: ints, or text like
    ``0-47,100`` as ``sunshade render --frames`` takes it, in the command's words."""
    from pipeline.run.folder import parse_frames

    count = config.animation.frames
    if frames is None:
        return None
    if isinstance(frames, str):
        return parse_frames(frames, count)
    try:
        if isinstance(frames, (bytes, bytearray)):
            raise TypeError
        given = list(frames)  # type: ignore[call-overload]
    except TypeError:
        raise RunError(f"--frames: {_shown(frames)} is not a list of frames: give ints or text like "
                       "'0-47,100'") from None
    for frame in given:
        if not _whole(frame):
            raise RunError(f"--frames: {_shown(frame)} is not a frame: give ints in 0..{count - 1}")
        if not 0 <= frame < count:
            raise RunError(f"--frames: {frame} is outside 0..{count - 1} (animation.frames is {count})")
    if not given:
        raise RunError("--frames: no frames given (None renders them all)")
    return tuple(sorted({int(frame) for frame in given}))


def _cache(cache: Cache | str | os.PathLike[str] | None) -> Cache:
    """The cache store of ``cache``: a store, a folder, or None for $SUNSHADE_CACHE or ./cache."""
    from pipeline.cache.store import Cache, cache_dir

    if isinstance(cache, Cache):
        return cache
    root = cache_dir(str(cache) if cache is not None else None)
    if root.exists() and not root.is_dir():
        raise BadInput(f"the cache folder {root}: is a file, not a folder")
    return Cache(root)


@dataclass(frozen=True)
class Frame:
    """A finished frame as arrays, as its EXR holds them: the RGB ones in ``output.colorspace``.

    Attributes
    ----------
    beauty : numpy.ndarray
        (rows, cols, 3) float32 radiance [kcd/m^2].
    sun, sky : numpy.ndarray or None
        (rows, cols, 3) float32 radiance lit by the sun, by the sky; they sum to ``beauty``
        [kcd/m^2] (docs/runs.md, "Light passes").
    lux : numpy.ndarray or None
        (rows, cols) float32 horizontal illuminance of the ground seen, 0 at the sky [lx].
    alpha : numpy.ndarray or None
        (rows, cols) float32 coverage of the foreground [1].
    depth : numpy.ndarray or None
        (rows, cols) float32 distance along the ray to the ground, inf at the sky [m].
    metadata : dict
        The EXR's attributes (``run.contents.frame_attributes``): the config's hash, S, the
        exposure, the sun and moon, the time; with passes the standard ones.
    sun_fraction : float
        S, the visible fraction of the sun [1].
    exposure : float
        The exposure [m^2/kcd].
    config : settings.Config
        The config it was rendered with (its ``output.passes`` those of the frame).
    result : stages.frame.FrameResult
        The frame stage's result, in the renderer's scene-linear Rec.709.
    """

    beauty: np.ndarray
    sun: np.ndarray | None
    sky: np.ndarray | None
    lux: np.ndarray | None
    alpha: np.ndarray | None
    depth: np.ndarray | None
    metadata: dict[str, Any]
    sun_fraction: float
    exposure: float
    config: Config
    result: FrameResult

    def picture(self) -> np.ndarray:
        """What the frame's PNG shows: exposed and white-balanced in scene-linear, then through
        ``camera.display``'s curve or ``output.view``'s OpenColorIO view.

        Returns
        -------
        numpy.ndarray
            (rows, cols, 3) uint8 codes, or float32 display values in [0, 1] (an OCIO view) [1].
        """
        from pipeline.run.contents import frame_picture

        return frame_picture(self.config, self.result)

    def write_exr(self, path: str | os.PathLike[str], *, half: bool = False) -> None:
        """Write the frame as ``sunshade frame -o FILE.exr`` does: beauty, passes and metadata.

        Parameters
        ----------
        path : str or os.PathLike
            The EXR file.
        half : bool, default False
            Half floats for the beauty and the RGB passes.
        """
        from pipeline.core import io
        from pipeline.run.contents import exr_layers

        io.write_exr(path, self.beauty, self.metadata, half=half,
                     layers=exr_layers(self.result, half, self.config.output))

    def write_png(self, path: str | os.PathLike[str]) -> None:
        """Write the frame's picture (``picture``) as ``sunshade frame -o FILE.png`` does.

        Parameters
        ----------
        path : str or os.PathLike
            The PNG file.
        """
        from pipeline.core import io

        io.write_png(path, self.picture())


def render_frame(config: ConfigLike, frame: int = 0, *, passes: Iterable[str] | str | None = None,
                 cache: Cache | str | os.PathLike[str] | None = None, threads: int | None = None) -> Frame:
    """Render one finished frame into arrays (``sunshade frame``).

    Parameters
    ----------
    config : str, os.PathLike, mapping or Config
        The config (``load_config``).
    frame : int, default 0
        The output frame, 0..animation.frames-1: the sun, moon and clouds of that moment, the
        canopy at frame mod cycle.
    passes : iterable of str, or str, optional
        The light passes to make, names in ``vocabulary.PASSES`` or text like ``sun,sky`` as
        ``--passes`` takes it (default: all of them, none with a ``ground.brdf``).
    cache : Cache, str or os.PathLike, optional
        The cache of the cycle products (default $SUNSHADE_CACHE, else ./cache).
    threads : int, optional
        FFT threads, at least 1 (default: all cores).

    Returns
    -------
    Frame
        The frame's arrays and metadata.

    Raises
    ------
    SunshadeError
        A bad config, frame, pass or input file, in the command's words.
    """
    import numpy as np

    from pipeline.run.contents import frame_attributes, in_working_space
    from pipeline.stages.frame import render_frame as frame_stage
    from pipeline.stages.plan import check_inputs

    with _naming(config):
        config = load_config(config, named_frames=False)
        config = dataclasses.replace(config, output=dataclasses.replace(
            config.output, passes=_passes_wanted(passes, config)))
        frame = _frame_number(frame, config)
        threads = _count("--threads", threads)
        plan = check_inputs(config)  # every input read and checked before anything is computed
        result = frame_stage(plan, frame, store=_cache(cache), workers=threads, passes=config.output.passes)
        if not np.all(np.isfinite(result.radiance)):
            raise BadInput(f"{config.path}: the frame overflowed; lower the sky's radiance")
    layers = {name: in_working_space(config.output, pixels) for name, pixels in result.layers.items()}

    def single(name: str) -> np.ndarray | None:
        return layers[name][..., 0] if name in layers else None

    return Frame(in_working_space(config.output, result.radiance), layers.get("sun"), layers.get("sky"),
                 single("illuminance"), single("alpha"), single("depth"),
                 frame_attributes(config, result, config.digest()), float(result.sun_fraction),
                 float(result.exposure), config, result)


def _passes_wanted(passes: object, config: Config) -> tuple[str, ...]:
    """The light passes a caller asked for (None: all, none with a ``ground.brdf``), names or
    text like ``sun,sky`` as ``sunshade frame --passes`` takes it, in ``PASSES``' order."""
    if passes is None:
        return PASSES if config.ground.brdf is None else ()
    if isinstance(passes, str):
        passes = [name.strip() for name in passes.split(",") if name.strip()]
    try:
        if isinstance(passes, (bytes, bytearray)):
            raise TypeError
        given = list(passes)  # type: ignore[call-overload]
    except TypeError:
        raise BadInput(f"--passes: {_shown(passes)} is not a list of pass names; valid: {', '.join(PASSES)}") \
            from None
    for name in given:
        if not isinstance(name, str) or name not in PASSES:
            raise BadInput(f"--passes: unknown pass {_shown(name)}; valid: {', '.join(PASSES)}")
    if given and config.ground.brdf is not None:
        raise BadInput(f"--passes: the light passes are not made with a ground.brdf yet ({config.path})")
    return tuple(name for name in PASSES if name in given)


def render_run(config: ConfigLike, folder: str | os.PathLike[str] | None = None, *,
               frames: Iterable[int] | str | None = None, progress: Callable[[str, int, int], None] | None = None,
               cache: Cache | str | os.PathLike[str] | None = None, jobs: int | None = None,
               force: bool = False) -> RunSummary:
    """Render a config's animation into a folder, resumably (``sunshade render``).

    Parameters
    ----------
    config : str, os.PathLike, mapping or Config
        The config (``load_config``).
    folder : str or os.PathLike, optional
        The output folder (default ``output.folder``).
    frames : iterable of int, or str, optional
        The output frames to render (default: all), ints or text like ``0-47,100`` as ``--frames``
        takes it; the video is made once all are done.
    progress : callable, optional
        Called as ``progress(stage, done, total)``, stage ``cycle``, ``frames`` or ``video``; a
        stage's first call counts what is done already (cycle products found in the cache), so a
        run whose products are all cached says ``cycle N N`` once (docs/api.md, "Progress").
    cache : Cache, str or os.PathLike, optional
        The cache of the cycle products (default $SUNSHADE_CACHE, else ./cache).
    jobs : int, optional
        Processes at once, 1 to 4 a core (default ``render.jobs``, else one per core).
    force : bool, default False
        Render the frames done already too.

    Returns
    -------
    run.record.RunSummary
        The frames rendered and skipped, the video, the timings [s].

    Raises
    ------
    SunshadeError
        A bad config or folder, or a run that cannot go on, in the command's words.
    """
    from pipeline.run.folder import check_outputs
    from pipeline.run.render import render_run as run
    from pipeline.stages.resolve import resolve, source_digest

    with _naming(config):
        written = load_config(config, resolved=False)
        if folder is not None:
            if not isinstance(folder, (str, os.PathLike)):
                raise BadInput(f"--output: {_shown(folder)} is not a folder")
            written = dataclasses.replace(written, output=dataclasses.replace(
                written.output, folder=Path(folder).expanduser().absolute()))
        jobs = _count("--jobs", jobs)
        check_jobs(jobs, written)
        chosen = _frames_chosen(frames, written)
        if progress is not None and not callable(progress):
            raise BadInput(f"progress: {_shown(progress)} is not callable: give a function of (stage, done, total)")
        check_outputs(written)
        source_hash = source_digest(written)
        return run(resolve(written), frames=chosen, store=_cache(cache), jobs=jobs, force=bool(force),
                   progress=progress, source_hash=source_hash)


def check_jobs(jobs: int | None, config: Config) -> None:
    """Refuse more processes at once than a local run may start (here and ``sunshade render``).

    Parameters
    ----------
    jobs : int or None
        The processes asked for; None: ``render.jobs`` of ``config``, else one per core.
    config : Config
        The run's config.

    Raises
    ------
    BadInput
        Naming --jobs or the config's key, over MAX_JOBS_PER_CORE a core.
    """
    from pipeline.core.cores import MAX_JOBS_PER_CORE, default_workers

    count, most = jobs or config.render.jobs, MAX_JOBS_PER_CORE * default_workers()
    if count and count > most:
        raise BadInput(f"{'--jobs' if jobs else config.where('render.jobs')} {count} would start {count} "
                       f"processes on {default_workers()} cores; the most is {most} ({MAX_JOBS_PER_CORE} a core)")


@dataclass(frozen=True)
class Ground:
    """The ground's irradiance under a config's canopy and sky at one frame (``sunshade ground``).

    Attributes
    ----------
    irradiance : numpy.ndarray
        (rows, cols, 3) float32 horizontal irradiance, north up [klx for a sky in kcd/m^2].
    extent : tuple of float
        (x0, y0, x1, y1) of the raster [m].
    pixel : float
        Its pixel size [m].
    unshadowed : numpy.ndarray
        (3,) the open sky's and sun's irradiance [klx].
    exact : bool
        Whether the sky square spans the canopy from every ground point (else light from beyond it
        was taken as unshadowed).
    metadata : dict
        The EXR's attributes (window, pixel size, the config's hash, version, frame).
    """

    irradiance: np.ndarray
    extent: tuple[float, float, float, float]
    pixel: float
    unshadowed: np.ndarray
    exact: bool
    metadata: dict[str, Any]


def ground_irradiance(config: ConfigLike, frame: int = 0, *, cache: Cache | str | os.PathLike[str] | None = None,
                      threads: int | None = None) -> Ground:
    """The ground's irradiance under the config's canopy masks and sky at one frame.

    Parameters
    ----------
    config : str, os.PathLike, mapping or Config
        The config (``load_config``).
    frame : int, default 0
        The output frame, 0..animation.frames-1.
    cache : Cache, str or os.PathLike, optional
        The cache of the cycle products (default $SUNSHADE_CACHE, else ./cache).
    threads : int, optional
        FFT threads (default: all cores).

    Returns
    -------
    Ground
        The irradiance on the sun window's grid (the window's without a sun) and its metadata.

    Raises
    ------
    SunshadeError
        A bad config, frame or input file, in the command's words.
    """
    import numpy as np

    from pipeline.stages.ground import render_ground
    from pipeline.stages.plan import plan_run

    with _naming(config):
        config = load_config(config, named_frames=False)
        frame = _frame_number(frame, config)
        threads = _count("--threads", threads)
        plan = plan_run(config)
        if plan.receivers.slope is not None:  # its light in its (u, w) metres (docs/method.md, "A sloped ground")
            from pipeline.stages.ground import FrameContext
            from pipeline.stages.slope import slope_ground

            result = slope_ground(FrameContext.of(plan, frame, store=_cache(cache), workers=threads))
        else:
            result = render_ground(plan, frame, store=_cache(cache), workers=threads)
        if not np.all(np.isfinite(result.irradiance)):
            raise BadInput(f"{config.path}: the ground irradiance overflowed; lower the sky's radiance")
    metadata = {"sunshade:window": result.grid.extent, "sunshade:pixel_size": float(result.grid.pixel),
                "sunshade:config_hash": config.digest(), "sunshade:version": __version__,
                "sunshade:frame": int(frame)}
    return Ground(result.irradiance, result.grid.extent, float(result.grid.pixel), result.unshadowed,
                  bool(result.exact), metadata)


def eclipse(latitude: float, longitude: float, start: datetime | str, end: datetime | str, *,
            elevation: float = 0.0) -> Circumstances:
    """The solar eclipse nearest a span of time, seen from a site: its contacts and maximum.

    Parameters
    ----------
    latitude, longitude : float
        The site, north and east positive [deg].
    start, end : datetime.datetime or str
        The span, aware datetimes or ISO 8601 text (without a zone: UTC).
    elevation : float, default 0
        The site's height above sea level [m].

    Returns
    -------
    sky.ephemeris.Circumstances
        ``contacts`` (C1..C4: aware UTC datetimes or None), ``maximum``, ``obscuration`` [1],
        ``kind`` ('total', 'annular', 'partial' or None) and ``central`` (C3 - C2) [s].

    Raises
    ------
    SunshadeError
        A site or time that cannot be, in one line.
    """
    from pipeline.sky.ephemeris import Site, circumstances

    def moment(value: datetime | str, name: str) -> datetime:
        if isinstance(value, str):
            try:
                value = datetime.fromisoformat(value)
            except ValueError:
                raise BadInput(f"{name}: not an ISO 8601 time: {value!r}") from None
        return value if value.tzinfo is not None else value.replace(tzinfo=UTC)

    begin, finish = moment(start, "start"), moment(end, "end")
    if not finish > begin:
        raise BadInput(f"end {finish.isoformat()} must be after start {begin.isoformat()}")
    for name, value, most in (("latitude", latitude, 90.0), ("longitude", longitude, 360.0)):
        if not -most <= value <= most:
            raise BadInput(f"{name} must be within -{most:g}..{most:g} degrees (got {value})")
    if not abs(elevation) < 1e5:
        raise BadInput(f"elevation must be within -1e5..1e5 m (got {elevation})")
    return circumstances(Site.from_degrees(latitude, longitude, elevation), begin, finish)
