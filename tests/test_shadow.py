import numpy as np
import pytest
from reference import direct_sum, equirect_patch, image_transmittance, monte_carlo_irradiance, monte_carlo_patch

from pipeline.canopy import masks as canopy
from pipeline.core.geometry import Grid, fold, sky_grid, sky_offset
from pipeline.ground import shadow
from pipeline.ground.layers import combine_layers, combine_lights
from pipeline.sky.base import UniformSky
from pipeline.sky.equirect import EquirectSky
from pipeline.sky.raster import SkyRaster


def random_case(rng, channels):
    """A small random window, canopy position and size, and a sky square that may crop."""
    p, h = 0.5, 2.0
    window = Grid((0.0, 0.0), p, (int(rng.integers(3, 9)), int(rng.integers(3, 9))))
    start = (int(rng.integers(-4, 6)), int(rng.integers(-4, 6)))
    shape = (int(rng.integers(2, 7)), int(rng.integers(2, 7)))
    canopy_grid = Grid((start[1] * p, -start[0] * p), p, shape)
    alpha = np.arctan(rng.uniform(0.5, 6) * p / h)
    half = shadow.sky_half_cells(h, p, alpha)
    full = sky_grid((-half, -half), (2 * half + 1, 2 * half + 1), p / h)
    e = rng.random((channels, 2 * half + 1, 2 * half + 1)).astype(np.float32)
    mask = rng.random(shape).astype(np.float32)
    return window, canopy_grid, start, h, alpha, half, full, e, mask


@pytest.mark.parametrize("channels", [1, 3])
def test_isolated_fft_equals_direct_sum(channels):
    rng = np.random.default_rng(10 + channels)
    for _ in range(5):
        window, canopy_grid, start, h, alpha, half, full, e, mask = random_case(rng, channels)
        plan = shadow.plan_isolated(window, canopy_grid, height=h, alpha=alpha)
        outside = rng.random(channels)
        if plan.sky is None:
            sub_grid, sub = sky_grid((0, 0), (1, 1), full.pixel), np.zeros((channels, 1, 1), np.float32)
        else:
            sub_grid = plan.sky
            r0 = round(0.5 - sub_grid.origin[1] / sub_grid.pixel) + half
            c0 = round(sub_grid.origin[0] / sub_grid.pixel + 0.5) + half
            sub = np.ascontiguousarray(e[:, r0 : r0 + sub_grid.shape[0], c0 : c0 + sub_grid.shape[1]])
        rest = outside + e.sum(axis=(1, 2), dtype=np.float64) - sub.sum(axis=(1, 2), dtype=np.float64)
        sky = SkyRaster(sub_grid, sub, rest)
        g = shadow.ground_isolated(sky, shadow.occlusion_spectrum(1 - mask, plan), plan)
        reference = direct_sum(e, (-half, -half), mask, start, window.shape, 1.0)
        reference += outside[:, None, None]
        assert g.dtype == np.float32 and g.shape == (channels, *window.shape)
        assert np.abs(g - reference).max() <= 1e-5 * reference.max()


@pytest.mark.parametrize("channels", [1, 3])
def test_periodic_fft_equals_direct_sum(channels):
    rng = np.random.default_rng(20 + channels)
    for _ in range(5):
        window, tile, start, h, alpha, half, full, e, mask = random_case(rng, channels)
        plan = shadow.plan_periodic(window, tile, height=h, alpha=alpha)
        outside = rng.random(channels)
        g = shadow.ground_periodic(SkyRaster(full, e, outside), shadow.transmittance_spectrum(mask),
                                   plan, float(mask.mean()))
        reference = direct_sum(e, (-half, -half), mask, start, window.shape, None)
        reference += outside[:, None, None] * mask.mean()
        assert np.abs(g - reference).max() <= 1e-5 * reference.max()


