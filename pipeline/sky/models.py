"""The sky models a config may name, each a class that the registry ``vocabulary.SKIES`` makes
from the config's ``sky`` section: where the sun and moon are at a frame, the frame's sky
(``base.Sky``), the clear light of the run and the files the model reads (docs/design.md,
"Models plug in")."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Protocol

import numpy as np

from pipeline.config.parse import MAX_RADIANCE
from pipeline.config.settings import SkyConfig
from pipeline.core import io
from pipeline.core.geometry import offset_direction
from pipeline.sky import ephemeris, equirect, procedural, sun_disc
from pipeline.sky.base import Sky, UniformSky
from pipeline.sky.clouds import CloudLayer
from pipeline.sky.eclipse import FULL_TABLE, METER_TABLE

__all__ = ["FrameScene", "SkyModel", "ProceduralModel", "ConstantSky", "UniformModel", "HdriModel", "clear_sky",
           "load_hdri", "with_still_sun"]


class FrameScene(Protocol):
    """What a sky model reads of a frame's scene (``scene.Scene`` has it): the frame's sun and
    moon (``SkyModel.discs``) and its time."""

    @property
    def time(self) -> float:
        """Film time [s]."""

    @property
    def sun(self) -> sun_disc.SunDisc | None:
        """The sun's disc, or None (a sky without a sun)."""

    @property
    def moon(self) -> sun_disc.MoonDisc | None:
        """The moon's disc, or None."""


class SkyModel(Protocol):
    """What the stages ask of a config's sky. A class of this shape, its module and one line in
    ``vocabulary.SKIES`` add a sky model (docs/design.md, "Models plug in")."""

    config: SkyConfig

    def discs(self, fraction: float) -> tuple[datetime | None, sun_disc.SunDisc | None, sun_disc.MoonDisc | None]:
        """The UTC time, sun and moon of the frame at ``fraction`` of the animation.

        Parameters
        ----------
        fraction : float
            The frame's place in the animation, 0 the first frame, 1 the last [1].

        Returns
        -------
        when : datetime or None
            The UTC time, or None (no site and time).
        sun : sun_disc.SunDisc or None
            The sun's disc (azimuth, elevation, angular radius [rad]), or None for a sky without a sun.
        moon : sun_disc.MoonDisc or None
            The moon's disc [rad], or None.
        """

    def at(self, scene: FrameScene | None, *, metering: bool = False) -> Sky:
        """The sky at a frame's scene.

        Parameters
        ----------
        scene : FrameScene or None
            The frame's scene; None for a sky without a sun.
        metering : bool
            For an exposure meter, which reads the whole sky's light only (a model may make it coarser).

        Returns
        -------
        base.Sky
            The sky's radiance [kcd/m^2] by direction and its sun.
        """

    def clear_light(self, sun: sun_disc.SunDisc | None) -> tuple[np.ndarray | None, np.ndarray]:
        """The light of the clear, uneclipsed sky with ``sun``: the run's reference light
        (``lighting.reference_lighting``).

        Parameters
        ----------
        sun : sun_disc.SunDisc or None
            The sun, or None without a sun.

        Returns
        -------
        sun_irradiance : ndarray, shape (3,), or None
            The sun's normal irradiance, or None without a sun [klx].
        sky_irradiance : ndarray, shape (3,)
            The sky's horizontal irradiance [klx].
        """

    def check(self) -> None:
        """Read and check the files the model needs.

        Raises
        ------
        io.ImageError
            Naming the file.
        """


