"""Every config in configs/ passes ``sunshade check`` and renders its first frame with --preview."""

from pathlib import Path

import numpy as np
import pytest

from pipeline.cli.main import main
from pipeline.config.parse import load_config
from pipeline.config.preview import PREVIEW_CYCLE, preview
from pipeline.core import io

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))


def test_the_demos_are_there():
    names = {path.stem for path in CONFIGS}
    assert {"eclipse", "sun-and-shade", "eclipse-2024-dallas", "forest", "hdri"} <= names


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.mark.parametrize("config", CONFIGS, ids=[path.stem for path in CONFIGS])
def test_config_checks_and_renders_a_preview_frame(config, cache, tmp_path, capsys):
    """One frame: a second one only repeated the first's checks at another flutter phase and time
    (the run machinery over several frames and jobs is tests/test_run.py's)."""
    assert main(["check", str(config)]) == 0
    assert ": ok: " in capsys.readouterr().out
    assert main(["render", str(config), "--preview", "--frames", "0", "--output", str(tmp_path),
                 "--cache", str(cache)]) == 0
    out = capsys.readouterr().out
    assert "1 frame rendered" in out
    assert len([line for line in out.splitlines() if line.startswith("sunshade: preview: ")]) == 1
    picture = io.read_image(tmp_path / "preview" / f"{config.stem}.0000.png")
    assert picture.shape[1] <= 400 and picture.std() > 0.01  # small, and not a flat colour
    radiance = io.read_image(tmp_path / "preview" / f"{config.stem}.0000.exr")
    assert np.all(np.isfinite(radiance)) and radiance.max() > 0


@pytest.mark.parametrize("config", CONFIGS, ids=[path.stem for path in CONFIGS])
def test_a_preview_keeps_every_leaf_and_the_sky(config):
    full = load_config(config)
    quick = preview(full)
    assert quick.canopy.trees == full.canopy.trees and quick.sky == full.sky
    assert quick.canopy.layers == full.canopy.layers and quick.animation == full.animation
    if full.canopy.trees is not None and full.foreground.model != "passes":
        assert quick.canopy.cycle == min(full.canopy.cycle, PREVIEW_CYCLE)
    else:
        assert quick.canopy.cycle == full.canopy.cycle
    assert quick.camera.resolution[0] <= full.camera.resolution[0] // 4
