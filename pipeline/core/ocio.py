"""Colour through OpenColorIO: the EXRs' working space and the display views (docs/runs.md, "Colour").

The renderer works in scene-linear Rec.709 (``colour``). An OCIO config, the built-in ACES
studio config or a user's, converts the linear EXR layers into another scene-linear space and
the exposed frame into a display and view for the PNGs. PyOpenColorIO (and numpy) are imported
inside the functions: a config without these keys never loads it, and the module stays cheap to
import for the config layer.
"""

from __future__ import annotations

import functools
import os
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

__all__ = ["BUILTIN_CONFIG", "OCIO_ENV", "RENDER_SPACE", "CHROMATICITIES", "VIDEO_TAGS", "OcioError",
           "default_source", "config_name", "working_space", "check_view", "to_working", "apply_view",
           "video_tags"]

BUILTIN_CONFIG = "ocio://studio-config-latest"
"""The OCIO config used when neither ``output.ocio_config`` nor $OCIO names one: the ACES studio
config built into OpenColorIO 2.x (its version follows the library's)."""

OCIO_ENV = "OCIO"
"""The environment variable every OCIO application reads for its config file."""

RENDER_SPACE = "lin_rec709"
"""The renderer's own space, scene-linear Rec.709 (D65), as the ACES configs name it (an alias of
'Linear Rec.709 (sRGB)'): the EXRs stay as rendered, byte for byte, in it."""

_REC709 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
_D60 = (0.32168, 0.33767)

CHROMATICITIES = {
    "lin_rec709_scene": _REC709,
    "lin_ap1_scene": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, *_D60),
    "lin_ap0_scene": (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.0770, *_D60),
    "lin_p3d65_scene": (0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290),
    "lin_rec2020_scene": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290),
}
"""OpenEXR's chromaticities (red x, y, green x, y, blue x, y, white x, y) of the scene-linear spaces
an EXR may be written in, by their colour-interop id: Rec.709 (ITU-R BT.709-6), ACES AP1 (ACEScg)
and AP0 (ACES2065-1) with the ACES white (SMPTE ST 2065-1), P3-D65 (SMPTE EG 432-1), Rec.2020
(ITU-R BT.2020-2)."""

_KNOWN_NAMES = {
    "lin_rec709_scene": ("lin_rec709", "linear rec.709 (srgb)", "utility - linear - srgb", "lin_srgb", "linear"),
    "lin_ap1_scene": ("acescg", "lin_ap1", "aces - acescg"),
    "lin_ap0_scene": ("aces2065-1", "lin_ap0", "aces - aces2065-1"),
    "lin_p3d65_scene": ("lin_p3d65", "linear p3-d65"),
    "lin_rec2020_scene": ("lin_rec2020", "linear rec.2020"),
}
"""Names and aliases by which a config without interop ids (OCIO before 2.5) gives those spaces."""

VIDEO_TAGS = {"srgb_rec709_display": "bt709", "g24_rec709_display": "bt709", "g22_rec709_display": "bt709"}
"""The displays, by interop id, whose pictures a video tags as BT.709 (primaries, transfer, matrix):
sRGB, Rec.1886 and gamma 2.2 Rec.709 displays share the BT.709 primaries and white. [name]"""


class OcioError(ValueError):
    """An OCIO config, colour space, display or view that cannot be used: ``str(error)`` says why,
    without the key, which the caller names."""


def default_source() -> str:
    """The OCIO config a config that names none uses: $OCIO where set, else ``BUILTIN_CONFIG``.

    Returns
    -------
    str
        A file path or an ``ocio://`` URI.
    """
    return os.environ.get(OCIO_ENV) or BUILTIN_CONFIG


@functools.lru_cache(maxsize=8)
def _config(source: str) -> Any:
    """The OCIO config of ``source`` (a path or an ``ocio://`` URI), read once per process."""
    import PyOpenColorIO as ocio  # 16 ms to import: only for a config that asks for it

    try:
        if source.startswith("ocio://"):
            return ocio.Config.CreateFromBuiltinConfig(source.removeprefix("ocio://"))
        return ocio.Config.CreateFromFile(source)
    except Exception as exc:  # PyOpenColorIO.Exception, or the file's own error
        raise OcioError(f"cannot read the OCIO config {source} ({_first_line(exc)})") from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


def config_name(source: str) -> str:
    """The name of an OCIO config as it says itself (for a built-in one, its versioned name).

    Parameters
    ----------
    source : str
        A file path or an ``ocio://`` URI.

    Returns
    -------
    str
        Its ``name`` ('studio-config-v4.0.0_aces-v2.0_ocio-v2.5', ...), or ``source`` if it has none.

    Raises
    ------
    OcioError
        When it cannot be read.
    """
    return str(_config(source).getName() or source)


def _interop(space: Any) -> str | None:
    """Which of ``CHROMATICITIES``' spaces an OCIO colour space is, by its interop id or names."""
    found = getattr(space, "getInteropID", lambda: "")() or ""
    if found in CHROMATICITIES:
        return found
    names = {space.getName().lower(), *(a.lower() for a in space.getAliases())}
    return next((key for key, known in _KNOWN_NAMES.items() if names & set(known)), None)


def _space(source: str, interop: str) -> str:
    """The name, in the config of ``source``, of the space with interop id ``interop``."""
    config = _config(source)
    for space in config.getColorSpaces():
        if _interop(space) == interop:
            return str(space.getName())
    raise OcioError(f"the OCIO config {source} has no {interop.removesuffix('_scene')} colour space "
                    "(the renderer's scene-linear Rec.709)")


