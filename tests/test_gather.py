"""The gather on every ISA against a NumPy statement of its rules, and the recycling of
the memory of ray batches and packets between batches.

The reference lays the order out lane by lane (each sub-packet at a multiple of 4 right
after the previous one's padded end) and applies the packet rules with NumPy: a ray is
active when its origin and direction are finite and 0 <= tmin < tmax; an active lane
holds the ray (subnormal direction components as zeros of their sign, 1 / d in float32);
every other lane is inactive (zeros, tmin +inf, t -inf); the bad ray is the first lane's
ray that is active yet not finite or with tmin < 0.  Batches of odd sizes leave every
kind of tail past the widest SIMD block.
"""
import threading

import numpy as np
import pytest

from raysort.rays import (Hits, PacketRow, RayBatch, RayRow, gather, gather_checked, scatter,
                          scatter_checked)

from _helpers import random_rays

BOX = np.array([[-1, -2, -3], [1, 2, 3]], dtype=np.float32)
TINY = np.finfo(np.float32).tiny
SPECIAL = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 3e-39, -3e-39, 1e-45, -1.0],
                   dtype=np.float32)


def bits(a):
    return np.ascontiguousarray(a).view(np.uint32)


def hostile_rays(rng, n):
    """Random rays with special values (NaN, inf, zeros, subnormals, tmin < 0, empty
    intervals) sprinkled over every row."""
    rays = random_rays(rng, n, BOX)
    rays.tmin[:] = rng.random(n).astype(np.float32) * 0.1
    rays.tmax[:] = np.where(rng.random(n) < 0.3, np.inf, 1 + 50 * rng.random(n))
    if n:
        hit = rng.random((RayRow.tmax + 1, n)) < 0.06
        picks = rng.choice(SPECIAL, size=hit.shape)
        rays.data[:, :n][hit] = picks[hit]
    return rays


def split(rng, n):
    offsets = [0]
    while offsets[-1] < n:
        offsets.append(min(n, offsets[-1] + int(rng.choice([1, 2, 3, 4, 5, 7, 13, 16, 17, 40]))))
    return np.array(offsets, dtype=np.int32)


def reference(rays, order, offsets, lanes=0):
    """(rows, index, bad_ray) of the gathered packets, by the rules above, in ``lanes``
    lanes if that is more than the sub-packets take (the rest are padding)."""
    counts = np.diff(offsets).astype(np.int64)
    padded = (counts + 3) & ~3
    starts = np.concatenate([[0], np.cumsum(padded)[:-1]]).astype(np.int64)
    capacity = max(int(padded.sum()), 4, lanes)
    index = np.full(capacity, -1, np.int32)
    position = np.arange(len(order))
    k = np.searchsorted(offsets, position, side="right") - 1
    index[starts[k] + position - offsets[k]] = order
    present = index >= 0
    src = rays.data[:, np.where(present, index, 0)]
    o, d = src[RayRow.ox:RayRow.oz + 1], src[RayRow.dx:RayRow.dz + 1]
    tmin, tmax = src[RayRow.tmin], src[RayRow.tmax]
    good = (tmin >= 0) & np.isfinite(o).all(0) & np.isfinite(d).all(0)
    active = tmin < tmax
    ok = present & good & active
    d = np.where(np.abs(d) < TINY, np.copysign(np.float32(0), d), d).astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = np.float32(1) / d
    rows = np.empty((len(PacketRow), capacity), np.float32)
    rows[PacketRow.ox:PacketRow.oz + 1] = np.where(ok, o, np.float32(0))
    rows[PacketRow.dx:PacketRow.dz + 1] = np.where(ok, d, np.float32(0))
    rows[PacketRow.ix:PacketRow.iz + 1] = np.where(ok, inv, np.float32(0))
    rows[PacketRow.tmin] = np.where(ok, tmin, np.float32(np.inf))
    rows[PacketRow.t] = np.where(ok, tmax, np.float32(-np.inf))
    bad = np.flatnonzero(present & active & ~good)
    return rows, index, int(index[bad[0]]) if len(bad) else -1


