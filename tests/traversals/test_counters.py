"""Table I counters of the built-in traversals.

Part 1: tiny hand-built BVHs where every counter can be worked out by hand from
the algorithm each traversal implements (the derivation is in the comment above
each expected row).  Part 2: general invariants on the Sibenik workloads.

Conventions used in the derivations:

* Scene S1: one triangle T = (0,0,0) (4,0,0) (0,4,0); the root is a leaf whose box
  is [0,4] x [0,4] x [0,0].
* Scene S2 (max_leaf=1): A = T (id 0) and B = T + (10,0,0) (id 1): node 0 is the
  root (split axis x, box [0,14] x [0,4] x [0,0]), node 1 the leaf of A, node 2
  the leaf of B.
* Unless tilted, every ray starts at z = 5 and points straight down, d = (0,0,-1):
  d.x = +0 >= 0, so every traversal visits the left child (A) first.  Its
  reciprocal direction is (+inf, +inf, -1); the interval-arithmetic (IA) test
  skips axes whose reciprocal interval is not finite and of one sign, so only z is
  used, where every box (flat at z = 0) spans t = 5 .. 5: tn = tf = 5, and the IA
  test NEVER culls these packets.  (Origins are never on a box plane, so the
  zero direction components do not meet a 0 * inf.)
* Ray kinds: h/a = hits T/A, b = hits B, g = hits the root box only (x = 7, in
  the gap), m = misses the root box (y = 6).
* Lanes are listed in sub-packet order; a packet is one sub-packet starting at
  lane 0, so lane i is also its absolute index (groups = lanes 4k..4k+3).
* single: one scalar box test (box1) per node a ray visits, one scalar triangle
  test (tri1) per triangle of every leaf whose box the ray hits.
  Per ray in S1: h -> box1 1, tri1 1; m -> box1 1.
  Per ray in S2: a, b -> box1 3 (root, A, B), tri1 1; g -> box1 3; m -> box1 1.
"""
import numpy as np
import pytest

import raysort
from raysort.bvh import BVH
from raysort.rays import RayBatch, gather, scatter

BUILTIN = ["single", "masked", "partition", "ranged"]
FIELDS = ("rays", "ia", "box1", "box4", "tri1", "tri4")
F32 = np.float32

T = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0]], F32)
S1 = (T, np.array([[0, 1, 2]], np.int32))
S2 = (np.vstack([T, T + F32([10, 0, 0])]), np.array([[0, 1, 2], [3, 4, 5]], np.int32))

XY = {
    "h": [(1, 1), (1.5, 0.5), (0.5, 2), (2, 1), (1, 1.5), (0.25, 0.25), (3, 0.5), (1, 2.5)],
    "b": [(11, 1), (12, 1), (11, 2), (10.5, 0.5), (11.5, 1.5)],
    "g": [(7, 1), (7.5, 2), (6, 3)],
    "m": [(7, 6), (1, 6), (2, 6), (3, 6.5), (0.5, 6), (12, 7), (5, 8), (9, 6)],
}
XY["a"] = XY["h"]


def packet(kinds, tilt=0.0):
    """Rays for a lane pattern like "mhhh": straight down (or tilted by ``tilt`` in x and y)."""
    used = {k: 0 for k in XY}
    o, d, tmin = [], [], []
    for k in kinds:
        if k == "x":                                      # an invalid ray (tmin == tmax)
            o.append((1, 1, 5))
            d.append((0, 0, -1))
            tmin.append(np.inf)
            continue
        x, y = XY[k][used[k]]
        used[k] += 1
        o.append((x, y, 5))
        d.append((tilt, tilt, -1))
        tmin.append(0.0)
    rays = RayBatch.from_arrays(np.array(o, F32), np.array(d, F32))
    rays.tmin[:] = tmin
    return rays


def counters(name, mesh, rays, offsets=None, any_hit=False, max_leaf=1):
    bvh = BVH(*mesh, max_leaf=max_leaf)
    n = len(rays)
    offsets = np.array([0, n], np.int32) if offsets is None else offsets
    packets = gather(rays, np.arange(n, dtype=np.int32), offsets)
    c = raysort.create("traversals", name).intersect(bvh, packets, any_hit=any_hit)
    return c, scatter(packets, n)


