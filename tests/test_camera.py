"""Tests of pipeline/camera/pinhole.py and texture/mipmap.py: mip maps, footprint filtering, the ground and sky views.

References are independent of the code under test: ray geometry written out by hand or through
``image_rays`` / ``project_points`` (the camera's contract), and brute-force supersampling with
scipy.ndimage.map_coordinates.
"""

import numpy as np
import pytest
import reference
from scipy import ndimage

from pipeline.camera import pinhole as camera
from pipeline.camera.pinhole import (
    Camera,
    background,
    ground_hits,
    ground_view,
    image_rays,
    pixel_rays,
    project_points,
    sky_view,
)
from pipeline.core import cores
from pipeline.core.geometry import Grid
from pipeline.sky.base import UniformSky
from pipeline.sky.equirect import EquirectSky
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc
from pipeline.texture import mipmap as texture
from pipeline.texture.mipmap import LOD_BIAS, MAX_TAPS, footprints, mipmap, sample_footprint, sample_footprints

ONE = Grid((0.0, 1.0), 1.0, (1, 1))


def constant_mip(value, channels=3):
    """A MipMap that is ``value`` everywhere."""
    v = np.full(channels, value, dtype=np.float32)
    return mipmap(v[None, None, :], ONE, outside="constant", value=v)


def straight_down(grid: Grid, height: float) -> Camera:
    """A camera over the centre of ``grid`` whose image pixels are the raster's pixels."""
    rows, cols = grid.shape
    x_min, y_min, x_max, y_max = grid.extent
    focal = height / grid.pixel  # one image pixel spans one raster pixel on the ground
    vfov = 2.0 * np.arctan(0.5 * rows / focal)
    return Camera((0.5 * (x_min + x_max), 0.5 * (y_min + y_max), height), 0.0, -np.pi / 2, vfov, cols, rows)


def supersampled_ground(camera: Camera, texture: np.ndarray, grid: Grid, n: int):
    """Brute force: n x n rays per pixel, each hitting the ground and reading the periodic texture
    (rows, cols) bilinearly at level 0. Returns (mean over the pixel's ground rays, ground ray
    count / n^2, pixel-centre point sample)."""
    h, w = camera.height, camera.width
    offsets = (np.arange(n) + 0.5) / n
    v = (np.arange(h)[:, None] + offsets).ravel()
    u = (np.arange(w)[:, None] + offsets).ravel()

    def read(uu, vv):
        rays = image_rays(camera, uu, vv)
        down = rays[..., 2] < 0
        t = np.where(down, -camera.position[2] / np.where(down, rays[..., 2], -1.0), 0.0)
        row, col = grid.raster_from_ground(camera.position[0] + t * rays[..., 0], camera.position[1] + t * rays[..., 1])
        values = ndimage.map_coordinates(texture.astype(np.float64), [row.ravel(), col.ravel()],
                                         order=1, mode="grid-wrap").reshape(row.shape)
        return np.where(down, values, 0.0), down

    values, down = read(u[None, :], v[:, None])
    total = values.reshape(h, n, w, n).sum(axis=(1, 3))
    count = down.reshape(h, n, w, n).sum(axis=(1, 3))
    centre, _ = read(np.arange(w)[None, :] + 0.5, np.arange(h)[:, None] + 0.5)
    return total / np.maximum(count, 1), count / n**2, centre


# --- mip maps ----------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", [(16, 16), (27, 45), (1, 7)])
def test_constant_levels_keep_the_integral(shape):
    rng = np.random.default_rng(1)
    raster = rng.random((*shape, 3)).astype(np.float32)
    grid = Grid((3.0, -2.0), 0.25, shape)
    value = np.array([0.2, 0.5, 0.9], dtype=np.float32)
    mip = mipmap(raster, grid, outside="constant", value=value)
    # the integral of (f - value) over the infinite plane, level by level
    expected = (raster - value).sum(axis=(0, 1), dtype=np.float64) * grid.pixel**2
    for k in range(mip.count):
        px, py = mip.pixels[k]
        got = (mip.level(k) - value).sum(axis=(0, 1), dtype=np.float64) * px * py
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)
    assert mip.shapes[-1] == (1, 1)


@pytest.mark.parametrize("shape", [(716, 1261), (27, 45), (1, 7), (6, 1)])
@pytest.mark.parametrize("value", [0.3, np.nan])
def test_constant_mipmap_has_the_bits_of_the_array_levels(shape, value):
    # the compiled halving (kernels.filter.halve_level) against the numpy levels it replaced
    raster = np.random.default_rng(3).random((*shape, 3)).astype(np.float32) * 7.0
    value = np.full(3, value, dtype=np.float32)
    mip = mipmap(raster, Grid((0.0, 0.0), 0.5, shape), outside="constant", value=value)
    levels = reference.constant_levels(raster, value)
    assert mip.shapes == tuple(level.shape[:2] for level in levels)
    for k, level in enumerate(levels):
        assert mip.level(k).tobytes() == level.tobytes()
    moved = np.moveaxis(np.ascontiguousarray(np.moveaxis(raster, -1, 0)), 0, -1)  # channels first in memory
    assert mip.texels.tobytes() == mipmap(moved, Grid((0.0, 0.0), 0.5, shape), outside="constant",
                                          value=value).texels.tobytes()
    stored = mip.texels[mip.offsets[-1]:].reshape(3, 3, 3)
    assert stored[0].tobytes() == np.broadcast_to(value, (3, 3)).tobytes()


