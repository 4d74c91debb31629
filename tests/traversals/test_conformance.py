"""Every registered exact traversal returns exactly the brute-force hits.

The traversal list comes from ``raysort.available("traversals")``, so a plugin
installed later is held to the same contract automatically (traversals that
declare ``exact = False``, such as an outside library, are held to a tolerance
in test_inexact_traversals.py instead): the same primitive,
bit-identical t and (on a hit) u, v as ``raysort.reference.brute_force``, ties to
the lower primitive index, whatever the sub-packet sizes, order and inactive
lanes, and for any-hit queries exactly the rays brute force finds a hit for.
"""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import raysort
from raysort.bvh import BVH
from raysort.rays import Hits, RayBatch, gather, scatter, scatter_occluded
from raysort.reference import brute_force

from _helpers import assert_same_hits, batch, concat, grid_scene, grid_tie_rays, random_rays

def _is_exact(name):
    try:
        return raysort.load("traversals", name).exact
    except raysort.PluginError:
        return True             # a broken plugin stays here and fails loudly


TRAVERSALS = [name for name in raysort.available("traversals") if _is_exact(name)]
F32 = np.float32

pytestmark = pytest.mark.parametrize("name", TRAVERSALS)


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------

def parallel_brute_force(V, F, rays):
    """brute_force on chunks of the batch in threads (it releases the GIL); same result."""
    n = len(rays)
    workers = max(1, min(os.cpu_count() or 1, 8))
    chunks = [c for c in np.array_split(np.arange(n), workers) if len(c)]
    with ThreadPoolExecutor(workers) as pool:
        parts = list(pool.map(lambda c: brute_force(V, F, rays.take(c)), chunks))
    hits = Hits(n)
    for c, h in zip(chunks, parts):
        hits.t[c], hits.prim[c], hits.u[c], hits.v[c] = h.t, h.prim, h.u, h.v
    return hits


def offsets_of(sizes):
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int32)


def fixed_offsets(n, size):
    return np.append(np.arange(0, n, size), n).astype(np.int32)


def random_offsets(rng, n, max_size=1024):
    """Sub-packet boundaries with random sizes in 1..max_size summing to n."""
    sizes, total = [], 0
    while total < n:
        size = int(min(rng.integers(1, max_size + 1), n - total))
        sizes.append(size)
        total += size
    return offsets_of(sizes)


def trace(name, bvh, rays, order=None, offsets=None, any_hit=False):
    """Gather ``rays`` (by default in order, one sub-packet), trace, scatter back."""
    n = len(rays)
    order = np.arange(n, dtype=np.int32) if order is None else np.asarray(order, np.int32)
    offsets = np.array([0, n], np.int32) if offsets is None else offsets
    packets = gather(rays, order, offsets)
    counters = raysort.create("traversals", name).intersect(bvh, packets, any_hit=any_hit)
    assert isinstance(counters, raysort.Counters)
    return scatter_occluded(packets, n) if any_hit else scatter(packets, n)


def take_hits(hits, index):
    """The hits of the rays ``index`` as a new Hits."""
    out = Hits(len(hits.t[index]))
    out.t[:], out.prim[:], out.u[:], out.v[:] = (hits.t[index], hits.prim[index],
                                                 hits.u[index], hits.v[index])
    return out