@pytest.mark.parametrize("n", [0, 1, 2, 3, 5, 8, 13, 16, 17, 31, 33, 47, 64, 100, 257, 1000])
def test_gather_follows_the_rules_on_every_isa(each_isa, n):
    """Bit for bit: the rows, index, prim/u/v, the kept tmax and the bad ray, for batches
    whose lanes end in every tail a 4-, 8- or 16-lane block leaves."""
    rng = np.random.default_rng(n)
    rays = hostile_rays(rng, n)
    order = rng.permutation(n).astype(np.int32)
    offsets = split(rng, n)
    big = np.array([0, n], np.int32)
    for check_order in (True, False):
        p, tmax, bad_ray = gather_checked(rays, order, offsets, big, keep_tmax=True,
                                          check_order=check_order, max_packet=max(n, 1))
        want_rows, want_index, want_bad = reference(rays, order, offsets, p.capacity)
        assert np.array_equal(p.index, want_index)
        assert np.array_equal(bits(p.rows), bits(want_rows))
        assert np.array_equal(bits(tmax), bits(want_rows[PacketRow.t]))
        assert (p.prim == -1).all() and (bits(p.u) == 0).all() and (bits(p.v) == 0).all()
        assert bad_ray == want_bad


def runs(rng, n):
    """An order of consecutive runs (some longer than a SIMD block, some not) in shuffled
    places, with single rays between them."""
    pieces, start = [], 0
    while start < n:
        length = min(n - start, int(rng.choice([1, 3, 8, 9, 16, 17, 40])))
        pieces.append(np.arange(start, start + length))
        start += length
    rng.shuffle(pieces)
    return np.concatenate(pieces or [np.zeros(0)]).astype(np.int32)


@pytest.mark.parametrize("n", [1, 5, 8, 16, 17, 64, 100, 257, 1000])
def test_runs_of_consecutive_rays_gather_by_the_same_rules(each_isa, n):
    """Blocks of consecutive rays (an unsorted batch) are loaded rather than gathered: the
    packets are still the reference's, bit for bit, for the input order and for runs."""
    rng = np.random.default_rng(n)
    rays = hostile_rays(rng, n)
    big = np.array([0, n], np.int32)
    for order in (np.arange(n, dtype=np.int32), runs(rng, n)):
        for offsets in (np.arange(0, n + 64, 64).clip(max=n).astype(np.int32), split(rng, n)):
            offsets = np.unique(offsets)
            p, tmax, bad_ray = gather_checked(rays, order, offsets, big, keep_tmax=True,
                                              max_packet=max(n, 1))
            want_rows, want_index, want_bad = reference(rays, order, offsets, p.capacity)
            assert np.array_equal(p.index, want_index)
            assert np.array_equal(bits(p.rows), bits(want_rows))
            assert np.array_equal(bits(tmax), bits(want_rows[PacketRow.t]))
            assert bad_ray == want_bad


def test_the_special_rays_reach_every_rule():
    """The hostile batches hold what the rules distinguish (else the test above is weak)."""
    rays = hostile_rays(np.random.default_rng(1000), 1000)
    d = rays.directions
    assert ((np.abs(d) < TINY) & (d != 0)).any()
    assert np.isnan(rays.origins).any() and np.isinf(rays.directions).any()
    assert (rays.tmin < 0).any() and (rays.tmin >= rays.tmax).any()
    assert reference(rays, np.arange(1000, dtype=np.int32), np.array([0, 1000], np.int32))[2] >= 0


def test_a_trusted_order_beyond_the_rays_is_refused_not_read():
    """Without the order check the gather still never reads past the batch."""
    rays = random_rays(np.random.default_rng(0), 8, BOX)
    order = np.array([0, 1, 2, 3, 4, 5, 6, 1 << 30], np.int32)
    p, _, _ = gather_checked(rays, order, np.array([0, 8], np.int32), np.array([0, 8], np.int32),
                             check_order=False)
    assert p is None


