"""Ray containers and the gather/scatter between batch order and aligned sub-packets.

References are computed here with NumPy: the gathered lanes are compared bit
for bit with the source rows read through ``packets.index``, inverse
directions with ``np.float32(1) / d``, and the layout with the documented
rules (each sub-packet starts at a multiple of 4 right after the previous
one's padded end; every row 16-byte aligned; padding and invalid rays
inactive: tmin=+inf, t=-inf, prim=-1).
"""
import numpy as np
import pytest

import raysort.isa
from raysort.errors import ConfigError
from raysort.rays import (MAX_PACKET, Hits, Packets, RayBatch, RayRow, add_unoccluded, gather,
                          scatter, scatter_occluded)

from _helpers import random_rays

BOX = np.array([[-1, -2, -3], [1, 2, 3]], dtype=np.float32)
ROW_OF = {"ox": 0, "oy": 1, "oz": 2, "dx": 3, "dy": 4, "dz": 5, "ix": 6, "iy": 7, "iz": 8,
          "tmin": 9, "t": 10}


def bits(a):
    return np.ascontiguousarray(a).view(np.uint32)


def round4(n):
    return (n + 3) // 4 * 4


def assert_aligned(arr, label=""):
    assert arr.ctypes.data % 16 == 0, f"{label} starts at {arr.ctypes.data:#x}"


def random_split(rng, n, sizes=(1, 2, 3, 4, 5, 7, 8, 63, 64, 65, 100)):
    """Offsets cutting n into sub-packets of assorted sizes."""
    offsets = [0]
    while offsets[-1] < n:
        offsets.append(min(n, offsets[-1] + int(rng.choice(sizes))))
    return np.array(offsets, dtype=np.int32)


def check_layout(packets, order, offsets):
    """counts, starts, index and the padding follow from (order, offsets)."""
    counts = np.diff(offsets)
    assert np.array_equal(packets.counts, counts)
    assert packets.starts.dtype == np.int32 and packets.counts.dtype == np.int32
    assert packets.index.dtype == np.int32 and packets.prim.dtype == np.int32
    assert packets.rows.dtype == np.float32 and packets.rows.shape[0] == 11
    expected_starts = np.concatenate([[0], np.cumsum([round4(c) for c in counts])[:-1]]) \
        if len(counts) else np.zeros(0)
    assert np.array_equal(packets.starts, expected_starts)
    assert (packets.starts % 4 == 0).all()
    cap, used = packets.capacity, max(4, sum(round4(c) for c in counts))
    assert spread_rows(cap) and used <= cap <= used + 1024
    for arr in (packets.prim, packets.u, packets.v, packets.index):
        assert arr.shape == (cap,)
    expected_index = np.full(cap, -1, dtype=np.int64)
    for k, (s, c) in enumerate(zip(packets.starts, counts)):
        expected_index[s:s + c] = order[offsets[k]:offsets[k] + c]
    assert np.array_equal(packets.index, expected_index)


def check_alignment(packets):
    for r in range(11):
        assert_aligned(packets.rows[r], f"row {r}")
        for s in packets.starts:
            assert_aligned(packets.rows[r, s:], f"row {r} at sub-packet start {s}")
    for label in ("prim", "u", "v", "index"):
        arr = getattr(packets, label)
        assert_aligned(arr, label)
        for s in packets.starts:
            assert_aligned(arr[s:], f"{label} at {s}")


def check_inactive(packets, lanes, label):
    assert (packets.rows[ROW_OF["tmin"], lanes] == np.inf).all(), f"{label}: tmin"
    assert (packets.rows[ROW_OF["t"], lanes] == -np.inf).all(), f"{label}: t"
    assert (packets.prim[lanes] == -1).all(), f"{label}: prim"


# -- RayBatch ---------------------------------------------------------------------------