def boxes_scene():
    """Axis-aligned unit-ish boxes (12 triangles each) at integer coordinates, some touching."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    cube = np.array([f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))], np.int32)
    boxes = [((0, 0, 0), (1, 1, 1)), ((1, 0, 0), (2, 1, 1)), ((3, 0, 0), (4, 2, 1)),
             ((0, 2, 0), (2, 3, 2)), ((0, 0, 2), (1, 1, 4)), ((3, 3, 3), (4, 4, 4)),
             ((2, 2, 2), (3, 3, 3))]
    Vs, Fs = [], []
    for k, (lo, hi) in enumerate(boxes):
        lo, hi = np.array(lo, F32), np.array(hi, F32)
        Vs.append(lo + corners * (hi - lo))
        Fs.append(cube + 8 * k)
    return np.vstack(Vs).astype(F32), np.vstack(Fs).astype(np.int32)


def check_untouched(name, bvh, rays, order, offsets, any_hit):
    """Trace and assert that nothing but t/prim/u/v of active lanes changed."""
    packets = gather(rays, order, offsets)
    before = {a: getattr(packets, a).copy() for a in ("rows", "prim", "u", "v", "index",
                                                      "starts", "counts")}
    inactive = ~packets.active()          # padding and invalid lanes
    ray_data = rays.data.copy()
    raysort.create("traversals", name).intersect(bvh, packets, any_hit=any_hit)
    unchanged = np.array_equal(packets.rows[:10].view(np.uint32),
                               before["rows"][:10].view(np.uint32))
    assert unchanged, "origin, direction, inverse direction or tmin rows changed"
    for a in ("index", "starts", "counts"):
        assert np.array_equal(getattr(packets, a), before[a]), a
    for a in ("prim", "u", "v"):
        assert np.array_equal(getattr(packets, a)[inactive].view(np.uint32),
                              before[a][inactive].view(np.uint32)), f"{a} of an inactive lane"
    assert np.array_equal(packets.t[inactive].view(np.uint32),
                          before["rows"][10][inactive].view(np.uint32)), "t of an inactive lane"
    assert np.array_equal(rays.data.view(np.uint32), ray_data.view(np.uint32))
    return packets


# ---------------------------------------------------------------------------
# shared references (brute force is computed once per module)
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def real(workloads, sibenik, sponza):
    """``real(scene_name, kind)`` -> (scene, bvh, rays, large-packet offsets, brute-force hits);
    kind is "primary", "diffuse" or "random" (512 random rays)."""
    cache, bvhs = {}, {}

    def get(scene_name, kind):
        key = (scene_name, kind)
        if key not in cache:
            scene = {"sibenik": sibenik, "sponza": sponza}[scene_name]
            if scene_name not in bvhs:                    # our own BVH: nobody refits it
                bvhs[scene_name] = BVH(scene.vertices, scene.faces)
            if kind == "random":
                rays = random_rays(np.random.default_rng(77), 512, scene.bounds)
                offsets = np.array([0, 512], np.int32)
            else:
                work = workloads(scene, kind)
                rays, offsets = work.rays, work.packets
            cache[key] = (scene, bvhs[scene_name], rays, offsets,
                          parallel_brute_force(scene.vertices, scene.faces, rays))
        return cache[key]

    return get


@pytest.fixture(scope="module")
def soup():
    """(V, F, bvh) of 2000 random triangles of mixed sizes, 5% of them zero-area."""
    rng = np.random.default_rng(31)
    m = 2000
    size = rng.choice([0.05, 0.5, 2.0], size=(m, 1, 1))
    V = (rng.random((m, 1, 3)) * 20 + rng.normal(size=(m, 3, 3)) * size).reshape(-1, 3)
    V = V.astype(F32)
    F = np.arange(3 * m, dtype=np.int32).reshape(m, 3)
    bad = np.flatnonzero(rng.random(m) < 0.05)
    F[bad, 2] = F[bad, 1]
    return V, F, BVH(V, F, max_leaf=4)


SCENE_KINDS = [(s, k) for s in ("sibenik", "sponza") for k in ("primary", "diffuse", "random")]


# ---------------------------------------------------------------------------
# real scenes
# ---------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("scene_name,kind", SCENE_KINDS)
def test_real_workloads(name, real, scene_name, kind):
    """Primary, first-bounce diffuse and random rays of Sibenik and Sponza, traced in the
    workload's large packets: closest hits and any-hit flags equal brute force."""
    scene, bvh, rays, offsets, ref = real(scene_name, kind)
    order = np.arange(len(rays), dtype=np.int32)
    assert_same_hits(trace(name, bvh, rays, order, offsets), ref, f"{name} {scene_name} {kind}")
    occluded = trace(name, bvh, rays, order, offsets, any_hit=True)
    assert np.array_equal(occluded, ref.prim >= 0), f"{name} any_hit {scene_name} {kind}"


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["primary", "diffuse"])
def test_subpacket_sizes_and_orders(name, real, kind):
    """Sub-packets of 1..1024 rays (fixed sizes and a random mix) gathered in random orders
    all give the brute-force hits."""
    scene, bvh, rays, _, ref = real("sibenik", kind)
    rng = np.random.default_rng(5)
    n = len(rays)
    for size in [1, 2, 3, 4, 5, 7, 8, 13, 64, 100, 1024, n]:
        order = rng.permutation(n)
        hits = trace(name, bvh, rays, order, fixed_offsets(n, size))
        assert_same_hits(hits, ref, f"{name} {kind} sub-packets of {size}")
    for trial in range(3):
        order = rng.permutation(n)
        hits = trace(name, bvh, rays, order, random_offsets(rng, n))
        assert_same_hits(hits, ref, f"{name} {kind} random sub-packet sizes #{trial}")
    # coherent order (as generated) in uneven pieces too
    hits = trace(name, bvh, rays, None, random_offsets(rng, n, 97))
    assert_same_hits(hits, ref, f"{name} {kind} in order, random sizes")


