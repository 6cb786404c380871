"""The camera's reads of a wall (``receivers.view``): the compiled loops (``kernels.arrays.taps_read``,
``points_add``, ``wall_over``) give the bits of their array versions and of the plain bilinear formula, on random
points and on a real wall's raster where a camera's points see it (docs/accuracy.md,
"The walls' cycle products and a wall's cost")."""

import numpy as np

from pipeline.camera.pinhole import Camera
from pipeline.core.geometry import Grid
from pipeline.receivers.hemisphere import world_radiance
from pipeline.receivers.layers import mask_layer
from pipeline.receivers.light import receiver_light
from pipeline.receivers.plane import wall
from pipeline.receivers.view import bilinear_taps, put_wall, read_taps, read_taps_arrays, seen_points, wall_hits
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc

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


def test_the_compiled_reads_and_sums_are_the_array_versions_bits_on_a_real_wall():
    """A wall's irradiance under a grille and a low sun, read where a camera's 3 x 3 points per
    pixel see it (partly hidden behind a near background) and put into a picture: the bits of the
    numpy reads, and of the pixels' sums in the order of the points."""
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
    seen = seen_points(hits, distance)
    assert 0 < seen.sum() < hits.hit.sum()
    values = []
    for k in range(len(seen)):
        u, w = hits.u[k][seen[k]], hits.w[k][seen[k]]
        assert_reads_agree(window, raster, u, w)
        values.append(read_taps(raster, bilinear_taps(window, u, w)))
    picture, depth = np.ones((48, 64, 3), np.float32), distance.copy()
    put_wall(picture, depth, hits, seen, values)
    rows, cols = hits.region
    total = np.zeros((*seen.shape[1:], 3), np.float32)  # the points' sum as numpy's fancy indexing adds it
    for k in range(len(seen)):
        total.reshape(-1, 3)[np.flatnonzero(seen[k])] += values[k] * np.float32(1 / len(seen))
    coverage = seen.sum(axis=0, dtype=np.float32) * np.float32(1 / len(seen))
    expected = np.ones((48, 64, 3), np.float32)
    expected[rows, cols] = expected[rows, cols] * (1 - coverage)[..., None] + total
    assert picture.tobytes() == expected.tobytes()
    nearest = np.where(seen, hits.distance, np.inf).min(axis=0)
    assert np.array_equal(depth[rows, cols], np.where(coverage > 0.5, nearest, distance[rows, cols]))
    strided, strided_depth = np.ones((48, 64, 4), np.float32)[..., :3], distance.copy()  # put_wall's numpy blend
    put_wall(strided, strided_depth, hits, seen, values)
    assert strided.tobytes() == picture.tobytes() and strided_depth.tobytes() == depth.tobytes()
