import numpy as np
import pytest

from pipeline.geometry import I0, sky_plane_from_direction
from pipeline.shadow import sky_grid
from pipeline.sky import EquirectSky, UniformSky

from reference import equirect_patch


def square(half, q):
    return sky_grid((-half, -half), (2 * half + 1, 2 * half + 1), q)


def centroid(weighted, grid):
    """Energy centroid (sx, sy) of a sky raster's first channel. [tan]"""
    e = weighted[0].astype(np.float64)
    rows, cols = np.indices(e.shape)
    sx, sy = grid.ground_from_raster(rows, cols)
    return (e * sx).sum() / e.sum(), (e * sy).sum() / e.sum()


def test_uniform_sky_is_exact():
    half, q = 100, 0.02
    raster = UniformSky(np.array([1.0, 2.0, 0.5])).raster(square(half, q))
    assert raster.weighted.dtype == np.float32
    assert raster.total == pytest.approx(np.pi * np.array([1.0, 2.0, 0.5]), rel=1e-12)
    inside = I0(np.arctan((half + 0.5) * q))
    assert raster.weighted[0].sum(dtype=np.float64) == pytest.approx(inside, rel=1e-6)


def test_uniform_equirect_equals_uniform_model():
    grid = square(300, 0.05 / 8)
    uniform = UniformSky(np.ones(3)).raster(grid)
    hdri = EquirectSky(np.ones((256, 512, 3), np.float32)).raster(grid)
    assert hdri.total == pytest.approx(uniform.total, rel=1e-9)
    assert hdri.weighted.sum() == pytest.approx(uniform.weighted.sum(), rel=1e-4)
    # cell by cell the splat carries a fine moire; over 8 x 8 blocks it is gone
    ratio = hdri.weighted[0] / uniform.weighted[0]
    blocks = ratio[:600, :600].reshape(75, 8, 75, 8).mean(axis=(1, 3))
    assert np.abs(blocks - 1).max() < 0.01


def test_small_bright_sun_keeps_its_energy_and_direction():
    width, height = 512, 256
    image, az, zen = equirect_patch(width, height, azimuth=(np.radians(119.0), np.radians(120.5)),
                                    zenith=(np.radians(40.0), np.radians(40.9)), radiance=1e5)
    sky = EquirectSky(image)
    energy = sky.total_irradiance()[0]
    # exact irradiance of the patch: L * integral of cos(theta) d_omega over it
    expected = 1e5 * (az[1] - az[0]) * 0.5 * (np.sin(zen[1]) ** 2 - np.sin(zen[0]) ** 2)
    assert energy == pytest.approx(expected, rel=1e-9)
    grid = square(400, 0.004)
    raster = sky.raster(grid)
    assert raster.weighted[0].sum(dtype=np.float64) == pytest.approx(energy, rel=1e-5)
    assert raster.outside[0] == pytest.approx(0.0, abs=1e-6 * energy)
    sx, sy = centroid(raster.weighted, grid)
    tx, ty = sky_plane_from_direction(np.mean(az), np.mean(zen))
    assert abs(sx - tx) < 0.01 and abs(sy - ty) < 0.01  # a patch is 0.03 wide here
    assert sx > 0 and sy < 0  # azimuth 120 degrees: east and a little south


def test_rotation_turns_the_sky_towards_the_east():
    image, az, zen = equirect_patch(256, 128, azimuth=(-0.05, 0.05), zenith=(0.5, 0.6), radiance=100.0)
    grid = square(200, 0.005)
    north = EquirectSky(image).raster(grid)
    turned = EquirectSky(image, rotation=np.radians(90.0)).raster(grid)
    nx, ny = centroid(north.weighted, grid)
    tx, ty = centroid(turned.weighted, grid)
    assert ny > 0.5 and abs(nx) < 0.01  # centre column looks north
    assert tx > 0.5 and abs(ty) < 0.01  # turned by 90 degrees: now east
    assert turned.total == pytest.approx(north.total)


def test_equirect_east_is_at_three_quarters_of_the_width():
    image = np.zeros((64, 128, 3), np.float32)
    image[20:24, 94:98] = 50.0  # u around 0.75
    grid = square(300, 0.01)
    sx, sy = centroid(EquirectSky(image).raster(grid).weighted, grid)
    assert sx > 1.0 and abs(sy) < 0.05 * sx


def test_raster_off_the_sky_counts_as_outside():
    image = np.ones((128, 256, 3), np.float32)
    grid = sky_grid((40, 40), (20, 30), 0.01)  # a small window away from the zenith
    raster = EquirectSky(image).raster(grid)
    assert raster.total == pytest.approx(np.full(3, np.pi), rel=1e-9)
    assert raster.outside[0] > 3.0
