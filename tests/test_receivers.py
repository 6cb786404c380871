"""Receivers other than the level ground: the frame, the hemisphere raster, the layers, the light
by the ground's correlation turned into the receiver's frame (docs/method.md, "Receivers: walls
and slopes"), against the level ground's own path, a turned sky and a world-coordinate Monte Carlo."""

import re

import numpy as np
import pytest
from reference import receiver_monte_carlo

from pipeline.canopy import masks as canopy
from pipeline.canopy.grove import FlutterParams, GroveParams, grow_grove, leaves_at
from pipeline.canopy.rasteriser import grove_mask
from pipeline.core.errors import ConfigError
from pipeline.core.geometry import Grid, sky_grid
from pipeline.ground import shadow
from pipeline.receivers.hemisphere import hemisphere_irradiance, hemisphere_raster, world_radiance
from pipeline.receivers.layers import GroveLayer, grove_in_frame, grove_layers, mask_layer
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import level_ground, slope, wall
from pipeline.receivers.sun import receiver_sun_kernel, sun_lights
from pipeline.sky.base import UniformSky
from pipeline.sky.equirect import EquirectSky, equirect_lookup
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc
from pipeline.sky.sun_kernel import sun_kernel

DEG = np.pi / 180


def unit(azimuth, elevation):
    return np.array([np.cos(elevation) * np.sin(azimuth), np.cos(elevation) * np.cos(azimuth), np.sin(elevation)])


def grille(n=40, bars=5, seed=3):
    """A lattice of bars with a few random holes punched in: transmittance in [0, 1]."""
    t = np.ones((n, n), np.float32)
    t[:, ::bars] = 0.0
    t[::bars, :] = 0.0
    rng = np.random.default_rng(seed)
    for r, c in rng.integers(0, n - 3, (12, 2)):
        t[r:r + 3, c:c + 3] = 0.4
    return t


def grille_lookup(t, centre, size):
    """f(a, b) [m] -> the 30 x 30 grille ``t`` covering ``size`` around ``centre`` (nearest texel), 1 outside."""
    return lambda a, b: np.where((np.abs(a - centre[0]) < size[0] / 2) & (np.abs(b - centre[1]) < size[1] / 2),
                                 t[np.clip(((centre[1] + size[1] / 2 - b) / size[1] * 30).astype(int), 0, 29),
                                   np.clip(((a - centre[0] + size[0] / 2) / size[0] * 30).astype(int), 0, 29)], 1.0)


# --- the frame ------------------------------------------------------------------------------------

def test_a_south_wall_has_east_across_up_along_and_south_out():
    plane = wall((1.0, 2.0, 0.0), facing=180 * DEG, width=3.0, height=2.0)
    assert np.allclose(plane.normal, [0, -1, 0]) and np.allclose(plane.across, [1, 0, 0])
    assert np.allclose(plane.along, [0, 0, 1])
    assert np.allclose(plane.world_points([0.5, 1.5, 0.25]), [1.5, 1.75, 1.5])
    assert np.array_equal(level_ground().rotation, np.eye(3))


@pytest.mark.parametrize("plane", [wall((0, 0, 0), facing=230 * DEG, width=1, height=1, tilt=12 * DEG),
                                   slope(tilt=35 * DEG, facing=70 * DEG)])
def test_directions_go_to_the_sky_plane_and_back(plane):
    rng = np.random.default_rng(1)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    d = d[d @ plane.normal > 0.05]
    s, cos_n = plane.sky_plane(d)
    assert np.allclose(plane.direction(s), d, atol=1e-12)
    assert np.allclose(cos_n, d @ plane.normal)
    # the frame is right-handed and orthonormal, its n the normal of the plane through the points
    assert np.allclose(plane.rotation.T @ plane.rotation, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(plane.rotation), 1.0)
    assert np.isclose(np.cross(plane.across, plane.along) @ plane.normal, 1.0)
    assert abs(plane.across[2]) < 1e-15  # u is level


@pytest.mark.parametrize(("make", "key"), [
    (lambda: wall((0, 0, 0), facing=0, width=0.0, height=2), "walls[0].width"),
    (lambda: wall((0, 0, 0), facing=0, width=1, height=-2), "walls[0].height"),
    (lambda: wall((0, 0, 0), facing=0, width=1, height=2, tilt=np.pi / 2), "walls[0].tilt"),
    (lambda: slope(tilt=90 * DEG, facing=0, where="walls[0]"), "walls[0].tilt"),
    (lambda: mask_layer(np.ones((2, 2)), center=(0, 0), size=(1, 1), distance=0.0, where="walls[0]"),
     "walls[0].distance"),
])
def test_bad_geometry_is_one_line_naming_the_key(make, key):
    with pytest.raises(ConfigError) as error:
        make()
    text = str(error.value)
    assert "\n" not in text and text.split(":")[0].endswith(key.split(".")[-1])


def test_bad_wall_size_names_the_full_key():
    with pytest.raises(ConfigError, match=r"^receivers\.walls\[2\]\.width: must be positive"):
        wall((0, 0, 0), facing=0, width=-1, height=2, where="receivers.walls[2]")