@pytest.mark.slow
def test_inactive_lanes(name, real):
    """Invalid rays (tmin >= tmax, negative tmin, NaN / inf origin or direction, NaN tmin/tmax)
    mixed into packets come back as misses and do not disturb the valid lanes."""
    scene, bvh, good, _, ref = real("sibenik", "diffuse")
    rng = np.random.default_rng(8)
    m = 600
    bad = good.take(rng.integers(0, len(good), m))         # rays that would hit, made invalid
    kind = np.arange(m) % 10
    col = np.arange(m)
    comp = rng.integers(0, 6, m)
    value = rng.choice(np.array([np.nan, np.inf, -np.inf], F32), m)
    nonfinite = kind < 4
    bad.data[comp[nonfinite], col[nonfinite]] = value[nonfinite]
    bad.tmin[kind == 4], bad.tmax[kind == 4] = 3.0, 3.0                  # tmin == tmax
    bad.tmin[kind == 5], bad.tmax[kind == 5] = 5.0, 1.0                  # tmin > tmax
    bad.tmin[kind == 6] = -1.0                                           # negative tmin
    bad.tmin[kind == 7] = np.nan
    bad.tmax[kind == 8] = np.nan
    bad.tmin[kind == 9], bad.tmax[kind == 9] = np.inf, np.inf
    rays = concat(good, bad)
    n, n_good = len(rays), len(good)

    def check(hits, label):
        assert_same_hits(take_hits(hits, slice(0, n_good)), ref, label)
        assert (hits.prim[n_good:] == -1).all() and (hits.t[n_good:] == np.inf).all(), label

    for size in [1, 4, 5, 7, 64, 1024]:
        order = rng.permutation(n)
        check(trace(name, bvh, rays, order, fixed_offsets(n, size)), f"{name} mixed, {size}")
        occ = trace(name, bvh, rays, order, fixed_offsets(n, size), any_hit=True)
        assert np.array_equal(occ, np.r_[ref.prim >= 0, np.zeros(m, bool)])
    # every sub-packet starts and ends with invalid rays; one sub-packet is all invalid
    sizes, order, gi, bi = [], [], 0, n_good
    while gi < n_good:
        k = int(min(rng.integers(1, 40), n_good - gi))
        order += [bi, *range(gi, gi + k), bi + 1]
        sizes.append(k + 2)
        gi, bi = gi + k, bi + 2
    order += list(range(bi, n))
    sizes.append(n - bi)
    hits = trace(name, bvh, rays, order, offsets_of(sizes))
    check(hits, f"{name} invalid at packet ends")


@pytest.mark.slow
def test_any_hit_shadow_tmax(name, real):
    """With shadow-ray tmax limits, any_hit is True iff the closest hit lies below tmax, and
    closest hits in the shortened interval are the brute-force ones cut at tmax."""
    scene, bvh, rays0, _, ref = real("sibenik", "diffuse")
    rng = np.random.default_rng(12)
    n = len(rays0)
    rays = rays0.take(np.arange(n))
    t = ref.t
    choice = rng.integers(0, 4, n)
    tmax = np.select([choice == 0, choice == 1, choice == 2],
                     [t, np.nextafter(t, F32(np.inf)), t * F32(0.5)],
                     rng.random(n).astype(F32) * F32(30)).astype(F32)
    rays.tmax[:] = tmax
    # brute force's closest hit in (tmin, inf) is at t, so one in (tmin, tmax) exists iff t < tmax
    expected = t < tmax
    assert 0.2 < expected.mean() < 0.8
    for size in [4, 7, 64]:
        order = rng.permutation(n)
        occluded = trace(name, bvh, rays, order, fixed_offsets(n, size), any_hit=True)
        assert np.array_equal(occluded, expected), f"{name} shadow any_hit, {size}"
        cut = Hits(n)
        cut.t[expected], cut.prim[expected] = t[expected], ref.prim[expected]
        cut.u[expected], cut.v[expected] = ref.u[expected], ref.v[expected]
        assert_same_hits(trace(name, bvh, rays, order, fixed_offsets(n, size)), cut,
                         f"{name} closest with shadow tmax, {size}")


