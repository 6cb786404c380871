"""The sky models a config may name, each a class that the registry ``vocabulary.SKIES`` makes
from the config's ``sky`` section: where the sun and moon are at a frame, the frame's sky
(``sky.Sky``), the clear light of the run and the files the model reads (docs/design.md,
"Models plug in")."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from datetime import datetime
from typing import Protocol

import numpy as np

from . import ephemeris, io
from . import sky as skylib
from .clouds import CloudLayer
from .config import MAX_RADIANCE
from .settings import SkyConfig
from .eclipse import METER_TABLE
from .geometry import offset_direction

__all__ = ["SkyModel", "ProceduralModel", "UniformModel", "HdriModel", "clear_sky", "load_hdri"]


class SkyModel(Protocol):
    """What the stages ask of a config's sky. A class of this shape, its module and one line in
    ``vocabulary.SKIES`` add a sky model (docs/design.md, "Models plug in")."""

    config: SkyConfig

    def discs(self, fraction: float) -> tuple[datetime | None, skylib.SunDisc | None, skylib.MoonDisc | None]:
        """The UTC time (or None), sun and moon (or None) of the frame at ``fraction`` [1] of the
        animation (0 the first frame, 1 the last)."""

    def at(self, scene, *, metering: bool = False) -> skylib.Sky:
        """The sky at a frame's ``scene`` (``scene.Scene``; None for a sky without a sun);
        ``metering``: for an exposure meter, which reads the
        whole sky's light only (a model may make it coarser)."""

    def clear_light(self, sun: skylib.SunDisc | None) -> tuple[np.ndarray | None, np.ndarray]:
        """(the sun's normal irradiance (3,) or None without a sun, the sky's horizontal
        irradiance (3,)) [klx] of the clear, uneclipsed sky with ``sun``: the run's reference
        light (``lighting.reference_lighting``)."""

    def check(self) -> None:
        """Read and check the files the model needs. Raises io.ImageError naming the file."""


@dataclass(frozen=True)
class ProceduralModel:
    """The procedural sky (``cie``, ``preetham``): absolute clear-sky daylight in the CIE or
    Preetham shape, the sun and moon from the ephemeris or the config's angles, clouds, the
    eclipse (docs/method.md, "The procedural sky").

    Parameters
    ----------
    config : SkyConfig
        The config's resolved ``sky`` section (``resolve``: turbidity looked up).
    """

    config: SkyConfig

    def discs(self, fraction: float):
        sky = self.config
        if sky.site is not None:
            site = sky.site
            when = site.start + (site.end - site.start) * fraction
            sun, moon = ephemeris.sun_and_moon(ephemeris.Site(site.latitude, site.longitude, site.elevation), when)
            return (when, skylib.SunDisc(sun.azimuth, sun.elevation, sun.angular_radius),
                    skylib.MoonDisc(moon.azimuth, moon.elevation, moon.angular_radius))
        s = sky.sun
        moon = None
        if sky.moon is not None:
            m = sky.moon
            dx, dy = (a + (b - a) * fraction for a, b in zip(m.offset_start, m.offset_end))
            azimuth, elevation = offset_direction(s.azimuth, s.elevation, dx, dy)
            moon = skylib.MoonDisc(azimuth, elevation, m.radius)
        return None, skylib.SunDisc(s.azimuth, s.elevation, s.radius), moon

    def at(self, scene, *, metering: bool = False):
        clouds = None
        if self.config.clouds is not None:
            c = self.config.clouds
            clouds = CloudLayer(cover=c.cover, scale=c.scale, altitude=c.altitude,
                                wind=np.asarray(c.wind), thickness=c.thickness, seed=c.seed)
        detail = {"eclipse_table": METER_TABLE} if metering else {}
        return clear_sky(self.config, scene.sun, moon=scene.moon, clouds=clouds, time=scene.time, **detail)

    def clear_light(self, sun):
        clear = clear_sky(self.config, sun)
        return clear.sun_normal_irradiance, clear.clear_sky_irradiance

    def check(self) -> None:
        pass


@dataclass(frozen=True)
class UniformModel:
    """A sky of one radiance in every direction, no sun (``sky.radiance`` [kcd/m^2]).

    Parameters
    ----------
    config : SkyConfig
        The config's ``sky`` section.
    """

    config: SkyConfig

    def discs(self, fraction: float):
        return None, None, None

    def at(self, scene, *, metering: bool = False):
        return skylib.UniformSky(np.asarray(self.config.radiance, dtype=np.float64))

    def clear_light(self, sun):
        return None, np.pi * np.asarray(self.config.radiance, dtype=np.float64)

    def check(self) -> None:
        pass


@dataclass(frozen=True)
class HdriModel:
    """An equirectangular image of the sky (``sky.hdri``), its sun cut out into a disc.

    Parameters
    ----------
    config : SkyConfig
        The config's ``sky`` section.
    """

    config: SkyConfig

    def discs(self, fraction: float):
        return None, load_hdri(self.config).sun, None

    def at(self, scene, *, metering: bool = False):
        return load_hdri(self.config)

    def clear_light(self, sun):
        hdri = load_hdri(self.config)
        if hdri.sun is None:
            return None, hdri.total_irradiance()
        return np.asarray(hdri.sun_normal_irradiance, dtype=np.float64), hdri.total_irradiance()

    def check(self) -> None:
        load_hdri(self.config)


def clear_sky(sky: SkyConfig, sun: skylib.SunDisc, **state) -> skylib.ProceduralSky:
    """The procedural sky of a config with ``sun``.

    Parameters
    ----------
    sky : SkyConfig
        A procedural sky's resolved config section.
    sun : sky.SunDisc
        The sun.
    **state
        ``moon``, ``clouds``, ``time`` [s], ``eclipse_table``: as ``sky.ProceduralSky`` takes them.

    Returns
    -------
    sky.ProceduralSky
    """
    return skylib.ProceduralSky(turbidity=sky.turbidity, sun=sun, skylight=sky.skylight, shape=sky.model,
                                cie_type=sky.cie_type, altitude=sky.site.elevation if sky.site else 0.0,
                                **state)


@functools.lru_cache(maxsize=4)
def load_hdri(sky: SkyConfig) -> skylib.EquirectSky:
    """An HDRI sky read, checked (negative radiance taken as 0) and its sun cut out, once per
    process (the plan needs its sun, every frame its image).

    Parameters
    ----------
    sky : SkyConfig
        A config's ``sky`` section with ``model: hdri``.

    Returns
    -------
    sky.EquirectSky
        Radiance [kcd/m^2] by direction, its sun a disc.

    Raises
    ------
    io.ImageError
        Naming the file, when it cannot be read or holds NaN, infinite or too large values.
    """
    image = io.read_image(sky.hdri)
    if image.shape[2] < 3:
        image = np.repeat(image[..., :1], 3, axis=2)
    image = image[..., :3]
    if not np.all(np.isfinite(image)):
        raise io.ImageError(sky.hdri, "the sky image holds NaN or infinite values")
    if image.max() > MAX_RADIANCE:
        raise io.ImageError(sky.hdri, f"radiance {image.max():.3g} is above the most, {MAX_RADIANCE:g}")
    return skylib.cut_sun(skylib.EquirectSky(np.maximum(image, 0.0), sky.rotation))
