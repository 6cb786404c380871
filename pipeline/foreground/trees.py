"""Foreground passes rendered: the trees themselves, seen by the camera (Max 1991, Figs. 8-9), lit by sun
and sky (``sun``) and by the sky alone (``sky``), with their coverage ``alpha`` (``tree_passes``,
the procedural grove), and the share of the sun and of the sky that reaches each leaf and stem past
the others (``sun_visibility``, ``sky_exposure``). Geometry, coverage, compositing, shading and sun
visibility: docs/method.md, "The foreground passes".
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import ArrayLike

from pipeline.camera.pinhole import Camera, project_points
from pipeline.canopy.grove import Leaves, Shapes, Wood
from pipeline.canopy.rasteriser import coverage_fragments
from pipeline.core.geometry import Grid, normalized
from pipeline.foreground.passes import ForegroundPasses
from pipeline.foreground.tree_detail import bark_pattern

__all__ = ["LEAF_REFLECTANCE", "LEAF_TRANSMITTANCE", "BARK_REFLECTANCE", "sun_visibility", "leaf_sun_visibility",
           "sky_exposure", "TreeOptics", "TREE_OPTICS", "tree_passes", "STEM_PROBE", "stem_visibility"]

LEAF_REFLECTANCE = (0.06, 0.12, 0.03)
"""Default hemispherical reflectance of a green leaf, linear Rec.709 RGB. [1]"""
LEAF_TRANSMITTANCE = (0.04, 0.12, 0.02)
"""Default hemispherical transmittance of a green leaf, linear Rec.709 RGB. [1]"""
BARK_REFLECTANCE = (0.25, 0.20, 0.15)
"""Default reflectance of bark, linear Rec.709 RGB. [1]"""

_DEPTH_RATIO = 1.05  # most ratio of the depths of a wood piece's ends in the camera pass
_MAX_PIECES = 256  # most pieces one capsule is cut into


# ---------------------------------------------------------------------------------------------
# Sun visibility
# ---------------------------------------------------------------------------------------------


def sun_visibility(leaves: Leaves, wood: Wood | None = None, *, sun_point: ArrayLike,
                   pixel: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Fraction of each leaf's and each capsule's area that the shapes nearer the sun let the sun reach.

    The sun is taken as a point (penumbra ignored). Partial pixels are treated as independent
    occluders; the error per leaf against exact rays (tests/test_foreground.py) is measured in
    docs/accuracy.md. The cost grows about as 1 / pixel^2 once pixels are below leaf size.

    Parameters
    ----------
    leaves : grove.Leaves
        The leaves: centres and semi-axes (N, 3) [m].
    wood : grove.Wood, optional
        The wood's capsules: ends (M, 3) and radii (M,) [m]; None: no wood.
    sun_point : tuple of (float, float)
        (sx, sy) the sun's sky-plane point (wx / wz, wy / wz) [1] (a tangent).
    pixel : float, optional
        Raster pixel across the light's beam; default a quarter of the median leaf length (half the
        median semi-axis |U|) [m].

    Returns
    -------
    leaf : numpy.ndarray
        (N,) float64 visibility in [0, 1] [1]; a shape that covers no pixel (a leaf edge-on to the
        sun) gets 1.
    wood : numpy.ndarray
        (M,) float64 visibility in [0, 1] [1].
    """
    point = np.asarray(sun_point, dtype=np.float64)
    s = np.array([point[0], point[1], 1.0], dtype=np.float64)
    return _visibility(leaves, _no_wood() if wood is None else wood, s / np.linalg.norm(s), pixel)


def leaf_sun_visibility(leaves: Leaves, wood: Wood | None = None, *, sun_point: ArrayLike,
                        pixel: float | None = None) -> np.ndarray:
    """The leaves' part of ``sun_visibility``.

    Parameters
    ----------
    leaves, wood, sun_point, pixel
        The arguments of ``sun_visibility``, passed on.

    Returns
    -------
    numpy.ndarray
        (N,) float64 visibility in [0, 1] [1].
    """
    return sun_visibility(leaves, wood, sun_point=sun_point, pixel=pixel)[0]