def spread_rows(lanes):
    """Rows of 4 kB or more (1024 lanes) sit one cache line past a multiple of 4 kB
    apart, so a kernel's accesses at one lane of every row fall in different cache sets;
    shorter rows are not padded beyond the multiple of 4."""
    return lanes % 1024 == 16 if lanes >= 1024 else lanes % 4 == 0


@pytest.mark.parametrize("n", [0, 1, 3, 4, 5, 8, 1008, 1023, 1024, 1040, 4097, 65536])
def test_raybatch_layout(n):
    """Capacity a multiple of 4 (at least 4, its rows spread over the cache sets), rows
    16-byte aligned, padding inactive."""
    b = RayBatch(n)
    assert len(b) == n and b.n == n
    assert b.data.dtype == np.float32 and b.data.flags.c_contiguous
    capacity = b.data.shape[1]
    assert b.data.shape[0] == len(RayRow) and spread_rows(capacity)
    assert max(4, round4(n)) <= capacity <= max(4, round4(n)) + 1024
    if n < 1008:
        assert capacity == max(4, round4(n))
    for r in RayRow:
        assert_aligned(b.data[r], f"row {r.name}")
    assert (b.data[:, :n] == 0).all()
    assert ((b.data[RayRow.tmin, n:] == np.inf).all()
            and (b.data[RayRow.tmax, n:] == -np.inf).all())
    assert b.origins.shape == (3, n) and b.directions.shape == (3, n)
    assert b.tmin.shape == (n,) and b.tmax.shape == (n,)
    if n:   # the row views write through to data
        for view in (b.origins, b.directions, b.tmin, b.tmax):
            assert np.shares_memory(view, b.data)


def test_raybatch_negative_size():
    with pytest.raises(ConfigError):
        RayBatch(-1)


