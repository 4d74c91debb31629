"""Tests of raysort.procedural: built-in procedural scenes."""
import dataclasses
import math

import numpy as np
import pytest

from raysort import procedural
from raysort.errors import SceneError


@pytest.fixture(scope="module")
def default_forest():
    return procedural.forest()


def scene(name, default_forest):
    return default_forest if name == "forest" else procedural.GENERATORS[name]()


def face_normals(mesh):
    v = mesh.vertices.astype(np.float64)[mesh.faces]
    return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])


def check_contract(mesh):
    assert isinstance(mesh, procedural.MeshData)
    v, f = mesh.vertices, mesh.faces
    assert v.dtype == np.float32 and v.ndim == 2 and v.shape[1] == 3
    assert f.dtype == np.int32 and f.ndim == 2 and f.shape[1] == 3
    assert v.flags.c_contiguous and f.flags.c_contiguous
    assert len(f) > 0
    assert np.isfinite(v).all()
    assert f.min() >= 0 and f.max() < len(v)
    assert mesh.n_faces == len(f) and mesh.n_vertices == len(v)
    # no degenerate triangles (a BVH does not want them)
    assert (np.linalg.norm(face_normals(mesh), axis=1) > 0).all()
    if mesh.albedo is not None:
        a = mesh.albedo
        assert a.dtype == np.float32 and a.shape == (len(f), 3) and a.flags.c_contiguous
        assert np.isfinite(a).all() and (a >= 0).all() and (a <= 1).all()
    if mesh.emission is not None:
        e = mesh.emission
        assert e.dtype == np.float32 and e.shape == (len(f), 3) and e.flags.c_contiguous
        assert np.isfinite(e).all() and (e >= 0).all()


def assert_same(a, b):
    for field in ("vertices", "faces", "albedo", "emission"):
        x, y = getattr(a, field), getattr(b, field)
        if x is None:
            assert y is None
        else:
            np.testing.assert_array_equal(x, y)


def edge_counts(faces):
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return counts


# --- registries -------------------------------------------------------------

def test_registries():
    assert set(procedural.GENERATORS) == {"forest", "furnace", "cornell", "plane"}
    assert set(procedural.CAMERAS) == set(procedural.GENERATORS)
    assert procedural.GENERATORS["furnace"] is procedural.furnace_sphere
    for camera in procedural.CAMERAS.values():
        assert set(camera) == {"eye", "look_at", "up", "vfov"}
        assert camera["up"] == (0.0, 1.0, 0.0)
        assert 0 < camera["vfov"] < 180
        assert np.linalg.norm(np.subtract(camera["look_at"], camera["eye"])) > 0
    assert procedural.FOREST_CAMERA["eye"] == (0.0, 1.7, -27.0)
    assert procedural.FOREST_CAMERA["look_at"] == (0.0, 2.5, 0.0)
    assert procedural.FURNACE_CAMERA == dict(eye=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, 1.0),
                                             up=(0.0, 1.0, 0.0), vfov=60.0)
    assert procedural.PLANE_CAMERA["eye"] == (0.0, 2.0, -2.0)
    assert procedural.PLANE_CAMERA["look_at"] == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("name", ["forest", "furnace", "cornell", "plane"])
def test_contract_and_determinism(name, default_forest):
    mesh = scene(name, default_forest)
    check_contract(mesh)
    assert mesh.albedo is not None
    assert_same(mesh, procedural.GENERATORS[name]())


def test_icosphere_contract():
    mesh = procedural.icosphere()
    check_contract(mesh)
    assert mesh.albedo is None and mesh.emission is None
    assert_same(mesh, procedural.icosphere())