def as_tuple(c):
    return tuple(getattr(c, f) for f in FIELDS)


def expect(rays, ia=0, box1=0, box4=0, tri1=0, tri4=0):
    return (rays, ia, box1, box4, tri1, tri4)


def test_scene_structure():
    """The tiny BVHs the derivations assume: S1 = one leaf; S2 = root (x split) + A + B."""
    b1 = BVH(*S1, max_leaf=1)
    assert len(b1.nodes) == 1 and b1.nodes[0]["count"] == 1
    assert b1.nodes[0]["lo"].tolist() == [0, 0, 0] and b1.nodes[0]["hi"].tolist() == [4, 4, 0]
    b2 = BVH(*S2, max_leaf=1)
    n = b2.nodes
    assert len(n) == 3 and n[0]["count"] == 0 and n[0]["axis"] == 0 and n[0]["offset"] == 2
    assert (n[1]["count"], n[2]["count"]) == (1, 1)
    assert b2.triangles["id"][n[1]["offset"]] == 0 and b2.triangles["id"][n[2]["offset"]] == 1
    assert n[0]["lo"].tolist() == [0, 0, 0] and n[0]["hi"].tolist() == [14, 4, 0]


def test_ray_kinds_hit_as_named():
    """Every ray kind hits what its name says (checked with the scalar traversal)."""
    _, hits = counters("single", S2, packet("aaaaabbbbbgggmmmmmmmm"))
    assert hits.prim.tolist() == [0] * 5 + [1] * 5 + [-1] * 11
    _, hits = counters("single", S1, packet("hhhhhhhhmmmmmmmm"))
    assert hits.prim.tolist() == [0] * 8 + [-1] * 8


