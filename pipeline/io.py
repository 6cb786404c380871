"""Images through OpenImageIO, written atomically with their metadata.

Every file is written under a temporary name in its final folder and renamed into place, so a
crash never leaves a half-written file under the real name.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio


class ImageError(ValueError):
    """An image that cannot be read or written; ``path`` names the file."""

    def __init__(self, path, message: str):
        super().__init__(f"{path}: {message}")
        self.path = Path(path)


def read_image(path) -> np.ndarray:
    """Pixels of an image file as float32 (rows, cols, channels), values as stored.

    Integer formats are scaled to [0, 1] (8- and 16-bit PNG); no colour conversion is done and
    colour is not multiplied by alpha, so a mask is read as the linear numbers it holds.
    Raises ImageError naming the file.
    """
    path = Path(path)
    if not path.is_file():
        raise ImageError(path, "no such file")
    as_stored = oiio.ImageSpec()
    as_stored.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), as_stored)
    if inp is None:
        raise ImageError(path, f"cannot read image ({oiio.geterror().strip() or 'unknown format'})")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        error = inp.geterror()
    finally:
        inp.close()
    if pixels is None or error:
        raise ImageError(path, f"cannot read image ({error.strip() or 'truncated or corrupt'})")
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    return pixels


def read_attributes(path, names) -> dict:
    """The named metadata attributes of an image file (missing ones are None)."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ImageError(path, f"cannot read image ({oiio.geterror().strip()})")
    try:
        spec = inp.spec()
        return {name: spec.getattribute(name) for name in names}
    finally:
        inp.close()


def write_exr(path, pixels: np.ndarray, attributes: dict | None = None, *, half=False) -> None:
    """Write (rows, cols, channels) scene-linear pixels as an EXR (float32 or half), ZIP-compressed,
    with ``attributes`` (str, int, float, or a tuple of floats) in its header."""
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    rows, cols, channels = pixels.shape
    spec = oiio.ImageSpec(cols, rows, channels, "half" if half else "float")
    spec.attribute("compression", "zip")
    for name, value in (attributes or {}).items():
        if isinstance(value, (tuple, list)):
            spec.attribute(name, oiio.TypeDesc(f"float[{len(value)}]"), tuple(float(v) for v in value))
        else:
            spec.attribute(name, value)
    _write_atomic(path, spec, pixels)


def write_png(path, pixels: np.ndarray) -> None:
    """Write display-referred pixels in [0, 1] (rows, cols, channels) as an 8-bit PNG.

    A fixed-seed dither of one code value breaks the banding of smooth gradients; the same
    pixels always give the same bytes.
    """
    pixels = np.asarray(pixels, dtype=np.float32)
    noise = np.random.default_rng(0).random(pixels.shape, dtype=np.float32)
    noise -= np.random.default_rng(1).random(pixels.shape, dtype=np.float32)
    codes = np.floor(np.clip(pixels, 0.0, 1.0) * 255.0 + 0.5 + 0.5 * noise)
    data = np.ascontiguousarray(np.clip(codes, 0, 255).astype(np.uint8))
    rows, cols, channels = data.shape
    spec = oiio.ImageSpec(cols, rows, channels, "uint8")
    _write_atomic(path, spec, data)


def _write_atomic(path, spec, data) -> None:
    path = Path(path)
    temporary = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise ImageError(path, f"cannot write this format ({oiio.geterror().strip()})")
    try:
        if not out.open(str(temporary), spec):
            raise ImageError(path, f"cannot write ({out.geterror().strip()})")
        ok = out.write_image(data)
        ok = out.close() and ok
        if not ok:
            raise ImageError(path, f"cannot write ({out.geterror().strip()})")
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()
