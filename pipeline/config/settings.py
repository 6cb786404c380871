"""The config's typed values: frozen dataclasses, one per section, with their defaults.

What ``parse.parse_config`` and ``parse.load_config`` return, checked already. Angles are
radians and lengths metres here (degrees in the YAML); file paths are absolute. ``Config.digest``
hashes every value that shapes a frame's bytes: the frames and the cache's keys carry it
(docs/runs.md, "Resume").
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from datetime import datetime
from pathlib import Path

from pipeline import __version__
from pipeline.config.receivers import ReceiversConfig
from pipeline.config.vocabulary import DEFAULT_CIE_TYPE
from pipeline.config.yamlsafe import KeyContext
from pipeline.core.mesh_files import mesh_files
from pipeline.core.ocio import RENDER_SPACE

__all__ = ["AUTO_LIMITS", "AUTO_TIME_CONSTANT", "AnimationConfig", "AutoExposureConfig", "BrdfConfig", "CameraConfig",
           "CanopyConfig", "CanopyLayer", "CloudsConfig", "Config", "FlutterConfig", "ForegroundConfig",
           "GroundConfig", "MoonConfig", "OutputConfig", "RenderConfig", "SiteConfig", "SkyConfig", "SunConfig",
           "TreesConfig", "MeshConfig"]


@dataclass(frozen=True)
class CanopyLayer:
    """One canopy plane.

    Attributes
    ----------
    mask : tuple of Path
        Transparency images (1 = open sky), north-up: one, or the frames of a numbered sequence
        (the flutter cycle); empty for a procedural grove.
    size : (float, float)
        Ground covered by the image, x then y (the tile of a periodic layout). [m]
    center : (float, float)
        World x, y of the image centre. [m]
    height : float
        Height of the plane above the ground. [m]
    """

    mask: tuple[Path, ...]
    size: tuple[float, float]
    center: tuple[float, float]
    height: float


@dataclass(frozen=True)
class TreesConfig:
    """A seeded procedural grove (``grove.GroveParams``).

    Attributes
    ----------
    count : int
        Trees in the grove.
    seed : int
        Seed of the trees' and leaves' placement.
    crown_radius : float
        Radius of each crown. [m]
    leaves_per_tree : int
        Leaves in each crown.
    leaf_length : float
        Mean length of a leaf. [m]
    spread : float or None
        The trees' bases lie within this distance of the canopy centre; None: chosen from the
        crowns. [m]
    """

    count: int
    seed: int
    crown_radius: float
    leaves_per_tree: int
    leaf_length: float
    spread: float | None


@dataclass(frozen=True)
class MeshConfig:
    """A tree read from a mesh file (``canopy.mesh``; ``mesh.MeshParams``).

    Attributes
    ----------
    file : Path
        The .glb, .gltf, .obj (with its .mtl) or .ply file.
    scale : float
        Metres per file unit. [m]
    position : (float, float)
        Where the file's origin stands on the ground, x east and y north. [m]
    rotation : float
        Turn about the vertical, anticlockwise seen from above. [rad]
    up : str or None
        The file's up axis, 'y' or 'z'; None for its format's own.
    leaves : tuple of str or None
        The leaf materials' names; None finds them by their alpha.
    wood : tuple of str
        Materials that are wood whatever their alpha.
    max_triangles : int
        The most triangles the file may hold.
    seed : int
        Seed of its leaves' flutter phases.
    """

    file: Path
    scale: float
    position: tuple[float, float]
    rotation: float
    up: str | None
    leaves: tuple[str, ...] | None
    wood: tuple[str, ...]
    max_triangles: int
    seed: int


@dataclass(frozen=True)
class FlutterConfig:
    """The procedural leaves' motion.

    Attributes
    ----------
    cycle : int
        Frames per flutter cycle.
    swing, twist : float
        The leaves' amplitudes. [rad]
    """

    cycle: int
    swing: float
    twist: float


@dataclass(frozen=True)
class CanopyConfig:
    """The canopy: its planes, and the grove that fills them or their mask images.

    Attributes
    ----------
    layout : str
        'isolated' or 'periodic' (``parse.LAYOUTS``).
    layers : tuple of CanopyLayer
        The canopy planes.
    trees : TreesConfig or None
        The procedural grove; None when the layers have mask images.
    flutter : FlutterConfig
        The grove's motion (and the mesh trees' leaves').
    meshes : tuple of MeshConfig
        Trees read from mesh files (``canopy.mesh``); empty for none.
    """

    layout: str
    layers: tuple[CanopyLayer, ...]
    trees: TreesConfig | None
    flutter: FlutterConfig
    meshes: tuple[MeshConfig, ...] = ()

    @property
    def cycle(self) -> int:
        """Frames in the canopy's cycle: the flutter cycle, or the length of the mask sequence.

        Returns
        -------
        int
            The cycle's length [frames].
        """
        if self.trees is not None or self.meshes:
            return self.flutter.cycle
        return len(self.layers[0].mask)


@dataclass(frozen=True)
class SunConfig:
    """The sun by explicit angles.

    Attributes
    ----------
    elevation : float
        Elevation above the horizon. [rad]
    azimuth : float
        Azimuth from north towards east. [rad]
    radius : float
        Angular radius. [rad]
    """

    elevation: float
    azimuth: float
    radius: float


@dataclass(frozen=True)
class SiteConfig:
    """A place and a span of time: the sun and moon follow the ephemeris from ``start`` over
    the first frame to ``end`` over the last.

    Attributes
    ----------
    latitude, longitude : float
        The place, longitude positive east. [rad]
    elevation : float
        Height above sea level. [m]
    start, end : datetime
        The times of the first and the last frame, in UTC.
    """

    latitude: float
    longitude: float
    elevation: float
    start: datetime
    end: datetime


@dataclass(frozen=True)
class MoonConfig:
    """The moon by explicit angles, its centre relative to the sun's, moving linearly from
    ``offset_start`` over the first frame to ``offset_end`` over the last.

    Attributes
    ----------
    offset_start, offset_end : (float, float)
        (to the right, up) as the observer faces the sun. [rad]
    radius : float
        Angular radius. [rad]
    """

    offset_start: tuple[float, float]
    offset_end: tuple[float, float]
    radius: float


@dataclass(frozen=True)
class CloudsConfig:
    """The cloud layer of a procedural sky.

    Attributes
    ----------
    cover : float
        Fraction of the sky covered.
    scale : float
        Feature size. [m]
    altitude : float
        Height of the layer. [m]
    wind : (float, float)
        Wind (east, north). [m/s]
    thickness : float
        Optical depth of a full cloud.
    seed : int
        Seed of the pattern.
    """

    cover: float = 0.4
    scale: float = 800.0
    altitude: float = 2000.0
    wind: tuple[float, float] = (8.0, 2.0)
    thickness: float = 1.0
    seed: int = 1


@dataclass(frozen=True)
class SkyConfig:
    """The sky: its model and, for the procedural models ('cie' and 'preetham',
    ``vocabulary.PROCEDURAL_MODELS``), the sun, moon, clouds and air.

    Attributes
    ----------
    model : str
        A name in ``vocabulary.SKY_MODELS``.
    radiance : (float, float, float)
        Linear RGB of a uniform sky. [kcd/m^2]
    hdri : Path or None
        Equirectangular image of model 'hdri'.
    rotation : float
        Rotation of the HDRI about the zenith. [rad]
    alpha : float
        Half-angle of the sky square. [rad]
    turbidity : float or None
        The Linke turbidity factor; with ``turbidity_auto`` None until ``resolve.resolve`` looks
        it up in the climatology for the site and the middle of the time span.
    sun : SunConfig or None
        The sun by angles; None with a site and time.
    site : SiteConfig or None
        The place and time span the sun and moon follow; None with the sun by angles.
    moon : MoonConfig or None
        The moon by angles (implied by a site and time).
    clouds : CloudsConfig or None
        The cloud layer; None for none.
    haze : float
        Extinction length of the air the camera looks through, 0 for none. [m]
    skylight : float
        Factor on the clear sky, 0 for the sun alone.
    cie_type : int
        The CIE standard general sky, 1..15 (model 'cie').
    turbidity_auto : bool
        Whether the config gave ``turbidity: auto``.
    params : tuple
        ((key, value), ...): the number keys of a model the parser has no code of its own for
        (``registry.Model.numbers``), e.g. the overcast sky's ``luminance`` [kcd/m^2].
    """

    model: str
    radiance: tuple[float, float, float]
    hdri: Path | None
    rotation: float
    alpha: float
    turbidity: float = 3.0
    sun: SunConfig | None = None
    site: SiteConfig | None = None
    moon: MoonConfig | None = None
    clouds: CloudsConfig | None = None
    haze: float = 3000.0
    skylight: float = 1.0
    cie_type: int = DEFAULT_CIE_TYPE
    turbidity_auto: bool = False
    params: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class GroundConfig:
    """The ground: its rasters, its albedo and its reflectance.

    Attributes
    ----------
    window : (float, float, float, float) or None
        (x_min, y_min, x_max, y_max); None to frame the canopy's shadow over the animation
        (``plan.plan_run``). [m]
    pixel : float
        Ground pixel. [m]
    sun_window : (float, float, float, float) or None
        The sun's fine raster; None: the ground the camera sees of the shadow, or the window
        when it is given. [m]
    sun_pixel : float or None
        The sun's fine raster's pixel; None: chosen so the sun disc spans 16 cells, within
        ``resolve.MAX_SUN_PIXELS``. [m]
    albedo : str or Path
        A built-in albedo's name or an image.
    albedo_size : float
        Ground covered by one tile of the albedo. [m]
    brdf : BrdfConfig or None
        The ground's reflectance; None: ``lambert``.
    """

    window: tuple[float, float, float, float] | None
    pixel: float
    sun_window: tuple[float, float, float, float] | None = None
    sun_pixel: float | None = None
    albedo: str | Path = "grass"
    albedo_size: float = 4.0
    brdf: BrdfConfig | None = None


@dataclass(frozen=True)
class BrdfConfig:
    """The ground's reflectance (``ground.brdf``). None in GroundConfig is ``lambert``, the
    paper's constant, on the code path it always had.

    Attributes
    ----------
    model : str
        A name in ``vocabulary.BRDF_PARAMETERS``.
    parameters : tuple of (str, float)
        (name, value), ... in that model's order.
    preset : str or None
        The name it was given by (``vocabulary.BRDF_PRESETS``), or None.
    """

    model: str
    parameters: tuple[tuple[str, float], ...] = ()
    preset: str | None = None


AUTO_TIME_CONSTANT = 0.2
"""Default time constant of ``camera.exposure: auto``: the exposure closes 63% of the gap to
the metered light in this much film time. [s]"""
AUTO_LIMITS = (-4.0, 10.0)
"""Default limits of ``camera.exposure: auto``: the least and the most exposure, in stops over
the fixed exposure of the run's clear sky. [stops]"""