def test_from_arrays_values(rng):
    """Origins/directions land in rows 0-5 (float32), scalar or per-ray tmin/tmax."""
    o, d = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    b = RayBatch.from_arrays(o, d)
    assert np.array_equal(bits(b.origins), bits(o.T.astype(np.float32)))
    assert np.array_equal(bits(b.directions), bits(d.T.astype(np.float32)))
    assert (b.tmin == 0).all() and (b.tmax == np.inf).all()
    assert ((b.data[RayRow.tmin, 7:] == np.inf).all()
            and (b.data[RayRow.tmax, 7:] == -np.inf).all())
    tmin, tmax = np.linspace(0, 1, 7), np.linspace(2, 3, 7)
    b = RayBatch.from_arrays(o, d, tmin=tmin, tmax=tmax)
    assert np.array_equal(b.tmin, tmin.astype(np.float32))
    assert np.array_equal(b.tmax, tmax.astype(np.float32))
    b = RayBatch.from_arrays(o, d, tmin=0.5, tmax=9)
    assert (b.tmin == 0.5).all() and (b.tmax == 9).all()
    empty = RayBatch.from_arrays(np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(empty) == 0 and empty.data.shape == (8, 4)


@pytest.mark.parametrize("o_shape, d_shape", [
    ((5, 2), (5, 2)), ((5, 3), (4, 3)), ((5, 3), (5, 2)), ((3,), (3,)), ((15,), (5, 3)),
    ((2, 5, 3), (2, 5, 3)), ((3, 5), (3, 5)),
])
def test_from_arrays_shape_validation(o_shape, d_shape):
    """Anything but two (n, 3) arrays is a ConfigError."""
    with pytest.raises(ConfigError, match="shape"):
        RayBatch.from_arrays(np.zeros(o_shape), np.ones(d_shape))


def test_take(rng):
    """take copies the chosen rays (repeats allowed) into a new, independent batch."""
    src = random_rays(rng, 10, BOX)
    src.tmax[:] = np.arange(10, 20)
    idx = np.array([9, 0, 3, 3, 7])
    out = src.take(idx)
    assert isinstance(out, RayBatch) and len(out) == 5
    assert np.array_equal(bits(out.data[:, :5]), bits(src.data[:, idx]))
    assert out.data.shape == (len(RayRow), 8)
    assert ((out.data[RayRow.tmin, 5:] == np.inf).all()
            and (out.data[RayRow.tmax, 5:] == -np.inf).all())
    for r in RayRow:
        assert_aligned(out.data[r])
    assert not np.shares_memory(out.data, src.data)
    out.origins[:] = 42
    assert not (src.origins == 42).any()
    assert len(src.take([])) == 0 and len(src.take(np.arange(10))) == 10


def test_truncate(rng):
    """truncate keeps the first k rays in place and makes the rest inactive padding."""
    b = random_rays(rng, 10, BOX)
    before = b.data.copy()
    data = b.data
    assert b.truncate(6) is b
    assert len(b) == 6 and b.data is data
    assert np.array_equal(bits(b.data[:, :6]), bits(before[:, :6]))
    assert ((b.data[RayRow.tmin, 6:] == np.inf).all()
            and (b.data[RayRow.tmax, 6:] == -np.inf).all())
    assert b.origins.shape == (3, 6)
    # the truncated rays are never gathered
    p = gather(b, np.arange(6, dtype=np.int32), np.array([0, 6], np.int32))
    assert set(p.index.tolist()) == set(range(6)) | {-1}
    b.truncate(0)
    assert len(b) == 0
    for k in (-1, 1):
        with pytest.raises(ValueError):
            b.truncate(k)


@pytest.mark.parametrize("n", [1, 5, 4097, 70_001])
def test_an_unfilled_batch_written_then_truncated_has_clean_padding(each_isa, rng, n):
    """RayBatch._unfilled (the shaders' output): the layout of RayBatch(n); after its
    writer truncates it, the lanes past the kept rays are padding as RayBatch's are
    (zero origin and direction, inactive), whatever the memory held before."""
    for _ in range(3):      # recycled memory full of old rays
        random_rays(rng, n, BOX)
    b = RayBatch._unfilled(n)
    assert b.data.shape == RayBatch(n).data.shape and b.prev_t is None
    assert ((b.data[RayRow.tmin, n:] == np.inf).all()
            and (b.data[RayRow.tmax, n:] == -np.inf).all())
    b.data[:, :n] = random_rays(rng, n, BOX).data[:, :n]
    k = n // 2
    kept = b.data[:, :k].copy()
    b.truncate(k)
    assert np.array_equal(bits(b.data[:, :k]), bits(kept))
    rows = [RayRow.ox, RayRow.oy, RayRow.oz, RayRow.dx, RayRow.dy, RayRow.dz]
    assert (bits(b.data[rows, k:]) == 0).all()
    assert ((b.data[RayRow.tmin, k:] == np.inf).all()
            and (b.data[RayRow.tmax, k:] == -np.inf).all())


@pytest.mark.parametrize("a, b", [(0, 0), (0, 1), (3, 4), (1, 17), (5, 100), (64, 1000),
                                  (13, 2064)])
def test_pad_rays_writes_padding_to_those_lanes_only(each_isa, rng, a, b):
    """The padding kernel (``truncate``'s, with stores that bypass the caches) at every
    alignment: lanes a..b get origin and direction 0 and tmin +inf, tmax -inf; every
    other lane keeps its bits."""
    data = random_rays(rng, 2064, BOX).data
    before = data.copy()
    raysort.isa.module("_gather").pad_rays(data, a, b)
    rows = [RayRow.ox, RayRow.oy, RayRow.oz, RayRow.dx, RayRow.dy, RayRow.dz]
    assert (bits(data[rows, a:b]) == 0).all()
    assert (data[RayRow.tmin, a:b] == np.inf).all() and (data[RayRow.tmax, a:b] == -np.inf).all()
    outside = np.ones(data.shape[1], bool)
    outside[a:b] = False
    assert np.array_equal(bits(data[:, outside]), bits(before[:, outside]))
    with pytest.raises(ValueError):
        raysort.isa.module("_gather").pad_rays(data, b, a - 1)


def test_hits_defaults():
    """Hits(n): t=+inf float32, prim=-1 int32, u=v=0 float32."""
    h = Hits(5)
    assert len(h) == 5
    assert h.t.dtype == np.float32 and (h.t == np.inf).all()
    assert h.prim.dtype == np.int32 and (h.prim == -1).all()
    for a in (h.u, h.v):
        assert a.dtype == np.float32 and (a == 0).all()
    assert len(Hits(0)) == 0


# -- gather ---------------------------------------------------------------------------

@pytest.fixture
def gathered(rng):
    n = 777
    rays = random_rays(rng, n, BOX)
    rays.tmin[:] = rng.random(n).astype(np.float32) * 0.1
    rays.tmax[:] = 1 + rng.random(n).astype(np.float32) * 100
    rays.tmax[::5] = np.inf
    order = rng.permutation(n).astype(np.int32)
    offsets = random_split(rng, n)
    return rays, order, offsets, gather(rays, order, offsets)


def test_gather_layout_and_alignment(gathered):
    """Sub-packet starts are multiples of 4, packed, every row and start 16-byte aligned."""
    rays, order, offsets, packets = gathered
    assert isinstance(packets, Packets) and packets.n_packets == len(offsets) - 1
    check_layout(packets, order, offsets)
    check_alignment(packets)


def test_gather_copies_rays_bit_for_bit(gathered):
    """Reading the source through packets.index gives the gathered rows exactly; t starts at
    tmax; prim -1, u = v = 0."""
    rays, order, offsets, packets = gathered
    lanes = np.flatnonzero(packets.index >= 0)
    assert len(lanes) == len(rays)
    src = rays.data[:, packets.index[lanes]]
    for row, name in enumerate(("ox", "oy", "oz", "dx", "dy", "dz", "tmin", "t")):
        assert np.array_equal(bits(packets.rows[ROW_OF[name], lanes]), bits(src[row])), name
    assert (packets.prim == -1).all()
    assert (packets.u == 0).all() and (packets.v == 0).all()


def test_gather_inverse_directions(gathered):
    """ix, iy, iz are 1/d computed in float32, bit for bit."""
    rays, _, _, packets = gathered
    lanes = np.flatnonzero(packets.index >= 0)
    d = rays.directions[:, packets.index[lanes]]
    want = np.float32(1) / d
    assert want.dtype == np.float32
    assert np.array_equal(bits(packets.inverse_directions[:, lanes]), bits(want))


def test_gather_padding_inactive(gathered):
    """Lanes with index -1 (padding after short sub-packets and at the end) are inactive."""
    _, _, _, packets = gathered
    pad = np.flatnonzero(packets.index == -1)
    assert len(pad) > 0
    check_inactive(packets, pad, "padding")


def test_gather_empty():
    """No rays: four inactive padding lanes, no sub-packets."""
    p = gather(RayBatch(0), np.zeros(0, np.int32), np.array([0], np.int32))
    assert p.n_packets == 0 and p.capacity == 4
    assert (p.index == -1).all()
    check_inactive(p, np.arange(4), "empty batch")
    check_alignment(p)
    h = scatter(p, 0)
    assert len(h) == 0
    assert len(scatter_occluded(p, 0)) == 0


@pytest.mark.parametrize("sizes", [[1], [3], [4], [5], [1, 1, 1], [4096], [4096, 1], [2, 4096]])
def test_gather_sizes(rng, sizes):
    """Assorted sub-packet sizes up to MAX_PACKET, in reverse ray order."""
    n = sum(sizes)
    rays = random_rays(rng, n, BOX)
    order = np.arange(n, dtype=np.int32)[::-1].copy()
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int32)
    assert max(sizes) <= MAX_PACKET
    p = gather(rays, order, offsets)
    check_layout(p, order, offsets)
    check_alignment(p)
    check_inactive(p, np.flatnonzero(p.index == -1), "padding")
    lanes = np.flatnonzero(p.index >= 0)
    assert np.array_equal(bits(p.rows[:RayRow.tmin, lanes]),
                          bits(rays.data[:RayRow.tmin, p.index[lanes]]))


