"""The Python API (docs/api.md): its worked example runs; a frame and a ground in arrays are the
commands' EXRs to the bit; a run reports its progress; an error is the command's own line."""

import re
from pathlib import Path

import numpy as np
import pytest
from scenes import ROOT, tiny_grove, write_config

import pipeline.api as api
from pipeline.cli.main import main
from pipeline.core import io
from pipeline.sky.ephemeris import Site, contact_times

ALL = "sun,sky,alpha,illuminance,depth"


def grove():
    """A tiny grove with trees in front, 48 x 32 px, at a site and time (two frames)."""
    config = tiny_grove()
    config["foreground"] = {"model": "trees"}
    config["camera"] = {"position": [6.0, -6.0, 1.7], "look_at": [0.0, 0.0, 2.0], "resolution": [48, 32]}
    config["sky"] = {"model": "procedural", "alpha": 70.0, "site": {"latitude": 48.1, "longitude": 11.6},
                     "time": {"start": "2024-06-01T10:00:00Z", "end": "2024-06-01T10:00:04Z"}}
    config["animation"] = {"frames": 2}
    return config


def test_the_worked_example_in_docs_api_md_runs(tmp_path, monkeypatch, capsys):
    code = re.search(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(), re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "docs/api.md", "exec"), {})
    said = capsys.readouterr().out.splitlines()
    assert said[0].startswith("(40, 64, 3) 2026-06-21T07:00:02+00:00")
    assert said[-1].endswith("sky.alpha: must be below 90 (got 120)")
    assert "partial" in said[-2]


def test_a_frame_in_python_is_the_frame_command_s_exr_to_the_bit(tmp_path):
    path = write_config(tmp_path, grove())
    cache = tmp_path / "cache"
    exr = tmp_path / "frame.exr"
    assert main(["frame", str(path), "--frame", "1", "--passes", ALL, "--threads", "1", "--cache", str(cache),
                 "-o", str(exr)]) == 0
    frame = api.render_frame(path, 1, cache=cache, threads=1)
    stored = io.read_layers(exr)
    np.testing.assert_array_equal(np.stack([stored[c] for c in "RGB"], axis=-1), frame.beauty)
    for name in ("sun", "sky"):
        np.testing.assert_array_equal(np.stack([stored[f"{name}.{c}"] for c in "RGB"], axis=-1),
                                      getattr(frame, name))
    for array, channel in ((frame.alpha, "alpha.A"), (frame.lux, "illuminance.Y"), (frame.depth, "depth.Z")):
        np.testing.assert_array_equal(stored[channel], array)
    header = io.read_attributes(exr, list(frame.metadata))
    assert header["sunshade:config_hash"] == frame.metadata["sunshade:config_hash"]
    assert header["sunshade:time_utc"] == frame.metadata["sunshade:time_utc"] == "2024-06-01T10:00:04+00:00"
    assert np.float32(header["sunshade:sun_fraction"]) == np.float32(frame.sun_fraction)


def test_the_ground_in_python_is_the_ground_command_s_exr_to_the_bit(tmp_path):
    path = write_config(tmp_path, grove())
    exr = tmp_path / "ground.exr"
    assert main(["ground", str(path), "--frame", "1", "--threads", "1", "--cache", str(tmp_path / "cache"),
                 "-o", str(exr)]) == 0
    ground = api.ground_irradiance(path, 1, cache=tmp_path / "cache", threads=1)
    np.testing.assert_array_equal(io.read_image(exr), ground.irradiance)
    assert io.read_attributes(exr, ["sunshade:config_hash"])["sunshade:config_hash"] == \
        ground.metadata["sunshade:config_hash"]
    assert ground.exact and ground.unshadowed.shape == (3,)


def test_a_run_reports_its_progress_and_resumes(tmp_path):
    calls = []
    folder = tmp_path / "run"
    summary = api.render_run(grove(), folder, cache=tmp_path / "cache", jobs=1,
                             progress=lambda *said: calls.append(said))
    assert summary.rendered == (0, 1) and summary.video == folder / "config.mp4"
    assert ("frames", 2, 2) in calls and ("video", 2, 2) in calls and calls[0][0] == "cycle"
    assert {p.name for p in folder.glob("config.000?.*")} == {"config.0000.exr", "config.0000.png",
                                                             "config.0001.exr", "config.0001.png"}
    again = api.render_run(grove(), folder, cache=tmp_path / "cache", jobs=1)
    assert again.rendered == () and again.skipped == (0, 1)


@pytest.mark.parametrize(("key", "value"), [("sky.alpha", 120), ("animation.frames", 0), ("output.video", "avi")])
def test_a_config_error_raises_the_line_the_command_prints(tmp_path, capsys, key, value):
    config = grove()
    section, name = key.split(".")
    config.setdefault(section, {})[name] = value
    path = write_config(tmp_path, config)
    assert main(["check", str(path)]) == 2
    printed = capsys.readouterr().err.strip()
    with pytest.raises(api.SunshadeError) as raised:
        api.load_config(path)
    assert printed == f"sunshade: error: {raised.value}"
    assert key in printed and list(tmp_path.iterdir()) == [path]


def test_a_bad_frame_or_pass_raises_as_the_frame_command_says(tmp_path, capsys):
    path = write_config(tmp_path, grove())
    for argv, call in ((["--frame", "5"], lambda: api.render_frame(path, 5)),
                       (["--passes", "glow"], lambda: api.render_frame(path, 0, passes=["glow"]))):
        assert main(["frame", str(path), *argv, "-o", str(tmp_path / "f.exr")]) == 2
        printed = capsys.readouterr().err.strip()
        with pytest.raises(api.SunshadeError) as raised:
            call()
        assert printed == f"sunshade: error: {raised.value}"
    assert not (tmp_path / "f.exr").exists()


def test_an_eclipse_s_contacts_are_the_ephemeris_s(tmp_path):
    """Dallas, 2024 April 8: a total eclipse; its contacts are ``contact_times``' over the same span."""
    found = api.eclipse(32.7767, -96.797, "2024-04-08T17:00:00+00:00", "2024-04-08T20:30:00")
    assert found.kind == "total" and 200 < found.central < 280 and found.obscuration == 1.0
    site = Site.from_degrees(32.7767, -96.797)
    direct = contact_times(site, found.contacts["C1"].replace(second=0, microsecond=0),
                           found.contacts["C4"].replace(microsecond=0).replace(second=59))
    for name in ("C1", "C2", "C3", "C4"):
        assert abs((found.contacts[name] - direct[name]).total_seconds()) < 0.1, name
    with pytest.raises(api.SunshadeError, match=r"latitude must be within -90\.\.90 degrees"):
        api.eclipse(95.0, 0.0, "2024-04-08", "2024-04-09")
    with pytest.raises(api.SunshadeError, match="start: not an ISO 8601 time: 'yesterday'"):
        api.eclipse(0.0, 0.0, "yesterday", "2024-04-09")


def test_importing_the_api_stays_cheap():
    """The API's module imports neither numpy's users among the stages nor PyOpenColorIO."""
    import subprocess
    import sys

    loaded = subprocess.run([sys.executable, "-c", "import sys, pipeline.api; print(' '.join(sys.modules))"],
                            capture_output=True, text=True, check=True, cwd=Path(__file__).parent).stdout.split()
    assert "PyOpenColorIO" not in loaded and "pipeline.stages.frame" not in loaded and "numba" not in loaded