# (scene, lanes, tilt, {traversal: expected (rays, ia, box1, box4, tri1, tri4)})
CASES = {
    # --- S1: the root is the leaf -------------------------------------------------------
    "S1 h": (S1, "h", 0.0, {
        "single": expect(1, box1=1, tri1=1),
        "masked": expect(1, box4=1, tri4=1),          # 1 group: box, then 1 tri for it
        "partition": expect(1, box4=1, tri4=1),       # first group hits; 1 tri x 1 group
        # first_hit: range [0,1) has no whole aligned group -> scalar box1 (hit);
        # last_hit(0,1): nothing after lane 0 -> 0; leaf_range [0,1): no group -> tri1
        "ranged": expect(1, box1=1, tri1=1),
    }),
    "S1 hhhh": (S1, "hhhh", 0.0, {
        "single": expect(4, box1=4, tri1=4),
        "masked": expect(4, box4=1, tri4=1),
        "partition": expect(4, box4=1, tri4=1),
        # first_hit [0,4): group 0 is whole -> speculative box1 on lane 0 hits;
        # last_hit(0,4): lo=1, b=align_up(1)=4 >= e=4 -> scalar from lane 3: box1 hits;
        # leaf_range [0,4): b=0 < e=4 -> one SIMD tri test for group 0
        "ranged": expect(4, box1=2, tri4=1),
    }),
    "S1 mmmm": (S1, "mmmm", 0.0, {
        "single": expect(4, box1=4),
        "masked": expect(4, box4=1),                  # the group misses: nothing else
        "partition": expect(4, box4=1),               # first group misses, ie == 1: no IA
        # speculative box1 (miss), IA (+1, no cull: straight down), head [1,0) empty,
        # group 0: box4 (miss), no tail -> culled
        "ranged": expect(4, ia=1, box1=1, box4=1),
    }),
    "S1 mhhhh": (S1, "mhhhh", 0.0, {
        "single": expect(5, box1=5, tri1=4),
        # 2 groups active: 2 box4; masks {1,2,3} and {4}: 1 tri x 2 groups
        "masked": expect(5, box4=2, tri4=2),
        # group 0 tested first (hits lanes 1-3), group 1 tested (hits): 2 box4, 2 tri4
        "partition": expect(5, box4=2, tri4=2),
        # first_hit [0,5): b=0 < e=4: speculative box1 lane 0 (miss), IA +1 (no cull),
        # group 0: box4 -> lanes 1..3 -> first = 1.  last_hit(1,5): lo=2, b=4 >= e=4 ->
        # scalar from lane 4: box1 (hit) -> last = 4.  leaf_range [1,5): b=4 >= e=4 ->
        # all scalar: 4 tri1
        "ranged": expect(5, ia=1, box1=2, box4=1, tri1=4),
    }),
    "S1 xhhhh": (S1, "xhhhh", 0.0, {
        # lane 0 is invalid (tmin = tmax = +inf): stored inactive, not a ray
        "single": expect(4, box1=4, tri1=4),
        "masked": expect(4, box4=2, tri4=2),          # group 0 still has lanes 1-3
        "partition": expect(4, box4=2, tri4=2),
        # first_hit skips inactive lane 0 -> first = 1; [1,5): b=4 >= e=4 -> scalar:
        # box1 lane 1 (hit).  last_hit(1,5) -> scalar from lane 4: box1 (hit).
        # leaf_range [1,5): all scalar: 4 tri1
        "ranged": expect(4, box1=2, tri1=4),
    }),
    "S1 hmmmmmmh": (S1, "hmmmmmmh", 0.0, {
        "single": expect(8, box1=8, tri1=2),
        "masked": expect(8, box4=2, tri4=2),          # both groups have a hitting lane
        "partition": expect(8, box4=2, tri4=2),
        # first_hit: speculative box1 lane 0 hits.  last_hit(0,8): lo=1, b=4 < e=8;
        # scalar tail [8,8) empty; group 4: box4 -> lane 7 = last.  leaf_range [0,8):
        # groups 0 and 4 -> 2 tri4
        "ranged": expect(8, box1=1, box4=1, tri4=2),
    }),
    "S1 mmmmmhhm": (S1, "mmmmmhhm", 0.0, {
        "single": expect(8, box1=8, tri1=2),
        "masked": expect(8, box4=2, tri4=1),          # only group 1 has hitting lanes
        # group 0 first: misses, ie=2 > 1 -> IA +1 (no cull); group 1: box4 hits ->
        # swapped to the front, live = 1; 1 tri x 1 group
        "partition": expect(8, ia=1, box4=2, tri4=1),
        # first_hit: spec box1 lane 0 (miss), IA +1, group 0 box4 (miss), group 4 box4
        # -> first = 5.  last_hit(5,8): lo=6, b=8 >= e=8 -> scalar lane 7 (miss), lane 6
        # (hit): 2 box1.  leaf_range [5,7): b=8 >= e=4 -> 2 tri1
        "ranged": expect(8, ia=1, box1=3, box4=2, tri1=2),
    }),
    "S1 mmmmmmmm tilted": (S1, "mmmmmmmm", 2.0 ** -10, {
        # d = (2^-10, 2^-10, -1): reciprocals (1024, 1024, -1) are finite and one-signed,
        # so IA uses y: box y in [0,4], origins y in [6,8] -> t_y in [(0-8)*1024,
        # (4-6)*1024] = [-8192, -2048]: tf <= -2048 < 0 <= tn, the IA test culls
        "single": expect(8, box1=8),
        "masked": expect(8, box4=2),
        "partition": expect(8, ia=1, box4=1),         # group 0 misses, IA culls
        "ranged": expect(8, ia=1, box1=1),            # speculative miss, IA culls
    }),
    # --- S2: root + leaf A (left) + leaf B (right) --------------------------------------
    "S2 a": (S2, "a", 0.0, {
        "single": expect(1, box1=3, tri1=1),
        # root box4, A box4 (hit) + tri4, B box4 (root mask non-empty; misses)
        "masked": expect(1, box4=3, tri4=1),
        # root 1, A 1 (hit) + tri4, B 1 (miss, ie == 1: no IA)
        "partition": expect(1, box4=3, tri4=1),
        # no whole group anywhere: scalar box1 at root, A, B; leaf A: 1 tri1
        "ranged": expect(1, box1=3, tri1=1),
    }),
    "S2 aabb": (S2, "aabb", 0.0, {
        "single": expect(4, box1=12, tri1=4),
        # root 1; A 1 -> mask {0,1} -> 1 tri4; B 1 -> mask {2,3} -> 1 tri4
        "masked": expect(4, box4=3, tri4=2),
        "partition": expect(4, box4=3, tri4=2),       # one group: it hits every node
        # root: spec box1 lane 0 hits.  A: spec box1 lane 0 hits; last_hit(0,4): b=4 >=
        # e=4 -> scalar lanes 3 (miss), 2 (miss), 1 (hit): 3 box1; leaf_range [0,2): 2 tri1.
        # B: spec box1 lane 0 (miss), IA +1 (no cull), group 0 box4 -> lane 2;
        # last_hit(2,4): scalar lane 3 (hit): 1 box1; leaf_range [2,4): 2 tri1
        # box1 = 1 + 1 + 3 + 1 + 1 = 7
        "ranged": expect(4, ia=1, box1=7, box4=1, tri1=4),
    }),
    "S2 mgabaaaa": (S2, "mgabaaaa", 0.0, {
        # m 1 + g 3 + 5 a x 3 + b 3 = 22 box1; 5 a + 1 b = 6 tri1
        "single": expect(8, box1=22, tri1=6),
        # root 2 -> masks {1,2,3} {4..7}; A 2 -> {2} {4..7} -> 2 tri4;
        # B 2 -> {3} {} -> 1 tri4
        "masked": expect(8, box4=6, tri4=3),
        # root: g0 hits, g1 hits (2 box4, live 2); A: g0 hits, g1 hits -> 2 tri4;
        # B: g0 hits (lane 3), g1 misses -> live 1 -> 1 tri4
        "partition": expect(8, box4=6, tri4=3),
        # root: spec box1 lane 0 (m, miss), IA +1, group 0 box4 -> first = 1.
        # A from 1: b=4 < e=8: spec box1 lane 1 (g, miss), IA +1, head lane 2 box1 (hit)
        #   -> first = 2; last_hit(2,8): tail empty, group 4 box4 -> last = 7;
        #   leaf_range [2,8): head lanes 2,3 -> 2 tri1, group 4 -> 1 tri4.
        # B from 1: spec box1 lane 1 (miss), IA +1, head lanes 2 (miss), 3 (hit): 2 box1
        #   -> first = 3; last_hit(3,8): lo=4, b=4 < e=8: group 4 box4 (miss), head
        #   [3,4) from lane 3 down to lo=4: empty -> last = 3; leaf_range [3,4): 1 tri1.
        # box1 = 1 + 1 + 1 + 1 + 2 = 6; box4 = 1 + 1 + 1 = 3
        "ranged": expect(8, ia=3, box1=6, box4=3, tri1=3, tri4=1),
    }),
    "S2 baaaa": (S2, "baaaa", 0.0, {
        "single": expect(5, box1=15, tri1=5),
        # root 2 -> {0..3} {4}; A 2 -> {1,2,3} {4} -> 2 tri4; B 2 -> {0} {} -> 1 tri4
        "masked": expect(5, box4=6, tri4=3),
        # root 2 (both hit); A: g0 hits, g1 hits -> 2 tri4; B: g0 hits, g1 misses -> 1
        "partition": expect(5, box4=6, tri4=3),
        # root: spec box1 lane 0 (b) hits.  A: spec box1 lane 0 (miss), IA +1, group 0
        #   box4 -> first = 1; last_hit(1,5): b=4 >= e=4 -> scalar lane 4 (hit) -> 4;
        #   leaf_range [1,5): all scalar, 4 tri1.
        # B: spec box1 lane 0 (hit); last_hit(0,5): b=4 >= e=4 -> scalar lanes 4,3,2,1
        #   (all miss): 4 box1 -> last = 0; leaf_range [0,1): 1 tri1.
        # box1 = 1 + 1 + 1 + 1 + 4 = 8
        "ranged": expect(5, ia=1, box1=8, box4=1, tri1=5),
    }),
    "S2 bbbbaaaa": (S2, "bbbbaaaa", 0.0, {
        "single": expect(8, box1=24, tri1=8),
        "masked": expect(8, box4=6, tri4=2),          # root 2, A 2, B 2; one group each
        # root: ids [g0, g1], both hit.  A: g0 first (miss), ie=2 -> IA +1 (no cull), g1
        # hits -> swapped to the front: ids [g1, g0], live 1 -> 1 tri4.  B resumes with
        # ie=2 but ids [g1, g0]: g1 first (miss) -> IA +1, g0 hits -> 1 tri4
        "partition": expect(8, ia=2, box4=6, tri4=2),
        # root: spec box1 lane 0 hits.  A: spec box1 lane 0 (miss), IA +1, groups 0
        #   (miss) and 4 (hit) box4 -> first = 4; last_hit(4,8): lo=5, b=8 >= e=8 ->
        #   scalar lane 7 (hit); leaf_range [4,8): group 4 -> 1 tri4.
        # B: spec box1 lane 0 (hit); last_hit(0,8): tail empty, group 4 box4 (miss),
        #   head lane 3 box1 (hit) -> 3; leaf_range [0,4): group 0 -> 1 tri4.
        # box1 = 1 + 1 + 1 + 1 + 1 = 5; box4 = 2 + 1 = 3
        "ranged": expect(8, ia=1, box1=5, box4=3, tri4=2),
    }),
}


