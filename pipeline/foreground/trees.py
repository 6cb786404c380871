"""Foreground passes rendered: the trees themselves, seen by the camera (Max 1991, Figs. 8-9), lit by sun
and sky (``sun``) and by the sky alone (``sky``), with their coverage ``alpha`` (``tree_passes``,
the procedural grove), and the share of the sun and of the sky that reaches each leaf and stem past
the others (``sun_visibility``, ``sky_exposure``). Geometry, coverage, compositing, shading and sun
visibility: docs/method.md, "The foreground passes".
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.pinhole import Camera, project_points
from pipeline.canopy.grove import Leaves, Shapes, Wood
from pipeline.canopy.rasteriser import coverage_fragments
from pipeline.core.geometry import Grid, normalized
from pipeline.foreground.passes import ForegroundPasses
from pipeline.foreground.tree_detail import bark_pattern

__all__ = ["LEAF_REFLECTANCE", "LEAF_TRANSMITTANCE", "BARK_REFLECTANCE", "sun_visibility", "leaf_sun_visibility",
           "sky_exposure", "tree_passes", "STEM_PROBE", "stem_visibility"]

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


def sun_visibility(leaves: Leaves, wood: Wood | None = None, *, sun_point, pixel: float | None = None):
    """Fraction of each leaf's and each capsule's area that the shapes nearer the sun let the sun reach.

    The sun is taken as a point (penumbra ignored). Partial pixels are treated as independent
    occluders; the error per leaf against exact rays (tests/test_foreground.py) is measured in
    docs/accuracy.md. The cost grows about as 1 / pixel^2 once pixels are below leaf size.

    Parameters
    ----------
    leaves : grove_geometry.Leaves
        The leaves: centres and semi-axes (N, 3) [m].
    wood : grove_geometry.Wood, optional
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
    s = np.array([sun_point[0], sun_point[1], 1.0], dtype=np.float64)
    return _visibility(leaves, _no_wood() if wood is None else wood, s / np.linalg.norm(s), pixel)


def leaf_sun_visibility(leaves: Leaves, wood: Wood | None = None, *, sun_point,
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
                 per_ring: int = 6):
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
    from pipeline.kernels import raster as _raster

    _raster.leaf_heights(shape, n_leaves, px, py, *(np.ascontiguousarray(shapes.center[:, k]) for k in (0, 1)),
                         slope_x, slope_y, h_center, np.hypot(h_u, h_v), height)
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