@dataclass(frozen=True)
class AutoExposureConfig:
    """``camera.exposure: auto``: the exposure follows the open ground's light (sun times S
    plus sky) through a first-order lag, clamped to limits over the fixed exposure of the
    clear sky.

    Attributes
    ----------
    time_constant : float
        The lag's time constant, in film time. [s]
    limits : (float, float)
        The least and the most exposure. [stops]
    """

    time_constant: float = AUTO_TIME_CONSTANT
    limits: tuple[float, float] = AUTO_LIMITS


@dataclass(frozen=True)
class CameraConfig:
    """The pinhole camera; what it leaves out is placed by ``framing.frame_scene``.

    Attributes
    ----------
    position : (float, float, float) or None
        (x, y, z); None to stand it where it sees the canopy and its shadows. [m]
    look_at : (float, float, float) or None
        The point it looks at; None with yaw and pitch, or to look at the canopy. [m]
    yaw : float or None
        Azimuth of the view, from north towards east. [rad]
    pitch : float or None
        Elevation of the view, negative looking down. [rad]
    fov : float
        Vertical field of view. [rad]
    resolution : (int, int)
        (width, height). [pixel]
    exposure : float
        Over the default (white ground under the clear sky at 1), or with ``auto_exposure``
        over the metered light. [stops]
    display : str
        A name in ``vocabulary.DISPLAYS``.
    auto_exposure : AutoExposureConfig or None
        The auto exposure; None for a fixed one.
    white_balance : str
        A name in ``vocabulary.WHITE_BALANCES``.
    follow : str
        A name in ``vocabulary.FOLLOWS``: whether a placed camera pans with the shadow.
    """

    position: tuple[float, float, float] | None = None
    look_at: tuple[float, float, float] | None = None
    yaw: float | None = None
    pitch: float | None = None
    fov: float = math.radians(50.0)
    resolution: tuple[int, int] = (1280, 720)
    exposure: float = 0.0
    display: str = "filmic"
    auto_exposure: AutoExposureConfig | None = None
    white_balance: str = "daylight"
    follow: str = "auto"


