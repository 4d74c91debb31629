"""The ``stream`` traversal: brute force's hits for both trees, every stream size, child order,
small-stream threshold and ISA; its counters against the single-ray traversal it falls back to
(``wide`` on the 4-wide tree, ``wide8`` on the 8-wide one).

The conformance suite (test_conformance.py) runs ``stream`` with its defaults; here the
parameters are pushed to their ends: streams of one ray, streams that never fall back to
single rays (every leaf and node sees streams of 1..n rays), and the whole batch as one stream.
"""
import numpy as np
import pytest

import raysort
from raysort import isa
from raysort.bvh import BVH
from raysort.rays import (Hits, PacketRow, RayBatch, RayRow, gather, scatter,
                          scatter_occluded)
from raysort.reference import brute_force
from raysort.stats import Counters
from raysort.workloads import camera_rays, workload

from _helpers import assert_same_hits, random_rays

F32 = np.float32
SETTINGS = [dict(stream_size=s, min_stream=m, order=o, tree=tree)
            for s, m, o in [(1, 0, "votes"), (3, 0, "direction"), (64, 0, "votes"),
                            (1000, 4, "direction"), (16384, 0, "votes"),
                            (16384, 8, "direction"), (16384, 1 << 20, "votes")]
            for tree in (4, 8)]
#: the single-ray traversal each tree's small streams finish with
SINGLE = {4: "wide", 8: "wide8"}


@pytest.fixture(params=isa.ISAS)
def each_isa(request):
    """Switch every kernel to one ISA for the test (skipped where it cannot run)."""
    name = request.param
    if name not in isa.available():
        pytest.skip(f"ISA {name} is not compiled here or this CPU cannot run it")
    previous = isa.use(name)
    yield name
    isa.use(previous)


def trace(bvh, rays, ray_order=None, offsets=None, any_hit=False, **params):
    """Gather (by default in order, one sub-packet), trace with ``stream``, scatter back."""
    n = len(rays)
    ray_order = np.arange(n, dtype=np.int32) if ray_order is None else \
        np.asarray(ray_order, np.int32)
    offsets = np.array([0, n], np.int32) if offsets is None else offsets
    packets = gather(rays, ray_order, offsets)
    counters = raysort.create("traversals", {"type": "stream", **params}).intersect(bvh, packets,
                                                                         any_hit=any_hit)
    hits = scatter_occluded(packets, n) if any_hit else scatter(packets, n)
    return hits, counters


def trace_batch(bvh, rays, ray_order=None, offsets=None, any_hit=False, parts=1, **params):
    """``trace`` without packets: ``stream`` reads the batch in ``ray_order`` itself and
    writes the hits in batch order (the pipeline's path), the sub-packets cut into
    ``parts`` calls.  Returns ``(hits, counters, bad_ray)``."""
    n = len(rays)
    ray_order = np.arange(n, dtype=np.int32) if ray_order is None else \
        np.asarray(ray_order, np.int32)
    offsets = np.array([0, n], np.int32) if offsets is None else offsets
    traversal = raysort.create("traversals", {"type": "stream", **params})
    out = np.empty(n, np.uint8) if any_hit else np.empty((4, n), np.float32)
    counters, bad = Counters(), []
    cuts = np.linspace(0, len(offsets) - 1, parts + 1).astype(int)
    for k0, k1 in zip(cuts[:-1], cuts[1:]):
        part, bad_ray, bad_hit, order_ok = traversal._intersect_batch(
            bvh, rays.data, ray_order, offsets, k0, k1, any_hit, out)
        assert order_ok and bad_hit == -1
        counters += part
        bad += [bad_ray] if bad_ray >= 0 else []
    return (out.view(bool) if any_hit else Hits._of_block(out)), counters, min(bad, default=-1)


def fixed_offsets(n, size):
    return np.append(np.arange(0, n, size), n).astype(np.int32)


