"""The ground's reflectance f_r(V, L) (Max 1991, eq. 1 and the paragraph after it; docs/method.md,
"The ground's reflectance"): the models (RPV, RossThick-LiSparse-Reciprocal), their shape
normalised to the albedo texture, the view bands of the sky's term, and the frame's ground seen
through them. ``lambert`` never comes here: its frames keep the camera's own path.

Directions are unit vectors (..., 3) in world axes pointing away from the ground: ``v`` towards
the viewer, ``l`` towards the light. Both conventions of relative azimuth in the literature
are avoided by writing each model with vectors: the hot spot is v = l (the viewer has the light
behind), where the phase angle g (cos g = v . l) is 0.

Why one module: the models, their shape normalised to the albedo, the view bands and the ground
seen through them are one approximation of Max's f_r(V, L), each tuned against the others
(``choose_bands`` measures the bands' blend against the shape, ``sky_ratio`` corrects it)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import camera as cam
from . import shadow
from .geometry import Grid, fold, sky_grid, sky_offset
from .sky import SkyRaster

__all__ = [
    "VIEW_ZENITH_LIMIT", "QUADRATURE", "BAND_TOLERANCE", "MAX_BANDS", "SKY_CELLS", "SHAPE_STEP", "reflectance_factor",
    "directional_reflectance", "white_sky_albedo", "shape", "clamp_view", "cell_directions", "ViewBands",
    "view_vectors", "choose_bands", "sky_ratio", "banded_sky", "shape_on_grid", "weighted_raster", "ground_radiance",
    "open_sky", "relative_sky", "background",
]

if TYPE_CHECKING:
    from .settings import BrdfConfig  # model and parameters: any value with those two fields

VIEW_ZENITH_LIMIT = np.radians(85.0)
"""The view zenith angle the models are read at, at most: a bowl-shaped RPV (k < 1) grows
without bound towards a grazing view (mu_v^(k - 1)), where no measurement supports it. [rad]"""

QUADRATURE = (32, 64)
"""Gauss-Legendre nodes in cos(zenith) on (0, 1) and equal steps in azimuth of the hemisphere
quadratures (directional and white-sky reflectance). [count]"""

BAND_TOLERANCE = 0.01
"""Largest relative error of the open sky's term over the pixels that ``choose_bands`` accepts:
it adds view bands until the blend meets it, up to MAX_BANDS. [1]"""

MAX_BANDS = 8
"""Most view bands (each one a correlation of the sky raster per canopy layer). [count]"""


def reflectance_factor(brdf: BrdfConfig, v, l) -> np.ndarray:
    """The bidirectional reflectance factor pi f_r(v, l) of the model.

    Parameters
    ----------
    brdf : config.BrdfConfig
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
    p = dict(brdf.parameters)
    v, l = np.asarray(v, dtype=np.float64), np.asarray(l, dtype=np.float64)
    if brdf.model == "rpv":
        return _rpv(v, l, p["rho0"], p["k"], p["theta"], p["rho_c"])
    if brdf.model == "rossli":
        return _rossli(v, l, p["f_iso"], p["f_vol"], p["f_geo"])
    raise ValueError(f"no such reflectance model: {brdf.model!r}")


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


def directional_reflectance(brdf: BrdfConfig, l) -> np.ndarray:
    """The directional-hemispherical reflectance (black-sky albedo) of light from ``l``.

    (1 / pi) integral of pi f_r cos(theta_v) d_omega_v.

    Parameters
    ----------
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).
    l : numpy.ndarray
        (..., 3) unit vector(s) towards the light [1].

    Returns
    -------
    numpy.ndarray
        (...) float64 [1].
    """
    dirs, w = _hemisphere()
    l = np.asarray(l, dtype=np.float64)
    brf = reflectance_factor(brdf, dirs[(None,) * (l.ndim - 1)], l[..., None, :])
    return brf @ w / np.pi


@functools.lru_cache(maxsize=8)
def white_sky_albedo(brdf: BrdfConfig) -> float:
    """The bihemispherical reflectance under a uniform sky.

    (1 / pi) integral of the directional reflectance times cos(theta_l) d_omega_l.

    Parameters
    ----------
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).

    Returns
    -------
    float
        The albedo [1].
    """
    dirs, w = _hemisphere()
    return float(directional_reflectance(brdf, dirs[:: QUADRATURE[1]]) @ w[:: QUADRATURE[1]] * QUADRATURE[1] / np.pi)