@pytest.mark.slow
def test_packets_not_modified_beyond_hits(name, real):
    """A traversal writes only t/prim/u/v of active lanes: rays, inverse directions, tmin,
    index, starts and counts, and the hit record of inactive lanes, are left as they were."""
    scene, bvh, rays, _, ref = real("sibenik", "diffuse")
    rng = np.random.default_rng(4)
    n = len(rays)
    mixed = rays.take(np.arange(n))
    mixed.tmin[::7] = np.inf                              # some invalid lanes too
    mixed.directions[0, 3::11] = np.nan
    for any_hit in (False, True):
        for size in (5, 64):
            check_untouched(name, bvh, mixed, rng.permutation(n).astype(np.int32),
                            fixed_offsets(n, size), any_hit)


# ---------------------------------------------------------------------------
# synthetic scenes
# ---------------------------------------------------------------------------

def test_random_soup(name, soup):
    """Random rays against a 2000-triangle soup, random orders and sub-packet sizes."""
    V, F, bvh = soup
    rng = np.random.default_rng(21)
    rays = random_rays(rng, 3000, bvh.bounds)
    ref = brute_force(V, F, rays)
    assert 0.2 < (ref.prim >= 0).mean() < 0.9
    n = len(rays)
    for trial in range(3):
        order = rng.permutation(n)
        offsets = random_offsets(rng, n, 300) if trial else fixed_offsets(n, 1)
        assert_same_hits(trace(name, bvh, rays, order, offsets), ref, f"{name} soup #{trial}")
        occluded = trace(name, bvh, rays, order, offsets, any_hit=True)
        assert np.array_equal(occluded, ref.prim >= 0)


def test_widest_subpacket(name, soup):
    """One sub-packet of MAX_PACKET (4096) rays gives the brute-force hits."""
    V, F, bvh = soup
    rng = np.random.default_rng(22)
    rays = random_rays(rng, raysort.rays.MAX_PACKET, bvh.bounds)
    ref = brute_force(V, F, rays)
    assert_same_hits(trace(name, bvh, rays, rng.permutation(len(rays))), ref, name)


def test_empty_batch(name, soup):
    """Zero rays: nothing to do, no error, no rays counted."""
    V, F, bvh = soup
    packets = gather(RayBatch(0), np.zeros(0, np.int32), np.zeros(1, np.int32))
    counters = raysort.create("traversals", name).intersect(bvh, packets)
    assert counters.rays == 0
    assert len(scatter(packets, 0)) == 0


def test_ties_lowest_index(name):
    """Rays through shared edges and vertices of a grid (and through duplicated faces) tie at
    equal t: every traversal reports the lowest index, whatever the leaf order."""
    rng = np.random.default_rng(3)
    V, F = grid_scene(rng)
    n = 3000
    rays = grid_tie_rays(rng, n)
    ref = brute_force(V, F, rays)
    assert (ref.prim >= 0).all()
    for max_leaf in (1, 3, 8):
        bvh = BVH(V, F, max_leaf=max_leaf)
        for size in (1, 4, 13, 64):
            hits = trace(name, bvh, rays, rng.permutation(n), fixed_offsets(n, size))
            assert_same_hits(hits, ref, f"{name} ties, max_leaf {max_leaf}, {size}")


