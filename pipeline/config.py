"""YAML configuration to frozen, validated values.

Angles are degrees in the YAML and radians in the values; lengths are metres. Every error names
the key path (and the YAML line where there is one) and is raised before any work starts.
File paths are relative to the folder of the config file.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from . import __version__
from .shadow import MAX_SKY_CELLS, sky_half_cells
from .sky import MODELS as SKY_MODELS

LAYOUTS = ("isolated", "periodic")
MAX_GROUND_PIXELS = 64_000_000
MAX_FFT_CELLS = 128_000_000
MAX_RADIANCE = 1e30
"""Largest radiance accepted: float32 sums of many cells must stay finite. [radiance]"""


class ConfigError(ValueError):
    """A bad configuration: ``where`` is 'file:line: key.path' or 'file: key.path'."""

    def __init__(self, where: str, message: str):
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class CanopyLayer:
    """One canopy plane.

    mask : Path -- transparency image (1 = open sky), north-up.
    size : (float, float) -- metres covered by the image, x then y. [m]
    center : (float, float) -- world x, y of the image centre. [m]
    height : float -- height of the plane above the ground. [m]
    """

    mask: Path
    size: tuple[float, float]
    center: tuple[float, float]
    height: float


@dataclass(frozen=True)
class CanopyConfig:
    layout: str
    layers: tuple[CanopyLayer, ...]


@dataclass(frozen=True)
class SkyConfig:
    """model : a name in ``sky.MODELS``; radiance : linear RGB of a uniform sky;
    hdri : equirectangular image; rotation [rad]; alpha : half-angle of the sky square [rad]."""

    model: str
    radiance: tuple[float, float, float]
    hdri: Path | None
    rotation: float
    alpha: float


@dataclass(frozen=True)
class GroundConfig:
    """window : (x_min, y_min, x_max, y_max) [m]; pixel : ground pixel [m]."""

    window: tuple[float, float, float, float]
    pixel: float


@dataclass(frozen=True)
class Config:
    path: Path
    canopy: CanopyConfig
    sky: SkyConfig
    ground: GroundConfig

    def digest(self) -> str:
        """Hash of every value and every input file's bytes, with the package version (16 hex)."""
        values = asdict(self)
        values.pop("path")
        files = sorted({str(layer.mask) for layer in self.canopy.layers} | (
            {str(self.sky.hdri)} if self.sky.hdri else set()))
        h = hashlib.sha256()
        h.update(json.dumps(values, sort_keys=True, default=str).encode())
        h.update(__version__.encode())
        for name in files:
            h.update(Path(name).read_bytes())
        return h.hexdigest()[:16]