def tree_passes(leaves: Leaves, wood: Wood | None, camera: Camera, *, sun_direction, sun_irradiance,
                sky_irradiance, leaf_sun_visibility=None, wood_sun_visibility=None,
                leaf_sky_exposure=0.7, wood_sky_exposure=0.6,
                leaf_reflectance=LEAF_REFLECTANCE, leaf_transmittance=LEAF_TRANSMITTANCE,
                bark_reflectance=BARK_REFLECTANCE, near: float = 0.1,
                ground_height: float | None = 0.0, haze: float = 0.0) -> ForegroundPasses:
    """The foreground passes of leaves and wood seen by ``camera`` (see the module docstring).

    Parameters
    ----------
    leaves : grove_geometry.Leaves
        The grove's leaves at one cycle frame (``grove_geometry.leaves_at``) [m].
    wood : grove_geometry.Wood or None
        Its wood (``grove.wood``) [m]; None: no wood.
    camera : camera.Camera
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
    leaf_reflectance, leaf_transmittance, bark_reflectance : array_like, optional
        (3,) linear RGB [1].
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
    n_leaves, n_wood = len(leaves.center), len(wood.radius)
    s = np.asarray(sun_direction, dtype=np.float64).reshape(3)
    if not np.isclose(np.linalg.norm(s), 1.0, atol=1e-6):
        raise ValueError(f"sun_direction must be a unit vector, got length {np.linalg.norm(s):.6g}")
    if not near > 0:
        raise ValueError(f"near must be positive, got {near} m")
    if ground_height is not None and not camera.position[2] > ground_height:
        raise ValueError(f"the camera (z = {camera.position[2]} m) must be above the ground "
                         f"(z = {ground_height} m)")
    e_sun = _rgb(sun_irradiance, "sun_irradiance")
    e_sky = _rgb(sky_irradiance, "sky_irradiance")
    rho, tau, bark = (_rgb(v, name) for v, name in ((leaf_reflectance, "leaf_reflectance"),
                                                   (leaf_transmittance, "leaf_transmittance"),
                                                   (bark_reflectance, "bark_reflectance")))
    leaf_vis, wood_vis = (None if value is None else _per_shape(value, n, name) for value, n, name in (
        (leaf_sun_visibility, n_leaves, "leaf_sun_visibility"),
        (wood_sun_visibility, n_wood, "wood_sun_visibility")))
    if s[2] <= 0 or not np.any(e_sun > 0):  # the sun has set, or is dark: no sun term
        e_sun, leaf_vis, wood_vis = np.zeros(3), np.zeros(n_leaves), np.zeros(n_wood)
    elif leaf_vis is None or wood_vis is None:
        leaf_v, wood_v = sun_visibility(leaves, wood, sun_point=s[:2] / s[2])
        leaf_vis = leaf_v if leaf_vis is None else leaf_vis
        wood_vis = wood_v if wood_vis is None else wood_vis
    leaf_exposure = _per_shape(leaf_sky_exposure, n_leaves, "leaf_sky_exposure")
    wood_exposure = _per_shape(wood_sky_exposure, n_wood, "wood_sky_exposure")

    rows, cols = camera.height, camera.width
    right, up, forward = camera.basis
    origin = np.asarray(camera.position, dtype=np.float64)
    focal = camera.focal

    # leaves: cull, project (centre and Jacobian), shade per leaf
    rel = leaves.center - origin
    depth = rel @ forward
    reach = np.hypot(leaves.axis_u @ forward, leaves.axis_v @ forward)
    kept = np.flatnonzero(depth - reach > near)
    rel, depth, reach = rel[kept], depth[kept], reach[kept]
    axis_u, axis_v = leaves.axis_u[kept], leaves.axis_v[kept]
    u, v, _ = project_points(camera, leaves.center[kept])  # depth > near > 0: as rel, depth here
    du = _image_vector(axis_u, rel, depth, right, up, forward, focal)
    dv = _image_vector(axis_v, rel, depth, right, up, forward, focal)
    normal = normalized(np.cross(axis_u, axis_v))
    facing = np.where(np.sum(rel * normal, axis=1) > 0, -1.0, 1.0)  # the face towards the viewer
    normal_seen = normal * facing[:, None]
    cos_sun = normal_seen @ s
    sky_view = 0.5 * (1 + normal_seen[:, 2])
    leaf_sky = (leaf_exposure[kept, None] * e_sky / np.pi) * (rho * sky_view[:, None]
                                                              + tau * (1 - sky_view[:, None]))
    leaf_sun = (leaf_vis[kept] * np.abs(cos_sun))[:, None] * e_sun / np.pi * np.where(
        (cos_sun > 0)[:, None], rho, tau)

    # wood: clip at the near plane, cut where the depth varies, project
    piece = _wood_pieces(wood, origin, forward, near)
    p0, p1, radius, owner = piece
    rel0, rel1 = p0 - origin, p1 - origin
    z0, z1 = rel0 @ forward, rel1 @ forward
    (u0, v0, _), (u1, v1, _) = project_points(camera, p0), project_points(camera, p1)
    radius_px = focal * radius / np.sqrt(z0 * z1)

    image = Grid((0.0, 0.0), 1.0, (rows, cols))  # plane point (u, -v) is image point (u, v)
    shapes = Shapes(np.column_stack([u, -v]), np.column_stack([du[:, 0], -du[:, 1]]),
                    np.column_stack([dv[:, 0], -dv[:, 1]]), np.column_stack([u0, -v0]),
                    np.column_stack([u1, -v1]), radius_px)
    flat, coverage, shape = coverage_fragments(shapes, image)
    row, col = np.divmod(flat, cols)
    pu, pv = col + 0.5, row + 0.5
    is_leaf = shape < len(kept)
    frag_depth = np.empty(len(flat))
    frag_sun = np.empty((len(flat), 3))
    frag_sky = np.empty((len(flat), 3))

    # leaf fragments: depth of the leaf's plane along the pixel's ray (n . ray, the ray at unit
    # depth), clamped to the leaf; compiled, the operations of _leaf_fragments_arrays
    from pipeline.kernels import raster as _raster

    n_forward, n_right, n_up, n_rel = normal @ forward, normal @ right, normal @ up, np.sum(normal * rel, axis=1)
    _raster.leaf_fragments(flat, shape, len(kept), cols, rows, float(focal), n_forward, n_right, n_up, n_rel,
                           depth - reach, depth + reach, leaf_sky, leaf_sun, frag_depth, frag_sun, frag_sky)

    # wood fragments: the cylinder's front surface and normal at the pixel
    j = shape[~is_leaf] - len(kept)
    if len(j):
        a0 = np.column_stack([u0, v0])[j]
        a1 = np.column_stack([u1, v1])[j]
        offset = np.column_stack([pu[~is_leaf], pv[~is_leaf]]) - a0
        t = _along(offset, a1 - a0)
        axis_z = 1.0 / ((1 - t) / z0[j] + t / z1[j])  # 1 / depth is affine on the image
        side = _wood_side(p0, p1, origin, right, up, forward, focal)
        perp = normalized(np.column_stack([-(v1 - v0), u1 - u0]) + np.array([1e-12, 0.0]))[j]
        lateral = np.clip(np.sum((offset - t[:, None] * (a1 - a0)) * perp, axis=1) / radius_px[j], -1, 1)
        facing_part = np.sqrt(1 - lateral**2)
        frag_depth[~is_leaf] = axis_z - radius[j] * facing_part
        toward, sideways = side
        n_w = facing_part[:, None] * toward[j] + lateral[:, None] * sideways[j]
        k = owner[j]
        axis_z = p0[j, 2] + t * (p1[j, 2] - p0[j, 2])  # height of the fragment's axis point [m]
        furrows = bark_pattern(n_w, p1[j] - p0[j], axis_z, radius_px[j])[:, None] * bark
        sky_w = (wood_exposure[k] * 0.5 * (1 + n_w[:, 2]))[:, None] * furrows * e_sky / np.pi
        sun_w = (wood_vis[k] * np.maximum(n_w @ s, 0.0))[:, None] * furrows * e_sun / np.pi
        frag_sky[~is_leaf] = sky_w
        frag_sun[~is_leaf] = sky_w + sun_w

    if ground_height is not None:
        ray_z = forward[2] + ((pu - 0.5 * cols) / focal) * right[2] + ((0.5 * rows - pv) / focal) * up[2]
        above = origin[2] + frag_depth * ray_z >= ground_height
        flat, coverage, frag_depth, frag_sun, frag_sky = (
            x[above] for x in (flat, coverage, frag_depth, frag_sun, frag_sky))
    weight = _front_to_back(flat, frag_depth, coverage)
    haze_image = None
    if haze > 0:
        ray = np.sqrt(1.0 + ((pu - 0.5 * cols) / focal) ** 2 + ((0.5 * rows - pv) / focal) ** 2)
        if ground_height is not None:
            ray = ray[above]
        transmittance = np.exp(-frag_depth * ray / haze)  # frag_depth is along forward
        frag_sun = frag_sun * transmittance[:, None]
        frag_sky = frag_sky * transmittance[:, None]
        haze_image = np.bincount(flat, weights=weight * (1.0 - transmittance),
                                 minlength=rows * cols).reshape(rows, cols).astype(np.float32)
    optical = np.bincount(flat, weights=-np.log1p(-coverage.astype(np.float64)), minlength=rows * cols)
    alpha = -np.expm1(-optical).reshape(rows, cols)
    sun_image, sky_image = (image.reshape(rows, cols, 3) for image in _raster.scatter_light(
        flat, weight, np.ascontiguousarray(frag_sun), np.ascontiguousarray(frag_sky), rows * cols))
    return ForegroundPasses(sun_image.astype(np.float32), sky_image.astype(np.float32),
                            alpha.astype(np.float32), haze_image)


def _leaf_fragments_arrays(flat, shape, leaves, cols, rows, focal, n_forward, n_right, n_up, n_rel, nearest,
                           farthest, leaf_sky, leaf_sun, frag_depth, frag_sun, frag_sky) -> None:
    """``_raster.leaf_fragments`` on arrays: its reference (tests/test_foreground.py)."""
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


def stem_visibility(leaves: Leaves, stems: Wood, *, sun_point, pixel: float | None = None):
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
    stems : grove_geometry.Wood
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


def _rgb(value, name) -> np.ndarray:
    value = np.asarray(value, dtype=np.float64)
    if value.shape not in ((), (3,)):
        raise ValueError(f"{name} must be a number or 3 numbers (RGB), got shape {value.shape}")
    if not np.all(np.isfinite(value)) or np.any(value < 0):
        raise ValueError(f"{name} must be finite and not negative, got {value}")
    return np.broadcast_to(value, (3,)).copy()


def _per_shape(value, n, name) -> np.ndarray:
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
