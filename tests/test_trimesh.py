"""raysort.trimesh.RayMeshIntersector, held to brute force (bit for bit) and to trimesh's own
pure-NumPy intersector (``trimesh.ray.ray_triangle``) on random rays over several meshes.

trimesh's intersector works in float64 with a tolerance, raysort in float32 exactly, so the
two may disagree only where a ray passes within float32 rounding of a face's edge; every
disagreement must be such a ray, and there must be few.
"""
import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("rtree")   # trimesh's ray_triangle intersector needs it

from trimesh.ray.ray_triangle import RayMeshIntersector as TrimeshIntersector  # noqa: E402

import raysort  # noqa: E402
from raysort import meshtrace  # noqa: E402
from raysort.rays import RayBatch  # noqa: E402
from raysort.reference import brute_force  # noqa: E402
from raysort.trimesh import RayMeshIntersector  # noqa: E402

N_RAYS = 400
EDGE = 1e-4      # barycentric distance to an edge within which float32 and float64 may differ


def _soup_of_boxes():
    rng = np.random.default_rng(4)
    boxes = [trimesh.creation.box(extents=rng.uniform(0.3, 1.0, 3),
                                  transform=trimesh.transformations.random_rotation_matrix(
                                      rng.random(3)) @ trimesh.transformations.translation_matrix(
                                      rng.uniform(-1, 1, 3)))
             for _ in range(12)]
    return trimesh.util.concatenate(boxes)


MESHES = {
    "icosphere": lambda: trimesh.creation.icosphere(subdivisions=3),
    "torus": lambda: trimesh.creation.torus(major_radius=1.0, minor_radius=0.3),
    "cylinder": lambda: trimesh.creation.cylinder(radius=0.5, height=2.0, sections=40),
    "overlapping boxes": _soup_of_boxes,
    "sponza": lambda: trimesh.Trimesh(*(lambda s: (s.vertices, s.faces))(
        raysort.load_scene("sponza")), process=False),
}


@pytest.fixture(scope="module", params=sorted(MESHES))
def case(request):
    """(name, mesh, origins, directions): random rays from a box 1.5 times the mesh's."""
    mesh = MESHES[request.param]()
    rng = np.random.default_rng(11)
    lo, hi = mesh.bounds
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.5
    origins = (centre + (rng.random((N_RAYS, 3)) * 2 - 1) * half).astype(np.float32)
    directions = rng.normal(size=(N_RAYS, 3)).astype(np.float32)
    return request.param, mesh, origins.astype(np.float64), directions.astype(np.float64)


@pytest.fixture(scope="module")
def reference(case):
    """trimesh's own answers for the case (slow, so computed once)."""
    _, mesh, origins, directions = case
    ref = TrimeshIntersector(mesh)
    return {"first": ref.intersects_first(origins, directions),
            "any": ref.intersects_any(origins, directions),
            "location": ref.intersects_location(origins, directions, multiple_hits=True)}


def _plane_hits(mesh, origins, directions, faces):
    """(t, barycentric) where each ray meets the plane of its face, in float64."""
    corners = mesh.vertices[mesh.faces[faces]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", corners[:, 0] - origins, normal) / np.einsum(
            "ij,ij->i", directions, normal)
        bary = trimesh.triangles.points_to_barycentric(corners, origins + t[:, None] * directions)
    return t, bary


def _near_edge(mesh, origins, directions, faces):
    """For rays paired with faces: does the ray meet the face's plane within EDGE
    (in barycentric coordinates) of the face's boundary?"""
    t, bary = _plane_hits(mesh, origins, directions, faces)
    return (np.abs(bary).min(axis=1) < EDGE) | ~np.isfinite(t)


def _excused(mesh, origins, directions, rays, faces_a, faces_b):
    """Rays whose disagreement is a float32-vs-float64 case: the ray passes within EDGE of
    an edge of a face either side reports, or meets both faces inside at the same distance
    to float32 precision (coplanar overlapping faces, as Sponza has)."""
    ok = np.zeros(len(rays), bool)
    for faces in (faces_a, faces_b):
        has = faces >= 0
        ok[has] |= _near_edge(mesh, origins[rays[has]], directions[rays[has]], faces[has])
    both = (faces_a >= 0) & (faces_b >= 0)
    o, d = origins[rays[both]], directions[rays[both]]
    t_a, bary_a = _plane_hits(mesh, o, d, faces_a[both])
    t_b, bary_b = _plane_hits(mesh, o, d, faces_b[both])
    ok[both] |= ((np.abs(t_a - t_b) <= 1e-6 * np.abs(t_a)) & (bary_a > -EDGE).all(axis=1)
                 & (bary_b > -EDGE).all(axis=1))
    return ok


