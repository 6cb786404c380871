"""Light through a plane-parallel slab of cloud (docs/method.md, "The cloud layer"): the singly
scattered radiance and flux below it (Blinn 1982), the total flux of a collimated sun
(delta-Eddington) and of a uniform sky (two-stream), and the unscattered part of the latter. The
layer (``clouds.CloudLayer``) builds its multiple-scattering term from their differences."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from pipeline.sky.scattering import henyey_greenstein

__all__ = [
    "single_scattering_flux_transmittance", "delta_eddington_transmittance",
    "two_stream_diffuse_transmittance", "diffuse_direct_transmittance",
]

_QUAD_NODES = 192  # Gauss-Legendre nodes per angle in the single-scattering flux quadrature

# numpy's Gauss-Legendre nodes and weights, cached: numpy finds them as the eigenvalues of a
# matrix at each call (50 ms for 192 nodes on a busy machine, several times a frame). Callers
# must not write to them.
_leggauss = lru_cache(maxsize=4)(np.polynomial.legendre.leggauss)


def _phi(x):
    """(1 - exp(-x)) / x for x >= 0, with phi(0) = 1. [dimensionless]"""
    x = np.asarray(x)
    if x.dtype != np.float32:
        x = x.astype(np.float64)
    x = np.maximum(x, np.finfo(x.dtype).tiny)  # expm1 is exact there: phi = 1
    return -np.expm1(-x) / x


def slab_path(tau: np.ndarray, inv_mu: np.ndarray, inv_mu0: float | np.floating) -> np.ndarray:
    """tau exp(-tau m) phi(tau d), m = min(1/mu, 1/mu0), d = |1/mu0 - 1/mu|: the integral over
    the depth t in [0, tau] of exp(-t / mu0 - (tau - t) / mu). [dimensionless]

    Blinn 1982 ("Light reflection functions for simulation of clouds and dusty surfaces",
    SIGGRAPH 82): the singly scattered radiance below a low-albedo slab lit from above, per unit
    sun normal irradiance, is ``L / F = w p mu0 / (mu - mu0) (exp(-tau/mu) - exp(-tau/mu0))``
    = ``w p (1 / mu) slab_path(tau, 1 / mu, 1 / mu0)``, a form exact and stable at ``mu = mu0``."""
    near = np.minimum(inv_mu, inv_mu0)
    x = np.abs(inv_mu0 - inv_mu)
    x = x * tau
    result = np.exp(-tau * near)
    result *= tau
    result *= _phi(x)
    return result


def single_scattering_flux_transmittance(optical_depth: ArrayLike, sun_cosine: float, *, asymmetry: float,
                                         albedo: float, nodes: int = _QUAD_NODES) -> np.ndarray:
    """S1: the singly scattered flux leaving the base of a slab over the sun's flux F mu0.

    The hemispheric integral of Blinn's singly scattered radiance per unit sun normal irradiance
    (``slab_path``) times ``mu`` over the lower hemisphere, by Gauss-Legendre quadrature in zenith
    (``nodes``) and azimuth (``nodes``); the azimuth integral of the Henyey-Greenstein phase is
    done once for all depths.

    Parameters
    ----------
    optical_depth : numpy.ndarray
        tau, vertical optical depths >= 0, any shape [1].
    sun_cosine : float
        mu0 in (0, 1] [1].
    asymmetry : float
        g of the Henyey-Greenstein phase [1].
    albedo : float
        Single-scattering albedo [1].
    nodes : int, optional
        Gauss-Legendre nodes per angle.

    Returns
    -------
    numpy.ndarray
        S1, float64 with the shape of ``optical_depth``, in [0, albedo] [1].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    mu0 = float(sun_cosine)
    x, w = _leggauss(int(nodes))
    theta = 0.25 * np.pi * (x + 1.0)  # zenith of the view, (0, pi/2)
    w_theta = 0.25 * np.pi * w
    phi = 0.5 * np.pi * (x + 1.0)  # azimuth from the sun, (0, pi); the integrand is even
    w_phi = np.pi * w  # twice 0.5 pi w: both halves of the circle
    sin0 = np.sqrt(max(0.0, 1.0 - mu0 * mu0))
    cos_scatter = (np.cos(theta)[:, None] * mu0
                   + np.sin(theta)[:, None] * sin0 * np.cos(phi)[None, :])
    phase_ring = henyey_greenstein(cos_scatter, asymmetry) @ w_phi  # (nodes,) [1/sr x rad]
    mu = np.cos(theta)
    inv_mu, inv_mu0 = 1.0 / mu, 1.0 / mu0
    t = tau.reshape(-1, 1)
    path = slab_path(t, inv_mu[None, :], inv_mu0)
    # integral of L mu d_omega = F w  int p path sin(theta) d_theta d_phi
    s1 = albedo * (path @ (w_theta * np.sin(theta) * phase_ring)) / mu0
    return s1.reshape(tau.shape)


