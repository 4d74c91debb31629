"""The ``wide16`` traversal and the 16-wide BVH it walks.

Hits are compared with brute force (``raysort.reference``) on every ISA this CPU
runs, including ties and zero-area triangles; the widened tree is checked against
the 8-wide tree it comes from: the same leaf slots (boxes and triangle groups),
each inner 8-wide node either kept as a node or opened into its parent.
(The conformance suite holds wide16 to the full contract on the active ISA.)
"""
from collections import Counter

import numpy as np
import pytest

import raysort
from raysort.bvh import BVH
from raysort.rays import gather
from raysort.reference import brute_force

from _helpers import (assert_same_hits, random_rays, tie_case, trace_one_call,
                      triangle_soup)

F32 = np.float32


def trace(bvh, rays, any_hit=False, size=None):
    return trace_one_call("wide16", bvh, rays, any_hit, size)


def soup(rng, m=800):
    return triangle_soup(rng, m)


def slots(nodes, width):
    """Every used slot of a wide tree: (child, count, lo, hi) per slot."""
    for node in nodes:
        for k in range(width):
            if node["child"][k] != 0:
                yield (int(node["child"][k]), int(node["count"][k]),
                       tuple(node["lo"][:, k]), tuple(node["hi"][:, k]))


@pytest.mark.parametrize("max_leaf, group_cost, merged", [(1, 1.0, 16), (8, 0.4, 32),
                                                          (8, 0.25, 64)])
def test_random_rays_match_brute_force_on_every_isa(each_isa, rng, max_leaf, group_cost,
                                                    merged):
    V, F = soup(rng)
    bvh = BVH(V, F, max_leaf=max_leaf)
    bvh._wide8 = bvh.collapse8(group_cost, merged)
    rays = random_rays(rng, 3000, bvh.bounds, spread=1.0)
    ref = brute_force(V, F, rays)
    assert 0.1 < (ref.prim >= 0).mean() < 0.95
    for size in (None, 4, 37):
        hits, _ = trace(bvh, rays, size=size)
        assert_same_hits(hits, ref, f"{each_isa}, packets of {size}")
    occluded, _ = trace(bvh, rays, any_hit=True)
    assert np.array_equal(occluded, ref.prim >= 0)


def test_ties_and_zero_area_triangles_on_every_isa(each_isa, rng):
    V, F, rays, ref = tie_case(rng)
    for max_leaf in (1, 8):
        bvh = BVH(V, F, max_leaf=max_leaf)
        hits, _ = trace(bvh, rays, size=13)
        assert_same_hits(hits, ref, f"{each_isa} ties, max_leaf {max_leaf}")


def test_widened_tree_keeps_the_leaf_slots_and_opens_inner_nodes(rng):
    V, F = soup(rng, 2000)
    bvh = BVH(V, F, max_leaf=2)
    w8, w16 = bvh.wide8, bvh.wide16
    assert w16.groups is w8.groups and 1 <= w16.depth <= w8.depth
    assert len(w16.nodes) < len(w8.nodes)               # some nodes were opened
    leaves8 = Counter(s for s in slots(w8.nodes, 8) if s[0] < 0)
    leaves16 = Counter(s for s in slots(w16.nodes, 16) if s[0] < 0)
    assert leaves16 == leaves8                          # every leaf once, same box
    # every inner slot's box is one of the 8-wide tree's inner boxes
    inner8 = Counter(s[2:] for s in slots(w8.nodes, 8) if s[0] > 0)
    inner16 = Counter(s[2:] for s in slots(w16.nodes, 16) if s[0] > 0)
    assert not inner16 - inner8
    # a tree: each node has one parent; an unused slot is an empty box
    parents = Counter(s[0] for s in slots(w16.nodes, 16) if s[0] > 0)
    assert set(parents) == set(range(1, len(w16.nodes))) and set(parents.values()) == {1}
    unused = w16.nodes["child"] == 0
    assert (w16.nodes["lo"][:, 0][unused] == np.inf).all()
    assert (w16.nodes["count"][unused] == 0).all()
    assert ((~unused).sum(axis=1) <= 16).all() and (~unused).sum(axis=1).mean() > 8


def test_refit_rebuilds_the_widened_tree(rng):
    V, F = soup(rng, 200)
    bvh = BVH(V, F)
    assert bvh.wide16 is bvh.wide16                     # built once
    moved = (V + np.float32(3.0)).astype(F32)
    bvh.refit(moved)
    rays = random_rays(rng, 1000, bvh.bounds)
    assert_same_hits(trace(bvh, rays)[0], brute_force(moved, F, rays), "after refit")


def test_counters_fewer_node_tests_than_wide8(rng):
    V, F = soup(rng, 3000)
    bvh = BVH(V, F)
    rays = random_rays(rng, 2000, bvh.bounds)
    _, c16 = trace(bvh, rays)
    packets = gather(rays, np.arange(len(rays), dtype=np.int32),
                     np.array([0, len(rays)], np.int32))
    c8 = raysort.create("traversals", "wide8").intersect(bvh, packets)
    assert c16.rays == c8.rays == len(rays) and c16.ia == c16.box1 == c16.tri1 == 0
    assert c16.rays <= c16.box4 < c8.box4     # the root's test, then fewer, wider nodes
    assert c16.tri4 > 0
