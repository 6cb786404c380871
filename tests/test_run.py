"""Runs: frames, video and run.json; resume after SIGKILL; jobs; a Dask cluster. Real processes."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import filelock
import imageio.v2 as imageio
import pytest
import yaml

from pipeline.cache.items import CacheWarning
from pipeline.cache.store import Cache
from pipeline.cli.main import main
from pipeline.core import io
from pipeline.core.errors import RunError
from pipeline.run.folder import frame_files, parse_frames
from pipeline.run.render import _frame_task, _frames_here
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load

ROOT = Path(__file__).resolve().parents[1]

TINY = {
    "canopy": {"height": 4.0, "trees": {"count": 1, "seed": 3, "crown_radius": 1.5,
                                        "leaves_per_tree": 3000, "leaf_length": 0.08},
               "flutter": {"cycle": 3}},
    "sky": {"sun": {"elevation": 60.0, "azimuth": 180.0},
            "moon": {"offset_start": [0.4, 0.1], "offset_end": [0.2, 0.05]},
            "clouds": {"cover": 0.4, "scale": 300.0}},
    # a 512^2 image albedo: the built-in grass (texture and tiling) costs each process of a run about 1 s
    "ground": {"window": [-4, -4, 4, 4], "pixel": 0.05, "sun_window": [-1, -1, 1, 1],
               "albedo": str(ROOT / "configs" / "assets" / "sand.png"), "albedo_size": 2.0},
    "camera": {"resolution": [96, 64]},
    "render": {"sun_cells": 8},
    "animation": {"frames": 8, "fps": 12},
    "output": {"report": False},  # its ~30 renders in their own processes: no matplotlib (test_passes.py)
}


def write_config(folder: Path, config=TINY, name="tiny.yaml") -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(config))
    return path


def sunshade(*args, **popen):
    """A real ``sunshade`` process."""
    return subprocess.Popen([sys.executable, "-m", "pipeline.cli", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def render_here(*args) -> None:
    """``sunshade render`` in this process, for a run whose own process is not what a test is
    about (a reference, a resume): a process of its own costs seconds of imports and warm-up."""
    assert main(["render", *map(str, args)]) == 0


def assert_same_files(folder: Path, expected: dict) -> None:
    """The run folder holds exactly the expected frame and video files, byte for byte."""
    found = contents(folder)
    assert sorted(found) == sorted(expected)
    differ = [name for name in expected if found[name] != expected[name]]
    assert not differ, f"these files differ from the reference run: {differ}"


def contents(folder: Path) -> dict:
    """The bytes of every frame and video file in a run folder (not run.json, not the lock, not
    the report's pictures: tests/test_passes.py)."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())
            if p.suffix in (".exr", ".png", ".mp4", ".gif") and p.name not in ("light-curve.png", "contact-sheet.png")}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run with one job: the bytes every other run must reproduce (made in this
    process; the runs held to it are other processes)."""
    folder = tmp_path_factory.mktemp("reference")
    config = write_config(folder)
    render_here(config, "--jobs", "1", "--output", folder / "run", "--cache", folder / "cache")
    return config, contents(folder / "run")


def test_a_run_writes_every_frame_the_video_and_run_json(reference):
    config, files = reference
    names = [f"tiny.{i:04d}.{ext}" for i in range(8) for ext in ("exr", "png")]
    assert sorted(files) == sorted([*names, "tiny.mp4"])
    folder = config.parent / "run"
    record = json.loads((folder / "run.json").read_text())
    assert record["config_hash"] == io.read_attributes(folder / "tiny.0003.exr", ["sunshade:config_hash"])[
        "sunshade:config_hash"]
    assert [f["frame"] for f in record["frames"]] == list(range(8))
    fractions = [f["sun_fraction"] for f in record["frames"]]
    assert all(0 < s < 1 for s in fractions) and fractions[0] > fractions[-1]  # the moon covers more
    assert record["frames"][0]["sun"] == pytest.approx({"azimuth": 180.0, "elevation": 60.0})
    assert "moon" in record["frames"][0] and record["video"]["frames"] == 8
    exposure = io.read_attributes(folder / "tiny.0003.exr", ["sunshade:exposure"])["sunshade:exposure"]
    assert record["frames"][3]["exposure"] == pytest.approx(exposure) and exposure > 0
    assert {"numpy", "OpenImageIO", "python"} <= set(record["versions"])
    assert record["config"]["animation"]["frames"] == 8
    assert record["timings"]["frames"] > 0 and "ground" in record["timings"]["frame_stages"]
    frames = imageio.mimread(folder / "tiny.mp4")
    assert len(frames) == 8 and frames[0].shape[:2] == (64, 96)


def test_the_video_made_while_rendering_is_the_one_made_from_the_pngs(reference, tmp_path, capsys):
    config, files = reference
    run, cache = tmp_path / "run", config.parent / "cache"
    shutil.copytree(config.parent / "run", run)  # the reference run's frames and video, as written
    (run / "tiny.mp4").unlink()
    capsys.readouterr()
    render_here(config, "--output", run, "--cache", cache)
    assert "0 frames rendered, 8 already done" in capsys.readouterr().out  # the video alone, from the PNGs
    assert_same_files(run, files)


def test_a_second_run_has_nothing_to_do(reference, capsys):
    config, _files = reference
    folder = config.parent / "run"
    before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.suffix != ".json"}
    assert main(["render", str(config), "--output", str(folder), "--cache", str(config.parent / "cache")]) == 0
    assert "0 frames rendered, 8 already done" in capsys.readouterr().out
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.suffix != ".json"} == before
    # run.json keeps the record of the run that did the work, and lists both
    record = json.loads((folder / "run.json").read_text())
    assert [run["frames"] for run in record["runs"]][-2:] == [8, 0]
    assert record["timings"]["frames"] > 0 and record["timings"] == record["runs"][-2]["timings"]
    assert set(record["runs"][-1]["timings"]) == {"check", "total"}
    # the camera the plan placed is written as placed, not as None
    assert record["config"]["placed"] == ["camera"]
    assert len(record["config"]["camera"]["position"]) == 3
    assert record["config"]["ground"]["window"] == pytest.approx([-4, -4, 4, 4])


def test_a_resume_with_nothing_to_do_resolves_nothing(tmp_path, capsys):
    """A site, a time and ``turbidity: auto``: the first run resolves the config (the ephemeris
    checks the sun, pvlib looks the turbidity up) and records the hash of the config as
    written; a resume with nothing to do reads the resolved hash beside it and imports neither
    (docs/runs.md, "Resume"); a changed config is resolved again."""
    sky = {"model": "cie", "turbidity": "auto",
           "site": {"latitude": 32.78, "longitude": -96.80, "elevation": 140.0},
           "time": {"start": "2024-04-08T17:23:15Z", "end": "2024-04-08T17:24:15Z"}}
    config = write_config(tmp_path, {**TINY, "sky": sky, "animation": {"frames": 2, "fps": 12},
                                     "output": {"video": "none"}})
    run, cache = tmp_path / "run", tmp_path / "cache"
    render_here(config, "--output", run, "--cache", cache, "--jobs", "1")  # the resume below: a fresh process
    record = json.loads((run / "run.json").read_text())
    assert record["config"]["sky"]["turbidity"] > 1 and record["source_hash"] != record["config_hash"]
    code = ("import sys; from pipeline.cli.main import main; main(sys.argv[1:]); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'pvlib')"
            " or m in ('pipeline.sky.ephemeris', 'pipeline.stages.plan')))")
    again = subprocess.run([sys.executable, "-c", code, "render", str(config), "--output", str(run),
                            "--cache", str(cache)], capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "0 frames rendered, 2 already done" in again and again.strip().endswith("[]"), again
    assert json.loads((run / "run.json").read_text())["source_hash"] == record["source_hash"]
    config.write_text(config.read_text().replace("17:24:15Z", "17:25:15Z"))  # a new span
    capsys.readouterr()
    render_here(config, "--output", run, "--cache", cache, "--jobs", "1")
    assert "2 frames rendered" in capsys.readouterr().out


def kill_when(process, ready, *, timeout=120.0) -> bool:
    """SIGKILL the process and its workers as soon as ``ready()``; False if it ended first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if ready():
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
            return True
        if process.poll() is not None:
            return False
        time.sleep(0.005)
    raise AssertionError("the run neither reached the kill point nor ended")


