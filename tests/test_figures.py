"""Tests of pipeline.cli.figures: the whole preview set is written, every PNG is readable and shows
what its figure should (Max 1991, Figs. 4 to 7, 10 to 13, 16 and S(t)); the I0 quadrature
against the closed form and the paper's 0.90 at 70 degrees; the scenes stand without configs/."""

from __future__ import annotations

import contextlib
import io as io_module
from pathlib import Path

import numpy as np
import pytest

from pipeline.camera import composite
from pipeline.cli import figures
from pipeline.cli.main import main
from pipeline.core import io
from pipeline.core.geometry import I0
from pipeline.stages.plan import plan_run


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The preview set, written once for the module by ``sunshade figures``: (folder, paths
    it names, its output)."""
    folder = tmp_path_factory.mktemp("figures") / "out"
    cache = folder.parent / "cache"
    out = io_module.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["figures", "--preview", "--output", str(folder), "--cache", str(cache)]) == 0
    paths = [Path(line.split(": ", 1)[0]) for line in out.getvalue().splitlines()[:-1]]
    return folder, paths, out.getvalue()


def _image(folder, name) -> np.ndarray:
    return io.read_image(folder / name)


def test_every_figure_is_written_in_order_as_a_readable_png(written):
    folder, paths, output = written
    names = [name for name, _ in figures.FIGURES]
    assert [p.name for p in paths] == names
    assert len(set(names)) == len(names) and all(n.endswith(".png") for n in names)
    assert all(caption.strip() for _, caption in figures.FIGURES)
    assert f"sunshade: {len(names)} figures" in output
    for path in paths:
        assert path.parent == folder and path.stat().st_size > 0
        image = io.read_image(path)
        assert image.ndim == 3 and min(image.shape[:2]) >= 16
        assert np.all(np.isfinite(image)) and image.min() >= 0 and image.max() <= 1
    leftovers = [p.name for p in folder.iterdir() if p.name.startswith(".")]
    assert not leftovers  # no temporary files left behind


def test_the_mask_holds_open_sky_and_leaves(written):
    mask = _image(written[0], "fig04-mask.png")[..., 0]
    assert mask.shape[0] > 50 and mask.shape[1] > 50
    assert (mask > 0.9).mean() > 0.2  # open sky between and around the crowns
    assert (mask < 0.1).mean() > 0.01  # leaves and wood


def test_the_sky_and_its_raster_show_structure(written):
    folder = written[0]
    for name in ("fig05-sky.png", "fig06-sky-raster.png"):
        image = _image(folder, name)
        assert image.shape[2] == 3 and image.std() > 0.02
        assert image.max() > 0.95  # the sun (and its glow) is the brightest thing
        assert image[..., 2].mean() > image[..., 0].mean()  # a blue sky
    # the weighted raster is dimmer towards its edges (cos^4), the sky-plane picture is not
    raster = _image(folder, "fig06-sky-raster.png") @ composite.REC709_LUMINANCE
    rows, cols = raster.shape
    middle = raster[rows // 3: 2 * rows // 3, cols // 3: 2 * cols // 3].mean()
    border = np.concatenate([raster[:rows // 10].ravel(), raster[-rows // 10:].ravel()]).mean()
    assert border < 0.85 * middle


def test_ground_rasters_hold_light_and_shade(written):
    folder = written[0]
    ground = _image(folder, "fig07-ground.png") @ composite.REC709_LUMINANCE
    assert ground.std() > 0.02
    assert np.percentile(ground, 95) > 0.75  # open ground: near 80% before the sRGB curve
    assert np.percentile(ground, 1) < 0.7 * np.percentile(ground, 95)  # shade
    eclipse = _image(folder, "fig12-eclipse-ground.png") @ composite.REC709_LUMINANCE
    assert eclipse.std() > 0.02


def test_shadows_fall_away_from_the_sun(written):
    """The sun of the grove is in the south-south-east, so the shade of the ground raster lies
    north-west of its centre: north up, east to the right."""
    ground = _image(written[0], "fig07-ground.png") @ composite.REC709_LUMINANCE
    config = figures.scene_config("grove", preview=True)
    x0, y0, x1, y1 = config.ground.window
    rows, cols = ground.shape
    shade = ground < np.percentile(ground, 20)
    r, c = np.nonzero(shade)
    x = x0 + (c.mean() + 0.5) / cols * (x1 - x0)
    y = y1 - (r.mean() + 0.5) / rows * (y1 - y0)
    trees = config.canopy.layers[0].center
    assert x < trees[0] - 0.5 and y > trees[1] + 2.0


def test_frames_are_pictures_and_the_point_sun_has_a_black_sky(written):
    folder = written[0]
    frame = _image(folder, "fig10-frame.png")
    point = _image(folder, "fig11-point-sun.png")
    eclipse = _image(folder, "fig13-eclipse-frame.png")
    for image in (frame, point, eclipse):
        assert image.shape == (180, 320, 3) and image.std() > 0.03
    assert frame[:20].mean() > 0.3  # sky in the top rows
    assert point[:20, -40:].max() < 0.05  # no sky light: the sky is black
    # the eclipse darkens the day (and the camera looks down at the shade)
    assert eclipse.mean() < frame.mean()


def test_plots_are_drawn(written):
    folder = written[0]
    for name in ("fig16-i0.png", "sun-fraction.png"):
        plot = _image(folder, name)
        assert plot.shape[2] == 3 and plot.shape[0] > 200
        assert (plot.mean(axis=-1) > 0.98).mean() > 0.5  # a white page
        assert (plot.mean(axis=-1) < 0.3).mean() > 0.005  # axes and text
        coloured = plot.max(axis=-1) - plot.min(axis=-1) > 0.3
        assert coloured.mean() > 0.002  # the curves


def test_i0_quadrature_matches_the_closed_form_and_the_paper():
    alpha = np.radians(np.arange(1.0, 90.0, 1.0))
    np.testing.assert_allclose(figures.i0_quadrature(alpha), I0(alpha), rtol=1e-6)
    assert figures.i0_quadrature(np.radians(70.0)) / np.pi == pytest.approx(0.90, abs=0.005)
    assert figures.i0_quadrature(np.radians(89.999)) == pytest.approx(np.pi, rel=1e-4)


def test_sun_fraction_goes_to_zero_in_totality_and_back():
    config = figures.scene_config("dallas-2024", preview=True)
    times, fraction, area = figures.sun_fraction_curve(config)
    assert len(times) == len(fraction) == len(area) == config.animation.frames
    assert fraction[0] == pytest.approx(1.0) and fraction[-1] == pytest.approx(1.0)
    assert fraction.min() < 0.02 and np.all((fraction >= 0) & (fraction <= 1))
    assert np.abs(fraction - area).max() < 0.1  # limb darkening moves S a little off the area


@pytest.mark.parametrize("name", sorted(figures.SCENES))
@pytest.mark.parametrize("preview", [False, True])
def test_scenes_load_from_their_own_text(name, preview, tmp_path, monkeypatch):
    """Every scene is a valid config on its own, wherever the process runs."""
    monkeypatch.chdir(tmp_path)
    config = figures.scene_config(name, preview=preview)
    assert config.animation.frames >= 1
    if name != "dallas-2024":
        plan_run(config)  # the grids fit together


def test_preview_merges_without_touching_the_scene_text():
    before = dict(figures.PREVIEW["grove"])
    full = figures.scene_config("grove")
    quick = figures.scene_config("grove", preview=True)
    assert figures.PREVIEW["grove"] == before
    assert quick.ground.pixel == 4 * full.ground.pixel
    assert quick.camera.resolution == (320, 180)
    assert quick.canopy.trees.leaves_per_tree * quick.canopy.trees.leaf_length**2 == pytest.approx(
        full.canopy.trees.leaves_per_tree * full.canopy.trees.leaf_length**2)
    assert quick.sky == full.sky


def test_the_brdf_figure_shows_the_hot_spot_brighter_than_lambert(written):
    """brdf-lawn.png: Lambert left, grass in the middle, sand right, at one exposure: round the
    antisolar point (bottom middle, the viewer has the sun behind) grass and sand are brighter
    (preview: 1.37 and 1.15 times Lambert there)."""
    image = _image(written[0], "brdf-lawn.png")
    third = image.shape[1] // 3
    left, middle_panel, right = (image[:, i * third + 2: (i + 1) * third - 2] for i in range(3))
    rows = slice(int(0.75 * image.shape[0]), None)
    middle = slice(int(0.4 * left.shape[1]), int(0.6 * left.shape[1]))
    assert middle_panel[rows, middle].mean() > 1.1 * left[rows, middle].mean()
    assert right[rows, middle].mean() > 1.05 * left[rows, middle].mean()