def load_config(path) -> Config:
    """Read and validate a YAML config file; raise ConfigError naming the file and key."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(str(path), f"cannot read the config ({exc.strerror or exc})") from None
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark else str(path)
        raise ConfigError(where, f"not valid YAML ({getattr(exc, 'problem', None) or exc})") from None
    lines: dict[str, int] = {}
    _key_lines(node, "", lines, path)
    root = _Section(data if data is not None else {}, "", _Context(path, lines))
    return _parse(root, path)


@dataclass(frozen=True)
class _Context:
    path: Path
    lines: dict

    def where(self, key: str) -> str:
        line = self.lines.get(key)
        location = f"{self.path}:{line}" if line else str(self.path)
        return f"{location}: {key}" if key else location


def _key_lines(node, prefix, lines, path):
    """Record the YAML line of every key path; reject duplicate keys."""
    if isinstance(node, yaml.MappingNode):
        seen = set()
        for key_node, value_node in node.value:
            key = f"{prefix}.{key_node.value}" if prefix else str(key_node.value)
            if key in seen:
                raise ConfigError(f"{path}:{key_node.start_mark.line + 1}: {key}", "duplicate key")
            seen.add(key)
            lines[key] = key_node.start_mark.line + 1
            _key_lines(value_node, key, lines, path)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            key = f"{prefix}[{i}]"
            lines[key] = item.start_mark.line + 1
            _key_lines(item, key, lines, path)


_MISSING = object()


class _Section:
    """A mapping being read: takes keys one by one, then reports the keys nobody took."""

    def __init__(self, data, path: str, ctx: _Context):
        if not isinstance(data, dict):
            raise ConfigError(ctx.where(path), f"must be a mapping of keys, not {_kind(data)}")
        self.data, self.path, self.ctx, self.taken = data, path, ctx, set()

    def key(self, name):
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name, message):
        raise ConfigError(self.ctx.where(self.key(name)), message)

    def has(self, name):
        return name in self.data

    def raw(self, name, default=_MISSING):
        self.taken.add(name)
        if name not in self.data:
            if default is _MISSING:
                raise ConfigError(self.ctx.where(self.path or ""), f"missing key '{self.key(name)}'")
            return default
        return self.data[name]

    def section(self, name, default=_MISSING):
        value = self.raw(name, {} if default is _MISSING else default)
        return _Section(value, self.key(name), self.ctx)

    def number(self, name, default=_MISSING, *, above=None, at_least=None, below=None):
        value = self.raw(name, default)
        if not _is_number(value):
            self.fail(name, f"must be a number, not {_kind(value)}")
        value = float(value)
        if not math.isfinite(value):
            self.fail(name, f"must be a finite number (got {value})")
        if above is not None and not value > above:
            self.fail(name, f"must be above {above:g} (got {value:g})")
        if at_least is not None and not value >= at_least:
            self.fail(name, f"must be at least {at_least:g} (got {value:g})")
        if below is not None and not value < below:
            self.fail(name, f"must be below {below:g} (got {value:g})")
        return value

    def numbers(self, name, count, default=_MISSING):
        value = self.raw(name, default)
        if not (isinstance(value, (list, tuple)) and len(value) == count):
            self.fail(name, f"must be a list of {count} numbers, not {_kind(value)}")
        for item in value:
            if not _is_number(item) or not math.isfinite(float(item)):
                self.fail(name, f"must be a list of {count} finite numbers (got {value})")
        return tuple(float(v) for v in value)

    def choice(self, name, choices, default=_MISSING):
        value = self.raw(name, default)
        if value not in choices:
            self.fail(name, f"unknown value {value!r}; valid: {', '.join(choices)}")
        return value

    def file(self, name):
        value = self.raw(name)
        if not isinstance(value, str) or not value:
            self.fail(name, f"must be a file name, not {_kind(value)}")
        path = (self.ctx.path.parent / value).resolve()
        if not path.is_file():
            self.fail(name, f"no such file: {path}")
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            self.fail(name, f"cannot read {path} ({exc.strerror})")
        return path

    def done(self):
        unknown = [k for k in self.data if k not in self.taken]
        if unknown:
            valid = ", ".join(sorted(self.taken))
            self.fail(str(unknown[0]), f"unknown key (valid here: {valid})")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _kind(value) -> str:
    if value is None:
        return "nothing"
    return {dict: "a mapping", list: "a list", str: f"the text {value!r}", bool: f"{value}"}.get(
        type(value), repr(value)
    )


def _parse(root: _Section, path: Path) -> Config:
    ground = _parse_ground(root.section("ground"))
    canopy = _parse_canopy(root.section("canopy"), ground)
    sky = _parse_sky(root.section("sky"), canopy, ground)
    root.done()
    return Config(path.resolve(), canopy, sky, ground)


def _parse_ground(s: _Section) -> GroundConfig:
    window = s.numbers("window", 4, (-20.0, -20.0, 20.0, 20.0))
    if not (window[2] > window[0] and window[3] > window[1]):
        s.fail("window", f"must be [x_min, y_min, x_max, y_max] with max above min (got {list(window)})")
    pixel = s.number("pixel", 0.05, above=0.0)
    cells = ((window[2] - window[0]) / pixel) * ((window[3] - window[1]) / pixel)
    if cells > MAX_GROUND_PIXELS:
        s.fail("pixel", f"the window would be {cells:.3g} pixels; the most is {MAX_GROUND_PIXELS:.3g}")
    s.done()
    return GroundConfig(window, pixel)


def _parse_canopy(s: _Section, ground: GroundConfig) -> CanopyConfig:
    layout = s.choice("layout", LAYOUTS, "isolated")
    base = _parse_layer(s, {}, ground, layout, mask_required=not s.has("layers"))
    if not s.has("layers"):
        layers = [base]
    else:
        items = s.raw("layers")
        if not isinstance(items, list) or not items:
            s.fail("layers", f"must be a non-empty list of mappings, not {_kind(items)}")
        layers = []
        for i, item in enumerate(items):
            ls = _Section(item, s.key(f"layers[{i}]"), s.ctx)
            layers.append(_parse_layer(ls, base, ground, layout, mask_required=base["mask"] is None))
            ls.done()
    s.done()
    return CanopyConfig(layout, tuple(CanopyLayer(**layer) for layer in layers))


def _parse_layer(s: _Section, base: dict, ground: GroundConfig, layout: str, *, mask_required):
    """One canopy plane's keys, each defaulting to ``base``'s; its rasters checked for size."""
    if s.has("mask") or mask_required:
        mask = s.file("mask")
    else:
        mask = base.get("mask")
    size = s.numbers("size", 2, base.get("size", (20.0, 20.0)))
    if min(size) <= 0:
        s.fail("size", f"both sides must be above 0 (got {list(size)})")
    layer = {
        "mask": mask,
        "size": size,
        "center": s.numbers("center", 2, base.get("center", (0.0, 0.0))),
        "height": s.number("height", base.get("height", 8.0), above=0.0),
    }
    pixels = [side / ground.pixel for side in size]
    if pixels[0] * pixels[1] > MAX_GROUND_PIXELS:
        s.fail("size", f"the canopy would be {pixels[0] * pixels[1]:.3g} pixels at ground.pixel "
               f"{ground.pixel:g} m; the most is {MAX_GROUND_PIXELS:.3g}")
    if layout == "periodic":
        for ratio in pixels:
            if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio) or round(ratio) < 1:
                s.fail("size", f"a periodic tile must be a whole number of ground pixels "
                       f"({ratio * ground.pixel:g} / {ground.pixel:g} = {ratio:.4g})")
    else:
        window = ground.window
        fft = ((window[2] - window[0]) / ground.pixel + pixels[0]) * (
            (window[3] - window[1]) / ground.pixel + pixels[1])
        if fft > MAX_FFT_CELLS:
            s.fail("size", f"canopy and window together need a {fft:.3g}-cell transform; "
                   f"the most is {MAX_FFT_CELLS:.3g}: raise ground.pixel")
    return layer


def _parse_sky(s: _Section, canopy: CanopyConfig, ground: GroundConfig) -> SkyConfig:
    model = s.choice("model", tuple(SKY_MODELS), "uniform")
    for key, owner in (("radiance", "uniform"), ("hdri", "hdri"), ("rotation", "hdri")):
        if s.has(key) and model != owner:
            s.fail(key, f"only used with model: {owner} (model is {model})")
    radiance = (1.0, 1.0, 1.0)
    hdri = None
    if model == "uniform":
        if _is_number(s.raw("radiance", 1.0)):
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
    if canopy.layout == "periodic":
        for layer in canopy.layers:
            n = 2 * sky_half_cells(layer.height, ground.pixel, alpha) + 1
            if n * n > MAX_SKY_CELLS:
                s.fail("alpha", f"the sky square at {alpha_deg:g} degrees would be {n} x {n} cells "
                       f"for a {ground.pixel:g} m pixel; lower alpha or raise ground.pixel")
    s.done()
    return SkyConfig(model, radiance, hdri, rotation, alpha)
