"""A placed camera that follows the shadow over a time span (``camera.follow``), and its sun
window that moves with it (docs/method.md, "Framing"). Small groves and small frames."""

from dataclasses import replace

import numpy as np
import pytest
from test_framing import site_config, write

from pipeline.cache.keys import key_of
from pipeline.cache.store import Cache
from pipeline.camera import pinhole as camera
from pipeline.cli.main import main
from pipeline.core import io
from pipeline.core.geometry import sky_plane_from_direction
from pipeline.stages import cycle
from pipeline.stages.frame import render_frame
from pipeline.stages.framing import crown_centre, seen_ground, shadow_extents
from pipeline.stages.ground import render_ground
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load
from pipeline.stages.scene import shading_scenes

FEW_PIXELS = 3.0
"""The most a following camera lets the shadow's own points jump from one frame to the next. [pixel]"""


def sunset_span(frames=48, **camera_keys) -> dict:
    """One tree 6 m high at Madrid from 17:40 to 18:20 UTC on 2026-08-12 (the sun from 17 down to
    9.5 degrees, the eclipse's sunset): its shadow moves about 20 m."""
    config = site_config(40.42, -3.70, "2026-08-12T17:40:00Z", **camera_keys)
    config["sky"]["time"]["end"] = "2026-08-12T18:20:00Z"
    config["canopy"]["trees"]["leaves_per_tree"] = 3000
    config["camera"]["resolution"] = [160, 90]
    config["ground"]["pixel"] = 0.1
    config["render"] = {"sun_cells": 4}
    config["animation"] = {"frames": frames}
    return config


def shadow_in_image(plan, config, views):
    """(u, v) per frame of the shadow of the crown's centre along that frame's sun, seen by that
    frame's camera [pixel]."""
    centre = crown_centre(config)
    points = []
    for view, scene in zip(views, plan.scenes):
        s = np.array(sky_plane_from_direction(scene.sun.azimuth, np.pi / 2 - scene.sun.elevation))
        u, v, _ = camera.project_points(view, np.append(centre[:2] - centre[2] * s, 0.0))
        points.append((float(u), float(v)))
    return np.array(points)


