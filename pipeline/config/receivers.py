"""The ``receivers`` section of a config: walls, and a sloped ground, lit as the level ground is
(docs/method.md, "Receivers: walls and slopes"). Parsed here with the errors of the rest of the
config (the key named, nothing written); the planes and their light are ``pipeline.receivers``'.
Angles are degrees in the YAML and radians in the values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pipeline.config.sections import Section, is_number, kind_of

__all__ = ["WALL_ALBEDOS", "MAX_WALL_CELLS", "DEFAULT_WALL_PIXEL", "ReceiverMask", "WallConfig", "SlopeConfig",
           "ReceiversConfig", "parse_receivers"]

WALL_ALBEDOS = {"plaster": (0.80, 0.75, 0.70), "brick": (0.25, 0.10, 0.07)}
"""A wall's preset albedos (linear RGB), docs/method.md "Receivers": ``plaster`` is the white
plaster of Radiance's materials library (Ward Larson & Shakespeare 1998, ``plaster_white``;
luminance 0.76, within the 0.70-0.80 lighting tables give white plaster); ``brick`` a new red
brick, luminance 0.13 within the 0.10-0.15 those tables give (its hue a choice). [1]"""

MAX_WALL_CELLS = 4096 * 4096
"""Most cells of a wall's fine raster (``receivers.walls[].pixel``). [count]"""

DEFAULT_WALL_PIXEL = 0.01
"""A wall's fine raster's pixel when none is given. [m]"""


@dataclass(frozen=True)
class ReceiverMask:
    """An image mask parallel to a receiver (a trellis, a pergola, a grille): 1 = open.

    Attributes
    ----------
    image : Path
        One channel of transmittance, rows along -w (upright as one faces the wall).
    center : (float, float)
        (u, w) of its centre on the receiver [m].
    size : (float, float)
        Its (u, w) extent [m].
    distance : float
        Of its plane along the receiver's normal [m].
    """

    image: Path
    center: tuple[float, float]
    size: tuple[float, float]
    distance: float


@dataclass(frozen=True)
class WallConfig:
    """A wall: a rectangle standing on its foot and facing an azimuth.

    Attributes
    ----------
    name : str
        Its name (``sunshade ground --receiver NAME``); default ``wall0``, ``wall1``...
    foot : (float, float, float)
        World point of the middle of its bottom edge [m].
    facing : float
        Azimuth of its outward normal, from north towards east [rad].
    width, height : float
        Its extent along u and up along w [m].
    tilt : float
        Its lean back from vertical, in (-pi/2, pi/2) [rad].
    albedo : str, (float, float, float) or Path
        A preset of ``WALL_ALBEDOS``, a linear RGB colour, or an image tiled over the wall.
    albedo_size : float
        Wall covered by the image's width [m].
    pixel : float
        Its fine raster's pixel [m].
    masks : tuple of ReceiverMask
        Mask layers parallel to it.
    """

    name: str
    foot: tuple[float, float, float]
    facing: float
    width: float
    height: float
    tilt: float = 0.0
    albedo: str | tuple[float, float, float] | Path = "plaster"
    albedo_size: float = 1.0
    pixel: float = DEFAULT_WALL_PIXEL
    masks: tuple[ReceiverMask, ...] = ()


@dataclass(frozen=True)
class SlopeConfig:
    """The ground tilted towards an azimuth (a hillside).

    Attributes
    ----------
    tilt : float
        The slope, in [0, pi/2) [rad].
    facing : float
        Azimuth it falls towards, from north towards east [rad].
    """

    tilt: float
    facing: float


@dataclass(frozen=True)
class ReceiversConfig:
    """The receivers besides the level ground; none by default.

    Attributes
    ----------
    walls : tuple of WallConfig
        The walls.
    slope : SlopeConfig or None
        The sloped ground; None: the level ground.
    """

    walls: tuple[WallConfig, ...] = ()
    slope: SlopeConfig | None = None


