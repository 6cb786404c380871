"""A config, YAML or a mapping, parsed and validated into frozen values.

Angles are degrees in the YAML and radians in the values; lengths are metres. Every error names
the key path (and the YAML line where there is one) and is raised before any work starts.
File paths are relative to the folder of the config file. The YAML is read by ``yamlsafe``,
its mappings key by key by ``sections.Section``, into the values of ``settings``; this module
holds the parsers, each section's checks and the limits they enforce. It imports no physics
(docs/design.md, "What each package may import").
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

from pipeline.config.meshes import parse_meshes
from pipeline.config.receivers import parse_receivers
from pipeline.config.sections import Section, is_number, kind_of
from pipeline.config.settings import (
    AUTO_LIMITS,
    AUTO_TIME_CONSTANT,
    AnimationConfig,
    AutoExposureConfig,
    BrdfConfig,
    CameraConfig,
    CanopyConfig,
    CanopyLayer,
    CloudsConfig,
    Config,
    FlutterConfig,
    ForegroundConfig,
    GroundConfig,
    MoonConfig,
    OutputConfig,
    RenderConfig,
    SiteConfig,
    SkyConfig,
    SunConfig,
    TreesConfig,
)
from pipeline.config.vocabulary import (
    BRDF_PARAMETERS,
    BRDF_PRESETS,
    CIE_TYPE_RANGE,
    DISPLAYS,
    FOLLOWS,
    FOREGROUNDS,
    PASSES,
    PROCEDURAL_MODELS,
    REFLECTANCES,
    SKIES,
    TURBIDITY_RANGE,
    WHITE_BALANCES,
)
from pipeline.config.yamlsafe import KeyContext, key_lines, load_yaml
from pipeline.core import ocio
from pipeline.core.constants import SUN_RADIUS_DEG

__all__ = ["FRAME_BYTES_PER_PIXEL", "LAYOUTS", "MAX_FRAMES", "MAX_IMAGE_PIXELS", "MAX_LEAVES",
           "MAX_RADIANCE", "MOON_RADIUS_DEG", "VIDEOS", "default_name", "load_config", "parse_config", "size_text"]

LAYOUTS = ("isolated", "periodic")
"""The canopy's layouts: one grove or image, or a tile repeated without end."""
MAX_LEAVES = 1_000_000
"""Most leaves of a procedural grove, all its trees together."""
MOON_RADIUS_DEG = 0.2725
"""Angular radius of the moon for explicit-angle eclipses: a little larger than the sun. [deg]"""
MAX_RADIANCE = 1e30
"""Largest radiance accepted: float32 sums of many cells must stay finite. [radiance]"""
VIDEOS = ("mp4", "gif", "none")
"""The video formats of ``output.video``."""


def load_config(path: str | os.PathLike[str], *, named_frames: bool = True) -> Config:
    """Read and validate a YAML config file.

    Parameters
    ----------
    path : str or path-like
        The config file; the file paths in it are relative to its folder.
    named_frames : bool, default True
        False for the commands that write no named frames (``frame``, ``ground``, ``sky``,
        ``mask``): an ``output.name`` that is no valid name is replaced by the default one.

    Returns
    -------
    Config
        The config's values.

    Raises
    ------
    ConfigError
        Naming the file, the key path and its line.
    """
    node, data = load_yaml(path)
    path = Path(path)
    lines: dict[str, int] = {}
    key_lines(node, "", lines, path)
    root = Section(data if data is not None else {}, "", KeyContext(path, lines))
    return _parse(root, path, named_frames)


def parse_config(mapping: dict[str, Any], base_dir: str | os.PathLike[str], *, name: str = "config",
                 named_frames: bool = True) -> Config:
    """Validate a config given as a mapping, as if read from ``base_dir/NAME.yaml``.

    Parameters
    ----------
    mapping : dict
        What a YAML file would hold.
    base_dir : str or path-like
        The folder its file paths are relative to.
    name : str, default 'config'
        The config file's name without ``.yaml`` (the default output name).
    named_frames : bool, default True
        As for ``load_config``.

    Returns
    -------
    Config
        The config's values, as ``load_config`` returns them.

    Raises
    ------
    ConfigError
        Naming the key path.
    """
    path = Path(base_dir) / f"{name}.yaml"
    return _parse(Section(mapping, "", KeyContext(path, {})), path, named_frames)


