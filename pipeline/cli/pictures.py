"""The ``sunshade`` commands that write one picture to -o: ``ground`` (the ground irradiance), ``frame`` (a
finished frame), ``mask`` (a canopy mask) and ``sky`` (the sky, equirectangular). Each command's stages are
imported inside it."""

from __future__ import annotations

import dataclasses
import sys
import time
from typing import TYPE_CHECKING, Any

from pipeline import __version__
from pipeline.cli.flags import check_frame, check_threads, checked_output, config_of, open_store, passes_flag
from pipeline.config.vocabulary import PASSES
from pipeline.core.errors import BadInput

if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable
    from pathlib import Path

    import numpy as np

__all__ = ["run_ground", "run_frame", "run_mask", "run_sky"]

SKY_PASSES = ("sun", "sky")
"""The light passes ``sunshade sky`` writes (the others need a ground and a camera)."""


def run_ground(args: argparse.Namespace) -> int:
    """write the ground irradiance under a canopy mask and a sky

    Write the ground irradiance (RGB float32, linear, radiance x sr) over ground.window at
    ground.pixel metres, north-up, as an EXR.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the config, -o and --png (the files), --frame, --threads, --cache.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    from pipeline.api import ground_irradiance
    from pipeline.camera.composite import display_ground

    exr, png = _exr_and_png(args)
    check_threads(args)
    if args.receiver is not None:
        return _run_wall(args, exr, png)
    config = config_of(args, named_frames=False)
    check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    started = time.perf_counter()
    result = ground_irradiance(config, args.frame, cache=open_store(args.cache), threads=args.threads)
    elapsed = time.perf_counter() - started
    if not result.exact:
        print(
            "sunshade: note: the sky square (sky.alpha) does not span the canopy from every "
            "ground point; light from beyond it is taken as unshadowed",
            file=sys.stderr,
        )
    written = _write(exr, png, result.irradiance, result.metadata,
                     lambda: display_ground(result.irradiance, result.unshadowed))
    rows, cols = result.irradiance.shape[:2]
    print(
        f"sunshade: ground {cols} x {rows} px at {result.pixel:g} m in {elapsed:.2f} s; "
        f"open-sky irradiance {', '.join(f'{v:.4g}' for v in result.unshadowed)} klx (R, G, B); "
        f"wrote {', '.join(str(p) for p in written)}"
    )
    return 0


def _run_wall(args: argparse.Namespace, exr: Path | None, png: Path | None) -> int:
    """``sunshade ground --receiver NAME``: a wall's irradiance raster, upright as one faces it."""
    from pipeline.camera.composite import display_ground
    from pipeline.stages.plan import plan_run
    from pipeline.stages.walls import wall_of_frame

    config = config_of(args, named_frames=False)
    check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    names = [wall.name for wall in config.receivers.walls]
    if args.receiver not in names:
        raise BadInput(f"--receiver: {args.config} has no wall {args.receiver!r} "
                       f"(its walls: {', '.join(names) or 'none'})")
    started = time.perf_counter()
    light = wall_of_frame(plan_run(config), args.frame, args.receiver, store=open_store(args.cache),
                          workers=args.threads)
    elapsed = time.perf_counter() - started
    unshadowed = light.sky_unshadowed + light.sun_unshadowed
    metadata = {"sunshade:window": light.grid.extent, "sunshade:pixel_size": float(light.grid.pixel),
                "sunshade:config_hash": config.digest(), "sunshade:version": __version__,
                "sunshade:frame": int(args.frame), "sunshade:receiver": args.receiver}
    written = _write(exr, png, light.irradiance, metadata, lambda: display_ground(light.irradiance, unshadowed))
    rows, cols = light.irradiance.shape[:2]
    print(f"sunshade: wall {args.receiver} {cols} x {rows} px at {light.grid.pixel:g} m in {elapsed:.2f} s; "
          f"open-wall irradiance {', '.join(f'{v:.4g}' for v in unshadowed)} (sky "
          f"{', '.join(f'{v:.4g}' for v in light.sky_unshadowed)}); wrote {', '.join(str(p) for p in written)}")
    return 0


