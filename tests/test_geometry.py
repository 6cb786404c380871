import numpy as np
import pytest
from scipy import integrate

from pipeline.core.geometry import (
    I0,
    Grid,
    cos4_antiderivative,
    direction_from_sky_plane,
    direction_vector,
    fold,
    lattice_offset,
    normalized,
    projected_solid_angle,
    sky_grid,
    sky_offset,
    sky_plane_from_direction,
    tangent_axes,
)


def test_grid_is_north_up_with_pixel_centres():
    grid = Grid.from_window((-2.0, -1.0, 2.0, 1.0), 0.5)
    assert grid.shape == (4, 8)
    assert grid.extent == (-2.0, -1.0, 2.0, 1.0)
    x, y = grid.ground_from_raster(0, 0)
    assert (x, y) == (-1.75, 0.75)  # row 0 is the north edge
    x, y = grid.ground_from_raster(3, 7)
    assert (x, y) == (1.75, -0.75)
    row, col = grid.raster_from_ground(np.array([0.3]), np.array([-0.2]))
    back = grid.ground_from_raster(row, col)
    assert np.allclose(back, ([0.3], [-0.2]))


def test_lattice_offset_requires_alignment():
    lattice = Grid((0.0, 0.0), 0.5, (4, 4))
    assert lattice_offset(Grid((1.0, -1.5), 0.5, (2, 2)), lattice) == (3, 2)
    with pytest.raises(ValueError):
        lattice_offset(Grid((0.25, 0.0), 0.5, (2, 2)), lattice)
    with pytest.raises(ValueError):
        lattice_offset(Grid((0.0, 0.0), 0.25, (2, 2)), lattice)


def test_sky_plane_mapping_round_trip_and_orientation():
    az, zen = np.radians(90.0), np.radians(45.0)  # east, 45 degrees up
    sx, sy = sky_plane_from_direction(az, zen)
    assert sx == pytest.approx(1.0) and sy == pytest.approx(0.0, abs=1e-12)
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 2 * np.pi, 50)
    z = rng.uniform(0, 1.5, 50)
    a2, z2 = direction_from_sky_plane(*sky_plane_from_direction(a, z))
    assert np.allclose(a2, a) and np.allclose(z2, z)


def test_cos4_antiderivative_matches_quadrature_over_rectangles():
    for x0, x1, y0, y1 in [(0.1, 0.7, -0.3, 0.2), (-2.0, 3.0, 1.0, 4.0), (5.0, 5.01, -5.0, -4.99)]:
        exact = (cos4_antiderivative(x1, y1) - cos4_antiderivative(x0, y1)
                 - cos4_antiderivative(x1, y0) + cos4_antiderivative(x0, y0))
        quad, _ = integrate.dblquad(lambda y, x: 1 / (1 + x * x + y * y) ** 2, x0, x1, y0, y1,
                                    epsabs=1e-14, epsrel=1e-11)
        assert exact == pytest.approx(quad, rel=1e-8)


def test_I0_against_quadrature_on_the_hemisphere_and_paper_figure_16():
    # Independent of the sky plane: integrate cos(theta) d_omega over the directions whose
    # sky-plane point lies in the square, theta_max(phi) = atan(tan(alpha) / max(|sin|, |cos|)).
    for alpha_deg in (10.0, 45.0, 70.0, 85.0):
        alpha = np.radians(alpha_deg)

        def inner(phi):
            theta_max = np.arctan(np.tan(alpha) / max(abs(np.sin(phi)), abs(np.cos(phi))))
            return 0.5 * np.sin(theta_max) ** 2

        quad, _ = integrate.quad(inner, 0, 2 * np.pi, points=[np.pi / 4 * k for k in range(1, 8)],
                                 epsabs=1e-13, limit=200)
        assert I0(alpha) == pytest.approx(quad, rel=1e-9)
    assert I0(np.radians(70.0)) / np.pi == pytest.approx(0.90, abs=0.005)  # paper, Fig. 16
    assert I0(np.pi / 2) == pytest.approx(np.pi)


