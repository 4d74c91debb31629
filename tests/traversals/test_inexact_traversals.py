"""Traversals that declare ``exact = False`` (e.g. an outside library such as Embree,
with its own triangle test) are held to brute force within floating-point tolerance.

Like the exact conformance suite, the list comes from the registry, so an installed
plugin is tested automatically; with only raysort's built-ins (all exact) the tests
are skipped.
"""
import numpy as np
import pytest

import raysort
from raysort.rays import gather, scatter, scatter_occluded
from raysort.reference import brute_force

INEXACT = [name for name in raysort.available("traversals")
           if not raysort.load("traversals", name).exact]


def assert_hits_close(hits, ref, label, rel=1e-4, mismatch=1e-3):
    """Hit/miss agrees on all but ``mismatch`` of the rays; where both hit, t agrees to
    ``rel``; a different primitive only where the two are at the same distance (ties)."""
    hit, ref_hit = hits.prim >= 0, ref.prim >= 0
    assert np.mean(hit != ref_hit) <= mismatch, f"{label}: hit/miss differ"
    both = hit & ref_hit
    assert (np.abs(hits.t[both] - ref.t[both]) <= rel * ref.t[both]).all(), f"{label}: t"
    assert np.mean(both & (hits.prim != ref.prim)) < 0.01, f"{label}: other primitives"


@pytest.mark.skipif(not INEXACT, reason="no inexact traversal is installed")
@pytest.mark.parametrize("name", INEXACT or ["none"])
@pytest.mark.parametrize("kind", ["primary", "diffuse"])
def test_inexact_traversal_within_tolerance(name, kind, real_scene, workloads):
    work = workloads(real_scene, kind)
    bvh = real_scene.bvh()
    n = len(work)
    order = np.random.default_rng(3).permutation(n).astype(np.int32)
    offsets = np.append(np.arange(0, n, 37), n).astype(np.int32)
    trav = raysort.create("traversals", name)
    packets = gather(work.rays, order, offsets)
    counters = trav.intersect(bvh, packets)
    ref = brute_force(real_scene.vertices, real_scene.faces, work.rays)
    assert_hits_close(scatter(packets, n), ref, f"{name} {real_scene.name} {kind}")
    assert isinstance(counters, raysort.Counters)
    packets = gather(work.rays, order, offsets)
    trav.intersect(bvh, packets, any_hit=True)
    occluded = scatter_occluded(packets, n)
    assert np.mean(occluded != (ref.prim >= 0)) <= 1e-3


@pytest.mark.skipif(not INEXACT, reason="no inexact traversal is installed")
@pytest.mark.parametrize("name", INEXACT or ["none"])
@pytest.mark.parametrize("tmin", [0.0, 0.5])
def test_a_ray_starting_on_a_triangle_does_not_hit_it_at_its_start(name, tmin):
    """raysort counts hits with t > tmin only.  A library whose tnear is inclusive
    (Embree's) reports t = tmin on the triangle a ray starts on; the plugin must not."""
    # a floor (z = 0) over [-4, 4]^2 and a wide ceiling (z = 2)
    v = np.array([[-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0],
                  [-1e3, -1e3, 2], [1e3, -1e3, 2], [1e3, 1e3, 2], [-1e3, 1e3, 2]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.int32)
    rng = np.random.default_rng(5)
    n = 256
    start = np.column_stack([rng.uniform(-3, 3, (n, 2)), np.zeros(n)]).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:, 2] = np.abs(d[:, 2]) + 0.2                 # away from the floor, up to the ceiling
    rays = raysort.RayBatch.from_arrays(start - tmin * d, d, tmin=tmin)
    bvh = raysort.BVH(v, f)
    ref = brute_force(v, f, rays)
    assert (ref.prim >= 2).all()                     # brute force: the ceiling, every ray
    order = np.arange(n, dtype=np.int32)
    packets = gather(rays, order, np.array([0, n], np.int32))
    raysort.create("traversals", name).intersect(bvh, packets)
    hits = scatter(packets, n)
    assert (hits.prim >= 2).all(), f"{name}: hits at the ray's start"
    assert np.allclose(hits.t, ref.t, rtol=1e-4)


@pytest.mark.skipif(not INEXACT, reason="no inexact traversal is installed")
@pytest.mark.parametrize("name", INEXACT or ["none"])
def test_inexact_traversal_renders_nearly_the_same_image(name, sibenik):
    """A whole render (closest-hit and shadow rays) through the pipeline's checks."""
    shader = {"type": "lambert", "shadow_rays": True}
    ours = raysort.Pipeline(sibenik, traversal="single", shader=shader).render(24, 16, 1)
    theirs = raysort.Pipeline(sibenik, traversal=name, shader=shader).render(24, 16, 1)
    assert np.abs(theirs.image - ours.image).mean() < 0.02 * ours.image.mean()