def _parse(root: Section, path: Path, named_frames: bool = True) -> Config:
    root.known_first()
    animation = _parse_animation(root.section("animation"))
    ground = _parse_ground(root.section("ground"))
    canopy = _parse_canopy(root.section("canopy"), ground)
    sky = _parse_sky(root.section("sky"))
    camera = _parse_camera(root.section("camera"))
    foreground = _parse_foreground(root.section("foreground"), canopy)
    output = _parse_output(root.section("output"), path, named_frames)
    render = _parse_render(root.section("render"))
    receivers = parse_receivers(root.section("receivers"))
    root.done()
    if canopy.meshes and (receivers.walls or receivers.slope is not None):
        root.fail("canopy.mesh", "mesh trees shade the level ground alone yet: leave out receivers")
    _check_frames(root, animation, camera, output)
    if camera.follow == "shadow" and (ground.sun_window is not None or ground.window is not None):
        given = "ground.sun_window" if ground.sun_window is not None else "ground.window"
        root.fail("camera.follow", f"shadow moves the windows with the camera: leave out {given} "
                                   "(or give follow: fixed)")
    if camera.follow == "shadow" and canopy.layout == "periodic":
        root.fail("camera.follow", "a periodic canopy casts no shadow to follow: give follow: fixed or auto")
    if camera.follow == "shadow" and foreground.model == "passes":
        root.fail("camera.follow", "shadow moves the camera, and imported foreground passes hold one camera's "
                                   "view: give follow: fixed")
    if output.passes and ground.brdf is not None:
        root.fail("output.passes", "the light passes are not made with a ground.brdf yet; give one or the other")
    if output.view is not None and isinstance(root.data.get("camera"), dict) and "display" in root.data["camera"]:
        root.fail("camera.display", "output.view shows the frames through an OCIO view instead; give one or the other")
    return Config(path.resolve(), canopy, sky, ground, animation, camera, foreground, output, render,
                  root.ctx.lines, receivers)


MAX_FRAMES = 100_000
"""Most output frames of one animation (a run plans and checks every frame before it starts)."""
FRAME_BYTES_PER_PIXEL = {True: 4.6, False: 7.8}
"""Disk a finished frame takes per pixel, its EXR (half floats: True; float32: False, PIZ) and
its PNG together: 4.2 MB for a 1280 x 720 frame of configs/eclipse.yaml in half floats (its 240
frames took 966.6 MiB, docs/accuracy.md); float32 adds about 3.2 bytes a pixel. About: the
compression follows the picture. [B]"""


def _check_frames(root: Section, animation: AnimationConfig, camera: CameraConfig, output: OutputConfig) -> None:
    """Refuse more than MAX_FRAMES frames, with what they would take on disk."""
    if animation.frames > MAX_FRAMES:
        width, height = camera.resolution
        size = animation.frames * width * height * FRAME_BYTES_PER_PIXEL[output.half]
        root.fail("animation.frames", f"{animation.frames:.3g} frames of {width} x {height} px "
                  f"would be about {size_text(size)} of files; the most is {MAX_FRAMES} frames")


def size_text(count: float) -> str:
    """A byte count for a message.

    Parameters
    ----------
    count : float
        Bytes. [B]

    Returns
    -------
    str
        Three significant digits and a decimal unit, e.g. '3.2 GB'.
    """
    for unit in ("B", "kB", "MB", "GB"):
        if count < 1000:
            return f"{count:.3g} {unit}"
        count /= 1000
    return f"{count:.3g} TB"


def default_name(path: Path) -> str:
    """The output name a config file gives by default.

    Parameters
    ----------
    path : Path
        The config file.

    Returns
    -------
    str
        Its file name without the suffix, every run of characters other than letters, digits,
        - and _ (a dot, a space) made one _; 'sunshade' if nothing is left.
    """
    name = re.sub(r"[^A-Za-z0-9_-]+", "_", path.stem).strip("_")
    return name or "sunshade"


