"""Hostile inputs (issue 16): each class through ``check`` and ``render`` exits 2 with one line
naming the key, flag or file, and writes nothing; the ones that once hung or took gigabytes run
as real processes, their memory measured."""

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from scenes import ROOT, base_config, write_config

from pipeline.cli.main import main
from pipeline.config.parse import MAX_FRAMES
from pipeline.config.yamlsafe import MAX_CONFIG_BYTES, MAX_YAML_DEPTH
from pipeline.core import io, paths

MOST_MEMORY = 300e6
"""The most a refused input may take (issue 16). [byte]"""


def tree(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def assert_refused(config, out, capfd, message, *, extra=(), commands=("check", "render")):
    """Exit 2 and one line holding ``message`` on stderr (libpng's own lines included: fd 2
    is captured), and nothing new under ``out``."""
    before = tree(out)
    for command in commands:
        argv = {"check": ["check", str(config)],
                "render": ["render", str(config), "--output", str(out / "run"),
                           "--cache", str(out / "cache"), *extra]}[command]
        assert main(argv) == 2, command
        err = capfd.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, (command, err)
        assert tree(out) == before, command


def alias_bomb():
    lines = ['a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    for parent, child in zip("abcdefghi", "bcdefghij"):
        lines.append(f"{child}: &{child} [{', '.join([f'*{parent}'] * 9)}]")
    return "\n".join(lines) + "\n"  # 9^10 = 3.5e9 strings once expanded


def merge_bomb():
    lines = ["a: &a {k1: 1, k2: 2, k3: 3, k4: 4, k5: 5, k6: 6, k7: 7, k8: 8, k9: 9}"]
    for parent, child in zip("abcdefghi", "bcdefghij"):
        lines.append(f"{child}: &{child} {{<<: [{', '.join([f'*{parent}'] * 9)}]}}")
    return "\n".join(lines) + "\n"  # merge keys copy 9^10 pairs once built


def with_sky(sky, **sections):
    config = base_config()
    config["sky"] = sky
    config.update(sections)
    return yaml.safe_dump(config)


def site(latitude, start, end):
    return {"model": "procedural", "site": {"latitude": latitude, "longitude": 2.35},
            "time": {"start": start, "end": end}}


YAML_TEXT = yaml.safe_dump(base_config())
CASES = [  # name, the config's bytes, the words of the message
    ("latin-1 comment", ("# café\n" + YAML_TEXT).encode("latin-1"), "config.yaml:1: not UTF-8 text (byte 0xe9"),
    ("utf-16", YAML_TEXT.encode("utf-16"), "not UTF-8 text (byte 0xff at offset 0)"),
    ("binary", bytes(range(128, 256)) * 8, "not UTF-8 text (byte 0x80"),
    ("alias bomb", alias_bomb().encode(), "values, its aliases expanded; the most is 100000"),
    ("merge-key bomb", merge_bomb().encode(), "values, its aliases expanded; the most is 100000"),
    ("alias inside itself", b"a: &a [1, *a]\n", "an alias refers to a mapping or list that holds it"),
    ("nested thousands deep", b"a: " + b"[" * 5000 + b"]" * 5000 + b"\n", "nested too deep"),
    ("nested past the limit", b"a: " + b"[" * (MAX_YAML_DEPTH + 2) + b"]" * (MAX_YAML_DEPTH + 2) + b"\n",
     f"the most is {MAX_YAML_DEPTH} levels"),
    ("over a megabyte", b"# padding\n" * (MAX_CONFIG_BYTES // 10 + 1), "the config is over"),
    ("impossible date", b"animation: {frames: 2024-13-45}\n", "not valid YAML (month must be in 1..12)"),
    ("integer past a float", f"animation: {{frames: {'9' * 400}}}\n".encode(),
     "animation.frames: must be a whole number"),
    ("NUL in a mask path", YAML_TEXT.replace("mask: mask.png", 'mask: "mask\\0.png"').encode(),
     "canopy.mask: contains a NUL byte"),
    ("mask name too long", YAML_TEXT.replace("mask: mask.png", f"mask: {'m' * 300}.png").encode(),
     f"canopy.mask: the name 'mmmmmmmmmmmmmmmmmmmmmmmm'... is 304 bytes long; the most is {paths.NAME_MAX}"),
    ("output folder of no user", yaml.safe_dump({**base_config(), "output": {"folder": "~no-such-user-x/r"}}).encode(),
     "output.folder: cannot resolve '~no-such-user-x'"),
    ("billion frames", yaml.safe_dump({**base_config(), "animation": {"frames": 10**9}}).encode(),
     f"animation.frames: 1e+09 frames of 1280 x 720 px would be about 4.24e+03 TB of files; the most is {MAX_FRAMES}"),
    ("huge sun window", with_sky({"model": "procedural"}, ground={"window": [-4, -4, 4, 4], "pixel": 0.1,
                                                                   "sun_window": [-1e4, -1e4, 1e4, 1e4]}).encode(),
     "ground.sun_window: the sun's fine raster would be 40,000,000,000 cells, about 2.08 TB; the most is 16,000,000"),
    ("huge window with a sun", with_sky({"model": "procedural"}, ground={"window": [-150, -150, 150, 150],
                                                                          "pixel": 0.05}).encode(),
     "ground.sun_window: the sun's fine raster would be 36,000,000 cells"),
    ("time across the night", with_sky(site(48.85, "2024-06-01T10:00:00Z", "2024-06-02T10:00:00Z")).encode(),
     "sky.time: the sun is 7.8 degrees below the horizon at 2024-06-01T20:43"),
    ("latitude a hair above 90", with_sky(site(90.0000000001, "2024-06-21T10:00:00Z", "2024-06-21T11:00:00Z")).encode(),
     "sky.site.latitude: must lie in [-90, 90] degrees"),
    # issue 33: numbers and dates past what the code computes with, each refused with its range
    ("frame rate of 1e-300 with clouds", with_sky({"model": "procedural", "clouds": {"cover": 0.4}},
                                                  animation={"fps": 1e-300}).encode(),
     "animation.fps: must lie in [0.01, 1000] frames per second (got 1e-300)"),
    ("year 9999 run past by its offset", with_sky(site(48.85, "9999-12-30T20:00:00-05:00",
                                                       "9999-12-30T21:00:00-05:00")).encode(),
     "sky.time.start: must lie from 0001-01-02T00:00:00Z to 9999-12-30T23:59:59Z in UTC, its offset applied "
     "(got 9999-12-30T20:00:00-05:00)"),
    ("year 1 run before by its offset", with_sky(site(48.85, "0001-01-01T02:00:00+05:00",
                                                      "0001-01-01T03:00:00+05:00")).encode(),
     "sky.time.start: must lie from 0001-01-02T00:00:00Z"),
    ("wind faster than any", with_sky({"model": "procedural", "clouds": {"wind": [1e300, 0.0]}}).encode(),
     "sky.clouds.wind: must lie in [-300, 300] m/s (got 1e+300)"),
    ("cloud seed past 64 bits", with_sky({"model": "procedural", "clouds": {"seed": 2**64}}).encode(),
     "sky.clouds.seed: must lie in [0, 9223372036854775807] (got 18446744073709551616)"),
    ("canopy higher than any", yaml.safe_dump({**base_config(), "canopy": {**base_config()["canopy"],
                                                                          "height": 1e300}}).encode(),
     "canopy.height: must lie in [0.01, 1000] m (got 1e+300)"),
    ("a hundred thousand trees", yaml.safe_dump({**base_config(), "canopy": {
        "trees": {"count": 100000, "leaves_per_tree": 1}}}).encode(),
     "canopy.trees.count: must lie in [1, 1000] trees (got 100000)"),
    ("mask sequence of absurd width", YAML_TEXT.replace("mask: mask.png", "mask: leaves.%0999999999d.png").encode(),
     "canopy.mask: a number field of width 999999999 makes names longer than the most, 255 bytes"),
]


@pytest.mark.parametrize("name,text,message", CASES, ids=[c[0] for c in CASES])
def test_hostile_config_exits_2_in_one_line_and_writes_nothing(inputs, capfd, name, text, message):
    folder, out = inputs
    config = folder / "config.yaml"
    config.write_bytes(text)
    assert_refused(config, out, capfd, message)


def test_truncated_png_is_one_line_without_libpng_s_own(inputs, capfd):
    folder, out = inputs
    whole = (folder / "mask.png").read_bytes()
    (folder / "mask.png").write_bytes(whole[:len(whole) // 2])
    assert_refused(write_config(folder, base_config()), out, capfd, "mask.png: cannot read image")


FLAGS = [  # render's flags: name, arguments, the words of the message
    ("jobs not a number", ["--jobs", "abc"], "argument --jobs: invalid int value: 'abc' (see sunshade render --help)"),
    ("unknown flag", ["--jbos", "2"], "unrecognized arguments: --jbos 2"),
    ("scheduler not an address", ["--scheduler", "no-port-here"],
     "--scheduler no-port-here: must be an address HOST:PORT"),
    ("scheduler port not a number", ["--scheduler", "tcp://127.0.0.1:eighty"],
     "--scheduler tcp://127.0.0.1:eighty: the port must be a whole number from 1 to 65535"),
    ("scheduler port past 65535", ["--scheduler", "127.0.0.1:99999"],
     "the port must be a whole number from 1 to 65535"),
    ("scheduler of another protocol", ["--scheduler", "http://127.0.0.1:8786"], "the protocol must be one of tcp://"),
    ("cache of no user", ["--cache", "~no-such-user-x/cache"], "--cache ~no-such-user-x/cache: cannot resolve"),
    ("cache with a NUL", ["--cache", "a\x00b"], "--cache a\\0b: contains a NUL byte"),
    ("output name too long", ["--output", "o" * 300], f"--output {'o' * 58}...{'o' * 58} (300 characters): the name"),
    ("cluster timeout of 0", ["--cluster-timeout", "0"], "--cluster-timeout must be above 0 s"),
    ("cache size not a size", ["--cache-size", "12X"], "--cache-size: invalid size '12X': expected a number"),
    ("a million jobs", ["--jobs", "1000000"], "--jobs 1000000 would start 1000000 processes on"),
]


@pytest.mark.parametrize("name,args,message", FLAGS, ids=[f[0] for f in FLAGS])
def test_bad_flags_exit_2_in_one_line_naming_the_flag(inputs, capfd, name, args, message):
    folder, out = inputs
    assert_refused(write_config(folder, base_config()), out, capfd, message, extra=args,
                   commands=("render",))


def test_cache_folder_from_the_environment_is_checked(inputs, capfd, monkeypatch):
    folder, out = inputs
    monkeypatch.setenv("SUNSHADE_CACHE", "~no-such-user-x/cache")
    config = write_config(folder, base_config())
    assert main(["ground", str(config), "-o", str(out / "g.exr")]) == 2
    assert capfd.readouterr().err.strip() == (
        "sunshade: error: $SUNSHADE_CACHE ~no-such-user-x/cache: cannot resolve "
        "'~no-such-user-x' (no such user or home folder)")
    assert tree(out) == []


@pytest.mark.parametrize("taken", ["config.0000.exr", "config.0047.png", "run.json", "config.mp4"])
def test_an_output_name_taken_by_a_folder_is_refused(inputs, capfd, taken):
    folder, out = inputs
    (out / "run" / taken).mkdir(parents=True)
    config = write_config(folder, {**base_config(), "output": {"folder": str(out / "run")}})
    assert_refused(config, out, capfd, f"{out / 'run' / taken}: is a folder where the run writes a file")


def test_output_name_too_long_for_a_frame_file(inputs, capfd):
    folder, out = inputs
    config = write_config(folder, {**base_config(), "output": {"name": "n" * 250, "folder": str(out / "run")}})
    assert_refused(config, out, capfd, "the name 'nnnnnnnnnnnnnnnnnnnnnnnn'... is 259 bytes long")


def test_an_unreachable_scheduler_leaves_no_folder(inputs, capfd):
    folder, out = inputs
    config = write_config(folder, base_config())
    argv = ["render", str(config), "--output", str(out / "new" / "run"), "--cache", str(out / "cache"),
            "--scheduler", "tcp://127.0.0.1:9", "--cluster-timeout", "0.5"]
    assert main(argv) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--scheduler tcp://127.0.0.1:9: cannot reach" in err
    assert tree(out) == []


def test_any_remaining_os_error_is_one_line_naming_the_path(inputs, capfd):
    folder, out = inputs
    (out / "cache").write_text("a file where the cache folder goes")
    config = write_config(folder, base_config())
    assert main(["ground", str(config), "-o", str(out / "g.exr"), "--cache", str(out / "cache")]) == 2
    assert capfd.readouterr().err.strip() == f"sunshade: error: --cache {out / 'cache'}: is a file, not a folder"
    # /proc looks writable to root, but no folder can be made in it: a raw OSError
    assert main(["figures", "--preview", "--output", "/proc/sunshade-test/figures"]) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "/proc/sunshade-test" in err, err
    assert "Traceback" not in err


def test_debug_shows_the_traceback_and_still_ends_with_the_line(inputs, capfd):
    folder, _out = inputs
    config = write_config(folder, {**base_config(), "animation": {"frames": 0}})
    assert main(["--debug", "check", str(config)]) == 2
    err = capfd.readouterr().err
    assert "Traceback (most recent call last)" in err
    assert err.strip().splitlines()[-1].startswith("sunshade: error: ")
    assert main(["check", str(config), "--debug"]) == 2
    assert "Traceback" in capfd.readouterr().err


HEAVY = ["alias bomb", "billion frames", "huge sun window",  # issue 16: > 1 minute, 2-4.7 GB
         "mask sequence of absurd width", "a hundred thousand trees"]  # issue 33: 5.7 GB, > 10 minutes


@pytest.mark.parametrize("name", HEAVY)
def test_what_once_hung_or_took_gigabytes_ends_small(inputs, name):
    folder, out = inputs
    _, text, message = next(c for c in CASES if c[0] == name)
    config = folder / "config.yaml"
    config.write_bytes(text)
    for command in (["check", config], ["render", config, "--output", out / "run", "--cache", out / "cache"]):
        code, err, _seconds, peak = run_peak(command, folder)
        assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err
        assert peak < MOST_MEMORY, f"{name}: {peak / 1e6:.0f} MB"
        assert tree(out) == []


PEAK = """
import os, subprocess, sys
process = subprocess.Popen(sys.argv[1:])
_, status, usage = os.wait4(process.pid, 0)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss * 1024)
"""
"""Runs a command and prints its exit code and peak resident memory [byte]: from a small
process, since Linux counts a child's peak from that of the process it was forked from."""


def run_peak(args, cwd):
    """A real ``sunshade`` process: (exit code, stderr, seconds, its peak resident memory [byte])."""
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-c", PEAK, sys.executable, "-m", "pipeline.cli",
                           *map(str, args)], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)  # a guard against a hang, not a time limit
    code, peak = (int(v) for v in done.stdout.split())
    return code, done.stderr, time.monotonic() - started, peak


@pytest.mark.parametrize("name,words", [("con\x00fig.yaml", "con\\0fig.yaml: bad config path: contains a NUL byte"),
                                        ("c" * 300 + ".yaml", "bad config path: the name"),
                                        ("~no-such-user-x/c.yaml", "bad config path: cannot resolve")])
def test_a_bad_config_path_is_one_line(inputs, capfd, name, words):
    _folder, out = inputs
    for argv in (["check", name], ["render", name, "--output", str(out / "run")]):
        assert main(argv) == 2
        err = capfd.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    assert tree(out) == []


# -- issue 33: the second pass ----------------------------------------------------------

NOT_UTF8 = os.fsdecode(b"old-\xe9t\xe9")
"""A folder name of Latin-1 bytes (an old archive's), not UTF-8: Python holds it as surrogates."""


def test_a_folder_name_that_is_not_utf8_is_one_line_naming_the_key(inputs, capfd):
    folder, out = inputs
    (folder / NOT_UTF8).mkdir()
    (folder / NOT_UTF8 / "mask.png").write_bytes((folder / "mask.png").read_bytes())
    (folder / "link").symlink_to(folder / NOT_UTF8)  # the config's own text is UTF-8
    config = write_config(folder, {**base_config(), "canopy": {**base_config()["canopy"], "mask": "link/mask.png"}})
    assert_refused(config, out, capfd, "canopy.mask: ")
    assert_refused(config, out, capfd, r"old-\xe9t\xe9/mask.png holds a byte that is not UTF-8 (0xe9)")


@pytest.mark.parametrize("flag", ["--output", "--cache"])
def test_a_flag_path_that_is_not_utf8_is_one_line_naming_the_flag(inputs, capfd, flag):
    folder, out = inputs
    config = write_config(folder, base_config())
    argv = ["render", str(config), flag, str(out / NOT_UTF8)]
    assert main(argv) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"sunshade: error: {flag} ")
    assert r"old-\xe9t\xe9 holds a byte that is not UTF-8 (0xe9)" in err, err
    assert tree(out) == []


def a_png_header(path, width, height):
    """A PNG whose header says ``width`` x ``height`` 8-bit grey and whose data holds 4 rows: a
    decompression bomb's first bytes (the whole of one would decode to width x height bytes).
    A text chunk of 10 kB passes OpenImageIO's own check of a header against its file's size."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = zlib.compress(b"\0" * (width + 1) * 4)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
                     + chunk(b"tEXt", b"Comment\0" + b"x" * 10_000) + chunk(b"IDAT", rows) + chunk(b"IEND", b""))


def test_an_image_too_large_is_refused_from_its_header_naming_file_and_size(inputs, capfd):
    folder, out = inputs
    a_png_header(folder / "mask.png", 30_000, 30_000)
    assert_refused(write_config(folder, base_config()), out, capfd,
                   f"{folder / 'mask.png'}: is 30000 x 30000 pixels of 1 channel (9e+08 values); the most "
                   "is 5.37e+08 (2 GiB as floats)")


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (8, 8)], ids=["1x1", "one row", "one column", "constant"])
def test_degenerate_images_work_as_albedo_mask_and_sky(inputs, capfd, shape):
    """Each image of one value renders as that value: no warning, no error."""
    folder, out = inputs
    io.write_png(folder / "albedo.png", np.full((*shape, 3), 0.4, np.float32))
    io.write_png(folder / "mask.png", np.full((*shape, 1), 1.0, np.float32))
    io.write_exr(folder / "sky.exr", np.full((*shape, 3), 1.0, np.float32))
    small = {"camera": {"resolution": [32, 18]}, "ground": {**base_config()["ground"], "albedo": "albedo.png"}}
    configs = [{**base_config(), **small},
               {**base_config(), **small, "sky": {"model": "hdri", "hdri": "sky.exr", "alpha": 80.0}}]
    for number, config in enumerate(configs):
        path = write_config(folder, config, f"config{number}.yaml")
        assert main(["frame", str(path), "-o", str(out / f"f{number}.exr")]) == 0
        assert capfd.readouterr().err == ""
        assert np.all(np.isfinite(io.read_image(out / f"f{number}.exr")))


def test_stochastic_tiling_of_one_texel_is_that_texel():
    from pipeline.core.geometry import Grid
    from pipeline.texture import albedo
    from pipeline.texture import mipmap as texture

    texel = np.array([[[0.2, 0.3, 0.4]]], np.float32)
    tiling = albedo.stochastic_tiling(texture.mipmap(texel, Grid((0.0, 1.0), 1.0, (1, 1)), outside="periodic",
                                                     period=(1.0, 1.0)))
    assert np.allclose(tiling.mean, texel[0, 0])
    assert np.all(np.isfinite(tiling.lookups)) and np.allclose(tiling.basis, np.eye(3))


def unwritable_folder(tmp_path) -> Path:
    """A folder in which no file can be made: one of mode 555 for a user, /sys/kernel for root
    (whom a mode does not stop)."""
    if os.geteuid() != 0:
        folder = tmp_path / "read-only"
        folder.mkdir(mode=0o555)
        return folder
    return Path("/sys/kernel")


@pytest.mark.parametrize("command", ["render", "ground", "frame"])
def test_a_cache_that_cannot_be_written_is_found_before_any_work(inputs, capfd, command):
    folder, out = inputs
    cache = unwritable_folder(folder) / "cache"
    config = write_config(folder, base_config())
    argv = {"render": ["render", str(config), "--output", str(out / "run")],
            "ground": ["ground", str(config), "-o", str(out / "g.exr")],
            "frame": ["frame", str(config), "-o", str(out / "f.exr")]}[command]
    assert main([*argv, "--cache", str(cache)]) == 2
    captured = capfd.readouterr()
    assert captured.out == ""  # no progress: nothing was computed
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"sunshade: error: --cache {cache}: cannot write in "), err
    assert err.endswith("give a cache folder that can be written (--cache DIR or $SUNSHADE_CACHE)")
    assert tree(out) == [] and not cache.exists()


def test_an_image_bomb_ends_small(inputs):
    folder, _out = inputs
    a_png_header(folder / "mask.png", 30_000, 30_000)
    config = write_config(folder, base_config())
    code, err, _, peak = run_peak(["check", config], folder)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "30000 x 30000 pixels" in err, err
    assert peak < MOST_MEMORY, f"{peak / 1e6:.0f} MB"


def test_a_long_message_is_cut_in_the_middle_with_its_length(inputs, capfd):
    folder, _out = inputs
    name = "/".join(["d" * 200] * 15) + "/leaves-%04d.png"  # 3000 characters in names the system allows
    config = write_config(folder, YAML_TEXT.replace("mask: mask.png", f"mask: {name}"))
    assert main(["check", str(config)]) == 2
    err = capfd.readouterr().err.strip()
    assert len(err) < 600 and "canopy.mask: no such files:" in err, err
    assert err.count(f".png ({len(str(folder / name))} characters)") == 2 and err.count("...") == 2, err


# -- issue 50: the third pass -----------------------------------------------------------

def with_bad_texel(image, value, at=(3, 5, 1)):
    image = image.copy()
    image[at] = value
    return image


def albedo_with(folder, value):
    io.write_exr(folder / "albedo.exr", with_bad_texel(np.full((32, 32, 3), 0.3, np.float32), value))
    config = base_config()
    config["ground"] = {**config["ground"], "albedo": "albedo.exr", "albedo_size": 2.0}
    return config


def half_mask_with(folder, value):
    io.write_exr(folder / "leaves.exr", with_bad_texel(np.full((40, 40, 3), 0.5, np.float32), value), half=True)
    config = base_config()
    config["canopy"] = {**config["canopy"], "mask": "leaves.exr"}
    return config


def imported_pass_with(folder, value):
    for name in ("sun", "sky", "alpha"):
        pixels = np.full((36, 64, 3), 0.5, np.float32)
        io.write_exr(folder / f"fg_{name}.exr", with_bad_texel(pixels, value) if name == "sky" else pixels)
    config = base_config()
    config["camera"] = {"position": [0.0, -6.0, 1.7], "look_at": [0.0, 0.0, 1.0], "resolution": [64, 36]}
    config["foreground"] = {"model": "passes", "sun": "fg_sun.exr", "sky": "fg_sky.exr", "alpha": "fg_alpha.exr"}
    return config


@pytest.mark.parametrize("value", [np.nan, np.inf], ids=["nan", "inf"])
@pytest.mark.parametrize("make,file,what", [(albedo_with, "albedo.exr", "albedo"),
                                            (half_mask_with, "leaves.exr", "mask"),
                                            (imported_pass_with, "fg_sky.exr", "pass")],
                         ids=["albedo", "half-float mask", "imported pass"])
def test_a_non_finite_texel_of_an_input_is_one_line_naming_it(inputs, capfd, make, file, what, value):
    """Every image a config names is read through one check of finite values: exit 2 from
    check, render and frame (which plans without check_inputs), one line naming the file and the
    first bad texel, nothing written."""
    folder, out = inputs
    config = write_config(folder, make(folder, np.float32(value)))
    shown = "nan" if np.isnan(value) else "inf"
    message = f"{file}: the {what} holds {shown} at row 3, column 5, channel 1; every value must be finite"
    assert_refused(config, out, capfd, message)
    assert main(["frame", str(config), "-o", str(out / "f.png"), "--cache", str(out / "cache")]) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert tree(out) == []


def test_a_non_finite_albedo_is_refused_small(inputs):
    """The albedo that ended in an internal error after 1.1 GB (issue 50): a real process's peak."""
    folder, out = inputs
    config = write_config(folder, albedo_with(folder, np.float32(np.nan)))
    for command in (["render", config, "--output", out / "run", "--cache", out / "cache"],
                    ["frame", config, "-o", out / "f.png", "--cache", out / "cache"]):
        code, err, _, peak = run_peak(command, folder)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "the albedo holds nan" in err, err
        assert peak < MOST_MEMORY, f"{peak / 1e6:.0f} MB"
    assert tree(out) == []


def test_negative_radiance_in_an_hdri_is_read_as_zero_with_the_texels_counted(inputs, capfd):
    folder, out = inputs
    sky = np.ones((32, 64, 3), np.float32)
    sky[2, 3] = [-0.5, 1.0, 1.0]
    sky[4, 9, 2] = -2.0
    io.write_exr(folder / "sky.exr", sky)
    config = write_config(folder, with_sky({"model": "hdri", "hdri": "sky.exr"}))
    assert main(["ground", str(config), "-o", str(out / "g.exr"), "--cache", str(out / "cache")]) == 0
    err = capfd.readouterr().err
    assert "sky.exr: 2 texels of negative radiance (the lowest -2) read as 0" in err, err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
@pytest.mark.parametrize("kind", ["named pipe", "folder", "device"])
def test_an_input_path_that_is_not_a_regular_file_says_what_it_is(inputs, capfd, kind):
    folder, out = inputs
    path = {"named pipe": folder / "pipe.png", "folder": folder / "sub.png", "device": Path("/dev/null")}[kind]
    if kind == "named pipe":
        os.mkfifo(path)
    elif kind == "folder":
        path.mkdir()
    config = base_config()
    config["canopy"]["mask"] = str(path)
    assert_refused(write_config(folder, config), out, capfd, f"canopy.mask: a {kind}, not a regular file: {path}")
    assert "a device, not a regular file" == paths.not_a_file(Path("/dev/null"))