def test_zero_area_triangles(name):
    """Zero-area triangles (v0 = v1, v1 = v2, v0 = v2, single points, exactly collinear
    vertices) among real ones, rays aimed at their vertices: the brute-force answers."""
    rng = np.random.default_rng(14)
    m = 300
    A = (rng.random((m, 3)) * 10).astype(F32)
    B = (A + rng.normal(size=(m, 3)) * 2).astype(F32)
    # exactly collinear: A8, A8 + s, A8 + 2 s on a 1/8 lattice (all exact in float32)
    A8 = (np.round(A * 8) / 8).astype(F32)
    s = (rng.integers(-16, 16, size=(m, 3)) / 8).astype(F32)
    real_tris = (A[:, None] + rng.normal(size=(m, 3, 3)) * 0.5).reshape(-1, 3)
    V = np.vstack([A, B, A8, A8 + s, A8 + 2 * s, real_tris]).astype(F32)
    i = np.arange(m)
    F = np.vstack([np.column_stack([i, i, m + i]),           # v0 = v1
                   np.column_stack([i, m + i, m + i]),       # v1 = v2
                   np.column_stack([m + i, i, m + i]),       # v0 = v2
                   np.column_stack([i, i, i]),               # a point
                   np.column_stack([2 * m + i, 3 * m + i, 4 * m + i]),   # collinear
                   5 * m + np.arange(3 * m).reshape(m, 3)]).astype(np.int32)
    F = F[rng.permutation(len(F))]
    n = 3000
    o = rng.random((n, 3)) * 14 - 2
    aim = V[rng.integers(0, 5 * m, n)]
    rays = batch(o, aim - o)
    assert (rays.directions != 0).all()
    ref = brute_force(V, F, rays)
    for max_leaf in (1, 4):
        bvh = BVH(V, F, max_leaf=max_leaf)
        for size in (1, 4, 33):
            order = rng.permutation(n)
            offsets = fixed_offsets(n, size)
            assert_same_hits(trace(name, bvh, rays, order, offsets), ref,
                             f"{name} zero-area, max_leaf {max_leaf}, {size}")
            occ = trace(name, bvh, rays, order, offsets, any_hit=True)
            assert np.array_equal(occ, ref.prim >= 0)


def test_sliver_triangle(name):
    """A sliver (near-zero-area) triangle in front of a real one: the traversal reports what
    brute force reports.

    Brute force's Moller-Trumbore "hits" the sliver at t = 0.0625, at a point far outside the
    sliver's box, because det is tiny and u, v, t are rounding noise; a BVH traversal that
    first finds the real triangle (t = 0.326) then culls the sliver's box, so the two differ
    (every built-in traversal reports primitive 1, brute force primitive 0)."""
    V = np.array([[9.0888605, 6.3554206, 3.0566537], [7.2084045, 4.561734, 2.0847077],
                  [5.3279486, 2.7680478, 1.1127616],                      # the sliver
                  [6, 3, 7.5], [8, 3, 7.5], [7, 5, 7.5]], F32)           # a real triangle
    F = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    rays = batch([[6.6261554, 3.2092233, 10.116445]], [[0.58224916, 1.3525109, -8.031736]])
    ref = brute_force(V, F, rays)
    assert_same_hits(trace(name, BVH(V, F, max_leaf=1), rays), ref, f"{name} sliver")


def axis_rays(rng, n, on_plane):
    """Rays whose direction has one or two components exactly 0 (+0 or -0).

    Origins are on a quarter-integer lattice; with ``on_plane`` the coordinates on the
    zero-direction axes are integers, i.e. exactly in the boxes' face planes."""
    d = rng.normal(size=(n, 3))
    zero = rng.random((n, 3)) < 0.5
    zero[np.arange(n), rng.integers(0, 3, n)] = False       # keep one non-zero component
    d[zero] = rng.choice([0.0, -0.0], size=zero.sum())
    o = rng.integers(-4, 24, size=(n, 3)) / 4.0
    if on_plane:
        o[zero] = rng.integers(0, 5, size=zero.sum())
    else:
        o[zero] = rng.integers(-1, 5, size=zero.sum()) + 0.5
    return batch(o, d)


def test_box_scene_parallel_rays(name):
    """Axis-aligned boxes, rays parallel to faces (zero direction components) running between
    the face planes: the brute-force hits, including any-hit."""
    V, F = boxes_scene()
    rng = np.random.default_rng(15)
    rays = axis_rays(rng, 4000, on_plane=False)
    ref = brute_force(V, F, rays)
    assert (ref.prim >= 0).mean() > 0.15
    for max_leaf in (1, 4):
        bvh = BVH(V, F, max_leaf=max_leaf)
        for size in (1, 4, 5, 64):
            order = rng.permutation(len(rays))
            assert_same_hits(trace(name, bvh, rays, order, fixed_offsets(len(rays), size)),
                             ref, f"{name} parallel rays, max_leaf {max_leaf}, {size}")
            occ = trace(name, bvh, rays, order, fixed_offsets(len(rays), size), any_hit=True)
            assert np.array_equal(occ, ref.prim >= 0)


