"""Tests of the cache (pipeline/cache/: store.py, items.py, keys.py): keys, hits and misses, damage and
repair, real concurrent processes, prune, sizes. Real files in tmp_path, real processes; no mocks."""

from __future__ import annotations

import json
import multiprocessing
import os
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline.cache.items import CacheWarning
from pipeline.cache.keys import CODE_VERSION, MAX_PARAM_ARRAY_SIZE, key_of
from pipeline.cache.store import ENV_VAR, Cache, cache_dir, parse_size
from pipeline.cli.main import main
from pipeline.core.geometry import Grid

PARAMS = {"frame": 3, "height": 10.0, "grid": Grid((0.0, 64.0), 0.25, (256, 256)),
          "sun": (0.3, 1.1)}


def spectrum(seed: int = 0, shape=(64, 33)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)


class Counter:
    """A compute function that counts its calls and returns fixed arrays."""
    def __init__(self, seed: int = 0):
        self.calls = 0
        self.seed = seed

    def __call__(self):
        self.calls += 1
        return {"spectrum": spectrum(self.seed), "mean": np.array(0.5, dtype=np.float32)}


def item_of(cache: Cache, kind="mask", params=PARAMS) -> Path:
    return cache.item_path(kind, key_of(kind, params))


# -- keys ------------------------------------------------------------------------------


def test_key_is_stable_hex_and_order_free():
    key = key_of("mask", PARAMS)
    assert len(key) == 64 and int(key, 16) >= 0
    assert key == key_of("mask", dict(reversed(list(PARAMS.items()))))
    assert key == key_of("mask", {**PARAMS, "sun": [0.3, 1.1]})  # tuple and list alike
    assert key == key_of("mask", {**PARAMS, "frame": np.int64(3), "height": np.float64(10.0)})


@pytest.mark.parametrize("change", [
    {"frame": 4},
    {"height": float(np.nextafter(10.0, 11.0))},  # floats are exact
    {"height": 10},  # int and float differ
    {"grid": Grid((0.0, 64.0), 0.25, (256, 257))},
    {"sun": (0.3, 1.1, 0.0)},
    {"extra": None},
])
def test_key_changes_with_any_param(change):
    assert key_of("mask", {**PARAMS, **change}) != key_of("mask", PARAMS)


def test_key_depends_on_kind_and_code_version():
    assert key_of("mask", PARAMS) != key_of("foreground", PARAMS)
    assert CODE_VERSION  # mixed into the hashed document; a bump changes every key


def test_key_rejects_what_it_cannot_hash_exactly():
    with pytest.raises(TypeError, match=r"params\['big'\]"):
        key_of("mask", {"big": np.zeros(MAX_PARAM_ARRAY_SIZE + 1)})
    with pytest.raises(TypeError, match=r"params\['f'\]: unsupported"):
        key_of("mask", {"f": object()})
    with pytest.raises(TypeError, match="keys must be str"):
        key_of("mask", {"d": {1: 2}})
    for kind in ("", "../x", "locks", ".tmp", "a/b"):
        with pytest.raises(ValueError, match="kind"):
            key_of(kind, PARAMS)
    # small arrays and non-finite floats are fine
    assert key_of("m", {"v": np.array([1.0, 2.0])}) != key_of("m", {"v": np.array([1.0, 2.5])})
    assert key_of("m", {"v": float("nan")}) != key_of("m", {"v": float("inf")})


def test_cache_dir_precedence(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert cache_dir() == tmp_path / "cache"
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "env"))
    assert cache_dir() == tmp_path / "env"
    assert cache_dir(tmp_path / "explicit") == tmp_path / "explicit"
    assert cache_dir("rel").is_absolute()


# -- hits and misses -------------------------------------------------------------------