def _parse_output(s: Section, path: Path, named_frames: bool = True) -> OutputConfig:
    name = s.raw("name", default_name(path))
    valid = isinstance(name, str) and name and all(c.isalnum() or c in "-_" for c in name)
    if not valid and not named_frames:
        name = default_name(path)
    elif not valid:
        s.fail("name", f"must be a name of letters, digits, - and _ (got {name!r})")
    folder = s.raw("folder", f"renders/{name}")
    if not isinstance(folder, str) or not folder:
        s.fail("folder", f"must be a folder name, not {kind_of(folder)}")
    s.check_path("folder", folder)
    video = s.choice("video", VIDEOS, OutputConfig.video)
    half = s.raw("half", OutputConfig.half)
    if not isinstance(half, bool):
        s.fail("half", f"must be true or false, not {kind_of(half)}")
    passes = _parse_passes(s)
    report = s.raw("report", OutputConfig.report)
    if not isinstance(report, bool):
        s.fail("report", f"must be true or false, not {kind_of(report)}")
    colorspace, view, source = _parse_colour(s)
    s.done()
    return OutputConfig(name, Path(folder).expanduser().absolute(), video, half, passes, report, colorspace, view,
                        source)


def _parse_colour(s: Section) -> tuple[str, tuple[str, str] | None, str | None]:
    """output.colorspace, output.view and output.ocio_config, checked against the OCIO config
    (docs/runs.md, "Colour"), which is read only when one of the first two asks for it; a
    built-in config is given by its versioned name, so the config's hash follows its version."""
    colorspace = s.raw("colorspace", OutputConfig.colorspace)
    if not isinstance(colorspace, str) or not colorspace:
        s.fail("colorspace", f"must be a colour space name, not {kind_of(colorspace)}")
    view = None
    if s.raw("view", None) is not None:
        v = s.section("view")
        view = (v.raw("display"), v.raw("view"))
        for key, value in zip(("display", "view"), view):
            if not isinstance(value, str) or not value:
                v.fail(key, f"must be a name, not {kind_of(value)}")
        v.done()
    given = s.raw("ocio_config", None)
    if given is not None and (not isinstance(given, str) or not given):
        s.fail("ocio_config", f"must be a file name or an ocio:// URI, not {kind_of(given)}")
    source = given if given is None or given.startswith("ocio://") else str(s.file("ocio_config"))
    if colorspace == ocio.RENDER_SPACE and view is None:
        return colorspace, None, None
    source, key = (source, "ocio_config") if source else (ocio.default_source(), f"ocio_config (${ocio.OCIO_ENV})")
    try:
        source = f"ocio://{ocio.config_name(source)}" if source.startswith("ocio://") else source
    except ocio.OcioError as exc:
        s.fail(key, str(exc))
    try:
        ocio.working_space(source, colorspace)
    except ocio.OcioError as exc:
        s.fail("colorspace", str(exc))
    try:
        if view is not None:
            ocio.check_view(source, *view)
    except ocio.OcioError as exc:
        s.fail("view", str(exc))
    return colorspace, view, source


def _parse_passes(s: Section) -> tuple[str, ...]:
    """output.passes: a list of names in PASSES (or one name), each once; returned in PASSES'
    order, so that the same set of passes hashes and writes the same way."""
    passes = s.raw("passes", [])
    if passes is None:
        passes = []
    if isinstance(passes, str):
        passes = [passes]
    if not isinstance(passes, list):
        s.fail("passes", f"must be a list of pass names ({', '.join(PASSES)}), not {kind_of(passes)}")
    for name in passes:
        if name not in PASSES:
            s.fail("passes", f"unknown pass {name!r}; valid: {', '.join(PASSES)}")
    if len(set(passes)) != len(passes):
        s.fail("passes", "names a pass more than once")
    return tuple(p for p in PASSES if p in passes)


def _parse_render(s: Section) -> RenderConfig:
    jobs = s.integer("jobs", at_least=1) if s.has("jobs") else None
    render = RenderConfig(jobs, s.integer("sun_cells", RenderConfig.sun_cells, at_least=2))
    if render.sun_cells > 64:
        s.fail("sun_cells", f"must be at most 64 (got {render.sun_cells})")
    s.done()
    return render


def _parse_animation(s: Section) -> AnimationConfig:
    frames = s.integer("frames", 48, at_least=1)
    fps = s.number("fps", 24.0, above=0.0)
    s.done()
    return AnimationConfig(frames, fps)


def _parse_window(s: Section, name: str, default: Any) -> tuple[float, float, float, float]:
    window = s.numbers(name, 4, default)
    if not (window[2] > window[0] and window[3] > window[1]):
        s.fail(name, f"must be [x_min, y_min, x_max, y_max] with max above min (got {list(window)})")
    return window


