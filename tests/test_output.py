"""Tests for raysort.output: EXR and PNG writers, render pairs, atomic writes, path errors.

PNG files are decoded with Pillow directly; EXR files with OpenEXR."""

import functools
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from raysort import output
from raysort.errors import ConfigError, OutputError, RaysortError

OpenEXR = pytest.importorskip("OpenEXR")


def _bits(a):
    return np.asarray(a, dtype=np.float32).view(np.uint32)


def _special_image():
    """A non-square float32 image with zeros, tiny, huge and infinite values."""
    rng = np.random.default_rng(1)
    image = rng.standard_normal((5, 7, 3)).astype(np.float32) * 1000
    image[0, 0] = [0.0, -0.0, 1e-45]                     # zero, -0, denormal
    image[0, 1] = [np.finfo(np.float32).tiny, 1e-30, -1e-40]
    image[0, 2] = [np.finfo(np.float32).max, 3e38, -np.finfo(np.float32).max]
    image[0, 3] = [np.inf, -np.inf, 1e30]
    image[0, 4] = [np.nan, 1.0, 0.1]
    return image


def _listdir(path):
    return sorted(os.listdir(path))


# --------------------------------------------------------------------------
# EXR
# --------------------------------------------------------------------------

def test_exr_round_trip_is_bit_exact(tmp_path):
    image = _special_image()
    target = tmp_path / "out.exr"
    output.write_exr(target, image)
    back = output.read_exr(target)
    assert back.dtype == np.float32
    assert back.shape == (5, 7, 3)
    np.testing.assert_array_equal(_bits(back), _bits(image))
    assert _listdir(tmp_path) == ["out.exr"]


def test_exr_file_layout(tmp_path):
    target = tmp_path / "out.exr"
    output.write_exr(target, np.ones((2, 3, 3), np.float32))
    exr = OpenEXR.File(str(target), separate_channels=True)
    header = exr.header()
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    assert header["type"] == OpenEXR.scanlineimage
    channels = exr.channels()
    assert sorted(channels) == ["B", "G", "R"]
    for channel in channels.values():
        assert channel.type() == OpenEXR.FLOAT
        assert channel.pixels.shape == (2, 3)


def test_exr_non_contiguous_input(tmp_path):
    # OpenEXR ignores numpy strides, so views must be copied before writing.
    base = np.arange(4 * 6 * 3, dtype=np.float32).reshape(6, 4, 3)
    view = base.transpose(1, 0, 2)[:, ::2]
    assert not view.flags["C_CONTIGUOUS"]
    target = tmp_path / "view.exr"
    output.write_exr(target, view)
    np.testing.assert_array_equal(output.read_exr(target), view)


def test_exr_float64_converted(tmp_path):
    image = np.linspace(-2.0, 1e6, 2 * 4 * 3).reshape(2, 4, 3) + 1e-9
    target = tmp_path / "out.exr"
    output.write_exr(target, image)
    back = output.read_exr(target)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(_bits(back), _bits(image.astype(np.float32)))


@pytest.mark.parametrize("shape", [(4, 4), (4, 4, 4), (4, 4, 1), (0, 4, 3),
                                   (1, 4, 4, 3)])
def test_exr_wrong_shape_rejected(tmp_path, shape):
    with pytest.raises(ValueError, match=str(shape).replace("(", r"\(")
                       .replace(")", r"\)")):
        output.write_exr(tmp_path / "x.exr", np.zeros(shape, np.float32))
    assert _listdir(tmp_path) == []


@pytest.mark.parametrize("dtype", [np.uint8, np.int32, np.float16, bool])
def test_exr_wrong_dtype_rejected(tmp_path, dtype):
    with pytest.raises(ValueError, match="float32"):
        output.write_exr(tmp_path / "x.exr", np.zeros((2, 2, 3), dtype))
    assert _listdir(tmp_path) == []


def test_exr_metadata_round_trip(tmp_path):
    target = tmp_path / "out.exr"
    metadata = {"raysort_version": "0.1.0",
                "raysort_settings": '{"spp": 16, "sorter": "morton"}',
                "comments": "ünïcode ✓", "empty": "", "k" * 255: "long name"}
    output.write_exr(target, np.zeros((1, 1, 3)), metadata=metadata)
    header = OpenEXR.File(str(target), header_only=True).header()
    for key, value in metadata.items():
        assert header[key] == value