def run_frame(args: argparse.Namespace) -> int:
    """render one finished frame: ground and sky in the camera, trees in front

    Render one finished frame (Max 1991, Fig. 10): the ground raster and the sky resampled
    in the camera, the haze, the foreground passes blended by the sun fraction S. A .png is
    exposed and display-transformed (camera.exposure, camera.display or output.view); an .exr
    is scene-linear radiance (in output.colorspace) with its metadata.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the config, -o, --half, --passes, --frame, --threads and --cache.

    Returns
    -------
    int
        The exit code: 0 done (the frame written).
    """
    from pipeline.api import render_frame

    output = checked_output(args.output)
    suffix = output.suffix.lower()
    check_threads(args)
    if args.half and suffix != ".exr":
        raise BadInput("--half is for EXR output")
    passes = passes_flag(args.passes, PASSES)
    if passes and suffix != ".exr":
        raise BadInput("--passes is for EXR output")
    config = config_of(args, named_frames=False)
    if passes and config.ground.brdf is not None:
        raise BadInput(f"--passes: the light passes are not made with a ground.brdf yet ({args.config})")
    passes = config.output.passes if passes is None else passes
    check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    started = time.perf_counter()
    frame = render_frame(config, args.frame, passes=passes if suffix == ".exr" else (), cache=open_store(args.cache),
                         threads=args.threads)
    elapsed = time.perf_counter() - started
    if suffix == ".exr":
        frame.write_exr(output, half=args.half)
    else:
        frame.write_png(output)
    rows, cols = frame.beauty.shape[:2]
    print(f"sunshade: frame {args.frame}, {cols} x {rows} px, S = {frame.sun_fraction:.4f}, "
          f"in {elapsed:.2f} s; wrote {output}")
    return 0


