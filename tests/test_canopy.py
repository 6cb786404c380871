import numpy as np
import pytest
from reference import image_transmittance

from pipeline.canopy.grove import (
    FlutterParams,
    GroveParams,
    Leaves,
    Shapes,
    Wood,
    grove_bounds,
    grow_grove,
    layer_index,
    leaves_at,
    project,
    shapes_bounds,
)
from pipeline.canopy.masks import occlusion_on_lattice, tile_on_lattice, transmittance_from_image
from pipeline.canopy.rasteriser import (
    _capsule_pieces,
    _ellipses,
    _translates,
    coverage_fragments,
    grove_mask,
    rasterize_transmittance,
)
from pipeline.core.geometry import Grid


def supersampled(f, grid, n=64):
    """Mean of f(x, y) [m] over each pixel of a grid, by n x n point samples."""
    rows, cols = grid.shape
    sub = (np.arange(n) + 0.5) / n - 0.5
    r = np.arange(rows)[:, None, None, None] + sub[None, None, :, None]
    c = np.arange(cols)[None, :, None, None] + sub[None, None, None, :]
    x, y = grid.ground_from_raster(r, c)
    return f(x, y).mean(axis=(2, 3))


def test_transmittance_from_image_channels_and_range():
    grey = np.full((2, 3, 1), 0.25, np.float32)
    assert np.allclose(transmittance_from_image(grey), 0.25)
    rgb = np.zeros((2, 3, 4), np.float32)
    rgb[..., 1] = 1.0  # pure green, alpha 0 ignored
    assert np.allclose(transmittance_from_image(rgb), 0.7152)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        transmittance_from_image(np.full((2, 2, 1), 2.0, np.float32))
    with pytest.raises(ValueError, match="finite"):
        transmittance_from_image(np.full((2, 2, 1), np.nan, np.float32))


def test_isolated_mask_is_area_averaged_onto_the_lattice():
    rng = np.random.default_rng(3)
    mask = (rng.random((37, 23)) > 0.5).astype(np.float32)
    center, size = (0.13, -0.41), (2.3, 3.7)  # texels 0.1 m, lattice 0.07 m, not aligned
    lattice = Grid.from_window((-3.0, -3.0, 3.0, 3.0), 0.07)
    occlusion, grid = occlusion_on_lattice(mask, center=center, size=size, lattice=lattice)
    # the grid covers the mask and sits on the lattice
    x0, y0, x1, y1 = grid.extent
    assert x0 <= center[0] - size[0] / 2 and x1 >= center[0] + size[0] / 2
    assert y0 <= center[1] - size[1] / 2 and y1 >= center[1] + size[1] / 2
    f = image_transmittance(mask, center=center, size=size, outside=1.0)
    reference = 1.0 - supersampled(f, grid)
    error = np.abs(occlusion - reference)  # the reference's point sampling errs ~1/64 per edge
    assert error.mean() < 0.004 and error.max() < 2.5 / 64
    # the occluded area is kept exactly
    texel_area = size[0] * size[1] / mask.size
    assert occlusion.sum() * 0.07**2 == pytest.approx((1 - mask).sum() * texel_area, rel=1e-5)


def test_periodic_tile_wraps_and_keeps_the_mean():
    rng = np.random.default_rng(4)
    mask = rng.random((16, 24)).astype(np.float32)
    center, size = (0.37, -0.12), (2.4, 1.6)  # 30 x 20 lattice pixels of 0.08 m
    lattice = Grid.from_window((-1.0, -1.0, 1.0, 1.0), 0.08)
    tile, grid = tile_on_lattice(mask, center=center, size=size, lattice=lattice)
    assert tile.shape == (20, 30)
    assert tile.mean() == pytest.approx(mask.mean(), rel=1e-5)
    f = image_transmittance(mask, center=center, size=size, periodic=True)
    error = np.abs(tile - supersampled(f, grid))
    assert error.mean() < 0.004 and error.max() < 2.5 / 64


# --- procedural grove, flutter, projection and anti-aliased rasterization -----------------------


NO_WOOD = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))


