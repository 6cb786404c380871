"""The sky of a deep or total solar eclipse, and the corona (docs/method.md, "The eclipse sky").

Up to 99.8% obscuration the sky is the clear sky times S (Sharp, Silverman & Lloyd 1971,
Applied Optics 10(6) 1207-1210): ``ProceduralSky`` does that by itself. Deeper, the sky is the
light scattered into the umbra from outside it. This module gives, for any sky direction w,

    F(w) = integral over the line of sight of  beta(l) T(l) S(l) dl / integral of beta(l) T(l) dl,

the uneclipsed fraction of the sun seen from the points where that line of sight scatters
sunlight (single scattering, Rayleigh plus aerosol with their scale heights, a spherical Earth),
weighted by how much each point adds to the clear sky's radiance: scattering coefficient beta
times phase function, times the transmittance T towards the observer and from the sun. S at a
point P follows from the observer's own sun and moon by parallax: the moon's centre seen from P
is D m - P (D its distance, from its angular radius, m its direction), the sun's direction does
not move. Per channel: red light comes from farther away along a ray than blue, so the rays near
the horizon, which leave the umbra, come out reddened.

Multiple scattering, which carries light sideways into the umbra, is k M(w) G(w): M is W, the
uneclipsed fraction on the ground averaged over a sideways diffusion length
(``diffused_fraction``), found at the foot of each point of the line of sight along the moon's
shadow, times the share of light that reaches that point sideways at its own height (``way_in``:
scattered once more on a horizontal path DIFFUSION_LENGTH long there and dimmed on it), averaged
along the line of sight as its extinction weights its points per channel; k the share of the
clear sky's light this multiply scattered light is (``UMBRA_SCATTERING``). The air low down takes
little of it (its way in is opaque): a line of sight near the horizon sees it from the points far
out and high up, through its own long low path, and comes out reddened, while the zenith's light,
scattered in at a few kilometres, is bluer than the day's. The deep-eclipse model is blended in
once the moon covers 99.8% of the sun's area (u, the uncovered area fraction of the uniform discs,
below ``SHARP_LIMIT``) so that it meets the clear sky times S with no bend:

    L(w) = L_clear(w) [(1 - b) S + b (F(w) + k M(w) G(w))],   b = clip(1 - u / SHARP_LIMIT, 0, 1)^3,

G(w) the clear sky's shape 90 degrees from the sun over its shape at w: the multiply scattered
light is the clear sky's light with its gradation with zenith angle (counted once: M is a mean,
not a path length) but without the circumsolar glow, which needs the direct sun
(``ProceduralSky._dimming_at``); plus, during the deep eclipse, b times the corona
(``corona_profile``) outside the moon. Which measurement fixes each constant: docs/method.md,
"The eclipse sky".

Units: radians, metres; the factors are dimensionless. [1]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike

from pipeline.sky.ephemeris import MOON_RADIUS, obscured_fraction

__all__ = [
    "SHARP_LIMIT", "MULTIPLE_SCATTERING", "UMBRA_SCATTERING", "EARTH_RADIUS", "RAYLEIGH_SCALE_HEIGHT",
    "AEROSOL_SCALE_HEIGHT", "AEROSOL_ASYMMETRY", "PATH_LENGTH", "PATH_NODES", "TABLE_ELEVATIONS", "TABLE_AZIMUTHS",
    "FULL_TABLE", "METER_TABLE",
    "DIFFUSION_LENGTH", "MAP_CELLS", "MAP_EXTENT", "CORONA_REACH", "RGB_WAVELENGTHS", "deep_weight",
    "vertical_optical_depths", "point_sun_fraction", "diffused_fraction", "line_of_sight", "EclipseField",
    "way_in", "corona_profile", "corona_beyond", "corona_drawn", "corona_drawn_beyond",
]

SHARP_LIMIT = 0.002
"""u, the sun's uncovered area fraction (1 - ``ephemeris.obscured_fraction``, the obscuration that
``sunshade check`` and ``sunshade eclipses`` give), below which the deep-eclipse sky is blended
in: 99.8% obscuration, the depth to which Sharp, Silverman & Lloyd (1971) found the sky to behave
as attenuated sunlight. At and above it the sky is exactly the clear sky times S (S, the
limb-darkened sun's light left, is about 0.0011 there). [1]"""

MULTIPLE_SCATTERING = 0.10
"""The twilight sky's floor of multiply scattered light, a fraction of the zenith's single
scattering (``twilight``; docs/method.md, "The procedural sky"): the factor the eclipse sky's
floor had when it was set at Dallas 2024; the eclipse's own is UMBRA_SCATTERING. [1]"""

UMBRA_SCATTERING = 0.147
"""k, the share of the clear sky's (glowless) light that the multiply scattered light in the
moon's shadow is, times the diffused uneclipsed fraction there and the share that reaches each
point sideways (``way_in``). Fixed by the sky-quality meters of the 2017 eclipse in Idaho
(12.4-13.3 mag/arcsec^2, the sun 46 degrees up): the zenith at mid-totality at Stanley, Idaho,
at their middle, 0.78 cd/m^2 (docs/method.md, "The eclipse sky"). [1]"""

EARTH_RADIUS = 6_371_000.0
"""Mean radius of the Earth, for the height of a point along a line of sight. [m]"""

RAYLEIGH_SCALE_HEIGHT = 8_000.0
"""Scale height of the molecular atmosphere (e.g. Bohren & Clothiaux 2006, sec. 8.1). [m]"""

AEROSOL_SCALE_HEIGHT = 1_200.0
"""Scale height of the boundary-layer aerosol (typical; Seinfeld & Pandis 2006, ch. 2). [m]"""

AEROSOL_ASYMMETRY = 0.7
"""Henyey-Greenstein asymmetry of continental aerosol (typical value). [1]"""

PATH_LENGTH = 1_000_000.0
"""Farthest distance along a line of sight integrated: a horizontal ray is 78 km up there. [m]"""

PATH_NODES = 192
"""Nodes along each line of sight, spaced quadratically (dense near the observer). [count]"""

TABLE_ELEVATIONS = 33
"""Elevations of the direction table, spaced quadratically from the horizon to the zenith. [count]"""

TABLE_AZIMUTHS = 72
"""Azimuths of the direction table, 5 degrees apart. [count]"""

FULL_TABLE = (TABLE_ELEVATIONS, TABLE_AZIMUTHS, PATH_NODES)
"""(elevations, azimuths, path nodes) of the deep eclipse's line-of-sight table (``EclipseField``)
for a frame's sky. [count]"""

METER_TABLE = (17, 36, 96)
"""(elevations, azimuths, path nodes) of the coarser table an exposure meter reads the deep
eclipse's horizontal irradiance from: within 0.35% of the full table's (TABLE_ELEVATIONS,
TABLE_AZIMUTHS, PATH_NODES) at Dallas 2024 from C2 to C3 (every 10 s, per channel), in a fifth
of the time (docs/accuracy.md, "The eclipse sky"). [count]"""

DIFFUSION_LENGTH = 100_000.0
"""Length over which light diffuses sideways into the umbra by multiple scattering (the kernel
of ``diffused_fraction``) and the length of the sideways path at each height that it crosses
(``way_in``): the umbra's radius, about 100 km (the margin r_moon - r_sun of a total eclipse
at 0.55 arcsec per km; 0.281 - 0.266 degrees at Dallas 2024). With k set at Stanley, Idaho
2017, Dallas 2024's zenith is in both published bands from 85 km up (docs/method.md, "The
eclipse sky"). [m]"""

MAP_CELLS = 160
"""Cells a side of the map of the diffused uneclipsed fraction. [count]"""

MAP_EXTENT = 1_200_000.0
"""Half-width of that map: every point of a line of sight falls on it. [m]"""

CORONA_REACH = 16.0
"""Solar radii out to which the corona is drawn, less its value there so that it meets the sky
with no edge (``corona_drawn``; what is left out: 5.9% of its light, 4.7% of it beyond). [1]"""

RGB_WAVELENGTHS = np.array([0.610, 0.550, 0.465])
"""Representative wavelengths of the R, G, B channels: the eclipse sky's and the sun's colour
(``sun_disc.sun_colour``). [um]"""


def deep_weight(uncovered: float) -> float:
    """b: the weight of the deep-eclipse sky, 0 for u >= SHARP_LIMIT, 1 at u = 0.

    b = v^3, v = 1 - u / SHARP_LIMIT: its slope and curvature are 0 where the blend starts, so the
    sky's light bends there no more than the eclipse's own light curve does (a linear b stalled
    its fall for a frame; docs/accuracy.md, "The eclipse sky"). u is the sun's uncovered area,
    not its light S: the blend starts at 99.8% obscuration as ``sunshade check`` reports it
    (limb darkening puts S = 0.002 at 99.66%).

    Parameters
    ----------
    uncovered : float
        u, the uncovered area fraction of the sun's disc, 1 - ``ephemeris.obscured_fraction`` [1].

    Returns
    -------
    float
        b = clip(1 - u / SHARP_LIMIT, 0, 1)^3; exactly 0 for u >= SHARP_LIMIT [1].
    """
    if not uncovered < SHARP_LIMIT:
        return 0.0
    return float(min(1.0 - uncovered / SHARP_LIMIT, 1.0) ** 3)


def vertical_optical_depths(turbidity: float) -> tuple[np.ndarray, np.ndarray]:
    """Rayleigh and aerosol vertical optical depths at RGB_WAVELENGTHS.

    0.008735 lambda^-4.08 and beta lambda^-1.3 with beta = 0.04608 T - 0.04586 (Preetham et al. 1999,
    appendix A.1, as ``sun_disc.sun_colour``).

    Parameters
    ----------
    turbidity : float
        T [1].

    Returns
    -------
    rayleigh, aerosol : numpy.ndarray
        Each (3,) per R, G, B [1].
    """
    lam = RGB_WAVELENGTHS
    beta = max(0.04608 * turbidity - 0.04586, 0.0)
    return 0.008735 * lam**-4.08, beta * lam**-1.3


def point_sun_fraction(points: ArrayLike, *, sun_direction: ArrayLike, moon_direction: ArrayLike, sun_radius: float,
                       moon_radius: float) -> np.ndarray:
    """Uneclipsed area fraction of the sun seen from points around the observer.

    The moon's centre, at distance D = R_moon / sin(moon_radius) along ``moon_direction`` from the
    observer, seen from P is D m - P; its angular radius there is asin(R_moon / |D m - P|); the sun's
    direction and radius do not change.

    Parameters
    ----------
    points : numpy.ndarray
        (..., 3) points, observer at the origin, x east, y north, z up [m].
    sun_direction, moon_direction : numpy.ndarray
        (3,) unit vectors of the sun and of the moon seen by the observer [1].
    sun_radius, moon_radius : float
        Angular radii of the sun and of the moon seen by the observer [rad].

    Returns
    -------
    numpy.ndarray
        (...) float64 fraction [1].
    """
    distance = MOON_RADIUS / np.sin(moon_radius)
    moon = distance * np.asarray(moon_direction, dtype=np.float64) - np.asarray(points, dtype=np.float64)
    reach = np.linalg.norm(moon, axis=-1)
    unit = moon / reach[..., None]
    sun = np.asarray(sun_direction, dtype=np.float64)
    sep = 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(unit - sun, axis=-1), 0.0, 1.0))
    covered = obscured_fraction(sep, np.full(sep.shape, sun_radius), np.arcsin(MOON_RADIUS / reach))
    return cast(np.ndarray, 1.0 - covered)  # arrays in, an array out


