"""Colour through OpenColorIO (docs/runs.md, "Colour"): the EXRs in another working space, the
PNGs through an OCIO display and view, the MP4's colour tags; each held to OCIO's own processor
(built by name here, not through the pipeline's lookup) or to the video bitstream's own fields."""

import re
import subprocess

import imageio_ffmpeg
import numpy as np
import PyOpenColorIO as OCIO
import pytest
from scenes import assert_refused, config_of, tiny_grove, write_config, write_inputs

import pipeline.api as api
from pipeline.core import io, ocio

ACES_VIEW = {"display": "sRGB - Display", "view": "ACES 2.0 - SDR 100 nits (Rec.709)"}
AP1_D60 = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
HALF_EPS = 2.0**-11  # half floats' relative rounding, to nearest
HALF_TINY = 2.0**-25  # half floats' absolute rounding among the subnormals


def grove(**output):
    """A tiny grove with trees in front, 48 x 32 px, at a site and time; ``output`` as given."""
    config = tiny_grove()
    config["foreground"] = {"model": "trees"}
    config["camera"] = {"position": [6.0, -6.0, 1.7], "look_at": [0.0, 0.0, 2.0], "resolution": [48, 32]}
    config["animation"] = {"frames": 2}
    config["output"] = output
    return config


def builtin():
    return OCIO.Config.CreateFromBuiltinConfig("studio-config-latest")


def processor(source, target):
    return builtin().getProcessor(source, target).getDefaultCPUProcessor()


def rgb(layers, prefix=""):
    """(rows, cols, 3) float64 of an EXR's R, G, B channels (of a layer ``prefix``)."""
    return np.stack([np.asarray(layers[f"{prefix}{c}"], dtype=np.float64) for c in "RGB"], axis=-1)


def back_to_rec709(pixels):
    out = np.array(pixels, dtype=np.float32)
    processor("ACEScg", "Linear Rec.709 (sRGB)").applyRGB(out.reshape(-1, 3))
    return out.astype(np.float64)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The same frame with every pass written as EXRs (float and half) in the default space and in
    ACEScg: {(space, half): layers read back}, and the ACEScg frame's attributes."""
    folder = tmp_path_factory.mktemp("colour")
    store = folder / "cache"
    files = {}
    for space in ("lin_rec709", "ACEScg"):
        frame = api.render_frame(config_of(grove(colorspace=space), folder), 1, cache=store, threads=1)
        for half in (False, True):
            files[space, half] = folder / f"{space}-{half}.exr"
            frame.write_exr(files[space, half], half=half)
    layers = {key: io.read_layers(path) for key, path in files.items()}
    return layers, io.read_attributes(files["ACEScg", False], ["chromaticities", "sunshade:colorspace"])


def test_an_acescg_frame_converted_back_by_ocio_is_the_default_frame(written):
    """Float layers: OCIO's ACEScg -> linear Rec.709 processor gives the default frame back within
    1e-5 of each pixel's largest channel; the single channels are untouched."""
    layers, _ = written
    aces, default = layers["ACEScg", False], layers["lin_rec709", False]
    for prefix in ("", "sun.", "sky."):
        reference = rgb(default, prefix)
        assert np.abs(rgb(aces, prefix) - reference).max() > 1e-3 * np.abs(reference).max()  # it was converted
        error = np.abs(back_to_rec709(rgb(aces, prefix)) - reference)
        scale = np.abs(reference).max(axis=-1, keepdims=True)
        assert np.all(error <= 1e-5 * scale + 1e-30), prefix
    for name in ("alpha.A", "illuminance.Y", "depth.Z"):
        np.testing.assert_array_equal(aces[name], default[name])


def test_a_half_acescg_frame_comes_back_within_half_rounding(written):
    """Half layers: each ACEScg value rounded to half (2^-11 relative, 2^-25 among subnormals)
    carried through the back conversion's |matrix|, plus the default frame's own rounding."""
    layers, _ = written
    aces, default = layers["ACEScg", True], layers["lin_rec709", True]
    matrix = np.abs(back_to_rec709(np.eye(3)).T)  # rec709 = M @ acescg; OCIO's own matrix
    for prefix in ("", "sun.", "sky."):
        stored, reference = rgb(aces, prefix), rgb(default, prefix)
        bound = (np.abs(stored) * HALF_EPS + HALF_TINY) @ matrix.T + np.abs(reference) * HALF_EPS + HALF_TINY
        error = np.abs(back_to_rec709(stored) - reference)
        assert np.all(error <= 1.01 * bound + 1e-7 * np.abs(reference).max()), prefix
        assert error.max() > 0  # half rounding shows: the bound is not vacuous


def test_the_chromaticities_are_the_ap1_primaries_and_the_aces_white(written):
    _, attributes = written
    np.testing.assert_array_equal(np.float32(attributes["chromaticities"]), np.float32(AP1_D60))
    assert attributes["sunshade:colorspace"] == "ACEScg"