def _parse_ground(s: Section) -> GroundConfig:
    window = _parse_window(s, "window", None) if s.has("window") else None
    pixel = s.number("pixel", 0.05, above=0.0)
    sun_window = _parse_window(s, "sun_window", None) if s.has("sun_window") else None
    sun_pixel = s.number("sun_pixel", above=0.0) if s.has("sun_pixel") else None
    if sun_pixel is not None:
        if sun_pixel > pixel:
            s.fail("sun_pixel", f"must not be above ground.pixel ({sun_pixel:g} > {pixel:g})")
    albedo = GroundConfig.albedo
    if s.has("albedo") and s.data["albedo"] != GroundConfig.albedo:
        albedo = s.file("albedo")
    s.raw("albedo", None)
    albedo_size = s.number("albedo_size", GroundConfig.albedo_size, above=0.0)
    brdf = _parse_brdf(s) if s.has("brdf") else None
    s.done()
    return GroundConfig(window, pixel, sun_window, sun_pixel, albedo, albedo_size, brdf)


def _parse_brdf(s: Section) -> BrdfConfig | None:
    """``ground.brdf``: ``lambert`` (None: the Lambertian path), a preset's name, or a mapping
    ``{model: NAME, PARAMETER: value, ...}``; each parameter inside its model's open range."""
    value = s.raw("brdf")
    if isinstance(value, str):
        if value == "lambert":
            return None
        if value not in BRDF_PRESETS:
            s.fail("brdf", f"unknown value {value!r}; valid: {', '.join(('lambert', *BRDF_PRESETS))}, "
                   "or a mapping with a model")
        model, parameters = BRDF_PRESETS[value]
        return BrdfConfig(model, tuple(parameters.items()), value)
    b = s.section("brdf")
    model = b.choice("model", REFLECTANCES.names)
    ranges = BRDF_PARAMETERS[model]
    values = {}
    for name, (low, high, brackets) in ranges.items():
        if name == "rho_c" and not b.has(name):
            continue
        value = values[name] = b.number(name)
        inside = (low <= value if brackets[0] == "[" else low < value) and (
            value <= high if brackets[1] == "]" else value < high)
        if not inside:
            b.fail(name, f"outside the physical range of {model}'s {name}, {brackets[0]}{low:g}, {high:g}"
                   f"{brackets[1]} (got {value:g})")
    if model == "rpv":
        values.setdefault("rho_c", values["rho0"])
    b.done()
    if model == "lambert":
        return None
    return BrdfConfig(model, tuple(values.items()))


def _parse_canopy(s: Section, ground: GroundConfig) -> CanopyConfig:
    layout = s.choice("layout", LAYOUTS, "isolated")
    images = s.has("mask") or (
        s.has("layers") and isinstance(s.data["layers"], list)
        and any(isinstance(item, dict) and "mask" in item for item in s.data["layers"]))
    if images and s.has("trees"):
        s.fail("trees", "give either trees (a procedural grove) or mask images, not both")
    meshes = parse_meshes(s, layout, images)
    trees = None if images or meshes else _parse_trees(s.section("trees"))
    flutter = _parse_flutter(s.section("flutter")) if trees or meshes else None
    if not trees and not meshes and s.has("flutter"):
        s.fail("flutter", "only used with trees (a mask sequence flutters by its own frames)")
    base = _parse_layer(s, {}, ground, layout, images=images, mask_required=not s.has("layers"), sized=bool(meshes))
    if not s.has("layers"):
        layers = [base]
    else:
        items = s.raw("layers")
        if not isinstance(items, list) or not items:
            s.fail("layers", f"must be a non-empty list of mappings, not {kind_of(items)}")
        layers = []
        for i, item in enumerate(items):
            ls = Section(item, s.key(f"layers[{i}]"), s.ctx)
            layers.append(_parse_layer(ls, base, ground, layout, images=images,
                                       mask_required=not base["mask"], sized=bool(meshes)))
            ls.done()
        counts = {len(layer["mask"]) for layer in layers}
        if len(counts) > 1:
            s.fail("layers", f"mask sequences of every layer must have the same length (got {sorted(counts)})")
    s.done()
    return CanopyConfig(layout, tuple(CanopyLayer(**layer) for layer in layers), trees,
                        flutter or FlutterConfig(1, 0.0, 0.0), meshes)


