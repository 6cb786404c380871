"""The ground's reflectance f_r(V, L) (Max 1991, eq. 1 and the paragraph after it; docs/method.md,
"The ground's reflectance"): the models (RPV, RossThick-LiSparse-Reciprocal), their albedos and
their shape normalised to the albedo texture. The sky's view bands are ``brdf_bands``'s, the
frame's ground seen through them ``brdf_view``'s. ``lambert`` never comes here: its frames keep
the camera's own path.

Directions are unit vectors (..., 3) in world axes pointing away from the ground: ``v`` towards
the viewer, ``l`` towards the light. Both conventions of relative azimuth in the literature
are avoided by writing each model with vectors: the hot spot is v = l (the viewer has the light
behind), where the phase angle g (cos g = v . l) is 0."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike

from pipeline.config.vocabulary import REFLECTANCES

__all__ = [
    "VIEW_ZENITH_LIMIT", "QUADRATURE", "reflectance_factor", "Reflectance", "Lambert", "Rpv", "RossLi",
    "directional_reflectance", "white_sky_albedo", "shape",
    "clamp_view", "cell_directions",
]

if TYPE_CHECKING:
    from pipeline.config.settings import BrdfConfig  # model and parameters: any value with those two fields
    from pipeline.core.geometry import Grid

VIEW_ZENITH_LIMIT = np.radians(85.0)
"""The view zenith angle the models are read at, at most: a bowl-shaped RPV (k < 1) grows
without bound towards a grazing view (mu_v^(k - 1)), where no measurement supports it. [rad]"""

QUADRATURE = (32, 64)
"""Gauss-Legendre nodes in cos(zenith) on (0, 1) and equal steps in azimuth of the hemisphere
quadratures (directional and white-sky reflectance). [count]"""


def reflectance_factor(brdf: BrdfConfig, v: ArrayLike, l: ArrayLike) -> np.ndarray:
    """The bidirectional reflectance factor pi f_r(v, l) of the model.

    Parameters
    ----------
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).
    v : numpy.ndarray
        (..., 3) unit vectors towards the viewer, above the ground [1].
    l : numpy.ndarray
        (..., 3) unit vectors towards the light, above the ground, broadcastable with ``v`` [1].

    Returns
    -------
    numpy.ndarray
        (...) float64 [1].

    Raises
    ------
    ValueError
        For an unknown model.
    """
    if brdf.model not in REFLECTANCES:
        raise ValueError(f"no such reflectance model: {brdf.model!r}")
    model: type[Reflectance] = REFLECTANCES.load(brdf.model)  # a class of the Protocol's shape
    return model.factor(np.asarray(v, dtype=np.float64), np.asarray(l, dtype=np.float64), **dict(brdf.parameters))


def _slopes(v, l):
    """cos of both zenith angles, cos g, and the tangent vectors v_xy / mu_v, l_xy / mu_l."""
    mv, ml = np.maximum(v[..., 2], 1e-9), np.maximum(l[..., 2], 1e-9)
    tv, tl = v[..., :2] / mv[..., None], l[..., :2] / ml[..., None]
    return mv, ml, np.clip(np.sum(v * l, axis=-1), -1.0, 1.0), tv, tl


def _rpv(v, l, rho0, k, theta, rho_c):
    """Rahman, Pinty and Verstraete (1993), eqs. 5-9: rho0 M F (1 + R), M the modified Minnaert
    term (mu_l mu_v)^(k-1) / (mu_l + mu_v)^(1-k), F the Henyey-Greenstein phase function of the
    phase angle g, (1 - theta^2) / (1 + 2 theta cos g + theta^2)^1.5 (theta < 0: backward), and
    1 + R = 1 + (1 - rho_c) / (1 + G) the hot spot, G = |tan(th_l) a_l - tan(th_v) a_v| the
    distance between the two directions on the plane z = 1 (0 at v = l)."""
    # component by component (no (..., 3) temporaries: the shape is read on large lattices)
    vx, vy, vz, lx, ly, lz = v[..., 0], v[..., 1], v[..., 2], l[..., 0], l[..., 1], l[..., 2]
    mv, ml = np.maximum(vz, 1e-9), np.maximum(lz, 1e-9)
    cos_g = np.clip(vx * lx + vy * ly + vz * lz, -1.0, 1.0)
    minnaert = (mv * ml) ** (k - 1.0) / (mv + ml) ** (1.0 - k)
    phase = (1.0 - theta * theta) / (1.0 + 2.0 * theta * cos_g + theta * theta) ** 1.5
    big_g = np.sqrt((lx / ml - vx / mv) ** 2 + (ly / ml - vy / mv) ** 2)
    return rho0 * minnaert * phase * (1.0 + (1.0 - rho_c) / (1.0 + big_g))


def _rossli(v, l, f_iso, f_vol, f_geo):
    """RossThick-LiSparse-Reciprocal (Lucht, Schaaf and Strahler 2000, eqs. 37-45; h/b = 2,
    b/r = 1): f_iso + f_vol K_vol + f_geo K_geo, xi the phase angle."""
    mv, ml, cos_xi, tv, tl = _slopes(v, l)
    xi = np.arccos(cos_xi)
    k_vol = ((0.5 * np.pi - xi) * cos_xi + np.sin(xi)) / (mv + ml) - 0.25 * np.pi
    sec = 1.0 / mv + 1.0 / ml
    d2 = np.sum((tl - tv) ** 2, axis=-1)
    cross = tl[..., 0] * tv[..., 1] - tl[..., 1] * tv[..., 0]  # tan tan sin(phi)
    cos_t = np.clip(2.0 * np.sqrt(d2 + cross * cross) / sec, -1.0, 1.0)
    t = np.arccos(cos_t)
    overlap = (t - np.sin(t) * cos_t) * sec / np.pi
    k_geo = overlap - sec + 0.5 * (1.0 + cos_xi) / (mv * ml)
    return f_iso + f_vol * k_vol + f_geo * k_geo


class Reflectance(Protocol):
    """A ground reflectance model: a class of this shape, and one line in
    ``vocabulary.REFLECTANCES`` naming it and its parameters (their ranges in
    ``vocabulary.BRDF_PARAMETERS``), add a model (docs/design.md, "Models plug in")."""

    @staticmethod
    def factor(v: np.ndarray, l: np.ndarray, **parameters: float) -> np.ndarray:
        """The bidirectional reflectance factor pi f_r(v, l).

        Parameters
        ----------
        v, l : numpy.ndarray
            (..., 3) float64 unit vectors towards the viewer and the light, above the ground [1].
        **parameters : float
            The model's parameters, by name [1].

        Returns
        -------
        numpy.ndarray
            (...) float64 [1].
        """


class Lambert:
    """The paper's constant reflectance: pi f_r = 1 (its frames take the camera's own path)."""

    @staticmethod
    def factor(v: np.ndarray, l: np.ndarray) -> np.ndarray:
        """1 for every pair of directions."""
        return np.ones(np.broadcast_shapes(np.shape(v), np.shape(l))[:-1])


class Rpv:
    """Rahman, Pinty and Verstraete (1993): rho0, k, theta, rho_c (``_rpv``)."""

    factor = staticmethod(_rpv)


class RossLi:
    """The MODIS RossThick-LiSparse-Reciprocal kernels: f_iso, f_vol, f_geo (``_rossli``)."""

    factor = staticmethod(_rossli)


@functools.lru_cache(maxsize=1)
def _hemisphere():
    """Quadrature directions (n, 3) of the upper hemisphere and weights (n,) of cos(zenith)
    d_omega, summing to pi. [1], [sr]"""
    nodes, weights = np.polynomial.legendre.leggauss(QUADRATURE[0])
    mu, wmu = 0.5 * (nodes + 1.0), 0.5 * weights
    phi = (np.arange(QUADRATURE[1]) + 0.5) * 2.0 * np.pi / QUADRATURE[1]
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - m * m)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    w = (wmu[:, None] * m * (2.0 * np.pi / QUADRATURE[1])).reshape(-1)
    return dirs, w


def directional_reflectance(brdf: BrdfConfig, l: ArrayLike) -> np.ndarray:
    """The directional-hemispherical reflectance (black-sky albedo) of light from ``l``.

    (1 / pi) integral of pi f_r cos(theta_v) d_omega_v.

    Parameters
    ----------
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).
    l : numpy.ndarray
        (..., 3) unit vector(s) towards the light [1].

    Returns
    -------
    numpy.ndarray
        (...) float64 [1].
    """
    dirs, w = _hemisphere()
    light = np.asarray(l, dtype=np.float64)
    brf = reflectance_factor(brdf, dirs[(None,) * (light.ndim - 1)], light[..., None, :])
    return brf @ w / np.pi


@functools.lru_cache(maxsize=8)
def white_sky_albedo(brdf: BrdfConfig) -> float:
    """The bihemispherical reflectance under a uniform sky.

    (1 / pi) integral of the directional reflectance times cos(theta_l) d_omega_l.

    Parameters
    ----------
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).

    Returns
    -------
    float
        The albedo [1].
    """
    dirs, w = _hemisphere()
    return float(directional_reflectance(brdf, dirs[:: QUADRATURE[1]]) @ w[:: QUADRATURE[1]] * QUADRATURE[1] / np.pi)


def shape(brdf: BrdfConfig, v: ArrayLike, l: ArrayLike) -> np.ndarray:
    """The model's shape pi f_r(v, l) / A, A its white-sky albedo.

    The factor on the albedo texture's rho / pi, so that under a uniform sky the ground reflects the
    texture's rho (docs/method.md, "The ground's reflectance"). v is read at VIEW_ZENITH_LIMIT or
    nearer the zenith.

    Parameters
    ----------
    brdf : settings.BrdfConfig
        The model and its parameters (any value with those two fields).
    v : numpy.ndarray
        (..., 3) unit vectors towards the viewer [1].
    l : numpy.ndarray
        (..., 3) unit vectors towards the light, broadcastable with ``v`` [1].

    Returns
    -------
    numpy.ndarray
        (...) float64 [1].
    """
    return reflectance_factor(brdf, clamp_view(v), l) / white_sky_albedo(brdf)


def clamp_view(v: ArrayLike) -> np.ndarray:
    """Unit vectors with their zenith angle held to VIEW_ZENITH_LIMIT at most.

    Parameters
    ----------
    v : numpy.ndarray
        (..., 3) unit vectors, any zenith angle [1].

    Returns
    -------
    numpy.ndarray
        (..., 3) float64, a new array [1].
    """
    held = np.array(v, dtype=np.float64)
    low = held[..., 2] < np.cos(VIEW_ZENITH_LIMIT)
    if np.any(low):
        across = np.linalg.norm(held[low, :2], axis=-1, keepdims=True)
        held[low, :2] *= np.sin(VIEW_ZENITH_LIMIT) / np.maximum(across, 1e-12)
        held[low, 2] = np.cos(VIEW_ZENITH_LIMIT)
    return held


@functools.lru_cache(maxsize=4)
def cell_directions(grid: Grid) -> np.ndarray:
    """Unit vectors towards the centres of a sky-plane grid's cells; the same array for the same
    grid (every view band of a frame weights the same grid).

    Parameters
    ----------
    grid : Grid
        The sky-plane grid of the cells [tan].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float64, read-only [1].
    """
    rows, cols = grid.shape
    sx, sy = grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
    w = np.stack(np.broadcast_arrays(sx, sy, np.ones_like(sx)), axis=-1)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    w.flags.writeable = False
    return w