def test_an_aces_view_renders_a_run_and_tags_its_video(tmp_path):
    """A run through the built-in config's ACES 2.0 sRGB view: its PNGs are OCIO's processor of the
    exposed, white-balanced scene-linear frame, dithered as ``io.write_png`` dithers (one code at
    most apart); the MP4 says BT.709 primaries, transfer and matrix in its stream and its box."""
    config = config_of(grove(view=ACES_VIEW, passes=["sun"]), tmp_path)
    summary = api.render_run(config, tmp_path / "run", cache=tmp_path / "cache", jobs=1)
    assert summary.rendered == (0, 1) and summary.video is not None
    frame = api.render_frame(config_of(grove(), tmp_path), 1, cache=tmp_path / "cache", threads=1, passes=())
    gain = (np.asarray(frame.result.balance) * frame.exposure).astype(np.float32)
    exposed = np.array(frame.beauty * gain, dtype=np.float32)
    cpu = builtin().getProcessor("Linear Rec.709 (sRGB)", ACES_VIEW["display"], ACES_VIEW["view"],
                                 OCIO.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()
    cpu.applyRGB(exposed.reshape(-1, 3))
    expected = np.floor(np.clip(exposed, 0, 1) * 255 + 0.5 + io.half_dither(exposed.shape))
    codes = io.read_codes(tmp_path / "run" / "config.0001.png")
    assert np.abs(codes.astype(int) - np.clip(expected, 0, 255)).max() <= 1
    filmic = np.asarray(frame.picture(), dtype=int)  # the default curve's PNG differs
    assert np.abs(filmic - codes.astype(int)).mean() > 5
    assert (tmp_path / "run" / "contact-sheet.png").is_file()

    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    said = subprocess.run([ffmpeg, "-hide_banner", "-i", str(summary.video)], capture_output=True, text=True).stderr
    assert re.search(r"yuv420p\(tv, bt709[,)]", said), said  # all three tags bt709
    trace = subprocess.run([ffmpeg, "-hide_banner", "-i", str(summary.video), "-c", "copy", "-bsf:v",
                            "trace_headers", "-f", "null", "-"], capture_output=True, text=True).stderr
    for field in ("colour_primaries", "transfer_characteristics", "matrix_coefficients"):
        assert re.search(rf"{field}\s+\d+ = 1\b", trace), field  # H.264 VUI: 1 is BT.709
    data = summary.video.read_bytes()
    assert data[data.index(b"colr") + 4:][:10] == b"nclx\x00\x01\x00\x01\x00\x01"


def test_the_tagged_video_is_converted_by_the_bt709_matrix(tmp_path):
    """Pure red decodes to the luma of BT.709's matrix (16 + 219 x 0.2126), not BT.601's (0.299)."""
    red = np.zeros((16, 16, 3), np.uint8)
    red[..., 0] = 255
    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    for colour, weight in (("bt709", 0.2126), (None, 0.299)):
        path = tmp_path / f"{colour}.mp4"
        io.write_video(path, [red] * 2, fps=24, colour=colour)
        planes = subprocess.run([ffmpeg, "-v", "error", "-i", str(path), "-frames:v", "1", "-f", "rawvideo",
                                 "-pix_fmt", "yuv420p", "-"], capture_output=True, check=True).stdout
        assert abs(planes[0] - (16 + 219 * weight)) <= 1, colour


def test_a_user_config_by_path_or_ocio_gives_the_same_working_space(tmp_path, monkeypatch):
    """The built-in config written to a file and named by output.ocio_config or by $OCIO converts
    as the built-in one; with the colour as rendered, $OCIO is not read and the hash keeps."""
    (tmp_path / "studio.ocio").write_text(builtin().serialize())
    by_path = config_of(grove(colorspace="ACEScg", ocio_config="studio.ocio"), tmp_path)
    assert by_path.output.ocio_config == str(tmp_path / "studio.ocio")
    pixels = np.random.default_rng(0).random((4, 5, 3), dtype=np.float32) * 10
    expected = np.array(pixels)
    processor("Linear Rec.709 (sRGB)", "ACEScg").applyRGB(expected.reshape(-1, 3))
    np.testing.assert_array_equal(ocio.to_working(pixels, by_path.output.ocio_config, "ACEScg"), expected)
    plain = config_of(grove(), tmp_path).digest()
    monkeypatch.setenv("OCIO", str(tmp_path / "studio.ocio"))
    assert config_of(grove(colorspace="ACEScg"), tmp_path).output.ocio_config == str(tmp_path / "studio.ocio")
    assert config_of(grove(), tmp_path).output.ocio_config is None
    assert config_of(grove(), tmp_path).digest() == plain


@pytest.mark.parametrize(("output", "message"), [
    ({"colorspace": "ACEScct"}, "output.colorspace: 'ACEScct' is not a scene-linear space"),
    ({"colorspace": "nowhere"}, "output.colorspace: no colour space 'nowhere'"),
    ({"view": {"display": "sRGB - Display", "view": "Filmic"}}, "output.view: unknown view 'Filmic'"),
    ({"view": {"display": "sRGB - Display"}}, "missing key 'output.view.view'"),
    ({"colorspace": "ACEScg", "ocio_config": "none.ocio"}, "output.ocio_config: no such file"),
])
def test_a_bad_colour_key_is_one_line_naming_it(inputs, capsys, output, message):
    folder, out = inputs
    config = {"canopy": {"mask": "mask.png", "size": [4.0, 4.0], "height": 3.0},
              "sky": {"model": "uniform", "radiance": 1.0, "alpha": 80.0},
              "ground": {"window": [-4, -4, 4, 4], "pixel": 0.1}, "output": output}
    assert_refused(write_config(folder, config), out, capsys, message)


def test_camera_display_and_output_view_are_not_both_given(tmp_path, capsys):
    write_inputs(tmp_path)
    config = grove(view=ACES_VIEW)
    config["camera"]["display"] = "srgb"
    with pytest.raises(api.SunshadeError, match=r"camera\.display: output\.view shows the frames"):
        config_of(config, tmp_path)