# --- the hemisphere -------------------------------------------------------------------------------

@pytest.mark.parametrize("plane", [level_ground(), wall((0, 0, 0), facing=3.0, width=1, height=1),
                                   slope(tilt=40 * DEG, facing=1.0)])
def test_a_uniform_sky_and_ground_give_the_view_factors(plane):
    sky, ground = 1.7, 0.3
    radiance = world_radiance(UniformSky(np.full(3, sky)), np.full(3, ground))
    f = (1 - np.cos(plane.zenith)) / 2  # the receiver's view factor to the ground
    expected = np.pi * (sky * (1 - f) + ground * f)
    assert hemisphere_irradiance(radiance, plane) == pytest.approx(np.full(3, expected), rel=1e-4)
    grid = sky_grid((-20, -20), (41, 41), 0.05)
    raster = hemisphere_raster(radiance, plane, grid)
    assert raster.irradiance == pytest.approx(hemisphere_irradiance(radiance, plane), rel=1e-12)


def test_the_level_receiver_is_the_level_ground():
    # the same mask, the same uniform sky: the receiver's path and the ground's give the same raster
    window = Grid.from_window((-1.0, -1.0, 1.0, 1.0), 0.05)
    t = grille()
    layer = mask_layer(t, center=(0.2, -0.1), size=(2.0, 2.0), distance=1.5)
    sky = UniformSky(np.array([1.0, 1.3, 1.8]))
    ours = receiver_light(world_radiance(sky, np.zeros(3)), sky, level_ground(), window, [layer],
                          alpha=70 * DEG)
    occlusion, grid = canopy.occlusion_on_lattice(t, center=(0.2, -0.1), size=(2.0, 2.0), lattice=window)
    plan = shadow.plan_isolated(window, grid, height=1.5, alpha=70 * DEG)
    theirs = shadow.ground_isolated(sky.raster(plan.sky), shadow.occlusion_spectrum(occlusion, plan), plan)
    assert np.max(np.abs(ours.sky - theirs)) <= 1e-5 * theirs.max()
    # and the sun kernel of the level receiver is the ground's, to the bit
    day = ProceduralSky(3.0, SunDisc(230 * DEG, 35 * DEG))
    q = day.sun.angular_radius / 6
    assert np.array_equal(receiver_sun_kernel(day, level_ground(), q).weighted, sun_kernel(day, q).weighted)


# --- invariance: a wall under a turned sky is the ground under the sky -----------------------------

def smooth_sphere(azimuth, zenith):
    """Radiance over the whole sphere, the lower half unlike the upper (an HDRI's ground). [radiance]"""
    base = 0.6 + 0.8 * (1 - np.cos(zenith)) + 0.3 * np.sin(zenith) * np.cos(azimuth - 135 * DEG)
    base = base + 0.5 * np.exp(-((zenith - 60 * DEG) ** 2 + (azimuth - 40 * DEG) ** 2) / 0.05)
    base = np.where(zenith > np.pi / 2, 0.25 + 0.1 * np.cos(2 * azimuth), base)
    return np.stack([base, 1.1 * base, 1.4 * base], axis=-1)


def equirect_of(function, width, height):
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    zen, az = np.meshgrid(v * np.pi, (u - 0.5) * 2 * np.pi, indexing="ij")
    return function(az, zen).astype(np.float32)


def turned_and_level(plane, **options):
    """``receiver_light`` (with ``options``) of ``plane`` under a smooth sky turned with it, and of the level
    ground under the sky unturned, behind the same grille 0.7 m away: (on the receiver, on the ground)."""
    image = equirect_of(smooth_sphere, 256, 128)
    # the sun: 30 degrees from the normal in the receiver's frame, and the same in the world's for the ground
    local_sun = unit(20 * DEG, 60 * DEG)
    world_sun = plane.world_directions(local_sun)
    assert world_sun[2] > 0.1
    normal_irradiance = np.array([40.0, 35.0, 28.0])

    def sky_at(direction):
        azimuth, elevation = np.arctan2(direction[0], direction[1]), np.arcsin(direction[2])
        return EquirectSky(image, sun=SunDisc(azimuth, elevation), sun_normal_irradiance=normal_irradiance)

    turned = lambda d: equirect_lookup(image, plane.local_directions(d)).astype(np.float64)  # noqa: E731
    unturned = lambda d: equirect_lookup(image, d).astype(np.float64)  # noqa: E731
    layer = mask_layer(grille(), center=(0.1, 1.0), size=(1.6, 1.6), distance=0.7)
    window = Grid.from_window((-0.6, 0.4, 0.6, 1.6), 0.02)
    sun_window = Grid.from_window((-0.2, 0.8, 0.2, 1.2), 0.004)
    return (receiver_light(turned, sky_at(world_sun), plane, window, [layer], sun_window=sun_window, **options),
            receiver_light(unturned, sky_at(local_sun), level_ground(), window, [layer], sun_window=sun_window,
                           **options))