def test_miss_then_hit_returns_read_only_memory_maps(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    first = cache.get_or_compute("mask", PARAMS, compute)
    second = cache.get_or_compute("mask", PARAMS, compute)
    assert compute.calls == 1 and (cache.misses, cache.hits) == (1, 1)
    for result in (first, second):
        assert list(result) == ["spectrum", "mean"]
        assert isinstance(result["spectrum"], np.memmap)
        assert result["spectrum"].dtype == np.complex64 and not result["spectrum"].flags.writeable
        np.testing.assert_array_equal(result["spectrum"], spectrum(0))
        assert result["mean"].shape == () and result["mean"] == np.float32(0.5)
    # a fresh store on the same folder (a second run) computes nothing
    again = Counter()
    Cache(tmp_path).get_or_compute("mask", PARAMS, again)
    assert again.calls == 0
    assert Cache(tmp_path).get("mask", PARAMS) is not None


def test_changed_param_recomputes_only_that_item(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    for frame in range(3):
        cache.get_or_compute("mask", {**PARAMS, "frame": frame}, compute)
    assert compute.calls == 3
    for frame in (0, 1, 2, 3):
        cache.get_or_compute("mask", {**PARAMS, "frame": frame}, compute)
    assert compute.calls == 4
    assert len(cache.list()) == 4


def test_compute_errors_propagate_and_store_nothing(tmp_path):
    cache = Cache(tmp_path)

    def fails():
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        cache.get_or_compute("mask", PARAMS, fails)
    with pytest.raises(TypeError, match="dict of arrays"):
        cache.get_or_compute("mask", PARAMS, lambda: np.zeros(3))
    with pytest.raises(TypeError, match="dtype object"):
        cache.get_or_compute("mask", PARAMS, lambda: {"a": np.array([None])})
    assert cache.list() == [] and cache.get("mask", PARAMS) is None
    assert cache.get_or_compute("mask", PARAMS, Counter())["spectrum"].shape == (64, 33)


def test_non_contiguous_input_is_stored_and_not_mutated(tmp_path):
    a = spectrum(1, (8, 6))
    view = a.T
    out = Cache(tmp_path).get_or_compute("mask", PARAMS, lambda: {"s": view})
    np.testing.assert_array_equal(out["s"], view)
    np.testing.assert_array_equal(a, spectrum(1, (8, 6)))


def test_unwritable_cache_warns_and_still_returns_the_result(tmp_path):
    (tmp_path / "file").write_text("not a folder")
    cache, compute = Cache(tmp_path / "file" / "cache"), Counter()
    with pytest.warns(RuntimeWarning, match="not stored"):
        out = cache.get_or_compute("mask", PARAMS, compute)
    np.testing.assert_array_equal(out["spectrum"], spectrum(0))
    assert compute.calls == 1 and cache.list() == []


# -- damage and repair -----------------------------------------------------------------


def test_truncated_item_is_detected_and_recomputed(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    npy = item_of(cache) / "spectrum.npy"
    os.truncate(npy, npy.stat().st_size - 100)

    (item, problem), = cache.verify()
    assert item.path == item_of(cache) and "spectrum.npy" in problem and "bytes" in problem
    assert cache.get("mask", PARAMS) is None
    out = cache.get_or_compute("mask", PARAMS, compute)  # cheap check, no verify=True needed
    assert compute.calls == 2 and cache.repaired == 1
    np.testing.assert_array_equal(out["spectrum"], spectrum(0))
    assert cache.verify() == []


def test_corrupted_header_is_detected_cheaply(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    npy = item_of(cache) / "spectrum.npy"
    with open(npy, "r+b") as f:
        f.write(b"garbage!")  # same size, broken magic
    out = cache.get_or_compute("mask", PARAMS, compute)
    assert compute.calls == 2
    np.testing.assert_array_equal(out["spectrum"], spectrum(0))


def test_flipped_byte_found_by_verify_and_recomputed_with_verify(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    npy = item_of(cache) / "spectrum.npy"
    data = bytearray(npy.read_bytes())
    data[-5] ^= 0x10
    npy.write_bytes(bytes(data))

    (_item, problem), = cache.verify()
    assert "checksum" in problem and "spectrum.npy" in problem
    out = cache.get_or_compute("mask", PARAMS, compute, verify=True)
    assert compute.calls == 2
    np.testing.assert_array_equal(out["spectrum"], spectrum(0))
    assert cache.verify() == []


def test_verify_remove_deletes_broken_items(tmp_path):
    cache = Cache(tmp_path)
    cache.get_or_compute("mask", PARAMS, Counter())
    cache.get_or_compute("mask", {**PARAMS, "frame": 9}, Counter())
    os.truncate(item_of(cache) / "spectrum.npy", 10)
    assert len(cache.verify(remove=True)) == 1
    assert cache.verify() == [] and len(cache.list()) == 1


def test_missing_meta_is_treated_as_absent(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    (item_of(cache) / "meta.json").unlink()
    (_item, problem), = cache.verify()
    assert "meta.json" in problem
    with pytest.warns(CacheWarning, match="meta.json is missing"):
        assert cache.get("mask", PARAMS) is None  # and removed, to be computed again
    assert cache.list() == []
    cache.get_or_compute("mask", PARAMS, compute)
    assert compute.calls == 2 and cache.verify() == []


def test_meta_records_what_the_item_is(tmp_path):
    cache = Cache(tmp_path)
    before = time.time()
    cache.get_or_compute("mask", PARAMS, Counter())
    meta = json.loads((item_of(cache) / "meta.json").read_text())
    assert meta["kind"] == "mask" and meta["key"] == key_of("mask", PARAMS)
    assert meta["params"]["frame"] == 3 and meta["checksum"] == "crc32"
    spec = meta["arrays"]["spectrum"]
    assert spec["dtype"] == "<c8" and spec["shape"] == [64, 33] and spec["nbytes"] == 64 * 33 * 8
    (item,) = cache.list()
    assert item.bytes == sum(p.stat().st_size for p in item_of(cache).iterdir())
    assert before <= item.created <= item.last_used <= time.time()


# -- two real processes on one key -----------------------------------------------------


def _race_worker(root, marker_dir, barrier, results):
    """Child process: wait for the other one, then ask for the same item."""
    def compute():
        (Path(marker_dir) / f"computed-{os.getpid()}").write_text("")
        time.sleep(0.5)
        # seeded by the process: equal results prove that only one process computed
        return {"spectrum": spectrum(os.getpid(), (128, 65))}

    barrier.wait(timeout=60)
    out = Cache(root).get_or_compute("mask", PARAMS, compute)
    results.put(np.array(out["spectrum"]))


def test_two_processes_compute_one_key_once(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    root, markers = tmp_path / "cache", tmp_path / "markers"
    markers.mkdir()
    barrier, results = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=_race_worker, args=(str(root), str(markers), barrier, results))
             for _ in range(2)]
    for p in procs:
        p.start()
    got = [results.get(timeout=60) for _ in procs]
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    assert len(list(markers.iterdir())) == 1  # exactly one computed
    np.testing.assert_array_equal(got[0], got[1])
    cache = Cache(root)
    (item,) = cache.list()
    assert cache.verify() == []
    np.testing.assert_array_equal(cache.get("mask", PARAMS)["spectrum"], got[0])
    leftovers = [p.name for p in item.path.parent.iterdir() if p.name.startswith(".")]
    assert leftovers == []


# -- maintenance -----------------------------------------------------------------------


def test_prune_removes_least_recently_used_first(tmp_path):
    cache = Cache(tmp_path)
    names = ["a", "b", "c"]
    for name in names:
        cache.get_or_compute("mask", {"name": name}, Counter())
    for age, name in zip((300, 200, 100), names):  # a oldest, c newest
        t = time.time() - age
        os.utime(item_of(cache, params={"name": name}) / "meta.json", (t, t))
    cache.get_or_compute("mask", {"name": "a"}, Counter())  # a hit makes a the newest
    size = {item.params["name"]: item.bytes for item in cache.list()}  # [B], all about equal

    assert cache.prune(sum(size.values())) == []
    removed = cache.prune(size["a"] + size["c"])
    assert [item.params["name"] for item in removed] == ["b"]
    assert sorted(item.params["name"] for item in cache.list()) == ["a", "c"]
    assert [item.params["name"] for item in cache.prune(size["a"])] == ["c"]
    assert len(cache.prune(0)) == 1 and cache.list() == []
    with pytest.raises(ValueError):
        cache.prune(-1)


def test_stale_temp_folder_ignored_by_list_and_removed(tmp_path):
    cache = Cache(tmp_path)
    cache.get_or_compute("mask", PARAMS, Counter())
    key = key_of("mask", {"frame": 1})
    parent = cache.item_path("mask", key).parent
    parent.mkdir(parents=True, exist_ok=True)
    stale = parent / f".tmp-{key}-99999-deadbeef"  # what a killed writer leaves
    stale.mkdir()
    (stale / "spectrum.npy").write_bytes(b"\x93NUMPY half")
    trash = item_of(cache).parent / f".del-{key_of('mask', PARAMS)}-99999-cafe0000"
    trash.mkdir()

    assert [item.key for item in cache.list()] == [key_of("mask", PARAMS)]
    assert cache.verify() == []
    assert cache.get("mask", {"frame": 1}) is None
    cache.prune(10**9)
    assert not stale.exists() and not trash.exists() and len(cache.list()) == 1
    stale.mkdir(parents=True)
    removed = cache.clear()
    assert len(removed) == 1 and not stale.exists()
    assert cache.list() == [] and not (tmp_path / "mask").exists()
    assert not any((tmp_path / "locks").glob("*.lock"))


def test_temp_folder_of_live_writer_is_kept(tmp_path):
    cache = Cache(tmp_path)
    key = key_of("mask", PARAMS)
    parent = cache.item_path("mask", key).parent
    parent.mkdir(parents=True)
    live = parent / f".tmp-{key}-1-00000000"
    live.mkdir()
    (tmp_path / "locks").mkdir()
    with cache._lock(key):  # the writer holds its key's lock until the rename
        cache.clear()
        assert live.exists()
    cache.clear()
    assert not live.exists()


def test_clear_keeps_foreign_files(tmp_path):
    cache = Cache(tmp_path)
    (tmp_path / ".gitkeep").write_text("")
    (tmp_path / "fftw_wisdom.pickle").write_bytes(b"w")
    cache.get_or_compute("mask", PARAMS, Counter())
    cache.clear()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".gitkeep", "fftw_wisdom.pickle"]
    assert Cache(tmp_path / "absent").list() == []
    assert Cache(tmp_path / "absent").clear() == []


@pytest.mark.parametrize("text, expected", [
    ("2G", 2 * 1024**3), ("2g", 2 * 1024**3), ("2GiB", 2 * 1024**3), ("2 GB", 2 * 1024**3),
    ("512M", 512 * 1024**2), ("1.5K", 1536), ("1T", 1024**4), ("1000", 1000), ("7B", 7),
    ("0", 0), (" 3k ", 3072), (4096, 4096),
])
def test_parse_size(text, expected):
    assert parse_size(text) == expected


@pytest.mark.parametrize("text", ["", "G", "2X", "-1G", "2GG", "1e3", "two", "2iB", "nan", -5])
def test_parse_size_rejects_bad_text(text):
    with pytest.raises(ValueError, match="invalid size"):
        parse_size(text)


# -- every read is checked (issue 16) ---------------------------------------------------


def flip_bit(path: Path, offset: int, *, keep_mtime: bool = False) -> None:
    """Flip the lowest bit of one byte of a file in place (offset from the end if negative)."""
    st = path.stat()
    with open(path, "r+b") as f:
        f.seek(offset, os.SEEK_SET if offset >= 0 else os.SEEK_END)
        byte = f.read(1)[0]
        f.seek(-1, os.SEEK_CUR)
        f.write(bytes([byte ^ 1]))
    if keep_mtime:
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


def test_every_read_checks_the_bytes_without_being_asked(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    npy = item_of(cache) / "spectrum.npy"
    original = npy.read_bytes()
    flip_bit(npy, -5, keep_mtime=True)  # the change time still moves: checked again
    with pytest.warns(CacheWarning, match=r"mask/[0-9a-f]{12} was damaged \(spectrum.npy: checksum"):
        out = Cache(tmp_path).get_or_compute("mask", PARAMS, compute)
    assert compute.calls == 2
    np.testing.assert_array_equal(out["spectrum"], spectrum(0))
    assert npy.read_bytes() == original  # repaired on disk
    flip_bit(npy, 200)
    with pytest.warns(CacheWarning, match="damaged"):
        assert cache.get("mask", PARAMS) is None  # get removes it too
    assert cache.list() == []


def test_damaged_meta_json_that_still_parses_is_found(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    meta_path = item_of(cache) / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta["arrays"]["spectrum"]["shape"] = [33, 64]  # valid JSON, wrong content
    meta_path.write_text(json.dumps(meta, indent=1))
    (_item, problem), = cache.verify()
    assert problem == "meta.json: checksum mismatch (corrupted)"
    with pytest.warns(CacheWarning, match="meta.json: checksum mismatch"):
        out = cache.get_or_compute("mask", PARAMS, compute)
    assert compute.calls == 2 and out["spectrum"].shape == (64, 33) and cache.verify() == []


def test_header_damage_in_an_item_of_the_previous_version_is_one_line(tmp_path):
    """Items written before whole-file checksums (no file_crc32, no meta_crc32): a header
    that numpy cannot parse (its tokenizer raises TokenError) is a broken item, not a
    traceback."""
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    meta_path = item_of(cache) / "meta.json"
    meta = json.loads(meta_path.read_text())
    del meta["meta_crc32"], meta["arrays"]["spectrum"]["file_crc32"]
    meta_path.write_text(json.dumps(meta, indent=1))
    assert Cache(tmp_path).get("mask", PARAMS) is not None  # still read, data CRC-32 checked
    npy = item_of(cache) / "spectrum.npy"
    data = bytearray(npy.read_bytes())
    at = data.index(b"'shape'")
    data[at:at + 12] = b"'shape': ((("
    npy.write_bytes(bytes(data))
    (_item, problem), = cache.verify()
    assert problem.startswith("unreadable: TokenError") and "\n" not in problem
    with pytest.warns(CacheWarning, match="TokenError"):
        out = cache.get_or_compute("mask", PARAMS, compute)
    np.testing.assert_array_equal(out["spectrum"], spectrum(0))
    assert compute.calls == 2 and cache.verify() == []


def test_recheck_tells_whether_an_item_is_still_what_was_served(tmp_path):
    cache, compute = Cache(tmp_path), Counter()
    cache.get_or_compute("mask", PARAMS, compute)
    (name, stamp), = cache.served.items()
    assert name == f"mask/{key_of('mask', PARAMS)}" and list(stamp) == ["spectrum.npy", "mean.npy"]
    assert stamp["spectrum.npy"][5] == json.loads((item_of(cache) / "meta.json").read_text())["created"]
    assert cache.recheck(name, stamp) is None  # unchanged: nothing read
    os.utime(item_of(cache) / "spectrum.npy")  # touched, same bytes
    fresh = Cache(tmp_path)
    assert fresh.recheck(name, stamp) is None and fresh.served[name] != stamp
    flip_bit(item_of(cache) / "spectrum.npy", -1)
    assert "damaged" in Cache(tmp_path).recheck(name, stamp, repair=False)
    assert len(cache.list()) == 1  # repair=False removes nothing
    with pytest.warns(CacheWarning):
        assert "damaged" in Cache(tmp_path).recheck(name, stamp)
    assert cache.list() == []
    assert "found damaged since" in cache.recheck(name, stamp)  # that copy, removed as damaged
    again = Cache(tmp_path)
    again.get_or_compute("mask", PARAMS, compute)
    copy = again.served[name]
    assert again.recheck(name, copy) is None
    again.clear()
    assert again.recheck(name, copy) is None  # absent: a clear or prune says nothing against it
    Cache(tmp_path).get_or_compute("mask", PARAMS, Counter(seed=5))  # computed again, other bytes
    assert "other bytes" in Cache(tmp_path).recheck(name, copy)


def test_cache_verify_reports_a_damaged_header_in_one_line(tmp_path, capsys):
    cache = Cache(tmp_path)
    cache.get_or_compute("mask", PARAMS, Counter())
    npy = item_of(cache) / "spectrum.npy"
    data = bytearray(npy.read_bytes())
    data[10:20] = b"{'descr': "[::-1]
    npy.write_bytes(bytes(data))
    assert main(["cache", "verify", "--cache", str(tmp_path)]) == 1
    out, err = capsys.readouterr()
    assert out.splitlines() == [f"mask {key_of('mask', PARAMS)[:16]}: spectrum.npy: checksum "
                                "mismatch (corrupted)", "1 broken of 1 items"]
    assert err == ""


def test_cache_verify_reports_every_entry_that_is_not_an_item(tmp_path, capsys):
    """Issue 33: a file where an item's folder should be, a folder of another name, a stray file
    in a kind's folder and a link are each a line of ``cache verify``; --remove removes them and
    keeps the item and what lies beside the kinds in the root (damaged items' records too)."""
    cache = Cache(tmp_path)
    cache.get_or_compute("mask", PARAMS, Counter())
    key = "ab" * 32
    strays = [tmp_path / "mask" / "ab" / key, tmp_path / "mask" / "not-a-prefix", tmp_path / "mask" / "notes.txt",
              tmp_path / "mask" / "ab" / ("cd" * 32)]
    strays[0].parent.mkdir()
    strays[0].write_text("a file where an item's folder should be")
    strays[1].mkdir()
    strays[2].write_text("notes")
    strays[3].symlink_to(item_of(cache))
    (tmp_path / "wisdom.pickle").write_bytes(b"kept")
    (tmp_path / "damaged").mkdir()  # the records of items found damaged are the cache's own
    (tmp_path / "damaged" / f"{key}.json").write_text("[]")
    assert main(["cache", "verify", "--cache", str(tmp_path)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert sorted(out[:-1]) == sorted([f"{strays[0]}: a file that is not a cache item",
                                       f"{strays[1]}: a folder that is not a cache item",
                                       f"{strays[2]}: a file that is not a cache item",
                                       f"{strays[3]}: a link that is not a cache item"])
    assert out[-1] == "0 broken of 1 items, 4 entries not an item"
    assert main(["cache", "verify", "--cache", str(tmp_path), "--remove"]) == 0
    capsys.readouterr()
    assert not any(p.exists() or p.is_symlink() for p in strays)
    assert item_of(cache).is_dir() and (tmp_path / "wisdom.pickle").exists()
    assert (tmp_path / "damaged" / f"{key}.json").exists()
    assert main(["cache", "verify", "--cache", str(tmp_path)]) == 0
    assert capsys.readouterr().out.splitlines() == ["0 broken of 1 items"]