def _agree(mesh, origins, directions, ours, theirs):
    """Per-ray first faces (-1: miss): every disagreement is excused, and they are few."""
    bad = np.flatnonzero(ours != theirs)
    excused = _excused(mesh, origins, directions, bad, ours[bad], theirs[bad])
    assert excused.all(), f"rays {bad[~excused][:5]} disagree away from any edge"
    assert len(bad) <= max(2, len(ours) // 100)


# --------------------------------------------------------------------------
# exactness: brute force on the float32 mesh and rays
# --------------------------------------------------------------------------

def test_first_hits_are_brute_force(case):
    _, mesh, origins, directions = case
    first = RayMeshIntersector(mesh).intersects_first(origins, directions)
    rays = RayBatch.from_arrays(origins, directions)
    ref = brute_force(mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32), rays)
    assert first.dtype == np.int64
    assert np.array_equal(first, ref.prim)


def test_second_hits_are_brute_force_past_the_first(case):
    """multiple_hits: a ray's second hit is brute force's closest hit beyond the first."""
    _, mesh, origins, directions = case
    tri, ray = RayMeshIntersector(mesh).intersects_id(origins, directions, max_hits=2)
    first = RayBatch.from_arrays(origins, directions)
    v32, f32 = mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32)
    hits = brute_force(v32, f32, first)
    hit = np.flatnonzero(hits.prim >= 0)
    beyond = first.take(hit)
    beyond.tmin[:] = hits.t[hit]
    second = brute_force(v32, f32, beyond)
    expected_ray = np.concatenate([hit, hit[second.prim >= 0]])
    expected_tri = np.concatenate([hits.prim[hit], second.prim[second.prim >= 0]])
    order = np.lexsort((np.concatenate([hits.t[hit], second.t[second.prim >= 0]]),
                        expected_ray))
    assert np.array_equal(ray, expected_ray[order])
    assert np.array_equal(tri, expected_tri[order])


# --------------------------------------------------------------------------
# agreement with trimesh's own intersector
# --------------------------------------------------------------------------

def test_intersects_first_matches_trimesh(case, reference):
    name, mesh, origins, directions = case
    ours = RayMeshIntersector(mesh).intersects_first(origins, directions)
    assert ours.shape == reference["first"].shape and ours.dtype == reference["first"].dtype
    assert (ours >= 0).sum() > N_RAYS // 20, name
    _agree(mesh, origins, directions, ours, reference["first"])


def test_intersects_any_matches_trimesh(case, reference):
    _, mesh, origins, directions = case
    ours = RayMeshIntersector(mesh).intersects_any(origins, directions)
    assert ours.dtype == bool and ours.shape == (N_RAYS,)
    first = RayMeshIntersector(mesh).intersects_first(origins, directions)
    assert np.array_equal(ours, first >= 0)
    # trimesh's any-hit answer is its first-hit answer's (checked above, with excuses)
    differ = ours != reference["any"]
    assert (first[differ] != reference["first"][differ]).all()


def test_every_hit_along_the_rays_matches_trimesh(case, reference):
    """intersects_location with multiple hits: the same number of hits per ray, the same
    faces and points (to float32 precision), for every ray not passing by an edge."""
    _, mesh, origins, directions = case
    locations, index_ray, index_tri = RayMeshIntersector(mesh).intersects_location(
        origins, directions)
    ref_locations, ref_ray, ref_tri = reference["location"]
    assert locations.dtype == np.float64 and locations.shape == (len(index_ray), 3)
    assert index_ray.dtype == index_tri.dtype == np.int64
    counts = np.bincount(index_ray, minlength=N_RAYS)
    ref_counts = np.bincount(ref_ray, minlength=N_RAYS)
    assert counts.sum() > N_RAYS // 10
    suspicious = np.flatnonzero(counts != ref_counts)
    faces_of = {r: set() for r in suspicious}
    for r, f in zip(np.concatenate([index_ray, ref_ray]), np.concatenate([index_tri, ref_tri])):
        if r in faces_of:
            faces_of[r].add(f)
    for r in suspicious:
        faces = np.array(sorted(faces_of[r]))
        near = _near_edge(mesh, np.repeat(origins[r:r + 1], len(faces), 0),
                          np.repeat(directions[r:r + 1], len(faces), 0), faces)
        assert near.any(), f"ray {r}: {counts[r]} hits, trimesh {ref_counts[r]}"
    assert len(suspicious) <= max(2, N_RAYS // 50)
    same = np.isin(index_ray, np.flatnonzero(counts == ref_counts))
    ref_same = np.isin(ref_ray, np.flatnonzero(counts == ref_counts))
    distance = np.einsum("ij,ij->i", ref_locations - origins[ref_ray], directions[ref_ray])
    ref_order = np.lexsort((distance[ref_same], ref_ray[ref_same]))
    scale = mesh.scale
    np.testing.assert_allclose(locations[same], ref_locations[ref_same][ref_order],
                               atol=1e-5 * scale)
    assert np.array_equal(index_ray[same], ref_ray[ref_same][ref_order])
    # ours on the faces we name: the point is inside its face
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[index_tri], locations)
    assert (bary > -1e-6).all()