def delta_eddington_transmittance(optical_depth: ArrayLike, sun_cosine: ArrayLike, *, asymmetry: float) -> np.ndarray:
    """Total (direct + diffuse) flux transmittance of a non-absorbing slab under a collimated sun.

    Delta-Eddington (Joseph, Wiscombe & Weinman 1976, J. Atmos. Sci. 33, 2452-2459): the forward
    peak ``f = g^2`` is folded into the direct beam, ``tau' = (1 - g^2) tau``, ``g' = g / (1 + g)``;
    then the conservative Eddington two-stream solution (Meador & Weaver 1980, J. Atmos. Sci. 37,
    630-643; ``gamma1 = 3 (1 - g') / 4``, ``gamma3 = (2 - 3 g' mu0) / 4``):
    ``R = (gamma1 tau' + (gamma3 - gamma1 mu0)(1 - exp(-tau'/mu0))) / (1 + gamma1 tau')``,
    ``T = 1 - R``.

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau, vertical optical depth >= 0 [1].
    sun_cosine : float or numpy.ndarray
        mu0 in (0, 1], broadcastable with ``optical_depth`` [1].
    asymmetry : float
        g in [0, 1) [1].

    Returns
    -------
    numpy.ndarray
        T, the transmitted flux over the incident ``F mu0``, float64 of the broadcast shape [1].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    mu0 = np.asarray(sun_cosine, dtype=np.float64)
    g = float(asymmetry)
    tau_s = (1.0 - g * g) * tau
    g_s = g / (1.0 + g)
    gamma1 = 0.75 * (1.0 - g_s)
    gamma3 = 0.25 * (2.0 - 3.0 * g_s * mu0)
    reflectance = ((gamma1 * tau_s + (gamma3 - gamma1 * mu0) * -np.expm1(-tau_s / mu0))
                   / (1.0 + gamma1 * tau_s))
    return 1.0 - reflectance


def two_stream_diffuse_transmittance(optical_depth: ArrayLike, *, albedo: float, asymmetry: float) -> np.ndarray:
    """Flux transmittance of a slab under uniform diffuse light, two-stream (hemispheric mean).

    ``dF+/dtau = g1 F+ - g2 F-``, ``dF-/dtau = g2 F+ - g1 F-``, ``g1 = 2 - w (1 + g)``,
    ``g2 = w (1 - g)`` (Meador & Weaver 1980, Table 1); with ``k = sqrt(g1^2 - g2^2)`` and
    ``r = g2 / (g1 + k)``, ``T = (1 - r^2) exp(-k tau) / (1 - r^2 exp(-2 k tau))``, written to
    stay finite as ``k -> 0`` (conservative limit ``T = 1 / (1 + (1 - g) tau)``, Bohren 1987,
    Am. J. Phys. 55, 524).

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau >= 0 [1].
    albedo : float
        w in [0, 1] [1].
    asymmetry : float
        g in (-1, 1) [1].

    Returns
    -------
    numpy.ndarray
        T, direct and diffuse together, float64 of the shape of ``optical_depth`` [1].
    """
    tau = np.asarray(optical_depth, dtype=np.float64)
    g1 = 2.0 - albedo * (1.0 + asymmetry)
    g2 = albedo * (1.0 - asymmetry)
    k = np.sqrt(max(0.0, g1 * g1 - g2 * g2))
    r = g2 / (g1 + k)
    # (1 - r^2) = 2k / (g1 + k); divide numerator and denominator by 2k.
    return np.exp(-k * tau) / (1.0 + (g1 + k) * r * r * tau * _phi(2.0 * k * tau))


def diffuse_direct_transmittance(optical_depth: ArrayLike) -> np.ndarray:
    """Unscattered fraction of uniform diffuse light through a slab: 2 E3(tau).

    Parameters
    ----------
    optical_depth : float or numpy.ndarray
        tau >= 0 [1].

    Returns
    -------
    numpy.ndarray
        float64 of the shape of ``optical_depth`` [1].
    """
    return 2.0 * special.expn(3, np.asarray(optical_depth, dtype=np.float64))
