"""Images and video written to real files and read back."""

import imageio.v2 as imageio
import numpy as np
import pytest

from pipeline.core import io


@pytest.mark.parametrize("half", [False, True])
def test_exr_metadata_round_trip(tmp_path, half):
    pixels = np.random.default_rng(0).random((5, 7, 3), dtype=np.float32) * 100
    attributes = {"sunshade:config_hash": "0123abcd", "sunshade:frame": 17,
                  "sunshade:sun_fraction": 0.4845, "sunshade:sun_azimuth_elevation": (180.0, 60.0)}
    path = tmp_path / "f.exr"
    io.write_exr(path, pixels, attributes, half=half)
    back = io.read_attributes(path, list(attributes))
    assert back["sunshade:config_hash"] == "0123abcd"
    assert back["sunshade:frame"] == 17
    assert back["sunshade:sun_fraction"] == pytest.approx(0.4845)
    assert tuple(back["sunshade:sun_azimuth_elevation"]) == pytest.approx((180.0, 60.0))
    np.testing.assert_allclose(io.read_image(path), pixels, rtol=1e-3 if half else 0)
    assert [p.name for p in tmp_path.iterdir()] == ["f.exr"]


def _frames(n, shape):
    return [np.full((*shape, 3), (i + 1) / (n + 1), dtype=np.float32) for i in range(n)]


def test_mp4_decodes_back_to_its_frames(tmp_path):
    path = tmp_path / "v.mp4"
    assert io.write_video(path, _frames(4, (48, 64)), fps=24) == 4
    frames = imageio.mimread(path)
    assert len(frames) == 4 and frames[0].shape == (48, 64, 3)
    means = [f.mean() / 255 for f in frames]
    np.testing.assert_allclose(means, [0.2, 0.4, 0.6, 0.8], atol=0.02)
    meta = imageio.get_reader(path).get_meta_data()
    assert meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]


def test_mp4_is_deterministic_and_pads_odd_sizes(tmp_path):
    a, b = tmp_path / "a.mp4", tmp_path / "b.mp4"
    io.write_video(a, _frames(3, (45, 63)), fps=24)
    io.write_video(b, _frames(3, (45, 63)), fps=24)
    assert a.read_bytes() == b.read_bytes()
    assert imageio.mimread(a)[0].shape == (46, 64, 3)


def test_gif_round_trip(tmp_path):
    path = tmp_path / "v.gif"
    io.write_video(path, _frames(4, (20, 30)), fps=10)
    frames = imageio.mimread(path)
    assert len(frames) == 4 and frames[0].shape[:2] == (20, 30)


def test_bad_video_format_or_no_frames_writes_nothing(tmp_path):
    with pytest.raises(io.ImageError, match=r"valid: \.mp4, \.gif"):
        io.write_video(tmp_path / "v.avi", _frames(2, (8, 8)), fps=24)
    with pytest.raises(io.ImageError, match="no frames"):
        io.write_video(tmp_path / "v.mp4", [], fps=24)
    assert list(tmp_path.iterdir()) == []


def test_png_holds_the_dithered_codes_and_is_deterministic(tmp_path):
    """write_png (cached dither, in-place arithmetic, Huffman codes of "sub"-filtered rows)
    decodes to exactly the codes of the dither written out in full as it was first made:
    floor(clip(p, 0, 1) 255 + 0.5 + (u0 - u1) / 2), u0 and u1 uniform of seeds 0 and 1."""
    rng = np.random.default_rng(4)
    pixels = rng.uniform(-0.2, 1.2, (37, 53, 3)).astype(np.float32)
    pixels[:5] = np.linspace(0.0, 1.0, 53, dtype=np.float32)[None, :, None]  # a smooth ramp
    noise = np.random.default_rng(0).random(pixels.shape, dtype=np.float32)
    noise -= np.random.default_rng(1).random(pixels.shape, dtype=np.float32)
    want = np.clip(np.floor(np.clip(pixels, 0.0, 1.0) * 255.0 + 0.5 + 0.5 * noise), 0, 255).astype(np.uint8)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    io.write_png(a, pixels)
    io.write_png(b, pixels.copy())
    np.testing.assert_array_equal(imageio.imread(a), want)
    assert a.read_bytes() == b.read_bytes()
    np.testing.assert_array_equal(pixels[5:], pixels[5:].copy())  # input not changed


def test_a_png_of_a_transposed_view_holds_its_pixels(tmp_path):
    """Pixels given as a view with other strides (a moved axis) are written as they are seen."""
    rng = np.random.default_rng(3)
    channels_first = rng.random((3, 20, 30)).astype(np.float32)
    view = np.moveaxis(channels_first, 0, -1)
    io.write_png(tmp_path / "view.png", view)
    io.write_png(tmp_path / "copy.png", np.ascontiguousarray(view))
    assert (tmp_path / "view.png").read_bytes() == (tmp_path / "copy.png").read_bytes()


def test_a_pngs_codes_read_as_they_are_stored(tmp_path):
    """read_codes gives the 8-bit codes that read_image gives as fractions of 255."""
    rng = np.random.default_rng(4)
    io.write_png(tmp_path / "p.png", rng.random((12, 17, 3)).astype(np.float32))
    codes = io.read_codes(tmp_path / "p.png")
    assert codes.dtype == np.uint8 and codes.shape == (12, 17, 3)
    fractions = io.read_image(tmp_path / "p.png")
    np.testing.assert_array_equal(codes, np.floor(fractions * 255.0 + 0.5).astype(np.uint8))
    assert np.abs(codes / 255.0 - fractions).max() < 1e-6


def test_a_png_of_codes_holds_them_as_given(tmp_path):
    """uint8 codes (composite.display_codes) are written as they are, without a dither."""
    codes = np.random.default_rng(5).integers(0, 256, (9, 14, 3), dtype=np.uint8)
    written = io.write_png(tmp_path / "c.png", codes)
    np.testing.assert_array_equal(io.read_codes(tmp_path / "c.png"), codes)
    np.testing.assert_array_equal(written, codes)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_a_png_decodes_to_its_codes_and_holds_its_text(tmp_path, channels):
    """The PNG written here (rows filtered by "Sub", deflated by zlib-ng) decodes to its codes in
    Pillow and in OpenImageIO, grey, grey and alpha, RGB or RGBA; its attributes are text chunks."""
    from PIL import Image

    rng = np.random.default_rng(channels)
    codes = rng.integers(0, 256, (23, 31, channels), dtype=np.uint8)
    codes[:7] = np.arange(31, dtype=np.uint8)[None, :, None] * 8  # a ramp: "Sub" leaves small numbers
    path = tmp_path / "p.png"
    io.write_png(path, codes, {"sunshade:frame": "7", "sunshade:config_hash": "ab12"})
    with Image.open(path) as image:
        decoded = np.asarray(image)
        assert image.text == {"sunshade:frame": "7", "sunshade:config_hash": "ab12"}
    np.testing.assert_array_equal(decoded.reshape(codes.shape), codes)
    np.testing.assert_array_equal(io.read_codes(path), codes)
    assert io.read_attributes(path, ["sunshade:frame"]) == {"sunshade:frame": "7"}


def test_a_png_that_cannot_be_written_names_its_file_and_leaves_nothing(tmp_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(io.ImageError, match="taken"):
        io.write_png(tmp_path / "taken", np.zeros((2, 2, 3), dtype=np.uint8))
    assert [p.name for p in tmp_path.iterdir()] == ["taken"]
