"""The sun on a receiver: its incidence and the two-scale sun's fine kernel on the receiver's own
sky plane (docs/method.md, "Two scales for the sun" and "Receivers: walls and slopes").

The kernel is ``sky.sun_kernel.sun_kernel`` drawn in the receiver's frame: the same sub-samples,
limb ramps and cloud dimming, each sub-sample's world direction handed to ``disc_samples`` and its
weight the cos^4 of its angle from the receiver's normal. For the level ground it is the ground's
kernel.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.geometry import Grid, sky_offset
from pipeline.receivers.plane import ReceiverPlane
from pipeline.sky.base import Sky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.raster import SkyRaster
from pipeline.sky.sun_disc import disc_samples
from pipeline.sky.sun_kernel import KERNEL_FLOOR, disc_layout, disc_sub_samples, sub_sample_footprint, sun_irradiance

__all__ = ["sun_incidence", "sun_lights", "receiver_sun_point", "receiver_sun_kernel", "receiver_sun_irradiance",
           "receiver_disc_layout", "kernel_block"]


def sun_incidence(sky: Sky, plane: ReceiverPlane) -> float:
    """cos of the sun's angle from the receiver's normal, s.n; 0 without a sun. [1]

    Parameters
    ----------
    sky : sky.base.Sky
        The sky.
    plane : ReceiverPlane
        The receiver.

    Returns
    -------
    float
        s.n, negative for a sun behind the receiver [1].
    """
    if sky.sun is None:
        return 0.0
    return float(np.asarray(sky.sun_direction) @ plane.normal)  # type: ignore[attr-defined]


def sun_lights(sky: Sky, plane: ReceiverPlane) -> bool:
    """Whether the sun's disc lies wholly above the world horizon and at least ``KERNEL_FLOOR`` above
    the receiver's plane, so that its kernel is drawn (a sun behind the receiver leaves it sky only).

    Parameters
    ----------
    sky : sky.base.Sky
        The sky.
    plane : ReceiverPlane
        The receiver.

    Returns
    -------
    bool
        True where the two-scale sun lights the receiver.
    """
    sun = sky.sun
    if sun is None or sun.elevation - sun.angular_radius <= 1e-3:
        return False
    return bool(np.arcsin(np.clip(sun_incidence(sky, plane), -1.0, 1.0)) - sun.angular_radius >= KERNEL_FLOOR)


def receiver_sun_point(sky: Sky, plane: ReceiverPlane) -> np.ndarray:
    """The sun's centre on the receiver's sky plane; meaningful where ``sun_lights``.

    Parameters
    ----------
    sky : sky.base.Sky
        A sky with a sun.
    plane : ReceiverPlane
        The receiver.

    Returns
    -------
    numpy.ndarray
        (2,) (s.u / s.n, s.w / s.n) [tan].
    """
    s, _ = plane.sky_plane(np.asarray(sky.sun_direction))  # type: ignore[attr-defined]
    return s


def receiver_sun_irradiance(sky: Sky, plane: ReceiverPlane) -> np.ndarray:
    """The sun's irradiance on the unshadowed receiver: its normal irradiance after the moon and
    clouds times s.n, as the kernel sums it (16 cells across the disc); zeros where it does not light it.

    Parameters
    ----------
    sky : sky.base.Sky
        The sky.
    plane : ReceiverPlane
        The receiver.

    Returns
    -------
    numpy.ndarray
        (3,) float64 [radiance x sr; klx for a procedural sky].
    """
    if not sun_lights(sky, plane):
        return np.zeros(3)
    if plane.zenith == 0.0:  # the level ground's own
        return sun_irradiance(sky)  # type: ignore[arg-type]
    cos_n = sun_incidence(sky, plane)
    q = sky.sun.angular_radius / 8 / cos_n**2  # type: ignore[union-attr]
    return receiver_sun_kernel(sky, plane, q).weighted.sum(axis=(1, 2), dtype=np.float64)


def receiver_sun_kernel(sky: Sky, plane: ReceiverPlane, q: float) -> SkyRaster:
    """The sun disc on a fine grid of the receiver's sky plane, cell q.

    As ``sky.sun_kernel.sun_kernel``, in the receiver's frame: each cell holds the integral of
    L_sun cos^4(theta) dA over it, theta from the receiver's normal; its sum is the sun's
    irradiance on the receiver, the normal irradiance times s.n.

    Parameters
    ----------
    sky : sky.base.Sky
        A procedural sky or an HDRI with a cut sun; ``sun_lights(sky, plane)`` must hold.
    plane : ReceiverPlane
        The receiver.
    q : float
        The sky-plane cell [tan].

    Returns
    -------
    sky.raster.SkyRaster
        On ``geometry.sky_grid(start, shape, q)`` of the receiver's sky plane, outside = 0 [radiance x sr].

    Raises
    ------
    ValueError
        Where the sun does not light the receiver, q is not positive, or the block passes MAX_KERNEL_CELLS.
    """
    if not sun_lights(sky, plane):
        raise ValueError("the sun does not light this receiver: no kernel to draw")
    if not q > 0:
        raise ValueError(f"q must be positive [tan], got {q}")
    sun = sky.sun
    assert sun is not None
    grid, cells, n = receiver_disc_layout(sky, plane, q)
    h_sub = q / n
    dimming = sky.sun_cloud_transmittance if isinstance(sky, ProceduralSky) else None
    out = np.zeros((3, grid.shape[0] * grid.shape[1]))
    for idx, cos_t, v in disc_sub_samples(grid, cells, n, q):

        def footprint(world_centre, rho, near, v=v, cos_t=cos_t):  # in the receiver's frame
            return sub_sample_footprint(h_sub, v, cos_t, plane.local_directions(world_centre), rho, near)

        disc = disc_samples(plane.world_directions(v), footprint, 2.0 * h_sub, sun,
                            np.asarray(sky.sun_direction), np.asarray(sky.sun_normal_irradiance),  # type: ignore[attr-defined]
                            getattr(sky, "moon", None))
        L = disc if dimming is None else disc * dimming
        out[:, idx] = np.einsum("kijc,kij->ck", L, cos_t**4) * h_sub**2
    return SkyRaster(grid, out.reshape(3, *grid.shape).astype(np.float32), np.zeros(3))


def receiver_disc_layout(sky: Sky, plane: ReceiverPlane, q: float) -> tuple:
    """Where the sun's kernel lies on the receiver's sky plane (``sun_kernel.disc_layout`` in its frame).

    Parameters
    ----------
    sky, plane, q
        As in ``receiver_sun_kernel``.

    Returns
    -------
    tuple
        (grid, flat indices (k,) of the cells that can hold any of the disc, sub-samples n per cell side).
    """
    centre = plane.local_directions(np.asarray(sky.sun_direction))  # type: ignore[attr-defined]
    return disc_layout(centre, float(np.arctan2(centre[0], centre[1])),
                       float(np.arcsin(np.clip(centre[2], -1.0, 1.0))), sky.sun.angular_radius, q)  # type: ignore[union-attr]


def kernel_block(grid: Grid) -> tuple[tuple[int, int], tuple[int, int]]:
    """The sky offsets of the first and last cells of a kernel's block on a sky plane.

    Parameters
    ----------
    grid : Grid
        The kernel's grid (``geometry.sky_grid``) [tan].

    Returns
    -------
    tuple
        ((dr, dc) of the first cell, (dr, dc) of the last) [cell].
    """
    lo = sky_offset(grid)
    return lo, (lo[0] + grid.shape[0] - 1, lo[1] + grid.shape[1] - 1)
