"""Framing at walls (docs/method.md, "Receivers: walls and slopes", "Framing at walls"): a camera
left out looks at the leaves' flecks on the sunlit wall, clear of the walls; ``check``'s bound
against an independent quadrature of the wall's hemisphere; no false warning where the wall takes
the leaves' shadow; the exposure of the brightest receiver in view."""

import re

import numpy as np
import pytest
from scenes import config_of, plan_of, tiny_grove, write_config

from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import direction_vector

DEG = np.pi / 180
SUN = (12.0, 250.0)  # elevation, azimuth [deg]: low in the west-south-west


def wall_scene(facing=250.0, camera=None, **changes):
    """tiny_grove's tree (crown 1.5 m round 2.6 m up) at a 12-degree sun, a 6 x 4 m wall 3 m beyond it
    from the sun (facing it at ``facing``); ``camera``, or the camera left out but for its size."""
    away = np.radians(SUN[1] + 180.0)
    config = tiny_grove(**{"canopy.height": 2.6, "sky.sun": {"elevation": SUN[0], "azimuth": SUN[1]},
                           "animation": {"frames": 3}, **changes})
    foot = [round(3.0 * float(np.sin(away)), 3), round(3.0 * float(np.cos(away)), 3)]
    config["receivers"] = {"walls": [{"foot": foot, "facing": facing,
                                      "width": 6.0, "height": 4.0, "pixel": 0.05}]}
    config["camera"] = camera or {"resolution": [96, 54]}
    return config


def test_the_placed_camera_sees_the_sunlit_wall_with_the_flecks_on_it(tmp_path):
    """Over the camera's pixels that see the wall (its rays meeting the rectangle), rays from the wall
    point to the sun tested against every leaf's ellipse (at rest): most of the wall in view sunlit,
    some of it in the leaves' shade, and the wall most of the picture."""
    from pipeline.receivers.view import wall_hits
    from pipeline.stages.inputs import grove_of
    from pipeline.stages.wall_framing import wall_planes

    config = wall_scene()
    plan = plan_of(config, tmp_path)
    assert "camera" in plan.auto
    resolved = config_of(config, tmp_path)
    plane = wall_planes(resolved)[0]
    hits = wall_hits(plan.camera, plane, samples=1)
    seen = hits.hit[0]
    assert seen.sum() > 0.5 * plan.camera.width * plan.camera.height
    points = plane.world_points(np.column_stack([hits.u[0][seen], hits.w[0][seen], np.zeros(seen.sum())]))
    leaves = grove_of(resolved.canopy)[0].leaves  # at rest
    s = direction_vector(SUN[1] * DEG, SUN[0] * DEG)
    n = np.cross(leaves.axis_u, leaves.axis_v)
    t = np.einsum("plk,lk->pl", leaves.center[None] - points[:, None], n) / (n @ s)  # along the ray to each leaf
    h = points[:, None] + t[..., None] * s - leaves.center[None]
    a = np.einsum("plk,lk->pl", h, leaves.axis_u) / np.sum(leaves.axis_u ** 2, axis=1)
    b = np.einsum("plk,lk->pl", h, leaves.axis_v) / np.sum(leaves.axis_v ** 2, axis=1)
    shaded = np.any((t > 0) & (a * a + b * b <= 1.0), axis=1)
    assert 0.5 < 1.0 - shaded.mean() < 0.95  # mostly the sunlit wall, and the leaves' shade in view
    assert plane.local_points(plan.camera.position)[2] > 0.5  # in front of it


def test_the_placed_camera_stands_clear_of_a_second_wall_where_it_would_first_stand(tmp_path):
    """A second wall across the first-chosen place: the camera goes elsewhere, in front of both."""
    from pipeline.stages.wall_framing import camera_wall_problem, wall_planes

    config = wall_scene()
    plan = plan_of(config, tmp_path)
    x, y, _ = plan.camera.position
    config["receivers"]["walls"].append({"name": "wall1", "foot": [float(x), float(y)], "facing": 250.0,
                                         "width": 2.0, "height": 3.0, "pixel": 0.1})
    moved = plan_of(config, tmp_path)
    assert "camera" in moved.auto and moved.camera.position != plan.camera.position
    assert all(camera_wall_problem(moved.camera, p) is None for p in wall_planes(config_of(config, tmp_path)))


def _hemisphere_quadrature(sky, normal, ground, n=96):
    """The irradiance of a plane of ``normal`` [1] from the sky above the horizon and a uniform
    ``ground`` radiance below: Gauss-Legendre in cos(theta) about the normal, midpoints in phi."""
    x, wx = np.polynomial.legendre.leggauss(n)
    mu, wmu = (x + 1) / 2, wx / 2  # cos(theta) in (0, 1)
    phi = (np.arange(2 * n) + 0.5) * np.pi / n
    a = np.cross(normal, [0.0, 0.0, 1.0])
    a = a / np.linalg.norm(a)
    b = np.cross(normal, a)
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m * m)
    d = (m[..., None] * normal + (s * np.cos(p))[..., None] * a + (s * np.sin(p))[..., None] * b).reshape(-1, 3)
    weight = (m * wmu[:, None] * (np.pi / n)).reshape(-1)  # cos(theta) d(cos theta) d(phi)
    radiance = np.tile(np.asarray(ground, dtype=np.float64), (len(d), 1))
    up = d[:, 2] > 0
    w = d[up].copy()
    w[:, 2] = np.maximum(w[:, 2], 1e-3)  # the sky just above the horizon, read as the camera does
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    radiance[up] = sky.view_radiance(w, w[:, :2] / w[:, 2:])
    return (radiance * weight[:, None]).sum(axis=0)


