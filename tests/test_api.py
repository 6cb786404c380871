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
from pipeline.core.errors import RunError
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
    assert next(said for said in calls if said[0] == "video") == ("video", 0, 2)  # each stage's first call
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


def quiet_grove(frames=2):
    """``tiny_grove`` of ``frames`` frames and no video: a run of a frame or two takes a second."""
    return tiny_grove(**{"animation.frames": frames}) | {"output": {"video": "none"}}


@pytest.mark.parametrize("frames", ["0-x", "2", "1-0", [0.5], [True], [-1], [2], [], 3, 1.5, b"01", ["0"]])
def test_frames_from_the_caller_are_checked_at_the_door_as_render_frames_is(tmp_path, capsys, frames):
    """A bad ``frames`` (text the command would refuse too, a float, a bool, a frame outside
    0..1, nothing) raises one line naming --frames, before anything is written; text the
    command takes raises what the command prints."""
    folder = tmp_path / "run"
    with pytest.raises(api.SunshadeError) as raised:
        api.render_run(quiet_grove(), folder, frames=frames, cache=tmp_path / "cache", jobs=1)
    said = str(raised.value)
    assert said.startswith("--frames: ") and "\n" not in said and "Traceback" not in said
    assert isinstance(raised.value, RunError) and list(tmp_path.iterdir()) == []
    if isinstance(frames, str):
        path = write_config(tmp_path, quiet_grove())
        assert main(["render", str(path), "--frames", frames, "--output", str(folder),
                     "--cache", str(tmp_path / "cache")]) == 2
        assert capsys.readouterr().err.strip() == f"sunshade: error: {said}"
        assert list(tmp_path.iterdir()) == [path]


@pytest.mark.parametrize(("call", "flag"), [
    (lambda c: api.render_frame(c, "1"), "--frame"),
    (lambda c: api.render_frame(c, 1.0), "--frame"),
    (lambda c: api.render_frame(c, True), "--frame"),
    (lambda c: api.ground_irradiance(c, -1), "--frame"),
    (lambda c: api.ground_irradiance(c, np.int64(2)), "--frame"),
    (lambda c: api.render_frame(c, 0, threads=0), "--threads"),
    (lambda c: api.render_frame(c, 0, passes=5), "--passes"),
    (lambda c: api.render_frame(c, 0, passes="sun,glow"), "--passes"),
    (lambda c: api.render_run(c, jobs="2"), "--jobs"),
    (lambda c: api.render_run(c, jobs=0), "--jobs"),
    (lambda c: api.render_run(c, jobs=2.0), "--jobs"),
    (lambda c: api.render_run(c, jobs=10**6), "--jobs"),
])
def test_a_frame_jobs_threads_or_passes_of_the_wrong_kind_raise_one_line(tmp_path, monkeypatch, call, flag):
    monkeypatch.chdir(tmp_path)  # the default cache and output folder: nothing may land there
    with pytest.raises(api.SunshadeError) as raised:
        call(quiet_grove())
    assert str(raised.value).startswith(f"{flag} ") or str(raised.value).startswith(f"{flag}: ")
    assert list(tmp_path.iterdir()) == []


def test_a_mapping_s_errors_name_it_not_a_file_that_is_not_there(tmp_path, monkeypatch):
    """A mapping is parsed as if read from ./config.yaml; its errors, from the parse and from the
    plan of a ``Config`` made of it, call it ``config (a mapping)``, as docs/api.md quotes."""
    monkeypatch.chdir(tmp_path)
    quoted = re.findall(r"`(config \(a mapping\): [^`]*)`", (ROOT / "docs" / "api.md").read_text())
    for base_dir in (None, ".", tmp_path):
        with pytest.raises(api.SunshadeError) as raised:
            api.load_config(tiny_grove(**{"sky.alpha": 120}), base_dir=base_dir)
        assert str(raised.value) == quoted[0] == "config (a mapping): sky.alpha: must be below 90 (got 120)"
        assert raised.value.where == "config (a mapping): sky.alpha"
    vast = api.load_config(tiny_grove(**{"ground.sun_pixel": 1e-5}), resolved=False)  # refused once planned
    with pytest.raises(api.SunshadeError, match=r"^config \(a mapping\): ground\.sun_window: ") as raised:
        api.render_frame(vast)
    assert str(tmp_path) not in str(raised.value) and list(tmp_path.iterdir()) == []
    path = write_config(tmp_path, tiny_grove(**{"ground.sun_pixel": 1e-5}))  # a file's errors name the file
    with pytest.raises(api.SunshadeError, match=f"^{re.escape(str(path))}: ground.sun_window: "):
        api.render_frame(api.load_config(path, resolved=False))


def test_the_errors_docs_api_md_quotes_are_what_the_library_raises(tmp_path):
    text = (ROOT / "docs" / "api.md").read_text()
    path = write_config(tmp_path, tiny_grove(**{"sky.alpha": 120}))
    with pytest.raises(api.SunshadeError) as raised:
        api.load_config(path)
    quoted = re.search(r"`configs/x\.yaml:12: (sky\.alpha: [^`]*)`", text).group(1)
    assert str(raised.value).endswith(f".yaml:{raised.value.where.split(':')[1]}: {quoted}")
    lines = re.findall(r"`(--frames: [^`]*)`", text)
    assert len(lines) == 2
    for line in lines:  # "--frames: 0.5 ...", "--frames: 48 ...": of an animation of 48 frames
        given = line.split()[1]
        with pytest.raises(api.SunshadeError) as raised:
            api.render_run(tiny_grove(**{"animation.frames": 48}), tmp_path / "run",
                           frames=[float(given) if "." in given else int(given)])
        assert str(raised.value) == line
    assert list(tmp_path.iterdir()) == [path]


def test_progress_starts_at_what_the_cache_holds(tmp_path):
    """Each stage's first call counts what is done already: from an empty cache ``cycle 0 N``;
    with the products cached (an earlier run's) one call, ``cycle N N``; the frames from 0."""
    calls = {}
    for name, frames in (("first", "1"), ("again", [1])):
        calls[name] = []
        summary = api.render_run(quiet_grove(), tmp_path / name, frames=frames, cache=tmp_path / "cache", jobs=1,
                                 progress=lambda *said, name=name: calls[name].append(said))
        assert summary.rendered == (1,) and summary.skipped == ()
    products = calls["first"][0][2]
    assert products >= 1 and calls["first"][:2] == [("cycle", 0, products), ("cycle", 1, products)]
    assert calls["again"] == [("cycle", products, products), ("frames", 0, 1), ("frames", 1, 1)]
    assert calls["first"][-2:] == calls["again"][-2:]
    done = []
    api.render_run(quiet_grove(), tmp_path / "again", frames=[1], cache=tmp_path / "cache", jobs=1,
                   progress=lambda *said: done.append(said))
    assert done == []  # nothing to do, nothing said