def cache_items(cache: Path) -> int:
    """Arrays in the cache so far (0 while a folder walked is renamed under us)."""
    try:
        return sum(1 for _ in cache.rglob("*.npy"))
    except OSError:
        return 0


def pngs(folder: Path) -> int:
    return sum(1 for _ in folder.glob("tiny.*.png")) if folder.exists() else 0


KILL_POINTS = [  # two jobs killed among the frames is the case "at the video"; it and "after five frames" render
    # frames with both one job and two (the resume takes the other count): they hold two jobs to one job's bytes
    ("in the cycle phase", "2", lambda run, cache: cache_items(cache) >= 1),
    ("after five frames", "1", lambda run, cache: pngs(run) >= 5),
    # the video is encoded as the frames are done: killed with it half written
    ("at the video", "2", lambda run, cache: pngs(run) >= 6 and any(run.glob(".tiny.tmp-*.mp4"))),
]


@pytest.mark.parametrize("name,jobs,ready", KILL_POINTS, ids=[k[0] for k in KILL_POINTS])
def test_killed_and_resumed_run_ends_with_the_same_bytes(reference, tmp_path, name, jobs, ready):
    config, files = reference
    run, cache = tmp_path / "run", tmp_path / "cache"
    process = sunshade("render", config, "--jobs", jobs, "--output", run, "--cache", cache,
                       start_new_session=True)
    killed = kill_when(process, lambda: ready(run, cache))
    assert killed, f"the run ended before the kill point: {process.stderr.read()}"
    other = "1" if jobs == "2" else "2"
    render_here(config, "--jobs", other, "--output", run, "--cache", cache)  # the same command again
    assert_same_files(run, files)
    assert not list(run.glob(".*.tmp-*"))