def test_checks_bound_is_the_suns_incidence_and_a_quadrature_of_the_walls_hemisphere(tmp_path, capsys):
    """A wall 20 degrees round from the sun: its incidence arccos(s.n) from the sun's and the
    normal's vectors, its sun the sun's normal irradiance times s.n, its sky an independent
    quadrature (the sky model's radiance above, the open ground's mean radiance below)."""
    from pipeline.cli.main import main
    from pipeline.sky.sun_kernel import sun_irradiance
    from pipeline.stages.inputs import albedo_mipmap

    config = wall_scene(facing=230.0, camera={"position": [-4.0, -4.0, 1.7], "look_at": [2.8, 1.0, 1.5],
                                              "resolution": [64, 36]}, animation={"frames": 1})
    assert main(["check", str(write_config(tmp_path, config))]) == 0
    out = capsys.readouterr()
    line = next(line for line in out.out.splitlines() if line.startswith("  wall wall0"))
    angle, sun, sky, bound = (float(v) for v in re.search(
        r"frame 0: sun ([\d.]+) degrees off its normal, sun ([\d.]+) klx, sky ([\d.]+) klx, a fleck at most "
        r"([\d.]+) x", line).groups())
    s = direction_vector(SUN[1] * DEG, SUN[0] * DEG)
    normal = np.array([np.sin(230 * DEG), np.cos(230 * DEG), 0.0])
    assert angle == pytest.approx(np.degrees(np.arccos(s @ normal)), abs=0.5)  # 23.3 degrees
    plan = plan_of(config, tmp_path)
    open_sky = plan.sky.at(plan.scenes[0])
    level_sun = sun_irradiance(open_sky)
    ground = albedo_mipmap(plan.ground).mean * (np.asarray(open_sky.sky_irradiance) + level_sun) / np.pi
    want_sun = float(level_sun @ REC709_LUMINANCE) / s[2] * float(s @ normal)
    want_sky = float(_hemisphere_quadrature(open_sky, normal, ground) @ REC709_LUMINANCE)
    assert sun == pytest.approx(want_sun, rel=0.01, abs=0.05)
    assert sky == pytest.approx(want_sky, rel=0.01, abs=0.05)
    assert bound == pytest.approx((want_sun + want_sky) / want_sky, rel=0.01)
    assert bound > 3.0  # a sun-facing wall at a 12-degree sun, against 2.1 on the level ground
    assert "receivers: the level ground" in out.out


def test_no_false_warning_where_the_wall_takes_the_leaves_shadow(tmp_path):
    """The ground's sun window by the trunk: every leaf's shadow falls on the wall, so none is
    missed; without the wall the same window misses them (the warning the wall-less plan gives)."""
    from pipeline.stages.framing import framing_warnings

    changes = {"ground": {"window": [-6, -6, 6, 6], "pixel": 0.1, "sun_window": [-1, -1, 1, 1], "sun_pixel": 0.04}}
    config = wall_scene(camera={"position": [-1.0, -5.0, 1.7], "look_at": [2.8, 1.0, 1.5], "resolution": [64, 36]},
                        **changes)
    resolved = config_of(config, tmp_path)
    assert not [w for w in framing_warnings(resolved, plan_of(config, tmp_path)) if "leaves' shadow" in w]
    del config["receivers"]
    bare = config_of(config, tmp_path)
    assert [w for w in framing_warnings(bare, plan_of(config, tmp_path)) if "leaves' shadow falls outside" in w]


def test_the_exposure_is_the_sunlit_walls_and_the_ground_alone_keeps_its_own(tmp_path):
    """With the wall filling the picture, the plan's stops are the config's less log2 of the wall's open
    light over the ground's; without walls, the config's exactly."""
    from pipeline.stages.wall_framing import open_receivers

    config = wall_scene(camera={"resolution": [96, 54], "exposure": 0.5})
    plan = plan_of(config, tmp_path)
    ground, wall = open_receivers(config_of(config, tmp_path), plan.sky.at(plan.scenes[1]), exact=False)
    assert plan.exposure.stops == pytest.approx(0.5 - np.log2((wall.sun + wall.sky) / (ground.sun + ground.sky)))
    assert plan.exposure.stops < -1.0
    del config["receivers"]
    assert plan_of(config, tmp_path).exposure.stops == 0.5


def test_a_camera_placed_for_the_ground_is_turned_out_from_behind_a_wall(tmp_path):
    """A high sun throws the shadow on the ground; a wall 2 m east leaning back, facing away from
    where the ground's framing would stand the camera: the camera is turned round its target until
    it stands clear of the wall (without the turn the plan refuses it, behind the wall)."""
    from pipeline.stages.wall_framing import camera_wall_problem, wall_planes

    config = tiny_grove()
    config["receivers"] = {"walls": [{"foot": [2.0, 0.0], "facing": 150.0, "tilt": 55.0, "width": 2.0,
                                      "height": 2.0, "pixel": 0.05}]}
    config["camera"] = {"resolution": [64, 36]}
    before = plan_of({k: v for k, v in config.items() if k != "receivers"}, tmp_path).camera
    planes = wall_planes(config_of(config, tmp_path))
    assert camera_wall_problem(before, planes[0]) == "behind"
    after = plan_of(config, tmp_path).camera
    assert camera_wall_problem(after, planes[0]) is None
    assert after.position[2] == before.position[2] and after.pitch == before.pitch