def _line_nodes(nodes: int = PATH_NODES):
    """Distances l along a line of sight [m] (``nodes`` of them, quadratically spaced) and their
    widths dl [m]."""
    t = (np.arange(nodes) + 0.5) / nodes
    return PATH_LENGTH * t * t, PATH_LENGTH * 2.0 * t / nodes


def diffused_fraction(*, sun_direction: ArrayLike, moon_direction: ArrayLike, sun_radius: float,
                      moon_radius: float) -> tuple[np.ndarray, float]:
    """The uneclipsed fraction S on the ground around the observer, diffused sideways.

    S on the ground plane, averaged with the kernel exp(-rho / DIFFUSION_LENGTH) /
    (2 pi DIFFUSION_LENGTH^2) (the light that diffuses sideways into the umbra, multiple scattering),
    on a MAP_CELLS x MAP_CELLS map centred on the observer, rows north-up.

    Parameters
    ----------
    sun_direction, moon_direction, sun_radius, moon_radius
        As in ``point_sun_fraction``.

    Returns
    -------
    W : numpy.ndarray
        (MAP_CELLS, MAP_CELLS) float64 map [1].
    extent : float
        Half-width of the map, MAP_EXTENT [m].
    """
    from scipy import fft

    n, extent = MAP_CELLS, MAP_EXTENT
    cell = 2.0 * extent / n
    centres = (np.arange(n) + 0.5) * cell - extent
    x, y = np.meshgrid(centres, -centres)
    points = np.stack([x, y, np.zeros_like(x)], axis=-1)
    s = point_sun_fraction(points, sun_direction=sun_direction, moon_direction=moon_direction,
                           sun_radius=sun_radius, moon_radius=moon_radius)
    half = int(np.ceil(8 * DIFFUSION_LENGTH / cell))
    k = (np.arange(-half, half + 1)) * cell
    kernel = np.exp(-np.hypot(*np.meshgrid(k, k)) / DIFFUSION_LENGTH)
    kernel /= kernel.sum()
    padded = np.pad(s, half, mode="edge")  # beyond the map: its edge's values
    shape = [fft.next_fast_len(n + 4 * half + 1, real=True)] * 2
    product = fft.rfft2(padded, shape) * fft.rfft2(kernel, shape)
    full = fft.irfft2(product, shape)
    return full[2 * half:2 * half + n, 2 * half:2 * half + n], extent