@pytest.mark.parametrize("metadata, error", [
    ({"version": 1}, TypeError),
    ({1: "x"}, TypeError),
    (["a"], TypeError),
    ({"": "x"}, ValueError),
    ({"a\0b": "x"}, ValueError),
    ({"k" * 256: "x"}, ValueError),        # OpenEXR would truncate silently
    ({"compression": "none"}, ValueError),
    ({"dataWindow": "x"}, ValueError),
    ({"name": "beauty"}, ValueError),       # a str OpenEXR would accept
    ({"chromaticities": "x"}, ValueError),  # typed standard attribute
])
def test_exr_bad_metadata_rejected_before_writing(tmp_path, monkeypatch,
                                                 metadata, error):
    def no_temp_file(*args, **kwargs):
        raise AssertionError("a temporary file was created")

    monkeypatch.setattr(output.tempfile, "mkstemp", no_temp_file)
    with pytest.raises(error):
        output.write_exr(tmp_path / "x.exr", np.zeros((1, 1, 3)),
                         metadata=metadata)
    assert _listdir(tmp_path) == []


def test_read_exr_missing_file(tmp_path):
    path = tmp_path / "missing.exr"
    with pytest.raises(OutputError, match="does not exist") as info:
        output.read_exr(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("content", [b"", b"hello world", b"\x76\x2f\x31\x01junk"])
def test_read_exr_not_an_exr(tmp_path, content):
    path = tmp_path / "bad.exr"
    path.write_bytes(content)
    with pytest.raises(OutputError) as info:
        output.read_exr(path)
    assert str(path) in str(info.value)


def test_read_exr_directory(tmp_path):
    with pytest.raises(OutputError, match="directory"):
        output.read_exr(tmp_path)


def test_read_exr_without_rgb(tmp_path):
    path = tmp_path / "y.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION,
                  "type": OpenEXR.scanlineimage},
                 {"Y": np.zeros((2, 2), np.float32)}).write(str(path))
    with pytest.raises(OutputError, match="R, G, B"):
        output.read_exr(path)


# --------------------------------------------------------------------------
# PNG
# --------------------------------------------------------------------------

def _pillow_read(path):
    """Decode a PNG with Pillow, checking its chunk CRCs first."""
    with Image.open(path) as picture:
        picture.verify()
    with Image.open(path) as picture:
        assert picture.format == "PNG" and picture.mode == "RGB"
        return np.asarray(picture), dict(picture.text)


def _png_of(tmp_path, values, **kw):
    image = np.array(values, dtype=np.float64).reshape(1, -1, 1).repeat(3, axis=2)
    target = tmp_path / "p.png"
    output.write_png(target, image, **kw)
    back, _ = _pillow_read(target)
    assert back.dtype == np.uint8 and back.shape == image.shape
    assert (back == back[..., :1]).all()
    return back[0, :, 0].tolist()


def test_png_known_values(tmp_path):
    values = [0.0, 1.0, 0.5, 1.5, 1e30, np.inf, -0.5, -np.inf, np.nan,
              0.002, 0.0031308, 0.18]
    # 0.5 -> sRGB 0.7354 -> 187.5 -> 188; 0.002 -> 12.92*0.002*255 = 6.6 -> 7
    expected = [0, 255, 188, 255, 255, 255, 0, 0, 0, 7, 10, 118]
    assert _png_of(tmp_path, values) == expected


def test_png_exposure(tmp_path):
    assert _png_of(tmp_path, [0.25, 0.5, 0.6, 0.0, np.nan],
                   exposure=1) == [188, 255, 255, 0, 0]
    assert _png_of(tmp_path, [1.0, 2.0, 4.0], exposure=-1) == [188, 255, 255]


def test_png_exact_srgb_curve():
    linear = np.linspace(0.0, 1.0, 10001)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear,
                    1.055 * linear ** (1 / 2.4) - 0.055)
    expected = np.floor(srgb * 255 + 0.5)
    got = output.tone_map(linear).astype(float)
    # rint rounds exact halves to even; no sample is within 1e-9 of a half
    assert np.array_equal(got, expected)


