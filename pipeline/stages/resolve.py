"""The config resolved for a run: checked against the compute limits and the sun over its time
span, ``turbidity: auto`` looked up. The first step of the plan stage (docs/design.md, "Stages").

The physics a check needs is imported only when a config asks for it (a site and time, a
periodic forest, an automatic turbidity), so that a command on a config with an explicit sun,
a resume with nothing to do among them, starts in a fraction of a second.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import replace

from pipeline.config.parse import load_config, size_text
from pipeline.config.settings import Config, SiteConfig
from pipeline.config.vocabulary import TURBIDITY_RANGE
from pipeline.core.errors import ConfigError

__all__ = ["MAX_GROUND_PIXELS", "MAX_FFT_CELLS", "MAX_SUN_PIXELS", "BYTES_PER_CELL", "MIN_SUN_ELEVATION",
           "SUN_SPAN_SAMPLES", "load", "source_digest", "resolve"]

MAX_GROUND_PIXELS = 64_000_000
"""Most pixels of the coarse ground raster, and of a canopy plane's mask. [1]"""
MAX_FFT_CELLS = 128_000_000
"""Most cells of any transform. [1]"""
MAX_SUN_PIXELS = 16_000_000
"""Most pixels of the sun's fine ground raster. [1]"""
BYTES_PER_CELL = 52
"""Memory a raster cell takes while a frame is made, for the messages. [B]"""
MIN_SUN_ELEVATION = math.radians(-6.0)
"""The lowest sun a site's time span may reach: the end of civil twilight, the lowest the
procedural sky models (``daylight.TWILIGHT_END``); below the horizon the sky alone lights the
ground (docs/method.md, "Twilight and a sun at the horizon"). [rad]"""
SUN_SPAN_SAMPLES = 20_000
"""Most moments at which the sun is checked over a site's time span. [count]"""


def load(path: str | os.PathLike[str]) -> Config:
    """A config file read, validated and resolved (``resolve``): what every command runs.

    Parameters
    ----------
    path : str or os.PathLike
        The config's YAML file.

    Returns
    -------
    settings.Config
        The resolved config.

    Raises
    ------
    ConfigError
        Naming the file and key.
    """
    return resolve(load_config(path))


def source_digest(config: Config) -> str:
    """Hash of what ``resolve`` makes of a config.

    The config as written and, with ``turbidity: auto``, the version of pvlib whose climatology is
    looked up. A run records it beside the resolved config's hash, so that a resume with nothing
    to do knows that hash without resolving (docs/runs.md, "Resume").

    Parameters
    ----------
    config : settings.Config
        The config as read, before ``resolve``.

    Returns
    -------
    str
        16 hex digits of a SHA-256.
    """
    parts = [config.digest()]
    if config.sky.site is not None and config.sky.turbidity is None:
        from importlib import metadata

        parts.append(f"pvlib {metadata.version('pvlib')}")
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


def resolve(config: Config) -> Config:
    """The config checked against the compute limits and the sun's path, ``turbidity: auto`` looked up.

    The limits are MAX_GROUND_PIXELS, MAX_SUN_PIXELS and MAX_FFT_CELLS; a site's sun must stay above
    MIN_SUN_ELEVATION over the time span; an automatic turbidity is the Linke climatology's at the
    site and the middle of the time span, within TURBIDITY_RANGE.

    Parameters
    ----------
    config : settings.Config
        The config as read (``parse.load_config``, ``parse.parse_config``).

    Returns
    -------
    settings.Config
        The same config, with the turbidity filled in when it was ``auto``.

    Raises
    ------
    ConfigError
        Naming the key.
    """
    _check_limits(config)
    sky = config.sky
    if sky.site is not None:
        _check_sun(config, sky.site)
        if sky.turbidity is None:
            lo, hi = TURBIDITY_RANGE
            middle = sky.site.start + (sky.site.end - sky.site.start) / 2
            from pipeline.sky.daylight import linke_turbidity  # pvlib: seconds to import, only when asked for

            turbidity = min(max(linke_turbidity(middle, sky.site.latitude, sky.site.longitude), lo), hi)
            config = replace(config, sky=replace(sky, turbidity=turbidity))
    return config