@pytest.mark.parametrize("shape, period_px", [((32, 32), (32, 32)), ((27, 45), (45, 27)),
                                               ((30, 40), (21.5, 13.25))])
def test_periodic_levels_keep_the_mean(shape, period_px):
    rng = np.random.default_rng(2)
    raster = rng.random((*shape, 2)).astype(np.float32)
    grid = Grid((0.0, 0.0), 0.1, shape)
    mip = mipmap(raster, grid, outside="periodic", period=(period_px[0] * 0.1, period_px[1] * 0.1))
    # the fundamental cell is the raster's south-west corner, fractional texels weighted by area
    lx, ly = period_px
    wx = np.clip(lx - np.arange(shape[1]), 0.0, 1.0)
    wy = np.clip(ly - np.arange(shape[0])[::-1], 0.0, 1.0)
    weight = wy[:, None] * wx[None, :]
    expected = np.einsum("rc,rcn->n", weight, raster.astype(np.float64)) / weight.sum()
    for k in range(mip.count):
        np.testing.assert_allclose(mip.level(k).mean(axis=(0, 1), dtype=np.float64), expected, rtol=1e-5)
    assert mip.shapes[-1] == (1, 1)


def test_mipmap_checks_its_input_and_does_not_change_it():
    raster = np.ones((4, 6, 3), dtype=np.float32)
    grid = Grid((0.0, 0.0), 1.0, (4, 6))
    before = raster.copy()
    mipmap(raster, grid, outside="constant", value=0.5)
    np.testing.assert_array_equal(raster, before)
    with pytest.raises(ValueError, match="outside"):
        mipmap(raster, grid, outside="mirror", value=0.5)
    with pytest.raises(ValueError, match="shape"):
        mipmap(raster[:3], grid, outside="constant", value=0.5)
    with pytest.raises(ValueError, match="cover one period"):
        mipmap(raster, grid, outside="periodic", period=(7.0, 4.0))
    with pytest.raises(ValueError, match="value"):
        mipmap(raster, grid, outside="constant")


# --- footprint sampling ------------------------------------------------------------------------

def test_constant_outside_gives_the_value():
    rng = np.random.default_rng(3)
    grid = Grid((-1.0, 1.0), 0.1, (20, 20))  # x, y in [-1, 1]
    value = np.array([7.0, 8.0, 9.0], dtype=np.float32)
    mip = mipmap(rng.random((20, 20, 3)).astype(np.float32), grid, outside="constant", value=value)
    x = np.array([5.0, -3.0, 0.0, 1.0e6, 1.15])
    y = np.array([0.0, 2.0, -1.2, 3.0, 0.0])
    for scale in (0.05, 0.5, 20.0):  # fine, middling and coarse levels
        jac = np.tile(np.diag([scale, scale]), (len(x), 1, 1))
        got = sample_footprint(mip, x, y, jac)
        far = np.hypot(np.maximum(np.abs(x) - 1, 0), np.maximum(np.abs(y) - 1, 0)) > 2 * scale + 0.1
        np.testing.assert_allclose(got[far], np.broadcast_to(value, got[far].shape), rtol=1e-6)
    # a straight-down view wider than the raster: the raster inside, the value all round it
    wide = Grid((-2.0, 2.0), 0.1, (40, 40))
    image, _, _ = ground_view(straight_down(wide, 2.0), irradiance=mip, albedo=constant_mip(np.pi))
    np.testing.assert_allclose(image[10:30, 10:30], mip.level(0), rtol=1e-5)
    np.testing.assert_allclose(image[:9], np.broadcast_to(value, image[:9].shape), rtol=1e-6)
    np.testing.assert_allclose(image[:, 31:], np.broadcast_to(value, image[:, 31:].shape), rtol=1e-6)


@pytest.mark.parametrize("period", [(2.0, 1.5), (1.37, 1.05)])
def test_periodic_points_moved_by_whole_periods_agree(period):
    rng = np.random.default_rng(4)
    grid = Grid((-1.0, 0.6), 0.1, (16, 24))  # covers 2.4 x 1.6 m
    mip = mipmap(rng.random((16, 24, 3)).astype(np.float32), grid, outside="periodic", period=period)
    n = 200
    x, y = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
    jac = rng.normal(0, 0.3, (n, 2, 2))
    shift_x = rng.integers(-50, 50, n) * period[0]
    shift_y = rng.integers(-50, 50, n) * period[1]
    a = sample_footprint(mip, x, y, jac)
    b = sample_footprint(mip, x + shift_x, y + shift_y, jac)
    np.testing.assert_allclose(a, b, atol=2e-5)


def test_periodic_period_of_a_fractional_number_of_pixels():
    # a cosine of period 1.05 m on 0.1 m pixels, the raster covering more than two periods
    period = 1.05
    grid = Grid((0.0, 1.0), 0.1, (10, 25))
    x, _ = grid.ground_from_raster(0, np.arange(25))
    raster = np.broadcast_to(np.cos(2 * np.pi * x / period)[None, :, None], (10, 25, 1)).astype(np.float32)
    mip = mipmap(raster, grid, outside="periodic", period=(period, 1.0))
    xs = np.linspace(-7.0, 9.0, 500)
    got = sample_footprint(mip, xs, np.full(500, 0.3), np.tile(np.diag([1e-4, 1e-4]), (500, 1, 1)))[:, 0]
    # bilinear reading of a cosine sampled 10.5 times a period: within a pixel's worth of it
    np.testing.assert_allclose(got, np.cos(2 * np.pi * xs / period), atol=0.12)
    assert np.abs(got - np.cos(2 * np.pi * xs / period)).mean() < 0.05