def test_png_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"\(2, 2\)"):
        output.write_png(tmp_path / "x.png", np.zeros((2, 2)))
    with pytest.raises(ValueError, match="exposure"):
        output.write_png(tmp_path / "x.png", np.zeros((2, 2, 3)),
                         exposure=float("nan"))
    assert _listdir(tmp_path) == []


@pytest.mark.parametrize("block", [None, 7, 39])
def test_png_pixels_and_text(tmp_path, monkeypatch, block):
    """Pillow reads back every pixel as the tone map of the float32 value, however
    the rows are cut into blocks (39 values = one row of 13 pixels per block)."""
    if block:
        monkeypatch.setattr(output, "_TONE_MAP_BLOCK", block)
    height, width = 9, 13
    image = np.random.default_rng(2).uniform(-0.1, 1.2, (height, width, 3))
    target = tmp_path / "v.png"
    output.write_png(target, image, exposure=0.5, text={"raysort.render_id": "abc"})
    pixels, text = _pillow_read(target)
    assert pixels.shape == (height, width, 3)
    linear = np.clip(image.astype(np.float32).astype(np.float64) * 2 ** 0.5, 0, 1)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    assert np.array_equal(pixels, np.rint(srgb * 255).astype(np.uint8))
    assert text == {"raysort.render_id": "abc"}
    assert np.array_equal(output.read_png(target), pixels)


def test_tone_map_blocks_match_one_pass(monkeypatch):
    image = np.random.default_rng(3).uniform(-0.5, 1.5, (7, 11, 3)).astype(np.float32)
    whole = output.tone_map(image, 0.25)
    monkeypatch.setattr(output, "_TONE_MAP_BLOCK", 5)
    assert np.array_equal(output.tone_map(image, 0.25), whole)
    assert np.array_equal(output.tone_map(image[:, ::2], 0.25), whole[:, ::2])


def _corrupt(tmp_path, data):
    path = tmp_path / "bad.png"
    path.write_bytes(data)
    with pytest.raises(OutputError) as info:
        output.read_png(path)
    assert str(path) in str(info.value)
    return str(info.value)


def test_read_png_rejects_bad_files(tmp_path):
    output.write_png(tmp_path / "good.png", np.full((2, 3, 3), 0.5))
    good = (tmp_path / "good.png").read_bytes()
    assert "not a PNG" in _corrupt(tmp_path, b"\x89PNX" + good[4:])
    broken = bytearray(good)
    broken[18] ^= 0xFF                     # inside the IHDR payload: bad CRC
    _corrupt(tmp_path, bytes(broken))
    _corrupt(tmp_path, good[:40])          # truncated in the image data
    Image.new("L", (2, 2)).save(tmp_path / "grey.png")
    with pytest.raises(OutputError, match="not 8-bit RGB"):
        output.read_png(tmp_path / "grey.png")


def test_read_png_missing(tmp_path):
    with pytest.raises(OutputError, match="does not exist"):
        output.read_png(tmp_path / "missing.png")


