"""Scenes: packaged scenes, scene files (TOML), mesh files, and the errors for bad ones.

The packaged PLY files are parsed here independently (NumPy on the raw bytes)
to check what the loader makes of them.
"""
import importlib.resources
import math

import numpy as np
import pytest

import raysort
from raysort import Camera, Scene
from raysort.errors import SceneError
from raysort.reference import brute_force

PACKAGED = {"cornell", "forest", "furnace", "plane", "sibenik", "sponza"}
SIBENIK_EMITTERS = {(0, 0, 0): (3.0, 2.8, 2.4), (112, 27, 13): (3.0, 0.8, 0.4)}


def packaged_file(name):
    return importlib.resources.files("raysort.scenes") / name


def read_binary_ply(data):
    """(vertices float32 (n,3), faces int32 (m,3), colours uint8 (m,3) or None) of a
    binary little-endian PLY laid out as scenes/README.md describes."""
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert "format binary_little_endian 1.0" in header
    counts = {line.split()[1]: int(line.split()[2]) for line in header
              if line.startswith("element")}
    coloured = "property uchar red" in header
    nv, nf = counts["vertex"], counts["face"]
    vertices = np.frombuffer(data, "<f4", count=nv * 3, offset=end).reshape(nv, 3)
    fields = [("n", "u1"), ("idx", "<i4", (3,))] + ([("rgb", "u1", (3,))] if coloured else [])
    faces = np.frombuffer(data, np.dtype(fields), count=nf, offset=end + nv * 12)
    assert (faces["n"] == 3).all()
    assert end + nv * 12 + nf * faces.dtype.itemsize == len(data)
    return vertices, faces["idx"].astype(np.int32), (faces["rgb"] if coloured else None)


@pytest.fixture(scope="module")
def sibenik_ply():
    return read_binary_ply(packaged_file("sibenik.ply").read_bytes())


@pytest.fixture(scope="module")
def sponza_ply():
    return read_binary_ply(packaged_file("dabrovic_sponza.ply").read_bytes())


def zero_area_faces(vertices, faces):
    """Indices of degenerate faces by the documented rule: the sine of the angle at the
    first vertex is at most 2**-20, computed here with the float64 law of sines."""
    v = vertices.astype(np.float64)[faces]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    n1, n2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sine = np.where(n1 * n2 > 0, area2 / (n1 * n2), 0.0)
    return np.flatnonzero(sine <= 2.0 ** -20)


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def write_obj(path, vertices, faces):
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


TRIANGLE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


# --------------------------------------------------------------------------
# packaged scenes
# --------------------------------------------------------------------------

def test_scene_names():
    """The six packaged scenes are listed, sorted."""
    assert raysort.scene_names() == sorted(PACKAGED)


@pytest.mark.parametrize("name", sorted(PACKAGED))
def test_every_packaged_scene_loads(name):
    """Each packaged scene loads into a consistent Scene whose camera sees into the scene."""
    scene = raysort.load_scene(name)
    m = scene.n_triangles
    assert m > 0 and scene.name == name
    assert scene.vertices.dtype == np.float32 and scene.vertices.shape[1] == 3
    assert scene.faces.dtype == np.int32 and scene.faces.shape == (m, 3)
    assert scene.faces.min() >= 0 and scene.faces.max() < len(scene.vertices)
    assert scene.albedo.shape == scene.emission.shape == (m, 3)
    assert ((scene.albedo >= 0) & (scene.albedo <= 1)).all()
    assert (scene.emission >= 0).all() and np.isfinite(scene.vertices).all()
    assert scene.sky.shape == (3,) and (scene.sky >= 0).all()
    assert isinstance(scene.camera, Camera)
    lo, hi = scene.bounds
    assert (lo <= hi).all()
    # the camera looks towards the scene box: look_at is inside it (slightly padded)
    pad = 1e-3 * (hi - lo).max()
    assert (np.asarray(scene.camera.look_at) >= lo - pad).all()
    assert (np.asarray(scene.camera.look_at) <= hi + pad).all()
    # something emits light: an emitter, the sky or a point light
    assert scene.emission.any() or scene.sky.any() or scene.lights


