"""The ``wide8`` traversal and the 8-wide BVH it walks.

Hits are compared with brute force (``raysort.reference``) on every ISA this
CPU runs, including ties, zero-area triangles and multi-group leaves; the
collapse is checked against an independent Python transcription of the
SAH-optimal dynamic program and against the triangles it must hold.
(The conformance suite holds wide8 to the full contract on the active ISA.)
"""
from functools import cache

import numpy as np
import pytest

from raysort import procedural
from raysort.bvh import BVH
from raysort.reference import brute_force

from _helpers import (assert_same_hits, batch, random_rays, tie_case,
                      trace_one_call, triangle_soup)

F32 = np.float32


def trace(bvh, rays, any_hit=False, size=None):
    return trace_one_call("wide8", bvh, rays, any_hit, size)


def soup(rng, m=600):
    return triangle_soup(rng, m)


@pytest.mark.parametrize("max_leaf, group_cost, merged", [(1, 1.0, 16), (8, 1.0, 16),
                                                          (8, 0.25, 64), (32, 4.0, 8)])
def test_random_rays_match_brute_force_on_every_isa(each_isa, rng, max_leaf, group_cost,
                                                    merged):
    V, F = soup(rng)
    bvh = BVH(V, F, max_leaf=max_leaf)
    bvh._wide8 = bvh.collapse8(group_cost, merged)    # leaves of one to eight groups
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
        for group_cost, merged in ((1.0, 16), (0.1, 64)):
            bvh._wide8 = bvh.collapse8(group_cost, merged)
            hits, _ = trace(bvh, rays, size=13)
            assert_same_hits(hits, ref, f"{each_isa} ties, max_leaf {max_leaf}")


def test_grazing_rays_along_faces_on_every_isa(each_isa, rng):
    """Rays in the planes of a cube's faces and along its edges (0 * inf slab terms)."""
    s = procedural.cornell_box()
    V, F = s.vertices, s.faces
    bvh = BVH(V, F)
    n = 2000
    o = rng.choice([0.0, 0.25, 0.5, 1.0], size=(n, 3)).astype(F32)
    d = rng.choice([-1.0, 0.0, 1.0], size=(n, 3)).astype(F32)
    d[(d == 0).all(axis=1), 0] = 1.0
    rays = batch(o, d)
    ref = brute_force(V, F, rays)
    assert_same_hits(trace(bvh, rays)[0], ref, each_isa)


def test_refit_rebuilds_the_wide_tree(rng):
    V, F = soup(rng, 200)
    bvh = BVH(V, F)
    assert bvh.wide8 is bvh.wide8          # built once
    moved = (V + np.float32(3.0)).astype(F32)
    bvh.refit(moved)
    rays = random_rays(rng, 1000, bvh.bounds)
    assert_same_hits(trace(bvh, rays)[0], brute_force(moved, F, rays), "after refit")


def test_counters(rng):
    V, F = soup(rng)
    bvh = BVH(V, F)
    rays = random_rays(rng, 2000, bvh.bounds)
    hits, c = trace(bvh, rays)
    assert c.rays == len(rays) and c.ia == c.box1 == c.tri1 == 0
    assert c.box4 >= c.rays                  # every ray tests the root's eight boxes
    assert 0 < c.tri4 < len(rays) * len(F) / 8 / 4     # brute force: len(F) / 8 per ray
    # rays that miss the scene's box: one node test each, no triangle test
    lo, hi = bvh.bounds
    away = batch(np.tile(hi + 1, (50, 1)), np.tile([1.0, 1.0, 1.0], (50, 1)))
    _, c = trace(bvh, away)
    assert (c.rays, c.box4, c.tri4) == (50, 50, 0)