def test_meshdata_is_frozen_and_checked():
    """A bad mesh is a SceneError, the same error every other way a mesh comes in."""
    mesh = procedural.plane_under_sky()
    with pytest.raises(dataclasses.FrozenInstanceError):
        mesh.faces = None
    with pytest.raises(SceneError, match="face indices"):
        procedural.MeshData(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(SceneError, match="albedo"):
        procedural.MeshData(np.zeros((3, 3)), [[0, 1, 2]], albedo=[[0.5, 0.5, 1.5]])
    with pytest.raises(SceneError, match="emission"):
        procedural.MeshData(np.zeros((3, 3)), [[0, 1, 2]], emission=[[0.0, -1.0, 0.0]])


# --- forest -----------------------------------------------------------------

def test_forest_triangle_count(default_forest):
    assert 160_000 <= default_forest.n_faces <= 185_000


def test_forest_seed_changes_geometry(default_forest):
    other = procedural.forest(seed=2)
    check_contract(other)
    assert (other.vertices.shape != default_forest.vertices.shape
            or not np.array_equal(other.vertices, default_forest.vertices))
    small = dict(seed=7, trees=5, leaves_per_tree=40, size=20.0)
    assert_same(procedural.forest(**small), procedural.forest(**small))


def test_forest_scales_with_parameters():
    base = procedural.forest(trees=0)             # ground and grass only
    check_contract(base)
    one = procedural.forest(trees=1, leaves_per_tree=0)
    leafy = procedural.forest(trees=1, leaves_per_tree=100)
    assert leafy.n_faces - one.n_faces == 200      # 2 triangles per leaf
    assert one.n_faces > base.n_faces
    big = procedural.forest(trees=0, size=200.0)  # grass stays on the ground
    assert np.abs(big.vertices[:, [0, 2]]).max() == pytest.approx(100.0)


def test_forest_layout(default_forest):
    v = default_forest.vertices
    half = 30.0
    assert np.abs(v[:, [0, 2]]).max() <= half + 4.0     # crowns may overhang the edge
    assert v[:, 1].min() > -1.0 and 8.0 < v[:, 1].max() < 15.0
    eye = np.array(procedural.FOREST_CAMERA["eye"])
    # the camera stands in a small clearing, above the ground
    assert np.linalg.norm(v - eye, axis=1).min() > 0.5
    near = np.linalg.norm(v[:, [0, 2]] - eye[[0, 2]], axis=1) < 1.0
    assert near.any() and v[near, 1].max() < eye[1] - 0.5
    # most geometry lies in front of the camera: it looks into the forest
    assert (v[:, 2] > eye[2]).mean() > 0.9
    # green foliage dominates the albedo
    green = default_forest.albedo[:, 1] > default_forest.albedo[:, [0, 2]].max(axis=1)
    assert green.mean() > 0.8
    assert default_forest.emission is None


# --- icosphere and furnace ----------------------------------------------------

@pytest.mark.parametrize("subdivisions", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("radius", [1.0, 2.5])
def test_icosphere_watertight_outward(subdivisions, radius):
    mesh = procedural.icosphere(radius=radius, subdivisions=subdivisions)
    check_contract(mesh)
    assert mesh.n_faces == 20 * 4 ** subdivisions
    assert mesh.n_vertices == 10 * 4 ** subdivisions + 2
    counts = edge_counts(mesh.faces)
    assert (counts == 2).all()
    assert len(counts) == 30 * 4 ** subdivisions           # Euler: V - E + F = 2
    r = np.linalg.norm(mesh.vertices.astype(np.float64), axis=1)
    np.testing.assert_allclose(r, radius, rtol=1e-5)
    centroids = mesh.vertices.astype(np.float64)[mesh.faces].mean(axis=1)
    assert (np.sum(face_normals(mesh) * centroids, axis=1) > 0).all()


def test_furnace_sphere():
    mesh = procedural.furnace_sphere(radius=3.0, subdivisions=2, albedo=0.25, emission=2.0)
    check_contract(mesh)
    assert (mesh.albedo == np.float32(0.25)).all()
    assert (mesh.emission == np.float32(2.0)).all()
    assert (edge_counts(mesh.faces) == 2).all()
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices, axis=1), 3.0, rtol=1e-5)
    default = procedural.furnace_sphere()
    assert default.n_faces == 1280
    assert (default.albedo == 0.5).all() and (default.emission == 1.0).all()
    np.testing.assert_array_equal(default.vertices,
                                  procedural.icosphere(subdivisions=3).vertices)
    # the camera sits at the centre, inside the sphere
    assert np.linalg.norm(procedural.FURNACE_CAMERA["eye"]) < 0.5