def test_a_following_camera_keeps_the_shadow_still_where_a_fixed_one_loses_it(tmp_path):
    path = write(tmp_path, sunset_span())
    config = load(path)
    plan = plan_run(config)
    assert plan.follow is not None and "camera" in plan.auto  # auto: the shadow strays
    views = [plan.at(f).camera for f in range(plan.frames)]
    assert len({v.yaw for v in views}) == 1 and len({v.pitch for v in views}) == 1  # it pans, no turn
    assert views[len(views) // 2] == plan.camera
    followed = shadow_in_image(plan, config, views)
    steps = np.hypot(*np.diff(followed, axis=0).T)
    assert steps.max() <= FEW_PIXELS
    assert np.all((followed[:, 0] > 0) & (followed[:, 0] < 160) & (followed[:, 1] > 0) & (followed[:, 1] < 90))
    fixed = shadow_in_image(plan, config, [plan.camera] * plan.frames)
    assert np.hypot(*(fixed[0] - fixed[-1])) > 10 * np.hypot(*(followed[0] - followed[-1]))
    # the camera walks with the shadow: as far as the shadow's centre moves, within 1 m
    walk = np.subtract(views[-1].position[:2], views[0].position[:2])
    centre = crown_centre(config)
    ends = [np.array(sky_plane_from_direction(plan.scenes[f].sun.azimuth, np.pi / 2 - plan.scenes[f].sun.elevation))
            for f in (0, -1)]
    assert np.linalg.norm(walk) > 10.0
    assert np.linalg.norm(walk + centre[2] * (ends[1] - ends[0])) < 1.0


def test_the_sun_window_follows_the_camera_and_renders_as_that_window_given(tmp_path):
    path = write(tmp_path, sunset_span(frames=6))
    plan = plan_run(load(path))
    assert plan.follow is not None
    store = Cache(tmp_path / "cache")
    f = 5
    seen = plan.at(f)
    move = np.subtract(seen.camera.position[:2], plan.camera.position[:2])
    shift = np.subtract(seen.sun_window.extent[:2], plan.sun_window.extent[:2])
    assert np.linalg.norm(move) > 5.0 and np.all(np.abs(shift - move) <= plan.sun_window.pixel / 2 + 1e-9)
    assert seen.sun_window.shape == plan.sun_window.shape  # the cost of a frame stays that of the middle one
    assert [lp.sun.mask for lp in seen.layers] == [lp.sun.mask for lp in plan.layers]  # one cached mask
    # the reference: the same config with that frame's windows and camera given
    given = sunset_span(frames=6, follow="fixed")
    given["ground"].update(window=list(plan.window.extent), sun_window=list(seen.sun_window.extent),
                           sun_pixel=plan.sun_window.pixel)
    reference = plan_run(load(write(tmp_path, given, "given.yaml")))
    assert reference.follow is None and reference.sun_window == seen.sun_window
    ours = render_ground(plan, f, store=store).irradiance
    theirs = render_ground(reference, f, store=Cache(tmp_path / "other")).irradiance
    assert np.abs(ours - theirs).max() <= 1e-4 * theirs.max()


@pytest.mark.parametrize("keys, fixed", [({"follow": "fixed"}, True), ({}, False)])
def test_follow_fixed_or_a_fixed_sun_keeps_one_camera(tmp_path, keys, fixed):
    config = sunset_span(frames=4, **keys)
    if not fixed:  # one sun for every frame: nothing to follow
        config["sky"] = {"model": "cie", "sun": {"elevation": 12.0, "azimuth": 250.0}, "turbidity": 3.0}
    plan = plan_run(load(write(tmp_path, config)))
    assert plan.follow is None and plan.at(3) is plan


@pytest.mark.parametrize("keys, message", [
    ({"follow": "pan"}, "camera.follow"),
    ({"follow": "shadow", "position": [0.0, 0.0, 1.7]}, "camera.follow"),
])
def test_a_bad_follow_is_a_one_line_error_naming_the_key(tmp_path, capsys, keys, message):
    path = write(tmp_path, sunset_span(frames=4, **keys))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


@pytest.mark.parametrize("key, value, named", [
    ("sun_window", [0.0, 0.0, 2.0, 2.0], "ground.sun_window"),
    ("window", [-20.0, -20.0, 20.0, 20.0], "ground.window"),
    ("layout", "periodic", "periodic"),
])
def test_follow_shadow_with_a_given_window_or_a_periodic_canopy_is_refused(tmp_path, capsys, key, value, named):
    config = sunset_span(frames=4, follow="shadow")
    (config["canopy"] if key == "layout" else config["ground"])[key] = value
    assert main(["check", str(write(tmp_path, config))]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "camera.follow" in err and named in err


def test_check_says_the_camera_follows_and_how_far_it_walks(tmp_path, capsys):
    path = write(tmp_path, sunset_span(frames=4, follow="shadow"))
    plan = plan_run(load(path))
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    walked = np.hypot(*np.subtract(plan.at(3).camera.position[:2], plan.at(0).camera.position[:2]))
    assert walked > 5.0 and f"follows the shadow, walking {walked:.1f} m" in out


def test_check_gives_the_open_ground_s_light_and_the_frames_whose_sun_is_set(tmp_path, capsys):
    """At a low sun a fleck stands little above the shade: check says how little, from the sky's own
    light, and which frames the sky alone lights."""
    config = sunset_span(frames=4)
    config["sky"]["time"] = {"start": "2026-08-12T18:50:00Z", "end": "2026-08-12T19:30:00Z"}  # Madrid: 4 to -3 degrees
    path = write(tmp_path, config)
    plan = plan_run(load(path))
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    light = next(line for line in out.splitlines() if "light on open ground" in line)
    sky = plan.sky.at(plan.scenes[0])
    sun_lux = 1000 * float(sky.sun_fraction() * np.asarray(sky.undimmed_sun_irradiance()) @ [0.2126, 0.7152, 0.0722])
    assert f"frame 0 (sun {np.degrees(plan.scenes[0].sun.elevation):.1f} degrees): sun {sun_lux:.0f} lx" in light
    set_frames = [f for f in range(4) if plan.scenes[f].sun.elevation < 0]
    assert set_frames and f"in {len(set_frames)} of 4 frames" in out and "the sky alone lights them" in out


def test_a_yaml_boolean_where_a_word_is_wanted_says_so(tmp_path, capsys):
    path = write(tmp_path, sunset_span(frames=4, follow=True))  # what YAML makes of `follow: yes`
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "camera.follow: unknown value True (YAML reads yes" in err


def test_a_preview_of_a_bad_config_is_the_error_s_one_line(tmp_path, capsys):
    """The preview's line comes once the config holds: a span past civil twilight is refused in one line
    with --preview too, and nothing is written."""
    config = sunset_span(frames=4)
    config["sky"]["time"]["end"] = "2026-08-12T20:40:00Z"  # Madrid: 15 degrees below the horizon
    path = write(tmp_path, config)
    assert main(["render", str(path), "--preview", "--output", str(tmp_path / "run"),
                 "--cache", str(tmp_path / "cache")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and "sky.time.end" in captured.err
    assert not (tmp_path / "run").exists()


def test_auto_keeps_one_camera_over_a_given_window(tmp_path):
    """The light is computed on the window given: a camera that walked off it would see ground the
    window does not hold."""
    config = sunset_span(frames=4)
    assert plan_run(load(write(tmp_path, config, "placed.yaml"))).follow is not None
    config["ground"]["window"] = [-30.0, -30.0, 30.0, 30.0]
    assert plan_run(load(write(tmp_path, config, "given.yaml"))).follow is None


def test_a_following_camera_s_trees_are_made_and_kept_per_camera(tmp_path):
    """Built-in trees in the picture are drawn for each frame's camera: the cycle phase, the keys a
    run holds in use and the disk estimate count one item per camera and cycle frame."""
    config = sunset_span(frames=4, follow="shadow")
    config["foreground"] = {"model": "trees"}
    plan = plan_run(load(write(tmp_path, config)))
    assert plan.follow is not None and plan.canopy.cycle == 1
    views = cycle.foreground_views(plan, [0])
    assert len(views) == len({plan.at(f).camera for f in range(4)}) == 4
    keys = cycle.config_item_keys(plan)
    for f in range(4):
        assert key_of("foreground", cycle.foreground_params(plan.at(f), 0)) in keys
    fixed = replace(plan, follow=None)
    assert cycle.disk_needed(plan).cache_bytes - cycle.disk_needed(fixed).cache_bytes == pytest.approx(
        3 * 8 * 4 * plan.camera.width * plan.camera.height)


def test_a_given_camera_hashes_alike_whatever_its_follow(tmp_path):
    """A camera given where it stands never follows: the key leaves its config's digest (and the
    frames' config_hash) as it was; a placed camera's digest tells follow's values apart."""
    digests = {}
    for follow in ("auto", "fixed"):
        given = sunset_span(frames=4, follow=follow, position=[0.0, 0.0, 1.7], look_at=[5.0, 0.0, 0.0])
        placed = sunset_span(frames=4, follow=follow)
        digests[follow] = (load(write(tmp_path, given, f"given-{follow}.yaml")).digest(),
                           load(write(tmp_path, placed, f"placed-{follow}.yaml")).digest())
    assert digests["auto"][0] == digests["fixed"][0]
    assert digests["auto"][1] != digests["fixed"][1]


def test_the_placed_window_holds_the_ground_the_cameras_see_and_no_more(tmp_path):
    """The placed window is what the cameras see over the span (each frame's sun window in it),
    far less than the shadow's union, and the frames read it as they read that union."""
    config = sunset_span(frames=6)
    resolved = load(write(tmp_path, config))
    plan = plan_run(resolved)
    pixel = plan.window.pixel
    x0, y0, x1, y1 = plan.window.extent
    boxes = np.array(shadow_extents(resolved, shading_scenes(list(plan.scenes)), plan.projection))
    shadow = (*(boxes[:, :2].min(axis=0) - 3.0), *(boxes[:, 2:].max(axis=0) + 3.0))  # half a crown height
    for f in range(plan.frames):
        seen = plan.at(f)
        points, _ = seen_ground(seen.camera)  # what it sees of the shadow's union is in the window
        points = points[(points[:, 0] >= shadow[0] + pixel) & (points[:, 0] <= shadow[2] - pixel)
                        & (points[:, 1] >= shadow[1] + pixel) & (points[:, 1] <= shadow[3] - pixel)]
        assert len(points) > 1000
        assert points[:, 0].min() >= x0 - pixel and points[:, 0].max() <= x1 + pixel
        assert points[:, 1].min() >= y0 - pixel and points[:, 1].max() <= y1 + pixel
        a, b, c, d = seen.sun_window.extent
        assert a >= x0 - pixel and b >= y0 - pixel and c <= x1 + pixel and d <= y1 + pixel
    area = (x1 - x0) * (y1 - y0)  # 551 m^2 against 1034 m^2 of the shadow's union
    assert area < 0.6 * (shadow[2] - shadow[0]) * (shadow[3] - shadow[1])
    # the same frame with the shadow's union given as the window: the same picture
    f = 5
    seen = plan.at(f)
    wide = sunset_span(frames=6, follow="fixed", position=list(seen.camera.position),
                       yaw=float(np.degrees(seen.camera.yaw)), pitch=float(np.degrees(seen.camera.pitch)))
    wide["ground"].update(window=[float(v) for v in shadow], sun_window=list(seen.sun_window.extent),
                          sun_pixel=seen.sun_window.pixel)
    reference = plan_run(load(write(tmp_path, wide, "wide.yaml")))
    ours = render_frame(plan, f, store=Cache(tmp_path / "cache")).radiance
    theirs = render_frame(reference, f, store=Cache(tmp_path / "other")).radiance
    # measured: 9.6e-4 of the largest value at most, 4.7e-6 of the mean on average (the coarse
    # lattice moved with the window)
    assert np.abs(ours - theirs).max() <= 0.005 * theirs.max()
    assert np.abs(ours - theirs).mean() <= 1e-4 * theirs.mean()


def test_follow_shadow_with_imported_foreground_passes_is_refused(tmp_path, capsys):
    """Imported passes were rendered from one camera: a camera that walks would leave them."""
    for name in ("sun", "sky", "alpha"):
        io.write_exr(tmp_path / f"fg_{name}.0000.exr", np.zeros((90, 160, 3 if name != "alpha" else 1), np.float32))
    config = sunset_span(frames=4, follow="shadow")
    config["foreground"] = {"model": "passes", "sun": "fg_sun.%04d.exr", "sky": "fg_sky.%04d.exr",
                            "alpha": "fg_alpha.%04d.exr"}
    assert main(["check", str(write(tmp_path, config))]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "camera.follow" in err and "passes" in err
    config["camera"]["follow"] = "auto"  # auto keeps one camera for them
    plan = plan_run(load(write(tmp_path, config)))
    assert plan.follow is None
