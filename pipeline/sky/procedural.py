"""The procedural sky (clear sky, sun, moon, clouds, the deep eclipse) with its weighted
sky-plane rasters ``e`` (Max 1991, eq. 1 and Fig. 6; ``sky.raster``).

The ``Sky`` interface it implements and the uniform sky are ``base``'s (``base.Sky``,
``base.UniformSky``); the HDRI sky is ``equirect.EquirectSky``; the sun and moon discs are
``sun_disc``'s; the nodes the procedural sky is evaluated on are ``nodes``'; the sun's fine kernel and its sum are
``sun_kernel``'s, which uses these models (they do not use it).

Why one module: ``ProceduralSky`` is one model of many parts (the clear sky's levels and shape,
the moon's cut, the clouds, the deep eclipse, its raster and its equirectangular image) that
share its cached state.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Literal, Protocol, overload

import numpy as np
from numpy.typing import ArrayLike

from pipeline.config.vocabulary import DEFAULT_CIE_TYPE, PROCEDURAL_MODELS, TURBIDITY_RANGE
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import (
    Grid,
    direction_vector,
    fold,
    sky_grid,
    sky_offset,
    tangent_axes,
)
from pipeline.sky import clearsky, daylight, eclipse
from pipeline.sky.ephemeris import obscured_fraction
from pipeline.sky.nodes import (
    gauss_legendre,
    lerp_nodes,
    outside_nodes,
    raster_nodes,
    relative_at,
    relative_nodes,
    solid_angles32,
)
from pipeline.sky.raster import SkyRaster, kept_raster
from pipeline.sky.sun_disc import (
    MoonDisc,
    SunDisc,
    SunLight,
    angle_to,
    disc_samples,
    sun_disc_radiance,
    sun_light,
)

__all__ = ["CLEAR_SKY_NODE_SPACING", "Clouds", "ProceduralSky"]


# ---------------------------------------------------------------------------------------------
# Procedural sky: a clear sky at the absolute levels of ``daylight`` (Ineichen & Perez 2002 with
# the Perez et al. 1990 efficacies) shaped by ``clearsky`` (CIE standard general sky or Preetham
# et al. 1999), an attenuated limb-darkened sun, a dark moon and duck-typed clouds.
#
# Units: radiance in kcd/m^2 per linear Rec.709 channel (the channels' Rec.709 luminance is the
# photometric luminance), so irradiances [radiance x sr] come out in klx. Directions: azimuth from
# north towards east, zenith angle from +z [rad]; sky-plane points s = (wx/wz, wy/wz) [tan].
#
# Clouds protocol (``Clouds``; implemented in ``pipeline/sky/clouds.py``, used here by duck typing):
#   clouds.transmittance(s (..., 2), time, footprint=None) -> (...) in [0, 1], direct transmittance along s;
#   clouds.radiance(s (..., 2), time, *, sun_s (2,), sun_irradiance (3,), sky_irradiance (3,), footprint=None)
#       -> (..., 3) light scattered towards the observer [kcd/m^2], given the sun's sky-plane
#       point, its normal irradiance above the clouds after the atmosphere and the moon [klx], and
#       the clear sky's horizontal irradiance [klx].
#   clouds.shade(s, time, *, sun_s, sun_irradiance, sky_irradiance, footprint=None), optional ->
#       (transmittance, radiance) as the two above return them, the pattern sampled once.
#   Sky behind cloud: L_clear(s) T(s) + clouds.radiance(s); the sun is dimmed by T(s_sun).
# ---------------------------------------------------------------------------------------------


class Clouds(Protocol):
    """What ``ProceduralSky`` asks of its clouds (the comment above; ``clouds.CloudLayer`` has it):
    ``transmittance`` and ``radiance``, and ``shade``, both at once, where they have it."""

    def transmittance(self, s: np.ndarray, time: float, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """(...) direct transmittance in [0, 1] along sky-plane points s (..., 2) [tan] at ``time`` [s],
        filtered over ``footprint`` [tan]. [1]"""

    def radiance(self, s: np.ndarray, time: float, *, sun_s: np.ndarray, sun_irradiance: np.ndarray,
                 sky_irradiance: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """(..., 3) light scattered towards the observer along sky-plane points s (..., 2) [tan] at
        ``time`` [s], lit by the sun at sky-plane point ``sun_s`` (2,) [tan] of normal irradiance
        ``sun_irradiance`` (3,) [klx] and by the clear sky of horizontal irradiance
        ``sky_irradiance`` (3,) [klx]. [kcd/m^2]"""


_kept_rasters: dict = {}  # ProceduralSky.raster's without clouds: (the sky at time 0, grid, fold) -> raster

CLEAR_SKY_NODE_SPACING = 0.02
"""Largest spacing of the nodes on which ``ProceduralSky.raster`` evaluates the clear sky. [tan]"""


def _unit(s) -> np.ndarray:
    """Unit vectors (..., 3) of sky-plane points s (..., 2). [tan] -> [1]"""
    s = np.asarray(s, dtype=np.float64)
    cos_zenith = 1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
    return np.stack([s[..., 0] * cos_zenith, s[..., 1] * cos_zenith, cos_zenith], axis=-1)



@dataclass(frozen=True)
class ProceduralSky:
    """Clear sky in absolute units with the sun, an optional moon and optional clouds; a ``Sky``.

    Radiance in kcd/m^2, irradiance in klx (linear Rec.709 channels). The clear sky (no moon, no
    clouds, skylight 1) gives the diffuse horizontal illuminance of ``daylight`` and the sun its
    direct normal illuminance. The moon cuts the sun and dims the clear sky and the clouds' glow
    by the same (limb-weighted) factor, since skylight is scattered sunlight; below the horizon
    there is no light (0).

    Parameters
    ----------
    turbidity : float
        Linke turbidity factor TL, in vocabulary.TURBIDITY_RANGE: the levels of sun and sky
        (``daylight.clear_daylight``) and the colours of both [1].
    sun : sun_disc.SunDisc
        Elevation at least ``daylight.TWILIGHT_END`` (-6 degrees, the end of civil twilight).
        Below 10 degrees the levels follow the USNO twilight curve (``daylight.sky_daylight``);
        with its disc not wholly above the horizon the sun gives no direct light. Its angular
        radius gives its distance, so the extraterrestrial irradiance [rad].
    moon : sun_disc.MoonDisc or None
        The new moon that cuts the sun.
    clouds : Clouds or None
        An object with the clouds protocol (``Clouds``, the module's comment above).
    time : float
        Passed to the clouds [s].
    skylight : float
        Factor on the clear sky's radiance; 0 leaves the sun alone, as in the paper's Fig. 11 [1].
    shape : str
        The clear sky's angular distribution, a name in ``vocabulary.PROCEDURAL_MODELS``.
    cie_type : int
        The CIE standard general sky type with shape 'cie', 1..15.
    altitude : float
        Of the site above sea level [m].
    eclipse_table : tuple of (int, int, int)
        (elevations, azimuths, path nodes) of a deep eclipse's line-of-sight table
        (``eclipse.EclipseField``): ``eclipse.FULL_TABLE``, or ``eclipse.METER_TABLE`` for an
        exposure meter [count].

    Raises
    ------
    ValueError
        For a turbidity, sun elevation, shape or CIE type out of range.
    """

    turbidity: float
    sun: SunDisc
    moon: MoonDisc | None = None
    clouds: Clouds | None = None
    time: float = 0.0
    skylight: float = 1.0
    shape: str = "cie"
    cie_type: int = DEFAULT_CIE_TYPE
    altitude: float = 0.0
    eclipse_table: tuple[int, int, int] = eclipse.FULL_TABLE
    light: SunLight | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        lo, hi = TURBIDITY_RANGE
        if not (lo <= self.turbidity <= hi):
            raise ValueError(f"turbidity must be in [{lo}, {hi}], got {self.turbidity}")
        if not self.sun.elevation >= daylight.TWILIGHT_END:
            raise ValueError(f"sun elevation must be at least {np.degrees(daylight.TWILIGHT_END):g} degrees (the end "
                             f"of civil twilight) for the sky, got {np.degrees(self.sun.elevation):.2f} degrees")
        if self.shape not in PROCEDURAL_MODELS:
            raise ValueError(f"unknown sky shape {self.shape!r} (valid: {', '.join(PROCEDURAL_MODELS)})")
        if self.cie_type not in clearsky.CIE_TYPES:
            raise ValueError(f"cie_type must be 1..15, got {self.cie_type}")

    # --- the sun ------------------------------------------------------------------------------
    @cached_property
    def sun_direction(self) -> np.ndarray:
        """Unit vector towards the sun's centre. [1]"""
        return direction_vector(self.sun.azimuth, self.sun.elevation)

    @cached_property
    def sun_point(self) -> np.ndarray:
        """Sky-plane point of the sun's centre (2,). [tan]"""
        return self.sun_direction[:2] / self.sun_direction[2]

    @cached_property
    def sun_light(self) -> SunLight:
        """The clear sky's daylight and the sun's colour at this sun, turbidity and altitude:
        ``light`` where it is theirs (a still sun's, made once in the command), else
        ``sun_disc.sun_light``'s (pvlib)."""
        if self.light is not None and self.light.of(self.sun, self.turbidity, self.altitude):
            return self.light
        return sun_light(self.sun, self.turbidity, self.altitude)

    @property
    def daylight(self) -> daylight.ClearDaylight:
        """The clear sky's direct and diffuse light at this sun, turbidity, altitude and distance."""
        return self.sun_light.daylight

    @cached_property
    def sun_normal_irradiance(self) -> np.ndarray:
        """Clear, uneclipsed normal irradiance of the sun after the atmosphere (3,): the direct
        normal illuminance of ``daylight`` in the colour of ``sun_disc.sun_colour`` (zeros with the
        disc not wholly up). [klx]"""
        return self.daylight.direct_normal_illuminance * self.sun_light.colour

    def undimmed_sun_irradiance(self) -> np.ndarray:
        """The sun's horizontal irradiance before the moon and clouds dim it (the hidden part included).

        Returns
        -------
        numpy.ndarray
            (3,) E_n cos(zenith) of the clear, uneclipsed sun: the sun kernel's sum without moon
            or cloud (to O(r^2)) [klx].
        """
        return self.sun_normal_irradiance * self.sun_direction[2]

    @cached_property
    def moon_visible(self) -> np.ndarray:
        """Fraction of the limb-darkened sun's power the moon leaves visible, per channel (3,). [1]

        Ring by ring: the ring of radius rho about the sun's centre is covered by the moon (centre d
        away, radius R) over arccos((rho^2 + d^2 - R^2) / (2 rho d)) / pi of its length; the rings
        are summed with Gauss-Legendre between the radii where that fraction has kinks. The discs
        are flat circles of their angular radii (error O(r^2)).
        """
        if self.moon is None:
            return np.ones(3)
        r, big_r = self.sun.angular_radius, self.moon.angular_radius
        d = float(angle_to(direction_vector(self.moon.azimuth, self.moon.elevation), self.sun_direction))
        if d >= r + big_r:
            return np.ones(3)
        cuts = np.unique(np.clip([0.0, abs(d - big_r), d + big_r, r], 0.0, r))
        rho, w = gauss_legendre(cuts[:-1], cuts[1:], 48)
        rho, w = rho.ravel(), w.ravel()
        k = (rho**2 + d**2 - big_r**2) / (2.0 * rho * max(d, 1e-300))
        covered = np.arccos(np.clip(k, -1.0, 1.0)) / np.pi
        ring = sun_disc_radiance(rho, angular_radius=r, normal_irradiance=np.ones(3),
                                 limb_darkening=self.sun.limb_darkening) * (w * rho)[:, None]
        return 1.0 - (ring * covered[:, None]).sum(axis=0) / ring.sum(axis=0)

    @cached_property
    def sun_cloud_transmittance(self) -> float:
        """Cloud transmittance towards the sun's centre, 1 without clouds. [1]"""
        if self.clouds is None:
            return 1.0
        return float(np.clip(self.clouds.transmittance(self.sun_point[None], self.time)[0], 0.0, 1.0))

    def sun_fraction(self) -> float:
        """S (docs/method.md, "The procedural sky").

        Returns
        -------
        float
            The direct sun power reaching the ground after moon and clouds over that of the clear,
            uneclipsed sun, weighted by Rec.709 luminance; 0 for a set sun [1].
        """
        e = self.sun_normal_irradiance * REC709_LUMINANCE
        if not e.sum() > 0:  # a set sun (twilight)
            return 0.0
        return float(self.sun_cloud_transmittance * (e @ self.moon_visible) / e.sum())

    def _sun_samples(self, w, footprint, widest):
        """Visible sun radiance (..., 3) [kcd/m^2] at unit vectors w (..., 3), cut by the moon and
        dimmed by the clouds' transmittance towards the sun's centre (see ``disc_samples``)."""
        return disc_samples(w, footprint, widest, self.sun, self.sun_direction, self.sun_normal_irradiance,
                             self.moon) * self.sun_cloud_transmittance

    # --- the sky ------------------------------------------------------------------------------
    @cached_property
    def _sky_dimming(self) -> np.ndarray:
        """Factor on the clear sky (3,): the sun's visible fraction (eclipse), times skylight. [1]"""
        return self.moon_visible * self.skylight

    def _relative_sky(self, s) -> np.ndarray:
        """The clear sky's shape and colour at sky-plane points s (..., 2) [tan]: zenith luminance 1;
        for read-only points (a still camera's rays), kept while the sun stands still
        (``nodes.relative_at``). [1]"""
        if isinstance(s, np.ndarray) and not s.flags.writeable:
            return relative_at(self._clear_key, s)
        return self._shape_at(s)

    def _shape_at(self, s) -> np.ndarray:
        """``_relative_sky`` computed. [1]"""
        w = _unit(s)
        return clearsky.relative_sky(w[..., 2], angle_to(w, self.sun_direction),
                                     sun_zenith=np.pi / 2 - self.sun.elevation, turbidity=self.turbidity,
                                     shape=self.shape, cie_type=self.cie_type)

    @cached_property
    def _relative_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,) of the sky of zenith luminance 1 (``_relative_sky``). [sr]"""
        weight = outside_nodes(None)[1]
        return (relative_nodes(self._clear_key, outside_nodes, None) * weight[..., None]).sum(axis=(0, 1, 2))

    @cached_property
    def _clear_key(self) -> ProceduralSky:
        """This sky without what does not shape the clear sky (the sun's size and limb, moon,
        clouds, time, skylight): the key of the caches of its shape."""
        return replace(self, sun=SunDisc(self.sun.azimuth, self.sun.elevation), moon=None, clouds=None,
                       time=0.0, skylight=1.0)

    @cached_property
    def zenith_luminance(self) -> float:
        """Luminance of the clear, uneclipsed sky at the zenith: the one that gives the diffuse
        horizontal illuminance of ``daylight`` (skylight and the moon not applied). [kcd/m^2]"""
        luminance = float(self._relative_irradiance @ np.asarray(REC709_LUMINANCE, dtype=np.float64))
        return self.daylight.diffuse_horizontal_illuminance / luminance

    def clear_radiance(self, s: ArrayLike) -> np.ndarray:
        """The clear sky's radiance, eclipse-dimmed, without the sun disc and the clouds.

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points [tan].

        Returns
        -------
        numpy.ndarray
            (..., 3) radiance [kcd/m^2].
        """
        return self._clear(s)

    def _clear(self, s, corona: bool = True) -> np.ndarray:
        """``clear_radiance``; ``corona`` False leaves the corona out (``equirect`` deposits it). [kcd/m^2]"""
        L = self._relative_sky(s) * (self.zenith_luminance * self._dimming_at(s))
        if corona and self._deep:
            L = L + self.corona_radiance(_unit(s))
        return L

    # --- the deep eclipse (docs/method.md, "The eclipse sky") ---------------------------------
    @cached_property
    def _deep(self) -> float:
        """b: the weight of the deep-eclipse sky (``eclipse.deep_weight``), 0 without a moon or
        up to 99.8% obscuration (of the sun's area, ``ephemeris.obscured_fraction``, the discs
        of ``moon_visible``), where the sky is the clear sky times S. [1]"""
        if self.moon is None:
            return 0.0
        separation = float(angle_to(self.moon_direction, self.sun_direction))
        covered = float(obscured_fraction(separation, self.sun.angular_radius, self.moon.angular_radius))
        return eclipse.deep_weight(1.0 - covered)

    @cached_property
    def moon_direction(self) -> np.ndarray:
        """Unit vector towards the moon's centre (with a moon). [1]"""
        return direction_vector(self._moon.azimuth, self._moon.elevation)

    @property
    def _moon(self) -> MoonDisc:
        """The moon, for what only a sky with a moon asks (the deep eclipse: ``_deep`` above 0)."""
        if self.moon is None:
            raise ValueError("the sky has no moon")
        return self.moon

    @cached_property
    def _eclipse_field(self) -> eclipse.EclipseField:
        """F and M of every sky direction at this sun and moon (``eclipse.line_of_sight``)."""
        return eclipse.EclipseField.compute(
            table=self.eclipse_table, sun_direction=self.sun_direction, moon_direction=self.moon_direction,
            sun_radius=self.sun.angular_radius, moon_radius=self._moon.angular_radius, turbidity=self.turbidity)

    def _dimming_at(self, s) -> np.ndarray:
        """Factor on the clear sky at sky-plane points s (..., 2) [tan]: ``_sky_dimming`` (3,)
        above 99.8% obscuration; deeper, (..., 3)
        (1 - b) S + b (F(w) + k M(w) G(w)) times skylight (``eclipse``), G the clear sky's
        shape 90 degrees from the sun over its shape at w (no circumsolar glow in the multiply
        scattered light). [1]"""
        b = self._deep
        if not b:
            return self._sky_dimming
        w = _unit(s)
        f, m = self._eclipse_field(w)
        # the multiply scattered light has no circumsolar glow: the clear sky's shape at 90
        # degrees from the sun (its gradation with zenith angle kept), over its shape here
        glowless = clearsky.relative_sky(w[..., 2], np.full(w.shape[:-1], np.pi / 2),
                                         sun_zenith=np.pi / 2 - self.sun.elevation, turbidity=self.turbidity,
                                         shape=self.shape, cie_type=self.cie_type) / self._relative_sky(s)
        deep = f + eclipse.UMBRA_SCATTERING * m * glowless
        return ((1.0 - b) * self.moon_visible + b * deep) * self.skylight

    def corona_radiance(self, w: ArrayLike) -> np.ndarray:
        """The corona as drawn (``eclipse.corona_drawn``: Baumbach's profile, ending with no edge
        at ``eclipse.CORONA_REACH`` solar radii) times b, 0 behind the moon.

        Parameters
        ----------
        w : numpy.ndarray
            (..., 3) unit vectors [1].

        Returns
        -------
        numpy.ndarray
            (..., 3) B(r) / B_sun of the sun's clear mean disc radiance E_n / (pi r^2) [kcd/m^2].
        """
        w = np.asarray(w, dtype=np.float64)
        r = self.sun.angular_radius
        mean_disc = self.sun_normal_irradiance / (np.pi * r * r)
        profile = eclipse.corona_drawn(angle_to(w, self.sun_direction) / r)
        profile = np.where(angle_to(w, self.moon_direction) >= self._moon.angular_radius, profile, 0.0)
        return (self._deep * profile)[..., None] * mean_disc

    @cached_property
    def corona_irradiance(self) -> np.ndarray:
        """Horizontal irradiance (3,) of ``corona_radiance`` (the moon taken as concentric with the
        sun, ``eclipse.corona_drawn_beyond``), dimmed by the cloud towards the sun. [klx]"""
        if not self._deep:
            return np.zeros(3)
        beyond = eclipse.corona_drawn_beyond(self._moon.angular_radius / self.sun.angular_radius)
        return (self._deep * beyond * self.sun_cloud_transmittance) * self.undimmed_sun_irradiance()

    def _corona_cells(self, grid: Grid):
        """(flat cell indices, (3, n) cell integrals of corona L cos^4(theta) dA) of ``grid``'s cells
        within ``eclipse.CORONA_REACH`` solar radii of the sun, 8 x 8 sub-samples a cell. [klx]"""
        reach = eclipse.CORONA_REACH * self.sun.angular_radius
        rows, cols = grid.shape
        x, y = grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
        near = angle_to(_unit(np.stack(np.broadcast_arrays(x, y), axis=-1)), self.sun_direction) <= reach + grid.pixel
        idx = np.flatnonzero(near)
        if idx.size == 0:
            return idx, np.zeros((3, 0))
        n = 8
        offsets = ((np.arange(n) + 0.5) / n - 0.5) * grid.pixel
        ox, oy = np.meshgrid(offsets, -offsets)
        sx = np.broadcast_to(x, (rows, cols)).ravel()[idx, None, None] + ox
        sy = np.broadcast_to(y, (rows, cols)).ravel()[idx, None, None] + oy
        cos4 = 1.0 / (1.0 + sx * sx + sy * sy) ** 2
        L = self.corona_radiance(_unit(np.stack([sx, sy], axis=-1))) * self.sun_cloud_transmittance
        return idx, np.einsum("kijc,kij->ck", L, cos4) * (grid.pixel / n) ** 2

    def radiance(self, s: ArrayLike, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """The sky's radiance without the sun disc: L_clear T + cloud glow.

        Parameters
        ----------
        s : numpy.ndarray
            (..., 2) sky-plane points [tan].
        footprint : float, numpy.ndarray or None
            The sky-plane width each point stands for (scalar or (...)) [tan], over which the
            cloud pattern is filtered (a camera's pixel near the horizon spans kilometres of
            cloud deck); None: unfiltered.

        Returns
        -------
        numpy.ndarray
            (..., 3) radiance [kcd/m^2].
        """
        return self._with_clouds(self.clear_radiance(s), s, footprint)

    def _with_clouds(self, L, s, footprint=None) -> np.ndarray:
        """The clear-sky radiance L (..., 3) [kcd/m^2] at sky-plane points s behind the clouds:
        L T + cloud glow (L itself, scaled in place, without clouds). [kcd/m^2]"""
        if self.clouds is None:
            return L
        transmittance, glow = self._cloud_shade(s, footprint)
        L *= np.clip(transmittance, 0.0, 1.0)[..., None]
        return L + glow

    def _cloud_shade(self, s, footprint=None):
        """The clouds' (transmittance (...), radiance (..., 3) [kcd/m^2]) at sky-plane points s
        (..., 2) [tan]: by their ``shade`` where they have one (the pattern sampled once)."""
        shade = getattr(self.clouds, "shade", None)
        if shade is not None:
            return shade(s, self.time, footprint=footprint, **self._cloud_light)
        return (self.clouds.transmittance(s, self.time, footprint),
                self.clouds.radiance(s, self.time, footprint=footprint, **self._cloud_light))

    def view_radiance(self, w: np.ndarray, s: np.ndarray, footprint: float | np.ndarray | None = None) -> np.ndarray:
        """``radiance(s, footprint)`` (..., 3) [kcd/m^2] at the sky-plane points s (..., 2) [tan] of
        the unit vectors w (..., 3), which it does not need (``Sky.view_radiance``)."""
        return self.radiance(s, footprint=footprint)

    @cached_property
    def _cloud_light(self) -> dict:
        return dict(sun_s=self.sun_point.copy(), sun_irradiance=self.sun_normal_irradiance * self.moon_visible,
                    sky_irradiance=self.clear_sky_irradiance)

    @cached_property
    def clear_sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the clear sky (3,), no sun disc, eclipse-dimmed. [klx]"""
        if self._deep:
            s, weight = outside_nodes(None)
            L = relative_nodes(self._clear_key, outside_nodes, None) * (self.zenith_luminance * self._dimming_at(s))
            return (L * weight[..., None]).sum(axis=(0, 1, 2))
        return self._relative_irradiance * (self.zenith_luminance * self._sky_dimming)

    @cached_property
    def sky_irradiance(self) -> np.ndarray:
        """Horizontal irradiance of the sky with clouds (3,), no sun disc (the corona in a deep
        eclipse included). [klx]"""
        if self._deep:
            return self._outside(None) + self.corona_irradiance
        return self._outside(None)

    def _outside(self, extent) -> np.ndarray:
        """Irradiance [klx] of the sky (``radiance``) outside the sky-plane rectangle ``extent``
        (x_min, y_min, x_max, y_max) [tan] (None: the whole hemisphere), by the quadrature of
        ``outside_nodes``; the clear sky's shape at its nodes is computed once for all frames
        with this clear sky (``nodes.relative_nodes``)."""
        s, weight = outside_nodes(extent)
        L = relative_nodes(self._clear_key, outside_nodes, extent) * (self.zenith_luminance * self._dimming_at(s))
        return (self._with_clouds(L, s) * weight[..., None]).sum(axis=(0, 1, 2))

    def raster(self, grid: Grid, *, fold_period: tuple[int, int] | None = None) -> SkyRaster:
        """The sky without the sun disc on a sky-plane grid: radiance at cell centres times the
        exact projected solid angles (Max 1991, eq. 2); ``outside`` by quadrature of the rest of the
        hemisphere (``_outside``).

        The smooth clear sky is evaluated on every k-th cell centre, nodes at most
        ``CLEAR_SKY_NODE_SPACING`` apart, and interpolated bilinearly (least accurate in the few
        cells at the sun where the Perez circumsolar term has a cusp; measured in
        docs/accuracy.md); clouds are evaluated at every cell centre.

        Parameters
        ----------
        grid : geometry.Grid
            The sky-plane grid [tan].
        fold_period : tuple of int or None
            (rows, cols): folded modulo that period, as in ``equirect.EquirectSky.raster``.

        Returns
        -------
        sky.raster.SkyRaster
            The weighted sky [klx]; without clouds, kept, from the second frame that asks for the same
            sky and grid, for the next (read-only: while the sun stands still every frame gets the same raster;
            a frame of forest.yaml spent 110 ms on its sky raster).
        """
        if self.clouds is not None:
            return self._raster(grid, fold_period)
        key = (replace(self, time=0.0), grid, None if fold_period is None else tuple(int(n) for n in fold_period))
        return kept_raster(_kept_rasters, key, lambda: self._raster(grid, fold_period), again=True)

    def _raster(self, grid: Grid, fold_period: tuple[int, int] | None) -> SkyRaster:
        """``raster`` computed. [klx]"""
        from pipeline.kernels import arrays

        rows, cols = grid.shape
        k = max(1, int(CLEAR_SKY_NODE_SPACING // grid.pixel))
        _, row_at, row_frac = lerp_nodes(rows, k)
        _, col_at, col_frac = lerp_nodes(cols, k)
        # clear_radiance at the nodes, the shape computed once for all frames (relative_nodes)
        relative = relative_nodes(self._clear_key, raster_nodes, grid, k)
        dimming = self._dimming_at(raster_nodes(grid, k)[0]) if self._deep else self._sky_dimming
        nodes = np.moveaxis(relative * (self.zenith_luminance * dimming), -1, 0)
        nodes = nodes.astype(np.float32)
        along = nodes[:, :, col_at] * (1 - col_frac) + nodes[:, :, col_at + 1] * col_frac  # (3, nodes, cols)
        weights = solid_angles32(grid)
        weighted = np.empty((3, rows, cols), dtype=np.float32)
        x, y = grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
        step = max(1, (1 << 20) // cols)
        transmittance, glow = np.empty((0, 0)), np.empty((0, 0, 3), dtype=np.float32)  # no clouds
        for lo in range(0, rows, step):  # bounded memory
            part = slice(lo, lo + step)
            if self.clouds is not None:
                transmittance, glow = self._cloud_shade(np.stack(np.broadcast_arrays(x, y[part]), axis=-1))
            # compiled: the clear sky between node rows, the clouds' transmittance and glow,
            # the solid angles, as L = lerp; L *= clip(T, 0, 1); L += glow; L * weights
            arrays.sky_rows(along, row_at, row_frac, lo, len(row_at[part]), self.clouds is not None,
                                  np.ascontiguousarray(transmittance, dtype=np.float64),
                                  np.ascontiguousarray(glow, dtype=np.float32), weights, weighted)
        outside = self._outside(grid.extent)
        if self._deep:  # the corona, cell by cell (its light beyond the grid is left out)
            idx, corona = self._corona_cells(grid)
            weighted.reshape(3, -1)[:, idx] += corona.astype(np.float32)
        if fold_period is not None:
            weighted = fold(weighted, sky_offset(grid), fold_period)
            period_rows, period_cols = fold_period
            grid = sky_grid((0, 0), (period_rows, period_cols), grid.pixel)
        return SkyRaster(grid, weighted, outside)

    @overload
    def equirect(self, width: int, *, parts: Literal[False] = False) -> np.ndarray: ...

    @overload
    def equirect(self, width: int, *, parts: Literal[True]) -> tuple[np.ndarray, dict[str, np.ndarray]]: ...

    @overload
    def equirect(self, width: int, *, parts: bool) -> np.ndarray | tuple[np.ndarray, dict[str, np.ndarray]]: ...

    def equirect(self, width: int, *, parts: bool = False) -> np.ndarray | tuple[np.ndarray, dict[str, np.ndarray]]:
        """The sky and its sun as an equirectangular radiance image.

        In ``equirect``'s convention (top row at the zenith, centre column north, east at three
        quarters), with the sun disc deposited area-correctly: each of many small samples of the
        disc carries L cos(theta) d_omega into the texel it falls in, divided by that texel's
        exact projected solid angle, so the image's irradiance equals
        ``sun_kernel.unshadowed(sky)``. Below the horizon: 0.

        Parameters
        ----------
        width : int
            Even, at least 4 [pixels].
        parts : bool
            Also the image's parts (the light passes).

        Returns
        -------
        numpy.ndarray or tuple
            The image (width / 2, width, 3) float32 [kcd/m^2]; with ``parts``, (the image,
            {"sun": the sun disc alone, "sky": the rest}), each float32 as rounded from the
            float64 parts the image is the sum of.

        Raises
        ------
        ValueError
            For an odd width or one under 4.
        """
        if width < 4 or width % 2:
            raise ValueError(f"width must be even and at least 4, got {width}")
        height = width // 2
        upper = height // 2
        theta = (np.arange(upper) + 0.5) * (np.pi / height)
        phi = ((np.arange(width) + 0.5) / width - 0.5) * 2.0 * np.pi
        tan = np.tan(theta)[:, None]
        s = np.stack([tan * np.sin(phi), tan * np.cos(phi)], axis=-1)
        image = np.zeros((height, width, 3), dtype=np.float64)
        image[:upper] = self._with_clouds(self._clear(s, corona=False), s)
        # the sun: samples on a square grid of the plane tangent at the sun (gnomonic)
        r = self.sun.angular_radius
        spacing = min(r / 64.0, np.pi / height / 4.0)
        sky = image.copy() if parts else None
        self._deposit(image, lambda w: self._sun_samples(w, lambda centre, rho, near: spacing, spacing), r, spacing)
        if self._deep:  # the corona, more coarsely: it is smooth beyond the limb; not S's light,
            # so in the sky's part
            spacing = min(r / 16.0, np.pi / height / 4.0)
            for target in (image, sky) if sky is not None else (image,):
                self._deposit(target, lambda w: self.corona_radiance(w) * self.sun_cloud_transmittance,
                              eclipse.CORONA_REACH * r, spacing)
        if sky is not None:  # with ``parts``
            return image.astype(np.float32), {"sun": (image - sky).astype(np.float32), "sky": sky.astype(np.float32)}
        return image.astype(np.float32)

    def _deposit(self, image, radiance, reach: float, spacing: float) -> None:
        """Add to the equirectangular ``image`` (height, width, 3) [kcd/m^2] the light
        ``radiance(w)`` (..., 3) [kcd/m^2] within ``reach`` [rad] of the sun, sampled every
        ``spacing`` [rad] on the plane tangent at the sun, each sample's L cos(theta) d_omega
        put into its texel over the texel's projected solid angle."""
        height, width = image.shape[:2]
        upper = height // 2
        n = int(np.ceil((reach + 2 * spacing) / spacing))
        g = (np.arange(-n, n + 1)) * spacing
        gx, gy = np.meshgrid(g, g)
        _, e1, e2 = tangent_axes(self.sun.azimuth, self.sun.elevation)
        p = self.sun_direction + gx[..., None] * e1 + gy[..., None] * e2
        norm = np.linalg.norm(p, axis=-1)
        w = p / norm[..., None]
        d_omega = spacing**2 / norm**3
        energy = radiance(w) * (d_omega * np.maximum(w[..., 2], 0.0))[..., None]
        row = np.minimum((np.arccos(np.clip(w[..., 2], -1, 1)) / np.pi * height).astype(np.int64), height - 1)
        col = np.floor((np.arctan2(w[..., 0], w[..., 1]) / (2 * np.pi) + 0.5) * width).astype(np.int64) % width
        keep = (row < upper) & (energy.sum(axis=-1) > 0)
        row, col, energy = row[keep], col[keep], energy[keep]
        theta0, theta1 = row * np.pi / height, (row + 1) * np.pi / height
        texel = 0.5 * (np.sin(theta1) ** 2 - np.sin(theta0) ** 2) * (2.0 * np.pi / width)
        np.add.at(image, (row, col), energy / texel[:, None])