# --- Cornell box --------------------------------------------------------------

def test_cornell_light():
    mesh = procedural.cornell_box(light=7.5)
    check_contract(mesh)
    emitting = (mesh.emission > 0).any(axis=1)
    assert emitting.sum() == 2
    np.testing.assert_array_equal(mesh.emission[emitting], 7.5)
    np.testing.assert_array_equal(mesh.emission[~emitting], 0.0)
    np.testing.assert_allclose(mesh.albedo[emitting], 0.78, rtol=1e-6)
    light = mesh.vertices[mesh.faces[emitting]].reshape(-1, 3)
    assert np.ptp(light[:, 1]) == 0 and 0.99 < light[0, 1] < 1.0     # just below ceiling
    assert (np.abs(light[:, [0, 2]] - 0.5) < 0.15).all()              # small, centred
    assert (face_normals(mesh)[emitting, 1] < 0).all()                # faces down
    dark = procedural.cornell_box(light=0.0)
    assert (dark.emission == 0).all()


def test_cornell_room():
    mesh = procedural.cornell_box()
    v = mesh.vertices.astype(np.float64)
    tri = v[mesh.faces]
    assert v.min() >= 0.0 and v.max() <= 1.0
    # open front: no face has all its vertices at z = 1
    assert not (tri[:, :, 2] == 1.0).all(axis=1).any()
    normals = face_normals(mesh)
    area = 0.5 * np.linalg.norm(normals, axis=1)
    wall = np.isclose(area, 0.5)
    assert wall.sum() == 10                                 # 5 walls x 2 triangles
    centroid = tri.mean(axis=1)
    assert (np.sum(normals[wall] * (0.5 - centroid[wall]), axis=1) > 0).all()  # inward
    for axis, side, color in [(0, 0.0, (0.65, 0.05, 0.05)), (0, 1.0, (0.12, 0.45, 0.15)),
                              (1, 0.0, (0.73,) * 3), (1, 1.0, (0.73,) * 3),
                              (2, 0.0, (0.73,) * 3)]:
        on = wall & (tri[:, :, axis] == side).all(axis=1)
        assert on.sum() == 2
        np.testing.assert_allclose(mesh.albedo[on], [color] * 2, rtol=1e-6)
    # the two blocks: closed (by position), outward, volumes 0.3^3 + 0.3*0.6*0.3
    block = ~wall & ~(mesh.emission > 0).any(axis=1)
    assert block.sum() == 24
    keys = np.round(v * 1e5).astype(np.int64)
    _, ids = np.unique(keys, axis=0, return_inverse=True)
    assert (edge_counts(ids.reshape(-1)[mesh.faces[block]]) == 2).all()
    b = tri[block]
    volume = np.sum(b[:, 0] * np.cross(b[:, 1], b[:, 2])) / 6.0
    assert volume == pytest.approx(0.3 ** 3 + 0.3 * 0.6 * 0.3, rel=1e-4)
    np.testing.assert_allclose(mesh.albedo[block], 0.73, rtol=1e-6)
    # the camera is outside the opening
    assert procedural.CORNELL_CAMERA["eye"][2] > 1.0


# --- plane ------------------------------------------------------------------

def ray_hits(origin, directions, mesh):
    """Moeller-Trumbore: does each ray hit any triangle of the mesh?"""
    tri = mesh.vertices.astype(np.float64)[mesh.faces]           # (F, 3, 3)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = directions[:, None, :]                                   # (R, 1, 3)
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origin - tri[:, 0]
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        w = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
        hit = (np.abs(det) > 1e-12) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
    return hit.any(axis=1)