@pytest.mark.parametrize("name", BUILTIN)
@pytest.mark.parametrize("case", list(CASES))
def test_hand_counted(name, case):
    """Exact counters of each traversal on a hand-analysed tiny BVH and packet."""
    mesh, lanes, tilt, table = CASES[case]
    c, _ = counters(name, mesh, packet(lanes, tilt))
    got = as_tuple(c)
    assert got == table[name], (f"{name} {case}: got {dict(zip(FIELDS, got))}, "
                                f"expected {dict(zip(FIELDS, table[name]))}")
    assert c.available is True


@pytest.mark.parametrize("name", BUILTIN)
@pytest.mark.parametrize("mesh_name", ["S1", "S2"])
def test_hand_counted_cases_sum_over_subpackets(name, mesh_name):
    """All cases of one scene gathered as consecutive sub-packets of one call count the sum
    of the cases (sub-packets are traced independently; padding lanes cost nothing)."""
    cases = [CASES[k] for k in CASES if k.startswith(mesh_name)]
    mesh = cases[0][0]
    batches = [packet(lanes, tilt) for _, lanes, tilt, _ in cases]
    rays = RayBatch(sum(len(b) for b in batches))
    rays.data[:, :len(rays)] = np.concatenate([b.data[:, :len(b)] for b in batches], axis=1)
    offsets = np.concatenate([[0], np.cumsum([len(b) for b in batches])]).astype(np.int32)
    c, _ = counters(name, mesh, rays, offsets)
    expected = tuple(sum(t[3][name][k] for t in cases) for k in range(len(FIELDS)))
    assert as_tuple(c) == expected