def working_space(source: str, name: str) -> tuple[float, ...]:
    """Check that ``name`` is a scene-linear space of known primaries in the config; its chromaticities.

    Parameters
    ----------
    source : str
        The OCIO config: a file path or an ``ocio://`` URI.
    name : str
        A colour space (or alias) of that config, e.g. 'ACEScg'.

    Returns
    -------
    tuple of float
        OpenEXR's chromaticities (8 values) of the space [1].

    Raises
    ------
    OcioError
        Naming the valid ones, for a space the config lacks or whose primaries are not known here.
    """
    if name == RENDER_SPACE:
        return _REC709
    space = _config(source).getColorSpace(name)
    if space is None:
        raise OcioError(f"no colour space {name!r} in the OCIO config {source}")
    interop = _interop(space)
    if interop is None:
        known = ", ".join(sorted(k.removesuffix("_scene") for k in CHROMATICITIES))
        raise OcioError(f"{name!r} is not a scene-linear space whose primaries the EXR header can give "
                        f"(those with the interop ids {known})")
    _space(source, "lin_rec709_scene")
    return CHROMATICITIES[interop]


def check_view(source: str, display: str, view: str) -> None:
    """Check that the config has ``display`` with ``view``, and a scene-linear Rec.709 space to view from.

    Parameters
    ----------
    source : str
        The OCIO config: a file path or an ``ocio://`` URI.
    display, view : str
        A display of the config and one of its views.

    Raises
    ------
    OcioError
        Naming the valid ones.
    """
    config = _config(source)
    displays = list(config.getDisplays())
    if display not in displays:
        raise OcioError(f"unknown display {display!r} in the OCIO config {source}; valid: {', '.join(displays)}")
    views = list(config.getViews(display))
    if view not in views:
        raise OcioError(f"unknown view {view!r} of display {display!r}; valid: {', '.join(views)}")
    _space(source, "lin_rec709_scene")


@functools.lru_cache(maxsize=16)
def _processor(source: str, target: str | None, display: str = "", view: str = "") -> Any:
    """The CPU processor from the renderer's space to ``target`` or to ``display`` and ``view``;
    None where it does nothing."""
    import PyOpenColorIO as ocio

    config = _config(source)
    origin = _space(source, "lin_rec709_scene")
    if target is not None:
        processor = config.getProcessor(origin, target)
    else:
        processor = config.getProcessor(origin, display, view, ocio.TRANSFORM_DIR_FORWARD)
    return None if processor.isNoOp() else processor.getDefaultCPUProcessor()


def _applied(pixels: np.ndarray, processor: Any) -> np.ndarray:
    """A float32 copy of (..., 3) ``pixels`` through ``processor``."""
    import numpy as np

    out = np.array(pixels, dtype=np.float32, order="C")
    if processor is not None:
        processor.applyRGB(out.reshape(-1, 3))
    return out


def to_working(pixels: np.ndarray, source: str, name: str) -> np.ndarray:
    """Scene-linear Rec.709 RGB converted into the working space ``name``.

    Parameters
    ----------
    pixels : numpy.ndarray
        (..., 3) scene-linear Rec.709 RGB [any linear unit].
    source : str
        The OCIO config: a file path or an ``ocio://`` URI.
    name : str
        The working space (``working_space`` checks it); ``RENDER_SPACE``: ``pixels`` as they are.

    Returns
    -------
    numpy.ndarray
        (..., 3) float32 RGB in ``name``, the same unit; ``pixels`` itself for ``RENDER_SPACE``.
    """
    if name == RENDER_SPACE:
        return pixels
    return _applied(pixels, _processor(source, name))


def apply_view(exposed: np.ndarray, source: str, display: str, view: str) -> np.ndarray:
    """Exposed scene-linear Rec.709 RGB through an OCIO display and view, clipped to [0, 1].

    Parameters
    ----------
    exposed : numpy.ndarray
        (..., 3) exposed and white-balanced scene-linear Rec.709 RGB (1: a white ground) [1].
    source : str
        The OCIO config: a file path or an ``ocio://`` URI.
    display, view : str
        A display of the config and one of its views (``check_view``).

    Returns
    -------
    numpy.ndarray
        (..., 3) float32 display code values in [0, 1] [1].
    """
    import numpy as np

    out = _applied(exposed, _processor(source, None, display, view))
    return np.clip(out, 0.0, 1.0, out=out)


def video_tags(source: str | None, display: str | None) -> str | None:
    """The colour tags of a video of a display's pictures: 'bt709' (primaries, transfer and matrix)
    for the sRGB-like displays (``VIDEO_TAGS``), None (untagged) for others.

    Parameters
    ----------
    source : str or None
        The OCIO config; None with ``display`` None: the built-in sRGB curves (``composite.display``).
    display : str or None
        The display of the config; None: the built-in sRGB curves.

    Returns
    -------
    str or None
        The ffmpeg colour name of all three tags, or None.
    """
    if display is None or source is None:
        return "bt709"
    config = _config(source)
    name = config.getDisplayViewColorSpaceName(display, config.getDefaultView(display))
    if name == "<USE_DISPLAY_NAME>":
        name = display
    space = config.getColorSpace(name)
    interop = getattr(space, "getInteropID", lambda: "")() if space is not None else ""
    return VIDEO_TAGS.get(interop or "", "bt709" if "srgb" in display.lower() else None)