def test_default_scene_is_sibenik():
    """load_scene() with no argument loads the Sibenik nave."""
    scene = raysort.load_scene()
    assert scene.name == "sibenik" and scene.n_triangles == 75_284


@pytest.mark.parametrize("name, ply, triangles, vertices", [
    ("sibenik", "sibenik_ply", 75_284, 40_981),
    ("sponza", "sponza_ply", 66_454, 39_999),
])
def test_real_meshes_load_exactly_as_stored(name, ply, triangles, vertices, request):
    """The real meshes keep every vertex and face exactly as in the file (process=False)."""
    scene = request.getfixturevalue(name)
    v, f, _ = request.getfixturevalue(ply)
    assert scene.n_triangles == len(f) == triangles
    assert len(scene.vertices) == len(v) == vertices
    np.testing.assert_array_equal(scene.vertices, v)
    np.testing.assert_array_equal(scene.faces, f)


def test_sibenik_face_colours_become_albedo(sibenik, sibenik_ply):
    """Sibenik's per-face RGB (0..255) becomes the albedo, divided by 255."""
    _, _, rgb = sibenik_ply
    np.testing.assert_allclose(sibenik.albedo, rgb / 255.0, rtol=0, atol=1e-7)
    # the stone colour from the README is the most common one
    colours, counts = np.unique(rgb, axis=0, return_counts=True)
    assert tuple(colours[counts.argmax()]) == (187, 186, 172)


def test_sibenik_emitters_select_faces_by_colour(sibenik, sibenik_ply):
    """[[emitter]] face_color picks exactly the faces of that colour; the others emit nothing."""
    _, _, rgb = sibenik_ply
    expected = np.zeros((len(rgb), 3))
    for colour, radiance in SIBENIK_EMITTERS.items():
        match = (rgb == colour).all(axis=1)
        assert match.sum() > 0, colour
        expected[match] = radiance
    np.testing.assert_allclose(sibenik.emission, expected, rtol=1e-7)
    assert len(sibenik.lights) == 1 and not sibenik.sky.any()


def test_sponza_uses_the_material_albedo(sponza):
    """Sponza has no face colours: every face gets [material] albedo, and nothing emits."""
    np.testing.assert_allclose(sponza.albedo, np.broadcast_to([0.75, 0.72, 0.65], (66_454, 3)),
                               rtol=1e-7)
    assert not sponza.emission.any()
    np.testing.assert_allclose(sponza.sky, [1.6, 1.8, 2.2], rtol=1e-7)


@pytest.mark.parametrize("name, ply, at_most", [("sibenik", "sibenik_ply", 13),
                                                ("sponza", "sponza_ply", 1)])
def test_degenerate_faces_are_kept_and_reported(name, ply, at_most, request):
    """Degenerate faces stay in the mesh; degenerate_faces() returns exactly the faces
    below float32 precision (scenes/README.md: Sibenik has 13 zero or near-zero area
    faces, Sponza 1)."""
    scene = request.getfixturevalue(name)
    v, f, _ = request.getfixturevalue(ply)
    expected = zero_area_faces(v, f)
    assert 0 < len(expected) <= at_most
    np.testing.assert_array_equal(scene.degenerate_faces(), expected)


def test_degenerate_triangles_in_a_small_mesh(tmp_path):
    """A collinear and a repeated-vertex triangle load and are the ones reported."""
    path = write_obj(tmp_path / "deg.obj",
                     [(0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0)],
                     [(0, 1, 2), (0, 1, 3), (0, 0, 2), (2, 1, 0)])
    scene = raysort.load_scene(path)
    assert scene.n_triangles == 4
    np.testing.assert_array_equal(scene.degenerate_faces(), [1, 2])
    assert scene.bvh().triangles.shape[0] == 4


# --------------------------------------------------------------------------
# scene files
# --------------------------------------------------------------------------

def test_minimal_scene_file(tmp_path):
    """The smallest valid scene file: one procedural mesh; defaults fill in the rest."""
    path = write(tmp_path, '[mesh]\nprocedural = "plane"\n', "tiny.toml")
    scene = raysort.load_scene(path)
    assert scene.name == "tiny" and scene.source == str(path)
    assert scene.n_triangles == 2
    assert not scene.sky.any() and scene.lights == []
    np.testing.assert_allclose(scene.albedo, 0.5)      # the plane generator's albedo


