"""raysort.sdk.LibraryTraversal: an outside library's inclusive tnear is hidden from raysort.

The "library" here is a NumPy Moller-Trumbore in float64 that, like Embree, counts a hit
at t = 0 from the origin it is given.  The base class must shift origins to tmin, trace
again past hits at the ray's start, and write brute force's hits (within rounding).
"""
import numpy as np
import pytest

import raysort
from raysort.rays import gather, scatter, scatter_occluded
from raysort.reference import brute_force
from raysort.sdk import LibraryTraversal

# a floor (z = 0) over [-4, 4]^2 and a wide ceiling (z = 2)
VERTICES = np.array([[-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0],
                     [-1e3, -1e3, 2], [1e3, -1e3, 2], [1e3, 1e3, 2], [-1e3, 1e3, 2]],
                    np.float32)
FACES = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.int32)


class InclusiveLibrary(LibraryTraversal):
    """Every triangle against every ray, t in [0, far] (inclusive at 0, as Embree)."""

    queries = 0

    def scene(self, bvh):
        v = bvh.vertices.astype(np.float64)
        f = bvh.faces
        return v[f[:, 0]], v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]

    def query(self, scene, origins, directions, far, any_hit):
        type(self).queries += 1
        v0, e1, e2 = (x[None] for x in scene)
        o, d = origins.astype(np.float64)[:, None], directions.astype(np.float64)[:, None]
        p = np.cross(d, e2)
        det = (e1 * p).sum(-1)
        with np.errstate(all="ignore"):
            s = o - v0
            u = (s * p).sum(-1) / det
            q = np.cross(s, e1)
            v = (d * q).sum(-1) / det
            t = (e2 * q).sum(-1) / det
            ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & \
                (t <= far[:, None])
        t = np.where(ok, t, np.inf)
        prim = np.where(ok.any(1), t.argmin(1), -1).astype(np.int32)
        rows = np.arange(len(prim))
        pick = np.maximum(prim, 0)
        best = np.where(prim >= 0, t[rows, pick], np.inf).astype(np.float32)
        return (best, prim, u[rows, pick].astype(np.float32),
                v[rows, pick].astype(np.float32))


def rays_from_floor(tmin, n=256):
    rng = np.random.default_rng(5)
    start = np.column_stack([rng.uniform(-3, 3, (n, 2)), np.zeros(n)]).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:, 2] = np.abs(d[:, 2]) + 0.2                 # away from the floor, up to the ceiling
    return raysort.RayBatch.from_arrays(start - tmin * d, d, tmin=tmin)


def trace(rays, any_hit=False):
    packets = gather(rays, np.arange(len(rays), dtype=np.int32),
                     np.array([0, len(rays)], np.int32))
    counters = InclusiveLibrary().intersect(raysort.BVH(VERTICES, FACES), packets, any_hit)
    assert isinstance(counters, raysort.Counters) and not counters.available
    return scatter_occluded(packets, len(rays)) if any_hit else scatter(packets, len(rays))


@pytest.mark.parametrize("tmin", [0.0, 0.5])
def test_a_hit_at_the_rays_start_is_traced_past(tmin):
    """Rays starting on the floor: the library reports the floor at t = 0; the base class
    must answer the ceiling, as brute force does."""
    rays = rays_from_floor(tmin)
    ref = brute_force(VERTICES, FACES, rays)
    assert (ref.prim >= 2).all()
    before = InclusiveLibrary.queries
    hits = trace(rays)
    assert InclusiveLibrary.queries > before + 1     # it did trace again
    assert (hits.prim >= 2).all()
    np.testing.assert_allclose(hits.t, ref.t, rtol=1e-5)


def test_rays_off_the_plane_need_one_query_and_match_brute_force():
    rng = np.random.default_rng(8)
    n = 200
    o = np.column_stack([rng.uniform(-3, 3, (n, 2)), np.full(n, 1.0)]).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    rays = raysort.RayBatch.from_arrays(o, d, tmin=0.0)
    ref = brute_force(VERTICES, FACES, rays)
    before = InclusiveLibrary.queries
    hits = trace(rays)
    assert InclusiveLibrary.queries == before + 1
    np.testing.assert_array_equal(hits.prim >= 0, ref.prim >= 0)
    both = ref.prim >= 0
    np.testing.assert_allclose(hits.t[both], ref.t[both], rtol=1e-5)
    np.testing.assert_allclose(hits.u[both], ref.u[both], atol=1e-4)


def test_any_hit_marks_the_occluded_rays():
    rng = np.random.default_rng(9)
    n = 200
    o = np.column_stack([rng.uniform(-3, 3, (n, 2)), np.full(n, 1.0)]).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    rays = raysort.RayBatch.from_arrays(o, d, tmin=0.0, tmax=0.5)
    ref = brute_force(VERTICES, FACES, rays)
    np.testing.assert_array_equal(trace(rays, any_hit=True), ref.prim >= 0)


def test_the_library_methods_must_be_given():
    packets = gather(rays_from_floor(0.0, 8), np.arange(8, dtype=np.int32),
                     np.array([0, 8], np.int32))
    with pytest.raises(NotImplementedError):
        LibraryTraversal().intersect(raysort.BVH(VERTICES, FACES), packets)