def test_footprint_average_of_a_linear_ramp_is_its_centre_value():
    # any filter symmetric about the centre reads a linear function at the centre, exactly
    grid = Grid((-50.0, 50.0), 0.5, (200, 200))
    x, y = grid.ground_from_raster(*np.indices(grid.shape))
    ramp = (2.0 + 0.01 * x + 0.02 * y)[..., None].astype(np.float32)
    mip = mipmap(ramp, grid, outside="constant", value=0.0)
    rng = np.random.default_rng(5)
    n = 300
    jac = rng.normal(0, 1.0, (n, 2, 2)) * rng.uniform(0.1, 3.0, (n, 1, 1))
    px, py = rng.uniform(-30, 30, n), rng.uniform(-30, 30, n)
    got = sample_footprint(mip, px, py, jac)[:, 0]
    np.testing.assert_allclose(got, 2.0 + 0.01 * px + 0.02 * py, atol=2e-3)


def reference_footprint_samples(mip, x, y, jacobian, lod_bias=LOD_BIAS):
    """sample_footprint written out point by point in float64, from its docstring's rule: the
    ellipse from an eigen-decomposition of J J^T, taps along its major axis, each a trilinear
    sample whose texels are read one by one from ``mip.level`` (the outside value beyond a
    "constant" raster, the texel a whole number of periods away in a "periodic" one)."""
    texel = np.sqrt(mip.pixels[0][0] * mip.pixels[0][1])
    levels = [mip.level(k).astype(np.float64) for k in range(mip.count)]

    def texel_value(k, r, c):
        rows, cols = mip.shapes[k]
        if mip.outside == "periodic":
            return levels[k][r % rows, c % cols]
        if 0 <= r < rows and 0 <= c < cols:
            return levels[k][r, c]
        return mip.value.astype(np.float64)

    def bilinear(k, px, py):
        (x0, y0), (sx, sy) = mip.origins[k], mip.pixels[k]
        col, row = (px - x0) / sx - 0.5, (y0 - py) / sy - 0.5
        c, r = int(np.floor(col)), int(np.floor(row))
        fc, fr = col - c, row - r
        top = (1 - fc) * texel_value(k, r, c) + fc * texel_value(k, r, c + 1)
        bottom = (1 - fc) * texel_value(k, r + 1, c) + fc * texel_value(k, r + 1, c + 1)
        return (1 - fr) * top + fr * bottom

    out = np.zeros((len(x), mip.channels))
    for j, jac in enumerate(jacobian):
        eigenvalues, vectors = np.linalg.eigh(jac @ jac.T)
        major = np.sqrt(max(eigenvalues[1], 0.0))
        minor = np.sqrt(max(eigenvalues[0], 0.0))
        axis = vectors[:, 1]
        taps = int(np.clip(np.ceil(major / max(minor, texel) - 1e-3), 1, MAX_TAPS))
        with np.errstate(divide="ignore"):
            lod = np.clip(np.log2(max(minor, major / taps) / texel) + lod_bias, 0, mip.count - 1)
        k = int(np.floor(lod))
        t = lod - k
        if t > 1 - 1e-6:
            k, t = k + 1, 0.0
        elif t < 1e-6:
            t = 0.0
        for i in range(taps):
            step = ((i + 0.5) / taps - 0.5) * major
            px, py = x[j] + step * axis[0], y[j] + step * axis[1]
            sample = bilinear(k, px, py)
            if t > 0:
                sample = (1 - t) * sample + t * bilinear(k + 1, px, py)
            out[j] += sample / taps
    return out


@pytest.mark.parametrize("outside, shape, channels", [
    ("constant", (32, 32), 3), ("constant", (27, 45), 1),
    ("periodic", (32, 64), 3), ("periodic", (27, 45), 3), ("periodic", (30, 40), 1),
])
def test_sample_footprint_agrees_with_a_direct_reference(outside, shape, channels):
    # every level, blended or not, one tap or many, near and across the raster's edges (or
    # periods), far beyond it, and degenerate footprints
    rng = np.random.default_rng(8)
    raster = rng.random((*shape, channels)).astype(np.float32)
    grid = Grid((-1.3, 0.9), 0.05, shape)
    x_min, y_min, x_max, y_max = grid.extent
    if outside == "constant":
        mip = mipmap(raster, grid, outside="constant", value=rng.random(channels))
    else:  # a whole number of texels along x, a fraction of one along y
        mip = mipmap(raster, grid, outside="periodic", period=(x_max - x_min, 0.9 * (y_max - y_min)))
    n = 600
    x = rng.uniform(x_min - 1.0, x_max + 1.0, n)
    y = rng.uniform(y_min - 1.0, y_max + 1.0, n)
    x[:40] = rng.uniform(-400.0, 400.0, 40)  # far beyond
    scale = np.exp(rng.uniform(np.log(0.005), np.log(5.0), n))
    jac = rng.normal(0.0, 1.0, (n, 2, 2)) * scale[:, None, None]
    jac[40:100, :, 1] *= rng.uniform(5.0, 40.0, (60, 1))  # long, thin footprints
    jac[100:110] = 0.0
    jac[110:120, :, 1] = 2.0 * jac[110:120, :, 0]  # a segment
    got = sample_footprint(mip, x, y, jac)
    assert got.dtype == np.float32 and got.shape == (n, channels)
    np.testing.assert_allclose(got, reference_footprint_samples(mip, x, y, jac), rtol=2e-5, atol=2e-6)


