"""What a frame's files hold: its EXR's pixels, layers and attributes, in the working space of
``output.colorspace``, and its PNG's picture through ``camera.display`` or ``output.view``
(docs/runs.md, "Light passes", "Colour")."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline import __version__
from pipeline.camera.composite import display_codes, display_view
from pipeline.config.settings import Config, OutputConfig
from pipeline.core import io, ocio
from pipeline.run.folder import frame_files

if TYPE_CHECKING:
    from pipeline.stages.frame import FrameResult
    from pipeline.stages.scene import Scene

__all__ = ["frame_record", "frame_attributes", "LAYER_CHANNELS", "standard_attributes", "exr_layers",
           "in_working_space", "colour_attributes", "frame_picture"]

_RECORD = {"sunshade:config_hash": "config_hash", "sunshade:frame": "frame",
           "sunshade:sun_fraction": "sun_fraction", "sunshade:sun_azimuth_elevation": "sun",
           "sunshade:moon_azimuth_elevation": "moon", "sunshade:time_utc": "time_utc",
           "sunshade:exposure": "exposure"}


def frame_record(config: Config, frame: int, digest: str) -> dict[str, Any] | None:
    """What a done frame's EXR says of itself.

    Parameters
    ----------
    config : settings.Config
        The config.
    frame : int
        Output frame index.
    digest : str
        The config's hash both files must carry.

    Returns
    -------
    dict or None
        ``file`` (the EXR's stem), ``frame``, ``sun_fraction`` S [1], ``sun`` and ``moon``
        {azimuth, elevation} [deg], ``time_utc``, ``exposure`` [m^2/kcd]; None unless both its files
        are there and carry ``digest``.
    """
    exr, png = frame_files(config, frame)
    if not (exr.is_file() and png.is_file()):
        return None
    try:
        found = io.read_attributes(exr, list(_RECORD))
        png_hash = io.read_attributes(png, ["sunshade:config_hash"])["sunshade:config_hash"]
    except io.ImageError:
        return None
    if found["sunshade:config_hash"] != digest or png_hash != digest or found["sunshade:frame"] != frame:
        return None
    record = {_RECORD[k]: v for k, v in found.items() if v is not None}
    for key in ("sun", "moon"):
        if key in record:
            record[key] = {"azimuth": float(record[key][0]), "elevation": float(record[key][1])}
    record.pop("config_hash")
    return {"file": exr.stem, **record}


def frame_attributes(config: Config, result: FrameResult, digest: str) -> dict[str, Any]:
    """Metadata of a finished frame: what made it, and the sun and moon of that moment.

    Parameters
    ----------
    config : settings.Config
        The config.
    result : frame.FrameResult
        The finished frame.
    digest : str
        The config's hash.

    Returns
    -------
    dict
        EXR attributes under ``sunshade:`` (hash, version, frame, S [1], exposure [m^2/kcd], sun and
        moon (azimuth, elevation) [deg], UTC time), in a working space other than the rendered one
        its ``chromaticities`` and name (``sunshade:colorspace``), and ``standard_attributes`` with
        light passes.

    Raises
    ------
    ValueError
        With light passes, for a frame without its open ground's light (``FrameResult.light``).
    """
    attributes: dict[str, Any] = {
        "sunshade:config_hash": digest,
        "sunshade:version": __version__,
        "sunshade:frame": int(result.scene.frame),
        "sunshade:sun_fraction": float(result.sun_fraction),
        "sunshade:exposure": float(result.exposure),
    }
    for name, disc in (("sun", result.scene.sun), ("moon", result.scene.moon)):
        if disc is not None:
            attributes[f"sunshade:{name}_azimuth_elevation"] = (np.degrees(disc.azimuth),
                                                                np.degrees(disc.elevation))
    if result.scene.when is not None:
        attributes["sunshade:time_utc"] = result.scene.when.isoformat()
    attributes.update(colour_attributes(config.output))
    if config.output.passes:  # only then: a frame without passes keeps its bytes
        if result.light is None:
            raise ValueError(f"frame {result.scene.frame}: light passes without the open ground's light")
        attributes.update(standard_attributes(config, result.scene, result.light))
    return attributes


LAYER_CHANNELS = {"sun": ("sun.R", "sun.G", "sun.B"), "sky": ("sky.R", "sky.G", "sky.B"),
                  "alpha": ("alpha.A",), "illuminance": ("illuminance.Y",), "depth": ("depth.Z",)}
"""The EXR channels of each light pass, in the multi-layer convention (layer.channel)."""


def standard_attributes(config: Config, scene: Scene, light: dict[str, Any]) -> dict[str, Any]:
    """The EXR header of a frame with light passes (docs/runs.md, "Light passes"): OpenEXR's
    standard ``chromaticities`` (of ``output.colorspace``); for a site and time its ``latitude``,
    ``longitude`` [degrees] and ``altitude`` [m], and ``capDate`` (OpenImageIO's ``DateTime``, the frame's UTC time from
    the config, not the clock) with ``utcOffset`` 0 [s]; and under ``sunshade:`` the open
    ground's light (``lighting.open_ground_light``) [lx, EV].

    Parameters
    ----------
    config : settings.Config
        The config.
    scene : scene.Scene
        The frame's moment (its UTC time).
    light : dict
        The open ground's light (``FrameResult.light``): ``sun_lux`` and ``sky_lux`` [lx],
        ``white_balance`` [1], ``ev100`` and ``camera_ev100`` [EV] (each may be None).

    Returns
    -------
    dict
        EXR attribute name -> value.
    """
    attributes: dict[str, Any] = {"chromaticities": _chromaticities(config.output)}
    site = config.sky.site
    if site is not None:
        attributes.update({"latitude": float(np.degrees(site.latitude)),
                           "longitude": float(np.degrees(site.longitude)),
                           "altitude": float(site.elevation), "utcOffset": 0.0})
    if scene.when is not None:
        attributes["DateTime"] = scene.when.strftime("%Y:%m:%d %H:%M:%S")
    attributes.update({"sunshade:sun_lux": light["sun_lux"], "sunshade:sky_lux": light["sky_lux"],
                       "sunshade:open_ground_lux": light["sun_lux"] + light["sky_lux"],
                       "sunshade:white_balance": tuple(light["white_balance"]),
                       "sunshade:passes": ",".join(config.output.passes)})
    for name in ("ev100", "camera_ev100"):
        if light[name] is not None:
            attributes[f"sunshade:{name}"] = light[name]
    return attributes


def exr_layers(result: FrameResult, half: bool,
               output: OutputConfig | None = None) -> dict[tuple[str, ...], tuple[np.ndarray, str]] | None:
    """``io.write_exr``'s layers of a frame's light passes.

    RGB passes in the beauty's format and, with ``output``, its working space (``in_working_space``);
    single channels in float32 (lux pass half's 65504; depth is inf at the sky).

    Parameters
    ----------
    result : frame.FrameResult
        The finished frame, with its ``layers``.
    half : bool
        Whether the beauty is written in half floats.
    output : settings.OutputConfig, optional
        The output settings whose ``colorspace`` the RGB passes are written in; None: as rendered.

    Returns
    -------
    dict or None
        {channel names: (pixels, "half" or "float")} (``LAYER_CHANNELS``); None without any pass.
    """
    if not result.layers:
        return None
    return {LAYER_CHANNELS[name]: (pixels if output is None else in_working_space(output, pixels),
                                   "half" if half and pixels.shape[-1] == 3 else "float")
            for name, pixels in result.layers.items()}


def in_working_space(output: OutputConfig, pixels: np.ndarray) -> np.ndarray:
    """Scene-linear Rec.709 RGB as the EXRs hold it: in ``output.colorspace`` (docs/runs.md, "Colour").

    Parameters
    ----------
    output : settings.OutputConfig
        The output settings (``colorspace``, ``ocio_config``).
    pixels : numpy.ndarray
        (rows, cols, channels) scene-linear Rec.709 values [any linear unit].

    Returns
    -------
    numpy.ndarray
        ``pixels`` themselves in the rendered space or for other than 3 channels, else a float32
        copy converted through the OCIO config's processor.
    """
    if output.colorspace == ocio.RENDER_SPACE or pixels.shape[-1] != 3:
        return pixels
    return ocio.to_working(pixels, output.ocio_config or ocio.default_source(), output.colorspace)


def colour_attributes(output: OutputConfig) -> dict[str, Any]:
    """The EXR attributes of a working space other than the rendered one (docs/runs.md, "Colour").

    Parameters
    ----------
    output : settings.OutputConfig
        The output settings (``colorspace``, ``ocio_config``).

    Returns
    -------
    dict
        OpenEXR's ``chromaticities`` of ``output.colorspace`` and its name as ``sunshade:colorspace``;
        empty in the rendered space (whose frames keep their bytes).
    """
    if output.colorspace == ocio.RENDER_SPACE:
        return {}
    return {"chromaticities": _chromaticities(output), "sunshade:colorspace": output.colorspace}


def _chromaticities(output: OutputConfig) -> tuple[float, ...]:
    return ocio.working_space(output.ocio_config or ocio.default_source(), output.colorspace)


def frame_picture(config: Config, result: FrameResult) -> np.ndarray:
    """What a frame's PNG shows, as ``io.write_png`` takes it: exposed and white-balanced in
    scene-linear, then through ``camera.display``'s curve or ``output.view``'s OCIO view.

    Parameters
    ----------
    config : settings.Config
        The config.
    result : frame.FrameResult
        The finished frame.

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3): uint8 codes (``composite.display_codes``, the built-in curves) or float32
        display values in [0, 1] (an OCIO view).
    """
    if config.output.view is None:
        return display_codes(result.radiance, exposure=result.exposure, transform=config.camera.display,
                             balance=result.balance)
    return display_view(result.radiance, exposure=result.exposure, balance=result.balance,
                        source=config.output.ocio_config or ocio.default_source(), view=config.output.view)