def shape(brdf: BrdfConfig, v, l) -> np.ndarray:
    """The model's shape pi f_r(v, l) / A, A its white-sky albedo.

    The factor on the albedo texture's rho / pi, so that under a uniform sky the ground reflects the
    texture's rho (docs/method.md, "The ground's reflectance"). v is read at VIEW_ZENITH_LIMIT or
    nearer the zenith.

    Parameters
    ----------
    brdf : config.BrdfConfig
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


def clamp_view(v) -> np.ndarray:
    """Unit vectors with their zenith angle held to VIEW_ZENITH_LIMIT at most.

    Parameters
    ----------
    v : numpy.ndarray
        (..., 3) unit vectors [1].

    Returns
    -------
    numpy.ndarray
        (..., 3) float64, a new array [1].
    """
    v = np.array(v, dtype=np.float64)
    low = v[..., 2] < np.cos(VIEW_ZENITH_LIMIT)
    if np.any(low):
        across = np.linalg.norm(v[low, :2], axis=-1, keepdims=True)
        v[low, :2] *= np.sin(VIEW_ZENITH_LIMIT) / np.maximum(across, 1e-12)
        v[low, 2] = np.cos(VIEW_ZENITH_LIMIT)
    return v


def cell_directions(grid) -> np.ndarray:
    """Unit vectors towards the centres of a sky-plane grid's cells.

    Parameters
    ----------
    grid : Grid
        A sky-plane grid [tan].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float64 [1].
    """
    rows, cols = grid.shape
    sx, sy = grid.ground_from_raster(np.arange(rows)[:, None], np.arange(cols)[None, :])
    w = np.stack(np.broadcast_arrays(sx, sy, np.ones_like(sx)), axis=-1)
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


# ---------------------------------------------------------------------------------------------
# View bands: the sky's term with V held per band (Max: f_r independent of V over a patch)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ViewBands:
    """View bands: the sky's term with the view V held per band (Max: f_r independent of V over a patch).

    Attributes
    ----------
    zeniths : tuple of float
        (B,) the bands' view zenith angles, near to far [rad].
    azimuth : float
        The azimuth of their view direction (from the ground towards the camera) [rad].
    error : float
        The largest relative error of the open sky's term over the sampled pixels that
        ``choose_bands`` measured [1].
    """

    zeniths: tuple[float, ...]
    azimuth: float
    error: float

    @property
    def colour(self) -> int:
        """The band whose term is correlated in every channel (the middle one).

        It gives the sky light's colour under the canopy; the others are correlated on the channels' sum
        and give only how the reflectance modulates it (``banded_sky``).

        Returns
        -------
        int
            Its index [index].
        """
        return len(self.zeniths) // 2

    def directions(self) -> np.ndarray:
        """Unit view vectors of the bands.

        Returns
        -------
        numpy.ndarray
            (B, 3) float64 [1].
        """
        z = np.asarray(self.zeniths)
        return np.stack([np.sin(z) * np.sin(self.azimuth), np.sin(z) * np.cos(self.azimuth), np.cos(z)], axis=-1)

    def weights(self, zenith) -> np.ndarray:
        """Weights of each band at view zenith angles; they sum to 1.

        Linear between neighbouring bands' zeniths (hat functions), held beyond the ends.

        Parameters
        ----------
        zenith : numpy.ndarray
            (n,) view zenith angles [rad].

        Returns
        -------
        numpy.ndarray
            (B, n) float64 [1].
        """
        z = np.asarray(self.zeniths)
        eye = np.eye(len(z))
        return np.stack([np.interp(zenith, z, eye[b]) for b in range(len(z))]) if len(z) > 1 \
            else np.ones((1, np.size(zenith)))


def view_vectors(camera: cam.Camera):
    """Unit vectors from the ground point each ground pixel sees towards the pinhole.

    For the pixels of ``camera._view_footprints`` (rows first).

    Parameters
    ----------
    camera : camera.Camera
        The camera [m].

    Returns
    -------
    numpy.ndarray
        (n, 3) float64 [1].
    """
    fp, _ = cam._view_footprints(camera)
    d = np.stack([camera.position[0] - fp.x, camera.position[1] - fp.y,
                  np.full(fp.x.shape, float(camera.position[2]))], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


@functools.lru_cache(maxsize=1)
def _camera_views(camera: cam.Camera):
    """``view_vectors`` held to VIEW_ZENITH_LIMIT (``clamp_view``) (n, 3), their zenith angles
    (n,) [rad] and azimuths (n,) [rad, from +y towards +x]: they depend on the camera alone, so
    the frames of a run, whose camera stands still, make them once. Read-only."""
    views = clamp_view(view_vectors(camera))
    zenith = np.arccos(np.clip(views[:, 2], -1.0, 1.0))
    azimuth = np.arctan2(views[:, 0], views[:, 1])
    for array in (views, zenith, azimuth):
        array.flags.writeable = False
    return views, zenith, azimuth


class _LastCall:
    """The last call of a function and its result, kept in this process: a frame asks again
    for what the frame (or the frame before, from the same camera) made. The key's objects are
    held, so their ids are not reused, and matched by identity; numbers and strings by value."""

    def __init__(self):
        self.key, self.value = None, None

    def get(self, key: tuple, make):
        """The result for ``key``: the last one if ``key`` is the last call's, else ``make()``."""
        same = self.key is not None and len(self.key) == len(key) and all(
            a == b if isinstance(b, (int, float, str)) else a is b for a, b in zip(self.key, key))
        if not same:
            self.key, self.value = key, make()
        return self.value