@dataclass(frozen=True)
class ProceduralModel:
    """The procedural sky (``cie``, ``preetham``): absolute clear-sky daylight in the CIE or
    Preetham shape, the sun and moon from the ephemeris or the config's angles, clouds, the
    eclipse (docs/method.md, "The procedural sky"). Its methods are ``SkyModel``'s.

    Parameters
    ----------
    config : SkyConfig
        The config's resolved ``sky`` section (``resolve``: turbidity looked up).
    light : sun_disc.SunLight or None
        The light of the run's sun where it stands still (``with_still_sun``), given to its skies.
    """

    config: SkyConfig
    light: sun_disc.SunLight | None = field(default=None, compare=False, repr=False)

    def discs(self, fraction: float) -> tuple[datetime | None, sun_disc.SunDisc | None, sun_disc.MoonDisc | None]:
        """The sun and moon from the ephemeris at the time ``fraction`` through ``sky.time``, or
        the config's sun with the moon slid from ``offset_start`` to ``offset_end``."""
        sky = self.config
        if sky.site is not None:
            site = sky.site
            when = site.start + (site.end - site.start) * fraction
            sun_at, moon_at = ephemeris.sun_and_moon(ephemeris.Site(site.latitude, site.longitude, site.elevation),
                                                     when)
            return (when, sun_disc.SunDisc(sun_at.azimuth, sun_at.elevation, sun_at.angular_radius),
                    sun_disc.MoonDisc(moon_at.azimuth, moon_at.elevation, moon_at.angular_radius))
        s = sky.sun
        if s is None:  # the parser gives a procedural sky a site or a sun
            raise ValueError("a procedural sky needs sky.sun or sky.site")
        moon = None
        if sky.moon is not None:
            m = sky.moon
            dx, dy = (a + (b - a) * fraction for a, b in zip(m.offset_start, m.offset_end))
            azimuth, elevation = offset_direction(s.azimuth, s.elevation, dx, dy)
            moon = sun_disc.MoonDisc(azimuth, elevation, m.radius)
        return None, sun_disc.SunDisc(s.azimuth, s.elevation, s.radius), moon

    def at(self, scene: FrameScene | None, *, metering: bool = False) -> procedural.ProceduralSky:
        """The clear sky with the scene's sun, moon, clouds and eclipse; ``metering``: a deep
        eclipse's line-of-sight table is the coarser ``eclipse.METER_TABLE``."""
        if scene is None or scene.sun is None:  # a procedural sky's scenes have a sun (``discs``)
            raise ValueError("a procedural sky needs a scene with a sun")
        clouds = None
        if self.config.clouds is not None:
            c = self.config.clouds
            clouds = CloudLayer(cover=c.cover, scale=c.scale, altitude=c.altitude,
                                wind=c.wind, thickness=c.thickness, seed=c.seed)
        return clear_sky(self.config, scene.sun, moon=scene.moon, clouds=clouds, time=scene.time,
                         eclipse_table=METER_TABLE if metering else FULL_TABLE, light=self.light)

    def clear_light(self, sun: sun_disc.SunDisc | None) -> tuple[np.ndarray, np.ndarray]:
        """The clear sky's (no clouds, no moon) with ``sun``."""
        if sun is None:  # a procedural sky has a sun (``discs``)
            raise ValueError("a procedural sky needs a sun")
        clear = clear_sky(self.config, sun, light=self.light)
        return clear.sun_normal_irradiance, clear.clear_sky_irradiance

    def check(self) -> None:
        """Nothing to read."""


class ConstantSky:
    """A sky of one radiance in every direction and no sun, its radiance (3,) [kcd/m^2] given by
    a subclass. Its methods are ``SkyModel``'s."""

    config: SkyConfig

    @property
    def radiance(self) -> np.ndarray:
        """The sky's radiance (3,) in each linear Rec.709 channel [kcd/m^2]."""
        raise NotImplementedError

    def discs(self, fraction: float) -> tuple[datetime | None, sun_disc.SunDisc | None, sun_disc.MoonDisc | None]:
        """No time, no sun, no moon."""
        return None, None, None

    def at(self, scene: FrameScene | None, *, metering: bool = False) -> UniformSky:
        """The radiance in every direction."""
        return UniformSky(self.radiance)

    def clear_light(self, sun: sun_disc.SunDisc | None) -> tuple[np.ndarray | None, np.ndarray]:
        """No sun; the sky's horizontal irradiance pi L."""
        return None, np.pi * self.radiance

    def check(self) -> None:
        """Nothing to read."""


@dataclass(frozen=True)
class UniformModel(ConstantSky):
    """The uniform sky: ``sky.radiance`` [kcd/m^2] in every direction, no sun.

    Parameters
    ----------
    config : SkyConfig
        The config's ``sky`` section.
    """

    config: SkyConfig

    @property
    def radiance(self) -> np.ndarray:
        """``sky.radiance`` (3,) [kcd/m^2]."""
        return np.asarray(self.config.radiance, dtype=np.float64)