def inside_ellipse(center, a, b):
    """f(x, y) [m] -> 1 inside the ellipse {center + a u + b v : u^2 + v^2 < 1} (solved by Cramer's rule)."""
    det = a[0] * b[1] - a[1] * b[0]

    def f(x, y):
        dx, dy = x - center[0], y - center[1]
        u, v = b[1] * dx - b[0] * dy, a[0] * dy - a[1] * dx  # det * (u, v)
        return (u * u + v * v < det * det).astype(np.float64)

    return f


def inside_capsule(p0, p1, radius):
    """f(x, y) [m] -> 1 within ``radius`` of the segment p0 p1 (inside the disc of either end or
    the rectangle between them)."""
    ex, ey = p1[0] - p0[0], p1[1] - p0[1]
    length = np.hypot(ex, ey)

    def f(x, y):
        along = ((x - p0[0]) * ex + (y - p0[1]) * ey) / length
        across = ((x - p0[0]) * ey - (y - p0[1]) * ex) / length
        ends = np.minimum(np.hypot(x - p0[0], y - p0[1]), np.hypot(x - p1[0], y - p1[1]))
        return ((ends < radius) | ((np.abs(across) < radius) & (along > 0) & (along < length))).astype(np.float64)

    return f


def reference_transmittance(shapes, grid, n=16):
    """Product over shapes of (1 - coverage), each coverage by n x n point samples per pixel."""
    t = np.ones(grid.shape)
    for c, a, b in zip(shapes.center, shapes.axis_a, shapes.axis_b):
        t *= 1 - supersampled(inside_ellipse(c, a, b), grid, n)
    for p0, p1, r in zip(shapes.start, shapes.end, shapes.radius):
        t *= 1 - supersampled(inside_capsule(p0, p1, r), grid, n)
    return t