_COARSE = _LastCall()
"""``_coarsened``: ``choose_bands`` and ``sky_ratio`` coarsen the same raster in one frame."""

SKY_CELLS = 2048
"""Most cells of the coarsened sky raster on which ``choose_bands`` and ``sky_ratio`` sum the
open sky's term (blocks of the raster's cells). [count]"""


def _coarsened(raster, most_cells: int = 4096, *, channels: bool = False):
    """A sky raster's cells summed in blocks to at most ``most_cells``: directions (m, 3)
    towards each block's light-weighted centre on the sky plane and weights (m,) (channels
    summed), or (m, channels) with ``channels``. [1], [radiance x sr]"""
    dirs, per_channel = _COARSE.get((raster, most_cells), lambda: _coarsen(raster, most_cells))
    return (dirs, per_channel) if channels else (dirs, per_channel.sum(axis=-1))


def _coarsen(raster, most_cells: int):
    """``_coarsened``'s work: (directions (m, 3), light per block and channel (m, channels))."""
    light = raster.weighted
    count, rows, cols = light.shape
    step = max(1, int(np.ceil(np.sqrt(rows * cols / most_cells))))
    rows, cols = max(rows // step * step, 1), max(cols // step * step, 1)
    step_r, step_c = min(step, rows), min(step, cols)
    sx, sy = raster.grid.ground_from_raster(np.arange(rows), np.arange(cols))
    cut = light[:, :rows, :cols].reshape(count, rows // step_r, step_r, cols // step_c, step_c)
    per_block = cut.sum(axis=(2, 4), dtype=np.float64)  # (channels, block rows, block cols)
    weight = per_block.sum(axis=0)
    safe = np.maximum(weight, 1e-30)
    # the light-weighted centres: x depends on the column alone, y on the row alone
    x = (cut.sum(axis=(0, 2), dtype=np.float64) * sx.reshape(-1, step_c)).sum(axis=-1) / safe
    y = (cut.sum(axis=(0, 4), dtype=np.float64) * sy.reshape(-1, step_r)[..., None]).sum(axis=1) / safe
    w = np.stack([x, y, np.ones_like(x)], axis=-1)
    dirs = (w / np.linalg.norm(w, axis=-1, keepdims=True)).reshape(-1, 3)
    return dirs, per_block.reshape(count, -1).T


def choose_bands(brdf: BrdfConfig, raster, views: np.ndarray, *, tolerance: float = BAND_TOLERANCE,
                 most: int = MAX_BANDS, samples: int = 192) -> ViewBands:
    """View bands, 1 to ``most``, added one at a time where the blend is worst.

    First the middle, then both ends, then the sampled view zenith of the largest error, until the
    blend gives the open sky's term sum_i e_i s(V, L_i) within ``tolerance`` (relative) at every
    sampled pixel's own view zenith, against that sum per pixel (brute force over the raster's cells,
    coarsened to SKY_CELLS) at the bands' azimuth. Azimuth of the bands: that of the views' mean (the
    change with azimuth across the image is ``sky_ratio``'s).

    Parameters
    ----------
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).
    raster : sky.SkyRaster
        The sky raster [radiance x sr].
    views : numpy.ndarray
        (n, 3) the pixels' view vectors [1].
    tolerance : float, optional
        Largest relative error accepted [1].
    most : int, optional
        Most bands [count].
    samples : int, optional
        About how many of the views are sampled [count].

    Returns
    -------
    ViewBands
        The bands, with the error they reached.
    """
    views = clamp_view(views)
    pick = views[:: max(1, len(views) // samples)]
    dirs, e = _coarsened(raster, SKY_CELLS)
    zenith = np.arccos(np.clip(pick[:, 2], -1.0, 1.0))
    mean = views.mean(axis=0)
    azimuth = float(np.arctan2(mean[0], mean[1]))
    # the bands fix the change with distance; the change across (azimuth) is ``sky_ratio``'s
    exact = shape(brdf, ViewBands(tuple(zenith), azimuth, 0.0).directions()[:, None, :], dirs[None]) @ e
    lo, hi = float(zenith.min()), float(zenith.max())
    zeniths = [0.5 * (lo + hi)]
    while True:  # greedy: the next band goes where the blend is worst
        trial = ViewBands(tuple(zeniths), azimuth, 0.0)
        at_bands = shape(brdf, trial.directions()[:, None, :], dirs[None]) @ e
        relative = np.abs(at_bands @ trial.weights(zenith) - exact) / np.maximum(np.abs(exact), 1e-30)
        worst = int(np.argmax(relative))
        bands = ViewBands(trial.zeniths, azimuth, float(relative[worst]))
        if bands.error <= tolerance or len(zeniths) >= most:
            return bands
        zeniths = [lo, hi] if len(zeniths) == 1 else sorted({*zeniths, float(zenith[worst])})
        if len(zeniths) == len(trial.zeniths):  # the worst sample is a band already
            return bands


def sky_ratio(brdf: BrdfConfig, raster, bands: ViewBands, views, *, lattice: int = 16, angles=None) -> np.ndarray:
    """The factor that makes the banded sky term exact on open ground, per channel and pixel.

    The open sky's term at the pixel's own view, sum_i e_i s(V, L_i), over what ``banded_sky`` gives
    on open ground, the colour band's term sum_i e_i s(V_c, L_i) times the blended modulation
    sum_b w_b S_b / S_c (S_b = sum_i e'_i s(V_b, L_i), e' the channels' sum), all over the raster
    coarsened to SKY_CELLS cells: it carries the change across the image (view azimuth) that the bands
    do not hold. Read on a lattice of ``lattice`` x ``lattice`` view zeniths and azimuths over the
    views' range, bilinearly (held at its edges).

    Parameters
    ----------
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).
    raster : sky.SkyRaster
        The sky raster [radiance x sr].
    bands : ViewBands
        The view bands.
    views : numpy.ndarray
        (n, 3) unit view vectors [1].
    lattice : int, optional
        Side of the lattice of views [count].
    angles : tuple of numpy.ndarray, optional
        If given, the views' zenith angles and azimuths after ``clamp_view`` ((n,) each,
        ``_camera_views``) [rad].

    Returns
    -------
    numpy.ndarray
        (channels, n) float32 [1].
    """
    dirs, e = _coarsened(raster, SKY_CELLS, channels=True)
    if angles is None:
        views = clamp_view(views)
        angles = np.arccos(np.clip(views[:, 2], -1.0, 1.0)), np.arctan2(views[:, 0], views[:, 1])
    lows, spans, corner, taps = _lattice_reads(angles[0], angles[1], bands.azimuth, lattice)
    axes = [low + span * np.linspace(0.0, 1.0, lattice) for low, span in zip(lows, spans)]
    z, t = np.meshgrid(*axes, indexing="ij")
    a = bands.azimuth + t
    v = np.stack([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)], axis=-1)
    own = shape(brdf, v[..., None, :], dirs) @ e  # (lattice, lattice, channels)
    at_bands = shape(brdf, bands.directions()[:, None, :], dirs[None]) @ e  # (B, channels)
    summed = at_bands.sum(axis=-1)
    modulation = summed / max(float(summed[bands.colour]), 1e-30)
    blended = np.maximum(at_bands[bands.colour][None, :] * (modulation @ bands.weights(axes[0]))[:, None], 1e-30)
    ratio = np.moveaxis(own / blended[:, None, :], -1, 0).astype(np.float32)
    from . import _filter

    flat = np.ascontiguousarray(ratio.reshape(len(ratio), -1))
    out = np.empty((len(ratio), len(corner)), dtype=np.float32)
    _filter.lattice_read(flat, corner, taps, lattice, out)
    return out


def _lattice_read_arrays(flat, corner, taps, lattice) -> np.ndarray:
    """``_filter.lattice_read`` with whole arrays (numpy): its reference. (channels, n) float32"""
    out = flat[:, corner] * taps[0]
    out += flat[:, corner + 1] * taps[1]
    out += flat[:, corner + lattice] * taps[2]
    out += flat[:, corner + lattice + 1] * taps[3]
    return out


_READS = _LastCall()
"""``_lattice_reads``: a camera's views are the same every frame (``_camera_views``)."""


def _lattice_reads(zenith, azimuth, band_azimuth: float, lattice: int):
    """Where ``sky_ratio`` reads its lattice for views of zenith angles and azimuths (n,) each
    [rad]: the lattice's lowest zenith and turn from ``band_azimuth`` and their spans [rad],
    the flat index (n,) of each view's first lattice corner and the bilinear weights (4, n)
    float32 of its four corners (held at the lattice's edges)."""
    return _READS.get((zenith, azimuth, band_azimuth, lattice),
                      lambda: _lattice_reads_made(zenith, azimuth, band_azimuth, lattice))


def _lattice_reads_made(zenith, azimuth, band_azimuth: float, lattice: int):
    """``_lattice_reads``' work."""
    turn = (azimuth - band_azimuth + np.pi) % (2.0 * np.pi) - np.pi
    lows = [float(zenith.min()), float(turn.min())]
    spans = [max(float(zenith.max()) - lows[0], 1e-9), max(float(turn.max()) - lows[1], 1e-9)]
    i = np.clip((zenith - lows[0]) / spans[0] * (lattice - 1), 0.0, lattice - 1.0)
    j = np.clip((turn - lows[1]) / spans[1] * (lattice - 1), 0.0, lattice - 1.0)
    i0, j0 = np.minimum(i.astype(np.intp), lattice - 2), np.minimum(j.astype(np.intp), lattice - 2)
    fi, fj = (i - i0).astype(np.float32), (j - j0).astype(np.float32)
    taps = np.stack([(1 - fi) * (1 - fj), (1 - fi) * fj, fi * (1 - fj), fi * fj])
    return lows, spans, i0 * lattice + j0, taps


def banded_sky(colour, bands_light, weights, ratio) -> np.ndarray:
    """The sky's term with the reflectance: r_c E_c,ch sum_b w_b G_b / sum_ch E_c,ch.

    The bands give how the reflectance modulates the sky's light at the point with the view, the
    colour band its colour, the ratio the open sky's term at the pixel's own view (docs/method.md,
    "The ground's reflectance").

    Parameters
    ----------
    colour : numpy.ndarray
        E_c (channels, n): the colour band's term (the sky raster weighted at its view, every
        channel, correlated) [radiance x sr].
    bands_light : numpy.ndarray
        G_b (B, n): each band's term on the channels' sum (``weighted_raster(summed=True)``; the
        colour band's is the sum of E_c's channels) [radiance x sr].
    weights : numpy.ndarray
        w_b (B, n): the bands' weights [1].
    ratio : numpy.ndarray or float
        r_c (channels, n): ``sky_ratio`` [1].

    Returns
    -------
    numpy.ndarray
        (channels, n) float32 [radiance x sr].
    """
    blend = bands_light[0] * weights[0]
    for b in range(1, len(weights)):
        blend += bands_light[b] * weights[b]
    blend /= np.maximum(colour.sum(axis=0), np.float32(1e-30))
    sky = colour * blend[None]
    sky *= ratio
    return sky


SHAPE_STEP = 0.04
"""Spacing on the sky plane [tan] (about 2.3 degrees at the zenith, less away from it) of the
lattice on which ``weighted_raster`` evaluates the shape s(V, L), read bilinearly at the sky
raster's cells: the shape changes over degrees (its sharpest feature, the hot spot's cusp
1 / (1 + G), is a cone in G, the distance on this same plane)."""


def shape_on_grid(brdf: BrdfConfig, view, grid) -> np.ndarray:
    """The shape s(view, L) at the cells of a sky-plane grid.

    Exact on a lattice of spacing at most SHAPE_STEP over the grid, bilinear between (the grid's own
    cells when they are coarser).

    Parameters
    ----------
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).
    view : numpy.ndarray
        (3,) unit view vector [1].
    grid : Grid
        A sky-plane grid [tan].

    Returns
    -------
    numpy.ndarray
        (rows, cols) float32 [1].
    """
    step = max(1, int(round(SHAPE_STEP / grid.pixel)))
    if step == 1 or min(grid.shape) < 4 * step:
        return shape(brdf, np.asarray(view)[None, None, :], cell_directions(grid)).astype(np.float32)
    pitch = step * grid.pixel
    rows, cols = (int(np.ceil(n / step)) + 3 for n in grid.shape)
    x0, y0 = grid.origin
    lattice = Grid((x0 + 0.5 * grid.pixel - 1.5 * pitch, y0 - 0.5 * grid.pixel + 1.5 * pitch), pitch, (rows, cols))
    coarse = shape(brdf, np.asarray(view)[None, None, :], cell_directions(lattice)).astype(np.float32)
    return shadow.resample_bilinear(coarse[None], lattice, grid)[0]


_SUM = _LastCall()
"""``_channel_sum``: the bands of a frame sum the same raster."""


def _channel_sum(raster) -> np.ndarray:
    """The sky raster's channels summed (1, rows, cols) float32, made once for the bands of a
    frame. Read-only. [radiance x sr]"""
    def made():
        total = raster.weighted.sum(axis=0, keepdims=True)
        total.flags.writeable = False
        return total
    return _SUM.get((raster,), made)


def weighted_raster(raster, brdf: BrdfConfig, view, *, fold_period=None, summed: bool = False):
    """The sky raster with each cell's light times the shape s(view, L_cell).

    Max's f_r(V, L) on the sky raster, before the correlation (``shape_on_grid``), folded after the
    weighting when ``fold_period`` is given; the light outside the raster times the mean shape over
    the raster's outermost ring of cells (the nearest directions to it).

    Parameters
    ----------
    raster : sky.SkyRaster
        The sky raster [radiance x sr].
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).
    view : numpy.ndarray
        (3,) unit view vector [1].
    fold_period : tuple of (int, int), optional
        The tile period to fold onto [cell].
    summed : bool, optional
        One channel, the channels' sum weighted (the view bands').

    Returns
    -------
    sky.SkyRaster
        The weighted raster, float32 [radiance x sr].
    """
    s = shape_on_grid(brdf, view, raster.grid)
    light = _channel_sum(raster) if summed else raster.weighted
    outside = np.asarray(raster.outside, dtype=np.float64)
    outside = outside.sum(keepdims=True) if summed else outside
    weighted = light * s[None]
    ring = np.ones(s.shape, dtype=bool)
    ring[1:-1, 1:-1] = False
    e = raster.weighted.sum(axis=0)
    edge = float((e[ring] * s[ring]).sum() / max(float(e[ring].sum()), 1e-30))
    grid = raster.grid
    if fold_period is not None:
        weighted = fold(weighted, sky_offset(grid), fold_period)
        grid = sky_grid((0, 0), tuple(fold_period), grid.pixel)
    return SkyRaster(grid, weighted.astype(np.float32), outside * edge)


def ground_radiance(camera: cam.Camera, brdf: BrdfConfig, albedo, *, sun, sky_maps, bands: ViewBands,
                    sun_direction, raster, open_light=None) -> np.ndarray:
    """The ground's radiance with the reflectance ``brdf``.

    rho / pi [ s(V(x), L_sun) E_sun(x) + r(x) E_c(x) sum_b w_b(x) G_b(x) / sum_ch E_c,ch(x) ], rho
    the albedo texture, E_sun the ground's light from the sun alone, the sky's term ``banded_sky``:
    w_b the bands' weights at the pixel's view zenith, r(x) ``sky_ratio`` over ``raster``, V(x) each
    pixel's own view vector. The sun's term is exact per pixel; the sky's is blended (docs/method.md,
    "The ground's reflectance"). 0 where no ground is seen.

    Parameters
    ----------
    camera : camera.Camera
        The camera [m].
    brdf : config.BrdfConfig
        The model and its parameters (any value with those two fields).
    albedo : object
        The albedo texture rho [1].
    sun : object
        MipMap chain of E_sun (``GroundResult.sun_part``) [radiance x sr].
    sky_maps : object
        The bands' terms: one MipMap chain whose channels are each band's, three for the colour
        band (``ViewBands.colour``, E_c), one (the channels' sum, G_b) for the others, so that the
        camera's footprints are filtered once for all of them [radiance x sr]. With
        ``open_light``, instead the one 3-channel raster of ``relative_sky`` (1 beyond it) [1].
    bands : ViewBands
        The view bands.
    sun_direction : numpy.ndarray or None
        (3,) unit vector towards the sun [1].
    raster : sky.SkyRaster
        The sky raster [radiance x sr].
    open_light : tuple, optional
        The colour band's open-sky light (3,) and every band's on the channels' sum (B,)
        [radiance x sr]: the sky's term is then the read of ``sky_maps`` times the same term on
        open ground at the pixel's view (``open_sky``): the same formula with the per-point part
        done on the ground raster before the camera reads it.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) float32 [radiance].
    """
    rows, _ = cam._ground_rows(camera)
    radiance = np.zeros((camera.height, camera.width, 3), dtype=np.float32)
    if not len(rows):
        return radiance
    fp, _ = cam._view_footprints(camera)
    views, zenith, azimuth = _camera_views(camera)
    light = cam._filtered_chain(sun, fp)
    if sun_direction is not None:
        light *= _sun_shape(brdf, camera, tuple(float(c) for c in sun_direction))[None]
    weights = _band_weights(camera, bands.zeniths)
    ratio = sky_ratio(brdf, raster, bands, views, angles=(zenith, azimuth))
    if open_light is not None:
        sky = cam._filtered_chain(sky_maps, fp)  # (3, n), relative to open ground
        sky *= open_sky(bands, weights, *open_light)
        sky *= ratio
        light += sky
    else:
        light += _stacked_sky(cam._filtered_chain(sky_maps, fp), bands, weights, ratio)
    rho = cam._albedo_in_view(camera, albedo)
    light *= rho
    light *= np.float32(1.0 / np.pi)
    radiance[rows] = light.T.reshape(len(rows), camera.width, -1)
    return radiance


def _stacked_sky(stack, bands: ViewBands, weights, ratio) -> np.ndarray:
    """``banded_sky`` of the bands' terms read as one stack (3 + B - 1, n): each band's channel,
    three for the colour band. [radiance x sr]"""
    c = bands.colour
    colour = stack[c:c + 3]
    bands_light = np.concatenate([stack[:c], colour.sum(axis=0)[None], stack[c + 3:]])
    return banded_sky(colour, bands_light, weights, ratio)


def open_sky(bands: ViewBands, weights, colour_open, bands_open) -> np.ndarray:
    """``banded_sky``'s blend on open ground, before ``sky_ratio``.

    The colour band's open light times sum_b w_b G_b,open / G_c,open.

    Parameters
    ----------
    bands : ViewBands
        The view bands.
    weights : numpy.ndarray
        w_b (B, n) the weights [1].
    colour_open : numpy.ndarray
        (3,) the colour band's open light [radiance x sr].
    bands_open : numpy.ndarray
        G_b,open (B,) each band's open light on the channels' sum [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (3, n) float32 [radiance x sr].
    """
    bands_open = np.asarray(bands_open, dtype=np.float64)
    scale = bands_open / max(float(bands_open[bands.colour]), 1e-30)
    blend = np.tensordot(scale.astype(np.float32), weights, axes=1)
    return np.asarray(colour_open, dtype=np.float32)[:, None] * blend[None]


def relative_sky(camera: cam.Camera, grid, bands: ViewBands, colour, bands_light, colour_open, bands_open):
    """``banded_sky`` before ``sky_ratio``, over the same on open ground, at each cell of a ground raster.

    r-free and 1 on open ground, so the camera can read it like any ground raster (1 beyond it) and
    ``ground_radiance`` multiply by the open term at each pixel's own view. The views are each cell's
    own, from its centre to the camera's pinhole (``_cell_weights``).

    Parameters
    ----------
    camera : camera.Camera
        The camera [m].
    grid : Grid
        The ground raster's grid [m].
    bands : ViewBands
        The view bands.
    colour : numpy.ndarray
        (rows, cols, 3): the colour band's term [radiance x sr].
    bands_light : numpy.ndarray
        (rows, cols, B): every band's on the channels' sum [radiance x sr].
    colour_open : numpy.ndarray
        (3,) the same on open ground [radiance x sr].
    bands_open : numpy.ndarray
        (B,) the same on open ground [radiance x sr].

    Returns
    -------
    numpy.ndarray
        (rows, cols, 3) float32 [1].
    """
    weights = _cell_weights(camera, grid, bands.zeniths)  # (B, rows * cols)
    flat = np.moveaxis(bands_light.reshape(-1, len(bands.zeniths)), -1, 0)
    colour_flat = np.moveaxis(colour.reshape(-1, 3), -1, 0)
    sky = banded_sky(colour_flat, flat, weights, np.float32(1.0))
    sky /= np.maximum(open_sky(bands, weights, colour_open, bands_open), np.float32(1e-30))
    return np.moveaxis(sky, 0, -1).reshape(*grid.shape, 3)


@functools.lru_cache(maxsize=2)
def _cell_weights(camera: cam.Camera, grid, zeniths: tuple) -> np.ndarray:
    """``ViewBands.weights`` (B, rows * cols) float32 at the view zeniths from a ground grid's
    cell centres to the camera's pinhole (held to VIEW_ZENITH_LIMIT). Read-only. [1]"""
    gx, gy = grid.ground_from_raster(np.arange(grid.shape[0])[:, None], np.arange(grid.shape[1])[None, :])
    across = np.hypot(camera.position[0] - gx, camera.position[1] - gy).reshape(-1)
    zenith = np.minimum(np.arctan2(across, float(camera.position[2])), VIEW_ZENITH_LIMIT)
    out = ViewBands(zeniths, 0.0, 0.0).weights(zenith).astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=2)
def _band_weights(camera: cam.Camera, zeniths: tuple) -> np.ndarray:
    """``ViewBands.weights`` (B, n) float32 at the camera's ground pixels' own view zeniths: the
    same while the camera and the bands stay (the sky changes slowly). Read-only. [1]"""
    out = ViewBands(zeniths, 0.0, 0.0).weights(_camera_views(camera)[1]).astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=2)
def _sun_shape(brdf: BrdfConfig, camera: cam.Camera, sun_direction: tuple) -> np.ndarray:
    """The shape s(V(x), L_sun) (n,) float32 at the camera's ground pixels' own views: made once
    while neither the camera nor the sun moves. Read-only. [1]"""
    out = shape(brdf, _camera_views(camera)[0], np.asarray(sun_direction)[None]).astype(np.float32)
    out.flags.writeable = False
    return out


def background(camera: cam.Camera, ground_radiance_: np.ndarray, sky) -> np.ndarray:
    """``camera.background`` with the ground's radiance given: f ground + (1 - f) sky.

    Parameters
    ----------
    camera : camera.Camera
        The camera [m].
    ground_radiance_ : numpy.ndarray
        (height, width, 3) the ground's radiance [radiance].
    sky : object
        The sky, as ``camera.sky_view`` takes it.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) radiance [radiance].
    """
    fraction, rest = cam._ground_fractions(camera)
    out = ground_radiance_ * fraction[..., None]
    out += cam.sky_view(camera, sky) * rest
    return out