def test_a_wall_under_a_turned_sky_gets_the_level_grounds_raster():
    on_wall, on_ground = turned_and_level(wall((3.0, -2.0, 0.5), facing=230 * DEG, width=2, height=2, tilt=10 * DEG))
    for ours, theirs in ((on_wall.sky, on_ground.sky), (on_wall.total, on_ground.total)):
        assert np.max(np.abs(ours - theirs) / theirs) < 1e-4
    assert on_ground.total.max() > 2 * on_ground.total.min()  # a real shadow


# --- against a world-coordinate Monte Carlo -------------------------------------------------------

def test_a_wall_behind_a_grille_matches_a_world_monte_carlo():
    rng = np.random.default_rng(5)
    facing, tilt = 250 * DEG, 0.0
    foot = np.array([2.0, 1.0, 0.0])
    plane = wall(foot, facing=facing, width=2, height=2, tilt=tilt)
    sky = ProceduralSky(3.0, SunDisc(235 * DEG, 25 * DEG))
    ground = np.array([0.9, 1.0, 1.1])
    t = grille(n=30, bars=6)
    d, centre, size = 0.4, (0.05, 1.0), (1.2, 1.2)
    layer = mask_layer(t, center=centre, size=size, distance=d)
    window = Grid.from_window((-0.3, 0.7, 0.3, 1.3), 0.01)
    sun_window = Grid.from_window((-0.1, 0.9, 0.1, 1.1), 0.0005)  # the disc about 10 cells across
    light = receiver_light(world_radiance(sky, ground), sky, plane, window, [layer], sun_window=sun_window)
    assert light.exact
    # independent axes from the facing and tilt; the mask's image upright as one faces the wall
    n = unit(facing, tilt)
    u = np.cross([0.0, 0.0, 1.0], n)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    mask = grille_lookup(t, centre, size)
    # 30 pixels: 16 in the sun's penumbrae, 7 lit, 7 in the bars' umbrae (ours only chooses them)
    sun_part = light.total[1] - shadow.resample_bilinear(light.sky, window, sun_window)[1]
    part, lit, dark = (np.argwhere(where)
                       for where in ((sun_part > 1) & (sun_part < 61), sun_part >= 61, sun_part <= 1))
    pick = np.concatenate([part[rng.integers(0, len(part), 16)], lit[rng.integers(0, len(lit), 7)],
                           dark[rng.integers(0, len(dark), 7)]])
    points = np.column_stack(sun_window.ground_from_raster(pick[:, 0], pick[:, 1]))
    # two independent estimates: their mean, and its noise from their difference
    mc, noise = receiver_monte_carlo(points, origin=foot, u=u, w=w, normal=n, distance=d, transmittance=mask, sky=sky,
                                     ground=ground, pixel=sun_window.pixel, rng=rng)
    ours = light.total[:, pick[:, 0], pick[:, 1]].T
    relative_rms = np.sqrt(np.mean((ours - mc) ** 2)) / np.mean(mc)
    assert noise < 0.003, noise
    assert relative_rms < 0.01, relative_rms
    assert mc[:, 1].max() > 2 * mc[:, 1].min()  # lit and shaded pixels both picked


# --- the sun behind, the grove turned -------------------------------------------------------------

def test_a_sun_behind_the_wall_leaves_it_sky_light_only():
    sky = ProceduralSky(3.0, SunDisc(60 * DEG, 20 * DEG))
    plane = wall((0, 0, 0), facing=240 * DEG, width=2, height=2)
    assert not sun_lights(sky, plane)
    layer = mask_layer(grille(), center=(0, 1), size=(1, 1), distance=0.5)
    window = Grid.from_window((-0.2, 0.8, 0.2, 1.2), 0.02)
    sun_window = Grid.from_window((-0.1, 0.9, 0.1, 1.1), 0.01)
    light = receiver_light(world_radiance(sky, np.full(3, 1.0)), sky, plane, window, [layer], sun_window=sun_window)
    assert np.all(light.sun_unshadowed == 0)
    assert np.allclose(light.total, shadow.resample_bilinear(light.sky, window, sun_window), rtol=1e-6)