# -- recycled memory ----------------------------------------------------------------

def batch(seed, n=300):
    rng = np.random.default_rng(seed)
    rays = random_rays(rng, n, BOX)
    rays.tmax[:] = 1 + rng.random(n).astype(np.float32)
    return rays, rng.permutation(n).astype(np.int32), split(rng, n)


def test_results_a_caller_holds_are_never_reused():
    """Packets, hits and views of them that are still referenced keep their values while
    later batches of the same size are gathered and scattered."""
    rays, order, offsets = batch(1)
    packets = gather(rays, order, offsets)
    hits = scatter(packets, len(rays))
    t_row = gather(rays, order, offsets).rows[PacketRow.t]     # only a view survives
    kept = [(a, a.copy()) for a in (packets.rows, packets.index, hits.t, hits.prim, t_row)]
    for seed in range(2, 8):
        other_rays, other_order, other_offsets = batch(seed)
        p = gather(other_rays, other_order, other_offsets)
        h = scatter(p, len(other_rays))
        for a, copy in kept:
            assert not np.shares_memory(a, p.rows) and not np.shares_memory(a, h.t)
            assert np.array_equal(bits(a), bits(copy))


def test_dropped_batches_give_their_memory_back():
    """The next batch of a similar size reuses a dropped batch's memory (no fresh pages)."""
    rays, order, offsets = batch(1, 5000)
    address = gather(rays, order, offsets).rows.ctypes.data
    assert gather(rays, order, offsets).rows.ctypes.data == address


def test_no_hits_leak_from_one_batch_into_the_next():
    """A ray no lane wrote (a trusted order that repeats a ray) reads as a miss, not as
    the hit an earlier batch left in its lanes."""
    n = 6000
    rays, order, offsets = batch(3, n)
    packets, tmax, _ = gather_checked(rays, order, offsets, np.array([0, n], np.int32),
                                      keep_tmax=True)
    packets.prim[packets.index >= 0] = 5
    packets.t[packets.index >= 0] = 0.5
    packets.u[:] = packets.v[:] = 0.25
    hits, fault = scatter_checked(packets, order, offsets, tmax, 10, False, check_hits=False)
    assert fault is None and (hits.prim == 5).all()
    del hits, packets, tmax
    repeated = order.copy()
    repeated[1] = repeated[0]
    packets, tmax, _ = gather_checked(rays, repeated, offsets, np.array([0, n], np.int32),
                                      check_order=False)
    hits, fault = scatter_checked(packets, repeated, offsets, None, 10, False,
                                  check_hits=False, check_order=False)
    assert fault is None
    missing = order[1]
    assert hits.prim[missing] == -1 and hits.t[missing] == np.inf
    assert hits.u[missing] == 0 and hits.v[missing] == 0
    fresh = Hits(n)
    assert (fresh.prim == -1).all() and (fresh.t == np.inf).all() and (fresh.u == 0).all()


def test_threads_gather_into_their_own_memory():
    """Threads gathering at once each get the packets of their own rays."""
    work = [batch(seed, 2000) for seed in range(4)]
    want = [reference(*w, gather(*w).capacity) for w in work]
    errors = []

    def run(k):
        for _ in range(30):
            p = gather(*work[k])
            if not np.array_equal(bits(p.rows), bits(want[k][0])):
                errors.append(k)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors


def test_a_new_ray_batch_starts_clean_in_recycled_memory():
    """A ray batch made where a dropped one lived holds zeros and inactive padding, and
    one still held keeps its rays."""
    n = 5001
    held = RayBatch(n)
    held.data[:] = 7.0
    dropped = RayBatch(n)
    dropped.data[:] = 5.0
    address = dropped.data.ctypes.data
    del dropped
    fresh = RayBatch(n)
    assert fresh.data.ctypes.data == address
    assert (fresh.data[:, :n] == 0).all()
    assert (fresh.data[RayRow.tmin, n:] == np.inf).all()
    assert (fresh.data[RayRow.tmax, n:] == -np.inf).all()
    assert (held.data == 7.0).all()