def box_pixels(shapes, grid):
    """Boolean raster of the pixels that meet any shape's bounding box."""
    half = np.sqrt(shapes.axis_a**2 + shapes.axis_b**2)
    low = np.concatenate([shapes.center - half, np.minimum(shapes.start, shapes.end) - shapes.radius[:, None]])
    high = np.concatenate([shapes.center + half, np.maximum(shapes.start, shapes.end) + shapes.radius[:, None]])
    x0, _y0, _x1, y1 = grid.extent
    out = np.zeros(grid.shape, bool)
    for (xa, ya), (xb, yb) in zip(low, high):
        c0, c1 = int(np.floor((xa - x0) / grid.pixel)), int(np.ceil((xb - x0) / grid.pixel))
        r0, r1 = int(np.floor((y1 - yb) / grid.pixel)), int(np.ceil((y1 - ya) / grid.pixel))
        out[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = True
    return out


def random_shapes(rng, n_ellipses, n_capsules, *, low, high, scale):
    """Ellipses of random size (0.05 to 1 x scale [m]), aspect (including needles and one exactly
    degenerate), skewed conjugate axes; capsules of random length and radius."""
    n = n_ellipses
    length = scale * np.exp(rng.uniform(np.log(0.05), 0.0, n))
    angle = rng.uniform(0, np.pi, n)
    aspect = rng.uniform(0, 1, n)
    aspect[:4] = [0.0, 1e-3, 0.02, 0.1]
    u = np.column_stack([np.cos(angle), np.sin(angle)])
    v = np.column_stack([-np.sin(angle), np.cos(angle)]) + rng.uniform(-0.5, 0.5, (n, 1)) * u
    start = rng.uniform(low, high, (n_capsules, 2))
    end = start + rng.normal(0, 0.8 * scale, (n_capsules, 2))
    end[0] = start[0] + [2.5 * scale, 1.1 * scale]  # long enough to be cut into pieces
    radius = scale * np.exp(rng.uniform(np.log(0.01), np.log(0.3), n_capsules))
    radius[0] = 0.03 * scale
    return Shapes(rng.uniform(low, high, (n, 2)), length[:, None] * u, (length * aspect)[:, None] * v,
                  start, end, radius)


def test_flutter_is_periodic_and_the_grove_deterministic():
    params = GroveParams(count=2, leaves_per_tree=300, seed=11)
    grove = grow_grove(params)
    flutter = FlutterParams(cycle=12, swing=0.3, twist=0.5)
    rest = leaves_at(grove, flutter, 0)
    for later in (flutter.cycle, -flutter.cycle, 5 * flutter.cycle):
        again = leaves_at(grove, flutter, later)
        for field in ("center", "axis_u", "axis_v"):
            assert np.allclose(getattr(again, field), getattr(rest, field), rtol=0, atol=1e-12)
    moved = leaves_at(grove, flutter, 1)
    assert np.abs(moved.axis_v - rest.axis_v).max() > 1e-3
    assert np.abs(moved.center - rest.center).max() > 1e-3
    # the leaf keeps its shape and its stem
    assert np.allclose(np.linalg.norm(moved.axis_u, axis=1), np.linalg.norm(rest.axis_u, axis=1))
    assert np.allclose(np.sum(moved.axis_u * moved.axis_v, axis=1), 0, atol=1e-15)
    assert np.allclose(moved.center - moved.axis_u, grove.pivot)
    # deterministic from the seed, different for another seed
    twin, other = grow_grove(params), grow_grove(GroveParams(count=2, leaves_per_tree=300, seed=12))
    assert np.array_equal(twin.leaves.center, grove.leaves.center)
    assert np.array_equal(twin.wood.end, grove.wood.end)
    assert not np.allclose(other.leaves.center, grove.leaves.center)
    # the bounds hold for every frame of the cycle
    sun = (0.4, -0.7)
    x0, y0, x1, y1 = grove_bounds(grove, flutter, sun=sun, plane_height=params.height)
    for frame in range(flutter.cycle):
        shapes = project(leaves_at(grove, flutter, frame), grove.wood, sun=sun, plane_height=params.height)
        a0, b0, a1, b1 = shapes_bounds(shapes)
        assert x0 <= a0 and y0 <= b0 and a1 <= x1 and b1 <= y1
    # a periodic grove lies in its tile
    tiled = grow_grove(GroveParams(count=4, leaves_per_tree=200, layout="periodic", tile=10.0, center=(1.0, 2.0)))
    assert np.all(np.abs(tiled.leaves.center[:, :2] - [1.0, 2.0]) <= 5.0)
    assert np.all(np.abs(tiled.wood.start[:, :2] - [1.0, 2.0]) <= 5.0)


@pytest.mark.parametrize("seed, scale", [(0, 1.0), (1, 0.3), (2, 0.1)])
def test_coverage_matches_supersampling(seed, scale):
    grid = Grid((0.0, 4.0), 0.1, (40, 40))
    shapes = random_shapes(np.random.default_rng(seed), 24, 6, low=-0.3, high=4.3, scale=scale)
    mask = rasterize_transmittance(shapes, grid)
    assert mask.dtype == np.float32 and mask.shape == grid.shape
    reference = reference_transmittance(shapes, grid)
    near = box_pixels(shapes, grid)
    assert np.abs(mask - reference)[near].mean() <= 0.01
    assert np.all(mask[~near] == 1.0)


def test_periodic_raster_wraps_every_translate():
    rng = np.random.default_rng(5)
    period = (3.2, 2.4)
    tile = Grid((0.0, 2.4), 0.1, (24, 32))
    shapes = random_shapes(rng, 12, 3, low=-0.5, high=3.0, scale=0.5)
    shapes = Shapes(np.vstack([shapes.center, [[3.15, 1.2]]]), np.vstack([shapes.axis_a, [[0.3, 0.0]]]),
                    np.vstack([shapes.axis_b, [[0.0, 0.2]]]), shapes.start, shapes.end, shapes.radius)
    shifts = [(i * period[0], j * period[1]) for i in range(-3, 4) for j in range(-3, 4)]

    def translates(s):
        def cat(v, sh=True):
            return np.concatenate([v + (np.array(d) if sh else 0) for d in shifts])
        return Shapes(cat(s.center), cat(s.axis_a, False), cat(s.axis_b, False),
                      cat(s.start), cat(s.end), np.tile(s.radius, len(shifts)))

    wrapped = rasterize_transmittance(shapes, tile, period=period)
    assert np.allclose(wrapped, rasterize_transmittance(translates(shapes), tile), atol=1e-5)
    # the ellipse across the east edge (x = 3.2) shows on the west side too
    row = int((2.4 - 1.2) / 0.1)
    assert wrapped[row, 0] < 0.01 and wrapped[row, -1] < 0.01
    # an arbitrary window larger than a period, not aligned with it
    window = Grid((-2.03, 3.71), 0.07, (90, 110))
    assert np.allclose(rasterize_transmittance(shapes, window, period=period),
                       rasterize_transmittance(translates(shapes), window), atol=1e-5)


@pytest.mark.parametrize("dz", [0.4, -0.3])
def test_projection_moves_leaves_away_from_the_sun(dz):
    height, zenith, azimuth = 6.0, np.radians(35.0), np.radians(110.0)
    towards_sun = np.array([np.sin(azimuth), np.cos(azimuth)])  # east, north
    sun = np.tan(zenith) * towards_sun
    leaf_centre = np.array([0.3, -0.2, height + dz])
    leaves = Leaves(leaf_centre[None], np.array([[0.05, 0.0, 0.02]]), np.array([[0.0, 0.03, 0.0]]))
    grid = Grid((-0.4, 0.5), 0.005, (200, 240))
    mask = rasterize_transmittance(project(leaves, sun=sun, plane_height=height), grid)
    occlusion = 1.0 - mask.astype(np.float64)
    x, y = grid.ground_from_raster(*np.indices(grid.shape))
    centroid = np.array([(occlusion * x).sum(), (occlusion * y).sum()]) / occlusion.sum()
    # the ray towards the sun from the ground point behind the centroid passes through the leaf
    ground = centroid - height * np.tan(zenith) * towards_sun
    w = np.array([np.sin(zenith) * towards_sun[0], np.sin(zenith) * towards_sun[1], np.cos(zenith)])
    hit = np.append(ground, 0.0) + w * (height + dz) / np.cos(zenith)
    assert np.allclose(hit, leaf_centre, atol=1e-3)
    shift = centroid - leaf_centre[:2]
    assert np.dot(shift, towards_sun) == pytest.approx(-dz * np.tan(zenith), abs=1e-3)
    # wood: an upright trunk keeps its radius, a branch across the sun widens by 1 / cos(zenith)
    across = np.array([towards_sun[1], -towards_sun[0], 0.0])
    wood = Wood(np.array([[0, 0, 0], [0, 0, height]]), np.array([[0, 0, height], [0, 0, height] + across]),
                np.array([0.2, 0.1]))
    shapes = project(leaves, wood, sun=sun, plane_height=height)
    assert np.allclose(shapes.radius, [0.2, 0.1 / np.cos(zenith)])


@pytest.mark.parametrize("zenith, azimuth", [(0.0, 0.0), (np.radians(50.0), np.radians(250.0))])
def test_sparse_grove_transmittance_is_one_minus_projected_leaf_area(zenith, azimuth):
    # leaves scattered one by one over the crown's shell: they rarely overlap (about 1 % of their area)
    grove = grow_grove(GroveParams(count=1, leaves_per_tree=200, crown_radius=3.0, leaf_length=0.1,
                                   leaves_per_cluster=1, seed=3))
    flutter = FlutterParams()
    height = grove.params.height
    w = np.array([np.sin(zenith) * np.sin(azimuth), np.sin(zenith) * np.cos(azimuth), np.cos(zenith)])
    sun = w[:2] / w[2]
    x0, y0, x1, y1 = grove_bounds(grove, flutter, sun=sun, plane_height=height)
    grid = Grid.from_window((x0 - 0.1, y0 - 0.1, x1 + 0.1, y1 + 0.1), 0.01)
    mask = grove_mask(grove, flutter, 7, sun=sun, plane_height=height, grid=grid, select=(slice(None), []))
    leaves = leaves_at(grove, flutter, 7)
    # a flat leaf of area pi |U x V| seen along w covers pi |(U x V) . w| / w_z of a horizontal plane
    area = np.pi * np.abs(np.cross(leaves.axis_u, leaves.axis_v) @ w) / w[2]
    covered = area.sum() / (grid.shape[0] * grid.shape[1] * grid.pixel**2)
    assert 0.002 < covered < 0.05
    assert 1.0 - mask.mean(dtype=np.float64) == pytest.approx(covered, rel=0.02)


def test_layers_split_the_grove_by_nearest_plane():
    grove = grow_grove(GroveParams(count=2, leaves_per_tree=400, crown_radius=2.0, seed=5))
    heights = [7.2, 8.0, 8.5]
    leaf_layer, wood_layer = layer_index(grove, heights)
    for z, layer in [(grove.leaves.center[:, 2], leaf_layer),
                     (0.5 * (grove.wood.start + grove.wood.end)[:, 2], wood_layer)]:
        distance = np.abs(z[:, None] - np.array(heights)[None, :])
        assert np.all(distance[np.arange(len(z)), layer] <= distance.min(axis=1))
    assert set(leaf_layer) == {0, 1, 2} and wood_layer[0] == 0  # the trunk's foot goes lowest
    sun, flutter = (0.2, 0.3), FlutterParams()
    shapes = project(leaves_at(grove, flutter, 3), grove.wood, sun=sun, plane_height=8.0)
    parts = [shapes.subset(leaf_layer == i, wood_layer == i) for i in range(3)]
    assert sum(len(p.center) for p in parts) == len(shapes.center)
    assert sum(len(p.radius) for p in parts) == len(shapes.radius)
    assert np.array_equal(np.sort(np.concatenate([p.center for p in parts]), axis=0), np.sort(shapes.center, axis=0))
    # with the product rule the layers' masks multiply to the whole grove's
    grid = Grid.from_window(grove_bounds(grove, flutter, sun=sun, plane_height=8.0), 0.04)
    whole = grove_mask(grove, flutter, 3, sun=sun, plane_height=8.0, grid=grid)
    product = np.prod([grove_mask(grove, flutter, 3, sun=sun, plane_height=8.0, grid=grid,
                                  select=(leaf_layer == i, wood_layer == i)) for i in range(3)], axis=0)
    assert np.allclose(product, whole, atol=1e-5)


# --- the array rasteriser that the compiled one replaced, kept as its reference ------------------
# (the former pipeline/canopy.py before the loops moved to pipeline/kernels/raster.py, verbatim but for names; the
# shapes' preparation, _ellipses, _capsule_pieces and _translates, is shared)


_CHUNK = 1 << 17  # samples evaluated at once [count]
_OPAQUE = np.float32(1.0 - 2.0**-20)  # coverage clipped below 1 before -log(1 - c)
_BUCKETS = np.unique(np.ceil(np.outer(2.0 ** np.arange(20), [1.0, 1.25, 1.5, 1.75]))).astype(np.int64)


def reference_rasterize(shapes, grid, *, period=None):
    """Transmittance of ``shapes`` on ``grid`` by the former array rasteriser."""
    rows, cols = grid.shape
    period_px = None if period is None else np.asarray(period, dtype=np.float64) / grid.pixel
    out = []
    (*ellipses, owner), (*capsules, source) = _ellipses(shapes, grid), _capsule_pieces(shapes, grid)
    for primitive in ((*ellipses, _ellipse_distance, None, owner),
                      (*capsules, _capsule_distance, _capsule_select, source)):
        _reference_scatter(*primitive, shape=grid.shape, period=period_px, out=out)
    flat = np.concatenate([f for f, _, _ in out]) if out else np.zeros(0, np.int64)
    weight = np.concatenate([w for _, w, _ in out]) if out else np.zeros(0, np.float32)
    optical = np.bincount(flat, weights=weight, minlength=(rows + 1) * (cols + 1))
    return np.exp(-optical).reshape(rows + 1, cols + 1)[:rows, :cols].astype(np.float32)


def _ellipse_distance(dx, dy, prm):
    """Approximate signed distance (g - 1) / |grad g| to an ellipse boundary, g the ellipse's
    gauge (exact for circles, finite for needles), and the outward unit normal. [pixel]"""
    ex, ey, major, minor = prm
    p, q = dx * ex + dy * ey, dy * ex - dx * ey
    bp, aq = minor * minor * p, major * major * q
    gauge = np.sqrt(np.square(minor * p) + np.square(major * q))  # A B g
    grad = np.sqrt(bp * bp + aq * aq) + 1e-3 * minor * minor
    distance = (gauge - major * minor) * (gauge + 1e-3 * minor) / grad
    return distance, (bp * ex - aq * ey) / grad, (bp * ey + aq * ex) / grad


def _capsule_distance(dx, dy, prm):
    """Exact signed distance to a capsule and the outward unit normal. [pixel]"""
    x0, y0, ex, ey, inverse, radius = prm[:6]
    rx, ry = dx - x0, dy - y0
    t = np.clip((rx * ex + ry * ey) * inverse, 0, 1)
    qx, qy = rx - t * ex, ry - t * ey
    length = np.sqrt(qx * qx + qy * qy) + 1e-6
    return length - radius, qx / length, qy / length


def _capsule_select(dx, dy, prm):
    """1 where a pixel centre projects onto the piece's stretch [t_lo, t_hi) of the axis."""
    x0, y0, ex, ey, inverse, _, t_lo, t_hi = prm
    t = ((dx - x0) * ex + (dy - y0) * ey) * inverse
    return (t >= t_lo) & (t < t_hi)


def _square_cdf(t, a, b):
    """Fraction of a unit square (centred on 0) where n . u <= t, |n| = 1, a = max(|nx|, |ny|),
    b = min(|nx|, |ny|): the CDF of a trapezoid. [dimensionless]"""
    s = np.abs(t)
    tail = np.where(s <= 0.5 * (a - b), 0.5 - s / a,
                    np.square(np.maximum(0.5 * (a + b) - s, 0)) / (2 * a * b + 1e-12))
    return np.where(t < 0, tail, 1 - tail)


def _reference_scatter(center, half, params, feature, thickness, distance, select, owner, *, shape, period, out,
             offset=None):
    """Append (flat index in a (rows + 1, cols + 1) raster, -log(1 - coverage), label) of every
    pixel of every shape's clipped box to ``out``; row ``rows`` and column ``cols`` collect
    padding. The label is None, or with an ``offset`` the fragment's shape index ``offset + owner``."""
    rows, cols = shape
    source = None if offset is None else offset + owner
    if period is not None:
        src, center = _translates(center, half, period, shape)
        half, params, feature, thickness = half[src], params[src], feature[src], thickness[src]
        source = None if source is None else source[src]
    lo = np.clip(np.floor(center - half), 0, [cols, rows]).astype(np.int64)
    hi = np.clip(np.ceil(center + half), 0, [cols, rows]).astype(np.int64)
    keep = np.all(hi > lo, axis=1)
    center, lo, size = center[keep], lo[keep], (hi - lo)[keep]
    params, feature, thickness = params[keep], feature[keep], thickness[keep]
    source = None if source is None else source[keep]
    if not len(center):
        return
    # k x k sub-samples: k = 1 for shapes at least 2.5 pixels thick (minor semi-axis or radius),
    # 2 down to 0.8 pixel, 4 below; thin shapes get the second edge of their strip
    sub = np.where(feature >= 2.5, 1, np.where(feature >= 0.8, 2, 4))
    area = size.prod(axis=1)  # and fewer for huge boxes, to bound the memory of one block
    sub = np.where(area * sub**2 > 16 * _CHUNK, np.where(area * 4 > 16 * _CHUNK, 1, 2), sub)
    thin = thickness * sub < 1.5
    block = _BUCKETS[np.minimum(np.searchsorted(_BUCKETS, size), len(_BUCKETS) - 1)]
    block = np.maximum(block, size)
    key = ((block[:, 1] * (1 << 20) + block[:, 0]) * 8 + sub) * 2 + thin
    order = np.argsort(key, kind="stable")
    starts = np.flatnonzero(np.diff(key[order], prepend=-1))
    for group in np.split(order, starts[1:]):
        w, h = block[group[0]]
        k = int(sub[group[0]])
        step = max(1, _CHUNK // (int(w) * int(h) * k * k))
        for j in range(0, len(group), step):
            idx = group[j:j + step]
            rel = (center[idx] - lo[idx]).astype(np.float32)
            prm = [c[:, None, None] for c in params[idx].astype(np.float32).T]
            xs = ((np.arange(w * k, dtype=np.float32) + 0.5) / k)[None, None, :] - rel[:, 0, None, None]
            ys = ((np.arange(h * k, dtype=np.float32) + 0.5) / k)[None, :, None] - rel[:, 1, None, None]
            d, nx, ny = distance(xs, ys, prm)
            nx, ny = np.abs(nx), np.abs(ny)
            a, b = np.maximum(np.maximum(nx, ny), np.float32(0.7071), dtype=np.float32), np.minimum(nx, ny)
            t = d * np.float32(-k)
            cover = _square_cdf(t, a, b)
            if thin[group[0]]:
                cover -= _square_cdf(t - (thickness[idx] * k).astype(np.float32)[:, None, None], a, b)
            if k > 1:
                cover = cover.reshape(len(idx), h, k, w, k).mean(axis=(2, 4))
            if select is not None:  # judged at pixel centres
                cover = cover * select(np.arange(w) + 0.5 - rel[:, 0, None, None],
                                       (np.arange(h) + 0.5)[:, None] - rel[:, 1, None, None], prm)
            weight = -np.log1p(-np.clip(cover, 0, _OPAQUE))
            r = np.where(np.arange(h) < size[idx, 1, None], lo[idx, 1, None] + np.arange(h), rows)
            c = np.where(np.arange(w) < size[idx, 0, None], lo[idx, 0, None] + np.arange(w), cols)
            label = None if source is None else np.repeat(source[idx], h * w)
            out.append(((r[:, :, None] * (cols + 1) + c[:, None, :]).ravel(), weight.ravel(), label))


def random_leaves(rng, n, *, low, high, pixel):
    """Leaf-like ellipses of every size the renders meet: semi-axes from a tenth of a pixel to
    eight pixels, aspects 0.02 to 1, skewed conjugate axes [m]."""
    length = pixel * np.exp(rng.uniform(np.log(0.1), np.log(8.0), n))
    angle = rng.uniform(0, np.pi, n)
    u = np.column_stack([np.cos(angle), np.sin(angle)])
    v = np.column_stack([-np.sin(angle), np.cos(angle)]) + rng.uniform(-0.5, 0.5, (n, 1)) * u
    aspect = rng.uniform(0.02, 1.0, n)
    return Shapes(rng.uniform(low, high, (n, 2)), length[:, None] * u, (length * aspect)[:, None] * v,
                  *NO_WOOD)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_rasteriser_matches_the_array_one_shape_by_shape(seed):
    # each shape alone: its coverage 1 - t of every pixel within 1e-3 of the pixel's area
    rng = np.random.default_rng(seed)
    grid = Grid((0.0, 3.0), 0.1, (30, 30))
    shapes = [random_leaves(rng, 60, low=-0.2, high=3.2, pixel=0.1),
              random_shapes(rng, 24, 8, low=-0.3, high=3.3, scale=0.6)]
    for group in shapes:
        for i in range(len(group.center)):
            one = group.subset(leaves=[i], wood=[])
            assert np.abs(rasterize_transmittance(one, grid) - reference_rasterize(one, grid)).max() <= 1e-3
        for j in range(len(group.radius)):
            one = group.subset(leaves=[], wood=[j])
            assert np.abs(rasterize_transmittance(one, grid) - reference_rasterize(one, grid)).max() <= 1e-3


def leaves_and_wood(rng, count: int) -> Shapes:
    """``count`` random leaves over about 5 m and 12 random capsule pieces among them."""
    leaves = random_leaves(rng, count, low=-0.5, high=4.5, pixel=0.04)
    wood = random_shapes(rng, 4, 12, low=0.0, high=4.0, scale=0.5)
    return Shapes(leaves.center, leaves.axis_a, leaves.axis_b, wood.start, wood.end, wood.radius)


@pytest.mark.parametrize("period", [None, (2.3, 1.7)])
def test_compiled_rasteriser_matches_the_array_one_on_many_leaves(period):
    shapes = leaves_and_wood(np.random.default_rng(9), 4000)
    for grid in (Grid((0.0, 4.0), 0.04, (100, 100)), Grid((-1.13, 5.21), 0.031, (170, 190))):
        new = rasterize_transmittance(shapes, grid, period=period)
        old = reference_rasterize(shapes, grid, period=period)
        assert new.dtype == np.float32 and new.shape == grid.shape
        assert np.abs(new - old).max() <= 1e-3
        assert np.abs(new - old).mean() <= 1e-6  # the same arithmetic: rounding apart


def test_compiled_rasteriser_matches_the_array_one_on_a_grove():
    grove = grow_grove(GroveParams(count=2, leaves_per_tree=3000, crown_radius=2.0, seed=4))
    flutter, sun = FlutterParams(), (0.3, -0.2)
    shapes = project(leaves_at(grove, flutter, 5), grove.wood, sun=sun, plane_height=grove.params.height)
    for pixel in (0.05, 0.012):  # a coarse mask (thin leaves, 4 x 4 sub-samples) and a fine one
        grid = Grid.from_window(grove_bounds(grove, flutter, sun=sun, plane_height=grove.params.height), pixel)
        new, old = rasterize_transmittance(shapes, grid), reference_rasterize(shapes, grid)
        assert np.abs(new - old).max() <= 1e-3


def reference_fragments(shapes, grid, *, period=None):
    """coverage_fragments by the former array rasteriser: (pixel, coverage, shape)."""
    rows, cols = grid.shape
    period_px = None if period is None else np.asarray(period, dtype=np.float64) / grid.pixel
    out = []
    (*ellipses, owner), (*capsules, source) = _ellipses(shapes, grid), _capsule_pieces(shapes, grid)
    for primitive, offset in (((*ellipses, _ellipse_distance, None, owner), 0),
                              ((*capsules, _capsule_distance, _capsule_select, source), len(shapes.center))):
        _reference_scatter(*primitive, shape=grid.shape, period=period_px, out=out, offset=offset)
    flat = np.concatenate([f for f, _, _ in out])
    weight = np.concatenate([w for _, w, _ in out])
    label = np.concatenate([s for _, _, s in out])
    row, col = np.divmod(flat, cols + 1)
    keep = (row < rows) & (col < cols) & (weight > 0)
    return row[keep] * cols + col[keep], (-np.expm1(-weight[keep])).astype(np.float32), label[keep]


@pytest.mark.parametrize("period", [None, (2.3, 1.7)])
def test_coverage_fragments_match_the_array_rasteriser(period):
    shapes = leaves_and_wood(np.random.default_rng(12), 1500)
    grid = Grid((-0.13, 4.21), 0.037, (120, 110))
    pixel, coverage, shape = coverage_fragments(shapes, grid, period=period)
    assert pixel.dtype == np.int64 and coverage.dtype == np.float32 and shape.dtype == np.int64
    assert np.all((coverage > 0) & (coverage < 1)) and np.all((pixel >= 0) & (pixel < 120 * 110))
    ref_pixel, ref_coverage, ref_shape = reference_fragments(shapes, grid, period=period)
    cells = grid.shape[0] * grid.shape[1]
    key, ref_key = shape * cells + pixel, ref_shape * cells + ref_pixel
    if period is None:  # one fragment per shape and pixel
        assert len(np.unique(key)) == len(key)
    union = np.union1d(key, ref_key)
    new = np.bincount(np.searchsorted(union, key), weights=coverage, minlength=len(union))
    old = np.bincount(np.searchsorted(union, ref_key), weights=ref_coverage, minlength=len(union))
    assert np.abs(new - old).max() <= 1e-3
    # the fragments multiply to the transmittance
    product = np.ones(cells)
    np.multiply.at(product, pixel, 1.0 - coverage.astype(np.float64))
    assert np.allclose(product.reshape(grid.shape), rasterize_transmittance(shapes, grid, period=period), atol=1e-6)