def test_a_turned_groves_leaves_shadow_the_wall_where_world_rays_from_the_sun_land():
    params = GroveParams(count=1, crown_radius=1.0, leaves_per_tree=300, leaf_length=0.1, leaves_per_cluster=1,
                         height=2.0, center=(0.0, -2.0))
    grove = grow_grove(params)
    flutter = FlutterParams()
    plane = wall((0.0, 0.0, 0.0), facing=180 * DEG, width=6, height=4)
    sky = ProceduralSky(3.0, SunDisc(200 * DEG, 30 * DEG))
    local = grove_in_frame(grove, plane)
    s = plane.sky_plane(sky.sun_direction)[0]
    (layer,) = grove_layers(local, flutter, 0, distances=[2.0], sun=s)
    no_wood = np.zeros(len(grove.wood.radius), bool)
    leaves_only = GroveLayer(local, flutter, 0, 2.0, layer.sun, (layer.select[0], no_wood))
    window = Grid.from_window((-2.0, 0.0, 3.0, 3.0), 0.02)
    light = receiver_light(world_radiance(sky, np.zeros(3)), sky, plane, window, [leaves_only], sun_window=window)
    deficit = light.sun_unshadowed[1] - (light.total[1] - light.sky[1])  # the leaves' sun shadow
    # world: rays from points of the wall's plane y = 0 (u = x, w = z) towards the sun's centre, hitting leaf ellipses
    leaves = leaves_at(grove, flutter, 0)
    x, z = window.ground_from_raster(*np.indices(window.shape))
    points = np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)
    normal = np.cross(leaves.axis_u, leaves.axis_v)
    sun = sky.sun_direction
    hidden = np.zeros(len(points), bool)
    for centre, a, b, nrm in zip(leaves.center, leaves.axis_u, leaves.axis_v, normal):
        t = ((centre - points) @ nrm) / (sun @ nrm)
        offset = points + t[:, None] * sun - centre
        hidden |= (t > 0) & ((offset @ a / (a @ a)) ** 2 + (offset @ b / (b @ b)) ** 2 <= 1)
    traced = hidden.reshape(window.shape).astype(float)
    for axis in (x, z):
        assert (deficit * axis).sum() / deficit.sum() == pytest.approx((traced * axis).sum() / traced.sum(), abs=0.005)
    # the same area in shadow (a leaf's penumbra keeps its area), and the same pixels blurred by the penumbra
    shade = deficit / light.sun_unshadowed[1]
    assert shade.sum() == pytest.approx(traced.sum(), rel=0.03)
    blurred = sum(np.roll(traced, (dr, dc), axis=(0, 1)) for dr in (-1, 0, 1) for dc in (-1, 0, 1)) / 9
    assert np.corrcoef(shade.ravel(), blurred.ravel())[0, 1] > 0.9
    assert (traced * x).sum() / traced.sum() > 0.5  # the sun in the south-south-west throws it east of the tree
    # the level receiver's turned grove is the grove: the ground's own mask
    level = grove_in_frame(grove, level_ground())
    ground_grid = Grid.from_window((-1.5, -3.5, 1.5, -0.5), 0.05)
    assert np.array_equal(grove_mask(level, flutter, 3, sun=(0.2, 0.1), plane_height=2.0, grid=ground_grid),
                          grove_mask(grove, flutter, 3, sun=(0.2, 0.1), plane_height=2.0, grid=ground_grid))


# --- a config's walls: the section, the wall's raster, the camera (slice 2) ------------------------

def wall_scene(**wall):
    """tiny_grove with one wall 2 m east of the tree, facing west; ``wall``: its keys changed."""
    from scenes import tiny_grove

    config = tiny_grove()
    config["receivers"] = {"walls": [{"foot": [2.0, 0.0], "facing": 270.0, "width": 3.0, "height": 2.0,
                                      "pixel": 0.05, **wall}]}
    return config


def test_a_walls_section_is_read_in_radians_with_its_presets(tmp_path):
    from pipeline.config.parse import parse_config
    from pipeline.config.receivers import WALL_ALBEDOS

    config = parse_config(wall_scene(tilt=10.0, albedo="brick"), tmp_path)
    (w,) = config.receivers.walls
    assert w.name == "wall0" and w.foot == (2.0, 0.0, 0.0) and w.albedo == "brick"
    assert w.facing == pytest.approx(270 * DEG) and w.tilt == pytest.approx(10 * DEG)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    # the presets' luminance inside the published ranges (docs/method.md, "Receivers")
    assert 0.70 <= luminance @ WALL_ALBEDOS["plaster"] <= 0.80 and 0.10 <= luminance @ WALL_ALBEDOS["brick"] <= 0.15


@pytest.mark.parametrize("change, key", [
    ({"width": 0.0}, "receivers.walls[0].width"), ({"height": -1.0}, "receivers.walls[0].height"),
    ({"tilt": 90.0}, "receivers.walls[0].tilt"), ({"albedo": "marble"}, "receivers.walls[0].albedo"),
    ({"albedo": [0.5, 1.2, 0.5]}, "receivers.walls[0].albedo"), ({"foot": [1.0]}, "receivers.walls[0].foot"),
    ({"colour": 1}, "receivers.walls[0].colour"), ({"pixel": 1e-5}, "receivers.walls[0].pixel"),
    ({"masks": [{"image": "none.png", "size": [1, 1], "distance": 1}]}, "receivers.walls[0].masks[0].image")])
def test_a_bad_wall_is_one_line_naming_its_key(tmp_path, change, key):
    from pipeline.config.parse import parse_config

    with pytest.raises(ConfigError) as error:
        parse_config(wall_scene(**change), tmp_path)
    assert key in str(error.value) and len(str(error.value).splitlines()) == 1


