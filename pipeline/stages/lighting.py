"""The run's light: the clear, uneclipsed sun and sky that light the foreground passes and set
the exposure, the incident-light meter and the auto exposure, and the light of a frame on open
ground as the run's report gives it (docs/method.md). Part of the plan stage: each function
takes the RunPlan, or a frame's sky."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pipeline.camera import composite
from pipeline.config.settings import AutoExposureConfig
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.sky.base import Sky
from pipeline.stages.plan import RunPlan
from pipeline.stages.scene import Scene

__all__ = ["Lighting", "reference_lighting", "EXPOSURE_MEMORY", "exposure_frames", "auto_exposures",
           "with_exposures", "meter", "LUX_PER_KLX", "INCIDENT_METER_C", "ev100", "open_ground_light"]


@dataclass(frozen=True)
class Lighting:
    """The clear, uneclipsed light of a run, fixed for all its frames: what the foreground
    passes are lit by and the exposure is set from.

    Attributes
    ----------
    sun_direction : ndarray, shape (3,), or None
        Unit vector towards the sun [1], or None without a sun.
    sun_irradiance : ndarray, shape (3,)
        The sun's normal irradiance [klx].
    sky_irradiance : ndarray, shape (3,)
        Horizontal irradiance of the sky alone [klx].
    """

    sun_direction: np.ndarray | None
    sun_irradiance: np.ndarray
    sky_irradiance: np.ndarray

    @functools.cached_property
    def sun_down(self) -> np.ndarray:
        """The sun's horizontal irradiance: its normal irradiance times the cosine of its zenith
        angle, made once; zeros without a sun.

        Returns
        -------
        ndarray, shape (3,)
            Irradiance [klx], read-only.
        """
        down = np.zeros(3) if self.sun_direction is None else self.sun_irradiance * self.sun_direction[2]
        down.setflags(write=False)
        return down

    @property
    def unshadowed(self) -> np.ndarray:
        """Horizontal irradiance of sun and sky together.

        Returns
        -------
        ndarray, shape (3,)
            Irradiance [klx].
        """
        if self.sun_direction is None:
            return self.sky_irradiance
        return self.sky_irradiance + self.sun_down


@functools.lru_cache(maxsize=8)
def reference_lighting(plan: RunPlan) -> Lighting:
    """The run's Lighting: the clear sky of the config with its sun at the projection direction.

    The middle frame's sun, no clouds and no moon. Made once per plan (every frame asks for it).

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.

    Returns
    -------
    Lighting
        The reference light [klx]; its arrays are read-only.
    """
    light = _reference_lighting(plan)
    return Lighting(None if light.sun_direction is None else _read_only(light.sun_direction),
                    _read_only(light.sun_irradiance), _read_only(light.sky_irradiance))


def _read_only(values: np.ndarray) -> np.ndarray:
    copy = np.array(values)
    copy.setflags(write=False)
    return copy


def _reference_lighting(plan: RunPlan) -> Lighting:
    """The reference light of ``reference_lighting``, its arrays as made."""
    s = np.append(plan.projection, 1.0)
    middle = plan.scenes[plan.frames // 2].sun
    sun, sky = plan.sky.clear_light(middle)
    if sun is None:
        return Lighting(None, np.zeros(3), sky)
    return Lighting(s / np.linalg.norm(s), sun, sky)


EXPOSURE_MEMORY = 14.0
"""Auto exposure forgets the light of frames more than this many time constants back (their
weight is exp(-14) < 1e-6): a frame meters only the frames just before it. [1]"""


def _auto_exposure(plan: RunPlan) -> AutoExposureConfig:
    """The plan's auto exposure; a ValueError for a fixed one."""
    if plan.exposure.auto is None:
        raise ValueError("the plan has a fixed exposure (camera.exposure is not auto)")
    return plan.exposure.auto


def exposure_frames(plan: RunPlan, frame: int) -> range:
    """The frames whose light the auto exposure of ``frame`` remembers.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan, with an auto exposure.
    frame : int
        Output frame index.

    Returns
    -------
    range
        From ``EXPOSURE_MEMORY`` time constants back (at least frame 0) to ``frame``.

    Raises
    ------
    ValueError
        For a plan without an auto exposure.
    """
    auto = _auto_exposure(plan)
    memory = int(np.ceil(EXPOSURE_MEMORY * auto.time_constant * plan.exposure.fps))
    return range(max(0, frame - memory), frame + 1)