@pytest.mark.parametrize("n, k", [(0, 3), (1, 1), (5, 0), (1024, 4), (37, 16)])
def test_sample_paths_is_tile_and_repeat(n, k):
    """The paths of a batch of k passes over n pixels: ``np.tile`` and ``np.repeat``."""
    from raysort._gather import sample_paths

    rng = np.random.default_rng(n + k)
    pixels, slots = (rng.integers(-5, 1 << 30, n).astype(np.int32) for _ in range(2))
    samples = rng.integers(0, 100, k).astype(np.int32)
    pixel, sample, slot = (np.full(n * k, 7, np.int32) for _ in range(3))
    sample_paths(pixels, slots, samples, pixel, sample, slot)
    assert np.array_equal(pixel, np.tile(pixels, k))
    assert np.array_equal(sample, np.repeat(samples, n))
    assert np.array_equal(slot, np.tile(slots, k))
    with pytest.raises(ValueError, match="one slot per pixel"):
        sample_paths(pixels, slots[:-1] if n else np.zeros(1, np.int32), samples, pixel,
                     sample, slot)
    with pytest.raises(ValueError, match="expected"):
        sample_paths(pixels, slots, samples, pixel[:-1] if n * k else np.zeros(1, np.int32),
                     sample, slot)


def test_paths_of_samples_are_the_paths_of_their_arrays():
    """``Paths._of_samples`` (the pipeline's paths of a generated batch, in a recycled
    block): the paths ``Paths`` makes of np.tile and np.repeat, throughput 1, in arrays
    that share no memory; the throughput read-only."""
    from raysort.paths import Paths

    pixels = np.arange(10, 30, dtype=np.int32)
    slots = np.arange(20, dtype=np.int32)[::-1].copy()
    samples = np.array([3, 4, 5], np.int32)
    made = Paths._of_samples(pixels, slots, samples)
    want = Paths(np.tile(pixels, 3), np.repeat(samples, 20), np.tile(slots, 3))
    for name in Paths.__slots__:
        got = getattr(made, name)
        assert got.dtype == getattr(want, name).dtype and got.flags.c_contiguous
        assert np.array_equal(got, getattr(want, name))
    arrays = [getattr(made, name) for name in Paths.__slots__]
    assert not any(np.shares_memory(a, b) for i, a in enumerate(arrays) for b in arrays[:i])
    assert not made.throughput.flags.writeable


def test_unit_throughput_is_ones_read_only_and_grows():
    """``unit_throughput(n)``: float32 ones (3, n), C-contiguous, and read-only for good (its
    memory is immutable); a larger n than any before gets a larger block, and the views
    handed out before keep their values."""
    from raysort.paths import unit_throughput

    small = unit_throughput(5)
    for n in (0, 1, 5, 1000, 70_000, 3):
        u = unit_throughput(n)
        assert u.shape == (3, n) and u.dtype == np.float32 and u.flags.c_contiguous
        assert (u == 1).all() and not u.flags.writeable
        with pytest.raises(ValueError):
            u.flags.writeable = True
    assert (small == 1).all() and small.shape == (3, 5)