PEAK_SCRIPT = """
import resource, sys
import numpy as np
from raysort import output
height, width = 3072, 4096
image = np.empty((height, width, 3), np.float32)
image[:] = np.linspace(-0.1, 1.3, width, dtype=np.float32)[None, :, None]
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
output.write_png(sys.argv[1], image)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(image.nbytes, (after - before) * 1024)
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss in KiB is Linux's")
def test_png_peak_memory_stays_near_the_image_size(tmp_path):
    """Writing the preview of a 4096x3072 float32 image (144 MiB) adds at most half the
    image's size to the process's peak resident memory: Pillow's 8-bit picture (a third)
    plus a block of rows.  Tone mapping the whole image in float64 at once added ~10x."""
    proc = subprocess.run([sys.executable, "-c", PEAK_SCRIPT, str(tmp_path / "big.png")],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    image_bytes, extra_peak = map(int, proc.stdout.split())
    assert extra_peak <= image_bytes // 2, (
        f"writing the PNG raised the peak by {extra_peak / 2**20:.0f} MiB for a "
        f"{image_bytes / 2**20:.0f} MiB image")
    assert _pillow_read(tmp_path / "big.png")[0].shape == (3072, 4096, 3)


# --------------------------------------------------------------------------
# An EXR and its PNG as one pair
# --------------------------------------------------------------------------

def _render_id(exr_path):
    return OpenEXR.File(str(exr_path), header_only=True).header()["raysort.render_id"]


def test_write_render_pair_shares_a_render_id(tmp_path):
    target = tmp_path / "r.exr"
    image = np.full((4, 5, 3), 0.5, np.float32)
    render_id = output.write_render(target, image, metadata={"raysort.scene": "x"},
                                    exposure=1.0)
    assert _listdir(tmp_path) == ["r.exr", "r.png"]
    assert _render_id(target) == render_id
    assert OpenEXR.File(str(target), header_only=True).header()["raysort.scene"] == "x"
    pixels, text = _pillow_read(tmp_path / "r.png")
    assert text == {"raysort.render_id": render_id}
    assert (pixels == 255).all()                           # 0.5 at +1 EV
    np.testing.assert_array_equal(output.read_exr(target), image)
    before = target.read_bytes(), (tmp_path / "r.png").read_bytes()
    assert output.write_render(target, image, metadata={"raysort.scene": "x"},
                               exposure=1.0) == render_id     # the same render: same bytes
    assert (target.read_bytes(), (tmp_path / "r.png").read_bytes()) == before
    changed = image.copy()
    changed[3, 4, 2] = np.nextafter(np.float32(0.5), np.float32(1))
    for other in (output.write_render(target, changed, metadata={"raysort.scene": "x"},
                                      exposure=1.0),
                  output.write_render(target, image, metadata={"raysort.scene": "y"},
                                      exposure=1.0),
                  output.write_render(target, image, metadata={"raysort.scene": "x"})):
        assert other != render_id
    output.write_render(tmp_path / "only.EXR", image, png=False)
    assert _listdir(tmp_path) == ["only.EXR", "r.exr", "r.png"]


def test_write_render_writes_its_sidecars_with_it(tmp_path, monkeypatch):
    """Sidecars are written with the EXR and PNG; one that fails leaves none of the
    files changed; a sidecar naming one of the render's own files, or text that is
    not a str, is refused before anything is written."""
    exr, js = tmp_path / "r.exr", tmp_path / "r.json"
    output.write_render(exr, np.ones((2, 2, 3)), sidecars={js: '{"a": 1}\n'})
    assert _listdir(tmp_path) == ["r.exr", "r.json", "r.png"]
    assert js.read_text() == '{"a": 1}\n'
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def full(target, text, path):
        raise OutputError(f"cannot write {path!r}: No space left on device")

    monkeypatch.setattr(output, "_write_text", full)
    with pytest.raises(OutputError, match="No space left"):
        output.write_render(exr, np.zeros((2, 2, 3)), sidecars={js: "{}"})
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    monkeypatch.undo()
    for side, other in ((exr, "the image"), (tmp_path / "r.png", "the preview"),
                        (tmp_path / "." / "r.exr", "the image")):
        with pytest.raises(ConfigError, match=f"a sidecar '{side}' is {other}"):
            output.write_render(exr, np.zeros((2, 2, 3)), sidecars={side: "{}"})
    with pytest.raises(ConfigError, match="is a sidecar"):
        output.write_render(exr, np.zeros((2, 2, 3)),
                            sidecars={js: "{}", f"{tmp_path}/./r.json": ""})
    with pytest.raises(TypeError, match="str"):
        output.write_render(exr, np.zeros((2, 2, 3)), sidecars={js: b"{}"})
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_write_render_failure_changes_neither_file(tmp_path, monkeypatch):
    """The PNG fails after the EXR temporary is complete: both old files stay, no temps."""
    exr, png = tmp_path / "r.exr", tmp_path / "r.png"
    exr.write_bytes(b"old exr")
    png.write_bytes(b"old png")

    def fail(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output, "_write_picture", fail)
    with pytest.raises(OutputError, match="No space left"):
        output.write_render(exr, np.ones((2, 2, 3)))
    assert _listdir(tmp_path) == ["r.exr", "r.png"]
    assert exr.read_bytes() == b"old exr" and png.read_bytes() == b"old png"
    with pytest.raises(OutputError, match=".exr"):
        output.write_render(tmp_path / "r.png", np.ones((2, 2, 3)))


PAIR_WRITER = """
import os, sys, time
import numpy as np
from raysort import output
directory, value, go = sys.argv[1], float(sys.argv[2]), sys.argv[3]
image = np.full((48, 64, 3), value, np.float32)
while not os.path.exists(go):
    time.sleep(0.001)