@dataclass(frozen=True)
class ForegroundConfig:
    """The trees in front of the camera.

    Attributes
    ----------
    model : str
        'trees' (the canopy's grove, rendered), 'passes' (imported EXR sequences) or 'none'
        (``vocabulary.FOREGROUNDS``).
    sun, sky, alpha : tuple of Path
        The imported passes, one file per cycle frame (model 'passes').
    """

    model: str
    sun: tuple[Path, ...] = ()
    sky: tuple[Path, ...] = ()
    alpha: tuple[Path, ...] = ()


@dataclass(frozen=True)
class AnimationConfig:
    """The animation's length.

    Attributes
    ----------
    frames : int
        Number of output frames.
    fps : float
        Frames per second of film time. [1/s]
    """

    frames: int
    fps: float


@dataclass(frozen=True)
class OutputConfig:
    """Where a run goes: frames ``name.0000.exr`` and ``.png`` and the video ``name.mp4``.

    Attributes
    ----------
    name : str
        The files' name.
    folder : Path
        Their folder (given relative to the current folder; default ``renders/NAME``).
    video : str
        A name in ``parse.VIDEOS``.
    half : bool
        EXR frames in half floats (else float32).
    passes : tuple of str
        The light passes each EXR holds as layers beside the beauty, names in
        ``vocabulary.PASSES`` in their order there (empty: none, and the EXR's bytes are as
        before passes existed).
    report : bool
        Whether a render that renders frames ends by writing the run's report (light.csv, light
        curve, contact sheet; docs/runs.md, "The report").
    colorspace : str
        The scene-linear space the EXRs' RGB layers are written in, a colour space of
        ``ocio_config`` (``ocio.RENDER_SPACE``, the default: as rendered; docs/runs.md, "Colour").
    view : (str, str) or None
        (display, view) of ``ocio_config`` the PNGs, the video and the contact sheet are shown
        through; None: ``camera.display``'s curve.
    ocio_config : str or None
        The OCIO config: a file path (absolute) or an ``ocio://`` URI; None where neither
        ``colorspace`` nor ``view`` needs one.
    """

    name: str
    folder: Path
    video: str = "mp4"
    half: bool = True
    passes: tuple[str, ...] = ()
    report: bool = True
    colorspace: str = RENDER_SPACE
    view: tuple[str, str] | None = None
    ocio_config: str | None = None


