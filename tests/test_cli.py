"""The ``raysort`` command line: renders, listings, and one-line errors that leave no files.

Most tests call ``raysort.cli.main`` in-process; a few run ``python -m raysort``
in a subprocess to see the real exit status and stderr.
"""
import importlib.resources
import io
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import raysort
from raysort import output
from raysort.cli import main

from _helpers import assert_one_line_error, run

BUILTINS = {("generators", "pinhole"), ("sorters", "none"), ("sorters", "nah"),
            ("sorters", "nah_numpy"), ("traversals", "single"), ("traversals", "masked"),
            ("traversals", "ranged"), ("traversals", "partition"), ("shaders", "lambert"),
            ("shaders", "ao")}
TABLE_I = ("N_IA", "scalar N_B", "SIMD N_B", "scalar N_T", "SIMD N_T")
TINY = ["--size", "8x6", "--spp", "1", "-q"]


def srgb8(linear):
    """8-bit sRGB code of a linear value in [0, 1] (IEC 61966-2-1)."""
    v = 12.92 * linear if linear <= 0.0031308 else 1.055 * linear ** (1 / 2.4) - 0.055
    return int(np.floor(v * 255 + 0.5))


def run_module(*argv, cwd):
    return subprocess.run([sys.executable, "-m", "raysort", *map(str, argv)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


# --------------------------------------------------------------------------
# renders
# --------------------------------------------------------------------------

def test_render_plane_subprocess(tmp_path):
    """`python -m raysort render plane` exits 0 with a clean stderr, prints the Table I
    counters, and writes an EXR of exactly albedo * sky = 0.5 plus its PNG preview."""
    proc = run_module("render", "plane", "--size", "16x12", "--spp", "1", "-o", "x.exr", "-q",
                      "--stats", "--traversal", "single", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert sorted(os.listdir(tmp_path)) == ["x.exr", "x.png"]
    image = output.read_exr(tmp_path / "x.exr")
    assert image.shape == (12, 16, 3) and image.dtype == np.float32
    np.testing.assert_allclose(image, 0.5, rtol=1e-6)
    png = output.read_png(tmp_path / "x.png")
    assert png.shape == (12, 16, 3)
    assert (png == srgb8(0.5)).all()
    # Table I: header, and the plane's BVH is one leaf of 2 triangles that every
    # primary ray enters: with `single`, 1 box and 2 triangle tests per primary ray
    out = proc.stdout
    header = next(line for line in out.splitlines() if "N_IA" in line)
    for label in TABLE_I:
        assert label in header
    row0 = next(line.split() for line in out.splitlines() if line.split()[:1] == ["0"])
    assert [float(v) for v in row0[1:]] == [0.0, 1.0, 0.0, 2.0, 0.0]
    assert "rendered plane 16x12, 1 spp" in out


def test_error_subprocess(tmp_path):
    """A user error exits with status 2 and one stderr line, no traceback, no file."""
    proc = run_module("render", "nosuchscene", "-o", "x.exr", "-q", cwd=tmp_path)
    assert proc.returncode == 2
    assert_one_line_error(proc.stderr, "nosuchscene")
    assert proc.stdout == "" and os.listdir(tmp_path) == []


def test_render_in_process_writes_exr_png_and_json(tmp_path, capsys):
    """main() renders the plane; --json records the settings and ray counts
    (192 primary rays, each bounces once off the plane and escapes)."""
    exr, js = tmp_path / "x.exr", tmp_path / "x.json"
    code, out, err = run(capsys, "render", "plane", "--size", "16x12", "--spp", "1", "-o", exr,
                         "-q", "--json", js, "--sorter", "nah", "--traversal", "ranged")
    assert code == 0 and err == ""
    np.testing.assert_allclose(output.read_exr(exr), 0.5, rtol=1e-6)
    assert output.read_png(tmp_path / "x.png").shape == (12, 16, 3)
    data = json.loads(js.read_text())
    s = data["settings"]
    assert (s["scene"], s["width"], s["height"], s["spp"], s["seed"]) == ("plane", 16, 12, 1, 0)
    assert "nah" in s["sorter"] and "ranged" in s["traversal"]
    assert data["stats"]["rays_per_depth"] == {"0": 192, "1": 192}
    assert data["stats"]["counters_per_depth"]["0"]["rays"] == 192
    assert sorted(os.listdir(tmp_path)) == ["x.exr", "x.json", "x.png"]


def test_summary_goes_to_the_current_stdout(tmp_path, capsys):
    """The render summary and --stats table are printed to sys.stdout as it is when
    main() runs (so capsys / contextlib.redirect_stdout see them)."""
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", tmp_path / "x.exr", "--stats")
    assert code == 0
    assert "rendered plane 8x6" in out
    for label in TABLE_I:
        assert label in out


def test_progress_goes_to_the_current_stderr(tmp_path, capsys, monkeypatch):
    """Without -q the progress bar is drawn on sys.stderr as it is when main() runs, if
    that is a terminal; redirected, or with -q, stderr stays empty."""
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    argv = ["render", "plane", "--size", "8x6", "--spp", "1", "-o", tmp_path / "x.exr"]
    code, out, err = run(capsys, *argv)
    assert code == 0 and err == ""
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert main([str(a) for a in argv]) == 0
    assert "render plane" in terminal.getvalue() and "Mrays/s" in terminal.getvalue()
    terminal.truncate(0)
    assert main([str(a) for a in argv + ["-q"]]) == 0
    assert terminal.getvalue() == ""


def test_render_default_scene_is_sibenik(tmp_path, capsys):
    """`raysort render` with no scene renders the Sibenik nave (one primary ray per pixel
    at depth 0 and 1 spp)."""
    exr, js = tmp_path / "s.exr", tmp_path / "s.json"
    code, out, err = run(capsys, "render", *TINY, "--depth", "0", "-o", exr, "--json", js)
    assert code == 0, err
    data = json.loads(js.read_text())
    assert data["settings"]["scene"] == "sibenik"
    assert data["stats"]["rays_per_depth"] == {"0": 48}
    image = output.read_exr(exr)
    assert image.shape == (6, 8, 3) and np.isfinite(image).all() and (image >= 0).all()
    assert image.any()


def test_render_overwrites_an_existing_output(tmp_path, capsys):
    """A successful render replaces existing outputs and leaves no temporary files."""
    exr = tmp_path / "x.exr"
    exr.write_bytes(b"old")
    (tmp_path / "x.png").write_bytes(b"old")
    code, _, _ = run(capsys, "render", "plane", *TINY, "-o", exr)
    assert code == 0
    assert output.read_exr(exr).shape == (6, 8, 3)
    assert output.read_png(tmp_path / "x.png").shape == (6, 8, 3)
    assert sorted(os.listdir(tmp_path)) == ["x.exr", "x.png"]


# --------------------------------------------------------------------------
# user errors: exit 2, one line, nothing written
# --------------------------------------------------------------------------

def _prepare(case, tmp_path):
    """(argv scene + options, expected message fragments) for each bad input."""
    inputs = tmp_path / "in"
    inputs.mkdir()
    if case == "missing-scene-file":
        return [inputs / "nope.toml"], ["nope.toml"]
    if case == "unknown-scene":
        return ["sibenikk"], ["sibenikk", "sibenik", "plane"]
    if case == "truncated-ply":
        data = (importlib.resources.files("raysort.scenes") / "sibenik.ply").read_bytes()
        (inputs / "half.ply").write_bytes(data[:len(data) // 2])
        return [inputs / "half.ply"], ["half.ply"]
    if case == "no-faces":
        (inputs / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
        return [inputs / "points.obj"], ["points.obj"]
    if case == "nan-vertices":
        (inputs / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
        return [inputs / "nan.obj"], ["nan.obj", "not finite"]
    if case == "unknown-sorter":
        return ["plane", "--sorter", "bogus"], ["bogus", "nah", "nah_numpy", "none"]
    if case == "unknown-traversal":
        return ["plane", "--traversal", "singel"], ["singel", "masked", "partition"]
    if case == "unread-parameter":
        return ["plane", "--sorter", "none:bogus=1"], ["'none'", "'bogus'", "packet_size"]
    if case == "bad-spec":
        return ["plane", "--sorter", "none:packet_size"], ["packet_size", "key=value"]
    if case == "bad-parameter-value":
        return ["plane", "--sorter", "none:packet_size=0"], ["packet_size"]
    if case == "bad-scene-key":
        (inputs / "s.toml").write_text('bogus = 1\n[mesh]\nprocedural = "plane"\n')
        return [inputs / "s.toml"], ["s.toml", "bogus"]
    if case == "bad-scene-value":
        (inputs / "s.toml").write_text('[mesh]\nprocedural = ["plane"]\n')
        return [inputs / "s.toml"], ["s.toml", "procedural"]
    if case == "truncated-ply-header":
        (inputs / "head.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement "
                                          b"vertex 3\nproperty fl")
        return [inputs / "head.ply"], ["head.ply", "not a readable mesh"]
    if case == "garbage-obj":
        (inputs / "junk.obj").write_bytes(bytes(range(256)) * 8)
        return [inputs / "junk.obj"], ["junk.obj"]
    if case == "huge-camera":
        (inputs / "s.toml").write_text('[mesh]\nprocedural = "plane"\n[camera]\n'
                                       'eye = [1e39, 0, -5]\nlook_at = [0, 0, 0]\n')
        return [inputs / "s.toml"], ["s.toml", "camera eye", "float32"]
    if case == "empty-spec-item":
        return ["plane", "--sorter", "nah:threshold=0.5,,max_cells=2"], ["empty item"]
    if case == "tile-too-big":
        return ["plane", "--tile", "65"], ["tile"]
    if case == "depth-too-big":
        return ["plane", "--depth", "100000"], ["max_depth"]
    if case == "bad-camera":
        (inputs / "s.toml").write_text('[mesh]\nprocedural = "plane"\n'
                                       '[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, 0]\n')
        return [inputs / "s.toml"], ["s.toml", "look_at"]
    raise AssertionError(case)


SCENE_AND_PLUGIN_ERRORS = ["missing-scene-file", "unknown-scene", "truncated-ply", "no-faces",
                           "nan-vertices", "unknown-sorter", "unknown-traversal",
                           "unread-parameter", "bad-spec", "bad-parameter-value",
                           "bad-scene-key", "bad-scene-value", "bad-camera",
                           "truncated-ply-header", "garbage-obj", "huge-camera",
                           "empty-spec-item", "tile-too-big", "depth-too-big"]


@pytest.mark.parametrize("case", SCENE_AND_PLUGIN_ERRORS)
def test_bad_input_is_one_line_and_writes_nothing(case, tmp_path, capsys):
    """Each bad scene or plugin choice: exit 2, one 'raysort: error:' line naming the
    problem, nothing on stdout, and no .exr, .png, .json or temporary file."""
    args, fragments = _prepare(case, tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code, out, err = run(capsys, "render", *args, *TINY, "-o", out_dir / "x.exr",
                         "--json", out_dir / "x.json")
    assert code == 2
    assert_one_line_error(err, *fragments)
    assert out == ""
    assert os.listdir(out_dir) == []


@pytest.mark.parametrize("case", ["under-a-file", "png-suffix", "no-suffix", "is-a-directory",
                                  "json-under-a-file"])
def test_bad_output_path_is_one_line_and_writes_nothing(case, tmp_path, capsys):
    """Each unusable output path: exit 2, one error line naming it, nothing created
    (no directory, no image, no temporary file)."""
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / "afile").write_bytes(b"keep")
    (out_dir / "dir.exr").mkdir()            # a directory whose name ends in .exr
    extra = []
    target = {"under-a-file": out_dir / "afile" / "x.exr",
              "png-suffix": out_dir / "x.png",
              "no-suffix": out_dir / "x",
              "is-a-directory": out_dir / "dir.exr",
              "json-under-a-file": out_dir / "x.exr"}[case]
    if case == "json-under-a-file":
        extra = ["--json", out_dir / "afile" / "sub" / "x.json"]
    before = sorted(os.listdir(out_dir))
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", target, *extra)
    assert code == 2
    name = "afile" if case.startswith("json") else os.path.basename(target)
    assert_one_line_error(err, name)
    assert out == ""
    assert sorted(os.listdir(out_dir)) == before
    assert (out_dir / "afile").read_bytes() == b"keep"


def test_failed_render_leaves_existing_outputs_untouched(tmp_path, capsys):
    """When a render fails before writing, existing .exr/.png files keep their bytes
    and modification times."""
    exr, png = tmp_path / "x.exr", tmp_path / "x.png"
    exr.write_bytes(b"precious exr")
    png.write_bytes(b"precious png")
    os.utime(exr, ns=(1_000_000_000, 1_000_000_000))
    os.utime(png, ns=(1_000_000_000, 1_000_000_000))
    for bad in (["plane", "--sorter", "bogus"], ["nosuchscene"],
                ["plane", "--sorter", "none:bogus=1"]):
        code, _, err = run(capsys, "render", *bad, *TINY, "-o", exr)
        assert code == 2 and err.startswith("raysort: error:")
        assert exr.read_bytes() == b"precious exr" and png.read_bytes() == b"precious png"
        assert exr.stat().st_mtime_ns == png.stat().st_mtime_ns == 1_000_000_000
    assert sorted(os.listdir(tmp_path)) == ["x.exr", "x.png"]


@pytest.mark.parametrize("argv, option", [
    (["render", "--size", "garbage"], "--size"),
    (["render", "--size", "0x10"], "--size"),
    (["render", "--size", "10x"], "--size"),
    (["render", "--spp", "0"], "--spp"),
    (["render", "--spp", "two"], "--spp"),
    (["render", "--depth", "-1"], "--depth"),
    (["render", "--threads", "0"], "--threads"),
    (["render", "--shadow-rays", "maybe"], "--shadow-rays"),
    (["render", "--exposure", "nan"], "--exposure"),
    (["render", "--exposure", "inf"], "--exposure"),
    (["render", "--exposure", "5000"], "--exposure"),
    (["render", "--exposure", "bright"], "--exposure"),
    (["render", "--seed", "4294967296"], "--seed"),
    (["render", "--seed", str(10**23)], "--seed"),
    (["render", "--seed", "-1"], "--seed"),
    (["frobnicate"], "frobnicate"),
    ([], "command"),
])
def test_argument_errors_exit_2(argv, option, tmp_path, capsys, monkeypatch):
    """Malformed options: exit status 2 and one 'raysort: error:' line naming the option,
    before anything is rendered or written."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert_one_line_error(capsys.readouterr().err, option, "--help")
    assert os.listdir(tmp_path) == []


def test_plugin_booleans_as_the_readme_writes_them(tmp_path, capsys):
    """true/false/none in a plugin spec are booleans and None, as in the README."""
    code, _, err = run(capsys, "render", "plane", *TINY, "-o", tmp_path / "x.exr", "--shader",
                       "lambert:russian_roulette=true,shadow_rays=none", "--generator",
                       "pinhole:jitter=false")
    assert code == 0, err


@pytest.mark.parametrize("seed", ["0", "4294967295"])
def test_seed_range_ends_are_accepted(seed, tmp_path, capsys):
    code, _, err = run(capsys, "render", "plane", *TINY, "--seed", seed, "-o", tmp_path / "x.exr")
    assert code == 0, err


@pytest.mark.parametrize("json_name", ["x.exr", "x.png", "./sub/../x.exr"])
def test_json_may_not_overwrite_the_image(json_name, tmp_path, capsys, monkeypatch):
    """--json naming the EXR or its PNG preview is an error up front, nothing written."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", "x.exr", "--json", json_name)
    assert code == 2
    assert_one_line_error(err, "--json", json_name)
    assert out == "" and os.listdir(tmp_path) == ["sub"]


@pytest.mark.parametrize("argv, fragment", [
    (["--json", "foo/"], "names a directory"),             # foo does not exist yet
    (["--json", "a/b/"], "names a directory"),
    (["--json", ""], "the path is empty"),
    (["-o", "newdir/.exr"], "must be an .exr file"),       # '.exr' is a name, not a suffix
    (["-o", "x.exr", "--json", "scene.toml"], "is the scene file"),
])
def test_bad_output_paths_fail_before_the_render(argv, fragment, tmp_path, capsys,
                                                 monkeypatch):
    """Outputs that cannot be written as asked fail up front in one line, exit 2, and
    nothing is written or created (the scene file is not overwritten)."""
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "scene.toml"
    scene.write_text('[mesh]\nprocedural = "plane"\n')
    code, out, err = run(capsys, "render", "scene.toml", *TINY, *argv)
    assert code == 2
    assert_one_line_error(err, fragment)
    assert out == "" and os.listdir(tmp_path) == ["scene.toml"]
    assert scene.read_text() == '[mesh]\nprocedural = "plane"\n'


@pytest.mark.skipif(not os.path.exists("/dev/null"), reason="needs /dev/null")
def test_json_to_a_device_writes_through_it(tmp_path, capsys):
    """--json /dev/null writes into the device (as a shell's > does) instead of
    replacing the device node with a file."""
    before = os.stat("/dev/null")
    code, _, err = run(capsys, "render", "plane", *TINY, "-o", tmp_path / "x.exr",
                       "--json", "/dev/null")
    assert code == 0, err
    after = os.stat("/dev/null")
    assert (after.st_mode, after.st_rdev) == (before.st_mode, before.st_rdev)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_json_that_cannot_be_written_leaves_no_image(tmp_path, capsys):
    """--json /dev/full (every write fails: no space): one error line, exit 2, and the
    image and preview are not written either."""
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", tmp_path / "x.exr",
                         "--json", "/dev/full")
    assert code == 2 and out == ""
    assert_one_line_error(err, "/dev/full", "No space left on device")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("fail", ["json", "png"])
def test_a_failed_write_leaves_no_file_and_no_new_directory(fail, tmp_path, capsys,
                                                              monkeypatch):
    """The image, its preview and --json are written all or none: when one of them
    cannot be written (the disk fills), none is left, nor the directories made for them,
    and a directory that was there stays."""
    real_text, real_picture = output._write_text, output._write_picture

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output, "_write_text", full if fail == "json" else real_text)
    monkeypatch.setattr(output, "_write_picture", full if fail == "png" else real_picture)
    (tmp_path / "kept").mkdir()
    exr = tmp_path / "kept" / "new" / "x.exr"
    js = tmp_path / "meta" / "deeper" / "x.json"
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", exr, "--json", js)
    assert code == 2 and out == ""
    assert_one_line_error(err, "No space left on device")
    assert sorted(os.listdir(tmp_path)) == ["kept"] and os.listdir(tmp_path / "kept") == []


def test_json_through_a_symbolic_link_keeps_the_link(tmp_path, capsys):
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "real.json")
    code, _, err = run(capsys, "render", "plane", *TINY, "-o", tmp_path / "x.exr",
                       "--json", link)
    assert code == 0, err
    assert link.is_symlink() and json.loads((tmp_path / "real.json").read_text())["stats"]


@pytest.mark.skipif(sys.platform == "win32" or sys.platform == "darwin",
                    reason="needs a file system that takes names that are not UTF-8")
def test_names_that_are_not_utf8_render(tmp_path, capsys):
    """A mesh and an output whose names are not UTF-8 (POSIX allows any bytes): the
    render is written, the scene's name printable."""
    mesh = os.path.join(os.fsencode(tmp_path), b"\xff\xfe.obj")
    with open(mesh, "wb") as fh:
        fh.write(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    exr = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"\xffout.exr"))
    code, _, err = run(capsys, "render", os.fsdecode(mesh), *TINY, "-o", exr)
    assert code == 0, err
    assert output.read_png(exr[:-4] + ".png").shape == (6, 8, 3)
    assert raysort.load_scene(os.fsdecode(mesh)).name == "\\xff\\xfe"


# --------------------------------------------------------------------------
# listings
# --------------------------------------------------------------------------

def test_plugins_lists_every_builtin(capsys):
    """`raysort plugins` lists each built-in with distribution raysort, status ok,
    and ends with the ISA line (the active ISA and every compiled one)."""
    raysort.refresh()
    code, out, err = run(capsys, "plugins")
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].split() == ["kind", "name", "distribution", "version", "status"]
    rows = {(cols[0], cols[1]): cols for cols in (line.split() for line in lines[1:]) if cols
            and cols[0] in {"generators", "sorters", "traversals", "shaders"}}
    assert BUILTINS <= set(rows)
    for key in BUILTINS:
        assert rows[key][2] == "raysort" and rows[key][4] == "ok", rows[key]
    from raysort import isa
    line = [line for line in lines if line.startswith("ISA:")]
    assert len(line) == 1 and f"active {isa.active()};" in line[0]
    assert f"compiled {', '.join(isa.compiled())};" in line[0]


def test_scenes_lists_packaged_scenes(capsys):
    """`raysort scenes` prints a header, then each packaged scene's name, triangle count
    (the loaded scene's) and a one-line description."""
    code, out, err = run(capsys, "scenes")
    assert code == 0 and err == ""
    header, *lines = out.splitlines()
    assert header.split() == ["name", "triangles", "description"]
    assert [line.split()[0] for line in lines] == raysort.scene_names()
    assert {"sibenik", "sponza", "plane", "furnace", "cornell", "forest"} <= set(
        raysort.scene_names())
    for line in lines:
        name, count, *description = line.split()
        assert int(count.replace(",", "")) == raysort.load_scene(name).n_triangles
        assert description, line


def test_threads_default_to_the_usable_cores(capsys, tmp_path):
    """--threads defaults to the cores this process may use (its affinity mask)."""
    from raysort.cli import build_parser

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert build_parser().parse_args(["render"]).threads == cores
    code, _, _ = run(capsys, "render", "plane", *TINY, "-o", tmp_path / "x.exr",
                     "--json", tmp_path / "x.json")
    assert code == 0
    assert json.loads((tmp_path / "x.json").read_text())["stats"]["threads"] == cores


def test_missing_output_directories_are_created_and_reported(tmp_path, capsys):
    """`-o out/deeper/x.exr` creates out/deeper after the render and says so; the --json
    directory too.  A render that fails creates nothing."""
    exr = tmp_path / "out" / "deeper" / "x.exr"
    js = tmp_path / "meta" / "x.json"
    code, _, err = run(capsys, "render", "nosuchscene", *TINY, "-o", exr, "--json", js)
    assert code == 2 and os.listdir(tmp_path) == []
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", exr, "--json", js)
    assert code == 0 and err == ""
    assert sorted(os.listdir(exr.parent)) == ["x.exr", "x.png"] and js.is_file()
    assert f"(created directory {tmp_path / 'out'})" in out
    assert f"(created directory {tmp_path / 'meta'})" in out
    code, out, _ = run(capsys, "render", "plane", *TINY, "-o", exr)
    assert code == 0 and "created directory" not in out


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_unwritable_target_fails_before_rendering(capsys, monkeypatch):
    """/proc looks writable to root but takes no files: the error comes before the render."""
    def no_render(*args, **kwargs):
        raise AssertionError("rendered before finding the output unwritable")

    monkeypatch.setattr(raysort.Pipeline, "render", no_render)
    code, out, err = run(capsys, "render", "plane", *TINY, "-o", "/proc/out.exr")
    assert code == 2 and out == ""
    assert_one_line_error(err, "/proc/out.exr", "cannot create a file in '/proc'")


class _DepthOnly(raysort.Shader):
    """A shader declaring `max_depth` but not `shadow_rays`, to test the shorthands."""

    def __init__(self, *, max_depth=1):
        self.max_depth = max_depth

    def shade(self, scene, rays, hits, paths, depth, seed, radiance):
        return None


def test_depth_shorthand_sets_max_depth_of_any_shader_declaring_it(monkeypatch):
    from raysort.cli import _shader_config, build_parser

    raysort.register("shaders", "depth_only", _DepthOnly)
    try:
        args = build_parser().parse_args(["render", "--shader", "depth_only", "--depth", "3"])
        assert _shader_config(args) == {"type": "depth_only", "max_depth": 3}
        args = build_parser().parse_args(["render", "--shader", "depth_only",
                                          "--shadow-rays", "off"])
        with pytest.raises(raysort.ConfigError, match="--shadow-rays sets the shader "
                                                      "parameter 'shadow_rays'.*depth_only"):
            _shader_config(args)
    finally:
        raysort.unregister("shaders", "depth_only")


@pytest.mark.parametrize("flag", [["--depth", "2"], ["--shadow-rays", "on"]])
def test_shorthand_for_a_shader_without_the_parameter_is_one_line(tmp_path, capsys, flag):
    code, out, err = run(capsys, "render", "plane", *TINY, "--shader", "ao", *flag,
                         "-o", tmp_path / "x.exr")
    assert code == 2 and out == ""
    assert err.startswith(f"raysort: error: {flag[0]} sets the shader parameter")
    assert "'ao' does not declare" in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []
