"""The library's functions (docs/api.md): each takes a config as a file, a mapping or a ``Config``
and raises a ``SunshadeError`` whose text is the one line the command prints. numpy and the
stages are imported inside the functions, so that importing the API (and the command) stays cheap.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline import __version__
from pipeline.config.settings import Config
from pipeline.config.vocabulary import PASSES
from pipeline.core.errors import BadInput

if TYPE_CHECKING:
    import numpy as np

    from pipeline.cache.store import Cache
    from pipeline.run.record import RunSummary
    from pipeline.sky.ephemeris import Circumstances
    from pipeline.stages.frame import FrameResult

__all__ = ["ConfigLike", "Frame", "Ground", "load_config", "render_frame", "render_run", "ground_irradiance",
           "eclipse"]

ConfigLike = Config | str | os.PathLike[str] | Mapping[str, Any]
"""What every function takes as its config: a YAML file, a mapping (what the file would hold) or a
``Config`` (``load_config``'s)."""


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
    if isinstance(source, Mapping):
        config = parse_config(dict(source), base_dir if base_dir is not None else Path.cwd(),
                              named_frames=named_frames)
    else:
        config = load_file(source, named_frames=named_frames)
    if not resolved:
        return config
    from pipeline.stages.resolve import resolve

    return resolve(config)


def _cache(cache: Cache | str | os.PathLike[str] | None) -> Cache:
    """The cache store of ``cache``: a store, a folder, or None for $SUNSHADE_CACHE or ./cache."""
    from pipeline.cache.store import Cache, cache_dir

    if isinstance(cache, Cache):
        return cache
    root = cache_dir(str(cache) if cache is not None else None)
    if root.exists() and not root.is_dir():
        raise BadInput(f"the cache folder {root}: is a file, not a folder")
    return Cache(root)


def _check_frame(frame: int, config: Config) -> None:
    count = config.animation.frames
    if not 0 <= frame < count:
        raise BadInput(f"--frame {frame} is outside 0..{count - 1} (animation.frames is {count})")


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


def render_frame(config: ConfigLike, frame: int = 0, *, passes: Iterable[str] | None = None,
                 cache: Cache | str | os.PathLike[str] | None = None, threads: int | None = None) -> Frame:
    """Render one finished frame into arrays (``sunshade frame``).

    Parameters
    ----------
    config : str, os.PathLike, mapping or Config
        The config (``load_config``).
    frame : int, default 0
        The output frame: the sun, moon and clouds of that moment, the canopy at frame mod cycle.
    passes : iterable of str, optional
        The light passes to make, names in ``vocabulary.PASSES`` (default: all of them, none with a
        ``ground.brdf``).
    cache : Cache, str or os.PathLike, optional
        The cache of the cycle products (default $SUNSHADE_CACHE, else ./cache).
    threads : int, optional
        FFT threads (default: all cores).

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

    config = load_config(config, named_frames=False)
    if passes is None:
        passes = PASSES if config.ground.brdf is None else ()
    wanted = set(passes)
    if unknown := sorted(wanted - set(PASSES)):
        raise BadInput(f"--passes: unknown pass {unknown[0]!r}; valid: {', '.join(PASSES)}")
    if wanted and config.ground.brdf is not None:
        raise BadInput(f"--passes: the light passes are not made with a ground.brdf yet ({config.path})")
    config = dataclasses.replace(config, output=dataclasses.replace(
        config.output, passes=tuple(p for p in PASSES if p in wanted)))
    _check_frame(frame, config)
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


def render_run(config: ConfigLike, folder: str | os.PathLike[str] | None = None, *,
               frames: Iterable[int] | None = None, progress: Callable[[str, int, int], None] | None = None,
               cache: Cache | str | os.PathLike[str] | None = None, jobs: int | None = None,
               force: bool = False) -> RunSummary:
    """Render a config's animation into a folder, resumably (``sunshade render``).

    Parameters
    ----------
    config : str, os.PathLike, mapping or Config
        The config (``load_config``).
    folder : str or os.PathLike, optional
        The output folder (default ``output.folder``).
    frames : iterable of int, optional
        The output frames to render (default: all); the video is made once all are done.
    progress : callable, optional
        Called as ``progress(stage, done, total)``, stage ``cycle``, ``frames`` or ``video``.
    cache : Cache, str or os.PathLike, optional
        The cache of the cycle products (default $SUNSHADE_CACHE, else ./cache).
    jobs : int, optional
        Processes at once (default ``render.jobs``, else one per core).
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

    written = load_config(config, resolved=False)
    if folder is not None:
        written = dataclasses.replace(written, output=dataclasses.replace(
            written.output, folder=Path(folder).expanduser().absolute()))
    if jobs is not None and jobs < 1:
        raise BadInput(f"--jobs must be at least 1 (got {jobs})")
    chosen = None if frames is None else tuple(sorted(set(frames)))
    for frame in chosen or ():
        _check_frame(frame, written)
    check_outputs(written)
    source_hash = source_digest(written)
    return run(resolve(written), frames=chosen, store=_cache(cache), jobs=jobs, force=force,
               progress=progress, source_hash=source_hash)


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
        The output frame.
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

    config = load_config(config, named_frames=False)
    _check_frame(frame, config)
    plan = plan_run(config)
    if plan.receivers.slope is not None:  # the slope's light, in its (u, w) metres (docs/method.md, "A sloped ground")
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
