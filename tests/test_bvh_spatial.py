"""Spatial splits (SBVH): tree invariants, exact hits of every traversal, SAH, refit.

With ``spatial_splits`` > 0 a triangle may be referenced by several leaves, each
holding the part of it inside the leaf's box.  The checks recompute everything
from the mesh with NumPy: every triangle is referenced, every point of every
triangle lies in the box of a leaf that references it, the references stay
within the budget, and every exact traversal returns brute force's hits bit for
bit (raysort.reference) on every ISA the CPU runs.
"""
import numpy as np
import pytest

import raysort
from raysort.bvh import BVH, MAX_SPATIAL_SPLITS, PRESETS
from raysort.errors import ConfigError
from raysort.rays import gather, scatter_occluded
from raysort.reference import brute_force

from _helpers import (assert_same_hits, batch, exact_traversals, grid_scene, grid_tie_rays,
                      random_rays)
from test_bvh import real_depth, trace, triangle_soup

F32 = np.float32


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------

#: barycentric sample points on a triangle: corners, points along the edges, inside
SAMPLES = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [.5, .5, 0], [0, .5, .5], [.5, 0, .5],
                    [.9, .1, 0], [0, .1, .9], [.1, 0, .9], [.33, .33, .34], [.8, .1, .1],
                    [.1, .8, .1], [.1, .1, .8], [.6, .3, .1], [.05, .15, .8]])


def leaf_of_references(nodes):
    """For each reference position, the index of the leaf holding it."""
    leaf = np.flatnonzero(nodes["count"] > 0)
    leaf = leaf[np.argsort(nodes["offset"][leaf])]
    return np.repeat(leaf, nodes["count"][leaf].astype(np.int64))


def check_spatial_structure(bvh, V, F, budget, max_leaf=None):
    """Assert every invariant of a BVH built with spatial splits over mesh (V, F)."""
    V = np.asarray(V, F32)
    F = np.asarray(F, np.int32)
    nodes, tris, order, m = bvh.nodes, bvh.triangles, bvh.order, len(F)
    n, refs = len(nodes), len(order)
    count, offset = nodes["count"].astype(np.int64), nodes["offset"].astype(np.int64)
    idx = np.arange(n)
    inner, leaf = idx[count == 0], idx[count > 0]

    # a full binary tree laid out depth first, leaves tiling the references in order
    right = offset[inner]
    assert (right > inner + 1).all() and (right < n).all()
    assert np.array_equal(np.sort(np.concatenate([inner + 1, right])), np.arange(1, n))
    assert len(leaf) == len(inner) + 1
    by_start = leaf[np.argsort(offset[leaf])]
    assert np.array_equal(offset[by_start], np.concatenate([[0], np.cumsum(count[by_start])[:-1]]))
    assert count[leaf].sum() == refs == bvh.references == bvh.stats()["references"]
    assert bvh.depth == real_depth(nodes)
    if max_leaf is not None:
        assert count[leaf].max() <= max_leaf

    # every triangle referenced, at most once per leaf, sorted there; within the budget
    assert np.array_equal(np.unique(order), np.arange(m)), "a triangle is in no leaf"
    assert m <= refs <= m + int(budget * m), (refs, m, budget)
    assert np.array_equal(tris["id"], order)
    assert np.array_equal(tris["v0"], V[F[order, 0]])
    for o, c in zip(offset[leaf], count[leaf]):
        assert (np.diff(order[o:o + c]) > 0).all(), "a leaf's triangles are sorted, unique"

    # boxes: inner = union of children; a leaf's box meets each of its triangles' boxes
    # and lies inside their union
    lo, hi = nodes["lo"], nodes["hi"]
    assert np.array_equal(lo[inner], np.minimum(lo[inner + 1], lo[right]))
    assert np.array_equal(hi[inner], np.maximum(hi[inner + 1], hi[right]))
    tv = V[F]
    tlo, thi = tv.min(axis=1), tv.max(axis=1)
    owner = leaf_of_references(nodes)
    assert (lo[owner] <= thi[order]).all() and (hi[owner] >= tlo[order]).all()
    starts = offset[by_start]
    assert (lo[by_start] >= np.minimum.reduceat(tlo[order], starts, axis=0)).all()
    assert (hi[by_start] <= np.maximum.reduceat(thi[order], starts, axis=0)).all()
    used = V[F.reshape(-1)]
    assert np.array_equal(bvh.bounds, np.stack([used.min(axis=0), used.max(axis=0)]))

    # the leaves referencing a triangle cover it: each sample point (float64) lies in
    # one of their boxes (a tolerance of double rounding only)
    points = np.einsum("kc,tcd->tkd", SAMPLES, tv.astype(np.float64))      # (m, k, 3)
    tol = 2.0 ** -40 * (1 + np.abs(used).max())
    by_tri = np.argsort(order, kind="stable")
    p = points[order[by_tri]]                                              # (refs, k, 3)
    box_lo = lo[owner[by_tri]][:, None, :].astype(np.float64)
    box_hi = hi[owner[by_tri]][:, None, :].astype(np.float64)
    inside = ((p >= box_lo - tol) & (p <= box_hi + tol)).all(axis=2)       # (refs, k)
    first = np.searchsorted(order[by_tri], np.arange(m))
    covered = np.logical_or.reduceat(inside, first, axis=0)
    bad = np.argwhere(~covered)
    assert len(bad) == 0, f"triangle {bad[0][0]}: sample {bad[0][1]} lies in no leaf box"