def test_box_scene_rays_in_face_planes(name):
    """Rays parallel to the faces that lie exactly in a face plane (origin coordinate = the
    plane, direction component +-0) hit the boxes' edges exactly as brute force says.

    Minimal case: one triangle (0,0,0) (0,1,0) (1,0,0) and the ray o=(0, 0.5, 5), d=(0, 0, -1)
    (it runs down the edge x = 0): brute force hits at t = 5, every built-in traversal misses.
    """
    V = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5]], F32)
    F = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    rays = batch([[0, 0.5, 5], [0.5, 0, 5], [0, 0.5, 5]], [[0, 0, -1], [0, 0, -1], [-0.0, 0, -1]])
    ref = brute_force(V, F, rays)
    assert ref.prim.tolist() == [0, 0, 0] and ref.t.tolist() == [5, 5, 5]
    assert_same_hits(trace(name, BVH(V, F, max_leaf=1), rays), ref, f"{name} edge x = 0")

    V, F = boxes_scene()
    rng = np.random.default_rng(16)
    rays = axis_rays(rng, 4000, on_plane=True)
    ref = brute_force(V, F, rays)
    bvh = BVH(V, F, max_leaf=2)
    for size in (1, 4, 64):
        order = rng.permutation(len(rays))
        assert_same_hits(trace(name, bvh, rays, order, fixed_offsets(len(rays), size)), ref,
                         f"{name} rays in face planes, {size}")


def test_rays_starting_on_surfaces(name):
    """Rays starting exactly on box faces (tmin = 0 and tmin > 0), leaving in any direction."""
    V, F = boxes_scene()
    bvh = BVH(V, F, max_leaf=2)
    rng = np.random.default_rng(17)
    n = 3000
    tri = rng.integers(0, len(F), n)
    corners = V[F[tri]]
    w = rng.random((n, 3))
    w /= w.sum(axis=1, keepdims=True)
    # on an axis-aligned face the weighted mean keeps the face's constant coordinate exactly
    o = np.einsum("nk,nkc->nc", w.astype(F32), corners).astype(F32)
    for c in range(3):
        flat = corners[:, 0, c] == corners[:, 1, c]
        flat &= corners[:, 0, c] == corners[:, 2, c]
        o[flat, c] = corners[flat, 0, c]
    d = rng.normal(size=(n, 3))
    tmin = rng.choice(np.array([0.0, 0.0, 1e-4, 0.25], F32), n)
    rays = batch(o, d, tmin)
    ref = brute_force(V, F, rays)
    assert (ref.prim >= 0).mean() > 0.2
    for size in (1, 4, 7, 64):
        order = rng.permutation(n)
        assert_same_hits(trace(name, bvh, rays, order, fixed_offsets(n, size)), ref,
                         f"{name} starting on surfaces, {size}")
        occ = trace(name, bvh, rays, order, fixed_offsets(n, size), any_hit=True)
        assert np.array_equal(occ, ref.prim >= 0)


def test_subnormal_direction_component(name):
    """A direction with a subnormal component is valid; the gather stores that component as
    zero (1/d would overflow to inf, which the slab test cannot use).  Every traversal then
    gives brute force's hits on rays that pass the triangles' edges by 1e-45 and on rays
    that cross them.

    Case: triangles (5, 1e-45, -1) (5, 1e-45, 1) (5, 1, 0) and the same at z + 10; rays
    from the origin plane with d = (1, +-1e-45, 0) at heights y = 0 (below the edge by
    1e-45: a miss once the component is zero) and y = 0.5 (a hit at t = 5)."""
    tiny = F32(1e-45)
    V = np.array([[5, tiny, -1], [5, tiny, 1], [5, 1, 0],
                  [5, tiny, 9], [5, tiny, 11], [5, 1, 10]], F32)
    F = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    rays = batch([[0, 0, 0], [0, 0, 10], [0, 0.5, 0], [0, 0.5, 10]],
                 [[1, tiny, 0], [1, -tiny, 0], [1, tiny, 0], [1, -tiny, 0]])
    ref = brute_force(V, F, rays)
    assert ref.prim.tolist() == [-1, -1, 0, 1] and ref.t[2:].tolist() == [5, 5]
    for max_leaf in (1, 2):
        assert_same_hits(trace(name, BVH(V, F, max_leaf=max_leaf), rays), ref,
                         f"{name} subnormal direction, max_leaf {max_leaf}")