@pytest.mark.parametrize("outside, shape, channels", [
    ("constant", (27, 45), 3), ("constant", (32, 32), 2), ("periodic", (32, 64), 3),
    ("periodic", (27, 45), 1), ("periodic", (30, 40), 4),
])
@pytest.mark.parametrize("threads", [1, 3])
def test_compiled_filtering_matches_the_array_version_bit_for_bit(outside, shape, channels, threads, monkeypatch):
    """mipmap.filtered_read (numba, footprint by footprint) against reference.filtered_arrays (numpy,
    grouped by level), the reference it replaces: the same float32 arithmetic in the same order
    gives the same bits, for every level, blend and tap count, far points, degenerate
    footprints and a NaN outside value (the finer rasters of a chain); in one thread or shared
    among three (cores.in_shares)."""
    monkeypatch.setattr(cores, "SMALLEST_SHARE", 100)
    with cores.loop_threads(threads):
        texture._TAPS.clear()
        rng = np.random.default_rng(21)
        raster = rng.random((*shape, channels)).astype(np.float32)
        grid = Grid((-1.3, 0.9), 0.05, shape)
        x_min, y_min, x_max, y_max = grid.extent
        if outside == "constant":
            value = rng.random(channels)
            value[0] = np.nan
            mip = mipmap(raster, grid, outside="constant", value=value)
        else:
            mip = mipmap(raster, grid, outside="periodic", period=(x_max - x_min, 0.9 * (y_max - y_min)))
        n = 3000
        x = rng.uniform(x_min - 1.0, x_max + 1.0, n)
        y = rng.uniform(y_min - 1.0, y_max + 1.0, n)
        x[:40] = rng.uniform(-4e5, 4e5, 40)
        scale = np.exp(rng.uniform(np.log(0.001), np.log(50.0), n))
        jac = rng.normal(0.0, 1.0, (n, 2, 2)) * scale[:, None, None]
        jac[40:300, :, 1] *= rng.uniform(5.0, 40.0, (260, 1))
        jac[300:310] = 0.0
        fp = footprints(x, y, jac)
        for bias in (LOD_BIAS, 0.0, 1.3):
            want = reference.filtered_arrays(mip, fp, bias)
            for _ in range(3):  # three channels: the second and third read from the kept tap table
                got = texture.filtered_read(mip, fp, bias)
                assert got.dtype == np.float32 and got.shape == want.shape == (channels, n)
                np.testing.assert_array_equal(got, want)
        assert np.isnan(texture.filtered_read(mip, fp, LOD_BIAS)).any() == (outside == "constant")
        # another frame's raster on the same grid: the kept taps read its texels
        other = mipmap(raster[::-1] * 2.0, grid, outside=outside, value=mip.value, period=mip.period)
        np.testing.assert_array_equal(texture.filtered_read(other, fp, LOD_BIAS),
                                      reference.filtered_arrays(other, fp, LOD_BIAS))


def test_a_still_cameras_tap_table_is_kept_from_the_second_read():
    """mipmap.filtered_read keeps where a still camera's taps fall (kept.kept_at) only once the same
    footprints and levels are read a second time, and reads from it afterwards."""
    rng = np.random.default_rng(5)
    grid = Grid((0.0, 1.0), 0.05, (20, 20))
    mip = mipmap(rng.random((20, 20, 3)).astype(np.float32), grid, outside="periodic", period=(1.0, 1.0))
    fp = footprints(rng.uniform(0, 1, 50), rng.uniform(0, 1, 50), rng.normal(0, 0.05, (50, 2, 2)))
    texture._TAPS.clear()
    texture.filtered_read(mip, fp, LOD_BIAS)
    assert [entry[1] for entry in texture._TAPS.values()] == [None]
    texture.filtered_read(mip, fp, LOD_BIAS)
    (start, first, fc, fr), = [entry[1] for entry in texture._TAPS.values()]
    assert start[0] == 0 and start[-1] == len(first) == len(fc) == len(fr) >= 50


def test_a_chains_footprints_beyond_its_first_map_keep_their_taps_too():
    """pinhole.filtered_chain reads the footprints whose read of the fine map is not finite from the
    coarse one: a still camera's are the same each frame, kept as the same arrays (pinhole._SUBSETS)
    so that mipmap.filtered_read keeps their taps as well; every frame's read has the array version's bits."""
    rng = np.random.default_rng(8)
    fine = mipmap(rng.random((24, 30, 3)).astype(np.float32), Grid((-0.6, -0.4), 0.04, (24, 30)),
                  outside="constant", value=np.full(3, np.nan))
    coarse = mipmap(rng.random((30, 30, 3)).astype(np.float32), Grid((-1.5, -1.5), 0.1, (30, 30)),
                    outside="constant", value=np.zeros(3))
    n = 2000
    fp = footprints(rng.uniform(-1.4, 1.4, n), rng.uniform(-1.4, 1.4, n),
                    rng.normal(0.0, 1.0, (n, 2, 2)) * np.exp(rng.uniform(np.log(0.005), np.log(0.5), n))[:, None, None])
    want = reference.filtered_arrays(fine, fp, LOD_BIAS)
    missing = np.flatnonzero(~np.isfinite(want).all(axis=0))
    subset = texture.Footprints(*(a[missing] for a in (fp.x, fp.y, fp.major, fp.minor, fp.ex, fp.ey)))
    want[:, missing] = reference.filtered_arrays(coarse, subset, LOD_BIAS)
    assert 200 < len(missing) < n - 200
    camera._SUBSETS.clear()
    texture._TAPS.clear()
    for _ in range(4):  # the subset kept from the second frame, its taps from the fourth
        np.testing.assert_array_equal(camera.filtered_chain((fine, coarse), fp), want)
    tables = [entry[1] for entry in texture._TAPS.values() if entry[1] is not None]
    assert len(tables) == 2  # the fine read's and the subset's (a first frame's one-off ask holds none)