def special_rays():
    """Valid edge cases followed by invalid rays; returns (rays, valid mask)."""
    nan, inf = np.nan, np.inf
    rows = [  # origin, direction, tmin, tmax, valid
        ((0, 0, 0), (1, 0, 0), 0, inf, True),              # zero components: inverse +-inf
        ((1, 2, 3), (-0.0, 0.0, -1), 0, inf, True),        # -0.0 -> -inf
        ((1, 2, 3), (3e-39, -3e-39, 1), 0, 10, True),      # subnormal: stored as +-0
        ((1, 2, 3), (0.7, 0.1, -0.2), -0.0, 1, True),      # tmin = -0.0 counts as >= 0
        ((1, 2, 3), (1e-30, 1e30, 2), 1, 1.0000001, True),
        ((1, 2, 3), (0, 0, 0), 0, 1, True),                # finite, so valid
        ((3e38, -3e38, 0), (1, 1, 1), 0, inf, True),
        ((nan, 0, 0), (1, 0, 0), 0, inf, False),
        ((0, inf, 0), (1, 0, 0), 0, inf, False),
        ((0, 0, -inf), (1, 0, 0), 0, inf, False),
        ((0, 0, 0), (nan, 1, 0), 0, inf, False),
        ((0, 0, 0), (1, inf, 0), 0, inf, False),
        ((0, 0, 0), (1, 0, -inf), 0, inf, False),
        ((0, 0, 0), (1, 0, 0), -1, inf, False),            # tmin < 0
        ((0, 0, 0), (1, 0, 0), -1e-30, inf, False),
        ((0, 0, 0), (1, 0, 0), 2, 2, False),               # tmin == tmax
        ((0, 0, 0), (1, 0, 0), 3, 2, False),               # tmin > tmax
        ((0, 0, 0), (1, 0, 0), nan, 2, False),
        ((0, 0, 0), (1, 0, 0), 0, nan, False),
        ((0, 0, 0), (1, 0, 0), inf, inf, False),
        ((0, 0, 0), (1, 0, 0), 0, -inf, False),
    ]
    o = np.array([r[0] for r in rows], dtype=np.float32)
    d = np.array([r[1] for r in rows], dtype=np.float32)
    rays = RayBatch.from_arrays(o, d, tmin=np.array([r[2] for r in rows], np.float32),
                                tmax=np.array([r[3] for r in rows], np.float32))
    return rays, np.array([r[4] for r in rows])