def test_a_bad_slope_and_a_second_wall_of_one_name_are_refused(tmp_path):
    from pipeline.config.parse import parse_config

    config = wall_scene()
    config["receivers"]["slope"] = {"tilt": 90.0, "facing": 180.0}
    with pytest.raises(ConfigError, match=r"receivers\.slope\.tilt"):
        parse_config(config, tmp_path)
    config = wall_scene()
    config["receivers"]["walls"].append(dict(config["receivers"]["walls"][0]))
    config["receivers"]["walls"][1]["name"] = "wall0"
    with pytest.raises(ConfigError, match=r"receivers\.walls\[1\]\.name"):
        parse_config(config, tmp_path)


def test_the_hash_of_the_level_ground_alone_is_unmoved_and_a_walls_files_move_it(tmp_path):
    from scenes import tiny_grove

    from pipeline.config.parse import parse_config
    from pipeline.core import io

    alone = parse_config(tiny_grove(), tmp_path).digest()
    empty = tiny_grove()
    empty["receivers"] = {"walls": []}
    assert parse_config(empty, tmp_path).digest() == alone
    io.write_png(tmp_path / "grille.png", grille()[..., None])
    masked = wall_scene(masks=[{"image": "grille.png", "size": [1.0, 1.0], "distance": 0.5}])
    first = parse_config(masked, tmp_path).digest()
    assert first != alone
    io.write_png(tmp_path / "grille.png", grille(seed=4)[..., None])
    assert parse_config(masked, tmp_path).digest() != first


def test_the_walls_raster_is_upright_as_one_faces_it(tmp_path, capsys):
    """A wall leaning back to face the sun (its normal on the sun) behind a mask with an opaque block
    at its upper left, as one faces the wall: the sun's shadow falls straight back, so the raster that
    ``sunshade ground --receiver`` writes is dark at its upper left, in the block's place, and lit elsewhere."""
    from scenes import write_config

    from pipeline.cli.main import main
    from pipeline.core import io

    image = np.ones((40, 40), np.float32)
    image[:20, :20] = 0.0  # the upper left quarter, rows along -w
    io.write_png(tmp_path / "block.png", image[..., None])
    config = wall_scene(facing=150.0, tilt=55.0, width=2.0, height=2.0, pixel=0.02,
                        masks=[{"image": "block.png", "center": [0.0, 1.0], "size": [1.0, 1.0], "distance": 0.3}])
    config["canopy"]["trees"]["crown_radius"] = 0.3  # the tree far from the wall's frame (at 2 m)
    out = tmp_path / "wall.exr"
    assert main(["ground", str(write_config(tmp_path, config)), "--receiver", "wall0", "--cache",
                 str(tmp_path / "cache"), "-o", str(out)]) == 0
    assert "wall wall0 100 x 100 px" in capsys.readouterr().out
    y = io.read_image(out) @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    assert io.read_attributes(out, ["sunshade:receiver"])["sunshade:receiver"] == "wall0"
    lit, block = np.median(y[55:95, 55:95]), np.median(y[30:45, 30:45])  # rows from the top
    assert block < 0.5 * lit  # the block's sun shadow, where it stands
    assert np.median(y[30:45, 55:70]) > 0.9 * lit and np.median(y[55:70, 30:45]) > 0.9 * lit


def test_the_camera_sees_a_wall_where_its_rays_meet_the_rectangle_and_hides_what_is_behind():
    """``view.wall_hits`` against the wall's corners projected by ``project_points`` (each pixel's
    centre point inside the projected quadrilateral), its depth the ray's length to the plane; and
    ``show_points`` puts the wall in front of a far background only."""
    from pipeline.camera.pinhole import Camera, project_points
    from pipeline.core.geometry import Grid
    from pipeline.receivers.view import bilinear_taps, show_points, wall_hits, wall_points

    plane = wall((0.0, 5.0, 0.0), facing=200 * DEG, width=4.0, height=2.5, tilt=8 * DEG)
    camera = Camera.look_at((1.0, -3.0, 1.4), (0.0, 5.0, 1.2), vertical_fov=40 * DEG, width=96, height=64)
    hits = wall_hits(camera, plane, samples=1)
    corners = plane.world_points([(-2, 0, 0), (2, 0, 0), (2, 2.5, 0), (-2, 2.5, 0)])
    u, v, _ = project_points(camera, corners)
    rows, cols = hits.region
    vv, uu = np.mgrid[rows, cols] + 0.5
    # inside the convex quadrilateral: on one side of all four edges (whichever the corners' winding)
    edges = [((u[k], v[k]), (u[(k + 1) % 4], v[(k + 1) % 4])) for k in range(4)]
    sides = np.stack([(b0 - a0) * (vv - a1) - (b1 - a1) * (uu - a0) for (a0, a1), (b0, b1) in edges])
    inside = np.all(sides > 0, axis=0) | np.all(sides < 0, axis=0)
    lengths = np.array([np.hypot(b0 - a0, b1 - a1) for (a0, a1), (b0, b1) in edges])
    sure = np.min(np.abs(sides) / lengths[:, None, None], axis=0) > 1e-6  # not on an edge
    assert inside.sum() > 500 and np.array_equal(hits.hit[0][sure], inside[sure])
    seen = hits.hit[0]
    d = np.stack([hits.u[0][seen], hits.w[0][seen], np.zeros(seen.sum())], axis=-1)
    points = plane.world_points(d)
    assert np.allclose(np.linalg.norm(points - np.array(camera.position), axis=-1), hits.distance[0][seen])
    grid = Grid.from_window((-2.0, 0.0, 2.0, 2.5), 0.1)
    raster = np.full((*grid.shape, 3), 5.0, np.float32)  # the wall's radiance, 5 everywhere
    wall_at, wu, ww = wall_points(hits)
    taps, white = bilinear_taps(grid, wu, ww), np.ones((1, 3), np.float32)
    picture = np.ones((64, 96, 3), np.float32)
    near = np.full((64, 96), 2.0, np.float32)  # a background nearer than the wall keeps its pixels
    show_points(picture, near, hits, wall_at, raster, taps, white, np.float32(1.0))
    assert np.all(picture == 1.0)
    far = np.full((64, 96), np.inf, np.float32)
    show_points(picture, far, hits, wall_at, raster, taps, white, np.float32(1.0))
    assert np.all(picture[rows, cols][seen] == 5.0) and np.all(picture[rows, cols][~seen] == 1.0)
    assert np.all(np.isfinite(far[rows, cols][seen])) and np.all(np.isinf(far[rows, cols][~seen]))