for k in range(int(sys.argv[4])):
    output.write_render(os.path.join(directory, f"x{k}.exr"), image)
"""


@pytest.mark.slow
def test_concurrent_writers_leave_matching_pairs(tmp_path):
    """Four processes write renders of different values to the same twelve paths at
    once; every EXR ends next to the PNG of the same render (same id, and the PNG's
    pixels are the tone map of the EXR's value)."""
    go, targets = tmp_path / "go", 12
    writers = [subprocess.Popen([sys.executable, "-c", PAIR_WRITER, str(tmp_path), str(v),
                                 str(go), str(targets)], cwd=tmp_path)
               for v in (0.1, 0.3, 0.6, 0.9)]
    go.touch()
    assert [w.wait(timeout=600) for w in writers] == [0] * 4
    for k in range(targets):
        exr = tmp_path / f"x{k}.exr"
        pixels, text = _pillow_read(tmp_path / f"x{k}.png")
        assert text["raysort.render_id"] == _render_id(exr), k
        assert np.array_equal(pixels, output.tone_map(output.read_exr(exr))), k
    assert not [name for name in os.listdir(tmp_path) if name.startswith(".")]


# --------------------------------------------------------------------------
# Atomic writes
# --------------------------------------------------------------------------

class Boom(Exception):
    pass


@pytest.mark.parametrize("exc", [Boom, KeyboardInterrupt])
def test_exr_failure_leaves_no_temp_and_keeps_target(tmp_path, monkeypatch, exc):
    target = tmp_path / "out.exr"
    target.write_bytes(b"old content")
    real = output._write_exr_file
    seen = []

    def write_then_fail(exr, tmp, path):
        real(exr, tmp, path)                      # the temp file is complete
        assert os.path.dirname(tmp) == str(tmp_path)
        assert os.path.getsize(tmp) > 0
        seen.append(tmp)
        raise exc("interrupted")

    monkeypatch.setattr(output, "_write_exr_file", write_then_fail)
    with pytest.raises(exc):
        output.write_exr(target, np.ones((4, 4, 3)))
    assert seen and not os.path.exists(seen[0])
    assert _listdir(tmp_path) == ["out.exr"]
    assert target.read_bytes() == b"old content"


def test_exr_library_error_becomes_output_error(tmp_path, monkeypatch):
    class FailingFile:
        def write(self, name):
            with open(name, "wb") as file:
                file.write(b"\x76\x2f\x31\x01partial")
            raise RuntimeError("disk on fire")

    monkeypatch.setattr(output, "_exr_file", lambda *args: FailingFile())
    target = tmp_path / "out.exr"
    with pytest.raises(OutputError, match="disk on fire") as info:
        output.write_exr(target, np.ones((1, 1, 3)))
    assert str(target) in str(info.value)
    assert _listdir(tmp_path) == []


@pytest.mark.parametrize("exc, raised", [(OSError(28, "No space left on device"),
                                          OutputError),
                                         (KeyboardInterrupt(), KeyboardInterrupt)])
def test_png_failure_leaves_no_temp_and_keeps_target(tmp_path, monkeypatch,
                                                     exc, raised):
    target = tmp_path / "out.png"
    target.write_bytes(b"old png")
    seen = []

    def write_half(picture, path, text):
        seen.append(path)
        with open(path, "wb") as file:
            file.write(b"\x89PNG half")
        raise exc

    monkeypatch.setattr(output, "_write_picture", write_half)
    with pytest.raises(raised) as info:
        output.write_png(target, np.ones((8, 8, 3)))
    if raised is OutputError:
        assert "No space left" in str(info.value)
        assert str(target) in str(info.value)
    assert seen and os.path.basename(seen[0]).startswith(".out.png.")
    assert _listdir(tmp_path) == ["out.png"]
    assert target.read_bytes() == b"old png"


@pytest.mark.parametrize("name", ["out.exr", "out.png"])
def test_successful_write_replaces_target(tmp_path, name):
    target = tmp_path / name
    target.write_bytes(b"old")
    old_umask = os.umask(0o027)
    try:
        output.write_image(target, np.full((3, 2, 3), 0.25))
    finally:
        os.umask(old_umask)
    assert _listdir(tmp_path) == [name]
    assert target.read_bytes() != b"old"
    assert (target.stat().st_mode & 0o777) == 0o640   # not mkstemp's 0o600


def test_write_image_dispatch(tmp_path):
    image = np.full((2, 2, 3), 0.5, np.float32)
    output.write_image(tmp_path / "a.exr", image, metadata={"x": "y"})
    output.write_image(tmp_path / "b.PNG", image, exposure=1.0)
    output.write_image(str(tmp_path / "c.png"), image)
    assert np.array_equal(output.read_exr(tmp_path / "a.exr"), image)
    assert (output.read_png(tmp_path / "b.PNG") == 255).all()
    assert (output.read_png(tmp_path / "c.png") == 188).all()


# --------------------------------------------------------------------------
# Path errors
# --------------------------------------------------------------------------

def _assert_output_error(call, path, reason):
    with pytest.raises(OutputError) as info:
        call()
    message = str(info.value)
    assert isinstance(info.value, RaysortError)
    assert str(path) in message and reason in message
    assert "\n" not in message
    return message


WRITERS = [output.write_exr, output.write_png, output.write_image]


@pytest.mark.parametrize("ext", [".exr", ".png"])
def test_missing_directory(tmp_path, ext):
    path = tmp_path / "nope" / "deeper" / ("x" + ext)
    image = np.zeros((1, 1, 3))
    for call in (lambda: output.check_writable(path),
                 lambda: output.write_image(path, image),
                 lambda: (output.write_exr if ext == ".exr"
                          else output.write_png)(path, image)):
        message = _assert_output_error(call, path, "does not exist")
        assert repr(str(path.parent)) in message
    assert _listdir(tmp_path) == []


def test_missing_relative_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    message = _assert_output_error(
        lambda: output.write_png("out/x.png", np.zeros((1, 1, 3))),
        "out/x.png", "does not exist")
    assert message == ("cannot write 'out/x.png': "
                       "directory 'out' does not exist")


@pytest.mark.parametrize("ext", [".exr", ".png"])
def test_path_under_regular_file(tmp_path, ext):
    afile = tmp_path / "afile"
    afile.write_bytes(b"data")
    for path in (afile / ("x" + ext), afile / "sub" / ("x" + ext)):
        _assert_output_error(functools.partial(output.check_writable, path), path,
                             f"{str(afile)!r} is not a directory")
        _assert_output_error(functools.partial(output.write_image, path, np.zeros((1, 1, 3))),
                             path, "is not a directory")
    assert _listdir(tmp_path) == ["afile"]
    assert afile.read_bytes() == b"data"


def test_path_is_directory(tmp_path):
    path = tmp_path / "dir.exr"
    path.mkdir()
    _assert_output_error(lambda: output.check_writable(path), path,
                         "is a directory")
    _assert_output_error(lambda: output.write_exr(path, np.zeros((1, 1, 3))),
                         path, "is a directory")
    assert _listdir(tmp_path) == ["dir.exr"] and _listdir(path) == []


def test_a_path_ending_in_a_separator_names_no_file(tmp_path):
    """'out/' names a directory even before it exists: nothing is created for it."""
    path = os.path.join(tmp_path, "out") + os.sep
    _assert_output_error(lambda: output.check_writable(path, parents=True), path,
                         "names a directory")
    assert _listdir(tmp_path) == []


def test_a_symbolic_link_is_written_through(tmp_path):
    """The link's target gets the file (atomically); the link stays a link."""
    link = tmp_path / "link.exr"
    link.symlink_to(tmp_path / "target.exr")
    image = _special_image()
    output.write_exr(link, image)
    assert link.is_symlink()
    assert np.array_equal(_bits(output.read_exr(tmp_path / "target.exr")), _bits(image))
    assert sorted(_listdir(tmp_path)) == ["link.exr", "target.exr"]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_a_device_or_pipe_is_written_into_not_replaced(tmp_path):
    """A target that is neither a regular file nor a directory (/dev/null, a named
    pipe) gets the output written into it; its node is not replaced by a file."""
    import threading

    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    output.write_json(fifo, {"a": 1})
    reader.join(10)
    assert got and b'"a"' in got[0]
    assert not fifo.is_file() and _listdir(tmp_path) == ["pipe.json"]
    if os.path.exists("/dev/null"):
        output.write_json("/dev/null", {"a": 1})
        assert not os.path.isfile("/dev/null")


@pytest.mark.skipif(sys.platform in ("win32", "darwin"),
                    reason="needs a file system that takes names that are not UTF-8")
def test_exr_names_that_are_not_utf8(tmp_path):
    """OpenEXR takes only UTF-8 names; a POSIX name may hold any bytes."""
    path = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"\xff\xfe.exr"))
    image = _special_image()
    output.write_exr(path, image)
    assert np.array_equal(_bits(output.read_exr(path)), _bits(image))
    assert _listdir(tmp_path) == [os.path.basename(path)]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root can write to read-only directories")
