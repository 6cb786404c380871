"""A frame's scene: the time, where the sun and moon are and the sky, at each output frame of a
run (docs/design.md, "Stages")."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING

import numpy as np

from pipeline.config.settings import Config, SkyConfig
from pipeline.config.vocabulary import SKIES
from pipeline.sky.base import Sky
from pipeline.sky.sun_disc import MoonDisc, SunDisc

if TYPE_CHECKING:
    from pipeline.sky.models import SkyModel

__all__ = ["Scene", "scene_at", "sky_model", "load_sky", "SHADOW_FLOOR", "sun_lights", "sun_shades",
           "shading_scenes", "sun_of"]


@dataclass(frozen=True)
class Scene:
    """The sky's state at one output frame.

    Attributes
    ----------
    frame : int
        The output frame's index, from 0.
    time : float
        Film time, frame / fps [s].
    when : datetime or None
        UTC time (site and time configs), else None.
    sun : SunDisc or None
        The sun's disc, or None (a sky without a sun).
    moon : MoonDisc or None
        The moon's disc, or None (no moon).
    """

    frame: int
    time: float
    when: datetime | None
    sun: SunDisc | None
    moon: MoonDisc | None


def scene_at(config: Config, frame: int) -> Scene:
    """Where the sun and moon are at output ``frame``: the sky model's discs
    (``sky.models.SkyModel.discs``) at the frame's place in the animation, from 0 at the first frame
    to 1 at the last (a site's time span spread evenly over the frames).

    Parameters
    ----------
    config : Config
        A resolved config.
    frame : int
        Output frame index.

    Returns
    -------
    Scene
        The frame's time, sun and moon.
    """
    frames = config.animation.frames
    fraction = frame / (frames - 1) if frames > 1 else 0.0
    return Scene(frame, frame / config.animation.fps, *sky_model(config.sky).discs(fraction))


@functools.lru_cache(maxsize=8)
def sky_model(sky: SkyConfig) -> SkyModel:
    """The sky model of a config's ``sky`` section, made by its registry (``vocabulary.SKIES``).

    Parameters
    ----------
    sky : SkyConfig
        A config's (resolved) ``sky`` section.

    Returns
    -------
    sky.models.SkyModel
        The model, cached per ``sky`` (the last 8).
    """
    return SKIES.load(sky.model)(sky)


def load_sky(sky: SkyConfig, scene: Scene | None = None, *, metering: bool = False) -> Sky:
    """The sky of a config at a frame's scene (``sky.models.SkyModel.at``).

    Parameters
    ----------
    sky : SkyConfig
        A config's (resolved) ``sky`` section.
    scene : Scene or None
        The frame's scene (``scene.scene_at``); a sky without a sun needs none.
    metering : bool
        For an exposure meter, which reads the light of the whole sky only: a deep eclipse's
        line-of-sight table is the coarser ``eclipse.METER_TABLE``.

    Returns
    -------
    base.Sky
        The sky's radiance and light at the scene.

    Raises
    ------
    io.ImageError
        Naming the file a model could not read.
    """
    return sky_model(sky).at(scene, metering=metering)



SHADOW_FLOOR = float(np.radians(2.0))
"""Below this elevation the sun's light is taken as unshadowed by the canopy: the shadow of a
canopy h high lies h cot(elevation) > 28 h away along the anti-solar azimuth, beyond any window
the plan would make, and a fine mask reaching it would pass the limits (docs/method.md,
"Twilight and a sun at the horizon"). [rad]"""


def sun_lights(sun: SunDisc | None) -> bool:
    """Whether a sun disc gives direct light: wholly above the horizon.

    As ``sun_kernel.sun_irradiance`` and ``sun_kernel.sun_kernel`` need; a sun between the
    horizon and -6 degrees lights the ground through the sky alone (docs/method.md, "Twilight and
    a sun at the horizon").

    Parameters
    ----------
    sun : SunDisc or None
        The sun's disc (its ``elevation`` and ``angular_radius`` [rad]), or None.

    Returns
    -------
    bool
        True when its lower limb stands over 1e-3 rad above the horizon.
    """
    return sun is not None and sun.elevation - sun.angular_radius > 1e-3


def sun_shades(sun: SunDisc | None) -> bool:
    """Whether a sun's light goes through the fine sun kernel and its canopy shadow.

    Parameters
    ----------
    sun : SunDisc or None
        The sun's disc, or None.

    Returns
    -------
    bool
        True when it lights the ground (``sun_lights``) and stands at least ``SHADOW_FLOOR`` high.
    """
    return sun is not None and sun_lights(sun) and sun.elevation >= SHADOW_FLOOR


def shading_scenes(scenes: Iterable[Scene]) -> list[Scene]:
    """The scenes whose sun casts the canopy's shadow (``sun_shades``).

    Those the windows, the sun window and the fine masks are planned from.

    Parameters
    ----------
    scenes : iterable of Scene
        A run's scenes.

    Returns
    -------
    list of Scene
        Those whose sun shades, in their order.
    """
    return [scene for scene in scenes if sun_shades(scene.sun)]


def sun_of(scene: Scene) -> SunDisc:
    """The sun of a scene that has one, as a shading scene has (``shading_scenes``).

    Parameters
    ----------
    scene : Scene
        A scene with a sun.

    Returns
    -------
    SunDisc
        Its sun's disc.

    Raises
    ------
    ValueError
        For a scene without a sun.
    """
    if scene.sun is None:
        raise ValueError(f"frame {scene.frame} has no sun")
    return scene.sun