def test_full_scene_file(tmp_path):
    """Every documented key is read: name, mesh file, camera, material, sky, light."""
    write_obj(tmp_path / "tri.obj", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)])
    path = write(tmp_path, """
        name = "custom"
        description = "a triangle"
        credits = "nobody"
        [mesh]
        file = "tri.obj"
        [camera]
        eye = [0.2, 0.3, -2]
        look_at = [0.2, 0.3, 0]
        up = [0, 1, 0]
        vfov = 45
        [material]
        albedo = [0.1, 0.2, 0.3]
        [sky]
        radiance = [0.5, 0.25, 1]
        [[light]]
        position = [0, 2, -1]
        intensity = [3, 4, 5]
        [[light]]
        position = [1, 2, -1]
        intensity = [1, 1, 1]
    """.replace("\n        ", "\n"))
    scene = raysort.load_scene(path)
    assert scene.name == "custom"
    assert scene.camera == Camera((0.2, 0.3, -2), (0.2, 0.3, 0), (0, 1, 0), 45)
    np.testing.assert_allclose(scene.albedo, [[0.1, 0.2, 0.3]], rtol=1e-7)
    np.testing.assert_allclose(scene.sky, [0.5, 0.25, 1])
    assert [tuple(map(float, light.position)) for light in scene.lights] == [(0, 2, -1), (1, 2, -1)]
    assert tuple(map(float, scene.lights[0].intensity)) == (3, 4, 5)