def test_groups_hold_every_triangle_once_in_its_boxes(rng):
    V, F = soup(rng)
    bvh = BVH(V, F, max_leaf=3, spatial_splits=0)     # each triangle in one leaf
    w = bvh.collapse8(0.5, 40)
    ids = w.groups["id"].ravel()
    real = ids != np.iinfo(np.int32).max
    assert np.array_equal(np.sort(ids[real]), np.arange(len(F)))
    assert (w.groups["e1"][~real.reshape(-1, 8)[:, None, :].repeat(3, 1)] == 0).all()
    tri_lo, tri_hi = V[F].min(axis=1), V[F].max(axis=1)
    seen = np.zeros(len(w.nodes), int)
    seen[0] = 1
    for node in w.nodes:
        for k in range(8):
            child = node["child"][k]
            lo, hi = node["lo"][:, k], node["hi"][:, k]
            if child > 0:
                seen[child] += 1
                # the child's boxes lie in this slot's box
                assert (w.nodes[child]["lo"].min(axis=1) >= lo).all()
            elif child < 0:
                g = w.groups[-child - 1: -child - 1 + node["count"][k]]["id"].ravel()
                g = g[g != np.iinfo(np.int32).max]
                assert (tri_lo[g] >= lo).all() and (tri_hi[g] <= hi).all()
            else:
                assert (lo == np.inf).all() and (hi == -np.inf).all()
    assert (seen == 1).all()                 # a tree: each node has one parent


def _area(lo, hi):
    e = np.maximum(hi.astype(float) - lo.astype(float), 0)
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


def reference_sah(bvh, group_cost, merged):
    """The optimal collapse cost by memoised recursion over the binary tree (Ylitie et al.
    2017), written independently of the Cython DP."""
    nodes = bvh.nodes

    @cache
    def tris(b):
        n = nodes[b]
        return int(n["count"]) if n["count"] else tris(b + 1) + tris(int(n["offset"]))

    def area(b):
        return _area(nodes[b]["lo"], nodes[b]["hi"])

    @cache
    def cover(b, i):         # best cost of subtree b in at most i slots
        n = nodes[b]
        leaf = area(b) * group_cost * -(-tris(b) // 8)
        if n["count"]:
            return leaf
        best = min(leaf if tris(b) <= merged else np.inf, area(b) + below(b))
        for j in range(2, i + 1):
            best = min(best, split(b, j))
        return best

    def split(b, j):
        return min(cover(b + 1, k) + cover(int(nodes[b]["offset"]), j - k) for k in range(1, j))

    @cache
    def below(b):
        return split(b, 8)

    root = cover(0, 1) if nodes[0]["count"] else area(0) + below(0)
    if nodes[0]["count"]:
        root += area(0)
    return root / area(0)


def emitted_sah(w, group_cost):
    """The SAH cost of the tree as written: node tests plus group tests, by area."""
    total = 0.0
    for node in w.nodes:
        live = node["lo"][0] <= node["hi"][0]
        total += _area(node["lo"][:, live].min(axis=1), node["hi"][:, live].max(axis=1))
        for k in np.flatnonzero((node["child"] < 0) & live):
            total += _area(node["lo"][:, k], node["hi"][:, k]) * group_cost * node["count"][k]
    root = w.nodes[0]
    live = root["lo"][0] <= root["hi"][0]
    return total / _area(root["lo"][:, live].min(axis=1), root["hi"][:, live].max(axis=1))


@pytest.mark.parametrize("max_leaf, group_cost, merged", [(1, 1.0, 16), (4, 0.3, 40),
                                                          (8, 3.0, 8)])
def test_collapse_is_sah_optimal(rng, max_leaf, group_cost, merged):
    V, F = soup(rng, 300)
    bvh = BVH(V, F, max_leaf=max_leaf)
    w = bvh.collapse8(group_cost, merged)
    assert w.sah_cost == pytest.approx(reference_sah(bvh, group_cost, merged), rel=1e-9)
    assert w.sah_cost == pytest.approx(emitted_sah(w, group_cost), rel=1e-5)


def test_single_leaf_scene():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], F32)
    F = np.array([[0, 1, 2]], np.int32)
    bvh = BVH(V, F)
    rays = batch([[0.2, 0.2, 1], [2, 2, 1]], [[0, 0, -1], [0, 0, -1]])
    hits, c = trace(bvh, rays)
    assert hits.prim.tolist() == [0, -1]
    assert_same_hits(hits, brute_force(V, F, rays), "one triangle")