def test_follow_paths_is_fancy_indexing_and_refuses_a_parent_out_of_range():
    """The paths' bookkeeping after a shade: pixel, sample, slot and t of each parent,
    as NumPy's indexing gives them (runs of consecutive parents, which are copied, and
    what only looks like one included); a parent out of range is an IndexError."""
    from raysort._gather import follow_paths

    rng = np.random.default_rng(5)
    n = 1000
    pixel, sample, slot = (rng.integers(0, 2**31 - 1, n).astype(np.int32) for _ in range(3))
    t = rng.random(n).astype(np.float32)
    t[::7] = np.inf
    swapped = np.arange(64)
    swapped[[1, 2]] = 2, 1                      # first and last 63 apart, yet not a run
    runs = np.concatenate([np.arange(128), np.arange(200, 330), [400, 402],
                           np.arange(500, 564), np.arange(n - 64, n)])
    repeat = np.arange(n)
    repeat[600] = 599                           # n parents, ascending, not every ray
    for parent in (np.sort(rng.integers(0, n, 700)), np.arange(n), np.zeros(0), runs,
                   swapped, np.r_[swapped, np.arange(64, 200)], repeat, repeat[::-1]):
        parent = parent.astype(np.int32)
        got = follow_paths(parent, pixel, sample, slot, t)
        for mine, array in zip(got, (pixel, sample, slot, t)):
            assert mine.dtype == array.dtype and np.array_equal(mine, array[parent])
            # every ray went on: the arrays themselves, no copies
            assert (mine is array) == np.array_equal(parent, np.arange(n))
    for bad in (-1, n):
        with pytest.raises(IndexError, match="out of range"):
            follow_paths(np.array([0, bad], np.int32), pixel, sample, slot, t)
        with pytest.raises(IndexError, match=rf"parent\[{n - 1}\]"):
            follow_paths(np.r_[np.arange(n - 1), bad].astype(np.int32), pixel, sample, slot, t)
        almost = np.arange(64, dtype=np.int32)
        almost[10] = bad                        # inside what begins like a run
        with pytest.raises(IndexError, match=r"parent\[10\]"):
            follow_paths(almost, pixel, sample, slot, t)


@pytest.mark.parametrize("any_hit", [False, True])
@pytest.mark.parametrize("n", [1, 7, 64, 1000])
def test_checked_scatter_puts_each_lane_back_and_finds_a_ray_left_out(each_isa, n, any_hit):
    """The pipeline's scatter of a sorter's order: every lane's hit at its ray (NumPy fancy
    indexing of the lanes), ``"order"`` when a ray comes twice and another not at all,
    ``"hits"`` at a lane naming a ray beyond the batch."""
    rng = np.random.default_rng(n)
    rays = random_rays(rng, n, BOX)
    order = rng.permutation(n).astype(np.int32)
    offsets = split(rng, n)
    packets = np.array([0, n], np.int32)
    batch, tmax, _ = gather_checked(rays, order, offsets, packets, keep_tmax=True)
    lanes = np.flatnonzero(batch.index >= 0)
    hit = lanes[rng.random(len(lanes)) < 0.5]
    batch.prim[hit] = rng.integers(0, 100, len(hit))
    batch.t[hit] = tmax[hit] / 2
    batch.u[hit], batch.v[hit] = 0.25, 0.5
    out, fault = scatter_checked(batch, order, offsets, tmax, 100, any_hit, check_hits=False)
    assert fault is None
    ray = batch.index[lanes]
    if any_hit:
        want = np.zeros(n, bool)
        want[ray] = batch.prim[lanes] >= 0
        assert out.dtype == bool and np.array_equal(out, want)
    else:
        hits = batch.prim[lanes] >= 0
        assert np.array_equal(bits(out.t[ray]), bits(np.where(hits, batch.t[lanes], np.inf)))
        assert np.array_equal(out.prim[ray], np.where(hits, batch.prim[lanes], -1))
        assert np.array_equal(out.u[ray], np.where(hits, batch.u[lanes], 0))
        assert np.array_equal(out.v[ray], np.where(hits, batch.v[lanes], 0))
    if n > 1:
        batch.index[lanes[1]] = batch.index[lanes[0]]      # a ray twice, another never
        assert scatter_checked(batch, order, offsets, tmax, 100, any_hit,
                               check_hits=False) == (None, "order")
    batch.index[lanes[-1]] = n                              # beyond the batch
    assert scatter_checked(batch, order, offsets, tmax, 100, any_hit,
                           check_hits=False) == (None, "hits")
