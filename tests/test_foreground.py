import numpy as np
import pytest

from pipeline.camera.pinhole import Camera, project_points
from pipeline.canopy import grove as grove_geometry
from pipeline.canopy.grove import Leaves, Wood
from pipeline.core.io import ImageError, write_exr
from pipeline.foreground import trees as foreground
from pipeline.foreground.passes import ForegroundPasses, check_passes_size, read_passes
from pipeline.foreground.tree_detail import TIP_TAPER, taper_wood
from pipeline.foreground.trees import (
    LEAF_REFLECTANCE,
    LEAF_TRANSMITTANCE,
    leaf_sun_visibility,
    sky_exposure,
    stem_visibility,
    sun_visibility,
    tree_passes,
)
from pipeline.kernels import raster as _raster

E_SUN = np.array([90.0, 85.0, 80.0])  # [klx]
E_SKY = np.array([10.0, 12.0, 16.0])  # [klx]
NO_WOOD = Wood(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


def north_camera(width=80, height=60, fov_deg=40.0):
    """At the origin looking north, level: right = east, up = +z."""
    return Camera((0.0, 0.0, 0.0), 0.0, 0.0, np.radians(fov_deg), width, height)


def discs(centers, radii):
    """Discs facing the camera of ``north_camera`` (in vertical planes y = const)."""
    centers = np.asarray(centers, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)[:, None]
    return Leaves(centers, r * [1.0, 0.0, 0.0], r * [0.0, 0.0, 1.0])


def render(leaves, camera, *, wood=NO_WOOD, sun=(0.0, -1.0, 0.0), **kw):
    kw.setdefault("leaf_sun_visibility", np.ones(len(leaves.center)))
    kw.setdefault("wood_sun_visibility", np.ones(len(wood.radius)))
    kw.setdefault("ground_height", None)  # the camera stands at z = 0
    return tree_passes(leaves, wood, camera, sun_direction=np.asarray(sun) / np.linalg.norm(sun),
                       sun_irradiance=E_SUN, sky_irradiance=E_SKY, **kw)


def test_a_disc_facing_the_camera_covers_its_projected_area_where_projected():
    camera = north_camera()
    center, radius = np.array([0.31, 6.0, -0.17]), 0.42
    passes = render(discs([center], [radius]), camera)
    assert passes.alpha.dtype == np.float32 and passes.alpha.shape == (60, 80)
    assert passes.sun.dtype == np.float32 and passes.sun.shape == (60, 80, 3)
    # a plane parallel to the image projects exactly: a circle of radius focal r / depth
    expected = np.pi * (camera.focal * radius / center[1]) ** 2
    assert passes.alpha.sum() == pytest.approx(expected, rel=0.01)
    u, v, _depth = project_points(camera, center)
    rows, cols = np.mgrid[0:60, 0:80] + 0.5
    total = passes.alpha.sum()
    assert np.sum(passes.alpha * cols) / total == pytest.approx(u, abs=0.02)
    assert np.sum(passes.alpha * rows) / total == pytest.approx(v, abs=0.02)


def test_alpha_is_zero_off_the_leaves_and_one_inside_an_opaque_disc():
    camera = north_camera()
    passes = render(discs([[0.0, 5.0, 0.0]], [1.0]), camera)
    u, v, _ = project_points(camera, [0.0, 5.0, 0.0])
    r_px = camera.focal * 1.0 / 5.0
    rows, cols = np.mgrid[0:60, 0:80] + 0.5
    distance = np.hypot(cols - u, rows - v)
    inside, outside = distance < r_px - 1, distance > r_px + 1
    assert inside.sum() > 500 and outside.sum() > 500
    assert np.all(np.abs(passes.alpha[inside] - 1) < 1e-3)
    assert np.all(passes.alpha[outside] == 0) and np.all(passes.sun[outside] == 0)
    assert np.all(passes.sky[outside] == 0)
    edge = ~inside & ~outside
    assert np.any((passes.alpha[edge] > 0.05) & (passes.alpha[edge] < 0.95))  # anti-aliased


@pytest.mark.parametrize("near_first", [True, False])
def test_the_nearer_leaf_shows_in_the_overlap_whatever_the_input_order(near_first):
    camera = north_camera()
    # a bright disc (full sky exposure) in front of a black one (none), overlapping
    centers, radii, exposure = [[-0.3, 4.0, 0.0], [0.4, 7.0, 0.0]], [0.6, 1.0], [1.0, 0.0]
    order = [0, 1] if near_first else [1, 0]
    leaves = discs(np.take(centers, order, axis=0), np.take(radii, order))
    passes = render(leaves, camera, leaf_sky_exposure=np.take(exposure, order))
    u_near, v_near, _ = project_points(camera, centers[0])
    u_far, v_far, _ = project_points(camera, centers[1])
    bright = passes.sky[int(v_near), int(u_near)]
    expected = np.asarray(E_SKY) / np.pi * 0.5 * (np.asarray(LEAF_REFLECTANCE) + LEAF_TRANSMITTANCE)
    assert np.allclose(bright, expected, rtol=1e-4)
    # the overlap: inside both discs, nearer to the far disc's centre than the near one's edge
    rows, cols = np.mgrid[0:60, 0:80] + 0.5
    in_near = np.hypot(cols - u_near, rows - v_near) < camera.focal * 0.6 / 4.0 - 1
    in_far = np.hypot(cols - u_far, rows - v_far) < camera.focal * 1.0 / 7.0 - 1
    overlap = in_near & in_far
    assert overlap.sum() > 20
    assert np.allclose(passes.sky[overlap], expected, rtol=1e-4)
    assert np.all(passes.sky[in_far & ~in_near & (np.hypot(cols - u_near, rows - v_near) > 20)] < 1e-6)


def test_sun_term_reflects_on_the_lit_side_and_shines_through_from_behind():
    camera = north_camera()
    leaves = discs([[0.0, 5.0, 0.0]], [1.0])  # normal along -y: facing the camera
    u, v, _ = project_points(camera, [0.0, 5.0, 0.0])
    pixel = (int(v), int(u))
    rho, tau = np.asarray(LEAF_REFLECTANCE), np.asarray(LEAF_TRANSMITTANCE)
    sky = 0.7 * E_SKY / np.pi * 0.5 * (rho + tau)  # default exposure, a vertical leaf
    angle = np.radians(50)
    front = np.array([0.0, -np.cos(angle), np.sin(angle)])  # from behind the camera, above
    lit = render(leaves, camera, sun=front, leaf_sun_visibility=np.array([0.8]))
    assert np.allclose(lit.sky[pixel], sky, rtol=1e-4)
    assert np.allclose(lit.sun[pixel] - lit.sky[pixel], 0.8 * np.cos(angle) * rho * E_SUN / np.pi, rtol=1e-4)
    back = np.array([0.0, np.cos(angle), np.sin(angle)])  # behind the leaf: translucency
    glow = render(leaves, camera, sun=back)
    assert np.allclose(glow.sky[pixel], sky, rtol=1e-4)
    assert np.allclose(glow.sun[pixel] - glow.sky[pixel], np.cos(angle) * tau * E_SUN / np.pi, rtol=1e-4)
    set_sun = render(leaves, camera, sun=[0.0, 1.0, -0.1])  # below the horizon: no sun term
    assert np.array_equal(set_sun.sun, set_sun.sky)
    assert np.allclose(set_sun.sky, lit.sky)


def test_wood_is_drawn_lit_on_the_sunny_side_and_hidden_behind_leaves():
    camera = north_camera(120, 90)
    trunk = Wood(np.array([[0.0, 8.0, -3.0]]), np.array([[0.0, 8.0, 3.0]]), np.array([0.3]))
    passes = render(Leaves(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))), camera, wood=trunk,
                    sun=[1.0, -0.2, 0.3])  # from the east (right), a little from the camera's side
    u, v, _ = project_points(camera, [0.0, 8.0, 0.0])
    r_px = camera.focal * 0.3 / 8.0
    row = int(v)
    assert passes.alpha[row, int(u)] > 0.999 and passes.alpha[row, int(u + r_px + 2)] == 0
    sun_part = (passes.sun - passes.sky)[row, :, 1]
    assert sun_part[int(u + 0.7 * r_px)] > sun_part[int(u)] > sun_part[int(u - 0.7 * r_px)] >= 0
    # a leaf in front of the trunk hides it
    leaf = discs([[0.0, 5.0, 0.0]], [0.5])
    both = render(leaf, camera, wood=trunk, sun=[1.0, -0.2, 0.3])
    alone = render(leaf, camera, sun=[1.0, -0.2, 0.3])
    assert np.allclose(both.sun[row, int(u)], alone.sun[row, int(u)], rtol=1e-4)