def _parse_trees(s: Section) -> TreesConfig:
    trees = TreesConfig(
        count=s.integer("count", 3, at_least=1),
        seed=s.integer("seed", 7, at_least=0),
        crown_radius=s.number("crown_radius", 4.0, above=0.0),
        leaves_per_tree=s.integer("leaves_per_tree", 12000, at_least=1),
        leaf_length=s.number("leaf_length", 0.08, above=0.0),
        spread=s.number("spread", at_least=0.0) if s.has("spread") else None,
    )
    if trees.count * trees.leaves_per_tree > MAX_LEAVES:
        s.fail("leaves_per_tree", f"{trees.count} trees of {trees.leaves_per_tree} leaves is "
               f"{trees.count * trees.leaves_per_tree} leaves; the most is {MAX_LEAVES}")
    s.done()
    return trees


def _parse_flutter(s: Section) -> FlutterConfig:
    flutter = FlutterConfig(
        cycle=s.integer("cycle", 48, at_least=1),
        swing=math.radians(s.number("swing", 12.0, at_least=0.0, below=90.0)),
        twist=math.radians(s.number("twist", 20.0, at_least=0.0, below=90.0)),
    )
    s.done()
    return flutter


def _parse_layer(s: Section, base: dict[str, Any], ground: GroundConfig, layout: str, *, images: bool,
                 mask_required: bool, sized: bool = False) -> dict[str, Any]:
    """One canopy plane's keys, each defaulting to ``base``'s; its rasters checked for size (``sized``: an
    area of its own, as mesh trees' planes have)."""
    if images and (s.has("mask") or mask_required):
        mask = s.mask_files("mask")
    else:
        mask = base.get("mask", ())
    default_size = (20.0, 20.0) if images or sized or layout == "periodic" else None
    default_size = base.get("size", default_size)
    if default_size is None and not s.has("size"):
        size = (0.0, 0.0)  # an isolated grove sizes itself
    else:
        size = s.numbers("size", 2, default_size)
    if min(size) <= 0 and (images or sized or layout == "periodic" or s.has("size")):
        s.fail("size", f"both sides must be above 0 (got {list(size)})")
    layer = {
        "mask": mask,
        "size": size,
        "center": s.numbers("center", 2, base.get("center", (0.0, 0.0))),
        "height": s.number("height", base.get("height", 8.0), above=0.0),
    }
    pixels = [side / ground.pixel for side in size]
    if layout == "periodic":
        for ratio in pixels:
            if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio) or round(ratio) < 1:
                s.fail("size", f"a periodic tile must be a whole number of ground pixels "
                       f"({ratio * ground.pixel:g} / {ground.pixel:g} = {ratio:.4g})")
    return layer


def _parse_sky(s: Section) -> SkyConfig:
    if s.raw("model", "cie") == "procedural":  # the former name of the CIE clear sky
        s.data = {**s.data, "model": "cie"}
    model = s.choice("model", SKIES.names, "cie")
    for key in SKIES.owned_keys():
        owners = SKIES.owners(key)
        if s.has(key) and model not in owners:
            s.fail(key, f"only used with model: {' or '.join(owners)} (model is {model})")
    radiance = (1.0, 1.0, 1.0)
    hdri = None
    if model == "uniform":
        if is_number(s.raw("radiance", 1.0)):
            radiance = (s.number("radiance", 1.0),) * 3
        else:
            radiance = s.numbers("radiance", 3)
        if min(radiance) < 0 or max(radiance) > MAX_RADIANCE:
            s.fail("radiance", f"must lie in [0, {MAX_RADIANCE:g}] (got {list(radiance)})")
    if model == "hdri":
        hdri = s.file("hdri")
    rotation = math.radians(s.number("rotation", 0.0) % 360.0)
    alpha_deg = s.number("alpha", 80.0, above=0.0, below=90.0)
    alpha = math.radians(alpha_deg)
    extra = {}
    if model in PROCEDURAL_MODELS:
        extra = _parse_procedural(s, model)
    extra["haze"] = s.number("haze", SkyConfig.haze, at_least=0.0)
    extra["params"] = _parse_numbers(s, SKIES[model].numbers)
    s.done()
    return SkyConfig(model, radiance, hdri, rotation, alpha, **extra)