def auto_exposures(plan: RunPlan, frames: Iterable[int] | None = None) -> dict[int, float]:
    """The exposure of frames with ``camera.exposure: auto``.

    Each frame's meter reading is the open ground's light (``meter``), followed through
    ``composite.auto_exposure``'s first-order lag and limits from the first frame it remembers
    (``exposure_frames``), so a frame's exposure is the same whichever frames are rendered.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan, with an auto exposure.
    frames : iterable of int or None
        Output frame indices; None for all.

    Returns
    -------
    dict of int to float
        Per frame, its exposure [m^2/kcd].

    Raises
    ------
    ValueError
        For a plan without an auto exposure.
    """
    auto = _auto_exposure(plan)
    light = reference_lighting(plan)
    frames = range(plan.frames) if frames is None else frames
    windows = {frame: exposure_frames(plan, frame) for frame in frames}
    readings = {f: meter(plan, plan.scenes[f], light) for f in sorted(set().union(*windows.values()))}
    e = plan.exposure
    return {frame: float(composite.auto_exposure(
                [readings[f] for f in window], reference=light.unshadowed,
                frame_time=1.0 / e.fps, time_constant=auto.time_constant,
                limits=auto.limits, stops=e.stops)[-1])
            for frame, window in windows.items()}


def with_exposures(plan: RunPlan, frames: Iterable[int] | None = None) -> RunPlan:
    """The plan with the auto exposure of ``frames``, metered once for a whole run.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    frames : iterable of int or None
        Output frame indices; None for all.

    Returns
    -------
    plan.RunPlan
        The plan, its ``exposures`` per frame [m^2/kcd] (None for the frames not asked); the plan
        itself with a fixed exposure.
    """
    if plan.exposure.auto is None:
        return plan
    exposures = auto_exposures(plan, frames)
    return replace(plan, exposures=tuple(exposures.get(f) for f in range(plan.frames)))


def meter(plan: RunPlan, scene: Scene, light: Lighting) -> np.ndarray:
    """What an incident-light meter on the open ground reads at a frame.

    The sky's horizontal irradiance now (clouds and the moon dim it) plus the clear sun's times S.

    Parameters
    ----------
    plan : plan.RunPlan
        The run's plan.
    scene : scene.Scene
        The frame's scene.
    light : Lighting
        The run's reference light (``reference_lighting``).

    Returns
    -------
    ndarray, shape (3,)
        Horizontal irradiance [klx].
    """
    sky = plan.sky.at(scene, metering=True)
    if light.sun_direction is None:
        return light.unshadowed
    return np.asarray(sky.sky_irradiance) + float(sky.sun_fraction()) * np.asarray(sky.undimmed_sun_irradiance())


LUX_PER_KLX = 1000.0
"""Lux in a kilolux. [lx/klx]"""
INCIDENT_METER_C = 250.0
"""The calibration constant C of an incident-light meter with a flat receptor (ISO 2720:1974,
240 to 400 for flat receptors; 250 as commonly used): EV100 = log2(E / 2.5), E in lux. [lx s]"""


def ev100(lux: float) -> float | None:
    """The exposure value at ISO 100 that an incident-light meter gives for a horizontal illuminance.

    log2(E 100 / C) (``INCIDENT_METER_C``).

    Parameters
    ----------
    lux : float
        Horizontal illuminance E [lx].

    Returns
    -------
    float or None
        EV100 [EV]; None without light.
    """
    return float(np.log2(lux * 100.0 / INCIDENT_METER_C)) if lux > 0 else None


def open_ground_light(sky: Sky, exposure: float, balance: np.ndarray | None) -> dict[str, Any]:
    """The light of a frame on open ground, for the run's report and the EXR's attributes.

    Sums by luminance (Rec.709) of the sky model's own irradiances (``meter``'s reading).

    Parameters
    ----------
    sky : base.Sky
        The frame's sky.
    exposure : float
        The camera's exposure [m^2/kcd].
    balance : ndarray, shape (3,), or None
        The white balance's display gains [1]; None: 1.

    Returns
    -------
    dict
        ``sun_lux`` the sun's horizontal illuminance now (its clear light times S) and ``sky_lux``
        the sky's (clouds and the moon dim it) [lx, for a procedural sky; an HDRI's or a uniform
        sky's in its own units x 1000]; ``ev100`` what an incident meter reads of the two together
        [EV]; ``camera_ev100`` the light the camera's exposure is set for (pi / exposure [klx], a
        white ground at 1) as EV100 [EV]; ``white_balance`` the display gains (3,) [1].
    """
    sun = float(sky.sun_fraction()) * np.asarray(sky.undimmed_sun_irradiance(), dtype=np.float64)
    sun_lux = float(sun @ REC709_LUMINANCE) * LUX_PER_KLX
    sky_lux = float(np.asarray(sky.sky_irradiance, dtype=np.float64) @ REC709_LUMINANCE) * LUX_PER_KLX
    return {"sun_lux": sun_lux, "sky_lux": sky_lux, "ev100": ev100(sun_lux + sky_lux),
            "camera_ev100": ev100(np.pi / exposure * LUX_PER_KLX) if exposure > 0 else None,
            "white_balance": [float(g) for g in (np.ones(3) if balance is None else balance)]}