ANY_HIT = {
    # S2, one ray over A, any_hit: the hit at A retires the ray (t = -inf)
    # single: root, A (hit, 1 tri1, retired) -> stops: B is never tested
    "single": expect(1, box1=2, tri1=1),
    # masked: B is still visited with the root's mask: 1 box4 (which the retired lane misses)
    "masked": expect(1, box4=3, tri4=1),
    "partition": expect(1, box4=3, tri4=1),
    # ranged: at B first_hit skips the retired lane -> no test at all
    "ranged": expect(1, box1=2, tri1=1),
}


@pytest.mark.parametrize("name", BUILTIN)
def test_hand_counted_any_hit(name):
    """An any-hit query stops testing a ray once it has found a hit."""
    c, _ = counters(name, S2, packet("a"), any_hit=True)
    assert as_tuple(c) == ANY_HIT[name]


# ---------------------------------------------------------------------------
# invariants on real workloads
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sib(sibenik, workloads):
    """Sibenik's BVH and its diffuse workload with a few invalid rays mixed in."""
    bvh = BVH(sibenik.vertices, sibenik.faces)
    work = workloads(sibenik, "diffuse")
    rays = work.rays.take(np.arange(len(work.rays)))
    rays.tmin[5::97] = np.inf                             # invalid: tmin >= tmax
    rays.origins[0, 7::89] = np.nan                          # invalid: NaN origin
    return bvh, work, rays