@dataclass(frozen=True)
class RenderConfig:
    """How a run computes.

    Attributes
    ----------
    jobs : int or None
        Processes rendering at once; None: one per core.
    sun_cells : int
        Cells across the sun disc's diameter on its fine grid, when ground.sun_pixel does not
        set it (16 shows crescents).
    """

    jobs: int | None = None
    sun_cells: int = 16


_NOT_IN_DIGEST = {"output": ("name", "folder", "video", "report"), "render": ("jobs",)}
"""Values that change where or how fast frames are made, not their bytes."""


@dataclass(frozen=True)
class Config:
    """A whole config, validated.

    Attributes
    ----------
    path : Path
        The config file (absolute).
    canopy, sky, ground, animation, camera, foreground, output, render
        The sections' values.
    lines : dict
        The YAML line of each key path, for messages.
    receivers : ReceiversConfig
        Walls and a slope besides the level ground.
    """

    path: Path
    canopy: CanopyConfig
    sky: SkyConfig
    ground: GroundConfig
    animation: AnimationConfig
    camera: CameraConfig
    foreground: ForegroundConfig
    output: OutputConfig
    render: RenderConfig = RenderConfig()
    lines: dict = field(default_factory=dict, compare=False, repr=False)
    """The YAML line of each key path, for messages."""
    receivers: ReceiversConfig = field(default_factory=ReceiversConfig)
    """Walls and a slope besides the level ground (``config.receivers``)."""

    def where(self, key: str) -> str:
        """Where a key is, for a message about it.

        Parameters
        ----------
        key : str
            A key path, e.g. ``sky.sun.elevation``.

        Returns
        -------
        str
            'file:line: key' (or 'file: key' where the key has no line).
        """
        return KeyContext(self.path, self.lines).where(key)

    def digest(self) -> str:
        """The config's hash, a cache key.

        Returns
        -------
        str
            16 hex digits of the SHA-256 of every value that shapes a frame's bytes, of every
            input file's bytes and of the package version.
        """
        values = asdict(self)
        values.pop("path")
        values.pop("lines")
        for section, names in _NOT_IN_DIGEST.items():
            for name in names:
                values[section].pop(name)
        if values["camera"]["auto_exposure"] is None:  # a fixed exposure hashes as it always did
            values["camera"].pop("auto_exposure")
        if self.camera.position is not None or self.camera.look_at is not None:
            values["camera"].pop("follow")  # a camera given where it stands or looks never follows
        if not values["output"]["passes"]:  # without passes a config hashes as it always did
            values["output"].pop("passes")
        for name, default in (("colorspace", OutputConfig.colorspace), ("view", None), ("ocio_config", None)):
            if values["output"][name] == default:  # the colour as rendered hashes as it always did
                values["output"].pop(name)
        if values["ground"]["brdf"] is None:  # a lambertian ground hashes as it always did
            values["ground"].pop("brdf")
        if not values["sky"]["params"]:  # a sky the parser reads itself hashes as it always did
            values["sky"].pop("params")
        if self.receivers == ReceiversConfig():  # the level ground alone hashes as it always did
            values.pop("receivers")
        if not self.canopy.meshes:  # a canopy without mesh trees hashes as it always did
            values["canopy"].pop("meshes")
        files = sorted({str(m) for layer in self.canopy.layers for m in layer.mask}
                       | {str(file) for mesh in self.canopy.meshes for file in mesh_files(mesh.file)}
                       | {str(p) for p in (*self.foreground.sun, *self.foreground.sky, *self.foreground.alpha)}
                       | ({str(self.sky.hdri)} if self.sky.hdri else set())
                       | ({str(self.ground.albedo)} if isinstance(self.ground.albedo, Path) else set())
                       | {str(p) for wall in self.receivers.walls
                          for p in (wall.albedo, *(m.image for m in wall.masks)) if isinstance(p, Path)}
                       | ({self.output.ocio_config} if self.output.ocio_config and
                          not self.output.ocio_config.startswith("ocio://") else set()))
        h = hashlib.sha256()
        h.update(json.dumps(values, sort_keys=True, default=str).encode())
        h.update(__version__.encode())
        for name in files:
            h.update(Path(name).read_bytes())
        return h.hexdigest()[:16]
