"""``raysort._normals.face_normals`` (behind :meth:`raysort.Scene.face_normals`): held bit for
bit to its NumPy statement on the packaged scenes and on random triangles with zero-area faces."""
import numpy as np
import pytest

import raysort
from raysort import _normals


def numpy_face_normals(vertices, faces):
    """``(v1 - v0) x (v2 - v0)`` in double, normalised (zero for a zero length), as float32."""
    v = vertices.astype(np.float64)[faces]
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.divide(nrm, length, out=np.zeros_like(nrm), where=length > 0)
    return np.ascontiguousarray(nrm, dtype=np.float32)


def random_mesh():
    """Random triangles over six orders of magnitude, with repeated and collinear vertices."""
    rng = np.random.default_rng(11)
    scale = 10.0 ** rng.integers(-3, 4, (400, 1))
    vertices = (rng.normal(0, 1, (400, 3)) * scale).astype(np.float32)
    vertices[10:20] = vertices[0]
    vertices[20:30] = vertices[1] + np.float32(3) * (vertices[1] - vertices[0])
    faces = rng.integers(0, 400, (5000, 3)).astype(np.int32)
    faces[:60, 2] = faces[:60, 0]
    faces[60:80] = [1, 0, 25]
    return vertices, faces


@pytest.mark.parametrize("name", ["sibenik", "sponza", "cornell", "forest", "furnace", "random"])
def test_face_normals_equal_the_numpy_statement_bit_for_bit(name):
    if name == "random":
        scene = raysort.Scene.from_mesh(*random_mesh())
    else:
        scene = raysort.load_scene(name)
    got = scene.face_normals()
    want = numpy_face_normals(scene.vertices, scene.faces)
    assert got.dtype == np.float32 and got.shape == (len(scene.faces), 3)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    if name == "random":
        assert (got[:60] == 0).all()                    # zero area: a zero normal


def test_face_normals_refuse_a_vertex_index_out_of_range():
    vertices, faces = random_mesh()
    faces[7, 2] = len(vertices)
    with pytest.raises(IndexError, match="face 7"):
        _normals.face_normals(vertices, faces, np.empty((len(faces), 3), np.float32))
    with pytest.raises(ValueError, match="expected"):
        _normals.face_normals(vertices, faces[:, :2].copy(), np.empty((len(faces), 3), np.float32))