def test_projected_solid_angle_of_square_grid_sums_to_I0():
    q = 0.01
    half = 150  # cells -150..150, edges at +-1.505
    grid = Grid((-(half + 0.5) * q, (half + 0.5) * q), q, (2 * half + 1, 2 * half + 1))
    w = projected_solid_angle(grid)
    assert w.sum() == pytest.approx(I0(np.arctan((half + 0.5) * q)), rel=1e-12)
    assert w[half, half] == pytest.approx(q * q, rel=1e-3)  # cos^4 ~ 1 at the zenith
    assert np.all(w > 0)


def test_fold_accumulates_modulo_the_period():
    rng = np.random.default_rng(5)
    e = rng.random((2, 11, 7))
    start, period = (-5, -3), (4, 3)
    folded = fold(e, start, period)
    expected = np.zeros((2, *period))
    for r in range(11):
        for c in range(7):
            expected[:, (start[0] + r) % 4, (start[1] + c) % 3] += e[:, r, c]
    assert np.allclose(folded, expected)


def test_sky_grid_and_sky_offset_are_inverse():
    for start, q in [((-3, 5), 0.01), ((0, 0), 0.25), ((17, -40), 1e-4)]:
        grid = sky_grid(start, (4, 6), q)
        assert sky_offset(grid) == start
        # cell [0, 0]'s centre is the sky offset s = (dc q, -dr q)
        x, y = grid.ground_from_raster(0, 0)
        assert (x, y) == pytest.approx((start[1] * q, -start[0] * q), abs=1e-12)


def test_direction_vector_and_tangent_axes():
    azimuth, elevation = np.radians([30.0, 200.0]), np.radians([10.0, 70.0])
    w = direction_vector(azimuth, elevation)
    assert w.shape == (2, 3) and np.allclose(np.linalg.norm(w, axis=-1), 1.0)
    assert np.allclose(direction_vector(0.0, 0.0), [0.0, 1.0, 0.0])  # north
    assert np.allclose(direction_vector(np.pi / 2, 0.0), [1.0, 0.0, 0.0])  # east
    for a, h in zip(azimuth, elevation):
        s, e_az, e_el = tangent_axes(a, h)
        assert np.array_equal(s, direction_vector(a, h))
        assert np.allclose([s @ e_az, s @ e_el, e_az @ e_el], 0.0, atol=1e-15)
        step = 1e-6  # e_az, e_el are the directions of increasing azimuth and elevation
        assert np.allclose((direction_vector(a + step, h) - s) / step, np.cos(h) * e_az, atol=1e-5)
        assert np.allclose((direction_vector(a, h + step) - s) / step, e_el, atol=1e-5)


def test_normalized_scales_to_unit_length_and_leaves_zero_alone():
    v = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [1e-100, 0.0, 0.0]])
    u = normalized(v)
    assert np.allclose(u, [[0.6, 0.8, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])


def test_length3_is_numpys_norm_to_the_bit():
    """length3 gives np.linalg.norm(v, axis=-1)'s bits on vectors of every scale (numpy sums the
    squares of a last axis of three left to right; summed the other way, many lengths differ)."""
    from pipeline.core.geometry import length3

    rng = np.random.default_rng(3)
    v = rng.standard_normal((400_000, 3)) * np.exp(rng.uniform(-30, 30, (400_000, 3)))
    np.testing.assert_array_equal(length3(v), np.linalg.norm(v, axis=-1))
    grid = rng.standard_normal((7, 16, 16, 3))
    np.testing.assert_array_equal(length3(grid), np.linalg.norm(grid, axis=-1))
    squares = v * v
    assert not np.array_equal(np.sqrt(squares[:, 0] + (squares[:, 1] + squares[:, 2])), length3(v))
