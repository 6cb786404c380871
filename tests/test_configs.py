"""Every config in configs/ passes ``sunshade check`` and renders two frames with --preview."""

from pathlib import Path

import numpy as np
import pytest

from pipeline import io
from pipeline.cli import main

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))


def test_the_demos_are_there():
    names = {path.stem for path in CONFIGS}
    assert {"eclipse", "sun-and-shade", "eclipse-2024-dallas", "forest", "hdri"} <= names


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.mark.parametrize("config", CONFIGS, ids=[path.stem for path in CONFIGS])
def test_config_checks_and_renders_two_preview_frames(config, cache, tmp_path, capsys):
    assert main(["check", str(config)]) == 0
    assert ": ok: " in capsys.readouterr().out
    assert main(["render", str(config), "--preview", "--frames", "0-1", "--output", str(tmp_path),
                 "--cache", str(cache)]) == 0
    assert "2 frames rendered" in capsys.readouterr().out
    for frame in (0, 1):
        picture = io.read_image(tmp_path / "preview" / f"{config.stem}.{frame:04d}.png")
        assert picture.shape[1] <= 400 and picture.std() > 0.01  # small, and not a flat colour
        radiance = io.read_image(tmp_path / "preview" / f"{config.stem}.{frame:04d}.exr")
        assert np.all(np.isfinite(radiance)) and radiance.max() > 0