@pytest.fixture(scope="module")
def soup():
    """2000 random triangles of mixed sizes (5% zero-area), a BVH with small leaves, 3000
    random rays and their brute-force hits."""
    rng = np.random.default_rng(41)
    m = 2000
    size = rng.choice([0.05, 0.5, 2.0], size=(m, 1, 1))
    V = (rng.random((m, 1, 3)) * 20 + rng.normal(size=(m, 3, 3)) * size).reshape(-1, 3)
    V = V.astype(F32)
    F = np.arange(3 * m, dtype=np.int32).reshape(m, 3)
    bad = rng.random(m) < 0.05
    F[bad, 2] = F[bad, 1]
    bvh = BVH(V, F, max_leaf=4)
    rays = random_rays(rng, 3000, bvh.bounds)
    return V, F, bvh, rays, brute_force(V, F, rays)


@pytest.fixture(scope="module")
def ties():
    """A grid of unit quads with duplicated faces, shuffled, and rays through its vertices,
    edges and along its plane: equal t on several triangles, grazing rays."""
    rng = np.random.default_rng(9)
    g = 8
    ii, jj = np.meshgrid(np.arange(g + 1), np.arange(g + 1), indexing="ij")
    V = np.column_stack([ii.ravel(), jj.ravel(), np.zeros(ii.size)]).astype(F32)
    k = lambda i, j: i * (g + 1) + j  # noqa: E731
    F = np.array([f for i in range(g) for j in range(g)
                  for f in ([k(i, j), k(i + 1, j), k(i + 1, j + 1)],
                            [k(i, j), k(i + 1, j + 1), k(i, j + 1)])], np.int32)
    F = np.vstack([F, F[rng.choice(len(F), 24, replace=False)], [[0, 0, 1]]])  # + a degenerate
    F = F[rng.permutation(len(F))]
    n = 2000
    targets = np.column_stack([rng.integers(0, g + 1, n) * 0.5, rng.integers(0, g + 1, n) * 0.5,
                               np.zeros(n)])
    origins = targets + rng.normal(size=(n, 3)) * [1, 1, 3]
    origins[: n // 4, 2] = 0.0                             # in the plane: grazing
    directions = targets - origins
    directions[: n // 4] = rng.normal(size=(n // 4, 3)) * [1, 1, 0]
    rays = RayBatch.from_arrays(origins.astype(F32), directions.astype(F32))
    return V, F, BVH(V, F, max_leaf=3), rays, brute_force(V, F, rays)


@pytest.mark.parametrize("params", SETTINGS, ids=lambda p: "-".join(map(str, p.values())))
def test_soup_matches_brute_force(each_isa, soup, params):
    """Random incoherent rays in random order and sub-packets: brute force's hits, any-hit flags."""
    V, F, bvh, rays, ref = soup
    rng = np.random.default_rng(3)
    order = rng.permutation(len(rays))
    offsets = fixed_offsets(len(rays), int(rng.integers(1, 300)))
    hits, counters = trace(bvh, rays, order, offsets, **params)
    assert_same_hits(hits, ref, f"{each_isa} {params}")
    occluded, _ = trace(bvh, rays, order, offsets, any_hit=True, **params)
    assert np.array_equal(occluded, ref.prim >= 0)
    assert counters.rays == len(rays)


@pytest.mark.parametrize("params", SETTINGS, ids=lambda p: "-".join(map(str, p.values())))
def test_reading_the_batch_matches_brute_force_and_the_packets(each_isa, soup, params):
    """Without packets (the pipeline's path): brute force's hits and any-hit flags, and
    the counters of the same rays gathered into packets, in one call or in three."""
    V, F, bvh, rays, ref = soup
    rng = np.random.default_rng(5)
    order = rng.permutation(len(rays))
    offsets = fixed_offsets(len(rays), int(rng.integers(1, 300)))
    _, expected = trace(bvh, rays, order, offsets, **params)
    for parts in (1, 3):
        hits, counters, bad_ray = trace_batch(bvh, rays, order, offsets, parts=parts, **params)
        assert_same_hits(hits, ref, f"{each_isa} {params} parts={parts}")
        assert bad_ray == -1
        if parts == 1:
            assert counters == expected
        occluded, _, _ = trace_batch(bvh, rays, order, offsets, any_hit=True, parts=parts,
                                     **params)
        assert np.array_equal(occluded, ref.prim >= 0)


@pytest.mark.parametrize("frustum", [True, False])
def test_reading_the_batch_takes_the_frustum_walk_as_the_packets(each_isa, sibenik, frustum):
    """Camera rays in 8x8 sub-packets read from the batch: the hits of brute force, and the
    packet path's counters (the same chunks take the frustum walk)."""
    rays = camera_rays(sibenik, 64, 64)[0].rays
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    order, offsets = raysort.create("sorters", "none").sort(
        rays, np.array([0, len(rays)], np.int32), sibenik.bvh().bounds)
    _, expected = trace(sibenik.bvh(), rays, order, offsets, frustum=frustum)
    hits, counters, _ = trace_batch(sibenik.bvh(), rays, order, offsets, frustum=frustum)
    assert_same_hits(hits, ref, f"{each_isa} sibenik camera, frustum={frustum}")
    assert counters == expected
    assert (counters.ia > 0) == frustum


@pytest.mark.parametrize("frustum", [True, False])
def test_reading_the_batch_in_short_sub_packets_as_the_packets(each_isa, sibenik, frustum):
    """Camera rays in sub-packets of 1 to 100 rays, most shorter than a chunk (those that
    fit share one, each at the next multiple of 4 lanes, as the gather lays them out):
    brute force's hits and the packet path's counters, some chunks walked."""
    rays = camera_rays(sibenik, 64, 64)[0].rays
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    sizes = np.resize([1, 3, 15, 16, 17, 33, 63, 64, 65, 100], len(rays))
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    offsets = np.append(offsets[offsets < len(rays)], len(rays)).astype(np.int32)
    order = np.arange(len(rays), dtype=np.int32)
    _, expected = trace(sibenik.bvh(), rays, order, offsets, frustum=frustum)
    hits, counters, _ = trace_batch(sibenik.bvh(), rays, order, offsets, frustum=frustum)
    assert_same_hits(hits, ref, f"{each_isa} sibenik camera, short sub-packets")
    assert counters == expected
    assert counters.rays == len(rays)
    assert (counters.ia > 0) == frustum


@pytest.mark.parametrize("size", [1, 4, 6, 13])
def test_short_sub_packets_share_a_chunk_and_its_walk(each_isa, sibenik, size):
    """Camera rays cut into sub-packets too short for the walk on their own (a sorter's
    small cells): consecutive ones share a chunk of up to 64 lanes, which takes the
    frustum walk on both paths (N_IA > 0), with brute force's hits and, read from the
    batch, the packet path's counters."""
    rays = camera_rays(sibenik, 64, 64)[0].rays
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    offsets = np.append(np.arange(0, len(rays), size), len(rays)).astype(np.int32)
    order = np.arange(len(rays), dtype=np.int32)
    hits, expected = trace(sibenik.bvh(), rays, order, offsets, frustum=True)
    assert_same_hits(hits, ref, f"{each_isa} packets of {size}")
    hits, counters, _ = trace_batch(sibenik.bvh(), rays, order, offsets, frustum=True)
    assert_same_hits(hits, ref, f"{each_isa} batch in sub-packets of {size}")
    assert counters == expected
    assert counters.ia > 0


def test_reading_the_batch_traces_invalid_rays_as_misses(each_isa, soup):
    """Rays that break the ray contract (NaN, infinite, tmin < 0) are misses, and the first
    in the sorter's order is reported, as the gather does; empty intervals are misses
    without a report."""
    V, F, bvh, rays, ref = soup
    bad = RayBatch(len(rays))
    bad.data[:] = rays.data
    broken = {7: ("ox", np.nan), 40: ("dy", np.inf), 3: ("tmin", -1.0)}
    for ray, (row, value) in broken.items():
        bad.data[int(RayRow[row]), ray] = value
    bad.data[int(RayRow.tmax), 11] = bad.data[int(RayRow.tmin), 11]     # empty: a miss
    order = np.arange(len(rays), dtype=np.int32)[::-1].copy()
    hits, _, bad_ray = trace_batch(bvh, bad, order)
    assert bad_ray == 40                # the first of 7, 40, 3 in the reversed order
    for ray in (*broken, 11):
        assert hits.prim[ray] == -1 and hits.t[ray] == np.inf
    keep = np.setdiff1d(np.arange(len(rays)), [*broken, 11])
    assert np.array_equal(hits.prim[keep], ref.prim[keep])


def test_reading_the_batch_refuses_an_order_beyond_the_rays(soup):
    """An order entry outside [0, n), or offsets that do not cut [0, n) into sub-packets
    of 1..MAX_PACKET rays, stop the call (order_ok False) before any read beyond them."""
    V, F, bvh, rays, ref = soup
    n = len(rays)
    traversal = raysort.create("traversals", "stream")
    cases = [(wrong, np.array([0, 1000, 2000, n], np.int32))
             for wrong in (n, -1, 2**31 - 1)]
    cases += [(None, np.array(offsets, np.int32)) for offsets in
              ([0, 1000, n + 5000], [0, 2000, 1000, n], [-4000, 0, n], [0, 1000, 1000, n],
               [0, 1000, 2000])]
    for wrong, offsets in cases:
        order = np.arange(n, dtype=np.int32)
        if wrong is not None:
            order[100] = wrong
        out = np.empty((4, n), np.float32)
        for k0, k1 in ((0, len(offsets) - 1), (1, len(offsets) - 1)):
            *_, order_ok = traversal._intersect_batch(bvh, rays.data, order, offsets, k0,
                                                      k1, False, out)
            assert not order_ok or (wrong is not None and k0 == 1), (wrong, offsets, k0)


def short_mesh(monkeypatch, bvh, faces):
    """A stand-in for ``bvh`` whose mesh has only ``faces`` faces: the kernel's own check
    of each hit it writes, which ``check_tree`` (a genuine BVH's tree and mesh agree)
    keeps any caller from needing, is reached only with check_tree out of the way."""
    from types import SimpleNamespace
    monkeypatch.setattr(isa.module("traversals.stream"), "check_tree", lambda tree: tree)
    return SimpleNamespace(faces=bvh.faces[:faces], triangles=bvh.triangles, wide8=bvh.wide8)


def test_reading_the_batch_flags_a_hit_beyond_the_mesh(soup, monkeypatch):
    """Each hit is checked as it is written: a BVH whose mesh is shorter than its triangle
    ids makes the kernel report a hit (the rules of check_hits: prim below n_prim)."""
    V, F, bvh, rays, ref = soup
    short = short_mesh(monkeypatch, bvh, 10)
    out = np.empty((4, len(rays)), np.float32)
    _, _, bad_hit, order_ok = raysort.create("traversals", "stream")._intersect_batch(
        short, rays.data, np.arange(len(rays), dtype=np.int32),
        np.array([0, len(rays)], np.int32), 0, 1, False, out)
    assert order_ok and bad_hit >= 0 and ref.prim[bad_hit] >= 10


@pytest.mark.parametrize("reverse", [False, True])
def test_coherent_chunks_flag_the_first_hit_beyond_the_mesh(each_isa, sibenik, reverse,
                                                           monkeypatch):
    """Camera rays, whose chunks take the frustum walk: the ``none`` order's consecutive
    rays have their hits written a row at a time, a chunk-reversed order's one by one.
    With a mesh shorter than the tree's ids, the first hit beyond it in the sorter's
    order is the one reported, either way, and every other hit is brute force's."""
    rays = camera_rays(sibenik, 64, 64)[0].rays
    n = len(rays)
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    limit = int(np.median(ref.prim[ref.prim >= 0]))
    order = np.arange(n, dtype=np.int32)
    if reverse:
        order = np.ascontiguousarray(order.reshape(-1, 64)[:, ::-1].ravel())
    bvh = sibenik.bvh()
    short = short_mesh(monkeypatch, bvh, limit)
    out = np.empty((4, n), np.float32)
    counters, _, bad_hit, order_ok = raysort.create("traversals", "stream")._intersect_batch(
        short, rays.data, order, np.arange(0, n + 1, 64, dtype=np.int32), 0, n // 64, False,
        out)
    assert order_ok and counters.ia > 0
    assert bad_hit == next(int(i) for i in order if ref.prim[i] >= limit)
    assert np.array_equal(out[1].view(np.int32), ref.prim)
    assert np.array_equal(out[0], ref.t)


@pytest.mark.parametrize("params", SETTINGS[:6] + SETTINGS[-6:],
                         ids=lambda p: "-".join(map(str, p.values())))
def test_ties_degenerates_and_grazing_rays(each_isa, ties, params):
    """Rays through shared vertices and edges and duplicated faces tie at equal t: the lower
    primitive wins; rays in the plane and the degenerate face are never hit."""
    V, F, bvh, rays, ref = ties
    assert (ref.prim >= 0).mean() > 0.5
    hits, _ = trace(bvh, rays, **params)
    assert_same_hits(hits, ref, f"{each_isa} {params}")


@pytest.fixture(scope="module")
def face_planes():
    """For each ordered pair of axes (p, q): a unit grid in the plane p = 0, and rays that
    travel toward it along p with no q component from an origin on a grid line q = j.
    The boxes have faces at those lines, so a slab test meets 0 * inf = NaN on axis q
    (q = z: the last axis a slab test takes, where a NaN is not overwritten)."""
    rng = np.random.default_rng(11)
    g, n = 8, 400
    ii, jj = np.meshgrid(np.arange(g + 1), np.arange(g + 1), indexing="ij")
    k = lambda i, j: i * (g + 1) + j  # noqa: E731
    F = np.array([f for i in range(g) for j in range(g)
                  for f in ([k(i, j), k(i + 1, j), k(i + 1, j + 1)],
                            [k(i, j), k(i + 1, j + 1), k(i, j + 1)])], np.int32)
    cases = []
    for p in range(3):
        for q in range(3):
            if q == p:
                continue
            r = 3 - p - q                       # the axis the rays may drift along
            V = np.zeros(((g + 1) ** 2, 3), F32)
            V[:, q], V[:, r] = ii.ravel(), jj.ravel()
            o = np.zeros((n, 3), F32)
            o[:, p] = 3.0
            o[:, q] = rng.choice([0, 8, 3, 5], n, p=[0.35, 0.35, 0.15, 0.15])  # box faces
            o[:, r] = rng.uniform(0.05, 7.95, n)
            d = np.zeros((n, 3), F32)
            d[:, p] = -1.0
            d[:, r] = rng.uniform(-0.2, 0.2, n)
            rays = RayBatch.from_arrays(o, d)
            cases.append(((p, q), V, F, BVH(V, F, max_leaf=3), rays, brute_force(V, F, rays)))
    return cases


@pytest.mark.parametrize("frustum", [False, True])
@pytest.mark.parametrize("params", [SETTINGS[0], SETTINGS[5], SETTINGS[-3], SETTINGS[-1]],
                         ids=lambda p: "-".join(map(str, p.values())))
def test_rays_on_box_faces_with_a_zero_direction_component(each_isa, face_planes, params,
                                                           frustum):
    """0 * inf = NaN in a slab test must not lose a box: min/max return their second
    operand, the running interval, when the first is NaN.  The rays hit the grid's edges
    on the lines they start on; on its outer lines (0 and 8) every box on the way has
    that face, so a box lost is a hit lost."""
    for (p, q), _, _, bvh, rays, ref in face_planes:
        assert (ref.prim >= 0).mean() > 0.9, (p, q)
        hits, _ = trace(bvh, rays, frustum=frustum, **params)
        assert_same_hits(hits, ref, f"{each_isa} {params} frustum={frustum} axes {p}, {q}")
        occluded, _ = trace(bvh, rays, any_hit=True, frustum=frustum, **params)
        assert np.array_equal(occluded, ref.prim >= 0), (p, q)


def test_sibenik_diffuse(each_isa, workloads, sibenik):
    """First-bounce diffuse rays of Sibenik in the nah sorter's order, one stream per call."""
    rays = workloads(sibenik, "diffuse").rays
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    order, offsets = raysort.create("sorters", "nah").sort(
        rays, np.array([0, len(rays)], np.int32), sibenik.bvh().bounds)
    for params in (dict(), dict(tree=4), dict(min_stream=0, order="direction", stream_size=500),
                   dict(tree=4, min_stream=0, order="direction", stream_size=500)):
        hits, _ = trace(sibenik.bvh(), rays, order, offsets, **params)
        assert_same_hits(hits, ref, f"{each_isa} sibenik {params}")


@pytest.mark.parametrize("frustum", [True, False])
def test_coherent_chunks_take_the_frustum_walk(each_isa, sibenik, frustum):
    """Camera rays in the ``none`` sorter's 8x8 packets: with ``frustum`` (the default)
    their chunks take the ``frustum`` traversal's walk (N_IA counted) instead of
    forming streams; the hits are brute force's either way."""
    rays = camera_rays(sibenik, 64, 64)[0].rays
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    order, offsets = raysort.create("sorters", "none").sort(
        rays, np.array([0, len(rays)], np.int32), sibenik.bvh().bounds)
    hits, c = trace(sibenik.bvh(), rays, order, offsets, frustum=frustum)
    assert_same_hits(hits, ref, f"{each_isa} sibenik camera, frustum={frustum}")
    if frustum:
        assert c.ia > 0 and c.stream_rays < len(rays) // 2
    else:
        assert c.ia == 0 and c.stream_rays >= len(rays)


@pytest.mark.parametrize("kind", ["shadow", "camera with gaps"])
def test_dense_blocks_of_a_chunk_keep_brute_forces_hits(each_isa, sibenik, kind):
    """Coherent chunks in the frustum walk test the leaves that most of a block's rays
    enter a triangle at a time for the block (``rs_frustum_leaf_block``): shadow rays to
    the lamp (any hit and closest hit), and camera rays of which every third is invalid
    (tmin > tmax), so that blocks hold lanes that do not look, whose hits must stay
    misses.  Every ray keeps brute force's hit, and the chunks take the walk."""
    if kind == "shadow":        # the first 4096 of a 256x256 render's (close origins)
        rays = workload(sibenik, "shadow", width=256, height=256, seed=3).rays.truncate(4096)
    else:
        rays = camera_rays(sibenik, 64, 64)[0].rays
        rays.tmin[::3] = 2.0
        rays.tmax[::3] = 1.0
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    order, offsets = raysort.create("sorters", "none").sort(
        rays, np.array([0, len(rays)], np.int32), sibenik.bvh().bounds)
    hits, c = trace(sibenik.bvh(), rays, order, offsets, frustum=True)
    assert_same_hits(hits, ref, f"{each_isa} sibenik {kind}")
    assert c.ia > 0
    occluded, _ = trace(sibenik.bvh(), rays, order, offsets, any_hit=True, frustum=True)
    np.testing.assert_array_equal(occluded, ref.prim >= 0)
    if kind != "shadow":
        assert (ref.prim[::3] == -1).all() and (ref.prim >= 0).mean() > 0.5


def test_lanes_follow_the_isa(each_isa):
    expected = {"scalar": 1, "sse2": 4, "avx2": 8, "avx512": 16, "avx512emu": 16}[each_isa]
    assert isa.module("traversals.stream").lanes() == expected


@pytest.mark.parametrize("tree", [4, 8])
def test_counters_are_the_same_on_every_isa(soup, tree):
    V, F, bvh, rays, _ = soup
    seen = {}
    for name in isa.available():
        previous = isa.use(name)
        try:
            seen[name] = trace(bvh, rays, min_stream=4, stream_size=700, tree=tree)[1].as_dict()
        finally:
            isa.use(previous)
    assert all(c == seen[isa.baseline()] for c in seen.values()), seen


@pytest.mark.parametrize("tree", [4, 8])
def test_single_ray_finish_counts_as_wide(soup, tree):
    """With a threshold above the stream size every ray walks alone from the root: the
    counters (and hits) are exactly those of ``wide`` (4-wide tree) or ``wide8``."""
    V, F, bvh, rays, ref = soup
    hits, c = trace(bvh, rays, min_stream=1 << 20, tree=tree)
    packets = gather(rays, np.arange(len(rays), dtype=np.int32),
                     np.array([0, len(rays)], np.int32))
    w = raysort.create("traversals", SINGLE[tree]).intersect(bvh, packets)
    assert (c.box4, c.tri1, c.tri4, c.box1, c.ia) == (w.box4, w.tri1, w.tri4, 0, 0)
    assert c.box4 > 0 and c.tri1 + c.tri4 > 0
    assert c.stream_tasks == c.stream_rays == 0


def test_stream_counters(soup):
    """Every stream popped is counted with its rays: the root stream holds every ray, each
    ray of an inner node's stream is one SIMD N_B, and leaf streams count SIMD N_T."""
    V, F, bvh, rays, _ = soup
    n = len(rays)
    for tree in (4, 8):
        _, one = trace(bvh, rays, min_stream=0, tree=tree)
        assert one.rays == n and one.stream_rays >= n and one.stream_tasks >= 1
        assert one.box4 >= n and one.tri4 > 0 and one.tri1 == one.box1 == one.ia == 0
        assert one.stream_rays > one.box4               # leaf streams hold rays too
        _, split = trace(bvh, rays, min_stream=0, stream_size=n // 3 + 1, tree=tree)
        assert split.stream_tasks > one.stream_tasks    # three root streams, each split again
        _, mixed = trace(bvh, rays, min_stream=16, tree=tree)
        assert mixed.stream_tasks < one.stream_tasks and mixed.stream_rays < one.stream_rays
        assert (mixed.tri1 > 0) == (tree == 4)      # the 4-wide tree's finish tests triangles
                                                    # one by one, the 8-wide one in groups


def level_rays_by_python(nodes, packets):
    """Rays that enter each level of a wide tree (``bvh.wide`` or ``bvh.wide8.nodes``) when
    nothing is ever hit, by a walk in NumPy: a box's rays are those of its parent that pass
    the slab test against it (float32, the kernel's operations and its 2^-14 slack), the
    root's are all rays."""
    rows = packets.rows
    o = [rows[int(PacketRow.ox) + a, :len(packets.index)] for a in range(3)]
    inv = [rows[int(PacketRow.ix) + a, :len(packets.index)] for a in range(3)]
    tmin, tmax = rows[int(PacketRow.tmin)], rows[int(PacketRow.t)]
    active = np.flatnonzero(tmin[:len(packets.index)] < tmax[:len(packets.index)])
    slack = F32(1 + 2.0 ** -14)
    levels = {}

    def visit(node, ids, level):
        levels[level] = levels.get(level, 0) + len(ids)
        if node < 0:
            return
        box = nodes[node]
        for k in range(len(box["child"])):
            if not box["lo"][0][k] <= box["hi"][0][k]:        # an empty slot
                continue
            tn, tf = tmin[ids], tmax[ids]
            for a in range(3):
                t_lo = (box["lo"][a][k] - o[a][ids]) * inv[a][ids]
                t_hi = (box["hi"][a][k] - o[a][ids]) * inv[a][ids]
                neg = np.signbit(inv[a][ids])
                near, far = np.where(neg, t_hi, t_lo), np.where(neg, t_lo, t_hi)
                tn = np.where(near > tn, near, tn)
                tf = np.where(far < tf, far, tf)
            sub = ids[tn <= tf * slack]
            if len(sub):
                visit(int(box["child"][k]), sub, level + 1)

    visit(0, active, 0)
    return tuple(levels.get(d, 0) for d in range(max(levels) + 1))


@pytest.mark.parametrize("tree", [4, 8])
def test_level_rays_equal_an_independent_count(each_isa, tree):
    """With triangles no ray can hit (zero area), which rays enter which box depends on the
    boxes alone: the per-level stream sizes equal a walk of the tree in NumPy, and add up
    to stream_rays."""
    rng = np.random.default_rng(17)
    m = 600
    v0 = rng.random((m, 3)) * 10
    v1 = v0 + rng.normal(size=(m, 3))
    V = np.stack([v0, v1, 2 * v1 - v0], axis=1).reshape(-1, 3).astype(F32)   # collinear
    F = np.arange(3 * m, dtype=np.int32).reshape(m, 3)
    bvh = BVH(V, F, max_leaf=2)
    rays = random_rays(rng, 1500, bvh.bounds)
    order = np.arange(len(rays), dtype=np.int32)
    packets = gather(rays, order, np.array([0, len(rays)], np.int32))
    want = level_rays_by_python(bvh.wide8.nodes if tree == 8 else bvh.wide, packets)
    hits, c = trace(bvh, rays, min_stream=0, tree=tree)
    assert (hits.prim == -1).all()
    assert len(want) >= 3 and want[0] == len(rays)
    assert c.stream_level_rays == want
    assert sum(c.stream_level_rays) == c.stream_rays


def test_level_rays_add_up(soup):
    """Level 0 holds every ray of every stream, the levels add up to stream_rays (also with
    the single-ray finish and several streams), and Counters add them entry by entry."""
    V, F, bvh, rays, _ = soup
    n = len(rays)
    depth = {4: bvh.wide_depth, 8: bvh.wide8.depth}
    for params in (dict(min_stream=0), dict(min_stream=16, stream_size=n // 3 + 1)):
        for tree in (4, 8):
            _, c = trace(bvh, rays, tree=tree, **params)
            assert c.stream_level_rays[0] == n
            assert sum(c.stream_level_rays) == c.stream_rays
            assert len(c.stream_level_rays) <= depth[tree] + 1
            assert c.as_dict()["stream_level_rays"] == list(c.stream_level_rays)
    _, w = trace(bvh, rays, min_stream=1 << 20)          # every ray alone: no streams
    assert w.stream_level_rays == ()
    a, b = Counters(), Counters()
    a.stream_level_rays, b.stream_level_rays = (5, 3), (1, 2, 4)
    assert (a + b).stream_level_rays == (6, 5, 4)
    assert (a + Counters()).stream_level_rays == (5, 3)


def test_parameters_are_checked():
    with pytest.raises(raysort.ConfigError, match="order"):
        raysort.create("traversals", {"type": "stream", "order": "random"})
    with pytest.raises(raysort.ConfigError, match="stream_size"):
        raysort.create("traversals", {"type": "stream", "stream_size": 0})
    with pytest.raises(raysort.ConfigError, match="min_stream"):
        raysort.create("traversals", {"type": "stream", "min_stream": -1})
    for tree in (2, 16, "8", True):
        with pytest.raises(raysort.ConfigError, match="tree"):
            raysort.create("traversals", {"type": "stream", "tree": tree})
    with pytest.raises(raysort.ConfigError, match="frustum"):
        raysort.create("traversals", {"type": "stream", "frustum": "yes please"})


def test_pipeline_image_equals_wide(sibenik):
    """A small render with stream gives wide's image bit for bit, with stream counters."""
    images = {}
    for name in ("wide", "stream"):
        pipe = raysort.Pipeline(sibenik, traversal=name, sorter="nah")
        result = pipe.render(32, 24, spp=1, seed=3)
        images[name] = result
    assert np.array_equal(images["wide"].image, images["stream"].image)
    counters = images["stream"].stats.counters[1]
    assert counters.stream_tasks > 0
    assert sum(counters.stream_level_rays) == counters.stream_rays > 0


def test_the_avx2_append_table_lists_each_masks_lanes_in_order():
    """lanes.h's rs_compress8 (the AVX2 filter's append): entry m holds the set bits of m,
    lowest first, one per 4-bit digit; read from the header, held to that definition."""
    import re
    from pathlib import Path
    header = Path(raysort.__file__).parent / "include" / "raysort" / "lanes.h"
    text = header.read_text()
    body = text[text.index("rs_compress8[256] = {"):]
    body = body[:body.index("};")]
    table = [int(v, 16) for v in re.findall(r"0x[0-9a-fA-F]+", body)]
    assert len(table) == 256
    for mask, entry in enumerate(table):
        lanes = [k for k in range(8) if mask >> k & 1]
        assert [entry >> (4 * j) & 0xF for j in range(len(lanes))] == lanes, mask
        assert entry >> (4 * len(lanes)) == 0, mask