def assert_exact(bvh, V, F, rays, rng, label):
    """Every exact traversal gives brute force's closest hits and any-hit flags."""
    ref = brute_force(V, F, rays)
    occluded = brute_force(V, F, rays, any_hit=True)
    for name in exact_traversals():
        for size in (64, 13):
            assert_same_hits(trace(name, bvh, rays, size, rng), ref, f"{label}: {name}")
        n = len(rays)
        packets = gather(rays, np.arange(n, dtype=np.int32), np.array([0, n], np.int32))
        raysort.create("traversals", name).intersect(bvh, packets, any_hit=True)
        assert np.array_equal(scatter_occluded(packets, n), occluded), f"{label}: {name} any"


def diagonal_slivers(m=200, width=0.01):
    """``m`` long thin parallel triangles, each along the whole diagonal of the unit cube
    (side by side, 0.05 apart in all): every one's box is nearly the root's."""
    s = np.linspace(0, 0.05, m)[:, None]
    v0 = np.hstack([s, -s, 0 * s])
    v1 = v0 + [1, 1, 1]
    v2 = v1 + [width, 0, 0]
    V = np.stack([v0, v1, v2], axis=1).reshape(-1, 3).astype(F32)
    return V, np.arange(3 * m, dtype=np.int32).reshape(m, 3)


def needles(rng, m=300):
    """Long, thin triangles in random directions through [0, 10]^3, with small ones."""
    a = rng.random((m, 3)) * 10
    b = rng.random((m, 3)) * 10
    c = b + rng.normal(size=(m, 3)) * 0.02
    long_ = np.stack([a, b, c], axis=1)
    V2, F2 = triangle_soup(rng, m, degenerate=0.0)
    V = np.vstack([long_.reshape(-1, 3), V2]).astype(F32)
    return V, np.vstack([np.arange(3 * m).reshape(m, 3), F2 + 3 * m]).astype(np.int32)


def big_triangle_scene(rng):
    """One triangle spanning the whole scene over a soup of small ones."""
    V, F = triangle_soup(rng, 400, degenerate=0.0)
    big = np.array([[-1, -1, 5], [30, -1, 5], [-1, 30, 4]], F32)
    return (np.vstack([V, big]).astype(F32),
            np.vstack([F, [[len(V), len(V) + 1, len(V) + 2]]]).astype(np.int32))


# ---------------------------------------------------------------------------
# structure
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("budget", [None, 0.5, MAX_SPATIAL_SPLITS])
def test_real_scene_structure(real_scene, budget):
    """Sibenik and Sponza with spatial splits (None: the default build's): every
    invariant, references within budget, and some triangles referenced twice or more."""
    V, F = real_scene.vertices, real_scene.faces
    bvh = BVH(V, F, spatial_splits=budget)
    budget = PRESETS["default"]["spatial_splits"] if budget is None else budget
    assert bvh.spatial_splits == budget > 0
    check_spatial_structure(bvh, V, F, budget, max_leaf=8)
    assert bvh.references > len(F)


@pytest.mark.parametrize("max_leaf,bins,alpha", [
    (1, 16, 1e-5), (2, 1, 1e-5), (4, 64, 0.0), (8, 3, 1e-3), (16, 7, 1.0)])
def test_soups_structure(rng, max_leaf, bins, alpha):
    """Random soups (zero-area triangles too), needles, a scene-sized triangle and
    diagonal slivers satisfy every invariant for any parameters."""
    scenes = [triangle_soup(rng, m) for m in (1, 2, 3, 17, 500)]
    scenes += [needles(rng), big_triangle_scene(rng), diagonal_slivers()]
    for V, F in scenes:
        for budget in (0.25, MAX_SPATIAL_SPLITS):
            bvh = BVH(V, F, max_leaf=max_leaf, bins=bins, spatial_splits=budget,
                      split_alpha=alpha)
            check_spatial_structure(bvh, V, F, budget, max_leaf=max_leaf)