def _map_lookup(field, extent, x, y):
    """Bilinear lookup of a ``diffused_fraction`` map at ground points (x, y) [m], clamped to its edges."""
    n = field.shape[0]
    cell = 2.0 * extent / n
    col = np.clip((x + extent) / cell - 0.5, 0.0, n - 1.000001)
    row = np.clip((extent - y) / cell - 0.5, 0.0, n - 1.000001)
    r, c = row.astype(np.int64), col.astype(np.int64)
    fr, fc = row - r, col - c
    return ((1 - fr) * ((1 - fc) * field[r, c] + fc * field[r, c + 1])
            + fr * ((1 - fc) * field[r + 1, c] + fc * field[r + 1, c + 1]))


def line_of_sight(directions: ArrayLike, *, sun_direction: ArrayLike, moon_direction: ArrayLike, sun_radius: float,
                  moon_radius: float, turbidity: float, nodes: int = PATH_NODES) -> tuple[np.ndarray, np.ndarray]:
    """F and M, per R, G, B channel, along lines of sight.

    F(w) = integral beta T S dl / integral beta T dl: the clear-sky-weighted uneclipsed fraction
    of the sun at the points where the line of sight scatters (single scattering; module
    docstring), beta the Rayleigh and aerosol scattering coefficients times their phase
    functions, T the transmittance to the observer and from the sun;
    M(w) = integral k_ext e^(-tau(0, l)) W(P0) I(l) dl / integral k_ext e^(-tau(0, l)) dl: the
    sideways-diffused uneclipsed fraction W (``diffused_fraction``) at the foot P0 of each point
    along the moon's shadow (the umbra is a cone along the moon's direction), times the share
    I = ``way_in`` of k_ext there that reaches the point sideways, averaged as the points' light
    reaches the observer.

    Parameters
    ----------
    directions : numpy.ndarray
        (n, 3) unit vectors, wz >= 0 [1].
    sun_direction, moon_direction, sun_radius, moon_radius
        As in ``point_sun_fraction``.
    turbidity : float
        T [1].
    nodes : int, optional
        Along each line of sight [count].

    Returns
    -------
    F, M : numpy.ndarray
        Each (n, 3) float64 [1].
    """
    w = np.asarray(directions, dtype=np.float64)
    l, dl = _line_nodes(nodes)
    wz = np.maximum(w[:, 2:3], 0.0)
    z = np.sqrt(EARTH_RADIUS**2 + l * l + 2.0 * EARTH_RADIUS * l * wz) - EARTH_RADIUS  # (n, k)
    tau_r, tau_a = vertical_optical_depths(turbidity)
    dens_r = np.exp(-z / RAYLEIGH_SCALE_HEIGHT)[..., None]
    dens_a = np.exp(-z / AEROSOL_SCALE_HEIGHT)[..., None]
    k_r = tau_r / RAYLEIGH_SCALE_HEIGHT * dens_r  # (n, k, 3) [1/m]
    k_a = tau_a / AEROSOL_SCALE_HEIGHT * dens_a
    step = (k_r + k_a) * dl[None, :, None]
    to_observer = np.exp(-(np.cumsum(step, axis=1) - 0.5 * step))
    sun = np.asarray(sun_direction, dtype=np.float64)
    airmass = 1.0 / max(sun[2], 0.05)
    from_sun = np.exp(-airmass * (tau_r * dens_r + tau_a * dens_a))
    c = w @ sun
    p_r = 3.0 / (16.0 * np.pi) * (1.0 + c * c)
    g = AEROSOL_ASYMMETRY
    p_a = (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * c) ** 1.5)
    weight = (k_r * p_r[:, None, None] + k_a * p_a[:, None, None]) * to_observer * from_sun
    points = l[None, :, None] * w[:, None, :]
    s = point_sun_fraction(points, sun_direction=sun, moon_direction=moon_direction, sun_radius=sun_radius,
                           moon_radius=moon_radius)
    single = np.einsum("nkc,nk->nc", weight, s) / weight.sum(axis=1)
    moon = np.asarray(moon_direction, dtype=np.float64)
    foot = points - (points[..., 2:3] / max(moon[2], 0.05)) * moon
    field, extent = diffused_fraction(sun_direction=sun, moon_direction=moon_direction, sun_radius=sun_radius,
                                      moon_radius=moon_radius)
    diffused = _map_lookup(field, extent, foot[..., 0], foot[..., 1])
    seen = step * to_observer
    multiple = np.einsum("nkc,nkc->nc", seen, diffused[..., None] * way_in(k_r + k_a)) / seen.sum(axis=1)
    return single, multiple