def test_check_lists_each_wall_with_its_sun_and_bound(tmp_path, capsys):
    """The wall faces the sun's azimuth: the sun is its elevation (55 degrees) off the wall's normal,
    and (sun + sky) / sky is printed from the light check prints."""
    from scenes import write_config

    from pipeline.cli.main import main

    config = wall_scene(facing=150.0)
    assert main(["check", str(write_config(tmp_path, config))]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("  wall wall0"))
    assert "(3 x 2 m, facing 150 degrees)" in line and line.count("55 degrees off its normal") == 3  # frames 0, 3, 5
    sun, sky, bound = (float(v) for v in re.search(r"frame 0: .*?sun ([\d.]+) klx, sky ([\d.]+) klx, a fleck at "
                                                     r"most ([\d.]+) x", line).groups())
    assert bound == pytest.approx((sun + sky) / sky, abs=0.02)


@pytest.mark.parametrize("change, message", [
    ({"receivers.slope": {"tilt": 20.0, "facing": 180.0}}, "receivers.walls: walls on a slope are not drawn yet"),
    ({"output": {"passes": ["sun"]}}, "output.passes: the light passes are not made with walls yet"),
    ({"receivers.walls": [{"foot": [0.0, 0.0], "facing": 270.0, "width": 3.0, "height": 2.0}]},
     "receivers.walls[0].foot: wall 'wall0' stands through the trunk of the tree at (0.0, 0.0) m")])