def _parse_numbers(s: Section, numbers: dict) -> tuple[tuple[str, float], ...]:
    """The number keys of a registered model (``registry.Model.numbers``), each inside its range."""
    values = []
    for key, (default, least, most, unit) in numbers.items():
        value = s.number(key, default)
        if not least <= value <= most:
            s.fail(key, f"must lie in [{least:g}, {most:g}] {unit} (got {value:g})")
        values.append((key, value))
    return tuple(values)


def _parse_procedural(s: Section, model: str) -> dict:
    lo, hi = TURBIDITY_RANGE
    auto = s.raw("turbidity", 3.0) == "auto"
    if auto and not (s.has("site") and s.has("time")):
        s.fail("turbidity", "auto needs sky.site and sky.time (the climatology is of a place and month)")
    turbidity = None if auto else s.number("turbidity", SkyConfig.turbidity, at_least=lo, below=hi + 1e-9)
    cie_type = SkyConfig.cie_type
    if model == "cie":
        first, last = CIE_TYPE_RANGE
        cie_type = s.integer("cie_type", SkyConfig.cie_type, at_least=first)
        if cie_type > last:
            s.fail("cie_type", f"must be one of the CIE standard general skies {first}..{last} (got {cie_type})")
    sun = site = moon = None
    if s.has("site") or s.has("time"):
        if s.has("sun"):
            s.fail("sun", "give the sun either by angles or by site and time, not both")
        if s.has("moon"):
            s.fail("moon", "the moon is implied by site and time")
        site = _parse_site(s.section("site"), s.section("time"))
    else:
        ss = s.section("sun")
        sun = SunConfig(
            elevation=math.radians(ss.number("elevation", 60.0, at_least=2.0, below=90.0 + 1e-9)),
            azimuth=math.radians(ss.number("azimuth", 180.0) % 360.0),
            radius=math.radians(ss.number("radius", SUN_RADIUS_DEG, above=0.0, below=5.0)),
        )
        ss.done()
        if s.has("moon"):
            ms = s.section("moon")
            moon = MoonConfig(
                offset_start=_radians_pair(ms.numbers("offset_start", 2)),
                offset_end=_radians_pair(ms.numbers("offset_end", 2)),
                radius=math.radians(ms.number("radius", MOON_RADIUS_DEG, above=0.0, below=5.0)),
            )
            ms.done()
    clouds = None
    if s.has("clouds"):
        cs = s.section("clouds")
        clouds = CloudsConfig(
            cover=cs.number("cover", CloudsConfig.cover, at_least=0.0, below=1.0 + 1e-9),
            scale=cs.number("scale", CloudsConfig.scale, above=0.0),
            altitude=cs.number("altitude", CloudsConfig.altitude, above=0.0),
            wind=cs.numbers("wind", 2, CloudsConfig.wind),
            thickness=cs.number("thickness", CloudsConfig.thickness, at_least=0.0),
            seed=cs.integer("seed", CloudsConfig.seed, at_least=0),
        )
        cs.done()
    skylight = s.number("skylight", SkyConfig.skylight, at_least=0.0, below=100.0)
    return {"turbidity": turbidity, "sun": sun, "site": site, "moon": moon, "clouds": clouds,
            "skylight": skylight, "cie_type": cie_type, "turbidity_auto": auto}


def _radians_pair(degrees: tuple[float, float]) -> tuple[float, float]:
    """Both angles of a pair in radians, each by ``math.radians``."""
    return math.radians(degrees[0]), math.radians(degrees[1])


def _parse_site(s: Section, t: Section) -> SiteConfig:
    site = SiteConfig(
        latitude=math.radians(s.number("latitude", at_least=-90.0, below=90.0 + 1e-9)),
        longitude=math.radians(s.number("longitude", at_least=-180.0, below=360.0)),
        elevation=s.number("elevation", 0.0, at_least=-500.0, below=10_000.0),
        start=t.utc("start"),
        end=t.utc("end"),
    )
    if not abs(site.latitude) <= math.pi / 2:  # degrees a hair above 90 pass number()
        s.fail("latitude", f"must lie in [-90, 90] degrees (got {math.degrees(site.latitude)!r})")
    if site.end < site.start:
        t.fail("end", f"must not be before time.start ({site.end.isoformat()} < {site.start.isoformat()})")
    s.done()
    t.done()
    return site


MAX_IMAGE_PIXELS = 64_000_000
"""Most pixels of the camera's picture. [pixel]"""