def test_mesh_file_is_relative_to_the_scene_file(tmp_path, monkeypatch):
    """mesh.file is resolved next to the scene file, not the working directory."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "tri.obj").write_text(TRIANGLE_OBJ)
    path = write(tmp_path / "sub", '[mesh]\nfile = "tri.obj"\n')
    monkeypatch.chdir(tmp_path)
    assert raysort.load_scene(path).n_triangles == 1
    assert raysort.load_scene("sub/scene.toml").n_triangles == 1


def test_face_colors_false_ignores_colours(tmp_path):
    """mesh.face_colors = false uses [material] albedo even if the mesh has colours."""
    (tmp_path / "m.ply").write_bytes(packaged_file("sibenik.ply").read_bytes())
    path = write(tmp_path, '[mesh]\nfile = "m.ply"\nface_colors = false\n'
                           '[material]\nalbedo = [0.2, 0.2, 0.2]\n')
    np.testing.assert_allclose(raysort.load_scene(path).albedo, 0.2, rtol=1e-7)


BASE = '[mesh]\nprocedural = "plane"\n'
CAMERA = '[camera]\neye = [0, 1, -3]\nlook_at = [0, 0, 0]\n'


@pytest.mark.parametrize("text, key", [
    ("bogus = 1\n" + BASE, "bogus"),
    (BASE + CAMERA + "focal = 3\n", "camera.focal"),
    (BASE + "scale = 2\n", "mesh.scale"),
    (BASE + "[material]\nkd = [1, 1, 1]\n", "material.kd"),
    (BASE + "[sky]\ncolor = [1, 1, 1]\n", "sky.color"),
    (BASE + "[[light]]\nposition = [0, 1, 0]\npower = 3\n", "light.power"),
    (BASE + "[[emitter]]\nface_colour = [0, 0, 0]\n", "emitter.face_colour"),
    ("camera = 3\n" + BASE, "camera"),
    ("mesh = 'plane'\n", "mesh"),
], ids=["top", "camera", "mesh", "material", "sky", "light", "emitter", "camera-not-table",
        "mesh-not-table"])
def test_unknown_or_misplaced_keys(tmp_path, text, key):
    """An unknown key (or a non-table section) is a SceneError naming the file and the key."""
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    assert str(path) in str(info.value) and key in str(info.value)


@pytest.mark.parametrize("text", [
    '[mesh]\nprocedural = "plane"\nfile = "x.obj"\n',
    '[mesh]\nparams = {albedo = 0.5}\n',
    '[mesh]\n',
    'name = "no mesh"\n',
], ids=["both", "neither", "empty", "missing"])
def test_mesh_needs_exactly_one_source(tmp_path, text):
    """[mesh] must have exactly one of file / procedural."""
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    msg = str(info.value)
    assert str(path) in msg and "'file'" in msg and "'procedural'" in msg


@pytest.mark.parametrize("camera, key", [
    ("vfov = 0", "vfov"),
    ("vfov = 180", "vfov"),
    ("vfov = -5", "vfov"),
    ('vfov = "wide"', "vfov"),
    ("vfov = nan", "vfov"),
    ("vfov = true", "vfov"),
    ("eye = [0, 0, 0]", "look_at"),
    ('eye = ["a", 0, 0]', "eye"),
    ("eye = [0, 1]", "eye"),
    ("eye = [0, inf, 0]", "eye"),
    ("look_at = 3", "look_at"),
    ("up = [0, 2, 0]\neye = [0, 5, 0]", "up"),
], ids=["vfov-0", "vfov-180", "vfov-negative", "vfov-string", "vfov-nan", "vfov-bool",
        "eye-is-look_at", "eye-string", "eye-2d", "eye-inf", "look_at-scalar", "up-parallel"])
def test_bad_camera_values(tmp_path, camera, key):
    """A bad camera value is a SceneError naming the file and the camera key."""
    table = dict(eye="[0, 1, -3]", look_at="[0, 0, 0]")
    for line in camera.splitlines():
        k, v = line.split(" = ")
        table[k] = v
    text = BASE + "[camera]\n" + "".join(f"{k} = {v}\n" for k, v in table.items())
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    assert str(path) in str(info.value) and key in str(info.value)


def test_camera_missing_look_at(tmp_path):
    """A camera without look_at is a SceneError naming look_at."""
    path = write(tmp_path, BASE + "[camera]\neye = [0, 1, -3]\n")
    with pytest.raises(SceneError, match="look_at") as info:
        raysort.load_scene(path)
    assert str(path) in str(info.value)


def test_emitter_needs_face_colours(tmp_path):
    """[[emitter]] on a mesh without face colours is an error, not a silent no-op."""
    (tmp_path / "tri.obj").write_text(TRIANGLE_OBJ)
    path = write(tmp_path, '[mesh]\nfile = "tri.obj"\n'
                           '[[emitter]]\nface_color = [0, 0, 0]\nradiance = [1, 1, 1]\n')
    with pytest.raises(SceneError, match="emitter") as info:
        raysort.load_scene(path)
    assert str(path) in str(info.value)


def test_emitter_colour_out_of_range_selects_nothing(tmp_path):
    """face_color [256, 0, 0] is not a colour of any face: it must not wrap around to
    (0, 0, 0) and light Sibenik's black windows (an error would be fine too)."""
    (tmp_path / "m.ply").write_bytes(packaged_file("sibenik.ply").read_bytes())
    path = write(tmp_path, '[mesh]\nfile = "m.ply"\n'
                           '[[emitter]]\nface_color = [256, 0, 0]\nradiance = [1, 1, 1]\n')
    try:
        scene = raysort.load_scene(path)
    except SceneError as exc:
        assert "face_color" in str(exc)
    else:
        assert not scene.emission.any()


@pytest.mark.parametrize("text, key", [
    ('[mesh]\nprocedural = "teapot"\n', "teapot"),
    ('[mesh]\nprocedural = "plane"\nparams = {albedo = 2.0}\n', "albedo"),
    ('[mesh]\nprocedural = "plane"\nparams = {colour = 0.5}\n', "colour"),
    ('[mesh]\nprocedural = "furnace"\nparams = {subdivisions = "many"}\n', "subdivisions"),
    ('[mesh]\nprocedural = "plane"\nparams = 3\n', "params"),
    ('[mesh]\nfile = "tri.obj"\nparams = {a = 1}\n', "params"),
    ('[mesh]\nprocedural = ["plane"]\n', "procedural"),
    ('[mesh]\nfile = 3\n', "file"),
], ids=["unknown", "bad-value", "unknown-param", "bad-type", "params-not-table",
        "params-with-file", "procedural-list", "file-int"])
