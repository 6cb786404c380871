import subprocess
import sys

import numpy as np
import pytest
from scenes import ROOT, plan_of, tiny_grove

from pipeline.cache import store as cache
from pipeline.core import io
from pipeline.stages.frame import _apply_haze, render_frame
from pipeline.stages.ground import blend_band


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
        ground = blend_band(ground, result.ground.grid, result.ground.outer.irradiance, result.ground.outer.grid)
    np.testing.assert_allclose(result.radiance, ground / np.pi, rtol=2e-3)
    assert result.sun_fraction == pytest.approx(1.0)


def test_compile_loops_leaves_a_frame_nothing_to_compile_for_its_camera(tmp_path):
    """``compile_loops`` (a render's command runs it while its workers make the cycle
    products) compiles every loop of the frame phase with the types a frame passes: in a
    fresh process, rendering a frame after it compiles nothing more in ``pipeline.kernels``' ``filter``, ``tiling`` or
    ``arrays``. A camera of 96 x 54 pixels: its frame runs the same 23 loops of ``pipeline.kernels`` (the 14
    of those three modules among them) with the same types as one of the default 1280 x 720 (every
    signature compared), in less time."""
    code = (
        "import sys; sys.path.insert(0, 'tests')\n"
        "from pathlib import Path\n"
        "from pipeline.cache import store as cache\n"
        "from pipeline.kernels import arrays as _array_loops, filter as _filter, tiling as _tiling\n"
        "from pipeline.stages.frame import compile_loops, render_frame\n"
        "from scenes import plan_of, tiny_grove\n"
        "folder = Path(sys.argv[1])\n"
        "plan = plan_of(tiny_grove(**{'sky.clouds': {'cover': 0.4, 'scale': 300.0},\n"
        "                             'camera': {'resolution': [96, 54]}}), folder)\n"
        "compile_loops(plan)\n"
        "loops = [f for m in (_filter, _tiling, _array_loops) for f in vars(m).values() if hasattr(f, 'signatures')]\n"
        "before = {f.__name__: len(f.signatures) for f in loops}\n"
        "assert sum(before.values()) > 0, before\n"
        "render_frame(plan, 0, store=cache.Cache(folder / 'cache'))\n"
        "print({f.__name__: len(f.signatures) - before[f.__name__] for f in loops"
        " if len(f.signatures) > before[f.__name__]})\n")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout
    assert out.strip() == "{}", out


def test_the_rasterisers_compile_loops_leave_a_cycle_product_nothing_to_compile(tmp_path):
    """``rasteriser.compile_loops`` (a render's command has a worker run it while it plans the run)
    compiles every loop of a cycle product with the types a product passes: in a fresh process,
    making a cycle product of a grove with leaves and wood after it compiles nothing more in
    ``pipeline.kernels``' ``raster``, and it ran each of them."""
    code = (
        "import sys; sys.path.insert(0, 'tests')\n"
        "from pathlib import Path\n"
        "from pipeline.cache import store as cache\n"
        "from pipeline.canopy.rasteriser import compile_loops\n"
        "from pipeline.kernels import raster\n"
        "from pipeline.stages.cycle import cycle_item\n"
        "from pipeline.stages.inputs import grove_of\n"
        "from scenes import plan_of, tiny_grove\n"
        "folder = Path(sys.argv[1])\n"
        "plan = plan_of(tiny_grove(), folder)\n"
        "assert len(grove_of(plan.canopy)[0].wood.radius) > 0\n"
        "compile_loops()\n"
        "loops = [f for f in vars(raster).values() if hasattr(f, 'signatures')]\n"
        "before = {f.__name__: len(f.signatures) for f in loops}\n"
        "assert before['shapes'] == before['flutter'] == before['onto'] == 1, before\n"
        "cycle_item(plan, 0, 0, cache.Cache(folder / 'cache'))\n"
        "print({f.__name__: len(f.signatures) - before[f.__name__] for f in loops"
        " if len(f.signatures) > before[f.__name__]})\n")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout
    assert out.strip() == "{}", out


def test_the_compiled_haze_has_the_bits_of_the_array_operations():
    rng = np.random.default_rng(5)
    background = rng.normal(size=(37, 53, 3)).astype(np.float32) * 40.0
    transmittance = rng.random((37, 53, 1), dtype=np.float32)
    background[::7, ::5], transmittance[::7, ::5] = -0.0, 1.0
    veil = 1.0 - transmittance
    horizon = rng.random((53, 3), dtype=np.float32) * 9.0
    horizon[::5] = -0.0  # with the -0 above: -0 T + 0 (-0) is -0, and + 0 makes it +0
    expected = background * transmittance
    expected += veil * horizon[None]
    expected = expected + np.float32(0.0)
    _apply_haze(background, transmittance, veil, horizon)
    assert background.tobytes() == expected.tobytes()