def test_open_sky_of_radiance_one_gives_pi():
    window = Grid.from_window((-5, -5, 5, 5), 0.1)
    sky = UniformSky(np.ones(3))
    open_mask = np.ones((40, 40), np.float32)
    occlusion, grid = canopy.occlusion_on_lattice(open_mask, center=(0, 0), size=(4, 4), lattice=window)
    plan = shadow.plan_isolated(window, grid, height=3.0, alpha=np.radians(80))
    g = shadow.ground_isolated(sky.raster(plan.sky), shadow.occlusion_spectrum(occlusion, plan), plan)
    assert np.abs(g / np.pi - 1).max() < 0.005
    tile, grid = canopy.tile_on_lattice(open_mask, center=(0, 0), size=(4, 4), lattice=window)
    pplan = shadow.plan_periodic(window, grid, height=3.0, alpha=np.radians(80))
    g = shadow.ground_periodic(sky.raster(pplan.sky), shadow.transmittance_spectrum(tile), pplan, 1.0)
    assert np.abs(g / np.pi - 1).max() < 0.005


def test_periodic_tile_mean_is_total_sky_times_mean_transmittance():
    rng = np.random.default_rng(6)
    window = Grid.from_window((0, 0, 6.4, 6.4), 0.1)  # exactly one 64 x 64 tile
    mask = rng.random((32, 32)).astype(np.float32) ** 3
    tile, grid = canopy.tile_on_lattice(mask, center=(3.2, 3.2), size=(6.4, 6.4), lattice=window)
    plan = shadow.plan_periodic(window, grid, height=4.0, alpha=np.radians(75))
    image = rng.random((64, 128, 3)).astype(np.float32)
    sky = EquirectSky(image).raster(plan.sky)
    g = shadow.ground_periodic(sky, shadow.transmittance_spectrum(tile), plan, float(tile.mean()))
    assert g.mean(axis=(1, 2)) == pytest.approx(sky.irradiance * tile.mean(), rel=1e-5)


def test_layers_combine_by_the_product_rule():
    rng = np.random.default_rng(7)
    i0 = np.array([3.0, 2.0, 1.0])
    a = rng.random((3, 4, 5)).astype(np.float32) * i0[:, None, None]
    b = rng.random((3, 4, 5)).astype(np.float32) * i0[:, None, None]
    open_layer = np.broadcast_to(i0[:, None, None], a.shape).astype(np.float32)
    assert np.allclose(combine_layers([a, open_layer], i0), a)
    assert np.allclose(combine_layers([a, b], i0), a * b / i0[:, None, None])
    assert np.allclose(combine_layers([a], i0), a)


ALPHA_85 = np.radians(85)


def ground_from_hdri(image, mask, *, center, size, height, window, alpha=ALPHA_85):
    """Ground irradiance (channels, rows, cols) of an isolated canopy under an equirect sky."""
    occlusion, grid = canopy.occlusion_on_lattice(mask, center=center, size=size, lattice=window)
    plan = shadow.plan_isolated(window, grid, height=height, alpha=alpha)
    sky = EquirectSky(image).raster(plan.sky)
    return shadow.ground_isolated(sky, shadow.occlusion_spectrum(occlusion, plan), plan)