def test_plane_every_primary_ray_hits():
    mesh = procedural.plane_under_sky()
    check_contract(mesh)
    assert mesh.n_faces == 2
    assert (mesh.vertices[:, 1] == 0).all()
    np.testing.assert_allclose(np.abs(mesh.vertices[:, [0, 2]]), 50.0)
    assert (face_normals(mesh)[:, 1] > 0).all()               # faces up, towards the sky
    np.testing.assert_array_equal(mesh.albedo, 0.5)
    assert mesh.emission is None

    camera = procedural.PLANE_CAMERA
    eye = np.array(camera["eye"])
    forward = np.subtract(camera["look_at"], eye)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera["up"])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rng = np.random.default_rng(0)
    half = math.radians(30.0)                                  # a 60 degree cone
    theta = np.concatenate([np.arccos(rng.uniform(math.cos(half), 1.0, 300)),
                            np.full(60, half)])                # inside and on the rim
    phi = np.concatenate([rng.uniform(0, 2 * np.pi, 300), np.linspace(0, 2 * np.pi, 60)])
    dirs = (np.cos(theta)[:, None] * forward
            + np.sin(theta)[:, None] * (np.cos(phi)[:, None] * right
                                        + np.sin(phi)[:, None] * up))
    # plus the corners of a 16:9 image with the camera's vertical field of view
    th = math.tan(math.radians(camera["vfov"]) / 2)
    corners = [forward + sx * th * 16 / 9 * right + sy * th * up
               for sx in (-1, 1) for sy in (-1, 1)]
    dirs = np.concatenate([dirs, corners])
    assert ray_hits(eye, dirs, mesh).all()
    # sanity check of the checker: a ray towards the horizon misses
    assert not ray_hits(eye, np.array([[0.0, 0.0, 1.0]]), mesh).any()


def test_plane_parameters():
    mesh = procedural.plane_under_sky(size=10.0, albedo=0.2)
    np.testing.assert_allclose(np.abs(mesh.vertices[:, [0, 2]]), 5.0)
    np.testing.assert_allclose(mesh.albedo, 0.2, rtol=1e-6)


# --- parameter validation ----------------------------------------------------

@pytest.mark.parametrize("func, kwargs, name", [
    (procedural.forest, dict(trees=-1), "trees"),
    (procedural.forest, dict(trees=2.5), "trees"),
    (procedural.forest, dict(trees=True), "trees"),
    (procedural.forest, dict(seed=-3), "seed"),
    (procedural.forest, dict(seed="1"), "seed"),
    (procedural.forest, dict(leaves_per_tree=10**6), "leaves_per_tree"),
    (procedural.forest, dict(size=0.0), "size"),
    (procedural.forest, dict(size=float("nan")), "size"),
    (procedural.furnace_sphere, dict(subdivisions=9), "subdivisions"),
    (procedural.furnace_sphere, dict(albedo=1.5), "albedo"),
    (procedural.furnace_sphere, dict(emission=-1.0), "emission"),
    (procedural.furnace_sphere, dict(radius=0.0), "radius"),
    (procedural.icosphere, dict(subdivisions=-1), "subdivisions"),
    (procedural.icosphere, dict(radius=float("inf")), "radius"),
    (procedural.icosphere, dict(radius="1"), "radius"),
    (procedural.cornell_box, dict(light=-0.1), "light"),
    (procedural.cornell_box, dict(light=None), "light"),
    (procedural.plane_under_sky, dict(size=-5.0), "size"),
    (procedural.plane_under_sky, dict(albedo=1.5), "albedo"),
])
def test_invalid_parameters(func, kwargs, name):
    with pytest.raises(ValueError, match=rf"\b{name}\b.*(in|>=) [\[(]?\d") as info:
        func(**kwargs)
    assert func.__name__ in str(info.value)


def test_parameters_are_keyword_only():
    with pytest.raises(TypeError):
        procedural.forest(1)
    with pytest.raises(TypeError):
        procedural.icosphere(1.0)


def test_numpy_scalars_accepted():
    mesh = procedural.icosphere(radius=np.float32(2.0), subdivisions=np.int64(1))
    assert mesh.n_faces == 80
    assert procedural.furnace_sphere(albedo=1, emission=0).albedo.max() == 1.0