def test_what_walls_cannot_be_drawn_with_is_refused_before_anything_is_written(tmp_path, capsys, change, message):
    from scenes import write_config

    from pipeline.cli.main import main

    config = wall_scene()
    for key, value in change.items():
        section, _, name = key.partition(".")
        if name:
            config[section][name] = value
        else:
            config[section] = value
    path = write_config(tmp_path, config)
    out = tmp_path / "out"
    out.mkdir()
    for argv in (["check", str(path)], ["frame", str(path), "--cache", str(out / "cache"), "-o", str(out / "f.exr")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, err
        assert list(out.iterdir()) == []


def test_a_segments_distance_to_a_wall_is_the_brute_force_least():
    """``wall_distance`` against the least distance between dense points on the segment and on the
    (leaning, raised) rectangle."""
    from pipeline.receivers.plane import wall_distance

    plane = wall((0.5, -1.0, 0.3), facing=200 * DEG, width=3.0, height=2.0, tilt=20 * DEG)
    rng = np.random.default_rng(5)
    start, end = rng.uniform(-3, 3, (5, 3)), rng.uniform(-3, 3, (5, 3))
    start[0], end[0] = plane.world_points([(0.3, 1.0, -1.0), (0.5, 0.8, 1.0)])  # through the wall: 0
    u, w = np.meshgrid(np.linspace(-1.5, 1.5, 151), np.linspace(0.0, 2.0, 101))
    rectangle = plane.world_points(np.stack([u.ravel(), w.ravel(), 0 * u.ravel()], axis=-1))
    t = np.linspace(0.0, 1.0, 201)[:, None, None]
    got = wall_distance(plane, start, end)
    assert got[0] < 1e-9
    for a, b, least in zip(start, end, got):
        brute = np.min(np.linalg.norm(rectangle[None] - (a + t * (b - a)), axis=-1))
        assert least <= brute + 1e-9 and least == pytest.approx(brute, abs=0.02)  # the grids' spacing


def test_walls_that_cross_are_told_from_walls_that_meet_at_an_edge():
    from pipeline.receivers.plane import walls_cross

    south = wall((0.0, 0.0, 0.0), facing=180 * DEG, width=4.0, height=2.0)  # x from -2 to 2 on y = 0
    east = lambda foot, **k: wall(foot, facing=90 * DEG, **{"width": 2.0, "height": 2.0, **k})  # noqa: E731
    assert walls_cross(south, east((0.0, 0.0, 0.0)), margin=1e-3)  # an X
    assert walls_cross(south, east((0.0, 0.99, 0.0)), margin=1e-3)  # a T 1 cm through
    assert walls_cross(south, wall((0.0, 1.0, 0.0), facing=0.0, width=3.0, height=3.0, tilt=40 * DEG),
                       margin=1e-3)  # a wall 1 m north leaning back over it
    assert not walls_cross(south, east((0.0, 1.0, 0.0)), margin=1e-3)  # a T: an end against the face
    assert not walls_cross(south, east((2.0, 1.0, 0.0)), margin=1e-3)  # an L: a corner
    assert not walls_cross(south, east((0.0, 0.0, 2.0)), margin=1e-3)  # standing on its top edge


@pytest.mark.parametrize("change, key, message", [
    ({"walls": [{"foot": [0.0, 0.0]}]}, "receivers.walls[0].foot", "wall 'wall0' stands through the trunk"),
    ({"walls": [{}, {"foot": [2.0, 0.0], "facing": 0.0}]}, "receivers.walls[1]",
     "wall 'wall1' passes through wall 'wall0'"),
    ({"camera": [2.0, 0.5, 1.0]}, "camera.position", "the camera stands in wall 'wall0'"),
    ({"camera": [4.0, 0.2, 1.5]}, "camera.position", "the camera is behind wall 'wall0' (receivers.walls[0]) "
                                                      "and sees its back")])
def test_a_wall_through_a_trunk_a_wall_or_the_camera_is_one_line_naming_the_key(tmp_path, change, key, message):
    """The tree stands at the origin (trunk radius 0.15 to 0.25 m); the wall 2 m east faces west."""
    from scenes import plan_of

    config = wall_scene()
    base = config["receivers"]["walls"][0]
    config["receivers"]["walls"] = [{**base, **w, "name": f"wall{i}"} for i, w in enumerate(change.get("walls", [{}]))]
    if "camera" in change:
        config["camera"] = {"position": change["camera"], "look_at": [0.0, 0.0, 1.0], "resolution": [64, 48]}
    with pytest.raises(ConfigError) as error:
        plan_of(config, tmp_path)
    text = str(error.value)
    assert len(text.splitlines()) == 1 and f"{key}: {message}" in text, text


@pytest.mark.parametrize("change", [
    {"foot": [0.5, 0.0]},  # 0.5 m from the trunk's axis
    {"camera": {"position": [4.0, 0.2, 1.5], "look_at": [8.0, 0.0, 1.0]}},  # behind the wall, looking away
    {"camera": {"position": [-3.0, 0.5, 1.5], "look_at": [2.0, 0.0, 1.0]}},  # in front of it
    {"second": {"foot": [1.0, 1.5], "facing": 180.0, "width": 2.0}}])  # an L at the wall's north end
def test_a_wall_clear_of_the_trunk_and_a_camera_that_cannot_see_its_back_are_planned(tmp_path, change):
    from scenes import plan_of

    config = wall_scene(**{key: value for key, value in change.items() if key == "foot"})
    if "camera" in change:
        config["camera"] = {**change["camera"], "resolution": [64, 48]}
    if "second" in change:
        config["receivers"]["walls"].append({**config["receivers"]["walls"][0], "name": "wall1", **change["second"]})
    assert plan_of(config, tmp_path).receivers.walls


# --- a wall on the ground: its sun shadow and the sky it hides (docs/method.md, "A wall on the ground")

def _wall_hit(plane, origins, directions):
    """Whether world rays (n, 3) from origins (n, 3) meet the wall's rectangle in front of them."""
    n = plane.normal
    dn = directions @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(plane.origin) - origins) @ n) / dn
    local = plane.local_points(origins + t[:, None] * directions)
    return (t > 0) & (np.abs(local[:, 0]) <= plane.width / 2) & (local[:, 1] >= 0) & (local[:, 1] <= plane.height)


def _lopsided_sky(d):
    """A test sky by world direction: much brighter towards the east and the zenith, coloured [radiance]."""
    d = np.asarray(d, dtype=np.float64)
    lum = 1.0 + 6.0 * (0.5 + 0.5 * d[..., 0]) ** 6 + d[..., 2]
    return lum[..., None] * np.array([1.0, 0.9, 1.2])


_SUN = unit(230 * DEG, 25 * DEG)


