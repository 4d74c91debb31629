"""BVH structure invariants, refit and parameter/mesh validation (raysort.bvh).

Every structural property is checked against values recomputed here from the
mesh with NumPy (float32 min/max of the vertices, a fresh walk of the node
array), never against an earlier output of the builder.  The structure checked
here is the plain binned-SAH tree's (``PLAIN``: each triangle in one leaf, boxes
of whole triangles); the default tree's spatial splits are test_bvh_spatial.py's.
"""
import numpy as np
import pytest

import raysort
from raysort.bvh import BVH, NODE_DTYPE, PRESETS, TRI_DTYPE
from raysort.errors import ConfigError, SceneError
from raysort.rays import gather, scatter
from raysort.reference import brute_force

from _helpers import assert_same_hits, exact_traversals, random_rays


#: the plain binned-SAH tree, without the default's spatial splits
PLAIN = {"spatial_splits": 0.0}


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------

def triangle_soup(rng, m, *, degenerate=0.05):
    """``m`` random triangles of mixed sizes in [0, 10]^3, some of them zero-area."""
    centres = rng.random((m, 1, 3)) * 10
    sizes = rng.choice([0.02, 0.3, 2.0], size=(m, 1, 1))
    V = (centres + rng.normal(size=(m, 3, 3)) * sizes).reshape(-1, 3).astype(np.float32)
    F = np.arange(3 * m, dtype=np.int32).reshape(m, 3)
    bad = np.flatnonzero(rng.random(m) < degenerate)
    F[bad[::2], 2] = F[bad[::2], 1]                       # repeated vertex: a segment
    F[bad[1::2], 1:] = F[bad[1::2], :1]                   # all three equal: a point
    return V, F


def real_depth(nodes):
    """Number of levels, found by walking the depth-first array level by level."""
    frontier, levels = np.array([0]), 0
    while len(frontier):
        levels += 1
        inner = frontier[nodes["count"][frontier] == 0]
        frontier = np.concatenate([inner + 1, nodes["offset"][inner]])
    return levels


