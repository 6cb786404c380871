"""The ``sunshade`` command: the only module that prints.

Exit codes: 0 done, 2 bad input (one line naming the key or file; nothing written),
1 an unexpected failure.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__, io
from .composite import display_ground
from .config import ConfigError, load_config

EXIT_BAD_INPUT = 2


class BadInput(Exception):
    """Bad input found by the command itself (an output path, say)."""


def main(argv=None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (ConfigError, io.ImageError, BadInput) as exc:
        print(f"sunshade: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        print("sunshade: error: not enough memory for this config; raise ground.pixel, or lower "
              "sky.alpha or the canopy size", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("sunshade: interrupted", file=sys.stderr)
        return 130


def _parser():
    parser = argparse.ArgumentParser(
        prog="sunshade",
        description="Sunlight and skylight through leaves (Max 1991, 'Unified sun and sky "
        "illumination for shadows under trees').",
    )
    parser.add_argument("--version", action="version", version=f"sunshade {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    ground = commands.add_parser(
        "ground",
        help="write the ground irradiance under a canopy mask and a sky",
        description="Write the ground irradiance (RGB float32, linear, radiance x sr) over "
        "ground.window at ground.pixel metres, north-up, as an EXR.",
    )
    ground.add_argument("config", help="YAML config file")
    ground.add_argument("-o", "--output", required=True, help="output EXR file")
    ground.add_argument("--png", action="store_true", help="also write a tone-mapped PNG beside it")
    ground.add_argument("--threads", type=int, default=None, help="FFT threads (default: all cores)")
    ground.set_defaults(run=_run_ground)

    cache = commands.add_parser(
        "cache",
        help="look after the on-disk cache of cycle products",
        description="The cache folder is --cache, else $SUNSHADE_CACHE, else ./cache.",
    )
    cache.add_argument("action", choices=("list", "verify", "clear", "prune"))
    cache.add_argument("--cache", default=None, help="cache folder")
    cache.add_argument("--max-size", default=None, help="prune: the most to keep, e.g. 2G (binary units)")
    cache.add_argument("--remove", action="store_true", help="verify: also remove broken items")
    cache.set_defaults(run=_run_cache)
    return parser


def _checked_output(path: str, suffix: str) -> Path:
    out = Path(path)
    if out.suffix.lower() != suffix:
        raise BadInput(f"{out}: the output must be a {suffix} file")
    if out.is_dir():
        raise BadInput(f"{out}: is a folder, not a file")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise BadInput(f"{out}: no such folder: {folder}")
    if not os.access(folder, os.W_OK):
        raise BadInput(f"{out}: cannot write to folder {folder}")
    return out


def _run_ground(args) -> int:
    from .render import render_ground

    output = _checked_output(args.output, ".exr")
    png = _checked_output(str(output.with_suffix(".png")), ".png") if args.png else None
    if args.threads is not None and args.threads < 1:
        raise BadInput(f"--threads must be at least 1 (got {args.threads})")
    config = load_config(args.config)
    digest = config.digest()
    started = time.perf_counter()
    result = render_ground(config, workers=args.threads)
    elapsed = time.perf_counter() - started
    if not np.all(np.isfinite(result.irradiance)):
        raise BadInput(f"{args.config}: the ground irradiance overflowed; lower the sky's radiance")
    if not result.exact:
        print(
            "sunshade: note: the sky square (sky.alpha) does not span the canopy from every "
            "ground point; light from beyond it is taken as unshadowed",
            file=sys.stderr,
        )
    attributes = {
        "sunshade:window": result.grid.extent,
        "sunshade:pixel_size": float(result.grid.pixel),
        "sunshade:config_hash": digest,
        "sunshade:version": __version__,
    }
    io.write_exr(output, result.irradiance, attributes)
    written = [output]
    if png is not None:
        io.write_png(png, display_ground(result.irradiance, result.unshadowed))
        written.append(png)
    rows, cols = result.grid.shape
    print(
        f"sunshade: ground {cols} x {rows} px at {result.grid.pixel:g} m in {elapsed:.2f} s; "
        f"open-sky irradiance {', '.join(f'{v:.4g}' for v in result.unshadowed)}; "
        f"wrote {', '.join(str(p) for p in written)}"
    )
    return 0


def _run_cache(args) -> int:
    from .cache import Cache, cache_dir, parse_size

    store = Cache(cache_dir(args.cache))
    if args.action == "prune":
        if args.max_size is None:
            raise BadInput("cache prune needs --max-size, e.g. --max-size 2G")
        try:
            limit = parse_size(args.max_size)
        except ValueError as exc:
            raise BadInput(f"--max-size: {exc}") from None
    elif args.max_size is not None:
        raise BadInput("--max-size is only for cache prune")
    if args.action == "list":
        items = store.list()
        for item in items:
            print(f"{item.kind:<12} {item.key[:16]}  {_size(item.bytes):>9}  "
                  f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(item.last_used))}")
        print(f"{len(items)} items, {_size(sum(i.bytes for i in items))} in {store.root}")
        return 0
    if args.action == "verify":
        count = len(store.list())
        broken = store.verify(remove=args.remove)
        for item, problem in broken:
            print(f"{item.kind} {item.key[:16]}: {problem}" + (" (removed)" if args.remove else ""))
        print(f"{len(broken)} broken of {count} items")
        return 1 if broken and not args.remove else 0
    removed = store.clear() if args.action == "clear" else store.prune(limit)
    print(f"removed {len(removed)} items, {_size(sum(i.bytes for i in removed))}")
    return 0


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024


if __name__ == "__main__":
    sys.exit(main())