def _ground_near_a_wall():
    """A wall; the model's and a Monte Carlo's irradiance at ground points round it (in front, past an
    end, behind), their sky and the wall's share apart; and cells' light under the sun's shadow."""
    from pipeline.receivers.ground_shade import hidden_sky, polygon_coverage, shadow_polygon, sky_table
    plane = wall((1.0, 2.0, 0.0), facing=200 * DEG, width=4.0, height=2.5)
    front, back, sun_normal = np.array([2.0, 1.9, 1.7]), np.array([0.6, 0.6, 0.7]), np.array([30.0, 28.0, 25.0])
    local = np.array([[0.0, 0.02], [0.5, 0.3], [-1.5, 1.0], [1.9, 0.1], [2.5, 0.5], [0.0, 3.0], [0.3, -0.2],
                      [-1.0, -1.0]])  # (u, along n) on the ground [m]
    points = plane.world_points(np.column_stack([local[:, 0], np.zeros(len(local)), local[:, 1]]))[:, :2]
    # the model: the open sky less what the wall hides, plus the wall's radiance x pi x its view factor
    hidden, factor = hidden_sky(plane, points, sky_table(_lopsided_sky))
    el = (np.arange(512) + 0.5) / 512 * np.pi / 2
    az = (np.arange(512) + 0.5) / 512 * 2 * np.pi
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.sin(az[:, None]), np.cos(el) * np.cos(az[:, None]),
                                     np.sin(el)[None, :]), axis=-1)
    open_sky = (_lopsided_sky(d) * (np.sin(el) * np.cos(el))[None, :, None]).sum(axis=(0, 1)) * (np.pi / 1024) ** 2 * 4
    wall_share = np.pi * np.where((local[:, 1] >= 0)[:, None], front, back) * factor[:, None]
    # the Monte Carlo: cosine-weighted rays, stratified 256 x 256, from each point in world axes
    k = 256
    rng = np.random.default_rng(5)
    u1 = ((np.arange(k)[:, None] + rng.random((k, k))) / k).ravel()
    u2 = ((np.arange(k)[None, :] + rng.random((k, k))) / k).ravel()
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    rays = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)])
    mc = []
    for p, ahead in zip(points, local[:, 1] >= 0):
        hit = _wall_hit(plane, np.broadcast_to(np.array([p[0], p[1], 0.0]), rays.shape), rays)
        mc.append(np.pi * np.where(hit[:, None], front if ahead else back, _lopsided_sky(rays)).mean(axis=0))
    # the sun: cells of 0.1 m, the polygon's cover against rays to the sun from 16 x 16 points a cell
    grid = Grid((-2.0, 6.0), 0.1, (100, 90))
    rows, cols = np.mgrid[0:100, 0:90]
    s = (np.arange(16) + 0.5) / 16
    x = grid.origin[0] + (cols[..., None, None] + s[None, None, None, :]) * grid.pixel
    y = grid.origin[1] - (rows[..., None, None] + s[None, None, :, None]) * grid.pixel
    starts = np.stack(np.broadcast_arrays(x, y, 0.0), axis=-1).reshape(-1, 3)
    seen = _wall_hit(plane, starts, np.broadcast_to(_SUN, starts.shape)).reshape(100, 90, -1).mean(axis=-1)
    sun_light = sun_normal * _SUN[2]

    def cells(cover):
        return open_sky + sun_light * (1 - cover[..., None])

    def cover(sun):
        return polygon_coverage(shadow_polygon(plane, sun), grid)

    return open_sky - hidden, wall_share, np.array(mc), cells, cover, cells(seen)


def test_a_walls_shadow_and_lost_sky_on_the_ground_match_a_world_monte_carlo():
    sky, wall_share, mc, cells, cover, cells_mc = _ground_near_a_wall()
    shade = cover(_SUN)
    assert 0.1 < shade.mean() < 0.9 and ((shade > 0.02) & (shade < 0.98)).sum() > 50  # edges in the window
    assert np.max(np.abs((sky + wall_share) / mc - 1)) < 0.02
    assert np.max(np.abs(cells(shade) / cells_mc - 1)) < 0.02
    # able to fail: the shadow turned 1 degree, the wall's view factor 5% off
    assert np.max(np.abs(cells(cover(unit(231 * DEG, 25 * DEG))) / cells_mc - 1)) > 0.1
    assert np.max(np.abs((sky + 1.05 * wall_share) / mc - 1)) > 0.02


@pytest.mark.parametrize("foot, tilt", [((1.0, 2.0, 0.0), 25 * DEG), ((1.0, 2.0, 0.6), 0.0)])
def test_a_leaning_or_raised_walls_view_factor_is_the_share_of_rays_that_meet_it(foot, tilt):
    from pipeline.receivers.ground_shade import hidden_sky
    plane = wall(foot, facing=200 * DEG, width=4.0, height=2.5, tilt=tilt)
    points = plane.world_points(np.array([[0.0, 0.0, 0.05], [0.5, 0.0, 0.6], [2.5, 0.0, 0.5], [0.3, 0.0, -1.5]]))
    points[:, 2] = 0.0
    _, factor = hidden_sky(plane, points[:, :2], None)
    k = 256
    rng = np.random.default_rng(7)
    u1 = ((np.arange(k)[:, None] + rng.random((k, k))) / k).ravel()
    u2 = ((np.arange(k)[None, :] + rng.random((k, k))) / k).ravel()
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    rays = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)])
    mc = [_wall_hit(plane, np.broadcast_to(p, rays.shape), rays).mean() for p in points]
    assert min(mc) > 0.02
    np.testing.assert_allclose(factor, mc, atol=0.003)