@pytest.mark.parametrize("split", ["one-packet", "singletons", "mixed"])
def test_gather_invalid_rays_inactive(split):
    """NaN/inf origin or direction, tmin < 0, tmin >= tmax, NaN tmin/tmax: stored inactive;
    the valid edge cases are stored as given with exact float32 inverses."""
    rays, valid = special_rays()
    n = len(rays)
    order = np.arange(n, dtype=np.int32)[::-1].copy()
    offsets = {"one-packet": [0, n], "singletons": list(range(n + 1)),
               "mixed": [0, 3, 4, 9, 16, n]}[split]
    p = gather(rays, order, np.array(offsets, np.int32))
    check_layout(p, order, np.array(offsets))
    lane_of = np.empty(n, dtype=np.int64)
    lanes = np.flatnonzero(p.index >= 0)
    lane_of[p.index[lanes]] = lanes
    bad = lane_of[~valid]
    check_inactive(p, bad, "invalid ray")
    good = lane_of[valid]
    src = rays.data[:, :n][:, valid].copy()
    # subnormal direction components are stored as zeros of the same sign
    d = src[RayRow.dx:RayRow.dz + 1]
    src[RayRow.dx:RayRow.dz + 1] = np.where(np.abs(d) < np.finfo(np.float32).tiny,
                                            np.copysign(np.float32(0), d), d)
    assert np.array_equal(bits(p.rows[:RayRow.tmin, good]), bits(src[:RayRow.tmin]))
    assert np.array_equal(bits(p.tmin[good]), bits(src[RayRow.tmin]))
    assert np.array_equal(bits(p.t[good]), bits(src[RayRow.tmax]))
    with np.errstate(divide="ignore"):
        inv = np.float32(1) / src[RayRow.dx:RayRow.dz + 1]
    assert np.array_equal(bits(p.inverse_directions[:, good]), bits(inv))
    assert inv[0, 1] == -np.inf                                  # spot check of the cases
    sub = np.flatnonzero((np.abs(rays.directions[:, valid]) < np.finfo(np.float32).tiny)
                         & (rays.directions[:, valid] != 0))
    assert len(sub) > 0, "the special rays include subnormal direction components"
    assert not np.isnan(inv).any()
    # an invalid ray scatters back as a miss
    h = scatter(p, n)
    assert (h.prim[~valid] == -1).all() and (h.t[~valid] == np.inf).all()


