"""A sloped ground (docs/method.md, "A sloped ground"): its light by the correlation in its own frame
against the level ground under a turned sky and a world-coordinate Monte Carlo, the trees standing
on it, the camera turned into its frame, a tiny config drawn and what is refused."""

import numpy as np
import pytest
from reference import receiver_monte_carlo
from test_receivers import equirect_of, grille, grille_lookup, smooth_sphere, turned_and_level, unit

from pipeline.camera.pinhole import Camera, project_points
from pipeline.canopy.grove import GroveParams, grow_grove
from pipeline.core.errors import ConfigError
from pipeline.core.geometry import Grid
from pipeline.ground import shadow
from pipeline.receivers.hemisphere import world_radiance
from pipeline.receivers.layers import mask_layer
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import level_ground, slope
from pipeline.receivers.slope import SkyInFrame, camera_in_frame, grove_on_slope, height_on, shading_grove
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc

DEG = np.pi / 180


def test_a_slope_under_a_turned_sky_gets_the_level_grounds_raster():
    # a mask parallel to the slope at distance d under the sky turned with it (its lower half, the
    # ground's, included) and the sun at the same local direction: the level ground's raster, with
    # the coarse sun beyond the fine window too
    on_slope, on_ground = turned_and_level(slope(tilt=40 * DEG, facing=250 * DEG, through=(1.0, -2.0, 0.5)),
                                           coarse_sun=True)
    for ours, theirs in ((on_slope.sky, on_ground.sky), (on_slope.total, on_ground.total),
                         (on_slope.outer, on_ground.outer)):
        assert np.max(np.abs(ours - theirs) / theirs) < 1e-4
    assert on_ground.total.max() > 2 * on_ground.total.min()  # a real shadow


def test_a_slope_under_a_mask_matches_a_world_monte_carlo():
    rng = np.random.default_rng(11)
    facing, tilt = 255 * DEG, 40 * DEG
    origin = np.array([1.0, 2.0, 0.3])
    plane = slope(tilt=tilt, facing=facing, through=origin)
    sky = ProceduralSky(3.0, SunDisc(262 * DEG, 8 * DEG))  # a low sun the slope faces
    ground = np.array([0.9, 1.0, 1.1])
    t = grille(n=30, bars=6)
    d, centre, size = 0.4, (0.05, 1.0), (1.2, 1.2)
    light = receiver_light(world_radiance(sky, ground), sky, plane, Grid.from_window((-0.3, 0.7, 0.3, 1.3), 0.01),
                           [mask_layer(t, center=centre, size=size, distance=d)],
                           sun_window=Grid.from_window((-0.1, 0.9, 0.1, 1.1), 0.0005))
    assert light.exact
    # independent axes: the normal from the facing and the tilt (its elevation 90 - tilt)
    n = unit(facing, np.pi / 2 - tilt)
    u = np.cross([0.0, 0.0, 1.0], n)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    mask = grille_lookup(t, centre, size)
    sun_window = light.sun_window
    sun_part = light.total[1] - shadow.resample_bilinear(light.sky, light.window, sun_window)[1]
    top = sun_part.max()
    part, lit, dark = (np.argwhere(where) for where in ((sun_part > 0.02 * top) & (sun_part < 0.98 * top),
                                                         sun_part >= 0.98 * top, sun_part <= 0.02 * top))
    pick = np.concatenate([part[rng.integers(0, len(part), 16)], lit[rng.integers(0, len(lit), 7)],
                           dark[rng.integers(0, len(dark), 7)]])
    points = np.column_stack(sun_window.ground_from_raster(pick[:, 0], pick[:, 1]))
    mc, noise = receiver_monte_carlo(points, origin=origin, u=u, w=w, normal=n, distance=d, transmittance=mask,
                                     sky=sky, ground=ground, pixel=sun_window.pixel, rng=rng)
    ours = light.total[:, pick[:, 0], pick[:, 1]].T
    relative_rms = np.sqrt(np.mean((ours - mc) ** 2)) / np.mean(mc)
    assert noise < 0.003, noise
    assert relative_rms < 0.01, relative_rms
    assert mc[:, 1].max() > 1.5 * mc[:, 1].min()  # lit and shaded points both picked
    # and the sun lights the slope far more than it lights the level ground
    assert light.sun_unshadowed[1] > 4 * sky.sun_normal_irradiance[1] * sky.sun_direction[2]