def test_bad_mesh_section(tmp_path, text, key):
    """A bad [mesh] (unknown generator, bad params, wrong types) is a SceneError naming
    the file and the offending key or value."""
    (tmp_path / "tri.obj").write_text(TRIANGLE_OBJ)
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    assert str(path) in str(info.value) and key in str(info.value)


@pytest.mark.parametrize("text, key", [
    (BASE + "[sky]\nradiance = [nan, 1, 1]\n", "sky.radiance"),
    (BASE + "[sky]\nradiance = 1\n", "sky.radiance"),
    (BASE + "[[light]]\nintensity = [1, 1, 1]\n", "light.position"),
    (BASE + "[[light]]\nposition = [0, 1, 0]\nintensity = 'bright'\n", "light.intensity"),
    ('[mesh]\nfile = "tri.obj"\n[material]\nalbedo = [2, 1, 1]\n', "albedo"),
    ('[mesh]\nfile = "tri.obj"\n[material]\nalbedo = "red"\n', "material.albedo"),
])
def test_bad_values(tmp_path, text, key):
    """Bad sky, light and material values are SceneErrors naming the file and key."""
    (tmp_path / "tri.obj").write_text(TRIANGLE_OBJ)
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    assert str(path) in str(info.value) and key in str(info.value)


@pytest.mark.parametrize("content", [b"[mesh\n", b'name = "\xe9"\n', b"a = = 1\n"],
                         ids=["syntax", "latin1", "syntax2"])
def test_unreadable_scene_file(tmp_path, content):
    """A file that is not valid UTF-8 TOML is a SceneError naming the file."""
    path = tmp_path / "bad.toml"
    path.write_bytes(content)
    with pytest.raises(SceneError, match="bad.toml"):
        raysort.load_scene(path)


def test_a_scene_file_nested_too_deeply(tmp_path):
    """TOML nested thousands of levels deep is a SceneError, not a RecursionError."""
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(SceneError, match="deep.toml.*nested too deeply"):
        raysort.load_scene(path)


@pytest.mark.parametrize("suffix", [".ply", ".toml"])
def test_a_name_too_long_for_the_system(suffix):
    """A file name the operating system refuses (ENAMETOOLONG) is a SceneError."""
    with pytest.raises(SceneError, match="cannot be read"):
        raysort.load_scene("b" * 300 + suffix)


def test_missing_scene_file_and_unknown_name(tmp_path):
    """A missing .toml, or a bare name that is neither packaged nor a file, is a SceneError."""
    with pytest.raises(SceneError, match="missing.toml"):
        raysort.load_scene(tmp_path / "missing.toml")
    with pytest.raises(SceneError) as info:
        raysort.load_scene("sibenikk")
    assert "'sibenikk'" in str(info.value)
    for name in PACKAGED:
        assert name in str(info.value)
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(SceneError, match="dir.toml"):
        raysort.load_scene(tmp_path / "dir.toml")


# --------------------------------------------------------------------------
# bad meshes
# --------------------------------------------------------------------------