def test_alpha_one_or_no_budget_gives_the_plain_tree(rng):
    """split_alpha=1 (no node's overlap exceeds the root's area) or a budget too small for
    one more reference: no spatial split, the same tree as without."""
    V, F = needles(rng)
    plain = BVH(V, F, spatial_splits=0)
    for params in ({"spatial_splits": 1.0, "split_alpha": 1.0},
                   {"spatial_splits": 0.5 / len(F)}):
        bvh = BVH(V, F, **params)
        assert bvh.references == len(F)
        for a in ("nodes", "order", "triangles"):
            assert getattr(bvh, a).tobytes() == getattr(plain, a).tobytes(), (params, a)


def test_degenerate_and_coincident_triangles():
    """All-degenerate meshes (points, segments, a repeated triangle) still build and hold
    every triangle."""
    V = np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [0, 3, 0], [3, 0, 0]], F32)
    meshes = [np.array([[0, 1, 2], [1, 1, 1], [0, 0, 2], [3, 4, 3], [2, 1, 0]] * 20),
              np.array([[0, 3, 4]] * 40)]
    for F in meshes:
        for max_leaf in (1, 4):
            bvh = BVH(V, F.astype(np.int32), max_leaf=max_leaf, spatial_splits=1.0,
                      split_alpha=0.0)
            check_spatial_structure(bvh, V, F, 1.0)


# ---------------------------------------------------------------------------
# SAH
# ---------------------------------------------------------------------------

def test_spatial_splits_beat_any_object_split_tree_on_diagonal_slivers():
    """Slivers along the cube's diagonal: without spatial splits every leaf holding one
    whole has at least its box's area, so the leaves alone cost at least
    sum(triangle box area) / root area; spatial splits cut them and go below that
    bound, and below the plain tree's cost."""
    V, F = diagonal_slivers()
    tv = V[F].astype(np.float64)
    ext = tv.max(axis=1) - tv.min(axis=1)
    area = (ext[:, 0] * ext[:, 1] + ext[:, 1] * ext[:, 2] + ext[:, 2] * ext[:, 0])
    plain = BVH(V, F)
    root = plain.bounds[1].astype(np.float64) - plain.bounds[0]
    bound = area.sum() / (root[0] * root[1] + root[1] * root[2] + root[2] * root[0])
    assert plain.stats()["sah_cost"] >= bound * (1 - 1e-6)
    for budget in (1.0, MAX_SPATIAL_SPLITS):
        sbvh = BVH(V, F, spatial_splits=budget)
        assert sbvh.stats()["sah_cost"] < bound, budget
        assert sbvh.wide8.sah_cost < plain.wide8.sah_cost


# ---------------------------------------------------------------------------
# exact hits
# ---------------------------------------------------------------------------

def test_real_scene_hits_match_brute_force(real_scene, workloads, rng):
    """First-bounce diffuse and random rays of Sibenik and Sponza through an SBVH."""
    V, F = real_scene.vertices, real_scene.faces
    bvh = BVH(V, F, spatial_splits=0.5)
    diffuse = workloads(real_scene, "diffuse").rays
    diffuse = diffuse.take(rng.choice(len(diffuse), 768, replace=False))
    assert_exact(bvh, V, F, diffuse, rng, f"{real_scene.name} diffuse")
    assert_exact(bvh, V, F, random_rays(rng, 768, bvh.bounds), rng, f"{real_scene.name} random")


def test_adversarial_hits_match_brute_force_on_every_isa(each_isa, rng):
    """Needles, a scene-sized triangle over a soup, diagonal slivers and a grid with ties
    and zero-area triangles, with spatial splits tried everywhere."""
    scenes = [("needles", *needles(rng)), ("big", *big_triangle_scene(rng)),
              ("slivers", *diagonal_slivers())]
    for label, V, F in scenes:
        for max_leaf in (1, 8):
            bvh = BVH(V, F, max_leaf=max_leaf, spatial_splits=2.0, split_alpha=0.0)
            assert bvh.references > len(F), label
            rays = random_rays(rng, 1500, bvh.bounds, spread=1.2)
            assert_exact(bvh, V, F, rays, rng, f"{each_isa} {label} max_leaf={max_leaf}")
    V, F = grid_scene(rng, zero_area=20)
    bvh = BVH(V, F, max_leaf=2, spatial_splits=2.0, split_alpha=0.0)
    assert bvh.references > len(F)
    assert_exact(bvh, V, F, grid_tie_rays(rng, 1500), rng, f"{each_isa} grid ties")
    # the 16 bins of the 8-unit grid put planes on its half-integer lines: rays in
    # those planes (a zero direction component, 0 * inf slabs), hitting edges and vertices
    n = 1500
    o = np.column_stack([rng.integers(0, 17, size=(n, 2)) / 2.0, np.full(n, 3.0)])
    d = np.column_stack([rng.choice([-1.0, -0.5, 0.0, 0.5, 1.0], size=(n, 2)), np.full(n, -2.0)])
    d[np.arange(n), rng.integers(0, 2, n)] = 0.0                 # stay in an x or y plane
    assert_exact(bvh, V, F, batch(o, d), rng, f"{each_isa} rays in the split planes")