def _check_limits(config: Config) -> None:
    """Refuse given windows, canopy planes and sky squares whose rasters would pass the limits."""
    ground, layout = config.ground, config.canopy.layout
    if ground.window is not None:
        _check_pixels(config, "ground.pixel", ground.window, ground.pixel, MAX_GROUND_PIXELS)
    fine = ground.sun_window or ground.window
    if ground.sun_pixel is not None and fine:
        _check_pixels(config, "ground.sun_pixel", fine, ground.sun_pixel, MAX_SUN_PIXELS)
    images = config.canopy.trees is None
    for index, layer in enumerate(config.canopy.layers):
        key = "canopy.size" if len(config.canopy.layers) == 1 else f"canopy.layers[{index}].size"
        pixels = [side / ground.pixel for side in layer.size]
        if pixels[0] * pixels[1] > MAX_GROUND_PIXELS:
            raise ConfigError(config.where(key), f"the canopy would be {pixels[0] * pixels[1]:.3g} pixels "
                              f"at ground.pixel {ground.pixel:g} m; the most is {MAX_GROUND_PIXELS:.3g}")
        if layout == "isolated" and images and ground.window is not None:  # an automatic window: the plan
            window = ground.window
            fft = ((window[2] - window[0]) / ground.pixel + pixels[0]) * (
                (window[3] - window[1]) / ground.pixel + pixels[1])
            if fft > MAX_FFT_CELLS:
                raise ConfigError(config.where(key), f"canopy and window together need a {fft:.3g}-cell "
                                  f"transform, about {size_text(fft * BYTES_PER_CELL)}; the most is "
                                  f"{MAX_FFT_CELLS:.3g}: raise ground.pixel")
    if layout == "periodic":
        from pipeline.ground import shadow

        for layer in config.canopy.layers:
            n = 2 * shadow.sky_half_cells(layer.height, ground.pixel, config.sky.alpha) + 1
            if n * n > shadow.MAX_SKY_CELLS:
                raise ConfigError(config.where("sky.alpha"), f"the sky square at "
                                  f"{math.degrees(config.sky.alpha):g} degrees would be {n} x {n} cells "
                                  f"for a {ground.pixel:g} m pixel; lower alpha or raise ground.pixel")


def _check_pixels(config: Config, key: str, window: tuple[float, float, float, float], pixel: float,
                  most: int) -> None:
    cells = ((window[2] - window[0]) / pixel) * ((window[3] - window[1]) / pixel)
    if cells > most:
        raise ConfigError(config.where(key), f"the window would be {cells:.3g} pixels, about "
                          f"{size_text(cells * BYTES_PER_CELL)} to render; the most is {most:.3g}")


def _check_sun(config: Config, site: SiteConfig) -> None:
    """The procedural sky needs the sun at least MIN_SUN_ELEVATION high (at most 6 degrees below
    the horizon) at time.start and time.end and at every frame's moment between (at most
    SUN_SPAN_SAMPLES of them, evenly spread, so a night is never missed): name the first moment
    it is not, with the sun's elevation."""
    from pipeline.sky import ephemeris

    place = ephemeris.Site(site.latitude, site.longitude, site.elevation)
    least = f"at most {-math.degrees(MIN_SUN_ELEVATION):g} degrees below the horizon (the end of civil twilight)"
    for key, when in (("start", site.start), ("end", site.end)):
        sun, _ = ephemeris.sun_and_moon(place, when)
        if sun.elevation < MIN_SUN_ELEVATION:
            raise ConfigError(config.where(f"sky.time.{key}"), f"the sun is {_height(sun.elevation)} at "
                              f"{when.isoformat()}; the procedural sky needs it {least}")
    count = min(config.animation.frames, SUN_SPAN_SAMPLES)
    for i in range(count):
        when = site.start + (site.end - site.start) * (i / (count - 1) if count > 1 else 0.0)
        sun, _ = ephemeris.sun_and_moon(place, when)
        if sun.elevation < MIN_SUN_ELEVATION:
            raise ConfigError(config.where("sky.time"), f"the sun is {_height(sun.elevation)} at "
                              f"{when.isoformat()}, between time.start and time.end; the procedural sky "
                              f"needs it {least} all through (a span that crosses the night)")


def _height(elevation: float) -> str:
    """'12.3 degrees above the horizon', or below it. [rad]"""
    side = "above" if elevation >= 0 else "below"
    return f"{abs(math.degrees(elevation)):.1f} degrees {side} the horizon"