def valid_count(rays):
    o, d = rays.origins, rays.directions
    with np.errstate(invalid="ignore"):
        ok = (np.isfinite(o).all(0) & np.isfinite(d).all(0)
              & (rays.tmin >= 0) & (rays.tmin < rays.tmax))
    return int(ok.sum())


def run(name, bvh, rays, order, offsets, any_hit=False):
    packets = gather(rays, np.asarray(order, np.int32), np.asarray(offsets, np.int32))
    return raysort.create("traversals", name).intersect(bvh, packets, any_hit=any_hit)


@pytest.mark.parametrize("name", BUILTIN)
@pytest.mark.parametrize("kind", ["primary", "diffuse"])
def test_counter_kinds_and_rays(name, kind, sibenik, workloads, sib):
    """single counts only scalar tests and no IA; masked only SIMD tests, no IA; partition
    only SIMD tests (and IA); rays = valid rays (padding and invalid lanes excluded);
    per_ray divides by rays; two runs count the same."""
    bvh = sib[0]
    rays = sib[2] if kind == "diffuse" else workloads(sibenik, kind).rays
    n, valid = len(rays), valid_count(rays)
    assert kind == "primary" or valid < n
    rng = np.random.default_rng(1)
    order = rng.permutation(n)
    for size in (5, 64, 1024):                              # 5: 3 padding lanes per packet
        offsets = np.append(np.arange(0, n, size), n)
        c = run(name, bvh, rays, order, offsets)
        assert c.rays == valid
        if name == "single":
            assert c.box4 == c.tri4 == c.ia == 0 and c.box1 > 0 and c.tri1 > 0
        elif name == "masked":
            assert c.box1 == c.tri1 == c.ia == 0 and c.box4 > 0 and c.tri4 > 0
        elif name == "partition":
            assert c.box1 == c.tri1 == 0 and c.box4 > 0 and c.tri4 > 0
        else:
            assert c.box1 > 0 and c.box4 > 0 and c.tri1 + c.tri4 > 0
        per = c.per_ray()
        assert set(per) == {"ia", "box1", "box4", "tri1", "tri4"}
        for key, value in per.items():
            assert value == getattr(c, key) / c.rays
        again = run(name, bvh, rays, order, offsets)
        assert again == c


def test_single_any_hit_counts_fewer(sib):
    """single follows each ray's closest-hit path until its first hit and then stops, so an
    any-hit query counts the same rays and no more tests."""
    bvh, _, rays = sib
    n = len(rays)
    offsets = np.append(np.arange(0, n, 64), n)
    closest = run("single", bvh, rays, np.arange(n), offsets)
    anyhit = run("single", bvh, rays, np.arange(n), offsets, any_hit=True)
    assert anyhit.rays == closest.rays
    assert anyhit.box1 < closest.box1 and anyhit.tri1 < closest.tri1


def test_single_counts_do_not_depend_on_packets(sib):
    """single traces each ray alone: its totals are the same for any order and packet sizes."""
    bvh, _, rays = sib
    n = len(rays)
    rng = np.random.default_rng(2)
    ref = run("single", bvh, rays, np.arange(n), [0, n])
    for size in (1, 3, 64, 1000):
        c = run("single", bvh, rays, rng.permutation(n), np.append(np.arange(0, n, size), n))
        assert c == ref