def test_trees_stand_vertical_on_the_slope_with_their_feet_on_it():
    grove = grow_grove(GroveParams(count=3, seed=2, crown_radius=1.5, leaves_per_tree=200, height=4.0))
    plane = slope(tilt=35 * DEG, facing=200 * DEG)
    standing = grove_on_slope(grove, plane)
    lift = standing.bases[:, 2] - grove.bases[:, 2]
    assert np.allclose(standing.bases[:, 2], height_on(plane, grove.bases[:, 0], grove.bases[:, 1]))
    assert np.allclose(plane.local_points(standing.bases)[:, 2], 0.0, atol=1e-12)  # on the plane
    assert np.ptp(lift) > 0.5  # the trees stand at different heights
    # each tree moved straight up, whole: its leaves by its foot's lift
    leaves = np.repeat(lift, 200)
    assert np.allclose(standing.leaves.center - grove.leaves.center, np.outer(leaves, [0, 0, 1]))
    assert np.array_equal(standing.leaves.axis_u, grove.leaves.axis_u)
    # a trunk's foot lowered by its radius x tan(tilt): its downhill edge meets the slope
    feet = np.arange(3) * (len(grove.wood.start) // 3)
    foot, radius = standing.wood.start[feet], standing.wood.radius[feet]
    downhill = foot + radius[:, None] * np.array([np.sin(200 * DEG), np.cos(200 * DEG), 0.0])
    assert np.allclose(plane.local_points(downhill)[:, 2], 0.0, atol=1e-9)
    # as they shade the slope, the feet stand on it at their axes: nothing buried casts a shadow
    shading = shading_grove(standing, plane)
    assert np.allclose(plane.local_points(shading.wood.start[feet])[:, 2], 0.0, atol=1e-9)
    assert np.array_equal(np.delete(shading.wood.start, feet, axis=0), np.delete(standing.wood.start, feet, axis=0))


@pytest.mark.parametrize("uphill", [True, False])
def test_the_camera_turned_into_the_slope_sees_the_same_picture(uphill):
    plane = slope(tilt=30 * DEG, facing=120 * DEG)
    down = np.array([np.sin(120 * DEG), np.cos(120 * DEG), 0.0])  # the fall line's horizontal
    position = np.array([1.0, 2.0, 0.0]) + np.array([0.0, 0.0, 2.0 + height_on(plane, 1.0, 2.0)])
    target = position + (-1 if uphill else 1) * 10 * down + np.array([0.0, 0.0, -1.0])
    camera = Camera.look_at(position, target, vertical_fov=50 * DEG, width=64, height=36)
    local = camera_in_frame(camera, plane)
    points = np.random.default_rng(4).normal(size=(50, 3)) * 5 + target
    for ours, theirs in zip(project_points(local, plane.local_points(points)), project_points(camera, points)):
        assert np.allclose(ours, theirs, atol=1e-6)
    askew = Camera(camera.position, camera.yaw + 0.2, camera.pitch, camera.vertical_fov, 64, 36)
    with pytest.raises(ValueError, match="straight up or down"):
        camera_in_frame(askew, plane)


def test_the_sky_in_the_slopes_frame_is_the_worlds_and_the_ground_below_its_horizon():
    plane = slope(tilt=40 * DEG, facing=270 * DEG)
    sky = ProceduralSky(3.0, SunDisc(270 * DEG, 5 * DEG))
    turned = SkyInFrame(sky, plane, (0.1, 0.2, 0.3))
    world = np.array([unit(80 * DEG, 30 * DEG), unit(200 * DEG, 10 * DEG), unit(90 * DEG, -20 * DEG)])
    local = plane.local_directions(world)
    ours = turned.view_radiance(local, local[:, :2] / local[:, 2:])
    assert np.allclose(ours[:2], sky.view_radiance(world[:2], world[:2, :2] / world[:2, 2:]), rtol=1e-6)
    assert np.allclose(ours[2], [0.1, 0.2, 0.3])


def hillside(**changes):
    """tiny_grove on a 35-degree slope facing a low western sun, the camera looking straight up it at the
    slope and the sky above its vanishing line."""
    from scenes import tiny_grove

    t = 35 * DEG
    config = tiny_grove(**{"sky.sun": {"elevation": 8.0, "azimuth": 270.0}, "ground.window": [-4, -2, 4, 8],
                           "ground.sun_window": [-2, 0, 2, 5], "ground.pixel": 0.1, "ground.sun_pixel": 0.04})
    config["canopy"]["layers"] = [{"height": 4.0, "center": [round(2 * np.cos(t), 6), 0.0]}]
    config["receivers"] = {"slope": {"tilt": 35.0, "facing": 270.0}}
    config["camera"] = {"position": [round(-4 * np.cos(t), 6), 0.0, round(-4 * np.sin(t) + 4.0, 6)],
                        "look_at": [round(6 * np.cos(t), 6), 0.0, round(6 * np.sin(t) + 2.0, 6)],
                        "fov": 50.0, "resolution": [64, 36]}
    config.update(changes)
    return config


def test_a_tiny_hillside_is_seen_at_the_slopes_depth_with_its_light(tmp_path):
    from scenes import plan_of

    from pipeline.camera.pinhole import image_rays
    from pipeline.stages.frame import irradiance_maps
    from pipeline.stages.ground import FrameContext
    from pipeline.stages.slope import open_slope, plane_of, slope_background, slope_ground

    plan = plan_of(hillside(), tmp_path)
    context = FrameContext.of(plan, 0)
    ground = slope_ground(context)
    radiance, distance, horizon = slope_background(plan, irradiance_maps(plan, ground), context.sky)
    plane = plane_of(plan)
    # each pixel's depth: the world ray from the pinhole meeting the slope's plane, independently
    rows, cols = np.indices(distance.shape)
    rays = image_rays(plan.camera, cols + 0.5, rows + 0.5)
    origin = np.asarray(plan.camera.position)
    along = -((origin - plane.origin) @ plane.normal) / (rays @ plane.normal)
    world = np.where(along > 0, along * np.linalg.norm(rays, axis=-1), np.inf)
    seen = np.isfinite(distance) & np.isfinite(world) & (world < 200)
    assert seen.mean() > 0.5  # the slope fills most of the picture, far above the level ground's horizon
    assert np.allclose(distance[seen], world[seen], rtol=1e-4)
    assert np.isfinite(radiance).all() and radiance.min() >= 0 and horizon.shape == (64, 3)
    # above the slope's vanishing line the world's sky in each pixel's world direction
    sky_rows = np.flatnonzero(np.isinf(distance).all(axis=1))[:-1]
    assert len(sky_rows) > 3
    d = rays[sky_rows] / np.linalg.norm(rays[sky_rows], axis=-1, keepdims=True)
    assert np.allclose(radiance[sky_rows], context.sky.view_radiance(d, d[..., :2] / d[..., 2:]), rtol=1e-5)
    # the open slope's light is the open slope's of ``check``, the sun at its incidence
    (first,) = open_slope(plan, [0])
    assert np.allclose(ground.unshadowed, first.sun + first.sky, rtol=1e-6)
    assert first.sun[1] > 3 * np.asarray(context.sky.sun_normal_irradiance)[1] * np.sin(8 * DEG)


@pytest.mark.parametrize("changes, key", [
    ({"receivers": {"slope": {"tilt": 90.0, "facing": 270.0}}}, "receivers.slope.tilt"),
    ({"camera": {"position": [-3.0, 1.0, 2.0], "look_at": [3.0, 0.0, 3.0], "resolution": [64, 36]}},
     "camera.look_at"),
    ({"output": {"passes": ["sun"]}}, "output.passes"),
    ({"camera": {"position": [-3.0, 0.0, 2.0], "resolution": [64, 36]}}, "camera.look_at"),  # a camera in part
    ({"camera": {"look_at": [3.0, 0.0, 3.0], "resolution": [64, 36]}}, "camera.position"),
    ({"camera": {"resolution": [64, 36], "follow": "shadow"}}, "camera.follow")])
def test_what_a_slope_cannot_be_drawn_with_is_one_line_naming_the_key(tmp_path, changes, key):
    from scenes import plan_of

    with pytest.raises(ConfigError) as error:
        plan_of(hillside(**changes), tmp_path)
    assert key in str(error.value) and len(str(error.value).splitlines()) == 1


@pytest.mark.parametrize("windows", [True, False])
def test_a_camera_placed_on_a_slope_sees_sunlit_slope_and_the_trees_shade_on_it(tmp_path, windows):
    # no camera (and no windows): the plan places one on the slope, looking along its fall line towards
    # the low sun, at eye height straight above the slope; its picture of the slope's light holds
    # both sun flecks and shade, judged against the open slope's sun and sky
    from scenes import plan_of

    from pipeline.camera import pinhole
    from pipeline.core.colour import REC709_LUMINANCE
    from pipeline.stages.frame import irradiance_maps
    from pipeline.stages.ground import FrameContext
    from pipeline.stages.slope import open_slope, plane_of, slope_ground

    config = hillside(camera={"fov": 50.0, "resolution": [64, 36]})
    if not windows:
        config["ground"] = {k: v for k, v in config["ground"].items() if k not in ("window", "sun_window")}
    plan = plan_of(config, tmp_path)
    assert "camera" in plan.auto and ("ground.window" in plan.auto) is not windows
    plane = plane_of(plan)
    view = camera_in_frame(plan.camera, plane)  # along the fall line: it would raise
    x, y, z = plan.camera.position
    assert z - height_on(plane, x, y) == pytest.approx(1.7)
    assert plan.camera.pitch < -np.radians(30)  # down the slope, towards the sun in the west
    assert np.sin(plan.camera.yaw) < -0.99
    assert plan.exposure.stops < -1  # the slope facing the sun is over twice the level ground's light
    context = FrameContext.of(plan, 0)
    seen = pinhole.ground_irradiance(view, irradiance=irradiance_maps(plan, slope_ground(context)))
    light = (seen @ REC709_LUMINANCE)[pinhole.ground_fraction_rows(view) >= 1].ravel()
    (open_light,) = open_slope(plan, [0])
    sun, sky = (float(np.asarray(v) @ REC709_LUMINANCE) for v in (open_light.sun, open_light.sky))
    assert len(light) > 0.9 * 64 * 36  # the slope fills the picture
    assert np.mean(light > sky + 0.7 * sun) > 0.05, np.mean(light > sky + 0.7 * sun)  # sunlit
    assert np.mean(light < sky + 0.3 * sun) > 0.05, np.mean(light < sky + 0.3 * sun)  # shaded


def test_a_mask_image_on_a_slope_lies_parallel_to_it_at_its_distance(tmp_path):
    # canopy.layers' mask on a slope: its centre and size in the slope's (u, w) metres, its top up the
    # slope, its height along the normal. Under the sky turned with the slope (the lower half, the
    # ground's, included) it gives the level ground's raster behind the same image, unturned, at that
    # height, within 1e-4: coarse, fine and the coarse sun beyond the fine window
    from scenes import plan_of

    from pipeline.core import io
    from pipeline.sky.equirect import EquirectSky, equirect_lookup
    from pipeline.stages.slope import layers_on_slope, plane_of

    t = grille()
    t[t == 0.4] = 1.0  # the holes open: 0 and 1 survive the PNG exactly
    io.write_png(tmp_path / "grille.png", t[..., None])
    config = hillside(canopy={"mask": "grille.png", "layers": [{"height": 0.7, "center": [0.1, 1.0],
                                                                 "size": [1.6, 1.2]}]}, foreground={"model": "none"})
    plan = plan_of(config, tmp_path)
    plane = plane_of(plan)
    image = equirect_of(smooth_sphere, 256, 128)
    local_sun = unit(20 * DEG, 60 * DEG)
    world_sun = plane.world_directions(local_sun)

    def sky_at(direction):
        azimuth, elevation = np.arctan2(direction[0], direction[1]), np.arcsin(direction[2])
        return EquirectSky(image, sun=SunDisc(azimuth, elevation), sun_normal_irradiance=np.array([40.0, 35.0, 28.0]))

    (layer,) = layers_on_slope(plan, sky_at(world_sun), 0)
    window = Grid.from_window((-0.6, 0.4, 0.6, 1.6), 0.02)
    sun_window = Grid.from_window((-0.2, 0.8, 0.2, 1.2), 0.004)
    on_slope = receiver_light(lambda d: equirect_lookup(image, plane.local_directions(d)).astype(np.float64),
                              sky_at(world_sun), plane, window, [layer], sun_window=sun_window, coarse_sun=True)
    level = mask_layer(t, center=(0.1, 1.0), size=(1.6, 1.2), distance=0.7)
    on_ground = receiver_light(lambda d: equirect_lookup(image, d).astype(np.float64), sky_at(local_sun),
                               level_ground(), window, [level], sun_window=sun_window, coarse_sun=True)
    for ours, theirs in ((on_slope.sky, on_ground.sky), (on_slope.total, on_ground.total),
                         (on_slope.outer, on_ground.outer)):
        assert np.max(np.abs(ours - theirs) / theirs) < 1e-4
    assert on_ground.total.max() > 2 * on_ground.total.min()  # a real shadow
    # the image upside down (its top down the slope) is another shadow
    flipped = receiver_light(lambda d: equirect_lookup(image, d).astype(np.float64), sky_at(local_sun),
                             level_ground(), window, [mask_layer(t[::-1], center=(0.1, 1.0), size=(1.6, 1.2),
                                                                 distance=0.7)], sun_window=sun_window)
    assert np.max(np.abs(flipped.total - on_slope.total) / on_slope.total) > 0.1


def test_a_still_skys_hemisphere_raster_is_kept_and_a_moved_one_is_not():
    # the slope's hemisphere raster and irradiance are kept while the light stands still: a procedural
    # sky at another time (no clouds) reads the kept ones, equal to those made afresh; another sun,
    # another light below the horizon or another plane make their own
    from dataclasses import replace

    from pipeline.core.geometry import sky_grid
    from pipeline.receivers.hemisphere import hemisphere_irradiance, hemisphere_raster

    plane = slope(tilt=35 * DEG, facing=270 * DEG)
    grid = sky_grid((-20, -20), (40, 40), 0.1)  # to 63 degrees off the normal: past the world horizon
    sky = ProceduralSky(3.0, SunDisc(250 * DEG, 12 * DEG))
    below = np.array([0.5, 0.6, 0.4])
    first, again, later = (hemisphere_raster(world_radiance(replace(sky, time=t), below), plane, grid)
                           for t in (0.0, 1.0, 2.0))
    assert later is again and first is not again  # kept from the second ask
    fresh = hemisphere_raster(lambda d: world_radiance(sky, below)(d), plane, grid)  # a plain function: not kept
    assert np.array_equal(later.weighted, fresh.weighted) and np.array_equal(later.outside, fresh.outside)
    assert not later.weighted.flags.writeable
    for light, where in ((world_radiance(ProceduralSky(3.0, SunDisc(250 * DEG, 13 * DEG)), below), plane),
                         (world_radiance(sky, below * 1.1), plane),
                         (world_radiance(sky, below), slope(tilt=36 * DEG, facing=270 * DEG))):
        other = hemisphere_raster(light, where, grid)  # the kept one, were the key to miss what moved
        assert other is not later and np.abs(other.weighted - later.weighted).max() > 0
    plain = hemisphere_irradiance(lambda d: light(d), where)
    assert np.array_equal(hemisphere_irradiance(light, where), plain)
    assert np.array_equal(hemisphere_irradiance(light, where), plain)  # kept
    assert not np.array_equal(hemisphere_irradiance(world_radiance(sky, below), plane), plain)