def test_read_only_directory(tmp_path):
    directory = tmp_path / "ro"
    directory.mkdir()
    directory.chmod(0o555)
    try:
        path = directory / "x.png"
        _assert_output_error(lambda: output.check_writable(path), path,
                             "is not writable")
        _assert_output_error(lambda: output.write_png(path, np.zeros((1, 1, 3))),
                             path, "is not writable")
        assert _listdir(directory) == []
    finally:
        directory.chmod(0o755)


def test_not_writable_directory_reported(tmp_path, monkeypatch):
    # Works as root too: pretend the kernel denies write access to `ro`.
    directory = tmp_path / "ro"
    directory.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: (
        False if os.fspath(p) == str(directory) else real_access(p, mode, **kw)))
    path = directory / "x.exr"
    message = _assert_output_error(lambda: output.check_writable(path), path,
                                   "is not writable")
    assert message == (f"cannot write {str(path)!r}: "
                       f"directory {str(directory)!r} is not writable")
    _assert_output_error(lambda: output.write_exr(path, np.zeros((1, 1, 3))),
                         path, "is not writable")
    assert _listdir(directory) == []


def test_unsupported_suffix(tmp_path):
    for name in ("x.jpg", "x", "x.exr.bak"):
        path = tmp_path / name
        message = _assert_output_error(
            functools.partial(output.write_image, path, np.zeros((1, 1, 3))), path,
            "unsupported")
        assert ".exr" in message and ".png" in message
    assert _listdir(tmp_path) == []