def test_low_sun_in_the_east_throws_the_shadow_west_in_world_coordinates():
    # a bright patch of sky 30 degrees above the eastern horizon, an opaque 2 m square at 8 m
    image, az, zen = equirect_patch(1024, 512, azimuth=(np.radians(88), np.radians(92)),
                                    zenith=(np.radians(58), np.radians(62)), radiance=100.0)
    h, p = 8.0, 0.1
    mask = np.zeros((20, 20), np.float32)
    window = Grid.from_window((-20, -4, 4, 4), p)
    g = ground_from_hdri(image, mask, center=(0, 0), size=(2, 2), height=h, window=window)
    # the shadow is the deficit from the open-sky value, along the row through y = 0
    rows, cols = window.shape
    x, _ = window.ground_from_raster(np.zeros(cols), np.arange(cols))
    deficit = g[0].max() - g[0, rows // 2]
    shadow_x = (deficit * x).sum() / deficit.sum()
    # independent: rays traced from world points to the patch through the square
    points = np.stack([x, np.zeros_like(x)], axis=1)
    square = image_transmittance(mask, center=(0, 0), size=(2, 2))
    mc = monte_carlo_patch(points, height=h, transmittance=square, azimuth=az, zenith=zen,
                           radiance=[100.0], rays=20000, rng=np.random.default_rng(0))[:, 0]
    open_patch = 100.0 * (az[1] - az[0]) * 0.5 * (np.sin(zen[1]) ** 2 - np.sin(zen[0]) ** 2)
    mc_deficit = open_patch - mc
    mc_x = (mc_deficit * x).sum() / mc_deficit.sum()
    expected = -h * np.tan(np.mean(zen))
    assert shadow_x < -10  # west
    assert abs(shadow_x - mc_x) < p
    assert abs(shadow_x - expected) < p
    # and north-south: a patch in the south throws the shadow north
    image_s, _az_s, zen_s = equirect_patch(1024, 512, azimuth=(np.radians(178), np.radians(182)),
                                          zenith=(np.radians(43), np.radians(47)), radiance=100.0)
    window_ns = Grid.from_window((-4, -4, 4, 12), p)
    g = ground_from_hdri(image_s, mask, center=(0, 0), size=(2, 2), height=h, window=window_ns)
    _, y = window_ns.ground_from_raster(np.arange(window_ns.shape[0]), np.zeros(window_ns.shape[0]))
    deficit = g[0].max() - g[0, :, window_ns.shape[1] // 2]
    assert (deficit * y).sum() / deficit.sum() == pytest.approx(h * np.tan(np.mean(zen_s)), abs=p)


def smooth_gradient_sky(azimuth, zenith):
    """A smooth sky: brighter towards the horizon and towards the south-east. [radiance]"""
    base = 0.6 + 0.8 * (1 - np.cos(zenith)) + 0.3 * np.sin(zenith) * np.cos(azimuth - np.radians(135))
    return np.stack([base, 1.1 * base, 1.4 * base], axis=-1)


def equirect_of(function, width, height):
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    zen, az = np.meshgrid(v * np.pi, (u - 0.5) * 2 * np.pi, indexing="ij")
    return function(az, zen).astype(np.float32)


@pytest.mark.parametrize("sky_name", ["uniform", "gradient"])
def test_leafy_canopy_matches_world_monte_carlo_within_one_percent(sky_name):
    rng = np.random.default_rng(8)
    h, p = 8.0, 0.1
    # 20 m of leaves: random blobs, texels of the ground pixel
    n = 200
    yy, xx = np.mgrid[0:n, 0:n]
    mask = np.ones((n, n), np.float32)
    for cx, cy, r in zip(rng.uniform(20, 180, 150), rng.uniform(20, 180, 150), rng.uniform(2, 9, 150)):
        mask[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] *= 0.3
    window = Grid.from_window((-20, -20, 20, 20), p)
    if sky_name == "uniform":
        radiance = lambda az, zen: np.ones((*np.shape(az), 1))  # noqa: E731
        image = np.ones((256, 512, 3), np.float32)
    else:
        radiance = smooth_gradient_sky
        image = equirect_of(smooth_gradient_sky, 1024, 512)
    g = ground_from_hdri(image, mask, center=(0, 0), size=(20, 20), height=h, window=window)
    # Monte Carlo at 60 ground pixels, each averaged over its area by jittered ray origins
    pick = rng.integers(0, window.shape[0], (60, 2))
    rays = 128 * 128
    cx, cy = window.ground_from_raster(pick[:, 0], pick[:, 1])
    jitter = rng.uniform(-p / 2, p / 2, (60, rays, 2))
    origins = np.stack([cx, cy], axis=1)[:, None, :] + jitter
    leaves = image_transmittance(mask, center=(0, 0), size=(20, 20))
    mc = monte_carlo_irradiance(origins, height=h, transmittance=leaves, radiance=radiance,
                                rays=rays, rng=rng)
    ours = g[:, pick[:, 0], pick[:, 1]].T[:, : mc.shape[1]]
    relative_rms = np.sqrt(np.mean((ours - mc) ** 2)) / np.mean(mc)
    assert relative_rms < 0.01


@pytest.mark.parametrize("model", ["uniform", "hdri"])
def test_sky_rasterized_folded_equals_the_folded_raster(model):
    rng = np.random.default_rng(9)
    window = Grid.from_window((0, 0, 3.0, 2.0), 0.1)
    tile, grid = canopy.tile_on_lattice(rng.random((8, 8)).astype(np.float32), center=(0.35, 0.2),
                                        size=(1.7, 1.3), lattice=window)
    plan = shadow.plan_periodic(window, grid, height=1.5, alpha=np.radians(70))
    sky = UniformSky(np.array([1.0, 0.5, 2.0])) if model == "uniform" else EquirectSky(
        rng.random((64, 128, 3)).astype(np.float32))
    full = sky.raster(plan.sky)
    folded = sky.raster(plan.sky, fold_period=plan.tile_shape)
    assert folded.weighted.shape == (3, *plan.tile_shape)
    expected = fold(full.weighted, sky_offset(plan.sky), plan.tile_shape)
    assert np.allclose(folded.weighted, expected, rtol=1e-5, atol=1e-7 * expected.max())
    assert folded.irradiance == pytest.approx(full.irradiance, rel=1e-6)
    spectrum = shadow.transmittance_spectrum(tile)
    a = shadow.ground_periodic(full, spectrum, plan, float(tile.mean()))
    b = shadow.ground_periodic(folded, spectrum, plan, float(tile.mean()))
    assert np.abs(a - b).max() <= 1e-5 * a.max()


def test_sun_kernel_correlation_equals_direct_sum():
    """The fine sun path: a small kernel anywhere inside the planned offsets, through the fine
    mask of the plan, is the brute-force sum of eq. 2."""
    rng = np.random.default_rng(5)
    p, h = 0.1, 2.0
    window = Grid((1.0, 3.0), p, (6, 7))
    centres = rng.uniform(-0.4, 0.4, (3, 2))
    lo, hi = shadow.sun_offset_range(centres, reach=0.1, q=p / h)
    plan = shadow.plan_sun(window, offset_lo=lo, offset_hi=hi)
    assert plan.mask.shape == (6 + hi[0] - lo[0], 7 + hi[1] - lo[1])
    mask = rng.random(plan.mask.shape).astype(np.float32)
    spectrum = shadow.fine_mask_spectrum(mask, plan)
    for _ in range(4):
        start = (int(rng.integers(lo[0], hi[0] - 2)), int(rng.integers(lo[1], hi[1] - 2)))
        shape = (int(rng.integers(1, hi[0] - start[0] + 2)), int(rng.integers(1, hi[1] - start[1] + 2)))
        e = rng.random((3, *shape)).astype(np.float32)
        kernel = SkyRaster(sky_grid(start, shape, p / h), e, np.zeros(3))
        g = shadow.ground_sun(kernel, spectrum, plan)
        # the mask grid's pixel [0, 0] sits at lattice offset lo from the window's
        expected = direct_sum(e, start, mask, lo, window.shape, outside_value=np.nan)
        np.testing.assert_allclose(g, expected, rtol=1e-4, atol=1e-5)


def test_sun_kernel_outside_the_plan_is_refused():
    window = Grid((0.0, 0.0), 0.1, (4, 4))
    plan = shadow.plan_sun(window, offset_lo=(-2, -2), offset_hi=(2, 2))
    spectrum = shadow.fine_mask_spectrum(np.ones(plan.mask.shape, np.float32), plan)
    kernel = SkyRaster(sky_grid((1, 1), (3, 3), 0.05), np.ones((3, 3, 3), np.float32), np.zeros(3))
    with pytest.raises(ValueError, match="outside the planned offsets"):
        shadow.ground_sun(kernel, spectrum, plan)


def test_fine_mask_sits_under_the_sun():
    """World check: a sun to the south-east at height h is seen through the canopy point
    h * s_sun away from the ground point, which is where plan.mask lies."""
    p, h = 0.05, 4.0
    window = Grid.from_window((-1, -1, 1, 1), p)
    s_sun = np.array([0.3, -0.2])  # east and south
    lo, hi = shadow.sun_offset_range(s_sun, reach=0.01, q=p / h)
    plan = shadow.plan_sun(window, offset_lo=lo, offset_hi=hi)
    x0, y0, x1, y1 = plan.mask.extent
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    assert abs(cx - h * s_sun[0]) < 2 * p and abs(cy - h * s_sun[1]) < 2 * p


def test_resample_bilinear_reproduces_a_linear_field():
    coarse = Grid((-2.0, 2.0), 0.5, (8, 8))
    fine = Grid((-1.3, 1.1), 0.07, (20, 25))
    xc, yc = coarse.ground_from_raster(np.arange(8)[:, None], np.arange(8)[None, :])
    field = np.stack([2 * xc - 3 * yc + 1, xc + yc]).astype(np.float32)
    out = shadow.resample_bilinear(field, coarse, fine)
    xf, yf = fine.ground_from_raster(np.arange(20)[:, None], np.arange(25)[None, :])
    np.testing.assert_allclose(out, np.stack([2 * xf - 3 * yf + 1, xf + yf]), atol=1e-5)


@pytest.mark.parametrize("fine", [Grid((-1.3, 1.1), 0.07, (40, 55)), Grid((-4.0, 4.0), 0.3, (30, 1)),
                                  Grid((-1.0, 1.0), 0.013, (150, 160))])
def test_resample_bilinear_has_the_bits_of_the_sparse_products(fine):
    # the compiled loop against the scipy products it replaced, beyond the edges too
    coarse = Grid((-2.0, 2.0), 0.5, (8, 9))
    field = np.random.default_rng(4).normal(size=(3, 8, 9)).astype(np.float32) * 50.0
    rows, cols = shadow.interpolation_matrices(coarse, fine)
    expected = np.stack([(cols @ (rows @ image).T).T for image in field])
    assert expected.dtype == np.float32
    assert shadow.resample_bilinear(field, coarse, fine).tobytes() == expected.tobytes()


@pytest.mark.parametrize("factor, west", [(2, -5.0), (4, -5.25)])
def test_coarser_isolated_is_the_block_mean_mask_and_the_correlation_at_its_cells(factor, west):
    """The coarse spectrum is that of the occlusion averaged over blocks (to float rounding); with
    the sky summed over the same blocks, the ground at the coarse cells is the full-resolution
    ground there, smoothed over less than a block (a smooth sky: 0.1%)."""
    from dataclasses import replace

    import scipy.fft as sfft

    from pipeline.sky.raster import coarser

    rng = np.random.default_rng(1)
    window, canopy_grid = Grid((west, 5.0), 0.25, (42, 39)), Grid((-2.0, 2.0), 0.25, (16, 16))
    plan = shadow.plan_isolated(window, canopy_grid, height=4.0, alpha=np.radians(70.0))
    plan = replace(plan, fft_shape=tuple(-(-n // (2 * factor)) * 2 * factor for n in plan.fft_shape))
    occlusion = (rng.random((16, 16)) < 0.6).astype(np.float32)
    spectrum = shadow.occlusion_spectrum(occlusion, plan)
    coarse_plan, coarse_spectrum, grid = shadow.coarser_isolated(spectrum, plan, factor, window)
    o = sfft.irfft2(spectrum, s=plan.fft_shape)
    block = sum(np.roll(o, (-a, -b), axis=(0, 1)) for a in range(factor) for b in range(factor))
    want = sfft.rfft2(block[::factor, ::factor] / factor**2)
    assert np.abs(coarse_spectrum - want).max() < 1e-5 * np.abs(want).max()
    rows, cols = np.mgrid[0:plan.sky.shape[0], 0:plan.sky.shape[1]]
    light = (1 + 0.3 * np.sin(cols / 7.0) + 0.2 * np.cos(rows / 5.0)).astype(np.float32)[None]
    sky = SkyRaster(plan.sky, light, np.zeros(1))
    fine = shadow.ground_isolated(sky, spectrum, plan)
    coarse = shadow.ground_isolated(coarser(sky, factor), coarse_spectrum, coarse_plan)
    assert coarse.shape[1:] == grid.shape
    x, y = grid.ground_from_raster(np.arange(grid.shape[0]), np.arange(grid.shape[1]))
    r, c = window.raster_from_ground(x, y)  # the coarse centres are centres of the window's cells inside it
    assert np.allclose(r, np.round(r)) and np.allclose(c, np.round(c))
    assert r.min() >= 0 and c.min() >= 0 and r.max() <= window.shape[0] - 1 and c.max() <= window.shape[1] - 1
    assert r.max() > window.shape[0] - 1 - factor and c.max() > window.shape[1] - 1 - factor
    assert np.max(np.abs(coarse / shadow.resample_bilinear(fine, window, grid) - 1)) < 1e-3


@pytest.mark.parametrize("fft_shape, start, count, workers", [
    ((540, 625), -174, 175, 1), ((864, 864), -439, 440, 2), ((75, 96), 30, 60, 1), ((81, 50), -7, 81, 2),
    ((64, 90), 5, 150, 1),  # more rows than the period: wrapped round
    ((540, 625), 0, 175, 1), ((75, 96), 10, 60, 2),  # not wrapped: a view of the rows kept
])
def test_a_correlations_kept_rows_are_irfft2s_rows_to_the_bit(fft_shape, start, count, workers):
    """shadow._correlate with ``rows``: its complex pass down the columns, then the real pass along
    the rows kept and one float32 scale, gives the bits of the whole inverse (scipy's irfft2) at
    those rows, for odd and even sizes, a window wrapped round the period, in one thread or two."""
    rng = np.random.default_rng(sum(fft_shape))
    sky = rng.random((3, fft_shape[0] - 3, fft_shape[1] - 5), dtype=np.float32)
    mask = rng.random(fft_shape, dtype=np.float32)
    spectrum = np.fft.rfft2(mask).astype(np.complex64)
    whole = shadow._correlate(sky, spectrum, fft_shape, workers)
    assert whole.shape == (3, *fft_shape) and whole.dtype == np.float32
    want = whole[:, (start + np.arange(count)) % fft_shape[0]]
    got = shadow._correlate(sky, spectrum, fft_shape, workers, rows=(start, count))
    assert got.dtype == np.float32 and got.tobytes() == want.tobytes()


@pytest.mark.parametrize("fft_shape, at, block, workers", [
    ((750, 1296), (300, 500), (14, 20), 1), ((81, 50), (0, 0), (81, 50), 2), ((64, 90), (40, 71), (24, 19), 1),
])
def test_a_block_placed_in_zeros_correlates_as_the_whole_raster_to_the_bit(fft_shape, at, block, workers):
    """shadow._correlate with ``at`` (the fine sun kernel: only its rows transformed along the rows)
    gives the bits of the raster of zeros with the block in place, whole or at kept rows."""
    rng = np.random.default_rng(block[0])
    kernel = rng.random((3, *block), dtype=np.float32)
    raster = np.zeros((3, *fft_shape), dtype=np.float32)
    raster[:, at[0]:at[0] + block[0], at[1]:at[1] + block[1]] = kernel
    spectrum = np.fft.rfft2(rng.random(fft_shape)).astype(np.complex64)
    for rows in (None, (0, fft_shape[0] // 2)):
        want = shadow._correlate(raster, spectrum, fft_shape, workers, rows=rows)
        got = shadow._correlate(kernel, spectrum, fft_shape, workers, rows=rows, at=at)
        assert got.tobytes() == want.tobytes()


def test_a_sky_raster_zero_but_for_a_block_gives_ground_isolated_to_the_bit():
    """shadow.ground_isolated_block (the coarse sun kernel: only its rows transformed) gives the
    bits of ground_isolated of the whole raster of zeros with the block in place."""
    rng = np.random.default_rng(7)
    checked = 0
    while checked < 4:
        window, canopy_grid, _, h, alpha, _, _, _, mask = random_case(rng, 3)
        plan = shadow.plan_isolated(window, canopy_grid, height=h, alpha=alpha)
        if plan.sky is None or min(plan.sky.shape) < 2:
            continue
        r0, c0 = (int(rng.integers(0, n - 1)) for n in plan.sky.shape)
        block = rng.random((3, int(rng.integers(1, plan.sky.shape[0] - r0 + 1)),
                            int(rng.integers(1, plan.sky.shape[1] - c0 + 1))), dtype=np.float32)
        weighted = np.zeros((3, *plan.sky.shape), dtype=np.float32)
        weighted[:, r0:r0 + block.shape[1], c0:c0 + block.shape[2]] = block
        sky = SkyRaster(plan.sky, weighted, rng.random(3))
        spectrum = shadow.occlusion_spectrum(1 - mask, plan)
        want = shadow.ground_isolated(sky, spectrum, plan)
        got = shadow.ground_isolated_block(block, (r0, c0), sky.irradiance, spectrum, plan)
        assert got.dtype == np.float32 and got.tobytes() == want.tobytes()
        checked += 1


def test_two_layers_under_sun_and_sky_match_world_monte_carlo():
    """Two planes of opaque leaves (8 m and 5.5 m up) under a uniform sky and a small bright patch
    standing for the sun: the layers' rasters combined with the sky's light and the sun's apart
    (``layers.combine_lights``) against rays traced in world coordinates through both planes. Where
    both planes hide the sun the paper's rule on the sum of the two lights scales the sky's light
    down by the sun's share of the open-sky total; the lights combined apart do not."""
    rng = np.random.default_rng(11)
    p, size = 0.1, (20.0, 20.0)
    n = 200
    yy, xx = np.mgrid[0:n, 0:n]
    masks = []
    for _ in range(2):
        mask = np.ones((n, n), np.float32)
        for cx, cy, r in zip(rng.uniform(20, 180, 30), rng.uniform(20, 180, 30), rng.uniform(8, 20, 30)):
            mask[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] = 0.0
        masks.append(mask)
    heights = (8.0, 5.5)
    window = Grid.from_window((-8, -8, 8, 8), p)
    sun_image, azimuth, zenith = equirect_patch(1024, 512, azimuth=np.radians((150, 153)),
                                                zenith=np.radians((30, 33)), radiance=2000.0)
    sky_image = np.ones((256, 512, 3), np.float32)

    def layer(image, mask, height):
        occlusion, grid = canopy.occlusion_on_lattice(mask, center=(0, 0), size=size, lattice=window)
        plan = shadow.plan_isolated(window, grid, height=height, alpha=ALPHA_85)
        raster = EquirectSky(image).raster(plan.sky)
        return shadow.ground_isolated(raster, shadow.occlusion_spectrum(occlusion, plan), plan), raster.irradiance

    skies, suns = zip(*[(layer(sky_image, m, h), layer(sun_image, m, h)) for m, h in zip(masks, heights)])
    sky_total, sun_total = skies[0][1], suns[0][1]
    grounds = [s[0] + u[0] for s, u in zip(skies, suns)]
    apart = combine_lights(grounds, [s[0] for s in skies], sky_total + sun_total, sky_total)[0]
    summed = combine_layers(grounds, sky_total + sun_total)[0]  # the paper's rule on the sum
    planes = [image_transmittance(m, center=(0, 0), size=size) for m in masks]
    # world rays through both planes, each ray's transmittances multiplied, from 60 ground pixels at
    # random and 20 where each plane alone hides the sun (picked from the layers' sun rasters)
    hidden = np.argwhere((suns[0][0][0] < 0.02 * sun_total[0]) & (suns[1][0][0] < 0.02 * sun_total[0]))
    assert len(hidden) > 1000  # the case this is about is there
    pick = np.concatenate([rng.integers(0, window.shape[0], (60, 2)), hidden[rng.choice(len(hidden), 20)]])
    xs, ys = window.ground_from_raster(pick[:, 0], pick[:, 1])
    truth = []
    for x, y in zip(xs, ys):
        def through(dx, dy, x=x, y=y):  # (dx, dy): a ray's offset per metre of height
            return planes[0](x + heights[0] * dx, y + heights[0] * dy) * planes[1](x + heights[1] * dx,
                                                                                 y + heights[1] * dy)
        sky = monte_carlo_irradiance(np.zeros((1, 2)), height=1.0, transmittance=through,
                                     radiance=lambda az, zen: np.ones((*np.shape(az), 1)), rays=64 * 64, rng=rng)
        sun = monte_carlo_patch(np.zeros((1, 2)), height=1.0, transmittance=through, azimuth=azimuth,
                                zenith=zenith, radiance=[2000.0], rays=4000, rng=rng)
        truth.append(float(sky[0, 0] + sun[0, 0]))
    truth, hidden_rows = np.array(truth), slice(60, None)
    ours, paper = apart[pick[:, 0], pick[:, 1]], summed[pick[:, 0], pick[:, 1]]

    def error(estimate, rows):  # mean absolute error over the mean light [1]
        return np.abs(estimate - truth)[rows].mean() / truth[rows].mean()

    # where both planes hide the sun the rule still assumes the planes uncorrelated, which they are
    # not around the sun's direction there: 7 to 9% under the rays (seeds 11 to 13), the rule on
    # the sum 47 to 49%
    assert error(ours, hidden_rows) < 0.15 and error(paper, hidden_rows) > 0.35
    assert error(ours, slice(60)) < 0.06 and error(ours, slice(60)) < 0.7 * error(paper, slice(60))