def sky_exposure(leaves: Leaves, wood: Wood | None = None, *, pixel: float | None = None, rings: int = 2,
                 per_ring: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Fraction of the open sky's horizontal irradiance that reaches each leaf and capsule past the others.

    The visibility of ``sun_visibility`` averaged over sky directions with weight cos(theta) (a
    uniform sky), by the midpoint rule in cos^2(theta): ``rings`` rings of equal irradiance, each of
    ``per_ring`` azimuths, every other ring turned half a step. The leaf's orientation is left to
    the shading. Costs ``rings * per_ring`` visibility passes.

    Parameters
    ----------
    leaves, wood, pixel
        As in ``sun_visibility``.
    rings : int, optional
        Rings of equal irradiance [count].
    per_ring : int, optional
        Azimuths per ring [count].

    Returns
    -------
    leaf : numpy.ndarray
        (N,) float64 in [0, 1] [1].
    wood : numpy.ndarray
        (M,) float64 in [0, 1] [1].

    Raises
    ------
    ValueError
        When ``rings`` or ``per_ring`` is below 1.
    """
    if rings < 1 or per_ring < 1:
        raise ValueError(f"rings and per_ring must be at least 1, got {rings} and {per_ring}")
    wood = _no_wood() if wood is None else wood
    leaf, bark = np.zeros(len(leaves.center)), np.zeros(len(wood.radius))
    for ring in range(rings):
        cos_theta = np.sqrt(1.0 - (ring + 0.5) / rings)  # equal shares of cos^2
        sin_theta = np.sqrt(1.0 - cos_theta**2)
        for k in range(per_ring):
            azimuth = 2 * np.pi * (k + 0.5 * (ring % 2)) / per_ring
            s = np.array([sin_theta * np.sin(azimuth), sin_theta * np.cos(azimuth), cos_theta])
            a, b = _visibility(leaves, wood, s, pixel)
            leaf += a
            bark += b
    n = rings * per_ring
    return leaf / n, bark / n


def _visibility(leaves: Leaves, wood: Wood, s, pixel):
    """sun_visibility along the unit vector ``s`` towards the light."""
    n_leaves, n_wood = len(leaves.center), len(wood.radius)
    if pixel is None:
        sizes = np.linalg.norm(leaves.axis_u, axis=1) if n_leaves else np.asarray(wood.radius)
        pixel = 0.5 * float(np.median(sizes)) if len(sizes) else 1.0
    if not pixel > 0:
        raise ValueError(f"pixel must be positive, got {pixel} m")
    if n_leaves + n_wood == 0:
        return np.ones(0), np.ones(0)
    e1 = np.cross(s, [0.0, 0.0, 1.0]) if abs(s[2]) < 1 - 1e-12 else np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(s, e1)
    basis = np.column_stack([e1, e2])
    shapes = Shapes(leaves.center @ basis, leaves.axis_u @ basis, leaves.axis_v @ basis,
                    wood.start @ basis, wood.end @ basis, np.asarray(wood.radius, dtype=np.float64))
    half = np.sqrt(shapes.axis_a**2 + shapes.axis_b**2)
    low = np.concatenate([shapes.center - half, np.minimum(shapes.start, shapes.end) - shapes.radius[:, None]])
    high = np.concatenate([shapes.center + half, np.maximum(shapes.start, shapes.end) + shapes.radius[:, None]])
    x0, y0 = low.min(axis=0) - pixel
    x1, y1 = high.max(axis=0) + pixel
    grid = Grid((x0, y1), float(pixel), (int(np.ceil((y1 - y0) / pixel)), int(np.ceil((x1 - x0) / pixel))))
    flat, coverage, shape = coverage_fragments(shapes, grid)
    # fragment positions on the plane [m] and their distance towards the light [m]
    row, col = np.divmod(flat, grid.shape[1])
    px, py = grid.ground_from_raster(row, col)
    is_leaf = shape < n_leaves
    height = np.empty(len(flat))
    h_center, h_u, h_v = leaves.center @ s, leaves.axis_u @ s, leaves.axis_v @ s
    slope_x, slope_y = _plane_slope(shapes.axis_a, shapes.axis_b, h_u, h_v)
    # leaf fragments: h_center + clip(rise, -reach, reach) per fragment, compiled
    from pipeline.kernels import raster

    raster.leaf_heights(shape, n_leaves, px, py, np.ascontiguousarray(shapes.center[:, 0]),
                         np.ascontiguousarray(shapes.center[:, 1]), slope_x, slope_y, h_center, np.hypot(h_u, h_v),
                         height)
    j = shape[~is_leaf] - n_leaves
    a0, a1 = shapes.start[j], shapes.end[j]
    t = _along(np.column_stack([px[~is_leaf], py[~is_leaf]]) - a0, a1 - a0)
    height[~is_leaf] = (1 - t) * (wood.start[j] @ s) + t * (wood.end[j] @ s) + wood.radius[j]
    weight = _front_to_back(flat, -height, coverage)
    seen = np.bincount(shape, weights=weight, minlength=n_leaves + n_wood)
    total = np.bincount(shape, weights=coverage, minlength=n_leaves + n_wood)
    visibility = np.where(total > 0, seen / np.where(total > 0, total, 1.0), 1.0)
    visibility = np.clip(visibility, 0.0, 1.0)
    return visibility[:n_leaves], visibility[n_leaves:]


def _plane_slope(a, b, h_u, h_v):
    """Gradient (d height / dx, d height / dy) on the plane of flat ellipses whose conjugate
    semi-axes a, b (n, 2) [m] rise by h_u, h_v (n,) [m]: the point alpha a + beta b rises by
    alpha h_u + beta h_v. Zero for an ellipse seen edge-on."""
    det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    inverse = np.where(np.abs(det) > 1e-12 * (np.sum(a * a, axis=1) + np.sum(b * b, axis=1)),
                       1.0 / np.where(det != 0, det, 1.0), 0.0)
    return (b[:, 1] * h_u - a[:, 1] * h_v) * inverse, (a[:, 0] * h_v - b[:, 0] * h_u) * inverse


def _along(offset, axis):
    """Parameter in [0, 1] of the nearest point of a segment (axis (n, 2)) to offset (n, 2)."""
    length2 = np.sum(axis**2, axis=1)
    return np.clip(np.sum(offset * axis, axis=1) / np.where(length2 > 1e-24, length2, 1.0), 0.0, 1.0)


def _front_to_back(flat, depth, coverage):
    """Weight c prod(1 - c') of each fragment, the product over the nearer fragments (smaller
    ``depth``) of the same pixel ``flat``: a segmented cumulative sum of -log(1 - c)."""
    if len(flat) and flat.max() < 2**32:  # one float key, pixel + depth in [0, 0.5]: 2-3 x faster
        span = float(depth.max() - depth.min())
        order = np.argsort(flat + (depth - depth.min()) * (0.5 / span if span > 0 else 0.0))
    else:
        order = np.lexsort((depth, flat))
    pix = flat[order]
    c = coverage[order].astype(np.float64)
    optical = -np.log1p(-c)
    before = np.cumsum(optical) - optical
    first = np.flatnonzero(np.r_[True, pix[1:] != pix[:-1]])
    starts = np.repeat(first, np.diff(np.r_[first, len(pix)]))
    weight = np.empty(len(c))
    weight[order] = c * np.exp(-(before - before[starts]))
    return weight


def _no_wood() -> Wood:
    return Wood(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


# ---------------------------------------------------------------------------------------------
# The camera pass
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TreeOptics:
    """The optical properties of the trees' leaves and bark in ``tree_passes``.

    Attributes
    ----------
    leaf_reflectance : float or tuple of float
        Hemispherical reflectance of a leaf, one number (grey) or linear Rec.709 RGB [1].
    leaf_transmittance : float or tuple of float
        Hemispherical transmittance of a leaf, likewise [1].
    bark_reflectance : float or tuple of float
        Mean reflectance of bark, likewise (``bark_pattern`` furrows it) [1].
    """

    leaf_reflectance: float | tuple[float, float, float] = LEAF_REFLECTANCE
    leaf_transmittance: float | tuple[float, float, float] = LEAF_TRANSMITTANCE
    bark_reflectance: float | tuple[float, float, float] = BARK_REFLECTANCE


TREE_OPTICS = TreeOptics()
"""The default optics of ``tree_passes``: LEAF_REFLECTANCE, LEAF_TRANSMITTANCE and BARK_REFLECTANCE. [1]"""


def tree_passes(leaves: Leaves, wood: Wood | None, camera: Camera, *, sun_direction: ArrayLike,
                sun_irradiance: ArrayLike, sky_irradiance: ArrayLike, leaf_sun_visibility: ArrayLike | None = None,
                wood_sun_visibility: ArrayLike | None = None, leaf_sky_exposure: ArrayLike = 0.7,
                wood_sky_exposure: ArrayLike = 0.6, optics: TreeOptics = TREE_OPTICS, near: float = 0.1,
                ground_height: float | None = 0.0, haze: float = 0.0) -> ForegroundPasses:
    """The foreground passes of leaves and wood seen by ``camera`` (see the module docstring).

    Parameters
    ----------
    leaves : grove.Leaves
        The grove's leaves at one cycle frame (``grove.leaves_at``) [m].
    wood : grove.Wood or None
        Its wood (``grove.wood``) [m]; None: no wood.
    camera : pinhole.Camera
        The pinhole camera.
    sun_direction : array_like
        (3,) unit vector towards the sun [1]; at or below the horizon (z <= 0), or with a zero
        ``sun_irradiance``, there is no sun term (nor visibility pass) and F_sun = F_sky.
    sun_irradiance : array_like
        (3,) normal irradiance of the clear, uneclipsed sun [klx].
    sky_irradiance : array_like
        (3,) horizontal irradiance of the clear sky (sun excluded) [klx].
    leaf_sun_visibility, wood_sun_visibility : numpy.ndarray, optional
        (N,), (M,) in [0, 1] [1], or None to compute them with ``sun_visibility`` at its default
        pixel. Pass ones for no shadows.
    leaf_sky_exposure, wood_sky_exposure : float or numpy.ndarray, optional
        Scalar or (N,), (M,): the share of the open sky that reaches each shape (``sky_exposure``
        computes them) [1].
    optics : TreeOptics, optional
        The leaves' reflectance and transmittance and the bark's reflectance, each (3,) linear RGB [1].
    near : float, optional
        Shapes nearer the pinhole than this are clipped (wood) or dropped (leaves) [m].
    ground_height : float or None, optional
        The ground plane z, which hides what lies below it (the trunks' round feet), judged at pixel
        centres; None keeps everything. The camera must be above it [m].
    haze : float, optional
        Extinction length of the air between the camera and the trees, or 0 for none: each fragment
        keeps T = exp(-distance / haze) of its light, and the ``haze`` pass gets the rest of its
        weight [m].

    Returns
    -------
    ForegroundPasses
        In radiance units, irradiance / sr [klx / sr = kcd/m^2].

    Raises
    ------
    ValueError
        For a sun direction that is not a unit vector, ``near`` not above 0, a camera not above the
        ground, or a reflectance, irradiance, visibility or exposure of the wrong shape or range.
    """
    wood = _no_wood() if wood is None else wood
    s = _checked_view(sun_direction, camera, near, ground_height)
    light = _checked_light(leaves, wood, s, sun_irradiance=sun_irradiance, sky_irradiance=sky_irradiance,
                           optics=optics, leaf_sun_visibility=leaf_sun_visibility,
                           wood_sun_visibility=wood_sun_visibility, leaf_sky_exposure=leaf_sky_exposure,
                           wood_sky_exposure=wood_sky_exposure)
    seen = _seen_leaves(leaves, camera, near)
    pieces = _seen_wood(wood, camera, near)
    fragments, shape = _fragments(camera, seen, pieces)
    _shade_leaf_fragments(fragments, shape, camera, seen, *_leaf_light(seen, light))
    _shade_wood_fragments(fragments, shape, len(seen.kept), camera, pieces, light)
    return _composite(fragments, camera, ground_height, haze)


@dataclass(frozen=True)
class _Light:
    """The light on the trees and their materials, checked (``_checked_light``); RGB linear Rec.709."""

    sun_direction: np.ndarray  # (3,) unit vector towards the sun [1]
    sun: np.ndarray  # (3,) normal irradiance of the sun, zero when it has set or is dark [klx]
    sky: np.ndarray  # (3,) horizontal irradiance of the sky [klx]
    reflectance: np.ndarray  # (3,) a leaf's [1]
    transmittance: np.ndarray  # (3,) a leaf's [1]
    bark: np.ndarray  # (3,) the bark's mean reflectance [1]
    leaf_sun_visibility: np.ndarray  # (N,) the share of the sun that reaches each leaf [1]
    wood_sun_visibility: np.ndarray  # (M,) and each capsule [1]
    leaf_sky_exposure: np.ndarray  # (N,) the share of the open sky that reaches each leaf [1]
    wood_sky_exposure: np.ndarray  # (M,) and each capsule [1]


def _checked_view(sun_direction: ArrayLike, camera: Camera, near: float, ground_height: float | None) -> np.ndarray:
    """The sun's direction (3,) float64 [1], once it, ``near`` and the camera's height are checked."""
    s = np.asarray(sun_direction, dtype=np.float64).reshape(3)
    if not np.isclose(np.linalg.norm(s), 1.0, atol=1e-6):
        raise ValueError(f"sun_direction must be a unit vector, got length {np.linalg.norm(s):.6g}")
    if not near > 0:
        raise ValueError(f"near must be positive, got {near} m")
    if ground_height is not None and not camera.position[2] > ground_height:
        raise ValueError(f"the camera (z = {camera.position[2]} m) must be above the ground "
                         f"(z = {ground_height} m)")
    return s


def _checked_light(leaves: Leaves, wood: Wood, s: np.ndarray, *, sun_irradiance: ArrayLike,
                   sky_irradiance: ArrayLike, optics: TreeOptics, leaf_sun_visibility: ArrayLike | None,
                   wood_sun_visibility: ArrayLike | None, leaf_sky_exposure: ArrayLike,
                   wood_sky_exposure: ArrayLike) -> _Light:
    """``tree_passes``'s light and optics checked, as arrays; the sun's visibility computed when not
    given, and zero (with the sun's irradiance) when the sun has set (``s`` z <= 0) or is dark."""
    n_leaves, n_wood = len(leaves.center), len(wood.radius)
    e_sun = _rgb(sun_irradiance, "sun_irradiance")
    e_sky = _rgb(sky_irradiance, "sky_irradiance")
    rho, tau, bark = (_rgb(v, name) for v, name in ((optics.leaf_reflectance, "leaf_reflectance"),
                                                   (optics.leaf_transmittance, "leaf_transmittance"),
                                                   (optics.bark_reflectance, "bark_reflectance")))
    leaf_vis, wood_vis = (None if value is None else _per_shape(value, n, name) for value, n, name in (
        (leaf_sun_visibility, n_leaves, "leaf_sun_visibility"),
        (wood_sun_visibility, n_wood, "wood_sun_visibility")))
    if s[2] <= 0 or not np.any(e_sun > 0):  # the sun has set, or is dark: no sun term
        e_sun, leaf_vis, wood_vis = np.zeros(3), np.zeros(n_leaves), np.zeros(n_wood)
    elif leaf_vis is None or wood_vis is None:
        leaf_v, wood_v = sun_visibility(leaves, wood, sun_point=s[:2] / s[2])
        leaf_vis = leaf_v if leaf_vis is None else leaf_vis
        wood_vis = wood_v if wood_vis is None else wood_vis
    return _Light(s, e_sun, e_sky, rho, tau, bark, leaf_vis, wood_vis,
                  _per_shape(leaf_sky_exposure, n_leaves, "leaf_sky_exposure"),
                  _per_shape(wood_sky_exposure, n_wood, "wood_sky_exposure"))


@dataclass(frozen=True)
class _SeenLeaves:
    """The leaves beyond the near plane, projected into the image (``_seen_leaves``)."""

    kept: np.ndarray  # (n,) int64, the index of each among all the leaves
    rel: np.ndarray  # (n, 3) its centre less the pinhole [m]
    depth: np.ndarray  # (n,) its centre's depth along the camera's forward [m]
    reach: np.ndarray  # (n,) how far it reaches in depth either side of its centre [m]
    u: np.ndarray  # (n,) its centre in the image [pixel]
    v: np.ndarray
    du: np.ndarray  # (n, 2) its semi-axes in the image [pixel]
    dv: np.ndarray
    normal: np.ndarray  # (n, 3) its unit normal, either face [1]


def _seen_leaves(leaves: Leaves, camera: Camera, near: float) -> _SeenLeaves:
    """The leaves wholly beyond ``near`` [m] in depth (the others dropped), projected (centre and
    the Jacobian of the projection)."""
    right, up, forward = camera.basis
    focal = camera.focal
    rel = leaves.center - np.asarray(camera.position, dtype=np.float64)
    depth = rel @ forward
    reach = np.hypot(leaves.axis_u @ forward, leaves.axis_v @ forward)
    kept = np.flatnonzero(depth - reach > near)
    rel, depth, reach = rel[kept], depth[kept], reach[kept]
    axis_u, axis_v = leaves.axis_u[kept], leaves.axis_v[kept]
    u, v, _ = project_points(camera, leaves.center[kept])  # depth > near > 0: as rel, depth here
    du = _image_vector(axis_u, rel, depth, right, up, forward, focal)
    dv = _image_vector(axis_v, rel, depth, right, up, forward, focal)
    normal = normalized(np.cross(axis_u, axis_v))
    return _SeenLeaves(kept, rel, depth, reach, u, v, du, dv, normal)


def _leaf_light(seen: _SeenLeaves, light: _Light) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (n, 3) [klx / sr] of each seen leaf's face towards the viewer: lit by the sky alone,
    and by the sun alone (reflected, or transmitted from the sun behind it)."""
    facing = np.where(np.sum(seen.rel * seen.normal, axis=1) > 0, -1.0, 1.0)  # the face towards the viewer
    normal_seen = seen.normal * facing[:, None]
    cos_sun = normal_seen @ light.sun_direction
    sky_view = 0.5 * (1 + normal_seen[:, 2])
    rho, tau = light.reflectance, light.transmittance
    leaf_sky = (light.leaf_sky_exposure[seen.kept, None] * light.sky / np.pi) * (rho * sky_view[:, None]
                                                                                 + tau * (1 - sky_view[:, None]))
    leaf_sun = (light.leaf_sun_visibility[seen.kept] * np.abs(cos_sun))[:, None] * light.sun / np.pi * np.where(
        (cos_sun > 0)[:, None], rho, tau)
    return leaf_sky, leaf_sun


@dataclass(frozen=True)
class _SeenWood:
    """The wood's pieces beyond the near plane, projected into the image (``_seen_wood``)."""

    start: np.ndarray  # (k, 3) the ends of each piece's axis [m]
    end: np.ndarray
    radius: np.ndarray  # (k,) its radius [m]
    owner: np.ndarray  # (k,) int64, the capsule it is cut from
    depth_start: np.ndarray  # (k,) the depths of its ends along the camera's forward [m]
    depth_end: np.ndarray
    u0: np.ndarray  # (k,) its ends (u0, v0), (u1, v1) in the image [pixel]
    v0: np.ndarray
    u1: np.ndarray
    v1: np.ndarray
    radius_px: np.ndarray  # (k,) its radius in the image [pixel]


def _seen_wood(wood: Wood, camera: Camera, near: float) -> _SeenWood:
    """The wood clipped at ``near`` [m], cut where its depth varies (``_wood_pieces``), projected."""
    origin = np.asarray(camera.position, dtype=np.float64)
    forward = camera.basis[2]
    p0, p1, radius, owner = _wood_pieces(wood, origin, forward, near)
    z0, z1 = (p0 - origin) @ forward, (p1 - origin) @ forward
    (u0, v0, _), (u1, v1, _) = project_points(camera, p0), project_points(camera, p1)
    return _SeenWood(p0, p1, radius, owner, z0, z1, u0, v0, u1, v1, camera.focal * radius / np.sqrt(z0 * z1))


@dataclass(frozen=True)
class _Fragments:
    """The trees' fragments in the image, one per shape and pixel it covers (``_fragments``); the
    shading fills in ``depth``, ``sun`` and ``sky``."""

    flat: np.ndarray  # (n,) int64, the pixel row * cols + col
    coverage: np.ndarray  # (n,) float32, the share of the pixel the shape covers [1]
    u: np.ndarray  # (n,) the pixel's centre in the image [pixel]
    v: np.ndarray
    depth: np.ndarray  # (n,) the depth of the shape's surface along the camera's forward [m]
    sun: np.ndarray  # (n, 3) its radiance lit by the sun and the sky [klx / sr]
    sky: np.ndarray  # (n, 3) lit by the sky alone [klx / sr]
    def cut(self, keep: np.ndarray) -> _Fragments:
        """The fragments where the (n,) bool ``keep`` is true."""
        return _Fragments(*(getattr(self, f.name)[keep] for f in fields(self)))


def _fragments(camera: Camera, leaves: _SeenLeaves, wood: _SeenWood) -> tuple[_Fragments, np.ndarray]:
    """The fragments of the seen leaves and wood, not yet shaded, and the (n,) int64 shape of each
    (leaf i is shape i, wood piece j shape ``len(leaves.kept) + j``)."""
    rows, cols = camera.height, camera.width
    image = Grid((0.0, 0.0), 1.0, (rows, cols))  # plane point (u, -v) is image point (u, v)
    shapes = Shapes(np.column_stack([leaves.u, -leaves.v]), np.column_stack([leaves.du[:, 0], -leaves.du[:, 1]]),
                    np.column_stack([leaves.dv[:, 0], -leaves.dv[:, 1]]), np.column_stack([wood.u0, -wood.v0]),
                    np.column_stack([wood.u1, -wood.v1]), wood.radius_px)
    flat, coverage, shape = coverage_fragments(shapes, image)
    row, col = np.divmod(flat, cols)
    fragments = _Fragments(flat, coverage, col + 0.5, row + 0.5, np.empty(len(flat)), np.empty((len(flat), 3)),
                           np.empty((len(flat), 3)))
    return fragments, shape


def _shade_leaf_fragments(fragments: _Fragments, shape: np.ndarray, camera: Camera, leaves: _SeenLeaves,
                          leaf_sky: np.ndarray, leaf_sun: np.ndarray) -> None:
    """Fill in the depth and light of the leaf fragments: the depth of the leaf's plane along the
    pixel's ray (n . ray, the ray at unit depth), clamped to the leaf; compiled, the operations of
    ``_leaf_fragments_arrays``."""
    from pipeline.kernels import raster

    right, up, forward = camera.basis
    normal = leaves.normal
    n_forward, n_right, n_up, n_rel = normal @ forward, normal @ right, normal @ up, np.sum(normal * leaves.rel, axis=1)
    raster.leaf_fragments(fragments.flat, shape, len(leaves.kept), camera.width, camera.height, float(camera.focal),
                           n_forward, n_right, n_up, n_rel, leaves.depth - leaves.reach, leaves.depth + leaves.reach,
                           leaf_sky, leaf_sun, fragments.depth, fragments.sun, fragments.sky)


def _shade_wood_fragments(fragments: _Fragments, shape: np.ndarray, n_leaves: int, camera: Camera,
                          wood: _SeenWood, light: _Light) -> None:
    """Fill in the depth and light of the wood fragments (shapes from ``n_leaves`` on)."""
    is_wood = shape >= n_leaves
    j = shape[is_wood] - n_leaves
    if not len(j):
        return
    t, normal, depth = _wood_surface(fragments.u[is_wood], fragments.v[is_wood], j, camera, wood)
    fragments.depth[is_wood] = depth
    sky, sun = _wood_light(normal, t, j, wood, light)
    fragments.sky[is_wood] = sky
    fragments.sun[is_wood] = sky + sun


def _wood_surface(pu: np.ndarray, pv: np.ndarray, j: np.ndarray, camera: Camera,
                  wood: _SeenWood) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The front surface of wood pieces ``j`` (n,) at image points (pu, pv) (n,) [pixel]: the
    parameter t in [0, 1] along the piece's axis of the nearest axis point [1], the surface's unit
    normal (n, 3) [1] and its depth (n,) [m]."""
    right, up, forward = camera.basis
    origin = np.asarray(camera.position, dtype=np.float64)
    a0 = np.column_stack([wood.u0, wood.v0])[j]
    a1 = np.column_stack([wood.u1, wood.v1])[j]
    offset = np.column_stack([pu, pv]) - a0
    t = _along(offset, a1 - a0)
    axis_depth = 1.0 / ((1 - t) / wood.depth_start[j] + t / wood.depth_end[j])  # 1 / depth is affine on the image
    toward, sideways = _wood_side(wood.start, wood.end, origin, right, up, forward, camera.focal)
    perp = normalized(np.column_stack([-(wood.v1 - wood.v0), wood.u1 - wood.u0]) + np.array([1e-12, 0.0]))[j]
    lateral = np.clip(np.sum((offset - t[:, None] * (a1 - a0)) * perp, axis=1) / wood.radius_px[j], -1, 1)
    facing_part = np.sqrt(1 - lateral**2)
    normal = facing_part[:, None] * toward[j] + lateral[:, None] * sideways[j]
    return t, normal, axis_depth - wood.radius[j] * facing_part


def _wood_light(normal: np.ndarray, t: np.ndarray, j: np.ndarray, wood: _SeenWood,
                light: _Light) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (n, 3) [klx / sr] of the bark (``bark_pattern``) of wood pieces ``j`` at the axis
    parameters ``t`` with surface normals ``normal``: lit by the sky alone, and by the sun alone."""
    k = wood.owner[j]
    p0, p1 = wood.start, wood.end
    axis_z = p0[j, 2] + t * (p1[j, 2] - p0[j, 2])  # height of the fragment's axis point [m]
    furrows = bark_pattern(normal, p1[j] - p0[j], axis_z, wood.radius_px[j])[:, None] * light.bark
    sky = (light.wood_sky_exposure[k] * 0.5 * (1 + normal[:, 2]))[:, None] * furrows * light.sky / np.pi
    sun = ((light.wood_sun_visibility[k] * np.maximum(normal @ light.sun_direction, 0.0))[:, None] * furrows
           * light.sun / np.pi)
    return sky, sun


def _composite(fragments: _Fragments, camera: Camera, ground_height: float | None, haze: float) -> ForegroundPasses:
    """The passes: the fragments above the ground composited front to back, veiled by the haze."""
    from pipeline.kernels import raster

    rows, cols = camera.height, camera.width
    if ground_height is not None:
        fragments = fragments.cut(_above_ground(fragments, camera, ground_height))
    weight = _front_to_back(fragments.flat, fragments.depth, fragments.coverage)
    frag_sun, frag_sky, haze_image = fragments.sun, fragments.sky, None
    if haze > 0:
        transmittance = _haze_transmittance(fragments, camera, haze)
        frag_sun = frag_sun * transmittance[:, None]
        frag_sky = frag_sky * transmittance[:, None]
        haze_image = np.bincount(fragments.flat, weights=weight * (1.0 - transmittance),
                                 minlength=rows * cols).reshape(rows, cols).astype(np.float32)
    optical = np.bincount(fragments.flat, weights=-np.log1p(-fragments.coverage.astype(np.float64)),
                          minlength=rows * cols)
    alpha = -np.expm1(-optical).reshape(rows, cols)
    sun_image, sky_image = (image.reshape(rows, cols, 3) for image in raster.scatter_light(
        fragments.flat, weight, np.ascontiguousarray(frag_sun), np.ascontiguousarray(frag_sky), rows * cols))
    return ForegroundPasses(sun_image.astype(np.float32), sky_image.astype(np.float32),
                            alpha.astype(np.float32), haze_image)


def _above_ground(fragments: _Fragments, camera: Camera, ground_height: float) -> np.ndarray:
    """(n,) bool: whether each fragment's surface, along its pixel centre's ray, is not below the
    ground plane z = ``ground_height`` [m]."""
    right, up, forward = camera.basis
    rows, cols, focal = camera.height, camera.width, camera.focal
    ray_z = forward[2] + ((fragments.u - 0.5 * cols) / focal) * right[2] + ((0.5 * rows - fragments.v) / focal) * up[2]
    return np.asarray(camera.position, dtype=np.float64)[2] + fragments.depth * ray_z >= ground_height


def _haze_transmittance(fragments: _Fragments, camera: Camera, haze: float) -> np.ndarray:
    """(n,) the share T = exp(-distance / haze) of each fragment's light that the air lets through
    to the camera, haze the extinction length [m] (``depth`` is along forward)."""
    rows, cols, focal = camera.height, camera.width, camera.focal
    ray = np.sqrt(1.0 + ((fragments.u - 0.5 * cols) / focal) ** 2 + ((0.5 * rows - fragments.v) / focal) ** 2)
    return np.exp(-fragments.depth * ray / haze)


def _leaf_fragments_arrays(flat, shape, leaves, cols, rows, focal, n_forward, n_right, n_up, n_rel, nearest,
                           farthest, leaf_sky, leaf_sun, frag_depth, frag_sun, frag_sky) -> None:
    """``kernels.raster.leaf_fragments`` on arrays: its reference (tests/test_foreground.py)."""
    row, col = np.divmod(flat, cols)
    pu, pv = col + 0.5, row + 0.5
    is_leaf = shape < leaves
    i = shape[is_leaf]
    across = (n_forward[i] + ((pu[is_leaf] - 0.5 * cols) / focal) * n_right[i]
              + ((0.5 * rows - pv[is_leaf]) / focal) * n_up[i])
    hit = n_rel[i] / np.where(np.abs(across) > 1e-12, across, 1e-12)
    frag_depth[is_leaf] = np.clip(hit, nearest[i], farthest[i])
    frag_sun[is_leaf] = leaf_sky[i] + leaf_sun[i]
    frag_sky[is_leaf] = leaf_sky[i]


STEM_PROBE = 1e-3
"""Radius of the stems' axis lines, as a share of their radius, in ``stem_visibility``. [1]"""


def stem_visibility(leaves: Leaves, stems: Wood, *, sun_point: ArrayLike,
                    pixel: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``sun_visibility`` of the leaves and of the pieces of the wood (``taper_wood``), in one pass.

    Each piece is probed along its axis by a line STEM_PROBE of its radius thick: so the pieces of
    a stem, whose round ends overlap, do not shade one another (a stem's own shading is its
    normal's, max(n . s, 0)), and a stem is shaded by the leaves where the crown's shade begins
    along it. The stems cast no shadow in this pass: on the leaves, a few dozen branches against
    thousands of leaves, that is left out.

    Parameters
    ----------
    leaves, sun_point, pixel
        As in ``sun_visibility``.
    stems : grove.Wood
        The wood's pieces (``taper_wood``): ends (K, 3) and radii (K,) [m].

    Returns
    -------
    leaf : numpy.ndarray
        (N,) float64 visibility in [0, 1] [1].
    stem : numpy.ndarray
        (K,) float64 visibility of each piece in [0, 1] [1].
    """
    probes = Wood(stems.start, stems.end, STEM_PROBE * np.asarray(stems.radius))
    return sun_visibility(leaves, probes, sun_point=sun_point, pixel=pixel)


def _rgb(value: ArrayLike, name: str) -> np.ndarray:
    value = np.asarray(value, dtype=np.float64)
    if value.shape not in ((), (3,)):
        raise ValueError(f"{name} must be a number or 3 numbers (RGB), got shape {value.shape}")
    if not np.all(np.isfinite(value)) or np.any(value < 0):
        raise ValueError(f"{name} must be finite and not negative, got {value}")
    return np.broadcast_to(value, (3,)).copy()


def _per_shape(value: ArrayLike, n: int, name: str) -> np.ndarray:
    value = np.asarray(value, dtype=np.float64)
    if value.ndim == 0:
        value = np.full(n, float(value))
    if value.shape != (n,):
        raise ValueError(f"{name} must be a number or hold one value per shape ({n}), got shape {value.shape}")
    if not np.all(np.isfinite(value)) or np.any(value < 0) or np.any(value > 1 + 1e-6):
        raise ValueError(f"{name} must lie in [0, 1]")
    return value


def _image_vector(vector, rel, depth, right, up, forward, focal):
    """(du, dv) [pixel] of small world vectors (n, 3) [m] at camera-relative points rel (n, 3):
    the Jacobian of the perspective projection."""
    along = vector @ forward
    x, y = rel @ right / depth, rel @ up / depth
    du = focal * (vector @ right - x * along) / depth
    dv = -focal * (vector @ up - y * along) / depth
    return np.column_stack([du, dv])


def _wood_pieces(wood: Wood, origin, forward, near):
    """Capsules clipped to depth >= near [m] and cut into pieces whose end depths differ by at
    most _DEPTH_RATIO: (start (k, 3), end (k, 3), radius (k,), owner capsule (k,))."""
    z0 = (wood.start - origin) @ forward
    z1 = (wood.end - origin) @ forward
    keep = np.flatnonzero((z0 > near) | (z1 > near))
    start, end, z0, z1 = wood.start[keep], wood.end[keep], z0[keep], z1[keep]

    def to_near(p, q, zp, zq):  # the point of segment p q at depth ``near``
        return p + (q - p) * ((near - zp) / np.where(zq != zp, zq - zp, 1.0))[:, None]

    start = np.where((z0 < near)[:, None], to_near(start, end, z0, z1), start)
    end = np.where((z1 < near)[:, None], to_near(end, start, z1, z0), end)
    z0, z1 = np.maximum(z0, near), np.maximum(z1, near)
    count = np.clip(np.ceil(np.abs(np.log(z1 / z0)) / np.log(_DEPTH_RATIO)), 1, _MAX_PIECES).astype(np.int64)
    src = np.repeat(np.arange(len(keep)), count)
    k = np.arange(len(src)) - np.repeat(np.cumsum(count) - count, count)
    f0, f1 = (k / count[src])[:, None], ((k + 1) / count[src])[:, None]
    span = end[src] - start[src]
    return start[src] + f0 * span, start[src] + f1 * span, np.asarray(wood.radius)[keep][src], keep[src]


def _wood_side(p0, p1, origin, right, up, forward, focal):
    """Per wood piece: the unit normal of its cylinder facing the camera, and the unit normal at
    right angles to it whose image points the way of the image normal (-(v1 - v0), u1 - u0)."""
    axis = normalized(p1 - p0)
    middle = 0.5 * (p0 + p1)
    view = origin - middle
    toward = normalized(view - np.sum(view * axis, axis=1, keepdims=True) * axis)
    sideways = normalized(np.cross(axis, toward))
    rel = middle - origin
    depth = rel @ forward
    image_axis = _image_vector(p1 - p0, rel, depth, right, up, forward, focal)
    image_side = _image_vector(sideways, rel, depth, right, up, forward, focal)
    perp = np.column_stack([-image_axis[:, 1], image_axis[:, 0]])
    flip = np.where(np.sum(image_side * perp, axis=1) < 0, -1.0, 1.0)
    return toward, sideways * flip[:, None]