@dataclass(frozen=True)
class HdriModel:
    """An equirectangular image of the sky (``sky.hdri``), its sun cut out into a disc. Its
    methods are ``SkyModel``'s.

    Parameters
    ----------
    config : SkyConfig
        The config's ``sky`` section.
    """

    config: SkyConfig

    def discs(self, fraction: float) -> tuple[datetime | None, sun_disc.SunDisc | None, sun_disc.MoonDisc | None]:
        """No time; the image's sun; no moon."""
        return None, load_hdri(self.config).sun, None

    def at(self, scene: FrameScene | None, *, metering: bool = False) -> equirect.EquirectSky:
        """The image (``load_hdri``)."""
        return load_hdri(self.config)

    def clear_light(self, sun: sun_disc.SunDisc | None) -> tuple[np.ndarray | None, np.ndarray]:
        """The image's sun (None without one) and its sky's horizontal irradiance."""
        hdri = load_hdri(self.config)
        if hdri.sun is None:
            return None, hdri.image_irradiance()
        return np.asarray(hdri.sun_normal_irradiance, dtype=np.float64), hdri.image_irradiance()

    def check(self) -> None:
        """Read and check the image (``load_hdri``)."""
        load_hdri(self.config)


def clear_sky(sky: SkyConfig, sun: sun_disc.SunDisc, *, moon: sun_disc.MoonDisc | None = None,
              clouds: procedural.Clouds | None = None, time: float = 0.0,
              eclipse_table: tuple[int, int, int] = FULL_TABLE,
              light: sun_disc.SunLight | None = None) -> procedural.ProceduralSky:
    """The procedural sky of a config with ``sun``.

    Parameters
    ----------
    sky : SkyConfig
        A procedural sky's resolved config section.
    sun : sun_disc.SunDisc
        The sun.
    moon, clouds, time, eclipse_table, light
        The moon, the clouds, the time [s], the eclipse's table and the light of a still sun, as
        ``procedural.ProceduralSky`` takes them.

    Returns
    -------
    procedural.ProceduralSky
        Radiance [kcd/m^2] by direction, the sun's and sky's light [klx].
    """
    return procedural.ProceduralSky(turbidity=sky.turbidity, sun=sun, skylight=sky.skylight, shape=sky.model,
                                cie_type=sky.cie_type, altitude=sky.site.elevation if sky.site else 0.0,
                                moon=moon, clouds=clouds, time=time, eclipse_table=eclipse_table, light=light)


def with_still_sun(model: SkyModel, suns: Sequence[sun_disc.SunDisc | None]) -> SkyModel:
    """A procedural model carrying the light of its sun (``sun_disc.sun_light``, pvlib) made once,
    where the sun stands still over ``suns``.

    The plan's model goes to the workers that render the frames: with the light in it they neither
    import pvlib nor compute it again (docs/accuracy.md, "A worker's first frame"). A moving sun's
    light is computed per frame.

    Parameters
    ----------
    model : SkyModel
        A config's sky model (``scene.sky_model``).
    suns : sequence of sun_disc.SunDisc or None
        The sun of each frame of the run.

    Returns
    -------
    SkyModel
        ``model`` with its ``light`` where it is procedural and ``suns`` are one sun; else ``model``.
    """
    if not isinstance(model, ProceduralModel) or len(set(suns)) != 1 or suns[0] is None:
        return model
    return replace(model, light=clear_sky(model.config, suns[0]).sun_light)


@functools.lru_cache(maxsize=4)
def load_hdri(sky: SkyConfig) -> equirect.EquirectSky:
    """An HDRI sky read, checked (negative radiance taken as 0) and its sun cut out, once per
    process (the plan needs its sun, every frame its image).

    Parameters
    ----------
    sky : SkyConfig
        A config's ``sky`` section with ``model: hdri``.

    Returns
    -------
    equirect.EquirectSky
        Radiance [kcd/m^2] by direction, its sun a disc.

    Raises
    ------
    io.ImageError
        Naming the file, when it cannot be read or holds NaN, infinite or too large values.
    ValueError
        For a section without ``hdri`` (the parser requires it of ``model: hdri``).
    """
    path = sky.hdri
    if path is None:
        raise ValueError("an hdri sky needs sky.hdri")
    image = io.read_finite_image(path, "sky image")
    if image.shape[2] < 3:
        image = np.repeat(image[..., :1], 3, axis=2)
    image = image[..., :3]
    if image.max() > MAX_RADIANCE:
        raise io.ImageError(path, f"radiance {image.max():.3g} is above the most, {MAX_RADIANCE:g}")
    negative = image < 0.0
    if negative.any():  # a sky gives no negative light: clamped, and said (docs/method.md, "Conventions")
        texels = int(negative.any(axis=2).sum())
        warnings.warn(f"{path}: {texels} texel{'s' if texels != 1 else ''} of negative radiance (the lowest "
                      f"{image.min():.3g}) read as 0", RuntimeWarning, stacklevel=2)
    return equirect.cut_sun(equirect.EquirectSky(np.maximum(image, 0.0), sky.rotation))