# bad mesh files written as (file name, contents); contents None: no file is written
_BAD_MESH_FILES = {
    "missing": ("missing.ply", None),
    "garbage": ("garbage.ply", b"this is not a mesh\n" * 20),
    "empty": ("empty.ply", b""),
    "no-faces": ("nofaces.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
    "nan": ("nan.obj", b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"),
    "index-out-of-range": ("oor.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
}


def _bad_mesh(tmp_path, kind):
    """Create a bad mesh of the given kind; returns its path."""
    if kind == "truncated":
        data = packaged_file("sibenik.ply").read_bytes()
        path = tmp_path / "truncated.ply"
        path.write_bytes(data[:len(data) // 2])
    elif kind == "directory":
        path = tmp_path / "folder.ply"
        path.mkdir()
    else:
        name, contents = _BAD_MESH_FILES[kind]
        path = tmp_path / name
        if contents is not None:
            path.write_bytes(contents)
    return path


BAD_MESHES = ["missing", "truncated", "garbage", "empty", "no-faces", "nan",
              "index-out-of-range", "directory"]


@pytest.mark.parametrize("kind", BAD_MESHES)
def test_bad_mesh_file(tmp_path, kind):
    """Loading a bad mesh file directly is a SceneError naming the file."""
    path = _bad_mesh(tmp_path, kind)
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    assert path.name in str(info.value)


@pytest.mark.parametrize("kind", BAD_MESHES)
def test_bad_mesh_referenced_by_scene_file(tmp_path, kind):
    """A scene file whose mesh is bad is a SceneError naming the mesh file."""
    mesh = _bad_mesh(tmp_path, kind)
    path = write(tmp_path, f'[mesh]\nfile = "{mesh.name}"\n')
    with pytest.raises(SceneError) as info:
        raysort.load_scene(path)
    assert mesh.name in str(info.value)


def test_nan_vertex_message_says_which(tmp_path):
    """The non-finite vertex error points at the first bad vertex."""
    with pytest.raises(SceneError, match="vertex 1"):
        raysort.load_scene(_bad_mesh(tmp_path, "nan"))


# --------------------------------------------------------------------------
# plain mesh files and Scene.from_mesh
# --------------------------------------------------------------------------

BOX = np.array([(x, y, z) for x in (9.0, 11.0) for y in (-4.0, -2.5) for z in (4.0, 7.0)])
BOX_FACES = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]


def project(camera, width, height, points):
    """(px, py, depth) of world points in the image of ``camera`` (pixels, row 0 on top)."""
    eye, fwd, right, up = (np.asarray(v, np.float64) for v in camera.frame(width, height))
    d = np.asarray(points, np.float64) - eye
    depth = d @ fwd
    sx = (d @ right) / depth / (right @ right)
    sy = (d @ up) / depth / (up @ up)
    return (sx + 1) * width / 2, (1 - sy) * height / 2, depth


def test_plain_mesh_is_framed_by_a_default_camera(tmp_path):
    """A bare OBJ gets a camera that sees it: its centre and all its corners project
    in front of the camera and inside a 4:3 image; albedo 0.7, sky 1, name = stem."""
    path = write_obj(tmp_path / "box.obj", BOX, BOX_FACES)
    scene = raysort.load_scene(path)
    assert scene.name == "box" and scene.n_triangles == 12
    np.testing.assert_array_equal(scene.vertices, BOX.astype(np.float32))
    w, h = 64, 48
    centre = (BOX.min(axis=0) + BOX.max(axis=0)) / 2
    px, py, depth = project(scene.camera, w, h, np.vstack([centre, BOX]))
    assert (depth > 0).all()
    assert (px > 0).all() and (px < w).all() and (py > 0).all() and (py < h).all()
    assert abs(px[0] - w / 2) < 1e-3 and abs(py[0] - h / 2) < 1e-3
    # and the centre pixel's primary ray hits the box (brute force)
    gen = raysort.create("generators", "pinhole:jitter=False")
    rays = gen.generate(scene.camera, np.array([(h // 2) * w + w // 2], np.int32),
                        np.array([0], np.int32), w, h, 1, 0)
    assert brute_force(scene.vertices, scene.faces, rays).prim[0] >= 0
    np.testing.assert_allclose(scene.albedo, 0.7, rtol=1e-7)
    np.testing.assert_allclose(scene.sky, 1.0)
    assert not scene.emission.any()


def test_mesh_colours_become_albedo(tmp_path):
    """Per-face colours of an ASCII PLY become albedo; vertex colours are averaged per face."""
    faces = tmp_path / "faces.ply"
    faces.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n"
                     "property float y\nproperty float z\nelement face 2\n"
                     "property list uchar int vertex_indices\nproperty uchar red\n"
                     "property uchar green\nproperty uchar blue\nend_header\n"
                     "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2 255 0 51\n3 1 3 2 10 20 30\n")
    scene = raysort.load_scene(faces)
    np.testing.assert_allclose(scene.albedo, np.array([[255, 0, 51], [10, 20, 30]]) / 255,
                               atol=1e-7)
    verts = tmp_path / "verts.ply"
    verts.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                     "property float y\nproperty float z\nproperty uchar red\n"
                     "property uchar green\nproperty uchar blue\nelement face 1\n"
                     "property list uchar int vertex_indices\nend_header\n"
                     "0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 200\n3 0 1 2\n")
    scene = raysort.load_scene(verts)
    np.testing.assert_allclose(scene.albedo, [[85 / 255, 85 / 255, 67 / 255]], atol=1e-7)


def test_quads_are_triangulated(tmp_path):
    """An OBJ quad becomes two triangles sharing its diagonal, with the same vertices."""
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    scene = raysort.load_scene(path)
    assert scene.n_triangles == 2 and len(scene.vertices) == 4
    v = scene.vertices.astype(np.float64)[scene.faces]
    area = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum() / 2
    assert area == pytest.approx(1.0)


def test_scene_from_mesh_defaults():
    """Scene.from_mesh converts to float32/int32, frames the mesh, broadcasts albedo
    and emission, and its bounds ignore unused vertices."""
    vertices = np.vstack([BOX, [[1e6, 1e6, 1e6]]])       # last vertex unused
    scene = Scene.from_mesh(vertices.tolist(), BOX_FACES)
    assert scene.vertices.dtype == np.float32 and scene.faces.dtype == np.int32
    assert scene.name == "mesh" and scene.n_triangles == 12
    np.testing.assert_allclose(scene.albedo, np.full((12, 3), 0.7), rtol=1e-7)
    assert scene.emission.shape == (12, 3) and not scene.emission.any()
    np.testing.assert_allclose(scene.sky, 1.0)
    np.testing.assert_array_equal(scene.bounds, [BOX.min(axis=0), BOX.max(axis=0)])
    px, py, depth = project(scene.camera, 40, 30, BOX)
    assert (depth > 0).all() and (px > 0).all() and (px < 40).all()
    assert (py > 0).all() and (py < 30).all()
    assert math.isclose(scene.camera.vfov, 60.0)


def test_scene_from_mesh_arguments():
    """Explicit camera, per-face albedo, emission, sky, lights and name are kept."""
    cam = Camera((0, 0, -5), (0, 0, 0))
    albedo = np.linspace(0, 1, 36).reshape(12, 3)
    light = raysort.scene.PointLight((0, 5, 0), (1, 1, 1))
    scene = Scene.from_mesh(BOX, BOX_FACES, camera=cam, albedo=albedo, emission=(1, 2, 3),
                            sky=(0, 0, 0), lights=[light], name="box")
    assert scene.camera is cam and scene.name == "box" and scene.lights == [light]
    np.testing.assert_allclose(scene.albedo, albedo, rtol=1e-7)
    np.testing.assert_allclose(scene.emission, np.broadcast_to([1, 2, 3], (12, 3)))
    assert not scene.sky.any()


@pytest.mark.parametrize("kwargs, match", [
    (dict(faces=[(0, 1, 99)]), "out of range"),
    (dict(faces=[(0, 1, -1)]), "out of range"),
    (dict(faces=np.zeros((0, 3), int)), "no triangle faces"),
    (dict(faces=[(0, 1, 2, 3)]), "no triangle faces"),
    (dict(vertices=BOX[:, :2]), "vertices"),
    (dict(vertices=np.where(BOX == 9.0, np.inf, BOX)), "not finite"),
    (dict(albedo=(1.5, 0, 0)), "albedo"),
    (dict(albedo=np.zeros((5, 3))), "albedo"),
    (dict(emission=(-1, 0, 0)), "emission"),
], ids=["index-high", "index-negative", "no-faces", "quads", "2d", "inf", "albedo-range",
        "albedo-shape", "emission-negative"])
def test_scene_from_mesh_rejects_bad_input(kwargs, match):
    """Bad arrays are SceneErrors saying what is wrong."""
    args = dict(vertices=BOX, faces=BOX_FACES, camera=Camera((0, 0, -5), (0, 0, 0)))
    args.update(kwargs)
    with pytest.raises(SceneError, match=match):
        Scene.from_mesh(**args)


def test_bvh_is_cached_per_parameters(sibenik):
    """scene.bvh() is built once per parameter set and covers the scene bounds."""
    scene = Scene.from_mesh(BOX, BOX_FACES)
    a = scene.bvh()
    assert scene.bvh() is a
    b = scene.bvh(max_leaf=2)
    assert b is not a and scene.bvh(max_leaf=2) is b
    np.testing.assert_array_equal(a.bounds, scene.bounds)