@pytest.mark.parametrize("view", [
    Camera.look_at((0.3, -2.0, 1.7), (1.0, 3.0, 0.0), vertical_fov=np.radians(60.0), width=160, height=90),
    Camera((1.0, 2.0, 30.0), 0.3, -np.pi / 2, 1.0, 60, 40),  # straight down
    Camera((1.0, 2.0, 3.0), 2.3, 0.02, 1.2, 133, 101),  # level: the horizon inside a row
])
def test_compiled_footprints_match_the_array_version_bit_for_bit(view):
    """pinhole._row_footprints (numba, pixel by pixel) against reference.row_footprints_arrays
    (row_hits and footprint_axes in numpy), the reference it replaces: the same bits, horizon included."""
    rows, part = camera.rows_seeing_ground(view)
    got = camera._row_footprints(view, rows, part)
    want = reference.row_footprints_arrays(view, rows, part)
    assert len(got) == len(want) == 7 and len(got[0]) == len(rows) * view.width > 0
    for g, w in zip(got, want):
        assert g.dtype == w.dtype
        np.testing.assert_array_equal(g, w)


def test_pixel_rays_are_image_rays_through_the_pixel_centres_bit_for_bit():
    """pixel_rays (one component at a time, from the row and column offsets) against
    image_rays on the full grid of pixel centres, which it replaces."""
    for view in (Camera.look_at((0.3, -2.0, 1.7), (1.0, 3.0, 0.0), vertical_fov=1.0, width=64, height=36),
                 Camera((1.0, 2.0, 3.0), 2.3, 0.02, 1.2, 33, 101)):
        v, u = np.mgrid[0:view.height, 0:view.width] + 0.5
        got = pixel_rays(view)
        assert got.shape == (view.height, view.width, 3) and got.dtype == np.float64
        np.testing.assert_array_equal(got, image_rays(view, u, v))


def test_compiled_filter_choice_matches_the_array_version_bit_for_bit():
    """mipmap.filter_choice (numba) against filter_choice_arrays (numpy), the reference it
    replaces: tap counts, levels and blends, for footprints from 1e-5 to 1e5 texels, round and
    long, and zero, NaN and infinite widths."""
    rng = np.random.default_rng(5)
    mip = mipmap(rng.random((30, 27, 3)).astype(np.float32), Grid((0.0, 1.0), 0.005, (30, 27)), value=0.1)
    n = 200000
    major = np.exp(rng.uniform(-12.0, 12.0, n)) * 0.005
    minor = major * rng.uniform(0.0, 1.2, n)
    major[:100], minor[100:200], minor[200:300] = 0.0, 0.0, np.inf
    major[300:400], minor[400:500], major[500:600] = np.nan, np.nan, np.inf
    for bias in (LOD_BIAS, 0.0, 0.7):
        got = texture.filter_choice(mip, bias, major, minor)
        want = reference.filter_choice_arrays(mip, bias, major.copy(), minor.copy())
        for g, w in zip(got, want):
            assert g.dtype == w.dtype
            np.testing.assert_array_equal(g, w)


def test_ground_view_reads_the_albedo_once_per_view():
    """The albedo seen by a camera depends on the view alone: a second frame of the same
    camera and albedo gives the same radiance without sampling the albedo again; another
    camera samples it anew."""
    rng = np.random.default_rng(12)
    grid = Grid((-2.0, 6.0), 0.05, (160, 80))
    tile = mipmap(rng.random((40, 40, 3)).astype(np.float32), Grid((0.0, 2.0), 0.05, (40, 40)),
                  outside="periodic", period=(2.0, 2.0))

    class Counting:
        calls = 0

        def sample(self, fp, *, lod_bias):
            Counting.calls += 1
            return texture.filtered_read(tile, fp, lod_bias)

    albedo = Counting()
    view = Camera.look_at((0.0, 0.0, 1.7), (0.0, 3.0, 0.0), vertical_fov=1.0, width=48, height=32)
    light = [mipmap(rng.random((160, 80, 3)).astype(np.float32) + f, grid, value=np.full(3, 1.0 + f))
             for f in (0.0, 1.0)]
    first = ground_view(view, irradiance=light[0], albedo=albedo)[0]
    second = ground_view(view, irradiance=light[1], albedo=albedo)[0]
    assert Counting.calls == 1
    np.testing.assert_array_equal(first, ground_view(view, irradiance=light[0], albedo=tile)[0])
    np.testing.assert_array_equal(second, ground_view(view, irradiance=light[1], albedo=tile)[0])
    assert not np.array_equal(first, second)
    other = Camera.look_at((0.5, 0.0, 1.7), (0.0, 3.0, 0.0), vertical_fov=1.0, width=48, height=32)
    ground_view(other, irradiance=light[0], albedo=albedo)
    assert Counting.calls == 2


