"""The camera's reads of a wall (``receivers.view``): the compiled loops (``kernels.arrays.taps_read``,
``points_over``) give the bits of their array versions and of the plain bilinear
formula, on random points and on a real wall's raster where a camera's points see it; the walls' shade on the
ground (``walls_on_ground``), the mean of a wall's light (``rows_sum``) and the haze of the walls' distances
give numpy's bits (docs/accuracy.md, "The walls' cycle products and a wall's cost")."""

import numpy as np
import pytest

from pipeline.camera.pinhole import Camera
from pipeline.core.geometry import Grid
from pipeline.kernels.arrays import rows_sum, walls_on_ground
from pipeline.receivers.hemisphere import world_radiance
from pipeline.receivers.layers import mask_layer
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import wall
from pipeline.receivers.view import (
    bilinear_taps,
    read_taps,
    read_taps_arrays,
    show_points,
    wall_hits,
    wall_points,
)
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.scattering import haze_transmittance
from pipeline.sky.sun_disc import SunDisc
from pipeline.stages.walls import distance_haze

DEG = np.pi / 180


def bilinear_formula(grid: Grid, image: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The raster read at (u, w) by the textbook formula, edges held, in float64 from float32 points."""
    x = np.clip((u - grid.origin[0]) / grid.pixel - 0.5, 0.0, grid.shape[1] - 1.0)
    y = np.clip((grid.origin[1] - w) / grid.pixel - 0.5, 0.0, grid.shape[0] - 1.0)
    c0 = np.minimum(x.astype(np.int64), grid.shape[1] - 2)
    r0 = np.minimum(y.astype(np.int64), grid.shape[0] - 2)
    fx, fy = (x - c0).astype(np.float64)[:, None], (y - r0).astype(np.float64)[:, None]
    top = image[r0, c0] * (1 - fx) + image[r0, c0 + 1] * fx
    bottom = image[r0 + 1, c0] * (1 - fx) + image[r0 + 1, c0 + 1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def assert_reads_agree(grid: Grid, image: np.ndarray, u: np.ndarray, w: np.ndarray) -> None:
    taps = bilinear_taps(grid, u, w)
    assert taps.fx.dtype == np.float32 and taps.corners[0].dtype == np.int32  # the compiled loop's types
    compiled = read_taps(image, taps)
    assert compiled.tobytes() == read_taps_arrays(image.reshape(-1, 3), taps).tobytes()
    assert compiled.tobytes() == bilinear_formula(grid, image, u, w).tobytes()


def test_the_compiled_read_is_the_array_reads_bits_on_random_points():
    """Points inside, on the edges and beyond a random raster with values over 12 decades."""
    rng = np.random.default_rng(7)
    grid = Grid(origin=(-1.3, 2.1), pixel=0.05, shape=(37, 53))
    image = (10.0 ** rng.uniform(-6, 6, (*grid.shape, 3))).astype(np.float32)
    u = rng.uniform(-1.5, -1.3 + 53 * 0.05 + 0.2, 20000).astype(np.float32)
    w = rng.uniform(2.1 - 37 * 0.05 - 0.2, 2.3, 20000).astype(np.float32)
    u[:50] = np.float32(-1.3 + 0.025)  # on the first centre column
    assert_reads_agree(grid, image, u, w)


def test_the_compiled_reads_are_the_array_versions_bits_on_a_real_wall():
    """A wall's irradiance under a grille and a low sun, read where a camera's 3 x 3 points per
    pixel see it (partly hidden behind a near background): the bits of the numpy reads."""
    plane = wall((0.0, 4.0, 0.0), facing=200 * DEG, width=3.0, height=2.0)
    sky = ProceduralSky(3.0, SunDisc(200 * DEG, 12 * DEG))
    bars = np.ones((24, 24), np.float32)
    bars[:, ::4] = 0.0
    window = Grid.from_window((-1.5, 0.0, 1.5, 2.0), 0.04)
    light = receiver_light(world_radiance(sky, np.full(3, 0.1)), sky, plane, window,
                           [mask_layer(bars, center=(0.0, 1.0), size=(1.5, 1.5), distance=0.4)], sun_window=window)
    raster = np.ascontiguousarray(light.total.transpose(1, 2, 0), dtype=np.float32)
    assert raster.max() > 1.5 * raster.min()  # the grille's shadow on it
    camera = Camera.look_at((1.0, -2.0, 1.5), (0.0, 4.0, 1.0), vertical_fov=40 * DEG, width=64, height=48)
    hits = wall_hits(camera, plane)
    distance = np.full((48, 64), np.inf, np.float32)
    distance[30:, :20] = 3.0  # nearer than the wall: those points keep the picture's
    rows, cols = hits.region
    seen = hits.hit & (hits.distance < distance[rows, cols][None])
    assert 0 < seen.sum() < hits.hit.sum()
    for k in range(len(seen)):
        assert_reads_agree(window, raster, hits.u[k][seen[k]], hits.w[k][seen[k]])


def numpy_show(picture, depth, hits, image, points_u, points_w, grid, albedo, scale):
    """A wall put into a picture with numpy alone: each sample's seen points read bilinearly
    (``read_taps_arrays``), times the albedo and ``scale``, summed into their pixels sample after
    sample by fancy indexing, then blended by cover as ``show_points`` documents."""
    rows, cols = hits.region
    seen = hits.hit & (hits.distance < depth[rows, cols][None])
    weight = np.float32(1 / len(seen))
    total = np.zeros((*seen.shape[1:], 3), np.float32)
    for k in range(len(seen)):
        taps = bilinear_taps(grid, points_u[k][seen[k]], points_w[k][seen[k]])  # in pixel order
        colour = albedo if albedo.ndim == 1 else albedo[k][seen[k]]
        values = read_taps_arrays(image.reshape(-1, 3), taps) * colour * scale
        total.reshape(-1, 3)[np.flatnonzero(seen[k])] += values * weight
    coverage = seen.sum(axis=0, dtype=np.float32) * weight
    picture[rows, cols] = picture[rows, cols] * (1 - coverage)[..., None] + total
    nearest = np.where(seen, hits.distance, np.inf).min(axis=0).astype(np.float32)
    depth[rows, cols] = np.where(coverage > 0.5, nearest, depth[rows, cols])


def test_the_walls_one_pass_show_is_numpys_bits_pixel_by_pixel():
    """``show_points`` (one compiled pass over the pixels, their points pixel by pixel) against
    numpy's reads and sums sample by sample, on a wall partly hidden behind a near background,
    with one albedo and with a texture's per point; a strided picture is refused."""
    plane = wall((0.0, 4.0, 0.0), facing=200 * DEG, width=3.0, height=2.0)
    grid = Grid.from_window((-1.5, 0.0, 1.5, 2.0), 0.04)
    rng = np.random.default_rng(11)
    image = (10.0 ** rng.uniform(-3, 3, (*grid.shape, 3))).astype(np.float32)
    camera = Camera.look_at((1.0, -2.0, 1.5), (0.0, 4.0, 1.0), vertical_fov=40 * DEG, width=64, height=48)
    hits = wall_hits(camera, plane)
    distance = np.full((48, 64), np.inf, np.float32)
    distance[30:, :20] = 3.0
    points, u, w = wall_points(hits)
    assert len(points.sample) == hits.hit.sum() and points.first[-1] == hits.hit.sum()
    taps = bilinear_taps(grid, u, w)
    scale = np.float32(1 / np.pi)
    texture = rng.uniform(0.1, 0.9, (len(u), 3)).astype(np.float32)
    per_sample = [np.zeros((*hits.hit.shape[1:], 3), np.float32) for _ in hits.hit]  # the texture by sample
    order = np.flatnonzero(np.moveaxis(hits.hit, 0, -1))
    for j, flat in enumerate(order):
        per_sample[flat % len(hits.hit)].reshape(-1, 3)[flat // len(hits.hit)] = texture[j]
    for albedo in (np.array([0.7, 0.6, 0.5], np.float32), texture):
        picture, depth = np.ones((48, 64, 3), np.float32), distance.copy()
        show_points(picture, depth, hits, points, image, taps, albedo, scale)
        expected, expected_depth = np.ones((48, 64, 3), np.float32), distance.copy()
        sampled = albedo if albedo.ndim == 1 else np.stack(per_sample)
        numpy_show(expected, expected_depth, hits, image, hits.u, hits.w, grid, sampled, scale)
        assert 0 < (picture != 1).sum() and picture.tobytes() == expected.tobytes()
        assert depth.tobytes() == expected_depth.tobytes()
    with pytest.raises(ValueError, match="C-contiguous"):
        show_points(np.ones((48, 64, 4), np.float32)[..., :3], distance.copy(), hits, points, image, taps, albedo,
                    scale)


def test_the_compiled_shade_of_the_ground_is_the_array_expressions_bits():
    """``kernels.arrays.walls_on_ground`` against the numpy expression it stands for, two walls,
    with the sun and without, on values over 8 decades."""
    rng = np.random.default_rng(5)
    shape, walls = (23, 31), 2
    sky_light = (10.0 ** rng.uniform(-4, 4, (*shape, 3))).astype(np.float32)
    total = sky_light + (10.0 ** rng.uniform(-4, 4, (*shape, 3))).astype(np.float32)
    keep = rng.uniform(0.0, 1.0, (walls, *shape, 3))
    factor = rng.uniform(0.0, 0.5, (walls, *shape))
    in_front = rng.uniform(size=(walls, *shape)) < 0.5
    front, back = rng.uniform(0, 50, (walls, 3)), rng.uniform(0, 50, (walls, 3))
    sun_keep = rng.uniform(0.0, 1.0, (walls, *shape))
    for lit in (True, False):
        sky_out, total_out = np.empty_like(sky_light), np.empty_like(sky_light)
        walls_on_ground(sky_light, total, keep, factor, in_front, front, back, sun_keep, lit, sky_out, total_out,
                        0, shape[0] * shape[1])
        sun = total.astype(np.float64) - sky_light
        sky = sky_light.astype(np.float64)
        for w in range(walls):
            sky = sky * keep[w] + np.where(in_front[w][..., None], front[w], back[w]) * factor[w][..., None]
            if lit:
                sun = sun * sun_keep[w][..., None]
        assert sky_out.tobytes() == sky.astype(np.float32).tobytes()
        assert total_out.tobytes() == (sky + sun).astype(np.float32).tobytes()


def test_the_compiled_rows_sum_gives_numpys_mean_of_a_walls_light():
    """``rows_sum`` / n, the mean a wall sends the ground, is numpy's ``mean(axis=0)`` to the bit."""
    rng = np.random.default_rng(3)
    for cells in ((10.0 ** rng.uniform(-6, 6, (50_001, 3))).astype(np.float32),
                  rng.uniform(0, 1, (7, 3)).astype(np.float32)):
        assert (rows_sum(cells) / np.float32(len(cells))).tobytes() == cells.mean(axis=0).tobytes()


def test_the_haze_of_the_walls_distances_follows_the_distances():
    """``distance_haze`` is the haze's transmittance of the distances given, kept only while they
    are the same bits: one changed pixel, or another length, gives the new one's."""
    rng = np.random.default_rng(2)
    distance = rng.uniform(1, 500, (20, 30)).astype(np.float32)
    distance[:3] = np.inf
    for d, length in ((distance, 300.0), (distance.copy(), 300.0), (distance, 100.0)):
        t, veil = distance_haze(d, length)
        assert t.tobytes() == haze_transmittance(d, length)[..., None].tobytes()
        assert veil.tobytes() == (1.0 - haze_transmittance(d, length)[..., None]).tobytes()
        assert not t.flags.writeable
    moved = distance.copy()
    moved[10, 10] = 2.0
    assert distance_haze(moved, 100.0)[0][10, 10, 0] == haze_transmittance(moved, 100.0)[10, 10]