def parse_receivers(s: Section) -> ReceiversConfig:
    """The ``receivers`` section: ``walls`` (a list) and ``slope``.

    Parameters
    ----------
    s : sections.Section
        The section (empty when the config has none).

    Returns
    -------
    ReceiversConfig
        Its values, angles in radians.

    Raises
    ------
    ConfigError
        Naming the key of the first bad value.
    """
    items = s.raw("walls", [])
    if not isinstance(items, list):
        s.fail("walls", f"must be a list of mappings, not {kind_of(items)}")
    walls = []
    for i, item in enumerate(items):
        w = Section(item, s.key(f"walls[{i}]"), s.ctx)
        walls.append(_parse_wall(w, i))
        w.done()
    names = [w.name for w in walls]
    for i, name in enumerate(names):
        if name in names[:i]:
            s.fail(f"walls[{i}].name", f"names a wall that walls[{names.index(name)}] names too ({name!r})")
    slope = None
    if s.raw("slope", None) is not None:
        t = s.section("slope")
        slope = SlopeConfig(math.radians(t.number("tilt", at_least=0.0, below=90.0)),
                            math.radians(t.number("facing")))
        t.done()
    s.done()
    return ReceiversConfig(tuple(walls), slope)


def _parse_wall(w: Section, index: int) -> WallConfig:
    name = w.raw("name", f"wall{index}")
    if not (isinstance(name, str) and name and all(c.isalnum() or c in "-_" for c in name)):
        w.fail("name", f"must be a name of letters, digits, - and _ (got {kind_of(name)})")
    foot = w.raw("foot")
    if not (isinstance(foot, list) and len(foot) in (2, 3) and all(is_number(v) for v in foot)
            and all(math.isfinite(float(v)) for v in foot)):
        w.fail("foot", f"must be [x, y] or [x, y, z], finite numbers [m] (got {kind_of(foot)})")
    x, y, z = (float(v) for v in (*foot, 0.0)[:3])
    width, height = w.number("width", above=0.0), w.number("height", above=0.0)
    pixel = w.number("pixel", DEFAULT_WALL_PIXEL, above=0.0)
    cells = math.ceil(width / pixel) * math.ceil(height / pixel)
    if cells > MAX_WALL_CELLS:
        w.fail("pixel", f"{pixel:g} m makes {cells:.3g} cells on a {width:g} x {height:g} m wall; "
               f"the most is {MAX_WALL_CELLS:.3g}")
    albedo = _parse_albedo(w)
    albedo_size = w.number("albedo_size", WallConfig.albedo_size, above=0.0)
    masks = w.raw("masks", [])
    if not isinstance(masks, list):
        w.fail("masks", f"must be a list of mappings, not {kind_of(masks)}")
    layers = []
    for i, item in enumerate(masks):
        m = Section(item, w.key(f"masks[{i}]"), w.ctx)
        layers.append(ReceiverMask(m.file("image"), m.numbers("center", 2, (0.0, height / 2)),
                                   m.numbers("size", 2), m.number("distance", above=0.0)))
        if not all(v > 0 for v in layers[-1].size):
            m.fail("size", f"must be two positive numbers (u, w) [m] (got {list(layers[-1].size)})")
        m.done()
    return WallConfig(name, (x, y, z), math.radians(w.number("facing")), width, height,
                      math.radians(w.number("tilt", 0.0, above=-90.0, below=90.0)), albedo, albedo_size, pixel,
                      tuple(layers))


def _parse_albedo(w: Section) -> str | tuple[float, float, float] | Path:
    """A wall's albedo: a preset's name, [r, g, b] in [0, 1], or an image file."""
    value = w.raw("albedo", WallConfig.albedo)
    if isinstance(value, list):
        rgb = w.numbers("albedo", 3)
        if not all(0.0 <= v <= 1.0 for v in rgb):
            w.fail("albedo", f"a colour must be [r, g, b] in [0, 1] (got {list(rgb)})")
        return rgb
    if isinstance(value, str) and value in WALL_ALBEDOS:
        return value
    if isinstance(value, str) and "." not in value:
        w.fail("albedo", f"unknown preset {value!r}; valid: {', '.join(WALL_ALBEDOS)}, [r, g, b] or an image file")
    return w.file("albedo")