# -- scatter --------------------------------------------------------------------------

def test_scatter_round_trip(gathered):
    """Hits written into lanes come back at the batch index of each lane; misses are
    t=+inf, prim=-1, u=v=0 whatever the lane held."""
    rays, order, offsets, packets = gathered
    n = len(rays)
    lanes = np.flatnonzero(packets.index >= 0)
    ray = packets.index[lanes]
    hit = ray % 3 != 0
    t = (ray.astype(np.float32) * np.float32(0.37) + np.float32(0.5)).astype(np.float32)
    packets.t[lanes] = t
    packets.prim[lanes] = np.where(hit, ray * 7 + 1, -1)
    packets.u[lanes] = np.float32(0.25) + ray.astype(np.float32) * np.float32(1e-4)
    packets.v[lanes] = np.float32(0.125)
    pad = packets.index < 0
    packets.prim[pad] = 99999                       # garbage in padding must be ignored
    h = scatter(packets, n)
    assert isinstance(h, Hits) and len(h) == n
    want_t = np.full(n, np.inf, np.float32)
    want_prim = np.full(n, -1, np.int32)
    want_u = np.zeros(n, np.float32)
    want_v = np.zeros(n, np.float32)
    want_t[ray[hit]] = t[hit]
    want_prim[ray[hit]] = ray[hit] * 7 + 1
    want_u[ray[hit]] = packets.u[lanes][hit]
    want_v[ray[hit]] = np.float32(0.125)
    assert np.array_equal(bits(h.t), bits(want_t))
    assert np.array_equal(h.prim, want_prim)
    assert np.array_equal(bits(h.u), bits(want_u)) and np.array_equal(bits(h.v), bits(want_v))
    # scattering into a given Hits overwrites every ray
    given = Hits(n)
    given.t[:] = 5
    given.prim[:] = 3
    assert scatter(packets, n, given) is given
    assert np.array_equal(bits(given.t), bits(want_t)) and np.array_equal(given.prim, want_prim)


def test_scatter_without_traversal_gives_tmax_as_t(gathered):
    """With prim set by hand to the ray index, scatter returns each ray's own tmax as t."""
    rays, _, _, packets = gathered
    lanes = np.flatnonzero(packets.index >= 0)
    packets.prim[lanes] = packets.index[lanes]
    h = scatter(packets, len(rays))
    assert np.array_equal(h.prim, np.arange(len(rays)))
    assert np.array_equal(bits(h.t), bits(rays.tmax))


