"""Scattering in the air and in clouds: the Henyey-Greenstein phase function and the haze's
transmittance between the camera and the ground (docs/method.md, "The camera, the foreground and
the finished frame")."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["henyey_greenstein", "haze_transmittance"]


def henyey_greenstein(cos_scattering_angle: ArrayLike, asymmetry: float) -> np.ndarray:
    """Henyey-Greenstein phase function, normalised to 1 over the sphere.

    p = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos(Theta))^(3/2))  (Henyey & Greenstein 1941,
    "Diffuse radiation in the galaxy", ApJ 93, 70-83; used for clouds by Blinn 1982).

    Parameters
    ----------
    cos_scattering_angle : array_like
        Cosine of the angle between the incident propagation direction and the scattered one; 1 is
        straight on (forward), any shape [1]. float32 stays float32, anything else is float64.
    asymmetry : float
        g, the mean cosine of the scattering angle, in (-1, 1) [1].

    Returns
    -------
    numpy.ndarray
        p, of ``cos_scattering_angle``'s shape [1/sr].
    """
    c = np.asarray(cos_scattering_angle)
    if c.dtype != np.float32:
        c = c.astype(np.float64)
    g = float(asymmetry)
    d = c * c.dtype.type(-2.0 * g)
    d += c.dtype.type(1.0 + g * g)
    d *= np.sqrt(d)
    return c.dtype.type((1.0 - g * g) / (4.0 * np.pi)) / d



def haze_transmittance(distance: np.ndarray, length: float) -> np.ndarray:
    """exp(-d / length) of a homogeneous haze over the distances d.

    Where the sky is seen (d inf) it is 1: the sky model holds its own haze.

    Parameters
    ----------
    distance : numpy.ndarray
        (rows, cols) distance d to the ground seen, inf where the sky is seen [m].
    length : float
        Extinction length of the haze; 0 or less: no haze [m].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 transmittance [1].
    """
    return _transmittance(distance, length).astype(np.float32)



def _transmittance(distance, length: float) -> np.ndarray:
    """``haze_transmittance`` in float64."""
    distance = np.asarray(distance, dtype=np.float64)
    ground = np.isfinite(distance)
    depth = np.where(ground, distance, 0.0) / length if length > 0 else np.zeros_like(distance)
    return np.where(ground, np.exp(-depth), 1.0)



