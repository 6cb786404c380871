"""Images read through OpenImageIO and written atomically with their metadata (EXRs through OpenEXR's
bindings, PNGs here, deflated by zlib-ng); video through imageio.

Every file is written under a temporary name in its final folder and renamed into place, so a
crash never leaves a half-written file under the real name.
"""

from __future__ import annotations

import contextlib
import functools
import os
import struct
import sys
import zlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from pipeline.core import paths
from pipeline.core.errors import ImageError

__all__ = ["MAX_IMAGE_VALUES", "PNG_FILTER_SUB", "PNG_ZLIB_LEVEL", "PNG_ZLIB_STRATEGY", "VIDEO_FORMATS", "read_image",
           "read_finite_image", "read_codes", "read_layers", "read_attributes", "write_exr", "write_png", "half_dither",
           "write_video"]

MAX_IMAGE_VALUES = 2**29
"""Most values (width x height x channels) an image read may hold: its header is read first, and
a larger image (a decompression bomb, a mistaken file) is refused before any pixel is decoded.
A 16384 x 8192 RGB HDRI holds 4.0e8. [1]"""


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Pixels of an image file as float32, values as stored.

    Integer formats are scaled to [0, 1] (8- and 16-bit PNG); no colour conversion is done and
    colour is not multiplied by alpha, so a mask is read as the linear numbers it holds. An image of
    more than MAX_IMAGE_VALUES values is refused before any pixel is decoded.

    Parameters
    ----------
    path : str or os.PathLike
        The image file.

    Returns
    -------
    numpy.ndarray
        (rows, cols, channels) float32, in the file's units (radiance [kcd/m^2] for a sky, [1] for
        a mask or an 8-bit picture).

    Raises
    ------
    ImageError
        Naming the file.
    """
    return _read(path, "float").astype(np.float32, copy=False)


def read_finite_image(path: str | os.PathLike[str], what: str) -> np.ndarray:
    """``read_image`` of an input a config names (a mask, an albedo, a sky, a pass), refusing a NaN
    or infinite value with the first such texel named, before anything is made from it.

    Parameters
    ----------
    path : str or os.PathLike
        The image file.
    what : str
        What the image is, for the message ("mask", "albedo", ...).

    Returns
    -------
    numpy.ndarray
        (rows, cols, channels) float32, as ``read_image``.

    Raises
    ------
    ImageError
        Naming the file and, for a value that is not finite, the first one: its row, column
        and channel (row-major order).
    """
    image = read_image(path)
    bad = ~np.isfinite(image)
    if bad.any():
        row, col, channel = (int(v) for v in np.argwhere(bad)[0])
        raise ImageError(path, f"the {what} holds {image[row, col, channel]} at row {row}, column {col}, "
                               f"channel {channel}; every value must be finite")
    return image


def read_codes(path: str | os.PathLike[str]) -> np.ndarray:
    """The 8-bit codes of an 8-bit image file (a frame's PNG), without a float round trip.

    Parameters
    ----------
    path : str or os.PathLike
        The 8-bit image file.

    Returns
    -------
    numpy.ndarray
        (rows, cols, channels) uint8 codes.

    Raises
    ------
    ImageError
        Naming the file, as ``read_image``.
    """
    return _read(path, "uint8")


def _read(path, kind: str) -> np.ndarray:
    """Pixels as stored, in OpenImageIO's ``kind`` (``float``, ``uint8``), (rows, cols, channels)."""
    path = Path(path)
    if (why := paths.not_a_file(path)) is not None:
        raise ImageError(path, why)
    as_stored = oiio.ImageSpec()
    as_stored.attribute("oiio:UnassociatedAlpha", 1)
    with _quiet_stderr():
        inp = oiio.ImageInput.open(str(path), as_stored)
        if inp is None:
            raise ImageError(path, f"cannot read image ({oiio.geterror().strip() or 'unknown format'})")
        try:
            spec = inp.spec()
            values = spec.width * spec.height * spec.nchannels
            if spec.width < 1 or spec.height < 1 or values > MAX_IMAGE_VALUES:
                raise ImageError(path, f"is {spec.width} x {spec.height} pixels of {spec.nchannels} channel"
                                 f"{'' if spec.nchannels == 1 else 's'} ({values:.3g} values); "
                                 f"the most is {MAX_IMAGE_VALUES:.3g} "
                                 f"({MAX_IMAGE_VALUES * 4 / 2**30:g} GiB as floats)")
            pixels = inp.read_image(0, 0, 0, spec.nchannels, kind)
            error = inp.geterror()
        finally:
            inp.close()
    if pixels is None or error:
        raise ImageError(path, f"cannot read image ({error.strip() or 'truncated or corrupt'})")
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    return pixels


def read_layers(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """The channels of an image file by name (``"R"``, ``"sun.R"``, ``"illuminance.Y"``).

    Parameters
    ----------
    path : str or os.PathLike
        The image file, of any format ``read_image`` reads.

    Returns
    -------
    dict of str to numpy.ndarray
        {channel name: (rows, cols) float32 as stored}.

    Raises
    ------
    ImageError
        Naming the file (from ``read_image``).
    """
    pixels = read_image(path)
    with _quiet_stderr():
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ImageError(path, f"cannot read image ({oiio.geterror().strip()})")
    try:
        names = inp.spec().channelnames
    finally:
        inp.close()
    return {name: pixels[..., i] for i, name in enumerate(names)}


def read_attributes(path: str | os.PathLike[str], names: Iterable[str]) -> dict[str, Any]:
    """The named metadata attributes of an image file.

    Parameters
    ----------
    path : str or os.PathLike
        The image file.
    names : iterable of str
        The attributes' names.

    Returns
    -------
    dict
        {name: value}; missing ones are None.

    Raises
    ------
    ImageError
        Naming the file, when it cannot be opened.
    """
    with _quiet_stderr():
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ImageError(path, f"cannot read image ({oiio.geterror().strip()})")
    try:
        spec = inp.spec()
        return {name: spec.getattribute(name) for name in names}
    finally:
        inp.close()


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence file descriptor 2 for the block: libpng prints its own error lines there, and
    the error reaches the user once, as an ImageError naming the file."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)
        os.close(null)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def write_exr(path: str | os.PathLike[str], pixels: np.ndarray, attributes: dict[str, Any] | None = None, *,
              half: bool = False, layers: dict[tuple[str, ...], tuple[np.ndarray, str]] | None = None) -> None:
    """Write scene-linear pixels as an EXR (float32 or half), PIZ-compressed (lossless), atomically.

    Written through the OpenEXR bindings: a 1280 x 720 half RGB frame in 33 ms of CPU, where
    OpenImageIO took 53 ms for the same header and the same compressed pixels (docs/runs.md,
    "Writing"). No time stamp is written unless ``attributes`` gives ``DateTime`` (OpenEXR's
    capDate), so the same pixels and attributes always give the same bytes.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    pixels : numpy.ndarray
        (rows, cols, channels) scene-linear values, channels R, G, B (A), or Y alone [kcd/m^2].
    attributes : dict, optional
        {name: str, int, float, or a tuple of floats} for its header: two or three floats are
        a V2f or V3f, eight named ``chromaticities`` OpenEXR's chromaticities, other counts a
        float vector; ``DateTime`` ("YYYY:MM:DD HH:MM:SS") is written as capDate.
    half : bool, optional
        Write the pixels as half floats.
    layers : dict, optional
        {channel names: (pixels (rows, cols, len(names)), "half" or "float")} written beside
        ``pixels``, named in the multi-layer convention (``("sun.R", "sun.G", "sun.B")``,
        ``("illuminance.Y",)``), each in its own format: a channel whose values pass half's 65504
        (lux) is kept in float. None: the file is as without this argument, byte for byte.

    Raises
    ------
    ImageError
        Naming the file, when it cannot be written.
    """
    import OpenEXR  # 6 ms to import: only where an EXR is written

    pixels = np.asarray(pixels, dtype=np.float32)
    rows, cols, channels = pixels.shape
    names = ("Y",) if channels == 1 and not layers else tuple("RGBA"[:channels])
    planes = [(names, pixels, half)]
    for layer_names, (layer, kind) in (layers or {}).items():
        planes.append((layer_names, np.asarray(layer, dtype=np.float32).reshape(rows, cols, -1), kind == "half"))
    stored: dict[str, np.ndarray] = {}
    with np.errstate(over="ignore"):  # beyond 65504 a half is inf, as OpenEXR's own conversion
        for plane_names, plane, in_half in planes:
            # channel by channel, converted in one pass: (channels, rows, cols), C order
            planar = plane.transpose(2, 0, 1).astype(np.float16 if in_half else np.float32, order="C")
            stored.update(zip(plane_names, planar))
    header = {"compression": OpenEXR.PIZ_COMPRESSION}
    for name, value in (attributes or {}).items():
        if name == "DateTime":
            if value:
                header["capDate"] = str(value)
        elif isinstance(value, (tuple, list)):
            values = tuple(float(v) for v in value)
            header[name] = values if len(values) in (2, 3) or name == "chromaticities" else list(values)
        elif isinstance(value, (int, np.integer)):
            header[name] = int(value)
        elif isinstance(value, (float, np.floating)):
            header[name] = float(value)
        else:
            header[name] = str(value)
    path = Path(path)
    temporary = _temporary(path)
    try:
        with OpenEXR.File(header, stored) as exr:
            exr.write(str(temporary))
        os.replace(temporary, path)
    except (OSError, RuntimeError) as exc:
        raise ImageError(path, f"cannot write ({getattr(exc, 'strerror', None) or exc})") from None
    finally:
        if temporary.exists():
            temporary.unlink()


def write_png(path: str | os.PathLike[str], pixels: np.ndarray, attributes: dict[str, Any] | None = None) -> np.ndarray:
    """Write display-referred pixels as an 8-bit PNG, atomically.

    A fixed-seed dither of one code value breaks the banding of smooth gradients
    (``half_dither``); the same pixels always give the same bytes. Codes given as uint8 (a
    frame's, made in one compiled pass by ``composite.display_codes``) are written as they are.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    pixels : numpy.ndarray
        (rows, cols, channels) display values in [0, 1] [1], or uint8 codes.
    attributes : dict, optional
        {name: str or int}, written as text chunks.

    Returns
    -------
    numpy.ndarray
        (rows, cols, channels) uint8: the codes written, what ``read_codes`` reads back.

    Raises
    ------
    ImageError
        Naming the file, when it cannot be written.
    """
    if np.asarray(pixels).dtype == np.uint8:
        data = np.ascontiguousarray(pixels)
    else:
        pixels = np.asarray(pixels, dtype=np.float32)
        codes = np.clip(pixels, 0.0, 1.0)  # floor(p 255 + 0.5 + noise / 2), in place, in that order
        codes *= 255.0
        codes += 0.5
        codes += half_dither(pixels.shape)
        np.floor(codes, out=codes)
        np.clip(codes, 0, 255, out=codes)
        data = np.ascontiguousarray(codes.astype(np.uint8))  # a transposed view keeps its strides
    path = Path(path)
    temporary = _temporary(path)
    try:
        temporary.write_bytes(_png_bytes(data, attributes or {}))
        os.replace(temporary, path)
    except OSError as exc:
        raise ImageError(path, f"cannot write ({exc.strerror or exc})") from None
    finally:
        if temporary.exists():
            temporary.unlink()
    return data


PNG_FILTER_SUB = 1
"""The PNG filter type "Sub" (ISO/IEC 15948, 9.2): each byte less the one a pixel to its left."""

PNG_ZLIB_LEVEL = 2
"""The zlib level of a PNG's pixels (zlib-ng); lossless whatever the level."""

PNG_ZLIB_STRATEGY = zlib.Z_HUFFMAN_ONLY
"""Deflate's strategy for a PNG's pixels: Huffman codes alone, no search for repeated strings. A
frame's dithered codes, filtered by "Sub", repeat little: the 13 shipped configs' 1280 x 720 frames
took 11 to 22 ms each with it against 20 to 38 ms with the search (``Z_FILTERED``), in files 3.5%
larger in all (-5.5% to +7.5% each; grove-point-sun's +20%, 0.87 to 1.05 MB; docs/runs.md,
"Writing")."""

_PNG_COLOUR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}  # channels: grey, grey and alpha, RGB, RGBA


def _png_bytes(codes: np.ndarray, attributes: dict) -> bytes:
    """A PNG file of (rows, cols, channels) uint8 codes, C-contiguous: the rows filtered by "Sub"
    and deflated by zlib-ng in one IDAT chunk, an sRGB chunk and a tEXt chunk per attribute."""
    from zlib_ng import zlib_ng  # 5 ms to import: only where a PNG is written

    rows, cols, channels = codes.shape
    line = codes.reshape(rows, cols * channels)
    filtered = np.empty((rows, cols * channels + 1), dtype=np.uint8)
    filtered[:, 0] = PNG_FILTER_SUB
    filtered[:, 1:1 + channels] = line[:, :channels]
    np.subtract(line[:, channels:], line[:, :-channels], out=filtered[:, 1 + channels:])  # modulo 256
    deflate = zlib_ng.compressobj(PNG_ZLIB_LEVEL, zlib.DEFLATED, 15, 8, PNG_ZLIB_STRATEGY)
    pixels = deflate.compress(filtered) + deflate.flush()
    header = struct.pack(">IIBBBBB", cols, rows, 8, _PNG_COLOUR_TYPES[channels], 0, 0, 0)
    text = [_png_chunk(b"tEXt", f"{name}\0{value}".encode("latin-1", "replace"))
            for name, value in attributes.items()]
    return b"".join([b"\x89PNG\r\n\x1a\n", _png_chunk(b"IHDR", header), _png_chunk(b"sRGB", b"\0"), *text,
                     _png_chunk(b"IDAT", pixels), _png_chunk(b"IEND", b"")])


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    """A PNG chunk: length, kind, data, the CRC-32 of kind and data (zlib-ng's: the same number, a
    frame's pixels in 0.02 ms where the standard library's zlib took 0.29)."""
    from zlib_ng import zlib_ng

    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib_ng.crc32(data, zlib_ng.crc32(kind)))