def test_footprints_serve_several_rasters():
    rng = np.random.default_rng(9)
    grid = Grid((0.0, 1.6), 0.05, (32, 32))
    constant = mipmap(rng.random((32, 32, 3)).astype(np.float32), grid, outside="constant", value=0.3)
    periodic = mipmap(rng.random((32, 32, 1)).astype(np.float32), grid, outside="periodic", period=(1.6, 1.6))
    n = 500
    x, y = rng.uniform(-1.0, 3.0, n), rng.uniform(-1.0, 3.0, n)
    jac = rng.normal(0.0, 0.2, (n, 2, 2))
    fp = footprints(x, y, jac)
    for mip in (constant, periodic):
        np.testing.assert_array_equal(sample_footprints(mip, fp), sample_footprint(mip, x, y, jac))
    assert sample_footprint(constant, [], [], np.zeros((0, 2, 2))).shape == (0, 3)


# --- the ground view ---------------------------------------------------------------------------

def test_ground_view_is_the_product_of_its_footprint_samples():
    rng = np.random.default_rng(10)
    grid = Grid((-3.0, 6.0), 0.05, (120, 80))
    irradiance = mipmap(rng.random((120, 80, 3)).astype(np.float32), grid, outside="constant", value=0.7)
    albedo = mipmap(rng.random((64, 64, 1)).astype(np.float32), Grid((0.0, 0.64), 0.01, (64, 64)),
                    outside="periodic", period=(0.64, 0.64))
    camera = Camera((0.2, -1.0, 1.6), 0.2, np.radians(-12), np.radians(45), 120, 70)
    image, fraction, distance = ground_view(camera, irradiance=irradiance, albedo=albedo)
    x, y, jac, hit_distance, coverage = ground_hits(camera)
    seen = np.isfinite(hit_distance)
    expected = np.zeros_like(image)
    expected[seen] = (sample_footprint(irradiance, x[seen], y[seen], jac[seen])
                      * sample_footprint(albedo, x[seen], y[seen], jac[seen]) * np.float32(1 / np.pi))
    np.testing.assert_array_equal(image, expected)
    np.testing.assert_array_equal(fraction, coverage.astype(np.float32))
    np.testing.assert_array_equal(distance, hit_distance.astype(np.float32))


def test_straight_down_view_reproduces_the_raster():
    rng = np.random.default_rng(6)
    grid = Grid((-1.7, 2.3), 0.1, (24, 32))
    raster = rng.random((24, 32, 3)).astype(np.float32)
    raster[0, -1] = 50.0  # the north-east corner
    camera = straight_down(grid, 3.0)
    irradiance = mipmap(raster, grid, outside="constant", value=np.zeros(3))
    image, fraction, distance = ground_view(camera, irradiance=irradiance, albedo=constant_mip(np.pi))
    np.testing.assert_allclose(image, raster, rtol=1e-5, atol=1e-6)
    assert np.unravel_index(np.argmax(image[..., 0]), image.shape[:2]) == (0, 31)  # north up, east right
    assert np.all(fraction == 1)
    x, y = grid.ground_from_raster(*np.indices(grid.shape))
    cx, cy, h = camera.position
    np.testing.assert_allclose(distance, np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + h * h), rtol=1e-6)
    # albedo multiplies, over pi
    albedo = mipmap(raster, grid, outside="constant", value=np.zeros(3))
    image2, _, _ = ground_view(camera, irradiance=constant_mip(2.0), albedo=albedo)
    np.testing.assert_allclose(image2, raster * 2.0 / np.pi, rtol=1e-5, atol=1e-6)


def test_ground_jacobian_matches_finite_differences():
    camera = Camera((1.0, -2.0, 1.7), 0.7, np.radians(-25), np.radians(50), 64, 48)
    x, _y, jac, distance, fraction = ground_hits(camera)
    v, u = np.mgrid[0:48, 0:64] + 0.5

    def hit(uu, vv):
        rays = image_rays(camera, uu, vv)
        t = -camera.position[2] / rays[..., 2]
        return (np.stack([camera.position[0] + t * rays[..., 0], camera.position[1] + t * rays[..., 1]], -1),
                t * np.linalg.norm(rays, axis=-1))

    full = fraction == 1
    d = 1e-4
    du = (hit(u + d, v)[0] - hit(u - d, v)[0]) / (2 * d)
    dv = (hit(u, v + d)[0] - hit(u, v - d)[0]) / (2 * d)
    np.testing.assert_allclose(jac[full][:, :, 0], du[full], rtol=1e-5)
    np.testing.assert_allclose(jac[full][:, :, 1], dv[full], rtol=1e-5)
    centre, length = hit(u, v)
    np.testing.assert_allclose(x[full], centre[full][:, 0], rtol=1e-9)
    np.testing.assert_allclose(distance[full], length[full], rtol=1e-9)
    assert np.all(np.isinf(distance[fraction == 0])) and np.all(np.isnan(x[fraction == 0]))