def check_structure(bvh, V, F, max_leaf):
    """Assert every invariant of a built (or refitted) BVH over mesh (V, F)."""
    V = np.asarray(V, np.float32)
    nodes, tris, m = bvh.nodes, bvh.triangles, len(F)
    n = len(nodes)
    assert nodes.dtype == NODE_DTYPE and tris.dtype == TRI_DTYPE
    assert 1 <= n <= 2 * m - 1
    count, offset = nodes["count"].astype(np.int64), nodes["offset"].astype(np.int64)
    idx = np.arange(n)
    inner, leaf = idx[count == 0], idx[count > 0]
    assert (nodes["flags"] == 0).all()

    # depth-first layout: left child = i + 1, right child > i + 1 (after the left subtree)
    right = offset[inner]
    assert (right > inner + 1).all() and (right < n).all()
    assert (nodes["axis"][inner] <= 2).all()
    children = np.sort(np.concatenate([inner + 1, right]))
    assert np.array_equal(children, np.arange(1, n)), "every node but the root has one parent"
    assert len(leaf) == len(inner) + 1                    # a full binary tree

    # every triangle appears exactly once in the leaves
    assert (offset[leaf] >= 0).all() and (offset[leaf] + count[leaf] <= m).all()
    slots = np.concatenate([np.arange(o, o + c) for o, c in zip(offset[leaf], count[leaf])])
    assert np.array_equal(np.sort(slots), np.arange(m))
    assert np.array_equal(np.sort(bvh.order), np.arange(m))
    assert np.array_equal(tris["id"], bvh.order)
    for o, c in zip(offset[leaf], count[leaf]):
        ids = tris["id"][o:o + c]
        assert (np.diff(ids) > 0).all(), "a leaf's triangles are sorted by input index"

    # the stored triangles are the mesh's, in float32 (v0, v1 - v0, v2 - v0); a degenerate
    # triangle (sine of its angle <= 2**-20 by the float64 law of sines, zero area
    # included) may instead store zero edges, so that it is never hit
    tv = V[F[bvh.order]]                                  # (m, 3 corners, 3)
    assert np.array_equal(tris["v0"], tv[:, 0])
    e1, e2 = tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]
    tv64 = tv.astype(np.float64)
    a64, b64 = tv64[:, 1] - tv64[:, 0], tv64[:, 2] - tv64[:, 0]
    norms = np.linalg.norm(a64, axis=1) * np.linalg.norm(b64, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sine = np.where(norms > 0, np.linalg.norm(np.cross(a64, b64), axis=1) / norms, 0.0)
    flat = sine <= 2.0 ** -20 * (1 + 1e-9)
    same = (tris["e1"] == e1).all(axis=1) & (tris["e2"] == e2).all(axis=1)
    zeroed = (tris["e1"] == 0).all(axis=1) & (tris["e2"] == 0).all(axis=1)
    assert (same | (flat & zeroed)).all(), np.flatnonzero(~(same | (flat & zeroed)))[:5]

    # leaf boxes: exactly the min/max of their triangles' float32 vertices
    tlo, thi = tv.min(axis=1), tv.max(axis=1)
    by_start = leaf[np.argsort(offset[leaf])]
    starts = offset[by_start]
    assert np.array_equal(nodes["lo"][by_start], np.minimum.reduceat(tlo, starts, axis=0))
    assert np.array_equal(nodes["hi"][by_start], np.maximum.reduceat(thi, starts, axis=0))
    # inner boxes: exactly the union of the two children's boxes
    lo, hi = nodes["lo"], nodes["hi"]
    assert np.array_equal(lo[inner], np.minimum(lo[inner + 1], lo[right]))
    assert np.array_equal(hi[inner], np.maximum(hi[inner + 1], hi[right]))
    used = V[F.reshape(-1)]
    assert np.array_equal(bvh.bounds, np.stack([used.min(axis=0), used.max(axis=0)]))

    # leaf size: at most max_leaf, unless all the leaf's centroids coincide
    cent = np.float32(0.5) * tlo + np.float32(0.5) * thi
    for o, c in zip(offset[leaf], count[leaf]):
        if c > max_leaf:
            assert (cent[o:o + c] == cent[o]).all(), f"leaf of {c} > max_leaf={max_leaf}"

    assert bvh.depth == real_depth(nodes)
    stats = bvh.stats()
    assert stats["nodes"] == n and stats["leaves"] == len(leaf)
    assert stats["depth"] == bvh.depth and stats["max_leaf_size"] == count[leaf].max()


def trace(name, bvh, rays, size, rng):
    """Closest hits of ``rays`` with traversal ``name`` in random sub-packets of ``size``."""
    n = len(rays)
    order = rng.permutation(n).astype(np.int32)
    offsets = np.append(np.arange(0, n, size), n).astype(np.int32)
    packets = gather(rays, order, offsets)
    raysort.create("traversals", name).intersect(bvh, packets)
    return scatter(packets, n)


# ---------------------------------------------------------------------------
# structure
# ---------------------------------------------------------------------------

def test_real_scene_structure(real_scene):
    """Sibenik and Sponza build (the default parameters but spatial splits) into a valid,
    tight, depth-first BVH."""
    bvh = BVH(real_scene.vertices, real_scene.faces, **PLAIN)
    check_structure(bvh, real_scene.vertices, real_scene.faces, max_leaf=8)


def test_sibenik_builds_with_other_parameters(sibenik):
    """Sibenik also builds with max_leaf=1, few bins and a high traversal cost."""
    for params in ({"max_leaf": 1}, {"bins": 2, "max_leaf": 4}, {"traversal_cost": 8.0}):
        bvh = BVH(sibenik.vertices, sibenik.faces, **params, **PLAIN)
        check_structure(bvh, sibenik.vertices, sibenik.faces, params.get("max_leaf", 8))


def test_manta_preset_builds_big_leaves_and_keeps_hits_exact(sibenik, rng):
    """The "manta" preset (Table I's proportions) builds a valid tree with leaves of tens
    of triangles; every exact traversal still returns brute force's hits on it."""
    bvh = BVH(sibenik.vertices, sibenik.faces, preset="manta")
    check_structure(bvh, sibenik.vertices, sibenik.faces, PRESETS["manta"]["max_leaf"])
    default = BVH(sibenik.vertices, sibenik.faces)
    assert bvh.stats()["mean_leaf_size"] > 10 * default.stats()["mean_leaf_size"]
    assert (bvh.max_leaf, bvh.traversal_cost) == (PRESETS["manta"]["max_leaf"],
                                                 PRESETS["manta"]["traversal_cost"])
    rays = random_rays(rng, 256, bvh.bounds)
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    for name in exact_traversals():
        assert_same_hits(trace(name, bvh, rays, 64, rng), ref, f"{name} on manta leaves")


def test_preset_parameters_are_overridden_by_given_ones():
    bvh = BVH(TRI_V, TRI_F, preset="manta", max_leaf=4)
    assert (bvh.preset, bvh.max_leaf, bvh.bins) == ("manta", 4, PRESETS["manta"]["bins"])
    assert BVH(TRI_V, TRI_F).max_leaf == PRESETS["default"]["max_leaf"]


@pytest.mark.parametrize("preset", ["nope", None, 3, ""])
def test_unknown_preset_names_the_presets(preset):
    with pytest.raises(ConfigError, match="unknown preset .*presets: default, manta"):
        BVH(TRI_V, TRI_F, preset=preset)


def test_pipeline_takes_a_preset(sibenik):
    pipe = raysort.Pipeline(sibenik, bvh={"preset": "manta"})
    assert pipe.bvh.preset == "manta"
    with pytest.raises(ConfigError, match="unknown preset"):
        raysort.Pipeline(sibenik, bvh={"preset": "nope"}).bvh  # noqa: B018


@pytest.mark.parametrize("max_leaf,bins,cost", [
    (1, 16, 1.0), (2, 1, 1.0), (4, 64, 1.0), (8, 16, 1.0), (8, 3, 20.0), (16, 7, 0.25)])
def test_random_soup_structure(rng, max_leaf, bins, cost):
    """Random soups (with zero-area triangles) satisfy every invariant for any parameters."""
    for m in (1, 2, 3, 17, 500):
        V, F = triangle_soup(rng, m)
        bvh = BVH(V, F, max_leaf=max_leaf, bins=bins, traversal_cost=cost, **PLAIN)
        check_structure(bvh, V, F, max_leaf)


def test_single_triangle_is_a_leaf_root():
    """One triangle: the root is a leaf holding it, one level deep, boxed by its vertices."""
    V = np.array([[0, 0, 0], [1, 2, 0], [0, 1, 3]], np.float32)
    bvh = BVH(V, [[0, 1, 2]])
    assert len(bvh.nodes) == 1 and bvh.depth == 1
    root = bvh.nodes[0]
    assert (root["count"], root["offset"]) == (1, 0)
    assert root["lo"].tolist() == [0, 0, 0] and root["hi"].tolist() == [1, 2, 3]


def test_two_far_triangles_split():
    """Two far-apart triangles with max_leaf=1: root + 2 leaves, the lower x on the left."""
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    V = np.vstack([tri + [10, 0, 0], tri]).astype(np.float32)   # face 0 is the far one
    bvh = BVH(V, [[0, 1, 2], [3, 4, 5]], max_leaf=1)
    check_structure(bvh, V, np.array([[0, 1, 2], [3, 4, 5]]), 1)
    nodes = bvh.nodes
    assert len(nodes) == 3 and bvh.depth == 2
    assert nodes[0]["count"] == 0 and nodes[0]["axis"] == 0 and nodes[0]["offset"] == 2
    assert bvh.triangles["id"][nodes[1]["offset"]] == 1          # x in [0, 1]
    assert bvh.triangles["id"][nodes[2]["offset"]] == 0          # x in [10, 11]


def test_coincident_centroids():
    """Many triangles with one common centroid still give a valid BVH holding each once."""
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    corners = []
    for a in angles:
        r = np.array([np.cos(a), np.sin(a), 0.0])
        corners += [r, -r, [0.0, 0.0, 1.0]]          # box centre (0, 0, 0.5) for all
    V = np.array(corners, np.float32)
    F = np.arange(len(V), dtype=np.int32).reshape(-1, 3)
    for max_leaf in (1, 4, 8):
        bvh = BVH(V, F, max_leaf=max_leaf, **PLAIN)
        check_structure(bvh, V, F, max_leaf)


def test_duplicate_triangles():
    """The same triangle repeated 50 times (identical boxes) is stored 50 times."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    F = np.zeros((50, 3), np.int32) + [0, 1, 2]
    bvh = BVH(V, F, max_leaf=3, **PLAIN)
    check_structure(bvh, V, F, 3)


# ---------------------------------------------------------------------------
# refit
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("motion", ["affine", "jitter"])
def test_refit_soup(rng, motion):
    """Refit after moving vertices gives tight boxes on the new mesh and brute-force hits."""
    V, F = triangle_soup(rng, 400)
    bvh = BVH(V, F, max_leaf=4, **PLAIN)
    before = bvh.nodes[["offset", "count", "axis"]].copy()
    order, depth = bvh.order.copy(), bvh.depth
    if motion == "affine":
        W = (V * np.float32([1.5, 0.5, 2.0]) + np.float32([3, -7, 0.25])).astype(np.float32)
    else:
        W = (V + rng.normal(size=V.shape) * 0.7).astype(np.float32)
    bvh.refit(W)
    # the topology is kept; only boxes and triangles move
    assert np.array_equal(bvh.nodes[["offset", "count", "axis"]], before)
    assert np.array_equal(bvh.order, order) and bvh.depth == depth
    assert np.array_equal(bvh.vertices, W)
    check_structure(bvh, W, F, 4)
    assert not np.array_equal(bvh.bounds, BVH(V, F).bounds)

    rays = random_rays(rng, 1500, bvh.bounds)
    ref = brute_force(W, F, rays)
    assert (ref.prim >= 0).sum() > 100
    for name in exact_traversals():
        assert_same_hits(trace(name, bvh, rays, 16, rng), ref, f"{name} after refit")


def test_refit_real_scene(sibenik, rng):
    """Refit of Sibenik after a translate + scale keeps every box tight and hits exact."""
    V, F = sibenik.vertices, sibenik.faces
    bvh = BVH(V, F, **PLAIN)
    W = (V * np.float32(0.75) + np.float32([1, 2, -3])).astype(np.float32)
    bvh.refit(W)
    check_structure(bvh, W, F, 8)
    rays = random_rays(rng, 256, bvh.bounds)
    ref = brute_force(W, F, rays)
    for name in exact_traversals():
        assert_same_hits(trace(name, bvh, rays, 64, rng), ref, f"{name} after refit")


def test_refit_back_restores_the_build(rng):
    """Moving the vertices away and back gives exactly the boxes of the original build."""
    V, F = triangle_soup(rng, 200)
    bvh = BVH(V, F, **PLAIN)
    original = bvh.nodes.copy(), bvh.triangles.copy()
    bvh.refit((V * 3 - 1).astype(np.float32))
    bvh.refit(V)
    assert bvh.nodes.tobytes() == original[0].tobytes()
    assert bvh.triangles.tobytes() == original[1].tobytes()


def test_refit_rejects_bad_vertices(rng):
    """Refit with a NaN vertex or too few vertices raises SceneError."""
    V, F = triangle_soup(rng, 20)
    bvh = BVH(V, F)
    W = V.copy()
    W[5, 1] = np.nan
    with pytest.raises(SceneError):
        bvh.refit(W)
    with pytest.raises(SceneError):
        bvh.refit(V[:-1])


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------

TRI_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
TRI_F = np.array([[0, 1, 2]], np.int32)


@pytest.mark.parametrize("params", [
    {"max_leaf": 0}, {"max_leaf": -1}, {"max_leaf": 65536}, {"max_leaf": 2.5},
    {"bins": 0}, {"bins": 65}, {"bins": -3}, {"bins": 4.0},
    {"traversal_cost": 0}, {"traversal_cost": -1.0}, {"traversal_cost": float("nan")},
    {"traversal_cost": 1001}, {"traversal_cost": "1"},
])
def test_bad_parameters(params):
    """Out-of-range or mistyped build parameters raise ConfigError naming the parameter."""
    with pytest.raises(ConfigError, match=next(iter(params))):
        BVH(TRI_V, TRI_F, **params)


@pytest.mark.parametrize("params", [
    {"max_leaf": 1}, {"max_leaf": 65535}, {"bins": 1}, {"bins": 64},
    {"traversal_cost": 1000}, {"traversal_cost": 1e-3}, {"max_leaf": np.int64(3)}])
def test_boundary_parameters_accepted(params):
    """The ends of every parameter range are accepted."""
    assert len(BVH(TRI_V, TRI_F, **params).nodes) == 1


def _nan_vertex():
    V = TRI_V.copy()
    V[1, 2] = np.nan
    return V, TRI_F


def _inf_vertex():
    V = TRI_V.copy()
    V[2, 0] = -np.inf
    return V, TRI_F


@pytest.mark.parametrize("mesh", [
    lambda: (TRI_V, np.zeros((0, 3), np.int32)),          # no faces
    _nan_vertex,
    _inf_vertex,
    lambda: (TRI_V, np.array([[0, 1, 3]], np.int32)),     # index == len(vertices)
    lambda: (TRI_V, np.array([[0, -1, 2]], np.int32)),    # negative index
    lambda: (TRI_V[:, :2], TRI_F),                        # 2-D vertices
    lambda: (TRI_V, np.array([[0, 1, 2, 0]], np.int32)),  # quads
], ids=["no-faces", "nan-vertex", "inf-vertex", "index-too-large", "negative-index",
        "vertices-2d", "faces-4"])
def test_bad_meshes(mesh):
    """Unusable meshes raise SceneError (not a crash or a silent wrong tree)."""
    V, F = mesh()
    with pytest.raises(SceneError):
        BVH(V, F)



# ---------------------------------------------------------------------------
# the 4-wide collapse used by the ``wide`` traversal
# ---------------------------------------------------------------------------

def _check_wide(bvh):
    nodes, wide = bvh.nodes, bvh.wide
    assert wide.dtype == raysort.bvh.NODE4_DTYPE and wide.ctypes.data % 16 == 0
    leaf = nodes["count"] > 0
    binary_leaves = sorted(zip(nodes["offset"][leaf].tolist(), nodes["count"][leaf].tolist()))
    leaf_at = dict(zip(nodes["offset"][leaf].tolist(), np.flatnonzero(leaf).tolist()))
    wide_leaves, inner_refs, depth = [], [], {0: 1}
    for w, node in enumerate(wide):
        for k in range(4):
            child, count = int(node["child"][k]), int(node["count"][k])
            lo, hi = node["lo"][:, k], node["hi"][:, k]
            if child < 0:
                wide_leaves.append((-child - 1, count))
                # a leaf child's box is exactly its binary leaf's: in the plain tree the
                # box of its triangles (with spatial splits, of their parts in the leaf)
                b = leaf_at[-child - 1]
                assert np.array_equal(lo, nodes["lo"][b]) and np.array_equal(hi, nodes["hi"][b])
                if bvh.references == len(bvh.faces):
                    tv = bvh.vertices[bvh.faces[bvh.order[-child - 1:-child - 1 + count]]]
                    assert np.array_equal(lo, tv.reshape(-1, 3).min(axis=0))
                    assert np.array_equal(hi, tv.reshape(-1, 3).max(axis=0))
            elif child > 0:
                assert count == 0 and child > w, "children follow their parent"
                inner_refs.append(child)
                depth[child] = depth[w] + 1
                # an inner child's box contains the boxes of its own children
                sub = wide[child]
                used = (sub["child"] != 0) | (sub["count"] > 0)
                assert (sub["lo"][:, used] >= lo[:, None]).all()
                assert (sub["hi"][:, used] <= hi[:, None]).all()
            else:                                     # an empty slot: nothing enters
                assert count == 0 and (lo == np.inf).all() and (hi == -np.inf).all()
    assert sorted(wide_leaves) == binary_leaves, "every leaf range exactly once"
    assert sorted(inner_refs) == list(range(1, len(wide))), "every node has one parent"
    assert bvh.wide_depth == max(depth.values()) <= bvh.depth


def test_wide_collapse_of_real_scenes(sibenik, sponza):
    for scene in (sibenik, sponza):
        _check_wide(scene.bvh())                    # the default: with spatial splits
        _check_wide(BVH(scene.vertices, scene.faces, **PLAIN))


def test_wide_collapse_of_tiny_trees():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5]], np.float32)
    one = BVH(V[:3], np.array([[0, 1, 2]], np.int32))           # the root is a leaf
    _check_wide(one)
    assert len(one.wide) == 1 and one.wide[0]["child"][0] == -1
    two = BVH(V, np.array([[0, 1, 2], [3, 4, 5]], np.int32), max_leaf=1)
    _check_wide(two)
    assert len(two.wide) == 1 and sorted(two.wide[0]["count"].tolist()) == [0, 0, 1, 1]


def test_wide_follows_a_refit(sibenik):
    bvh = BVH(sibenik.vertices, sibenik.faces)
    before = bvh.wide.copy()
    bvh.refit(sibenik.vertices * np.float32(2))
    _check_wide(bvh)
    assert not np.array_equal(bvh.wide["hi"], before["hi"])


# -- the tree cannot be edited --------------------------------------------------------

def _tree_arrays(bvh):
    return {"nodes": bvh.nodes, "triangles": bvh.triangles, "order": bvh.order,
            "bounds": bvh.bounds, "vertices": bvh.vertices, "faces": bvh.faces,
            "wide": bvh.wide, "wide8.nodes": bvh.wide8.nodes, "wide8.groups": bvh.wide8.groups,
            "wide16.nodes": bvh.wide16.nodes}


@pytest.mark.parametrize("refitted", [False, True])
def test_the_tree_cannot_be_edited(rng, refitted):
    """The kernels trust a BVH's arrays (an edited child index or triangle offset made
    them read out of bounds): every array is read-only, NumPy refuses to make it
    writeable, and the tree's attributes cannot be assigned, also after a refit."""
    vertices = rng.uniform(-1, 1, (90, 3)).astype(np.float32)
    faces = np.arange(90, dtype=np.int32).reshape(30, 3)
    bvh = BVH(vertices, faces)
    if refitted:
        bvh.refit(vertices * 2)
    rays = random_rays(rng, 64, bvh.bounds)
    for name, array in _tree_arrays(bvh).items():
        assert not array.flags.writeable, name
        with pytest.raises(ValueError):
            array.flags.writeable = True
        with pytest.raises(ValueError, match="read-only"):
            array.view(np.uint8)[...] = 0
    for name in ("nodes", "triangles", "order", "depth", "bounds", "vertices", "faces",
                 "wide", "wide8", "wide16", "wide_depth"):
        with pytest.raises(AttributeError):
            setattr(bvh, name, getattr(bvh, name))
    with pytest.raises(AttributeError):
        bvh.wide8.nodes = bvh.wide8.nodes
    # and the arrays the kernels read still give brute force's hits
    for traversal in ("wide8", "stream", "ranged"):
        order = np.arange(len(rays), dtype=np.int32)
        offsets = np.arange(0, len(rays) + 1, 16, dtype=np.int32)
        packets = gather(rays, order, offsets)
        raysort.create("traversals", traversal).intersect(bvh, packets, any_hit=False)
        assert_same_hits(scatter(packets, len(rays)),
                         brute_force(bvh.vertices, bvh.faces, rays))


def test_a_copy_of_an_array_is_the_callers():
    """Reading is unchanged: a copy of a tree array is an ordinary writeable array."""
    bvh = BVH(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.int32))
    nodes = bvh.nodes.copy()
    nodes["count"] = 0
    assert bvh.nodes["count"][0] == 1