@pytest.mark.parametrize("scale,offset", [(1e-3, 1e4), (1e4, -3e5), (1e-20, 1e-18)])
def test_far_small_and_huge_meshes(rng, scale, offset):
    """Needles and a scene-sized triangle moved far from the origin (float32 steps larger
    than the cuts' rounding), shrunk or grown: every invariant and exact hits."""
    for V, F in (needles(rng), big_triangle_scene(rng)):
        V = (V.astype(np.float64) * scale + offset).astype(F32)
        bvh = BVH(V, F, max_leaf=2, spatial_splits=2.0, split_alpha=0.0)
        check_spatial_structure(bvh, V, F, 2.0)
        assert bvh.references > len(F)
        assert_exact(bvh, V, F, random_rays(rng, 1000, bvh.bounds, spread=1.2), rng,
                     f"x {scale} + {offset}")


def test_all_degenerate_mesh_is_never_hit(rng):
    V = np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [0, 3, 0]], F32)
    F = np.array([[0, 1, 2], [1, 1, 1], [0, 0, 3], [3, 3, 0]] * 10, np.int32)
    bvh = BVH(V, F, max_leaf=1, spatial_splits=1.0, split_alpha=0.0)
    rays = random_rays(rng, 500, bvh.bounds)
    assert (brute_force(V, F, rays).prim == -1).all()
    assert_exact(bvh, V, F, rays, rng, "degenerate")


# ---------------------------------------------------------------------------
# refit, parameters
# ---------------------------------------------------------------------------

def test_refit_boxes_whole_triangles_and_keeps_hits_exact(rng):
    """Refit of an SBVH: each leaf's box becomes the union of its triangles' whole boxes
    (conservative), and every traversal still returns brute force's hits."""
    V, F = needles(rng)
    bvh = BVH(V, F, spatial_splits=1.0, split_alpha=0.0)
    moved = (V * F32(1.5) + rng.normal(size=V.shape).astype(F32) * F32(0.05)).astype(F32)
    bvh.refit(moved)
    nodes, order = bvh.nodes, bvh.order
    leaf = np.flatnonzero(nodes["count"] > 0)
    leaf = leaf[np.argsort(nodes["offset"][leaf])]
    tv = moved[F[order]]
    starts = nodes["offset"][leaf].astype(np.int64)
    assert np.array_equal(nodes["lo"][leaf], np.minimum.reduceat(tv.min(axis=1), starts))
    assert np.array_equal(nodes["hi"][leaf], np.maximum.reduceat(tv.max(axis=1), starts))
    assert_exact(bvh, moved, F, random_rays(rng, 1000, bvh.bounds), rng, "refit")


@pytest.mark.parametrize("params", [
    {"spatial_splits": -0.1}, {"spatial_splits": MAX_SPATIAL_SPLITS + 1},
    {"spatial_splits": float("nan")}, {"spatial_splits": "0.3"}, {"spatial_splits": True},
    {"split_alpha": -1e-5}, {"split_alpha": 1.5}, {"split_alpha": float("inf")}])
def test_bad_parameters_name_themselves(params):
    V, F = diagonal_slivers(3)
    with pytest.raises(ConfigError, match=next(iter(params))):
        BVH(V, F, **params)


def test_pipeline_and_bench_take_spatial_splits(sibenik):
    from raysort.bench.command import bvh_params

    params = bvh_params("spatial_splits=0.25,split_alpha=1e-4")
    assert params == {"spatial_splits": 0.25, "split_alpha": 1e-4}
    pipe = raysort.Pipeline(sibenik, bvh=params)
    assert (pipe.bvh.spatial_splits, pipe.bvh.split_alpha) == (0.25, 1e-4)
    assert pipe.bvh.references > len(sibenik.faces)


@pytest.mark.parametrize("traversal", ["wide8", "stream", "ranged"])
def test_renders_are_bit_identical_with_and_without_spatial_splits(sponza, traversal):
    """A whole frame (two bounces) through an SBVH is the plain tree's, bit for bit."""
    images = [raysort.Pipeline(sponza, traversal=traversal, bvh=bvh).render(40, 30, spp=2)
              .image.tobytes() for bvh in ({}, {"spatial_splits": 0.3})]
    assert images[0] == images[1]