def test_horizon_row_and_antialiased_coverage():
    camera = Camera((0.0, 0.0, 1.7), 1.1, -0.2, 0.7, 8, 101)
    # the horizon: the image of a point far away at the camera's height, straight ahead
    far = np.array(camera.position) + 1e12 * np.array([np.sin(1.1), np.cos(1.1), 0.0])
    _, v_horizon, _ = project_points(camera, far)
    row = int(np.floor(v_horizon))
    assert 0.05 < v_horizon - row < 0.95  # the test needs a partly covered row
    _, fraction, distance = ground_view(camera, irradiance=constant_mip(1.0), albedo=constant_mip(1.0))
    expected = np.clip(np.arange(101) + 1 - v_horizon, 0.0, 1.0)
    np.testing.assert_allclose(fraction[:, 3], expected, atol=1e-9)
    assert np.all(fraction[:row] == 0) and np.all(fraction[row + 1:] == 1)
    assert np.all(fraction == fraction[:, :1])  # level camera: a level horizon
    assert np.all(np.isinf(distance[:row])) and np.all(np.isfinite(distance[row:]))
    # the blend: ground below, sky above, the horizon row by its coverage
    image, _ = background(camera, irradiance=constant_mip(np.pi), albedo=constant_mip(0.5),
                          sky=UniformSky(np.array([2.0, 2.0, 2.0])))
    f = expected[row]
    np.testing.assert_allclose(image[row], f * 0.5 + (1 - f) * 2.0, rtol=1e-5)
    np.testing.assert_allclose(image[:row], 2.0)
    np.testing.assert_allclose(image[row + 1:], 0.5, rtol=1e-6)


@pytest.mark.parametrize("pitch", [-0.2, -1.2, 0.5])  # the horizon in view; ground alone; sky alone
def test_background_is_f_ground_plus_1_minus_f_sky_to_the_bit(pitch):
    """pinhole.background (f ground made channels first, added to (1 - f) sky channel by channel)
    gives the bits of the image's float32 products f ground + (1 - f) sky."""
    view = Camera((0.0, 0.0, 1.7), 1.1, pitch, 0.7, 24, 61)
    grid = Grid((-30.0, 30.0), 0.25, (240, 240))
    irradiance = mipmap(np.random.default_rng(5).random((240, 240, 3)).astype(np.float32) * 3.0, grid,
                        outside="constant", value=np.full(3, 1.5, dtype=np.float32))
    sky = UniformSky(np.array([2.0, 1.5, 1.0]))
    ground, fraction, distance = ground_view(view, irradiance=irradiance, albedo=constant_mip(0.4))
    assert (fraction < 1).any() == (pitch > -1)
    f = fraction[..., None]
    want = ground * f + camera.sky_view(view, sky) * (np.float32(1) - f)
    got, got_distance = background(view, irradiance=irradiance, albedo=constant_mip(0.4), sky=sky)
    assert got.dtype == np.float32 and got.tobytes() == want.tobytes()
    assert got_distance.tobytes() == distance.tobytes()