def test_a_changed_config_renders_again_only_what_it_changes(reference, tmp_path, capsys):
    config, files = reference
    run, cache = tmp_path / "run", tmp_path / "cache"
    assert main(["render", str(config), "--frames", "0-2", "--output", str(run), "--cache", str(cache),
                 "--jobs", "1"]) == 0
    assert not (run / "tiny.mp4").exists()  # the video waits for every frame, and the last line says so
    assert json.loads((run / "run.json").read_text())["video"] is None
    assert "3 frames rendered, 0 already done" in (out := capsys.readouterr().out)
    assert out.rstrip().endswith("; the video waits for the other 5 frames"), out
    assert main(["render", str(config), "--frames", "1", "--output", str(run), "--cache", str(cache)]) == 0
    assert capsys.readouterr().out.rstrip().endswith("; the video waits for the other 5 frames")  # nothing to do
    assert main(["render", str(config), "--output", str(run), "--cache", str(cache), "--jobs", "1"]) == 0
    assert "5 frames rendered, 3 already done" in capsys.readouterr().out
    assert_same_files(run, files)
    # the video format does not change a frame; the exposure changes every frame
    gif = write_config(tmp_path, {**TINY, "output": {"video": "gif"}})
    assert main(["render", str(gif), "--output", str(run), "--cache", str(cache), "--jobs", "1"]) == 0
    assert "0 frames rendered, 8 already done" in capsys.readouterr().out
    assert (run / "tiny.gif").is_file()
    brighter = write_config(tmp_path, {**TINY, "camera": {"resolution": [96, 64], "exposure": 1.0}})
    assert main(["render", str(brighter), "--output", str(run), "--cache", str(cache), "--jobs", "1"]) == 0
    assert "8 frames rendered, 0 already done" in capsys.readouterr().out
    changed = contents(run)
    assert changed["tiny.0000.png"] != files["tiny.0000.png"]


def test_preview_is_small_and_apart(reference, tmp_path):
    config, _files = reference
    render_here(config, "--preview", "--frames", "0-1", "--output", tmp_path / "run",
                "--cache", tmp_path / "cache", "--jobs", "1")
    image = io.read_image(tmp_path / "run" / "preview" / "tiny.0000.png")
    assert image.shape[:2] == (16, 24)
    assert not list((tmp_path / "run").glob("tiny.*"))


def test_parse_frames():
    assert parse_frames("0-3,7, 5", 10) == (0, 1, 2, 3, 5, 7)
    assert parse_frames("9", 10) == (9,)
    for bad in ("10", "3-1", "-1", "x", "1-2-3", ""):
        with pytest.raises(RunError):
            parse_frames(bad, 10)


def test_a_second_render_in_the_same_folder_is_refused(reference, tmp_path, capsys):
    """The folder's lock held here (another open file: flock refuses it as it would another
    process's; renders in two processes race in test_two_renders_racing_for_one_new_folder_...)."""
    config, _ = reference
    run = tmp_path / "run"
    run.mkdir()
    with filelock.FileLock(run / ".sunshade.lock"):
        code = main(["render", str(config), "--output", str(run), "--cache", str(tmp_path / "cache")])
    assert code == 2 and "another sunshade render" in capsys.readouterr().err
    assert not list(run.glob("tiny.*"))