def _parse_camera(s: Section) -> CameraConfig:
    """The camera; what it leaves out is placed by ``framing.frame_scene``."""
    position = s.numbers("position", 3) if s.has("position") else None
    if position is not None and position[2] <= 0:
        s.fail("position", f"the camera must be above the ground (z = {position[2]:g})")
    if s.has("look_at") and (s.has("yaw") or s.has("pitch")):
        s.fail("look_at", "give either look_at or yaw and pitch, not both")
    look_at = yaw = pitch = None
    if s.has("look_at"):
        look_at = s.numbers("look_at", 3)
        if position is not None and look_at == position:
            s.fail("look_at", "must differ from camera.position")
    elif s.has("yaw") or s.has("pitch"):
        yaw = math.radians(s.number("yaw", 0.0) % 360.0)
        pitch = math.radians(s.number("pitch", 0.0, at_least=-90.0, below=90.0 + 1e-9))
    fov = math.radians(s.number("fov", above=0.0, below=170.0)) if s.has("fov") else CameraConfig.fov
    resolution = s.numbers("resolution", 2, CameraConfig.resolution)
    if not all(v.is_integer() and v >= 2 for v in resolution):
        s.fail("resolution", f"must be two whole numbers of at least 2 (got {list(resolution)})")
    width, height = (int(v) for v in resolution)
    if width * height > MAX_IMAGE_PIXELS:
        s.fail("resolution", f"{width} x {height} is {width * height:.3g} pixels; the most is {MAX_IMAGE_PIXELS:.3g}")
    stops, auto = _parse_exposure(s)
    follow = s.choice("follow", FOLLOWS, CameraConfig.follow)
    if follow == "shadow" and (position is not None or look_at is not None):
        s.fail("follow", "shadow moves the camera to keep the shadow in view: leave out camera.position "
                         "and camera.look_at (or give follow: fixed)")
    camera = CameraConfig(position, look_at, yaw, pitch, fov, (width, height), exposure=stops,
                          display=s.choice("display", DISPLAYS, CameraConfig.display), auto_exposure=auto,
                          white_balance=s.choice("white_balance", WHITE_BALANCES, CameraConfig.white_balance),
                          follow=follow)
    s.done()
    return camera


def _parse_exposure(s: Section) -> tuple[float, AutoExposureConfig | None]:
    """camera.exposure: stops (fixed), ``auto``, or ``{mode: auto, stops, time_constant,
    limits}``. Returns (stops, AutoExposureConfig or None)."""
    value = s.raw("exposure", CameraConfig.exposure)
    if value == "auto":
        return CameraConfig.exposure, AutoExposureConfig()
    if not isinstance(value, dict):
        if not is_number(value):
            s.fail("exposure", f"must be a number of stops, auto, or a mapping with mode: auto, not {kind_of(value)}")
        return s.number("exposure", CameraConfig.exposure, at_least=-20.0, below=20.0), None
    e = s.section("exposure")
    e.choice("mode", ("auto",))
    stops = e.number("stops", CameraConfig.exposure, at_least=-20.0, below=20.0)
    time_constant = e.number("time_constant", AUTO_TIME_CONSTANT, at_least=0.0, below=1e6)
    limits = e.numbers("limits", 2, AUTO_LIMITS)
    if not -30.0 <= limits[0] <= limits[1] <= 30.0:
        e.fail("limits", f"must be [least, most] stops with -30 <= least <= most <= 30 (got {list(limits)})")
    e.done()
    return stops, AutoExposureConfig(time_constant, limits)


def _parse_foreground(s: Section, canopy: CanopyConfig) -> ForegroundConfig:
    model = s.choice("model", FOREGROUNDS.names, "trees" if canopy.trees else "none")
    if model == "trees" and canopy.trees is None:
        s.fail("model", "'trees' renders the canopy's procedural grove; this canopy has mask images")
    files = {}
    for name in ("sun", "sky", "alpha"):
        if model == "passes":
            files[name] = s.mask_files(name)
            if len(files[name]) != canopy.cycle:
                s.fail(name, f"needs one file per cycle frame: {canopy.cycle}, found {len(files[name])}")
        elif s.has(name):
            s.fail(name, f"only used with model: {' or '.join(FOREGROUNDS.owners(name))} (model is {model})")
    s.done()
    return ForegroundConfig(model, **files)