def test_far_ground_does_not_alias():
    # 1 cm random texture, tiled; a camera at 1.7 m looking 10 degrees down over it
    rng = np.random.default_rng(7)
    n, pixel = 256, 0.01
    texture = rng.random((n, n)).astype(np.float32)
    grid = Grid((0.0, n * pixel), pixel, (n, n))
    albedo = mipmap(texture[..., None], grid, outside="periodic", period=(n * pixel, n * pixel))
    camera = Camera((0.3, 0.7, 1.7), 0.3, np.radians(-10), np.radians(40), 96, 64)
    image, fraction, _ = ground_view(camera, irradiance=constant_mip(np.pi, 1), albedo=albedo)
    filtered = image[..., 0]
    reference, coverage, point = supersampled_ground(camera, texture, grid, 16)
    np.testing.assert_allclose(fraction, coverage, atol=1.0 / 16)
    ground_rows = np.flatnonzero(fraction[:, 0] == 1)
    far = ground_rows[: len(ground_rows) // 2]
    assert len(far) >= 10
    # per-row means of the far ground, and the energy of the whole image, within 2 %
    np.testing.assert_allclose(filtered[far].mean(axis=1), reference[far].mean(axis=1), rtol=0.02)
    np.testing.assert_allclose((filtered * fraction).mean(), (reference * coverage).mean(), rtol=0.02)
    # no shimmer: pixel by pixel the filtered far ground is close to the supersampled one, while
    # point sampling is as noisy as the texture itself
    def rms(a):
        return float(np.sqrt(np.mean((a[far] - reference[far]) ** 2)))

    assert rms(filtered) < 0.1 * texture.std()
    assert rms(point) > 0.5 * texture.std()
    assert filtered[far].std() < 0.15 * texture.std()


def test_far_ground_is_not_overblurred_across_the_view():
    # stripes running away from the camera: the footprints are long along them and narrow across,
    # so anisotropic filtering keeps their contrast, which isotropic filtering would wash out
    period, pixel = 0.5, 0.01
    grid = Grid((0.0, 0.04), pixel, (4, 50))
    x, _ = grid.ground_from_raster(0, np.arange(50))
    stripes = np.broadcast_to(0.5 + 0.4 * np.cos(2 * np.pi * x / period), (4, 50)).astype(np.float32)
    albedo = mipmap(stripes[..., None], grid, outside="periodic", period=(period, 0.04))
    camera = Camera((0.13, 0.0, 1.7), 0.0, np.radians(-10), np.radians(40), 96, 64)
    image, fraction, _ = ground_view(camera, irradiance=constant_mip(np.pi, 1), albedo=albedo)
    reference, _, _ = supersampled_ground(camera, stripes, grid, 16)
    rows = np.flatnonzero(fraction[:, 0] == 1)
    far = rows[: len(rows) // 2]
    contrast = image[far, 20:76, 0].std(axis=1)
    expected = reference[far, 20:76].std(axis=1)
    resolved = expected > 0.1  # rows where the stripes are resolved across the image
    assert resolved.sum() >= 10
    np.testing.assert_allclose(contrast[resolved], expected[resolved], rtol=0.2)


def test_ground_view_needs_a_camera_above_the_ground():
    camera = Camera((0.0, 0.0, -1.0), 0.0, -0.3, 0.8, 8, 6)
    with pytest.raises(ValueError, match="above the ground"):
        ground_view(camera, irradiance=constant_mip(1.0), albedo=constant_mip(1.0))


# --- the sky view ------------------------------------------------------------------------------

def test_uniform_sky_is_constant_above_the_horizon():
    camera = Camera((0.0, 0.0, 1.7), 2.0, 0.1, 1.0, 40, 30)
    radiance = np.array([1.0, 2.0, 3.0])
    image = sky_view(camera, UniformSky(radiance))
    _, fraction, _ = ground_view(camera, irradiance=constant_mip(1.0), albedo=constant_mip(1.0))
    sky = fraction < 1
    np.testing.assert_array_equal(image[sky], np.broadcast_to(radiance, image[sky].shape).astype(np.float32))
    np.testing.assert_array_equal(image[~sky], 0.0)
    assert image.dtype == np.float32 and image.shape == (30, 40, 3)


@pytest.mark.parametrize("rotation", [0.0, 0.4])
def test_equirect_sky_texel_lands_where_geometry_says(rotation):
    height, width = 180, 360
    image = np.zeros((height, width, 3), dtype=np.float32)
    row, col = 59, 270  # texel centre: zenith 59.5 deg, image azimuth 90.5 deg (east at 3/4 width)
    image[row, col] = 100.0
    zenith = (row + 0.5) / height * np.pi
    azimuth = ((col + 0.5) / width - 0.5) * 2 * np.pi + rotation
    assert abs(np.degrees(zenith) - 59.5) < 1e-9 and abs(np.degrees(azimuth - rotation) - 90.5) < 1e-9
    camera = Camera((0.0, 0.0, 1.7), azimuth, np.pi / 2 - zenith, np.radians(10), 41, 41)
    view = sky_view(camera, EquirectSky(image, rotation))
    assert np.unravel_index(np.argmax(view[..., 0]), view.shape[:2]) == (20, 20)
    np.testing.assert_allclose(view[20, 20], 100.0, rtol=1e-3)
    # looking the other way, nothing
    away = Camera((0.0, 0.0, 1.7), azimuth + np.pi, np.pi / 2 - zenith, np.radians(10), 41, 41)
    assert sky_view(away, EquirectSky(image, rotation)).max() == 0.0


def test_procedural_sky_matches_its_model():
    sky = ProceduralSky(3.0, SunDisc(np.radians(200), np.radians(35)))
    yaw, pitch = np.radians(120), np.radians(15)
    camera = Camera((0.0, 0.0, 1.7), yaw, pitch, np.radians(40), 31, 21)
    image = sky_view(camera, sky)
    w = np.array([np.cos(pitch) * np.sin(yaw), np.cos(pitch) * np.cos(yaw), np.sin(pitch)])
    np.testing.assert_allclose(image[10, 15], sky.radiance(w[:2] / w[2]), rtol=1e-5)
    assert np.all(np.isfinite(image)) and np.all(image >= 0)
    # a view down to the horizon stays finite
    low = Camera((0.0, 0.0, 1.7), yaw, np.radians(-5), np.radians(40), 31, 21)
    assert np.all(np.isfinite(sky_view(low, sky)))


def reference_footprint_axes(dxdu, dxdv, dydu, dydv):
    """The numpy arithmetic that mipmap.footprint_axes compiles (its former body)."""
    a = dxdu * dxdu + dxdv * dxdv  # J J^T = [[a, b], [b, c]]
    b = dxdu * dydu + dxdv * dydv
    c = dydu * dydu + dydv * dydv
    bb = b * b
    half = a - c
    half *= half
    half *= 0.25
    half += bb
    np.sqrt(half, out=half)
    big = a + c  # the larger eigenvalue
    big *= 0.5
    big += half
    major = np.sqrt(big)
    minor = dxdu * dydv
    minor -= dxdv * dydu
    np.abs(minor, out=minor)  # the area
    with np.errstate(divide="ignore", invalid="ignore"):
        minor /= major
    minor[~(major > 0)] = 0.0
    big_c = np.subtract(big, c, out=c)
    big_a = np.subtract(big, a, out=a)
    first = big_c * big_c + bb >= bb + big_a * big_a
    ex, ey = np.where(first, big_c, b), np.where(first, b, big_a)
    norm = np.sqrt(ex * ex + ey * ey)
    overflow = ~np.isfinite(norm)
    if overflow.any():
        norm[overflow] = np.hypot(ex[overflow], ey[overflow])
    round_ = norm <= 1e-12 * np.maximum(big, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ex /= norm
        ey /= norm
    ex[round_] = 1.0
    ey[round_] = 0.0
    return major, minor, ex, ey


def test_footprint_axes_are_the_numpy_arithmetic_bit_for_bit():
    """The compiled footprint ellipse against its numpy reference on random Jacobians, round
    footprints, zero ones and ones whose moments overflow: the same bits."""
    rng = np.random.default_rng(11)
    entries = rng.normal(size=(4, 20000)) * np.exp(rng.uniform(-20, 20, size=(1, 20000)))
    entries[:, :100] = 0.0  # a point
    entries[:, 100:200] = [[1.0], [0.0], [0.0], [1.0]]  # round
    entries[:, 200:300] *= 1e160  # moments overflow
    got = texture.footprint_axes(*entries)
    with np.errstate(all="ignore"):
        want = reference_footprint_axes(*(e.copy() for e in entries))
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
