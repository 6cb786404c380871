import numpy as np
import pytest

from pipeline import cache, io
from pipeline.frame import render_frame
from pipeline.ground import blend_band

from scenes import plan_of, tiny_grove


def test_a_camera_looking_straight_down_sees_the_ground_raster(tmp_path):
    """No foreground, no haze, a white albedo: a camera straight above the sun window whose
    pixels fall on the raster's pixels shows radiance E / pi of the ground raster, north up."""
    io.write_exr(tmp_path / "white.exr", np.ones((4, 4, 3), np.float32))
    height = 2.0
    fov = float(np.degrees(2 * np.arctan(1.0 / height)))  # 2 m across at 2 m: one 0.04 m texel per pixel
    plan = plan_of(tiny_grove(**{
        "ground.albedo": "white.exr", "sky.haze": 0.0, "foreground": {"model": "none"},
        "camera": {"position": [0.0, 0.0, height], "yaw": 0.0, "pitch": -90.0, "fov": fov,
                   "resolution": [50, 50]}}), tmp_path)
    result = render_frame(plan, 0, store=cache.Cache(tmp_path / "c"))
    ground = result.ground.irradiance
    assert ground.shape == (50, 50, 3)
    if result.ground.outer:  # within the blend band the fine raster gives way to the coarse one
        ground = blend_band(ground, result.ground.grid, *result.ground.outer)
    np.testing.assert_allclose(result.radiance, ground / np.pi, rtol=2e-3)
    assert result.sun_fraction == pytest.approx(1.0)