def test_first_hit_locations_and_ids(case, reference):
    _, mesh, origins, directions = case
    ours = RayMeshIntersector(mesh)
    tri, ray, locations = ours.intersects_id(origins, directions, multiple_hits=False,
                                             return_locations=True)
    first = ours.intersects_first(origins, directions)
    assert np.array_equal(ray, np.flatnonzero(first >= 0)) and np.array_equal(tri, first[ray])
    hits = RayBatch.from_arrays(origins, directions)
    t = brute_force(mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32), hits).t
    along = origins[ray] + t[ray, None].astype(np.float64) * directions[ray]
    np.testing.assert_allclose(locations, along, atol=1e-4 * mesh.scale)


# --------------------------------------------------------------------------
# conventions
# --------------------------------------------------------------------------

def test_drop_in_for_mesh_ray():
    """`mesh.ray = RayMeshIntersector(mesh)` makes trimesh's own methods use raysort."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    points = np.random.default_rng(2).uniform(-1.2, 1.2, (300, 3))
    expected = np.linalg.norm(points, axis=1) < 1.0
    radius = np.linalg.norm(points, axis=1)
    clear = np.abs(radius - 1.0) > 0.02           # away from the faceted surface
    mesh.ray = RayMeshIntersector(mesh, sorter="none", traversal="single")
    assert np.array_equal(mesh.contains(points)[clear], expected[clear])
    assert mesh.ray.intersects_any([[0, 0, 0]], [[0, 0, 1]]).tolist() == [True]


def test_empty_queries_and_bad_arrays():
    mesh = trimesh.creation.box()
    ours = RayMeshIntersector(mesh)
    none = np.zeros((0, 3))
    assert ours.intersects_first(none, none).shape == (0,)
    tri, ray, loc = ours.intersects_id(none, none, return_locations=True)
    assert tri.dtype == ray.dtype == np.int64 and loc.shape == (0, 3)
    tri, ray = ours.intersects_id([[5, 5, 5]], [[1, 0, 0]])
    assert len(tri) == len(ray) == 0
    with pytest.raises(ValueError, match="don't match"):
        ours.intersects_first([[0, 0, 0]], [[0, 0, 1], [0, 1, 0]])


def test_max_hits_order_and_mesh_edits():
    """Three unit boxes in a row: a ray along them hits 6 faces, nearest first; max_hits
    caps that; moving the mesh is seen by the next query."""
    mesh = trimesh.util.concatenate([trimesh.creation.box(
        transform=trimesh.transformations.translation_matrix([2.0 * k, 0, 0]))
        for k in range(3)])
    ours = RayMeshIntersector(mesh)
    origins, directions = [[-3.0, 0.1, 0.2], [9.0, 0.3, -0.1]], [[1.0, 0, 0], [-1.0, 0, 0]]
    locations, ray, _ = ours.intersects_location(origins, directions)
    assert ray.tolist() == [0] * 6 + [1] * 6
    assert locations[:6, 0].tolist() == [-0.5, 0.5, 1.5, 2.5, 3.5, 4.5]
    assert locations[6:, 0].tolist() == [4.5, 3.5, 2.5, 1.5, 0.5, -0.5]
    _, ray = ours.intersects_id(origins, directions, max_hits=2)
    assert ray.tolist() == [0, 0, 1, 1]
    mesh.apply_translation([0, 100, 0])
    assert (ours.intersects_first(origins, directions) == -1).all()


def test_pipeline_choices_give_the_same_hits(case):
    _, mesh, origins, directions = case
    base = RayMeshIntersector(mesh).intersects_location(origins, directions)
    meshtrace.clear_cache()
    other = RayMeshIntersector(mesh, sorter="none", traversal="ranged", threads=2,
                               bvh={"max_leaf": 2}).intersects_location(origins, directions)
    for a, b in zip(base, other):
        assert np.array_equal(a, b)