@functools.lru_cache(maxsize=4)
def half_dither(shape: tuple[int, ...]) -> np.ndarray:
    """Half the fixed-seed dither of ``write_png``: the difference of two uniform fields of
    seeds 0 and 1, halved; made once per frame size (read-only).

    Parameters
    ----------
    shape : tuple of int
        (rows, cols, channels) of the pixels.

    Returns
    -------
    numpy.ndarray
        (shape) float32 in (-0.5, 0.5), read-only [code values].
    """
    noise = np.random.default_rng(0).random(shape, dtype=np.float32)
    noise -= np.random.default_rng(1).random(shape, dtype=np.float32)
    noise *= 0.5
    noise.flags.writeable = False
    return noise


VIDEO_FORMATS = (".mp4", ".gif")
"""The video files ``write_video`` writes, by suffix."""


def write_video(path: str | os.PathLike[str], frames: Iterable[np.ndarray], *, fps: float,
                colour: str | None = None) -> int:
    """Write display-referred frames as a video, atomically.

    ``.mp4``: H.264 in yuv420p, which browsers play; frames of odd width or height are padded
    by repeating their last column or row (yuv420p needs even sizes). One encoder thread and
    no time stamps in the header, so the same frames give the same bytes. x264's "veryfast"
    preset: at CRF 18 it encoded the eclipse frames in 22 ms each instead of 58 ("medium"), in
    files of the same size, 0.3 dB PSNR lower (39.1 dB).
    ``.gif``: through Pillow, an adaptive palette per frame, looping.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its suffix (one of VIDEO_FORMATS) picks the format.
    frames : iterable of numpy.ndarray
        Each (rows, cols, 3), floats in [0, 1] or uint8 codes; read once, in order.
    fps : float
        Frames per second [1/s].
    colour : str or None
        ``.mp4``: the ffmpeg name of the colour primaries, transfer and matrix the video is tagged
        with (in the H.264 stream and the MP4's colr box) and converted to YUV by ('bt709'); None:
        untagged, BT.601's matrix (docs/runs.md, "Colour").

    Returns
    -------
    int
        The number of frames written.

    Raises
    ------
    ImageError
        Naming the file: an unknown format, or no frames.
    """
    path = Path(path)
    if path.suffix.lower() not in VIDEO_FORMATS:
        raise ImageError(path, f"unknown video format; valid: {', '.join(VIDEO_FORMATS)}")
    temporary = _temporary(path)
    count = 0
    try:
        if path.suffix.lower() == ".gif":
            from PIL import Image

            images = [Image.fromarray(_codes(f)) for f in frames]
            if not images:
                raise ImageError(path, "no frames to write")
            images[0].save(temporary, save_all=True, append_images=images[1:], loop=0,
                           duration=int(round(1000.0 / fps)), optimize=False)
            count = len(images)
        else:
            import imageio.v2 as imageio

            writer = imageio.get_writer(
                temporary, format="FFMPEG", fps=fps, codec="libx264", pixelformat="yuv420p",
                macro_block_size=1, quality=None, output_params=[
                    "-crf", "18", "-preset", "veryfast", "-threads", "1", "-movflags", "+faststart",
                    "-map_metadata", "-1", "-fflags", "+bitexact", "-flags:v", "+bitexact",
                    *(["-vf", f"setparams=color_primaries={colour}:color_trc={colour}:colorspace={colour}"]
                      if colour else [])])
            try:
                for frame in frames:
                    codes = _codes(frame)
                    pad = ((0, codes.shape[0] % 2), (0, codes.shape[1] % 2), (0, 0))
                    writer.append_data(np.pad(codes, pad, mode="edge"))
                    count += 1
            finally:
                writer.close()
            if not count:
                raise ImageError(path, "no frames to write")
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()
    return count


def _codes(frame) -> np.ndarray:
    """8-bit RGB codes of a frame given as uint8 or as floats in [0, 1]."""
    frame = np.asarray(frame)
    if frame.dtype != np.uint8:
        frame = np.clip(np.floor(frame.astype(np.float32) * 255.0 + 0.5), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(frame[..., :3])


def _temporary(path: Path) -> Path:
    """A temporary name beside ``path`` with its suffix (writers pick the format by suffix)."""
    return path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
