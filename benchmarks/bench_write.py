"""CPU of a frame's write stage, part by part, with this checkout's ``core.io`` and a baseline's.

    python benchmarks/bench_write.py [CONFIG] [--frame 3] [--repeat 15] [--baseline TREE]
        [--passes sun,sky,alpha,illuminance,depth] [--cache DIR] [--alternatives]

Renders one real frame of CONFIG (default configs/eclipse.yaml, the README's demo; its cycle
product made first in ``--cache``, default a fresh folder, not timed), then writes that frame's
files as a run writes them (``run.render._write_task``: the finiteness check, the EXR with its
layers and attributes, the display codes, the PNG, then ``contents.frame_record`` and the
``index.file_stamp`` of both files, which read them back) ``--repeat`` times into a fresh folder,
each part timed by ``time.process_time`` (the process's CPU, every thread). The EXR, the display
codes and the PNG are made both by this checkout (``core.io``,
``camera.composite.display_codes``) and by TREE's (``--baseline``, e.g. a ``git worktree add`` of
the commit before; its ``pipeline/core/io.py`` and ``pipeline/camera/composite.py`` loaded beside
this one's, numpy casting to half in its ``write_exr``), alternated within each repetition; the
other parts are this checkout's for both. Prints each
part's median CPU [ms] per frame for both, the totals and their ratio, whether the two EXRs are
byte-identical and whether the two PNGs decode to the same codes, and the load average before
and after. One FFT thread renders; OpenEXR and zlib write in the calling thread.
``--alternatives`` also times the frame's half RGB through OpenEXR's bindings with each lossless
compression, and its PNG's filtered rows with other deflaters (zlib-ng settings; ISA-L's ``isal``
and libdeflate's ``deflate`` where importable): ms and MB each (docs/accuracy.md, "The write stage").
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.cache import store as cache
from pipeline.core import io
from pipeline.run.contents import exr_layers, frame_attributes, frame_picture, frame_record, in_working_space
from pipeline.run.folder import frame_files
from pipeline.run.index import file_stamp
from pipeline.stages.cycle import cycle_phase
from pipeline.stages.frame import render_frame
from pipeline.stages.lighting import with_exposures
from pipeline.stages.plan import plan_run
from pipeline.stages.resolve import load

PARTS = ("finite", "exr", "display codes", "png", "record", "stamps")


def baseline_module(tree: Path, name: str):
    """TREE's ``pipeline/NAME.py`` (``core/io``, ``camera/composite``) as a module of its own (its
    imports of other modules are this checkout's)."""
    spec = importlib.util.spec_from_file_location(f"baseline_{name.replace('/', '_')}",
                                                  tree / "pipeline" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_frame(module, config, result, frame: int, composite=None) -> dict[str, float]:
    """The write stage of ``run.render._write_task`` with ``module`` as ``core.io``: CPU [s] per part.
    ``composite``:
    a baseline's ``camera.composite`` whose ``display_codes`` makes the PNG's codes, or None for
    this checkout's ``contents.frame_picture``."""
    seconds: dict[str, float] = {}
    mark = time.process_time()

    def lap(part: str) -> None:
        nonlocal mark
        now = time.process_time()
        seconds[part] = now - mark
        mark = now

    assert np.all(np.isfinite(result.radiance))
    lap("finite")
    exr, png = frame_files(config, frame)
    half = config.output.half
    pixels = in_working_space(config.output, result.radiance)
    layers = exr_layers(result, half, config.output)
    module.write_exr(exr, pixels, frame_attributes(config, result, "bench"), half=half, layers=layers)
    lap("exr")
    if composite is not None and config.output.view is None:
        picture = composite.display_codes(result.radiance, exposure=result.exposure,
                                          transform=config.camera.display, balance=result.balance)
    else:
        picture = frame_picture(config, result)
    lap("display codes")
    module.write_png(png, picture, {"sunshade:config_hash": "bench", "sunshade:frame": str(frame)})
    lap("png")
    frame_record(config, frame, "bench")
    lap("record")
    file_stamp(exr), file_stamp(png)
    lap("stamps")
    return seconds


def median_ms(run, repeat: int) -> float:
    """Median CPU [ms] of ``run()`` over ``repeat`` calls (``time.process_time``)."""
    seconds = []
    for _ in range(repeat):
        mark = time.process_time()
        run()
        seconds.append(time.process_time() - mark)
    return statistics.median(seconds) * 1e3


def alternatives(radiance: np.ndarray, codes: np.ndarray, folder: Path, repeat: int) -> None:
    """CPU [ms] and size [MB] of the frame's half RGB through OpenEXR's bindings with each lossless
    compression, and of its PNG's "Sub"-filtered rows with each deflater: what other settings
    would cost (each moves the files' bytes; PIZ and zlib-ng's Huffman-only level 2 are today's)."""
    import zlib

    import OpenEXR
    from zlib_ng import zlib_ng

    print("float32 -> half, planar (numpy's cast, as write_exr): "
          f"{median_ms(lambda: radiance.transpose(2, 0, 1).astype(np.float16, order='C'), repeat):.1f} ms")
    planes = dict(zip("RGB", radiance.transpose(2, 0, 1).astype(np.float16, order="C")))
    path = folder / "alternative.exr"
    for name in ("PIZ", "NO", "RLE", "ZIPS", "ZIP", "ZSTD", "HTJ2K256", "HTJ2K32"):
        if not hasattr(OpenEXR, f"{name}_COMPRESSION"):
            continue
        exr = OpenEXR.File({"compression": getattr(OpenEXR, f"{name}_COMPRESSION")}, planes)
        ms = median_ms(lambda exr=exr: exr.write(str(path)), repeat)
        print(f"EXR {name:>9s}: {ms:6.1f} ms, {path.stat().st_size / 1e6:.3f} MB")
    rows, cols, channels = codes.shape
    line = codes.reshape(rows, cols * channels)
    filtered = np.empty((rows, cols * channels + 1), dtype=np.uint8)  # as core.io's PNG rows
    filtered[:, 0] = io.PNG_FILTER_SUB
    filtered[:, 1:1 + channels] = line[:, :channels]
    np.subtract(line[:, channels:], line[:, :-channels], out=filtered[:, 1 + channels:])
    data = filtered.tobytes()

    def zng(level: int, strategy: int, memory: int = 8):
        return lambda: (lambda d: d.compress(data) + d.flush())(
            zlib_ng.compressobj(level, zlib.DEFLATED, 15, memory, strategy))

    deflaters = {"zlib-ng 2 Huffman only": zng(io.PNG_ZLIB_LEVEL, io.PNG_ZLIB_STRATEGY),
                 "zlib-ng 2 Huffman only, memLevel 9": zng(io.PNG_ZLIB_LEVEL, io.PNG_ZLIB_STRATEGY, 9),
                 "zlib-ng 1 RLE": zng(1, zlib.Z_RLE), "zlib-ng 0 (stored)": zng(0, zlib.Z_DEFAULT_STRATEGY)}
    try:
        from isal import isal_zlib
        deflaters.update({f"isal {level}": (lambda level=level: isal_zlib.compress(data, level))
                          for level in range(4)})
    except ImportError:
        print("isal not importable: not timed")
    try:
        import deflate
        deflaters.update({f"libdeflate {level}": (lambda level=level: deflate.zlib_compress(data, level))
                          for level in (1, 2)})
    except ImportError:
        print("deflate (libdeflate) not importable: not timed")
    for name, run in deflaters.items():
        packed = run()
        assert zlib.decompress(packed) == data
        print(f"PNG rows, {name:>34s}: {median_ms(run, repeat):6.1f} ms, {len(packed) / 1e6:.3f} MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(ROOT / "configs" / "eclipse.yaml"))
    parser.add_argument("--frame", type=int, default=3)
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--baseline", type=Path, default=None, help="the tree whose core/io.py is the baseline")
    parser.add_argument("--passes", default="", help="light passes to write as layers (default: the config's)")
    parser.add_argument("--cache", default=None, help="the cycle products' folder (default: a fresh one)")
    parser.add_argument("--alternatives", action="store_true",
                        help="also time the frame's EXR with OpenEXR's other compressions and its PNG's rows "
                             "with other deflaters (isal, libdeflate: where importable)")
    args = parser.parse_args()
    config = load(args.config)
    if args.passes:
        config = replace(config, output=replace(config.output, passes=tuple(args.passes.split(","))))
    plan = with_exposures(plan_run(config), [args.frame])
    root = Path(args.cache or tempfile.mkdtemp(prefix="sunshade-bench-"))
    store = cache.Cache(root)
    cycle_phase(plan, store, jobs=1, workers=1, cycle_frames={args.frame % plan.canopy.cycle})
    result = render_frame(plan, args.frame, store=store, workers=1, passes=config.output.passes or None)
    folder = Path(tempfile.mkdtemp(prefix="sunshade-write-"))
    modules = {"new": io}
    composites = {"new": None}
    if args.baseline:
        modules = {"baseline": baseline_module(args.baseline.resolve(), "core/io"), "new": io}
        composites["baseline"] = baseline_module(args.baseline.resolve(), "camera/composite")
    configs = {name: replace(config, output=replace(config.output, folder=folder / name)) for name in modules}
    for each in configs.values():
        each.output.folder.mkdir()
    print(f"{Path(args.config).stem} frame {args.frame}, {result.radiance.shape[1]} x {result.radiance.shape[0]}, "
          f"layers {sorted(result.layers) or 'none'}; load average {os.getloadavg()}", flush=True)
    for name, module in modules.items():  # warm: imports, numba's cache, the dither
        write_frame(module, configs[name], result, args.frame, composites[name])
    times: dict[str, dict[str, list[float]]] = {name: {p: [] for p in PARTS} for name in modules}
    for _ in range(args.repeat):
        for name, module in modules.items():
            for part, value in write_frame(module, configs[name], result, args.frame, composites[name]).items():
                times[name][part].append(value)
    medians = {name: {p: statistics.median(v) * 1e3 for p, v in parts.items()} for name, parts in times.items()}
    print(f"median CPU per frame [ms] of {args.repeat}:")
    print(f"{'part':>14s}" + "".join(f"{name:>10s}" for name in modules) + ("     ratio" if args.baseline else ""))
    for part in (*PARTS, "total"):
        values = [sum(m.values()) if part == "total" else m[part] for m in medians.values()]
        ratio = f"{values[1] / values[0]:10.2f}" if args.baseline and values[0] else ""
        print(f"{part:>14s}" + "".join(f"{v:10.1f}" for v in values) + ratio)
    files = {name: frame_files(each, args.frame) for name, each in configs.items()}
    for name, (exr, png) in files.items():
        print(f"{name}: EXR {exr.stat().st_size} B, PNG {png.stat().st_size} B")
    if args.baseline:
        same_exr = files["baseline"][0].read_bytes() == files["new"][0].read_bytes()
        same_codes = np.array_equal(io.read_codes(files["baseline"][1]), io.read_codes(files["new"][1]))
        print(f"EXRs byte-identical: {same_exr}; PNGs decode to the same codes: {same_codes}")
    if args.alternatives:
        alternatives(in_working_space(config.output, result.radiance), io.read_codes(files["new"][1]),
                     folder, args.repeat)
    print(f"load average {os.getloadavg()}")
    shutil.rmtree(folder)
    if args.cache is None:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