def test_one_ray_packets_count_like_single(sib):
    """With one ray per sub-packet every traversal does exactly the scalar traversal's work:
    masked/partition box4 and tri4 equal single's box1 and tri1 (one 4-wide test per node
    and triangle, no IA since ie == 1); ranged has no aligned group, so it is all scalar."""
    bvh, _, rays = sib
    n = len(rays)
    offsets = np.arange(n + 1)
    s = run("single", bvh, rays, np.arange(n), offsets)
    for name in ("masked", "partition"):
        c = run(name, bvh, rays, np.arange(n), offsets)
        assert (c.rays, c.ia, c.box1, c.box4, c.tri1, c.tri4) == \
            (s.rays, 0, 0, s.box1, 0, s.tri1), name
    c = run("ranged", bvh, rays, np.arange(n), offsets)
    assert (c.rays, c.ia, c.box1, c.box4, c.tri1, c.tri4) == (s.rays, 0, s.box1, 0, s.tri1, 0)


def test_counters_add():
    """Counters add field by field; availability is kept only if both are available."""
    a = raysort.Counters(rays=1, ia=2, box1=3, box4=4, tri1=5, tri4=6)
    b = raysort.Counters(rays=10, ia=20, box1=30, box4=40, tri1=50, tri4=60, available=False)
    s = a + b
    assert (s.rays, s.ia, s.box1, s.box4, s.tri1, s.tri4) == (11, 22, 33, 44, 55, 66)
    assert s.available is False and (a + a).available is True
    assert b.per_ray() == {k: None for k in ("ia", "box1", "box4", "tri1", "tri4")}
    assert raysort.Counters().per_ray() == {k: 0.0 for k in ("ia", "box1", "box4", "tri1", "tri4")}


def test_counters_add_in_place_like_add():
    """``total += c`` gives what ``total + c`` gives, in ``total`` itself, and leaves
    ``c`` alone (the pipeline's running totals), stream levels included."""
    a = raysort.Counters(rays=1, ia=2, box1=3, box4=4, tri1=5, tri4=6, stream_tasks=7,
                         stream_rays=8, stream_level_rays=(8, 3))
    b = raysort.Counters(rays=10, ia=20, box1=30, box4=40, tri1=50, tri4=60, stream_tasks=70,
                         stream_rays=80, stream_level_rays=(80, 30, 5), available=False)
    want = (a + b).as_dict()
    total, before = a, b.as_dict()
    total += b
    assert total is a and total.as_dict() == want
    assert b.as_dict() == before
    assert want["stream_level_rays"] == [88, 33, 5] and want["available"] is False


# ---------------------------------------------------------------------------
# wide: one 4-wide test of a node's (up to) four child boxes per node visited
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("kinds, mesh, expected", [
    # S1: the 4-wide root holds the single leaf.  Every valid ray tests the root's four
    # child boxes once (box4 1); "h" rays enter the leaf (tri1 1), "m" rays miss it.
    ("hhhh", S1, expect(4, box4=4, tri1=4)),
    ("mmmm", S1, expect(4, box4=4)),
    ("mhxh", S1, expect(3, box4=3, tri1=2)),
    # S2: the root holds both leaves A (x 0..4) and B (x 10..14).  An "a" ray enters A
    # only, a "b" ray B only, a "g" ray (x 6..7.5) neither: one box4 each, one tri1 per
    # leaf entered.
    ("aab", S2, expect(3, box4=3, tri1=3)),
    ("gggb", S2, expect(4, box4=4, tri1=1)),
])
def test_wide_hand_counted(kinds, mesh, expected):
    c, _ = counters("wide", mesh, packet(kinds))
    assert as_tuple(c) == expected


def test_wide_counts_only_its_kinds_and_not_packets(sib):
    """wide counts SIMD box tests (four child boxes each) and scalar triangle tests only,
    and traces each ray alone: its totals do not depend on order or sub-packet sizes."""
    bvh, _, rays = sib
    n = len(rays)
    ref = run("wide", bvh, rays, np.arange(n), [0, n])
    assert ref.ia == ref.box1 == ref.tri4 == 0 and ref.box4 > 0 and ref.tri1 > 0
    assert ref.rays == valid_count(rays)
    rng = np.random.default_rng(5)
    for size in (1, 7, 256):
        assert run("wide", bvh, rays, rng.permutation(n),
                   np.append(np.arange(0, n, size), n)) == ref
