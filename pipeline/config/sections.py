"""A config's mappings read key by key, every value checked as it is taken.

``Section`` takes a mapping's keys one by one (numbers with their limits and
``vocabulary.NUMBER_RANGES``, lists, choices, times in UTC, files relative to the config's
folder), then reports the keys nobody took with those ``_VALID_KEYS`` allows; every error names
the key path and its YAML line. Only ``parse``'s parsers use it: it has no public names.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal, NoReturn, overload

from pipeline.config.vocabulary import NUMBER_RANGES, SKIES, TIME_RANGE
from pipeline.config.yamlsafe import KeyContext
from pipeline.core import paths
from pipeline.core.errors import ConfigError

__all__: list[str] = []


_MISSING = object()


class Section:
    """A mapping being read: takes keys one by one, then reports the keys nobody took."""

    def __init__(self, data: object, path: str, ctx: KeyContext) -> None:
        if not isinstance(data, dict):
            raise ConfigError(ctx.where(path), f"must be a mapping of keys, not {kind_of(data)}")
        self.data: dict[Any, Any] = data
        self.path, self.ctx = path, ctx
        self.taken: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, message: str) -> NoReturn:
        raise ConfigError(self.ctx.where(self.key(name)), message)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: Any = _MISSING) -> Any:
        self.taken.add(name)
        if name not in self.data:
            if default is _MISSING:
                raise ConfigError(self.ctx.where(self.path or ""), f"missing key '{self.key(name)}'")
            return default
        return self.data[name]

    def section(self, name: str, default: Any = _MISSING) -> Section:
        value = self.raw(name, {} if default is _MISSING else default)
        return Section(value, self.key(name), self.ctx)

    def number(self, name: str, default: Any = _MISSING, *, above: float | None = None,
               at_least: float | None = None, below: float | None = None) -> float:
        value = self.raw(name, default)
        if not is_number(value):
            self.fail(name, f"must be a number, not {kind_of(value)}")
        value = float(value)
        if not math.isfinite(value):
            self.fail(name, f"must be a finite number (got {value})")
        if above is not None and not value > above:
            self.fail(name, f"must be above {above:g} (got {value:g})")
        if at_least is not None and not value >= at_least:
            self.fail(name, f"must be at least {at_least:g} (got {value:g})")
        if below is not None and not value < below:
            self.fail(name, f"must be below {below:g} (got {value:g})")
        self.in_range(name, value)
        return value

    def in_range(self, name: str, value: float) -> None:
        """Fail naming the key and its range if ``value`` lies outside NUMBER_RANGES."""
        limits = NUMBER_RANGES.get(re.sub(r"\[\d+\]", "[]", self.key(name)))
        if limits is not None and not limits[0] <= value <= limits[1]:
            least, most, got = (str(v) if isinstance(v, int) else f"{v:g}" if isinstance(v, float) else v
                                 for v in (*limits[:2], value))
            self.fail(name, f"must lie in [{least}, {most}]{' ' + limits[2] if limits[2] else ''} (got {got})")

    @overload
    def numbers(self, name: str, count: Literal[2], default: Any = ...) -> tuple[float, float]: ...
    @overload
    def numbers(self, name: str, count: Literal[3], default: Any = ...) -> tuple[float, float, float]: ...
    @overload
    def numbers(self, name: str, count: Literal[4], default: Any = ...) -> tuple[float, float, float, float]: ...
    @overload
    def numbers(self, name: str, count: int, default: Any = ...) -> tuple[float, ...]: ...
    def numbers(self, name: str, count: int, default: Any = _MISSING) -> tuple[float, ...]:
        value = self.raw(name, default)
        if not (isinstance(value, (list, tuple)) and len(value) == count):
            got = f"a list of {len(value)}" if isinstance(value, (list, tuple)) else kind_of(value)
            self.fail(name, f"must be a list of {count} numbers, not {got}")
        for item in value:
            if not is_number(item) or not math.isfinite(float(item)):
                self.fail(name, f"must be a list of {count} finite numbers (got {value})")
            self.in_range(name, float(item))
        return tuple(float(v) for v in value)

    def integer(self, name: str, default: Any = _MISSING, *, at_least: int | None = None) -> int:
        value = self.raw(name, default)
        if not (is_number(value) and float(value).is_integer()):
            self.fail(name, f"must be a whole number, not {kind_of(value)}")
        if at_least is not None and value < at_least:
            self.fail(name, f"must be at least {at_least} (got {int(value)})")
        self.in_range(name, value)
        return int(value)

    def utc(self, name: str) -> datetime:
        value = self.raw(name)
        if isinstance(value, str):
            try:
                value = datetime.fromisoformat(value.replace("Z", "+00:00"))
            except ValueError:
                self.fail(name, f"must be a time like \"2024-04-08T18:20:00Z\" (got {value!r})")
        if not isinstance(value, datetime):
            self.fail(name, f"must be a time like \"2024-04-08T18:20:00Z\", not {kind_of(value)}")
        if value.tzinfo is None:
            self.fail(name, "must say its time zone, e.g. end in Z for UTC")
        first, last = (datetime.fromisoformat(t) for t in TIME_RANGE)
        try:
            utc = value.astimezone(UTC)
        except OverflowError:
            utc = None
        if utc is None or not first <= utc <= last:
            self.fail(name, f"must lie from {TIME_RANGE[0][:19]}Z to {TIME_RANGE[1][:19]}Z in UTC, its "
                      f"offset applied (got {value.isoformat()})")
        return utc

    def mask_files(self, name: str) -> tuple[Path, ...]:
        """One image, or a numbered sequence ``leaves.%04d.png`` from frame 0 (or 1) on."""
        value = self.raw(name)
        if not isinstance(value, str) or "%" not in value:
            return (self.file(name),)
        self.check_path(name, value)
        pattern = self.resolved(name, value)
        widths = re.findall(r"%[-#0 +]*(\d*)(?:\.(\d*))?", value)
        if any(int(n or 0) > paths.NAME_MAX for field in widths for n in field):
            self.fail(name, f"a number field of width {max(int(n or 0) for f in widths for n in f)} "
                      f"makes names longer than the most, {paths.NAME_MAX} bytes")
        try:
            names = [Path(str(pattern) % i) for i in range(2)]
        except (TypeError, ValueError):
            self.fail(name, f"a sequence needs one number field like %04d (got {paths.shown(value)!r})")
        first = next((i for i, n in enumerate(names) if n.is_file()), None)
        if first is None:
            self.fail(name, f"no such files: {paths.shown(names[0])} or {paths.shown(names[1])}")
        frames: list[Path] = []
        while Path(str(pattern) % (first + len(frames))).is_file():
            frames.append(Path(str(pattern) % (first + len(frames))))
        return tuple(frames)

    def choice(self, name: str, choices: Collection[str], default: Any = _MISSING) -> str:
        value = self.raw(name, default)
        if value not in choices:
            read = " (YAML reads yes, no, on and off as true and false: quote the word)" if isinstance(
                value, bool) else ""
            self.fail(name, f"unknown value {value!r}{read}; valid: {', '.join(choices)}")
        return value

    def file(self, name: str) -> Path:
        value = self.raw(name)
        if not isinstance(value, str) or not value:
            self.fail(name, f"must be a file name, not {kind_of(value)}")
        self.check_path(name, value)
        path = self.resolved(name, value)
        if (why := paths.not_a_file(path)) is not None:
            self.fail(name, f"{why}: {path}")
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            self.fail(name, f"cannot read {path} ({exc.strerror})")
        return path

    def check_path(self, name: str, value: object) -> None:
        """Fail naming the key if ``value`` cannot be a path (see ``paths.problem``)."""
        if problem := paths.problem(value):
            self.fail(name, problem)

    def resolved(self, name: str, value: str) -> Path:
        """``value`` relative to the config's folder, made absolute, the whole path checked
        (the folder too may hold bytes that are not UTF-8)."""
        path = (self.ctx.path.parent / value).resolve()
        self.check_path(name, path)
        return path

    def done(self) -> None:
        self._fail_unknown(self.taken)

    def known_first(self) -> None:
        """``done``'s check before any value is read, for a section whose keys are all known
        beforehand (the top level): a misspelled section is said first, not after an error in
        the values of another (a config copied away from the files it names)."""
        self._fail_unknown(set(_VALID_KEYS[self.path]))

    def _fail_unknown(self, known: set[str]) -> None:
        """Fail naming the first key not in ``known``."""
        unknown = [k for k in self.data if k not in known]
        if unknown:
            pattern = re.sub(r"\[\d+\]", "[]", self.path)
            valid = ", ".join(sorted(known | set(_VALID_KEYS.get(pattern, ()))))
            self.fail(str(unknown[0]), f"unknown key (valid here: {valid})")


_VALID_KEYS = {
    "": ("animation", "ground", "canopy", "sky", "camera", "foreground", "output", "render", "receivers"),
    "canopy": ("layout", "trees", "flutter", "mask", "size", "center", "height", "layers", "mesh"),
    "canopy.mesh": ("file", "scale", "position", "rotation", "up", "leaves", "wood", "max_triangles", "seed"),
    "canopy.mesh[]": ("file", "scale", "position", "rotation", "up", "leaves", "wood", "max_triangles", "seed"),
    "canopy.layers[]": ("mask", "size", "center", "height"),
    "canopy.trees": ("count", "seed", "crown_radius", "leaves_per_tree", "leaf_length", "spread"),
    "canopy.flutter": ("cycle", "swing", "twist"),
    "sky": ("model", "alpha", "haze", *SKIES.owned_keys()),
    "sky.sun": ("elevation", "azimuth", "radius"),
    "sky.moon": ("offset_start", "offset_end", "radius"),
    "sky.clouds": ("cover", "scale", "altitude", "wind", "thickness", "seed"),
    "sky.site": ("latitude", "longitude", "elevation"),
    "sky.time": ("start", "end"),
    "ground": ("window", "pixel", "sun_window", "sun_pixel", "albedo", "albedo_size", "brdf"),
    "ground.brdf": ("model", "rho0", "k", "theta", "rho_c", "f_iso", "f_vol", "f_geo"),
    "camera": ("position", "look_at", "yaw", "pitch", "fov", "resolution", "exposure", "display",
               "white_balance", "follow"),
    "camera.exposure": ("mode", "stops", "time_constant", "limits"),
    "foreground": ("model", "sun", "sky", "alpha"),
    "animation": ("frames", "fps"),
    "output": ("name", "folder", "video", "half", "passes", "report", "colorspace", "view", "ocio_config"),
    "output.view": ("display", "view"),
    "render": ("jobs", "sun_cells"),
    "receivers": ("walls", "slope"),
    "receivers.walls[]": ("name", "foot", "facing", "width", "height", "tilt", "albedo", "albedo_size", "pixel",
                          "masks"),
    "receivers.walls[].masks[]": ("image", "center", "size", "distance"),
    "receivers.slope": ("tilt", "facing"),
}
"""Every key each section accepts (a layer's index written []), whichever the parser reads:
what an unknown-key error lists."""


def is_number(value: object) -> bool:
    """An int or float (not a bool); an int too big for a float is not one."""
    return isinstance(value, float) or (isinstance(value, int) and not isinstance(value, bool)
                                        and abs(value) < 10**300)


def kind_of(value: object) -> str:
    if value is None:
        return "nothing"
    text = {dict: "a mapping", list: "a list", str: f"the text {value!r}", bool: f"{value}"}.get(
        type(value), repr(value)
    )
    return text if len(text) <= 80 else f"{text[:60]}... ({len(text)} characters)"
