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
