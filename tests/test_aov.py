"""AOV layers (depth, normal, albedo, prim) from each pixel's first primary hit: checked
against brute-force hits of the same camera rays, written as named channels of the EXR,
read back by OpenEXR itself and by raysort's reader, the same for any shader or sorter."""
import numpy as np
import OpenEXR
import pytest

import raysort
from raysort import output
from raysort.aov import LAYERS, exr_channels, read_aov
from raysort.cli import main
from raysort.reference import brute_force

W, H, SPP, SEED = 40, 28, 2, 6
ALL = ["depth", "normal", "albedo", "prim"]


@pytest.fixture(scope="module")
def result(sibenik):
    return raysort.Pipeline(sibenik, threads=2).render(W, H, SPP, SEED, aov=ALL)


@pytest.fixture(scope="module")
def expected(sibenik):
    """The layers computed here from sample 0 of every pixel, traced by brute force."""
    gen = raysort.create("generators", "pinhole")
    rays = gen.generate(sibenik.camera, np.arange(W * H, dtype=np.int32),
                        np.zeros(1, np.int32), W, H, SPP, SEED)
    hits = brute_force(sibenik.vertices, sibenik.faces, rays)
    hit = hits.prim >= 0
    d = rays.directions.T.astype(np.float64)
    nrm = sibenik.face_normals()[np.maximum(hits.prim, 0)]
    nrm = np.where(((nrm * d).sum(axis=1) > 0)[:, None], -nrm, nrm)
    return {
        "depth": np.where(hit, hits.t * np.linalg.norm(d, axis=1), np.inf).reshape(H, W),
        "normal": np.where(hit[:, None], nrm, 0).reshape(H, W, 3),
        "albedo": np.where(hit[:, None], sibenik.albedo[np.maximum(hits.prim, 0)], 0
                           ).reshape(H, W, 3),
        "prim": hits.prim.reshape(H, W),
    }


def test_layers_are_the_first_samples_hits(result, expected):
    assert list(result.aov) == ALL
    assert result.aov["prim"].dtype == np.int32 and (result.aov["prim"] >= 0).mean() > 0.9
    np.testing.assert_array_equal(result.aov["prim"], expected["prim"])
    np.testing.assert_array_equal(result.aov["albedo"], expected["albedo"].astype(np.float32))
    np.testing.assert_array_equal(result.aov["normal"], expected["normal"].astype(np.float32))
    np.testing.assert_allclose(result.aov["depth"], expected["depth"], rtol=1e-6)
    for name in ("depth", "normal", "albedo"):
        assert result.aov[name].dtype == np.float32


def test_misses_have_the_documented_values():
    """A triangle in front of the camera: pixels beside it are inf / 0 / 0 / -1."""
    cam = raysort.Camera(eye=(0, 0, -3), look_at=(0, 0, 0))
    scene = raysort.Scene.from_mesh([(-1, -1, 0), (1, -1, 0), (0, 1, 0)], [(0, 1, 2)],
                                    camera=cam, albedo=(0.2, 0.4, 0.6))
    aov = raysort.Pipeline(scene).render(16, 16, 1, aov=ALL).aov
    miss, hit = aov["prim"] == -1, aov["prim"] == 0
    assert miss.any() and hit.any() and (miss | hit).all()
    assert np.isinf(aov["depth"][miss]).all() and (aov["depth"][hit] > 2.9).all()
    assert (aov["normal"][miss] == 0).all() and (aov["albedo"][miss] == 0).all()
    np.testing.assert_array_equal(aov["normal"][hit], np.tile([0, 0, -1], (hit.sum(), 1)))
    np.testing.assert_array_equal(aov["albedo"][hit],
                                  np.tile(np.float32([0.2, 0.4, 0.6]), (hit.sum(), 1)))


def test_same_layers_for_any_shader_sorter_and_traversal(sibenik, result):
    for kw in ({"shader": "ao:samples=2", "sorter": "none", "traversal": "single"},
               {"shader": "lambert:max_depth=0", "sorter": "nah", "traversal": "ranged"}):
        other = raysort.Pipeline(sibenik, **kw).render(W, H, SPP, SEED, aov=ALL).aov
        for name in ALL:
            assert np.array_equal(other[name], result.aov[name]), (kw, name)


def test_exr_has_named_channels_openexr_reads(result, tmp_path):
    """The EXR holds R, G, B and every AOV channel with its type; OpenEXR reads each
    channel back bit for bit, and raysort's readers return the same arrays."""
    path = tmp_path / "aov.exr"
    result.write(path)
    channels = OpenEXR.File(str(path), separate_channels=True).channels()
    names = [c for layer in ALL for c in LAYERS[layer]]
    assert sorted(channels) == sorted(["R", "G", "B"] + names)
    assert str(channels["prim"].type()).endswith("UINT")
    assert all(str(channels[c].type()).endswith("FLOAT") for c in names if c != "prim")
    written = exr_channels(result.aov)
    for name in names:
        assert np.array_equal(channels[name].pixels.view(np.uint32), written[name].view(
            np.uint32)), name
    back = read_aov(path)
    for name in ALL:
        assert np.array_equal(back[name].view(np.uint32), result.aov[name].view(np.uint32))
    assert np.array_equal(output.read_exr(path), result.image)
    assert output.read_png(path.with_suffix(".png")).shape == (H, W, 3)


def test_cli_aov_option(tmp_path, capsys):
    out = tmp_path / "plane.exr"
    code = main(["render", "plane", "--size", "12x8", "--spp", "1", "-q", "--aov",
                 "depth,prim", "-o", str(out)])
    assert code == 0
    assert "AOV layers: depth, prim" in capsys.readouterr().out
    back = read_aov(out)
    assert sorted(back) == ["depth", "prim"]
    assert (back["prim"] >= 0).all() and np.isfinite(back["depth"]).all()
    plain = tmp_path / "plain.exr"
    assert main(["render", "plane", "--size", "12x8", "--spp", "1", "-q", "-o",
                 str(plain)]) == 0
    assert read_aov(plain) == {}


@pytest.mark.parametrize("bad", ["depth,colour", "depth,depth", ""])
def test_cli_bad_aov_list_is_a_usage_error(tmp_path, capsys, bad):
    out = tmp_path / "x.exr"
    with pytest.raises(SystemExit) as info:
        main(["render", "plane", "--size", "4x4", "-q", "--aov", bad, "-o", str(out)])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "--aov" in err and "Traceback" not in err
    assert not out.exists()


def test_bad_names_in_the_api():
    with pytest.raises(raysort.ConfigError, match="unknown AOV 'z'; AOVs: depth, normal"):
        raysort.Pipeline("plane").render(4, 4, 1, aov=["z"])


def test_extra_exr_channels_are_checked(tmp_path):
    image = np.zeros((2, 3, 3), np.float32)
    for channels, message in (({"Z": np.zeros((3, 2), np.float32)}, "shape"),
                              ({"Z": np.zeros((2, 3), np.int64)}, "float32 .* or uint32"),
                              ({"R": np.zeros((2, 3), np.float32)}, "name")):
        with pytest.raises(ValueError, match=message):
            output.write_exr(tmp_path / "x.exr", image, channels=channels)
    assert not (tmp_path / "x.exr").exists()