def test_the_ground_hides_what_lies_below_it():
    camera = north_camera(120, 90)
    trunk = Wood(np.array([[0.0, 8.0, -1.0]]), np.array([[0.0, 8.0, 1.0]]), np.array([0.3]))
    leaf = discs([[1.0, 8.0, -0.5]], [0.3])
    everything = render(leaf, camera, wood=trunk)
    above = render(leaf, camera, wood=trunk, ground_height=-0.4)
    _, v_ground, _ = project_points(camera, [0.0, 8.0, -0.4])
    rows = np.arange(90) + 0.5
    assert np.all(above.alpha[rows > v_ground + 0.5] == 0) and np.all(above.sun[rows > v_ground + 0.5] == 0)
    assert np.array_equal(above.alpha[rows < v_ground - 0.5], everything.alpha[rows < v_ground - 0.5])
    assert everything.alpha[rows > v_ground + 0.5].sum() > 100
    with pytest.raises(ValueError, match="above the ground"):
        render(leaf, camera, wood=trunk, ground_height=0.5)


def random_leaves(rng, n, *, spread, size):
    """n leaves of length ~2 size [m] with random orientations in a box of half-size ``spread``."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(u, rng.normal(size=(n, 3)))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    length = size * rng.uniform(0.7, 1.3, n)
    return Leaves(rng.uniform(-1, 1, (n, 3)) * spread, u * length[:, None],
                  v * (length * rng.uniform(0.5, 0.9, n))[:, None])


def monte_carlo_visibility(leaves, sun, rng, samples=4000):
    """Fraction of random points on each leaf whose ray towards the sun misses every other leaf,
    by exact ray-ellipse intersections in world coordinates."""
    s = np.asarray(sun, dtype=np.float64) / np.linalg.norm(sun)
    c, a, b = leaves.center, leaves.axis_u, leaves.axis_v
    normal = np.cross(a, b)
    out = []
    for i in range(len(c)):
        radius, angle = np.sqrt(rng.random(samples)), 2 * np.pi * rng.random(samples)
        points = c[i] + (radius * np.cos(angle))[:, None] * a[i] + (radius * np.sin(angle))[:, None] * b[i]
        blocked = np.zeros(samples, bool)
        for j in range(len(c)):
            if j == i:
                continue
            t = ((c[j] - points) @ normal[j]) / (s @ normal[j])
            hit = points + t[:, None] * s - c[j]
            alpha = hit @ a[j] / (a[j] @ a[j])
            beta = hit @ b[j] / (b[j] @ b[j])
            blocked |= (t > 0) & (alpha**2 + beta**2 <= 1)
        out.append(1 - blocked.mean())
    return np.array(out)


def test_leaf_sun_visibility_matches_rays_in_world_coordinates():
    rng = np.random.default_rng(5)
    leaves = random_leaves(rng, 24, spread=np.array([0.12, 0.12, 0.3]), size=0.06)
    sun_point = (0.35, -0.2)
    sun = np.array([*sun_point, 1.0])
    reference = monte_carlo_visibility(leaves, sun, np.random.default_rng(6))
    assert reference.min() < 0.5 and reference.max() == 1.0  # the leaves do shade each other
    fine = leaf_sun_visibility(leaves, None, sun_point=sun_point, pixel=0.004)
    assert fine.shape == (24,)
    assert np.abs(fine - reference).max() < 0.025 and np.abs(fine - reference).mean() < 0.006
    coarse = leaf_sun_visibility(leaves, None, sun_point=sun_point)  # a quarter of a leaf
    assert np.abs(coarse - reference).mean() < 0.05
    # the topmost leaf towards the sun is not shaded
    top = np.argmax(leaves.center @ sun)
    assert fine[top] == pytest.approx(1.0)


def test_wood_shades_leaves_and_leaves_shade_wood():
    leaves = discs([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 3.0]], [0.1, 0.1, 0.1])
    leaves = Leaves(leaves.center, leaves.axis_u, np.array([[0.0, 0.1, 0.0]] * 3))  # horizontal
    branch = Wood(np.array([[-1.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 1.0]]), np.array([0.5]))
    leaf, wood = sun_visibility(leaves, branch, sun_point=(0.0, 0.0), pixel=0.01)
    assert leaf[0] == pytest.approx(0.0, abs=1e-3)  # under the branch
    assert leaf[1] == pytest.approx(1.0) and leaf[2] == pytest.approx(1.0)
    # the top leaf's shadow (pi 0.1^2) on the branch's shadow (2 m x 1 m and its round ends)
    assert wood[0] == pytest.approx(1 - np.pi * 0.01 / (2 + np.pi * 0.25), abs=2e-3)


def test_sky_exposure_under_a_roof():
    # a small leaf 1 m below a flat disc of radius 1 m: a cosine-weighted sky blocked by half
    leaves = Leaves(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                    np.array([[0.02, 0.0, 0.0], [1.0, 0.0, 0.0]]), np.array([[0.0, 0.02, 0.0], [0.0, 1.0, 0.0]]))
    leaf, wood = sky_exposure(leaves, None, pixel=0.005, rings=8, per_ring=8)
    assert wood.shape == (0,)
    assert leaf[0] == pytest.approx(0.5, abs=0.03)
    assert leaf[1] == pytest.approx(1.0)


def test_inputs_are_checked_and_not_mutated():
    camera = north_camera()
    leaves = discs([[0.0, 5.0, 0.0], [0.1, 6.0, 0.1]], [0.5, 0.5])
    copies = [x.copy() for x in (leaves.center, leaves.axis_u, leaves.axis_v)]
    render(leaves, camera, sun=[0.3, 0.5, 0.8], leaf_sun_visibility=None, wood_sun_visibility=None)
    assert all(np.array_equal(a, b) for a, b in zip(copies, (leaves.center, leaves.axis_u, leaves.axis_v)))
    with pytest.raises(ValueError, match="unit vector"):
        tree_passes(leaves, None, camera, sun_direction=[0, 0, 2], sun_irradiance=E_SUN, sky_irradiance=E_SKY,
                    ground_height=None)
    with pytest.raises(ValueError, match="leaf_sun_visibility"):
        render(leaves, camera, leaf_sun_visibility=np.ones(3))
    with pytest.raises(ValueError, match="sun_irradiance"):
        tree_passes(leaves, None, camera, sun_direction=[0, 0, 1], sun_irradiance=[1, 2], sky_irradiance=E_SKY,
                    ground_height=None)
    # leaves behind the camera or through its near plane are left out, not drawn inverted
    behind = render(discs([[0.0, -5.0, 0.0], [0.0, 0.05, 0.0]], [0.5, 0.5]), camera)
    assert np.all(behind.alpha == 0)


def test_read_passes_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(0)
    sun = rng.random((6, 9, 3)).astype(np.float32)
    sky = rng.random((6, 9, 1)).astype(np.float32)
    alpha = rng.random((6, 9)).astype(np.float32)
    write_exr(tmp_path / "sun.exr", np.concatenate([sun, np.ones((6, 9, 2), np.float32)], axis=2))
    write_exr(tmp_path / "sky.exr", sky)
    write_exr(tmp_path / "alpha.exr", np.concatenate([sun, alpha[..., None]], axis=2))  # RGBA: alpha is A
    passes = read_passes(tmp_path / "sun.exr", tmp_path / "sky.exr", tmp_path / "alpha.exr")
    assert np.array_equal(passes.sun, sun) and np.array_equal(passes.alpha, alpha)
    assert np.array_equal(passes.sky, np.repeat(sky, 3, axis=2))
    check_passes_size(passes, north_camera(9, 6))
    with pytest.raises(ValueError, match=r"9 x 6 .* 8 x 6"):
        check_passes_size(passes, north_camera(8, 6))
    write_exr(tmp_path / "grey_alpha.exr", alpha[..., None])
    assert np.array_equal(read_passes(tmp_path / "sun.exr", tmp_path / "sky.exr",
                                      tmp_path / "grey_alpha.exr").alpha, alpha)
    write_exr(tmp_path / "small.exr", sky[:5])
    with pytest.raises(ImageError, match=r"small\.exr.*9 x 5.*9 x 6") as error:
        read_passes(tmp_path / "sun.exr", tmp_path / "small.exr", tmp_path / "alpha.exr")
    assert error.value.path.name == "small.exr"
    with pytest.raises(ImageError, match=r"missing\.exr"):
        read_passes(tmp_path / "sun.exr", tmp_path / "sky.exr", tmp_path / "missing.exr")
    write_exr(tmp_path / "bright_alpha.exr", 2 * np.ones((6, 9, 1), np.float32))
    with pytest.raises(ImageError, match=r"bright_alpha\.exr.*\[0, 1\]"):
        read_passes(tmp_path / "sun.exr", tmp_path / "sky.exr", tmp_path / "bright_alpha.exr")
    with pytest.raises(ValueError, match="sun pass"):
        ForegroundPasses(sun[:, :4], sun, alpha)


def test_default_grove_renders(capsys):
    grove = grove_geometry.grow_grove(grove_geometry.GroveParams())
    leaves = grove_geometry.leaves_at(grove, grove_geometry.FlutterParams(), 0)
    camera = Camera.look_at((0.0, -20.0, 1.7), (0.0, 0.0, 5.0), vertical_fov=np.radians(45),
                            width=640, height=360)
    s = np.array([0.0, 0.8, 0.6])  # behind the trees
    visibility = sun_visibility(leaves, grove.wood, sun_point=s[:2] / s[2])
    passes = tree_passes(leaves, grove.wood, camera, sun_direction=s, sun_irradiance=E_SUN,
                         sky_irradiance=E_SKY, leaf_sun_visibility=visibility[0],
                         wood_sun_visibility=visibility[1])
    assert capsys.readouterr().out == ""  # nothing printed: pytest's progress dots stay whole
    assert 0.3 < visibility[0].mean() < 0.95
    assert np.all(np.isfinite(passes.sun)) and np.all(passes.sun >= passes.sky - 1e-6)
    assert 0.02 < passes.alpha.mean() < 0.5 and passes.alpha.max() <= 1
    # upright: the trunks reach the bottom half of the image, the crowns fill the top half
    rows_with_trees = np.flatnonzero(passes.alpha.max(axis=1) > 0.5)
    assert rows_with_trees.max() > 250 and passes.alpha[:180].sum() > 2 * passes.alpha[180:].sum()


# ---- smooth tapered stems (issue 18) ---------------------------------------------------------


def _bent_trunk():
    """Three capsules end to end, bent at the two joints, radii stepping down 0.2, 0.16, 0.12 m."""
    knots = np.array([[0.0, 6.0, 0.0], [0.15, 6.0, 2.5], [-0.1, 6.1, 5.0], [0.05, 6.0, 7.5]])
    return Wood(knots[:-1], knots[1:], np.array([0.2, 0.16, 0.12])), knots


def test_tapered_stems_pass_through_the_joints_and_narrow_without_steps():
    wood, knots = _bent_trunk()
    pieces, owner = taper_wood(wood)
    assert np.all(np.diff(owner) >= 0) and set(owner) == {0, 1, 2}
    np.testing.assert_allclose(pieces.start[0], knots[0])
    np.testing.assert_allclose(pieces.end[-1], knots[-1])
    np.testing.assert_allclose(pieces.start[1:], pieces.end[:-1])  # one unbroken axis
    for k in (1, 2):  # the axis goes through each joint
        assert np.min(np.linalg.norm(pieces.end - knots[k], axis=1)) < 1e-12
    # the width falls steadily, by millimetres a piece, to TIP_TAPER of the last radius
    steps = np.diff(pieces.radius)
    assert np.all(steps < 0) and np.abs(steps).max() < 0.005
    assert pieces.radius[-1] == pytest.approx(TIP_TAPER * 0.12, rel=0.05)
    # the axis turns from piece to piece by under a third of the capsules' bend at a joint
    def turns(start, end):
        axis = (end - start) / np.linalg.norm(end - start, axis=1)[:, None]
        return np.degrees(np.arccos(np.clip(np.sum(axis[1:] * axis[:-1], axis=1), -1, 1)))

    assert turns(pieces.start, pieces.end).max() < turns(wood.start, wood.end).max() / 3


def test_a_bent_trunk_has_no_band_of_light_at_its_joints():
    """The brightest sunlit line of a stem piece of axis a has radiance in proportion to
    sqrt(1 - (a . s)^2) (its best-lit normal, at right angles to a): along the tapered trunk it
    changes from piece to piece by under a third of the jump at a joint of the straight
    capsules, where the band of light began at the same height on every trunk."""
    wood, _ = _bent_trunk()
    sun = np.array([1.0, -0.4, 0.5]) / np.linalg.norm([1.0, -0.4, 0.5])

    def brightest(start, end):
        axis = (end - start) / np.linalg.norm(end - start, axis=1)[:, None]
        return np.sqrt(1.0 - (axis @ sun) ** 2)

    pieces, _ = taper_wood(wood)
    smooth = np.abs(np.diff(brightest(pieces.start, pieces.end))).max()
    kinked = np.abs(np.diff(brightest(wood.start, wood.end))).max()
    assert kinked > 0.02 and smooth < kinked / 3


def test_stem_pieces_are_shaded_by_leaves_not_by_each_other():
    """A vertical trunk under one broad leaf at 6 m, the sun 30 degrees from the zenith: the
    pieces in the leaf's shadow get visibility about 0, the others about 1 (in the old
    capsule-wide visibility each segment got one value, and the round ends of consecutive
    pieces would shade each other)."""
    wood = Wood(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 3.0]]), np.array([[0.0, 0.0, 3.0], [0.0, 0.0, 6.0]]),
                np.array([0.2, 0.15]))
    pieces, _ = taper_wood(wood)
    leaf = Leaves(np.array([[0.0, 0.0, 6.5]]), np.array([[0.6, 0.0, 0.0]]), np.array([[0.0, 0.6, 0.0]]))
    sun = np.array([np.tan(np.radians(30.0)), 0.0])  # towards +x, 30 degrees from the zenith
    _, visibility = stem_visibility(leaf, pieces, sun_point=sun, pixel=0.02)
    middle = 0.5 * (pieces.start[:, 2] + pieces.end[:, 2])
    # the leaf's shadow along the trunk: where the ray towards the sun meets z = 6.5 within 0.6 m
    shaded = (6.5 - middle) * np.tan(np.radians(30.0)) < 0.55
    lit = (6.5 - middle) * np.tan(np.radians(30.0)) > 0.65
    assert shaded.any() and lit.any()
    assert np.all(visibility[shaded] < 0.05)
    assert np.all(visibility[lit] > 0.98)


def test_the_compiled_leaf_fragments_have_the_bits_of_the_array_version():
    rng = np.random.default_rng(9)
    leaves, wood, cols, rows, n = 40, 6, 37, 23, 5000
    flat = rng.integers(0, rows * cols, n)
    shape = rng.integers(0, leaves + wood, n)
    per_leaf = [rng.normal(size=leaves) for _ in range(4)]
    per_leaf[0][:3] = 0.0  # n . ray near 0: kept from 0
    depth, reach = rng.random(leaves) * 9 + 1, rng.random(leaves) * 0.05
    light = [rng.random((leaves, 3)) for _ in range(2)]
    outputs = []
    for kernel in (_raster.leaf_fragments, foreground._leaf_fragments_arrays):
        out = (np.full(n, -1.0), np.full((n, 3), -1.0), np.full((n, 3), -1.0))  # wood left as it is
        kernel(flat, shape, leaves, cols, rows, 31.7, *per_leaf, depth - reach, depth + reach, *light, *out)
        outputs.append(b"".join(a.tobytes() for a in out))
    assert outputs[0] == outputs[1]


def test_the_compiled_scatter_of_light_has_the_bits_of_bincount():
    rng = np.random.default_rng(10)
    pixels, n = 300, 20000
    flat = rng.integers(0, pixels, n)
    weight = rng.random(n)
    light = [rng.random((n, 3)) * 50.0 for _ in range(2)]
    sun, sky = _raster.scatter_light(flat, weight, *light, pixels)
    for image, each in zip((sun, sky), light):
        expected = np.stack([np.bincount(flat, weights=weight * each[:, c], minlength=pixels) for c in range(3)],
                            axis=-1)
        assert image.tobytes() == expected.tobytes()


def test_the_compiled_leaf_heights_have_the_bits_of_the_array_version():
    rng = np.random.default_rng(11)
    leaves, wood, n = 50, 5, 8000
    shape = rng.integers(0, leaves + wood, n)
    px, py = rng.normal(size=(2, n)) * 3.0
    cx, cy, slope_x, slope_y, h_center = rng.normal(size=(5, leaves))
    reach = rng.random(leaves) * 0.1
    height = np.full(n, -7.0)
    _raster.leaf_heights(shape, leaves, px, py, cx, cy, slope_x, slope_y, h_center, reach, height)
    expected = np.full(n, -7.0)  # wood fragments left as they are
    is_leaf = shape < leaves
    i = shape[is_leaf]
    rise = (px[is_leaf] - cx[i]) * slope_x[i] + (py[is_leaf] - cy[i]) * slope_y[i]
    expected[is_leaf] = h_center[i] + np.clip(rise, -reach[i], reach[i])
    assert height.tobytes() == expected.tobytes()