def test_a_dask_cluster_renders_the_same_bytes(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    config, files = reference
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        # the command in this process; its cycle products and frames are made by the two workers
        render_here(config, "--scheduler", cluster.scheduler_address,
                    "--output", tmp_path / "run", "--cache", tmp_path / "cache")
    assert_same_files(tmp_path / "run", files)


# -- done means whole (issue 19) and damaged cache items (issue 16) ---------------------


@pytest.fixture
def finished(reference, tmp_path):
    """A copy of the reference run folder and its cache: new inodes and times, same bytes."""
    config, files = reference
    shutil.copytree(config.parent / "run", tmp_path / "run")
    shutil.copytree(config.parent / "cache", tmp_path / "cache")
    return config, files, tmp_path / "run", tmp_path / "cache"


def flip(path: Path, offset: int) -> None:
    """Flip one bit of a file in place."""
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x04
    path.write_bytes(bytes(data))


def damage(run: Path, how: str, name: str) -> None:
    path = run / name
    if how == "truncate":
        os.truncate(path, path.stat().st_size // 2)
    elif how == "corrupt":
        flip(path, path.stat().st_size // 2)
    else:  # replace: another frame's file of the same kind under this name
        other = "tiny.0005" if not name.startswith("tiny.0005") else "tiny.0006"
        shutil.copyfile(run / f"{other}{path.suffix}", path)


def render_in_process(config, run, cache, capsys, *extra) -> tuple[int, str, str]:
    code = main(["render", str(config), "--output", str(run), "--cache", str(cache), *extra])
    out, err = capsys.readouterr()
    return code, out, err


DAMAGE = [("truncate", ("tiny.0000.exr", "tiny.0007.png")),
          ("corrupt", ("tiny.0004.exr", "tiny.0000.png")),
          ("replace", ("tiny.0007.exr", "tiny.0004.png"))]


@pytest.mark.parametrize("how,names", DAMAGE, ids=[d[0] for d in DAMAGE])
def test_damaged_frames_are_found_and_rendered_again(finished, capsys, how, names):
    config, files, run, cache = finished
    for name in names:
        damage(run, how, name)
    stems = sorted(name[:9] for name in names)
    code, out, err = render_in_process(config, run, cache, capsys, "--verify")
    assert code == 1 and err == ""
    assert [line.split(":")[0] for line in out.splitlines()[:-1]] == stems
    assert all(": damaged: " in line for line in out.splitlines()[:-1])
    assert "6 of 8 frames whole, 2 damaged, 0 foreign" in out
    code, out, err = render_in_process(config, run, cache, capsys, "--jobs", "1")
    assert code == 0 and "2 frames rendered, 6 already done" in out
    notes = [line for line in err.splitlines() if "warning" in line]
    assert [line.split(":")[2].strip() for line in notes] == stems  # one line each
    assert all(line.startswith("sunshade: warning: ") and "rendering it again" in line for line in notes)
    assert_same_files(run, files)
    assert render_in_process(config, run, cache, capsys, "--verify")[0] == 0


def items_of_frame(run: Path, frame: int) -> dict:
    return json.loads((run / "index.json").read_text())["frames"][str(frame)]["items"]


@pytest.mark.parametrize("kind", ["spectra", "foreground"])
def test_frames_made_from_a_swapped_cache_item_are_rendered_again(finished, capsys, kind):
    """A cache item replaced by another's bytes after the run: the frames made from it are not
    done (the item may have been wrong when they were made); exactly they render again."""
    config, files, run, cache = finished
    (victim,) = [i for i in items_of_frame(run, 1) if i.startswith(kind)]
    (donor,) = [i for i in items_of_frame(run, 2) if i.startswith(kind)]
    file = "coarse.npy" if kind == "spectra" else "sun.npy"

    def path(item):
        return cache / item.split("/")[0] / item.split("/")[1][:2] / item.split("/")[1] / file

    original = path(victim).read_bytes()
    shutil.copyfile(path(donor), path(victim))
    code, out, _ = render_in_process(config, run, cache, capsys, "--verify")
    assert code == 1 and [line[:9] for line in out.splitlines()[:-1]] == ["tiny.0001", "tiny.0004", "tiny.0007"]
    code, out, err = render_in_process(config, run, cache, capsys, "--jobs", "2")
    assert code == 0 and "3 frames rendered, 5 already done" in out
    assert f"cache item {victim[:len(kind) + 13]} was damaged" in err
    assert_same_files(run, files)
    assert path(victim).read_bytes() == original


def test_unchanged_frames_are_not_read_and_copies_are_hashed_once(finished, capsys):
    """A no-op resume compares sizes, inodes and times with index.json; a copied folder (new
    inodes) is hashed once, found whole, and its new stamps recorded."""
    config, files, run, cache = finished
    index = json.loads((run / "index.json").read_text())
    code, out, err = render_in_process(config, run, cache, capsys)
    assert code == 0 and "0 frames rendered, 8 already done" in out and err == ""
    assert json.loads((run / "index.json").read_text()) != index  # new inodes recorded
    stamps = (run / "index.json").read_bytes()
    assert render_in_process(config, run, cache, capsys)[0] == 0
    assert (run / "index.json").read_bytes() == stamps  # nothing new to record
    assert_same_files(run, files)


def test_foreign_and_unrecorded_frames_are_rendered_again(finished, capsys):
    config, files, run, cache = finished
    index = json.loads((run / "index.json").read_text())
    del index["frames"]["2"]  # as if killed between the rename and the index
    index["frames"]["5"]["config_hash"] = "0" * 16
    (run / "index.json").write_text(json.dumps(index))
    code, out, _ = render_in_process(config, run, cache, capsys, "--verify")
    assert code == 1 and out.splitlines()[:-1] == [
        "tiny.0002: foreign: not recorded in index.json",
        "tiny.0005: foreign: made by another config"]
    code, out, _ = render_in_process(config, run, cache, capsys)
    assert code == 0 and "2 frames rendered, 6 already done" in out
    assert_same_files(run, files)
    (run / "index.json").write_text("{not json")
    code, out, err = render_in_process(config, run, cache, capsys, "--frames", "0-1")
    assert code == 0 and "2 frames rendered, 0 already done" in out and "index.json" in err
    assert_same_files(run, files)


def npy_of(cache: Path, item: str, name: str) -> Path:
    kind, key = item.split("/")
    return cache / kind / key[:2] / key / name


FAULTS = {
    "data": [("spectra", 0, "coarse.npy", -9), ("spectra", 1, "fine.npy", -9),
             ("spectra", 2, "mean.npy", -1), ("foreground", 0, "sun.npy", -9),
             ("foreground", 1, "sky.npy", -9), ("foreground", 2, "alpha.npy", -9)],
    "headers": [("spectra", 0, "coarse.npy", 30), ("spectra", 1, "meta.json", 40),
                ("foreground", 2, "alpha.npy", 60), ("foreground", 0, "meta.json", 60)],
}


@pytest.mark.parametrize("where", list(FAULTS))
def test_flipped_bits_in_every_kind_of_cache_item_never_reach_a_frame(finished, tmp_path, capsys, where):
    """Issue 16: bits flipped in mask spectra, fine masks, means and foreground passes, or in
    their headers: the render says so in one line per item, repairs them and writes the
    reference's bytes."""
    config, files, run, cache = finished
    faults = []
    for kind, cycle_frame, name, offset in FAULTS[where]:
        (item,) = [i for i in items_of_frame(run, cycle_frame) if i.startswith(kind)]
        path = npy_of(cache, item, name)
        faults.append((item, path, path.read_bytes()))
        flip(path, offset)
    fresh = tmp_path / "fresh"  # frames 0-2 read every cycle frame's items
    code, out, err = render_in_process(config, fresh, cache, capsys, "--jobs", "1", "--frames", "0-2")
    assert code == 0 and "Traceback" not in err
    warned = [line for line in err.splitlines() if "cache item" in line]
    assert len(warned) == len(faults) and all(line.startswith("sunshade: warning: ") for line in warned)
    for item, path, before in faults:
        assert any(item[:len(item.split('/')[0]) + 13] in line for line in warned)
        if path.suffix == ".npy":
            assert path.read_bytes() == before  # computed again, the same bytes
    assert_same_files(fresh, {name: files[name] for name in contents(fresh)})
    assert sorted(contents(fresh)) == [f"tiny.000{i}.{ext}" for i in range(3) for ext in ("exr", "png")]
    code, out, err = main(["cache", "verify", "--cache", str(cache)]), *capsys.readouterr()
    assert code == 0 and out.strip().startswith("0 broken")


def test_an_index_that_is_a_folder_stops_the_run_before_any_work(reference, tmp_path, capsys):
    config, _ = reference
    (tmp_path / "run" / "index.json").mkdir(parents=True)
    code, _out, err = render_in_process(config, tmp_path / "run", tmp_path / "cache", capsys)
    assert code == 2 and err.strip().endswith("index.json: is a folder, not a file")
    assert len(err.strip().splitlines()) == 1 and not list((tmp_path / "run").glob("tiny.*"))


def test_damage_found_in_a_worker_comes_back_as_warnings_and_in_the_index_entry(finished, tmp_path):
    """What a frame task (run in a worker process by joblib or Dask) returns: the cache
    warnings it raised, for the command to say, and the items it read, repaired."""
    config_path, files, run, cache = finished
    config = load(config_path)
    config = replace(config, output=replace(config.output, folder=tmp_path / "out"))
    (tmp_path / "out").mkdir()
    (item,) = [i for i in items_of_frame(run, 4) if i.startswith("foreground")]
    flip(npy_of(cache, item, "sky.npy"), -17)
    written = _frame_task(config, plan_run(config), 4, str(cache), config.digest(), 1)
    frame, entry, caught = written.frame, written.entry, written.caught
    assert frame == 4 and [category for category, _ in caught] == [CacheWarning]
    assert f"cache item {item[:23]} was damaged (sky.npy: checksum mismatch" in caught[0][1]
    assert entry["items"][item]["sky.npy"][0] == items_of_frame(run, 4)[item]["sky.npy"][0]
    for path in frame_files(config, 4):
        assert path.read_bytes() == files[path.name]


def test_with_one_job_a_frame_rendered_before_a_failure_is_written_and_yielded(finished, tmp_path):
    """``--jobs 1`` writes frame k while frame k + 1 renders: frames come out in order, with the
    reference's bytes, and when a frame fails to render (99 is past the animation's end) the
    frame before it is still written and handed back before the error."""
    config_path, files, _, cache = finished
    config = load(config_path)
    config = replace(config, output=replace(config.output, folder=tmp_path / "out"))
    (tmp_path / "out").mkdir()
    frames = _frames_here(config, plan_run(config), Cache(cache), [5, 3, 99], config.digest(), 1, False)
    assert [next(frames).frame, next(frames).frame] == [5, 3]
    with pytest.raises(IndexError):
        next(frames)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "tiny.0003.exr", "tiny.0003.png", "tiny.0005.exr", "tiny.0005.png"]
    for frame in (3, 5):
        for path in frame_files(config, frame):
            assert path.read_bytes() == files[path.name]


def test_frames_made_from_an_item_found_damaged_elsewhere_render_again_pruned_do_not(finished, capsys):
    """An item found damaged and removed by another command (here `cache verify --remove`)
    leaves a record of that copy: the frames made from it render again; items pruned or
    cleared say nothing against the frames made from them."""
    config, files, run, cache = finished
    assert "0 frames rendered" in render_in_process(config, run, cache, capsys)[1]  # the copies' inodes
    (item,) = [i for i in items_of_frame(run, 2) if i.startswith("spectra")]
    flip(npy_of(cache, item, "fine.npy"), -33)
    assert main(["cache", "verify", "--remove", "--cache", str(cache)]) == 0
    assert "(removed)" in capsys.readouterr()[0]
    code, out, err = render_in_process(config, run, cache, capsys)
    assert code == 0 and "2 frames rendered, 6 already done" in out
    assert [line.split(":")[2].strip() for line in err.splitlines() if "warning" in line] == [
        "tiny.0002", "tiny.0005"]
    assert "found damaged since (fine.npy: checksum mismatch" in err
    assert_same_files(run, files)
    assert main(["cache", "clear", "--cache", str(cache)]) == 0
    code, out, err = render_in_process(config, run, cache, capsys)
    assert code == 0 and "0 frames rendered, 8 already done" in out


def test_an_unreachable_scheduler_writes_nothing(tmp_path, capfd):
    pytest.importorskip("distributed")
    config = write_config(tmp_path)
    code = main(["render", str(config), "--scheduler", "tcp://127.0.0.1:9", "--output",
                 str(tmp_path / "run"), "--cache", str(tmp_path / "cache")])
    err = capfd.readouterr().err
    assert code == 2 and "cannot reach the scheduler" in err
    assert not (tmp_path / "run").exists()


def test_check_says_the_disk_a_run_needs(reference, capsys):
    """The cache part of the estimate is the most the cycle products take: the spectra at their
    exact array sizes, the trees' passes over the whole frame. Against the reference run's cache
    on disk: the spectra within 2% (the .npy headers), the passes within the whole frame."""
    config, _ = reference
    assert main(["check", str(config)]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.strip().startswith("disk:"))
    estimate = float(line.split("cache at most ")[1].split()[0]) * 1024 ** (" KMG".index(line.split(
        "cache at most ")[1].split()[1][0]) if line.split("cache at most ")[1].split()[1] != "B" else 0)
    cache = config.parent / "cache"
    spectra = sum(p.stat().st_size for p in (cache / "spectra").rglob("*.npy"))
    passes = sum(p.stat().st_size for p in (cache / "foreground").rglob("*.npy"))
    cycle, (width, height) = 3, (96, 64)  # TINY
    assert spectra + passes <= estimate * 1.02, (line, spectra, passes)
    assert estimate <= (spectra + cycle * 8 * 4 * width * height) * 1.02, (line, spectra, passes)


HOLD = """
import sys
from pipeline.cache.store import Cache
with Cache(sys.argv[1]).in_use(set(sys.argv[2:])):
    print("holding", flush=True)
    sys.stdin.read()
"""
"""A live run's part: names the keys as in use until its standard input closes."""


def test_a_run_over_the_cache_budget_ends_under_it_keeping_its_own_and_a_live_run_s_items(tmp_path, capsys):
    """Issue 32: at the end of a render the least recently used items that no live run uses go,
    down to the budget: the run's own items stay, and so does an item another process (a real
    one) holds in use, older though it is; the command says what went in one line."""
    import numpy as np

    from pipeline.stages.cycle import config_item_keys

    config, run, cache = write_config(tmp_path, {**TINY, "output": {"video": "none", "report": False}}), \
        tmp_path / "run", tmp_path / "cache"
    assert render_in_process(config, run, cache, capsys, "--frames", "0-2", "--jobs", "1")[0] == 0  # every cycle frame
    store = Cache(cache)
    mine = set(config_item_keys(plan_run(load(config))))
    for name in ("old", "held"):
        store.get_or_compute("spectra", {"other": name}, lambda: {"a": np.ones(40_000, np.float32)})
    keys = {item.key: item for item in store.list()}
    assert mine < set(keys) and len(keys) == len(mine) + 2
    other_keys = set(keys) - mine
    for item in keys.values():  # the two others used long ago, the oldest first
        age = 10_000 if item.key in other_keys else 100
        os.utime(item.path / "meta.json", (time.time() - age, time.time() - age))
    held = sorted(other_keys)[0]
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(cache), held], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert holder.stdout.readline().strip() == "holding"
        budget = sum(item.bytes for item in keys.values()) - 1  # one item over
        code, out, _ = render_in_process(config, run, cache, capsys, "--frames", "3", "--jobs", "1",
                                         "--cache-size", str(budget))
    finally:
        holder.communicate("")
    assert code == 0
    left = {item.key: item for item in store.list()}
    assert set(left) == mine | {held} and sum(item.bytes for item in left.values()) <= budget
    assert out.strip().splitlines()[-1].startswith("sunshade: the cache was over its budget of ")
    (gone,) = other_keys - {held}
    assert f"removed 1 item ({keys[gone].bytes / 1024:.1f} KiB) that no live run uses" in out
    assert not list((cache / ".runs").glob("*.json"))  # the runs' lists go with them


def test_index_entries_encoded_once_give_the_same_bytes(tmp_path):
    """write_index with the texts of entries already encoded writes the bytes of encoding the whole
    index (json.dumps), and an entry replaced with its text removed is encoded again."""
    from pipeline.run.index import INDEX_FORMAT, write_index

    index = {"3": {"files": {"exr": {"bytes": 10}}, "items": ["a", "b"]}, "0": {"record": {"light": 1.5e-7}}}
    encoded = {}
    write_index(tmp_path, index, encoded)
    whole = json.dumps({"format": INDEX_FORMAT, "frames": index}, separators=(",", ":")) + "\n"
    assert (tmp_path / "index.json").read_text() == whole and set(encoded) == {"3", "0"}
    index["3"] = {"record": None, "name": "caf\u00e9"}
    encoded.pop("3")
    index["7"] = {"items": []}
    write_index(tmp_path, index, encoded)
    whole = json.dumps({"format": INDEX_FORMAT, "frames": index}, separators=(",", ":")) + "\n"
    assert (tmp_path / "index.json").read_text() == whole
    stale = dict(encoded, **{"0": '{"x":1}'})  # a text the caller failed to remove is what is written
    write_index(tmp_path, index, stale)
    assert (tmp_path / "index.json").read_text() != whole


RACE = """
import json, os, sys
from pipeline.cli.main import main


def child(args, log, gate):
    code = 99
    try:
        os.close(gate[1])
        fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.read(gate[0], 1)  # both wait here until the gate opens
        try:
            code = main(args)
        except SystemExit as exc:
            code = exc.code
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code or 0)


def race(configs, folder, cache, logs):
    gate = os.pipe()
    pids = []
    for k, config in enumerate(configs):
        pid = os.fork()
        if pid == 0:
            child(["render", config, "--output", folder, "--cache", cache, "--jobs", "1"], f"{logs}-{k}.log", gate)
        pids.append(pid)
    os.close(gate[0])
    os.write(gate[1], b"go")
    os.close(gate[1])
    codes = [os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) for pid in pids]
    return codes, [open(f"{logs}-{k}.log").read() for k in range(len(configs))]


a, b, root, trials = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
for k, config in enumerate((a, b)):  # alone: the reference bytes, and every loop loaded before the forks
    main(["render", config, "--output", f"{root}/alone-{k}", "--cache", f"{root}/cache", "--jobs", "1"])
found = []
for trial in range(trials):
    for kind, configs in (("same", (a, a)), ("two", (a, b))):
        codes, logs = race(configs, f"{root}/{kind}{trial}/new/run", f"{root}/cache", f"{root}/{kind}{trial}")
        found.append({"folder": f"{root}/{kind}{trial}/new/run", "configs": configs, "codes": codes, "logs": logs})
with open(f"{root}/race.json", "w") as f:
    json.dump(found, f)
"""
"""Two renders forked at the same moment (after a gate both wait on) into the same new folder, two
levels of it new, ``trials`` times with one config and with two: what each exits with and says."""
RACE_TRIALS = 12
"""Races of each kind: nearly every one overlaps, so 24 give the refused render and its one line many times."""


def test_two_renders_racing_for_one_new_folder_leave_one_run_whole(tmp_path):
    """Issue 50: of two renders started at once into one new folder (the same config, and two
    configs), 12 times each, the folder always ends as the renders that ran would leave it one after
    the other. When they overlap, exactly one is refused with its one line and never removes the
    folder or the lock file the other holds; on a loaded machine the first can finish before the
    second reaches the lock, and the second then runs as any later render would (both exit 0: the
    same config finds its frame done, another adds its own frames). Most trials overlap (39 or 40
    of 40 in runs of 20 trials each at load 4-6)."""
    config = {**TINY, "animation": {"frames": 1, "fps": 12}, "output": {"report": False, "video": "none"},
              "sky": {"sun": {"elevation": 60.0, "azimuth": 180.0}}}
    a = write_config(tmp_path, config, "a.yaml")
    b = write_config(tmp_path, {**config, "sky": {"sun": {"elevation": 60.0, "azimuth": 170.0}}}, "b.yaml")
    subprocess.run([sys.executable, "-c", RACE, str(a), str(b), str(tmp_path), str(RACE_TRIALS)], cwd=ROOT,
                   check=True, capture_output=True, timeout=600)
    alone = [contents(tmp_path / f"alone-{k}") for k in (0, 1)]
    assert all(alone) and alone[0] != alone[1]
    trials = json.loads((tmp_path / "race.json").read_text())
    assert len(trials) == 2 * RACE_TRIALS
    overlapped = 0
    for trial in trials:
        folder, codes, logs = Path(trial["folder"]), trial["codes"], trial["logs"]
        assert sorted(codes) in ([0, 2], [0, 0]), (folder, codes, logs)
        if 2 in codes:
            overlapped += 1
            refused = f"sunshade: error: {folder}: another sunshade render is writing to this folder"
            assert logs[codes.index(2)].strip() == refused, logs
        expected: dict[str, bytes] = {}  # what the renders that ran leave, as one after the other would
        for config, code in zip(trial["configs"], codes):
            if code == 0:
                expected.update(alone[0 if Path(config).stem == "a" else 1])
        assert contents(folder) == expected, folder
        left = sorted(p.name for p in folder.iterdir())
        assert left == sorted([*expected, ".sunshade.lock", "index.json", "run.json"]), left
    assert overlapped >= 5, overlapped  # the race itself was run


def test_an_interrupt_while_the_video_finishes_leaves_no_video(tmp_path):
    """Ctrl-C or SIGTERM while the command waits for the encoder (``VideoStream.finish``): the
    encoder is stopped and its temporary file removed, no video under its name. Here the
    interrupt comes from ``finish``'s progress call, with the encoder waiting for the last frame."""
    import numpy as np

    from pipeline.run.video import VideoStream

    written = load(write_config(tmp_path))
    config = replace(written, output=replace(written.output, folder=tmp_path / "run"))
    config.output.folder.mkdir()
    path = config.output.folder / "tiny.mp4"
    count = config.animation.frames
    stream = VideoStream(config, "0" * 16, path, range(count))
    for frame in range(count - 1):  # the last frame never comes: the encoder waits for it
        stream.add(frame, np.full((64, 96, 3), 10 * frame, dtype=np.uint8))

    def interrupted(stage, done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        stream.finish(interrupted, {})
    assert not stream.thread.is_alive()
    assert sorted(p.name for p in config.output.folder.iterdir()) == []  # no video, no temporary