def test_scatter_occluded(gathered):
    """scatter_occluded: True exactly where the ray's lane has prim >= 0; padding ignored."""
    rays, _, _, packets = gathered
    n = len(rays)
    lanes = np.flatnonzero(packets.index >= 0)
    ray = packets.index[lanes]
    packets.prim[lanes] = np.where(ray % 4 == 1, 0, np.where(ray % 4 == 2, 12, -1))
    packets.prim[packets.index < 0] = 5
    occ = scatter_occluded(packets, n)
    assert occ.dtype == bool and occ.shape == (n,)
    want = np.zeros(n, bool)
    want[ray] = np.isin(ray % 4, (1, 2))
    assert np.array_equal(occ, want)


# -- shadow-ray radiance --------------------------------------------------------------

def test_add_unoccluded_is_np_add_at(each_isa):
    """The same float64 sums as ``np.add.at`` (same order, repeated slots included), bit for
    bit, whatever sums it starts from, on every ISA (whole groups of 16 rays and a tail)."""
    rng = np.random.default_rng(5)
    m, slots = 5000, 37
    slot = rng.integers(0, slots, m).astype(np.int32)
    contribution = rng.random((3, 2 * m), dtype=np.float32)[:, :m]      # strided, as shaders
    occluded = rng.random(m) < 0.3
    start = rng.random((slots, 3))
    start[:4, 0] = -0.0, np.inf, -np.inf, np.nan     # an occluded ray leaves even these alone
    want = start.copy()
    np.add.at(want, slot[~occluded], contribution[:, ~occluded].T)
    got = start.copy()
    add_unoccluded(got, slot, contribution, occluded)
    assert np.array_equal(got.view(np.uint64), want.view(np.uint64))


@pytest.mark.parametrize("bad", [37, -1, 2**31 - 1])
def test_add_unoccluded_refuses_a_slot_out_of_range_and_adds_nothing(each_isa, bad):
    """A slot that is not a row of the radiance, even an occluded ray's, is an IndexError
    naming it, before anything is added."""
    slot = np.arange(40, dtype=np.int32) % 37
    slot[33] = bad
    radiance = np.zeros((37, 3))
    with pytest.raises(IndexError, match=r"slot\[33\]"):
        add_unoccluded(radiance, slot, np.ones((3, 40), np.float32), np.zeros(40, bool))
    assert not radiance.any()


@pytest.mark.parametrize("order, offsets", [
    ([0, 1, 1, 3], [0, 4]),            # a ray twice
    ([0, 1, 2, 7], [0, 4]),            # a ray beyond the batch
    ([0, 1, 2, 3], [0, 2, 2, 4]),      # an empty sub-packet
    ([0, 1, 2, 3], [0, 5]),            # offsets beyond the batch
    ([0, 1, 2], [0, 3]),               # too few rays
])
def test_gather_rejects_a_broken_sort_result(order, offsets):
    """The public gather checks the order it reads through (a ValueError, not a crash)."""
    rays = RayBatch.from_arrays(np.zeros((4, 3)), np.tile([0, 0, 1.0], (4, 1)))
    with pytest.raises(ValueError, match="permutation"):
        gather(rays, np.array(order, np.int32), np.array(offsets, np.int32))


def test_scatter_rejects_an_index_beyond_the_hits():
    rays = RayBatch.from_arrays(np.zeros((4, 3)), np.tile([0, 0, 1.0], (4, 1)))
    packets = gather(rays, np.arange(4, dtype=np.int32), np.array([0, 4], np.int32))
    packets.index[2] = 4
    with pytest.raises(ValueError, match="beyond"):
        scatter(packets, 4)
    with pytest.raises(ValueError, match="beyond"):
        scatter_occluded(packets, 4)


def test_gather_takes_one_sub_packet_larger_than_a_traversal_does():
    """A reference that loops over rays (raysort.reference) gathers the batch whole."""
    n = MAX_PACKET + 5
    rays = RayBatch.from_arrays(np.zeros((n, 3)), np.tile([0, 0, 1.0], (n, 1)))
    packets = gather(rays, np.arange(n, dtype=np.int32), np.array([0, n], np.int32))
    assert packets.counts.tolist() == [n] and (packets.index[:n] == np.arange(n)).all()