def test_check_writable_creates_nothing(tmp_path):
    output.check_writable(tmp_path / "new.exr")
    output.check_writable(str(tmp_path / "new.png"))
    existing = tmp_path / "old.png"
    existing.write_bytes(b"keep")
    output.check_writable(existing)
    with pytest.raises(OutputError):
        output.check_writable(tmp_path / "a" / "b" / "c.exr")
    assert _listdir(tmp_path) == ["old.png"]
    assert existing.read_bytes() == b"keep"


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_check_writable_probes_the_directory():
    """/proc looks writable to root, but no file can be made there: the probe finds out
    before anything is rendered."""
    _assert_output_error(lambda: output.check_writable("/proc/out.exr"), "/proc/out.exr",
                         "cannot create a file in '/proc'")


def test_check_writable_with_parents(tmp_path):
    path = tmp_path / "a" / "b" / "c.exr"
    output.check_writable(path, parents=True)
    assert _listdir(tmp_path) == []
    afile = tmp_path / "afile"
    afile.write_bytes(b"")
    _assert_output_error(lambda: output.check_writable(afile / "b" / "c.exr", parents=True),
                         afile / "b" / "c.exr", "is not a directory")
    assert output.make_parents(path) == str(tmp_path / "a")
    assert (tmp_path / "a" / "b").is_dir()
    assert output.make_parents(path) is None
    assert output.make_parents("c.exr") is None


def test_empty_path():
    with pytest.raises(OutputError, match="empty"):
        output.check_writable("")


def test_write_json_is_atomic_and_readable(tmp_path, monkeypatch):
    """write_json writes valid JSON through the same temporary-then-rename path; a failure
    while writing leaves the old file and no temporary file behind."""
    import json

    path = tmp_path / "r.json"
    output.write_json(path, {"a": 1, "b": [1.5, "x"]})
    assert json.loads(path.read_text()) == {"a": 1, "b": [1.5, "x"]}

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(json, "dumps", boom)
    with pytest.raises(RuntimeError):
        output.write_json(path, {"c": 2})
    assert json.loads(path.read_text()) == {"a": 1, "b": [1.5, "x"]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]
