"""``raysort.mesh``: one validator per fact, whichever way a mesh comes in.

The same bad mesh must raise the same :class:`SceneError` (saying what is
wrong) from the BVH, ``Scene.from_mesh``, ``Scene(...)``, a procedural
``MeshData``, brute force and a mesh file; good meshes come back as
C-contiguous float32 vertices and int32 faces.
"""
import numpy as np
import pytest

import raysort
from raysort import procedural
from raysort.bvh import BVH, degenerate_faces, prepare_triangles
from raysort.camera import Camera
from raysort.errors import SceneError
from raysort.mesh import check_mesh, per_face
from raysort.scene import Scene

V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float64)
F = np.array([[0, 1, 2], [1, 3, 2]], np.int64)
CAMERA = Camera((0.5, 0.5, 2), (0.5, 0.5, 0))


def with_vertex(value):
    v = V.copy()
    v[1] = value
    return v, F


BAD = {
    "nan-vertex": (with_vertex([np.nan, 0, 0]), "not finite"),
    "inf-vertex": (with_vertex([0, -np.inf, 0]), "not finite"),
    "float32-overflow": (with_vertex([1e39, 0, 0]), "not finite in float32"),
    "index-too-large": ((V, [[0, 1, 4]]), "out of range 0..3"),
    "negative-index": ((V, [[0, -1, 2]]), "out of range"),
    "int32-wrap": ((V, np.array([[0, 1, 2**32 + 2]])), "out of range"),
    "no-faces": ((V, np.zeros((0, 3), int)), "no triangle faces"),
    "quads": ((V, [[0, 1, 3, 2]]), "no triangle faces"),
    "2d-vertices": ((V[:, :2], F), r"vertices have shape \(4, 2\)"),
    "fractional-index": ((V, [[0, 1, 2.5]]), "whole numbers"),
    "string-vertices": ((V.astype(str), F), "must be numbers"),
    "ragged-faces": ((V, [[0, 1, 2], [1, 2]]), "array of numbers|no triangle"),
}

PATHS = {
    "check_mesh": lambda v, f: check_mesh(v, f),
    "BVH": lambda v, f: BVH(v, f),
    "brute-force triangles": lambda v, f: prepare_triangles(v, f),
    "Scene.from_mesh": lambda v, f: Scene.from_mesh(v, f, camera=CAMERA),
    "Scene": lambda v, f: Scene(v, f, 0.5, 0.0, CAMERA),
    "MeshData": lambda v, f: procedural.MeshData(v, f),
}


@pytest.mark.parametrize("path", sorted(PATHS))
@pytest.mark.parametrize("case", sorted(BAD))
def test_the_same_bad_mesh_is_the_same_error_everywhere(case, path):
    (vertices, faces), match = BAD[case]
    with pytest.raises(SceneError, match=match):
        PATHS[path](vertices, faces)


@pytest.mark.parametrize("case", ["nan-vertex", "index-too-large", "no-faces"])
def test_a_bad_mesh_file_is_the_same_error(case, tmp_path):
    """Written as an OBJ file: the SceneError names the file."""
    (vertices, faces), match = BAD[case]
    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in np.asarray(faces)]
    path = tmp_path / "bad.obj"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SceneError, match="bad.obj") as info:
        raysort.load_scene(path)
    assert "faces" in str(info.value) or "not finite" in str(info.value) \
        or "not a readable mesh" in str(info.value)


def test_good_mesh_types():
    vertices, faces = check_mesh(V.tolist(), F.astype(np.uint16), "x")
    assert vertices.dtype == np.float32 and faces.dtype == np.int32
    assert vertices.flags.c_contiguous and faces.flags.c_contiguous
    assert np.array_equal(faces, F)


@pytest.mark.parametrize("value, ok", [
    (0.5, True), ((0.1, 0.2, 0.3), True), (np.full((2, 3), 0.4), True),
    (1.5, False), (-0.1, False), (np.nan, False), ((0.1, 0.2), False), (np.ones((3, 3)), False),
    ("red", False),
])
def test_per_face_values(value, ok):
    if ok:
        out = per_face("albedo", value, 2, 0.0, 1.0)
        assert out.shape == (2, 3) and out.dtype == np.float32
    else:
        with pytest.raises(SceneError, match="albedo"):
            per_face("albedo", value, 2, 0.0, 1.0)


def test_emission_must_fit_float32():
    with pytest.raises(SceneError, match="emission"):
        Scene(V, F, 0.5, 1e39, CAMERA)


def test_degenerate_faces_come_from_the_triangle_set_up():
    """Scene.degenerate_faces and bvh.degenerate_faces are the faces the triangle set-up
    flattens (zero edges), checked here against the rule written out in double."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, 1e-7, 0], [1, 1e-5, 0]],
                 np.float32)
    # a triangle, a line, a sliver with sine 1e-7 < 2^-20, a point, one with sine 1e-5
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 3, 4], [2, 2, 2], [0, 3, 5]], np.int32)
    e1 = v[f[:, 1]].astype(np.float64) - v[f[:, 0]]
    e2 = v[f[:, 2]].astype(np.float64) - v[f[:, 0]]
    cross = np.cross(e1, e2)
    rule = np.flatnonzero((cross ** 2).sum(1) <= 2.0**-40 * (e1 ** 2).sum(1) * (e2 ** 2).sum(1))
    assert rule.tolist() == [1, 2, 3]
    assert degenerate_faces(v, f).tolist() == rule.tolist()
    assert Scene(v, f, 0.5, 0.0, CAMERA).degenerate_faces().tolist() == rule.tolist()