@dataclass(frozen=True)
class EclipseField:
    """F and M of ``line_of_sight`` tabulated over the upper hemisphere, interpolated bilinearly.

    Attributes
    ----------
    table : numpy.ndarray
        (TABLE_ELEVATIONS, TABLE_AZIMUTHS + 1, 6) F and M (R, G, B each) at elevations
        (pi/2) u^2 (u uniform in [0, 1]) and azimuths 0..2 pi (the last column repeats the
        first) [1].
    """

    table: np.ndarray

    @classmethod
    def compute(cls, *, sun_direction: ArrayLike, moon_direction: ArrayLike, sun_radius: float,
                moon_radius: float, turbidity: float,
                table: tuple[int, int, int] = FULL_TABLE) -> EclipseField:
        """The table of ``line_of_sight`` for a sun and moon.

        Parameters
        ----------
        sun_direction, moon_direction, sun_radius, moon_radius, turbidity
            As ``line_of_sight`` takes them.
        table : tuple of (int, int, int), optional
            Its (elevations, azimuths, path nodes) [count] (FULL_TABLE; METER_TABLE: the meter's
            coarser one).

        Returns
        -------
        EclipseField
            The field.
        """
        elevations, azimuths, nodes = table
        u = np.linspace(0.0, 1.0, elevations)
        el = 0.5 * np.pi * u * u
        az = np.arange(azimuths) * (2.0 * np.pi / azimuths)
        e, a = np.meshgrid(el, az, indexing="ij")
        w = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1).reshape(-1, 3)
        f = np.concatenate(line_of_sight(w, sun_direction=sun_direction, moon_direction=moon_direction,
                                         sun_radius=sun_radius, moon_radius=moon_radius, turbidity=turbidity,
                                         nodes=nodes), axis=-1)
        f = f.reshape(elevations, azimuths, 6)
        return cls(np.concatenate([f, f[:, :1]], axis=1))

    def __call__(self, w: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """F and M at unit vectors w.

        Parameters
        ----------
        w : numpy.ndarray
            (..., 3) unit vectors; wz below 0 is taken as the horizon [1].

        Returns
        -------
        F, M : numpy.ndarray
            Each (..., 3) float64 [1].
        """
        w = np.asarray(w, dtype=np.float64)
        elevations, azimuths = self.table.shape[0], self.table.shape[1] - 1
        el = np.arcsin(np.clip(w[..., 2], 0.0, 1.0))
        u = np.sqrt(el / (0.5 * np.pi)) * (elevations - 1)
        v = (np.arctan2(w[..., 0], w[..., 1]) % (2.0 * np.pi)) / (2.0 * np.pi) * azimuths
        i = np.minimum(u.astype(np.int64), elevations - 2)
        j = np.minimum(v.astype(np.int64), azimuths - 1)
        fu, fv = (u - i)[..., None], (v - j)[..., None]
        t = self.table
        out = ((1 - fu) * ((1 - fv) * t[i, j] + fv * t[i, j + 1])
               + fu * ((1 - fv) * t[i + 1, j] + fv * t[i + 1, j + 1]))
        return out[..., :3], out[..., 3:]


def way_in(extinction: ArrayLike) -> np.ndarray:
    """The share of light that reaches a point of the umbra sideways: tau e^-tau.

    tau = extinction x DIFFUSION_LENGTH, the optical depth of the horizontal path from the
    umbra's edge at the point's own height: the light was scattered once more on its way (tau,
    bluer) and dimmed on it (e^-tau, redder). Low down, where the air is dense, tau is large and
    little gets in (e^-13 in red at the ground at Dallas 2024); a few kilometres up tau is near 1.

    Parameters
    ----------
    extinction : float or numpy.ndarray
        Extinction coefficient (Rayleigh and aerosol) at the point, per channel [1/m].

    Returns
    -------
    numpy.ndarray
        tau e^-tau, float64 of the shape of ``extinction`` [1].
    """
    tau = np.asarray(extinction, dtype=np.float64) * DIFFUSION_LENGTH
    return cast(np.ndarray, tau * np.exp(-tau))


def corona_profile(r: ArrayLike) -> np.ndarray:
    """Baumbach's K+F corona, B(r) / B_sun = 1e-6 (0.0532 r^-2.5 + 1.425 r^-7 + 2.565 r^-17).

    B_sun the mean radiance of the disc (Allen's Astrophysical Quantities, Cox 2000, sec. 14.8).

    Parameters
    ----------
    r : float or numpy.ndarray
        Distance from the sun's centre, >= 1 (0 inside the limb) [solar radii].

    Returns
    -------
    numpy.ndarray
        B(r) / B_sun, float64 of the shape of ``r`` [1].
    """
    r = np.asarray(r, dtype=np.float64)
    safe = np.maximum(r, 1.0)
    b = 1e-6 * (0.0532 * safe**-2.5 + 1.425 * safe**-7 + 2.565 * safe**-17)
    return np.where(r >= 1.0, b, 0.0)


def corona_beyond(r0: float) -> float:
    """The corona's flux outside r0 over the sun's: 2 integral_{r0}^inf r B/B_sun dr in closed form.

    1.12e-6 for r0 = 1.

    Parameters
    ----------
    r0 : float
        >= 1 [solar radii].

    Returns
    -------
    float
        The flux ratio [1].
    """
    r0 = max(float(r0), 1.0)
    return 2e-6 * (0.0532 * r0**-0.5 / 0.5 + 1.425 * r0**-5 / 5.0 + 2.565 * r0**-15 / 15.0)


def corona_drawn(r: ArrayLike) -> np.ndarray:
    """The corona as drawn, B(r) - B(CORONA_REACH) out to CORONA_REACH and 0 beyond, over B_sun.

    ``corona_profile``, made continuous where it ends.

    Parameters
    ----------
    r : float or numpy.ndarray
        Distance from the sun's centre [solar radii].

    Returns
    -------
    numpy.ndarray
        float64 of the shape of ``r`` [1].
    """
    r = np.asarray(r, dtype=np.float64)
    edge = float(corona_profile(CORONA_REACH))
    return np.where(r <= CORONA_REACH, corona_profile(r) - edge, 0.0) * (r >= 1.0)


def corona_drawn_beyond(r0: float) -> float:
    """The flux of ``corona_drawn`` outside r0 over the sun's, in closed form.

    Parameters
    ----------
    r0 : float
        As in ``corona_beyond``; held to CORONA_REACH at most.

    Returns
    -------
    float
        The flux ratio [1].
    """
    r0 = min(max(float(r0), 1.0), CORONA_REACH)
    edge = float(corona_profile(CORONA_REACH))
    return corona_beyond(r0) - corona_beyond(CORONA_REACH) - edge * (CORONA_REACH**2 - r0 * r0)