def run_mask(args: argparse.Namespace) -> int:
    """write the canopy mask of a cycle frame (Max 1991, Fig. 4)

    Write the transmittance mask (1 = open sky) of one canopy layer at one cycle frame, the
    leaves projected along the sun onto the canopy plane, north-up: the coarse mask of the
    whole canopy, or with --fine the fine mask under the sun window.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the config, -o, --frame, --layer and --fine.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    from pipeline.core import io
    from pipeline.stages.cycle import layer_masks
    from pipeline.stages.plan import plan_run

    output = checked_output(args.output)
    suffix = output.suffix.lower()
    config = config_of(args, named_frames=False)
    check_frame(args.frame, config.canopy.cycle, "--frame", "the canopy's cycle")
    check_frame(args.layer, len(config.canopy.layers), "--layer", "the number of canopy layers")
    plan = plan_run(config)
    layer = plan.layers[args.layer]
    if args.fine and layer.sun is None:
        raise BadInput(f"{args.config}: --fine needs a sky with a sun (sky.model: cie, preetham or hdri)")
    started = time.perf_counter()
    masks = layer_masks(plan, args.layer, args.frame)
    coarse, fine = masks.coarse, masks.fine
    mask, grid = coarse, layer.canopy
    if args.fine and layer.sun is not None and fine is not None:  # a sun makes its fine mask (checked above)
        mask, grid = fine, layer.sun.mask
    elapsed = time.perf_counter() - started
    if suffix == ".exr":
        io.write_exr(output, mask[..., None], {"sunshade:window": grid.extent,
                                               "sunshade:pixel_size": float(grid.pixel)})
    else:
        io.write_png(output, mask[..., None])
    rows, cols = mask.shape
    x0, y0, x1, y1 = grid.extent
    print(f"sunshade: mask {cols} x {rows} px at {grid.pixel:g} m over x {x0:.2f}..{x1:.2f}, "
          f"y {y0:.2f}..{y1:.2f} m; mean transmittance {mask.mean():.3f}; {elapsed:.2f} s; "
          f"wrote {output}")
    return 0


def run_sky(args: argparse.Namespace) -> int:
    """write the sky of a frame as an equirectangular EXR

    Write the sky (sun, moon, clouds) of a frame as linear RGB radiance, equirectangular:
    top row at the zenith, centre column north, east at three quarters of the width; the
    lower half is below the horizon.

    Parameters
    ----------
    args : argparse.Namespace
        The command line, parsed: the config, -o, --png, --width, --passes and --frame.

    Returns
    -------
    int
        The exit code: 0 done.
    """
    import numpy as np

    from pipeline.camera.composite import display_sky
    from pipeline.stages.scene import load_sky, scene_at

    exr, png = _exr_and_png(args)
    if not 8 <= args.width <= 16384 or args.width % 2:
        raise BadInput(f"--width must be an even number from 8 to 16384 (got {args.width})")
    passes = passes_flag(args.passes, SKY_PASSES)
    config = config_of(args, named_frames=False)
    if passes is None:
        passes = tuple(p for p in config.output.passes if p in SKY_PASSES)
    check_frame(args.frame, config.animation.frames, "--frame", "animation.frames")
    scene = scene_at(config, args.frame)
    sky = load_sky(config.sky, scene)
    if not hasattr(sky, "equirect"):
        raise BadInput(f"{args.config}: sunshade sky writes the cie and preetham skies (sky.model is "
                       f"{config.sky.model}; an hdri sky is its image)")
    parts: dict[str, np.ndarray] = {}
    if passes:
        image, parts = sky.equirect(args.width, parts=True)
    else:
        image = sky.equirect(args.width)
    from pipeline.run.contents import colour_attributes, in_working_space

    attributes = {"sunshade:config_hash": config.digest(), "sunshade:frame": int(args.frame),
                  "sunshade:version": __version__, **colour_attributes(config.output)}
    if scene.sun is not None:
        attributes["sunshade:sun_azimuth_elevation"] = (np.degrees(scene.sun.azimuth),
                                                        np.degrees(scene.sun.elevation))
    layers = None
    if passes:  # as a frame's: the standard attributes and the layers (docs/runs.md)
        from pipeline.run.contents import LAYER_CHANNELS, standard_attributes
        from pipeline.stages.lighting import open_ground_light

        light = open_ground_light(sky, 1.0, None)
        attributes.update(standard_attributes(
            dataclasses.replace(config, output=dataclasses.replace(config.output, passes=passes)), scene, light))
        attributes.pop("sunshade:camera_ev100", None)  # no camera here
        layers = {LAYER_CHANNELS[name]: (in_working_space(config.output, parts[name]), "float") for name in passes}
    written = _write(exr, png, in_working_space(config.output, image), attributes, lambda: display_sky(image),
                     layers=layers)
    print(f"sunshade: sky {args.width} x {args.width // 2} px; wrote {', '.join(map(str, written))}")
    return 0


def _exr_and_png(args: argparse.Namespace) -> tuple[Path | None, Path | None]:
    """The files of -o and --png (ground, sky): (the EXR or None, the PNG or None); a PNG beside an EXR with
    --png, of the EXR's name. Raises BadInput as ``checked_output``."""
    output = checked_output(args.output)
    exr = output if output.suffix.lower() == ".exr" else None
    png = output if exr is None else (checked_output(str(output.with_suffix(".png"))) if args.png else None)
    return exr, png


def _write(exr: Path | None, png: Path | None, image: np.ndarray, attributes: dict[str, Any],
           shown: Callable[[], np.ndarray],
           layers: dict[tuple[str, ...], tuple[np.ndarray, str]] | None = None) -> list[Path]:
    """Write ``image`` with its attributes (and layers) to ``exr`` and ``shown()``, the display picture, to
    ``png``, where each is not None; the files written, in that order."""
    from pipeline.core import io

    written = []
    if exr is not None:
        io.write_exr(exr, image, attributes, layers=layers)
        written.append(exr)
    if png is not None:
        io.write_png(png, shown())
        written.append(png)
    return written
