"""The sort-key sorters (origin_direction, two_point, termination, garanzha).

Checked against references written here from the documented formulas, not
against stored output:

* the bit split of a key table equals a bit-by-bit interleave of the levels;
* the coordinates the kernel quantises (origin in the box, direction
  components, octahedral map, the end point with its length, tmax and box-exit
  clamps, and the previous hit distance of ``termination``) equal float64
  formulas within one quantisation step;
* the order is a stable sort by key inside every large packet (numpy lexsort),
  with and without Garanzha and Loop's compression;
* sub-packets are cut at ``packet_size``, at changes of the key's top
  ``split_bits`` and never across octants when ``octant`` is on;
* a render's bounce rays carry the previous bounce's hit distance.
"""
import numpy as np
import pytest

import raysort
from raysort import isa
from raysort.errors import ConfigError
from raysort.rays import RayBatch
from raysort.sorters import _keysort
from raysort.sorters.garanzha import GaranzhaSorter
from raysort.sorters.origin_direction import LAYOUTS, OriginDirectionSorter
from raysort.sorters.termination import TerminationSorter
from raysort.sorters.two_point import TwoPointSorter

from _helpers import random_rays

BOX = np.array([[-3.0, -1.0, 2.0], [5.0, 4.0, 3.5]], dtype=np.float32)
QMAX = 2 ** _keysort.COORD_BITS - 1
#: the builds that assemble short keys in vector registers (plan_windows)
VECTOR_KEYS = ("avx2", "avx512", "avx512emu")
KEY_SORTERS = ["origin_direction", "two_point", "termination", "garanzha"]


# -- key tables --------------------------------------------------------------------

def reference_key(q, levels):
    """Bit-by-bit interleave: level by level, each listed coordinate's next bit."""
    key, used, pos = 0, [0] * 6, 63
    for level in levels:
        for coord in level:
            bit = 15 - used[coord]
            key |= ((int(q[coord]) >> bit) & 1) << pos
            used[coord] += 1
            pos -= 1
    return key


def apply_table(table, q):
    """The kernel's lookup: OR of two byte-tables per coordinate."""
    key = np.zeros(q.shape[1], dtype=np.uint64)
    for k in range(6):
        key |= table[k, 0, q[k] & 255] | table[k, 1, q[k] >> 8]
    return key


@pytest.mark.parametrize("levels", [
    [(0, 1, 2)] * 16,
    [(0, 1, 2)] * 3 + [(0, 1, 2, 3, 4, 5)] * 9 + [(0,)],
    [(3, 4)] * 4 + [(0, 1, 2)] * 15 + [(5,)],
    [(0, 1, 2)] * 5 + [(3, 4)] * 3,
    [(5, 0)] * 16,
], ids=["origin", "aila", "costa", "hash", "pairs"])
def test_key_table_is_the_interleave(levels, rng):
    table, bits = _keysort.key_table(levels)
    assert bits == sum(len(level) for level in levels)
    q = rng.integers(0, QMAX + 1, size=(6, 300)).astype(np.uint32)
    got = apply_table(table, q)
    want = [reference_key(q[:, i], levels) for i in range(q.shape[1])]
    assert [int(k) for k in got] == want


def test_key_table_limits():
    with pytest.raises(ValueError, match="64 bits"):
        _keysort.key_table([(0, 1, 2, 3, 4, 5)] * 11)
    with pytest.raises(ValueError, match="only 16 bits"):
        _keysort.key_table([(0,)] * 17)


# -- coordinates -------------------------------------------------------------------

def quantised(sorter_coordinates, rays, bounds, k, **kw):
    """The kernel's quantised coordinate k of every ray (a table with only k's bits)."""
    table, _ = _keysort.key_table([(k,)] * 16)
    keys = _keysort.make_keys(rays, sorter_coordinates, bounds, table, **kw)
    return (keys >> np.uint64(48)).astype(np.int64)


def reference_coords(rays, bounds, mode, length=0.0, prev_t=None, prev_scale=1.0):
    """float64 coordinates in [0, 1] from the documented formulas."""
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    o = rays.origins.astype(np.float64)
    d = rays.directions.astype(np.float64)
    d = d / np.linalg.norm(d, axis=0)
    c = [(o[k] - lo[k]) / (hi[k] - lo[k]) for k in range(3)]
    if mode == "components":
        c += [(d[k] + 1) / 2 for k in range(3)]
    elif mode == "octahedral":
        s = np.abs(d).sum(axis=0)
        u, v = d[0] / s, d[1] / s
        below = d[2] < 0
        fu = (1 - np.abs(v)) * np.where(u < 0, -1, 1)
        fv = (1 - np.abs(u)) * np.where(v < 0, -1, 1)
        c += [(np.where(below, fu, u) + 1) / 2, (np.where(below, fv, v) + 1) / 2]
    else:
        L = np.full(len(rays), length)
        if prev_t is not None:
            known = (prev_t > 0) & np.isfinite(prev_t)
            L[known] = prev_t[known] * prev_scale
        L = np.minimum(L, rays.tmax)
        with np.errstate(divide="ignore", invalid="ignore"):
            exits = np.where(d > 0, (hi[:, None] - o) / d, (lo[:, None] - o) / d)
        L = np.minimum(L, np.maximum(exits.min(axis=0) * (1 - 1e-3), 0))
        end = o + L * d
        c += [(end[k] - lo[k]) / (hi[k] - lo[k]) for k in range(3)]
    return [np.floor(np.clip(x, 0, 1) * QMAX).astype(np.int64) for x in c]


def inside_rays(rng, n):
    """Rays from inside BOX (so the box-exit clamp is defined), unnormalised directions."""
    origins = BOX[0] + rng.random((n, 3)) * (BOX[1] - BOX[0])
    directions = rng.normal(size=(n, 3)) * rng.uniform(0.2, 5, size=(n, 1))
    tmax = np.where(rng.random(n) < 0.3, rng.uniform(0.1, 3, n), np.inf)
    return RayBatch.from_arrays(origins, directions, 0.0, tmax)


@pytest.mark.parametrize("mode", ["components", "octahedral"])
def test_origin_and_direction_coordinates(mode, rng):
    rays = inside_rays(rng, 2000)
    want = reference_coords(rays, BOX, mode)
    for k in range(6 if mode == "components" else 5):
        got = quantised(mode, rays, BOX, k)
        assert np.abs(got - want[k]).max() <= 1, f"coordinate {k}"


def short_tables(rng):
    """Tables that read only the coordinates' high bytes (the kernel then pairs
    coordinates into shared lookups): the default keys' bit splits, and rows of
    random bits that depend on the top u bits of the byte, one of them constant."""
    from raysort.sorters.origin_direction import _levels
    yield "aila-24", _keysort.key_table(_levels("interleaved", 3)[:7])[0]
    yield "two-point-21", _keysort.key_table([(0, 1, 2, 3, 4, 5)] * 3 + [(0, 1, 2)])[0]
    yield "hash", _keysort.key_table([(0, 1, 2)] * 5 + [(3, 4)] * 3)[0]
    yield "one-coord", _keysort.key_table([(4,)] * 8)[0]
    table = np.zeros((6, 2, 256), np.uint64)
    for k, u in enumerate([0, 3, 8, 1, 5, 2]):
        top = rng.integers(0, 2**63, size=1 << u, dtype=np.uint64)
        table[k, 1] = top[np.arange(256) >> (8 - u)]
    yield "random-rows", table


@pytest.mark.parametrize("mode", ["components", "octahedral", "end_point"])
def test_short_keys_are_the_table_lookups(mode, rng):
    """Keys of tables that read only high bytes (looked up in pairs of coordinates)
    equal the OR of the table's rows at the kernel's quantised coordinates."""
    rays = inside_rays(rng, 1500)
    n_coords = 5 if mode == "octahedral" else 6
    q = np.zeros((6, len(rays)), np.int64)
    for k in range(n_coords):
        q[k] = quantised(mode, rays, BOX, k, length=2.5)
    for name, table in short_tables(rng):
        if n_coords == 5:
            table = table.copy()
            table[5] = 0                 # the octahedral map has no sixth coordinate
        got = _keysort.make_keys(rays, mode, BOX, table, length=2.5)
        assert np.array_equal(got, apply_table(table, q)), name


def with_octant(keys, rays):
    """Keys shifted down by three bits under the octant's: bit 63 - k is d[k] < 0."""
    signs = sum((rays.directions[k] < 0).astype(np.uint64) << np.uint64(63 - k)
                for k in range(3))
    return keys >> np.uint64(3) | signs


def lookup_tables(rng):
    """short_tables and, for the builds that assemble keys in vector registers: keys that
    read a coordinate's whole high byte (two lookups per coordinate: six in all, and
    eight), and one too long for the key's high 32 bits (which those builds leave to the
    scalar lookups)."""
    yield from short_tables(rng)
    yield "eight-bits", _keysort.key_table([(0, 1, 2)] * 8)[0]
    yield "eight-lookups", _keysort.key_table([(0, 1, 2, 3)] * 7)[0]
    yield "36-bits", _keysort.key_table([(0, 1, 2, 3, 4, 5)] * 6)[0]


@pytest.mark.parametrize("octant", [False, True])
@pytest.mark.parametrize("n", [1, 7, 9, 16, 1500])
@pytest.mark.parametrize("mode", ["components", "octahedral", "end_point"])
def test_keys_on_every_isa(mode, n, octant, rng, each_isa):
    """Every build's keys (on AVX-512 assembled sixteen at a time from 32-entry tables,
    on AVX2 eight at a time from 8-entry tables, with a masked last vector) are the OR
    of the table's rows at the quantised coordinates, with the octant's signs on top."""
    rays = inside_rays(rng, n)
    n_coords = 5 if mode == "octahedral" else 6
    q = np.zeros((6, n), np.int64)
    for k in range(n_coords):
        q[k] = quantised(mode, rays, BOX, k, length=2.5)
    for name, table in lookup_tables(rng):
        table = table.copy()
        table[n_coords:] = 0
        want = apply_table(table, q)
        if octant:
            want = with_octant(want, rays)
        module = isa.module("sorters._keysort")
        if name in ("eight-bits", "eight-lookups") and each_isa in VECTOR_KEYS:
            assert module._windows(mode, table, octant), name
        got = module.make_keys(rays, mode, BOX, table, length=2.5, octant=octant)
        assert np.array_equal(got, want), name


def test_a_table_changed_in_place_is_planned_again(rng, each_isa):
    """The module keeps the last table's plan (the pairs and windows it looks up) and
    reuses it for an equal table: one changed in place between calls, or the same table
    with the octant flag or mode changed, must not get the old plan."""
    module = isa.module("sorters._keysort")
    rays = inside_rays(rng, 300)
    q = np.zeros((6, len(rays)), np.int64)
    for k in range(6):
        q[k] = quantised("components", rays, BOX, k)
    table = _keysort.key_table([(0, 1, 2, 3, 4, 5)] * 4)[0]
    first = module.make_keys(rays, "components", BOX, table)
    assert np.array_equal(first, apply_table(table, q))
    table[[0, 3]] = table[[3, 0]]           # origin x and direction x swap places
    assert np.array_equal(module.make_keys(rays, "components", BOX, table),
                          apply_table(table, q))
    assert np.array_equal(module.make_keys(rays, "components", BOX, table, octant=True),
                          with_octant(apply_table(table, q), rays))


@pytest.mark.parametrize("prev", [None, "some"], ids=["fixed-length", "prev_t"])
def test_end_point_coordinates(prev, rng):
    rays = inside_rays(rng, 2000)
    prev_t = None
    if prev:
        prev_t = rng.uniform(0, 4, len(rays)).astype(np.float32)
        prev_t[::5] = np.nan                    # unknown: the fixed length
        prev_t[1::7] = np.inf
        prev_t[2::9] = 0
        prev_t[3::11] = -1.5                    # not a distance: the fixed length
        prev_t[4::13] = -0.0
        prev_t[5::17] = -np.inf
        prev_t[6::19] = 1e-42                   # subnormal, positive: a known distance
    want = reference_coords(rays, BOX, "end_point", length=2.5, prev_t=prev_t, prev_scale=0.7)
    for k in range(6):
        got = quantised("end_point", rays, BOX, k, length=2.5, prev_t=prev_t, prev_scale=0.7)
        assert np.abs(got - want[k]).max() <= 1, f"coordinate {k}"


def test_termination_uses_prev_t_and_falls_back_to_two_point(rng):
    rays = inside_rays(rng, 500)
    two, term = TwoPointSorter(), TerminationSorter()
    assert np.array_equal(term.keys(rays, BOX), two.keys(rays, BOX)), "no prev_t: two_point"
    rays.prev_t = np.full(len(rays), np.nan, np.float32)
    assert np.array_equal(term.keys(rays, BOX), two.keys(rays, BOX)), "all unknown: two_point"
    rays.prev_t = rng.uniform(0.01, 0.5, len(rays)).astype(np.float32)
    assert not np.array_equal(term.keys(rays, BOX), two.keys(rays, BOX))
    rays.prev_t = np.zeros(3, np.float32)
    with pytest.raises(ConfigError, match="prev_t"):
        term.keys(rays, BOX)


# -- order and sub-packets -----------------------------------------------------------

def reference_order(keys, packets, digits):
    """Stable sort by (large packet, top ``digits`` bytes of the key)."""
    top = keys >> np.uint64(64 - 8 * digits) if digits < 8 else keys
    label = np.repeat(np.arange(len(packets) - 1), np.diff(packets))
    return np.lexsort((np.arange(len(keys)), top, label))


def reference_offsets(keys_sorted, packets, packet_size, split_bits):
    """Starts: each large packet's first ray, every packet_size-th ray of a run, and
    every change of the key's top split_bits; plus the end."""
    n = len(keys_sorted)
    starts = set(int(p) for p in packets[:-1] if p < n)
    top = (keys_sorted >> np.uint64(64 - split_bits)) if split_bits else np.zeros(n, np.uint64)
    last = None
    for i in range(n):
        if i in starts or i - last == packet_size or (split_bits and top[i] != top[i - 1]):
            starts.add(i)
            last = i
    return np.array(sorted(starts) + [n])


@pytest.mark.parametrize("compress", [False, True])
@pytest.mark.parametrize("digits,packet_size,split_bits", [(1, 64, 0), (3, 7, 5), (8, 4096, 0),
                                                           (4, 64, 12), (1, 16, 20)])
def test_sort_keys_is_a_stable_sort(rng, each_isa, compress, digits, packet_size, split_bits):
    """On every ISA (NumPy's sort or the radix sort, see
    test_which_builds_sort_with_numpy).  (The last case splits on more bits than it sorts: runs of
    the same top bits are then not contiguous, and every change of them cuts.)"""
    n = 3000
    packets = np.array([0, 0, 5, 1029, 1029, 2500, 3000], np.int32)
    keys = rng.integers(0, 2**63, size=n, dtype=np.uint64) << np.uint64(1)
    keys[rng.random(n) < 0.4] = np.uint64(7) << np.uint64(60)   # long runs of one key
    keys[1000:1400] = keys[1000]
    order, offsets = isa.module("sorters._keysort").sort_keys(
        keys, packets, digits, compress=compress, packet_size=packet_size,
        split_bits=split_bits)
    assert np.array_equal(order, reference_order(keys, packets, digits))
    assert np.array_equal(offsets, reference_offsets(keys[order], packets, packet_size,
                                                     split_bits))


@pytest.mark.parametrize("compress", [False, True])
@pytest.mark.parametrize("digits", [1, 3])
def test_packets_already_in_order(rng, each_isa, compress, digits):
    """Packets whose sorted bits never descend keep their order without a sort (found in
    the pass that also finds the bits that vary); one descent anywhere, even at the last
    ray or the first, sorts them.  Low bits below the sorted ones may descend freely."""
    size = 700
    top = np.sort(rng.integers(0, 256 ** digits, size=size, dtype=np.uint64))
    ascending = top << np.uint64(64 - 8 * digits)
    low = rng.integers(0, 2 ** (64 - 8 * digits), size=size, dtype=np.uint64)
    last_descends = ascending.copy()
    last_descends[-1] = ascending[0] if ascending[-1] != ascending[0] else np.uint64(0)
    first_descends = ascending.copy()
    first_descends[0] = np.uint64((256 ** digits - 1) << (64 - 8 * digits))     # the largest
    equal = np.full(size, ascending[size // 2])
    blocks = [ascending, ascending | low, last_descends, first_descends, equal]
    keys = np.concatenate(blocks)
    packets = np.arange(0, len(keys) + 1, size, dtype=np.int32)
    order, offsets = isa.module("sorters._keysort").sort_keys(
        keys, packets, digits, compress=compress, packet_size=64, split_bits=0)
    assert np.array_equal(order, reference_order(keys, packets, digits))
    assert np.array_equal(offsets, reference_offsets(keys[order], packets, 64, 0))
    for p in (0, 1, 4):     # kept in input order
        assert np.array_equal(order[p * size:(p + 1) * size], np.arange(p * size, (p + 1) * size))


def test_which_builds_sort_with_numpy(each_isa):
    """The avx2 and avx512 builds sort 32-bit compact keys with NumPy's sort, the
    avx512 builds also 64-bit packed keys; the rest is the radix sort (the tests of
    sort_keys run on every ISA, so each path is held to the reference)."""
    module = isa.module("sorters._keysort")
    assert module.compact_sort == (each_isa in ("avx2", "avx512", "avx512emu"))
    assert module.library_sort == (each_isa in ("avx512", "avx512emu"))


@pytest.mark.parametrize("share", [0.6, 0.97])
def test_sort_keys_where_most_keys_share_digits(rng, each_isa, share):
    """Coherent rays: most keys of a large packet share every digit (the sort then
    counts in a copy of its counters, see rs_keysort_scatter); still the stable sort."""
    n = 4096
    packets = np.array([0, 1024, 2048, 3000, 4096], np.int32)
    keys = rng.integers(0, 2**63, size=n, dtype=np.uint64) << np.uint64(1)
    keys[rng.random(n) < share] = np.uint64(0x5A3C_9600_0000_0000)
    for digits in (1, 3):
        order, offsets = isa.module("sorters._keysort").sort_keys(
            keys, packets, digits, packet_size=64, split_bits=3)
        assert np.array_equal(order, reference_order(keys, packets, digits))
        assert np.array_equal(offsets, reference_offsets(keys[order], packets, 64, 3))


@pytest.mark.parametrize("split_bits", [0, 3, 5, 10, 16, 24])
@pytest.mark.parametrize("sizes", [(1, 5, 1024), (4096, 2000), (300, 3000, 700)])
def test_sort_keys_with_runs_of_varying_bits(rng, each_isa, split_bits, sizes):
    """Keys whose varying bits form runs with constant bits between them, as a
    bounce's keys do (the avx2 and avx512 builds then sort 32-bit keys made of the
    varying runs, keeping the smallest gaps while they fit, and cuts on their top bits;
    4096-ray packets do not fit and take the 64-bit sort); split_bits ends above,
    inside and below runs and gaps."""
    runs = [(61, 64), (50, 56), (47, 48), (40, 45)]      # [lo, hi): 3 + 6 + 1 + 5 bits
    n = sum(sizes)
    packets = np.cumsum([0, *sizes]).astype(np.int32)
    keys = np.full(n, 0x9C00_0000_0000_0000 & ~sum(((1 << (hi - lo)) - 1) << lo
                                                    for lo, hi in runs), np.uint64)
    for lo, hi in runs:
        keys |= rng.integers(0, 1 << (hi - lo), size=n, dtype=np.uint64) << np.uint64(lo)
    keys[rng.random(n) < 0.2] = keys[0]                     # ties
    order, offsets = isa.module("sorters._keysort").sort_keys(
        keys, packets, 3, packet_size=64, split_bits=split_bits)
    assert np.array_equal(order, reference_order(keys, packets, 3))
    assert np.array_equal(offsets, reference_offsets(keys[order], packets, 64, split_bits))


@pytest.mark.parametrize("compress", [False, True])
@pytest.mark.parametrize("packet_size,split_bits", [(64, 0), (7, 3), (64, 10), (16, 24)])
def test_sort_keys_in_runs(rng, each_isa, compress, packet_size, split_bits):
    """Keys in runs of equal keys, as shadow and camera rays' come (the avx2 and avx512
    builds sort the runs, sort_runs, where a packet's runs average 2 rays or more): runs of
    1 to 40 keys (around the 16 rays a run's first stores write), few or many distinct keys,
    varying bits that fit a 32-bit key with the run number and bits that do not, runs
    at a packet's ends, packets of 1 to 1,024 rays; the stable sort and its cuts."""
    sizes = [1, 3, 4, 500, 1024, 0, 600, 900, 48]
    packets = np.cumsum([0, *sizes]).astype(np.int32)
    keys = []
    for p, size in enumerate(sizes):
        if p % 3 == 2:          # 64 varying bits: no compact key fits
            values = rng.integers(0, 2**63, size=40, dtype=np.uint64) << np.uint64(1)
        else:                   # 2 to 40 distinct keys, their varying bits in the top 24
            values = (rng.integers(0, 1 << 24, size=2 + 19 * (p % 3), dtype=np.uint64)
                      & rng.integers(0, 1 << 24, dtype=np.uint64)) << np.uint64(40)
        lengths = rng.choice([1, 2, 3, 7, 15, 16, 17, 40], size=size)
        run = np.repeat(rng.integers(0, len(values), size=size), lengths)[:size]
        keys.append(values[run])
    keys = np.concatenate(keys)
    order, offsets = isa.module("sorters._keysort").sort_keys(
        keys, packets, 3, compress=compress, packet_size=packet_size, split_bits=split_bits)
    assert np.array_equal(order, reference_order(keys, packets, 3))
    assert np.array_equal(offsets, reference_offsets(keys[order], packets, packet_size,
                                                     split_bits))


@pytest.mark.parametrize("spec", ["two_point", "termination", "origin_direction", "garanzha",
                                  "two_point:split_bits=10,packet_size=7",
                                  "origin_direction:layout=octahedral",
                                  "garanzha:split=true,packet_size=16"])
def test_sorters_sort_rays_in_runs(spec, rng, each_isa):
    """A sorter's order and cuts of rays whose keys come in runs (copies of a ray, as
    shadow and camera rays nearly are), of a packet already in key order and of a
    4,096-ray packet whose varying bits and index do not fit 32 bits, against the
    stable sort of the keys it makes: on the avx2 and avx512 builds the sort reads the
    keys' high halves as made in vector registers (sort_packet of 32-bit keys: runs,
    compact keys, the packet's own order, and widened to 64 bits for the rest)."""
    sorter = raysort.create("sorters", spec)
    base = inside_rays(rng, 600)
    sizes = [1, 3, 500, 1024, 0, 900, 48, 4096, 700]
    pick = []
    for p, size in enumerate(sizes):
        if p == 7:              # every ray its own
            pick.append(rng.integers(0, len(base), size=size))
            continue
        lengths = rng.choice([1, 2, 3, 7, 15, 16, 17, 40], size=size)
        pick.append(np.repeat(rng.integers(0, 20 + 200 * (p % 2), size=size), lengths)[:size])
    rays = base.take(np.concatenate(pick))
    packets = np.cumsum([0, *sizes]).astype(np.int32)
    last = slice(packets[-2], packets[-1])      # the last packet already in key order
    keys = sorter.keys(rays, BOX)
    index = np.arange(len(rays))
    index[last] = packets[-2] + np.argsort(keys[last], kind="stable")
    rays = rays.take(index)
    keys = sorter.keys(rays, BOX)
    assert np.all(np.diff(keys[last].astype(np.float64)) >= 0)
    if each_isa in VECTOR_KEYS:
        assert isa.module("sorters._keysort")._windows(sorter.coordinates, sorter._table,
                                                       sorter.octant)
    order, offsets = sorter.sort(rays, packets, BOX)
    assert np.array_equal(order, reference_order(keys, packets, sorter._digits))
    assert np.array_equal(offsets, reference_offsets(keys[order], packets, sorter.packet_size,
                                                     sorter._split))


@pytest.mark.parametrize("digits,split_bits", [(3, 0), (4, 12), (8, 40)])
def test_sort_rays_is_sort_keys_of_make_keys(digits, split_bits, rng, each_isa):
    """sort_rays (keys made packet by packet; on the avx2 and avx512 builds their high
    halves sorted as 32-bit keys where the split is within them) gives sort_keys' order
    and cuts of make_keys' keys, for any digits and split."""
    module = isa.module("sorters._keysort")
    sorter = raysort.create("sorters", "two_point")
    base = inside_rays(rng, 300)
    rays = base.take(np.repeat(rng.integers(0, 300, size=900), 3)[:2500])
    packets = np.array([0, 1, 700, 1724, 2500], np.int32)
    table = sorter._table
    keys = module.make_keys(rays, "end_point", BOX, table, length=2.5, octant=True)
    want = module.sort_keys(keys, packets, digits, packet_size=64, split_bits=split_bits)
    got = module.sort_rays(rays, "end_point", BOX, table, packets, digits, length=2.5,
                           octant=True, packet_size=64, split_bits=split_bits)
    assert np.array_equal(got[0], want[0])
    assert np.array_equal(got[1], want[1])


@pytest.mark.parametrize("n", [1, 5, 300, 1024, 4096])
def test_digit_plan_covers_the_varying_bits(n, rng):
    """The radix digits span every bit from the highest to the lowest varying one, are
    at most MAX_DIGIT_BITS wide, need no more passes than that width allows, and have
    no more buckets than about the keys (at least a byte's)."""
    assert _keysort._digit_plan(0, n)[2] == 0, "equal keys: no pass"
    for _ in range(200):
        top = int(rng.integers(0, 64))
        bottom = int(rng.integers(0, top + 1))
        vary = (1 << top) | (1 << bottom) | (int(rng.integers(0, 2**63)) & ((1 << top) - 1)
                                             & ~((1 << bottom) - 1))
        floor = int(rng.integers(0, bottom + 1))
        low_bit, width, passes = _keysort._digit_plan(vary, n, floor)
        assert floor <= low_bit <= bottom and low_bit + passes * width >= top + 1
        assert low_bit + (passes - 1) * width < 64
        assert 1 <= width <= _keysort.MAX_DIGIT_BITS
        assert 1 << width <= max(n, 1 << _keysort.MIN_DIGIT_BITS)
        widest = max(_keysort.MIN_DIGIT_BITS, min(_keysort.MAX_DIGIT_BITS, n.bit_length() - 1))
        assert passes == -(-(top - bottom + 1) // widest)


@pytest.mark.parametrize("compress", [False, True])
@pytest.mark.parametrize("varying", [(0, 0), (40, 41), (40, 52), (56, 64), (30, 64), (0, 64)],
                         ids=["equal", "one-bit", "middle", "top-byte", "top-34", "all"])
def test_sort_keys_sorts_only_the_varying_bits(rng, each_isa, compress, varying):
    """Keys whose bits vary only in [lo, hi) (the rest the same in every key): the sort
    skips the constant digits and still gives the stable order of the whole keys."""
    lo, hi = varying
    n = 6000
    packets = np.array([0, 1, 6, 300, 1324, 5420, 6000], np.int32)
    base = np.uint64(0xA5C3_96F0_0F69_3C5A)
    span = np.uint64(((1 << (hi - lo)) - 1) << lo) if hi > lo else np.uint64(0)
    keys = (base & ~span) | (rng.integers(0, 2**63, size=n, dtype=np.uint64) * np.uint64(2)
                             + np.uint64(1)) & span
    keys[rng.random(n) < 0.3] = base & ~span                   # runs of one key
    # packed (the index rides in the low bits), 64-bit keys, and a split below the
    # sorted bits (the key is not packed: its bits below the sorted ones are not sorted on)
    for digits, split_bits in ((3, 0), (8, 0), (2, 40)):
        order, offsets = isa.module("sorters._keysort").sort_keys(
            keys, packets, digits, compress=compress, packet_size=64, split_bits=split_bits)
        assert np.array_equal(order, reference_order(keys, packets, digits)), digits


def morton_reference(cells, levels):
    """Keys (left aligned) of integer coordinates ``cells[k]`` interleaved level by
    level, most significant first, with NumPy: independent of the kernel's tables."""
    key = np.zeros(cells.shape[1], dtype=np.uint64)
    used, pos = [0] * len(cells), 63
    for level in levels:
        for coord in level:
            bit = np.uint64(15 - used[coord])
            key |= ((cells[coord].astype(np.uint64) >> bit) & np.uint64(1)) << np.uint64(pos)
            used[coord] += 1
            pos -= 1
    return key


@pytest.mark.parametrize("bits", [9, 12, 20, 30])
def test_origin_keys_sort_like_numpy_argsort(bits, rng):
    """The ``origin`` layout on origins at cell centres (so quantisation is exact): the
    sorter's order equals a stable ``np.argsort`` of Morton keys made in NumPy.  The
    first large packet's origins share a corner of the box (constant top digits)."""
    n = 3000
    cells = rng.integers(0, QMAX, size=(3, n))
    cells[:, :1024] = cells[:, :1024] % 2**11        # one corner: top bits the same
    lo, hi = BOX[0].astype(np.float64), BOX[1].astype(np.float64)
    # the middle of a quantisation cell (the kernel's q = floor(c * QMAX)), well inside
    # it after rounding to float32
    origins = lo + (cells.T + 0.5) / QMAX * (hi - lo)
    rays = RayBatch.from_arrays(origins, np.tile([0.3, -0.2, 0.9], (n, 1)), 0.0, np.inf)
    sorter = OriginDirectionSorter(layout="origin", bits=bits, octant=False)
    packets = np.array([0, 1024, 2048, 3000], np.int32)
    order, _ = sorter.sort(rays, packets, BOX)
    want = morton_reference(cells, [(0, 1, 2)] * 16) >> np.uint64(64 - bits)
    ref = np.concatenate([a + np.argsort(want[a:b], kind="stable")
                          for a, b in zip(packets[:-1], packets[1:])])
    assert np.array_equal(order, ref)


@pytest.mark.parametrize("name", KEY_SORTERS)
def test_sorter_orders_by_its_key(name, rng):
    sorter = raysort.create("sorters", name)
    rays = random_rays(rng, 2500, BOX)
    packets = np.array([0, 1024, 2048, 2500], np.int32)
    order, offsets = sorter.sort(rays, packets, BOX)
    keys = sorter.keys(rays, BOX)
    assert np.array_equal(order, reference_order(keys, packets, sorter._digits))


@pytest.mark.parametrize("name", ["origin_direction", "two_point", "termination"])
def test_octant_prefix(name, rng):
    rays = random_rays(rng, 3000, BOX)
    packets = np.array([0, 1024, 2048, 3000], np.int32)
    order, offsets = raysort.create("sorters", name).sort(rays, packets, BOX)
    d = rays.directions[:, order]
    octant = (d[0] < 0) * 1 + (d[1] < 0) * 2 + (d[2] < 0) * 4
    sizes = np.diff(offsets)
    first = np.repeat(octant[offsets[:-1]], sizes)
    assert np.array_equal(octant, first), "a sub-packet mixes octants"
    plain = raysort.create("sorters", f"{name}:octant=False").sort(rays, packets, BOX)[0]
    assert not np.array_equal(order, plain)


def test_garanzha_compression_gives_the_plain_sort(rng, each_isa):
    rays = random_rays(rng, 2000, BOX)
    rays.data[:, 100:600] = rays.data[:, 100:101]            # a long run of one ray
    sorter = GaranzhaSorter(split=True)
    keys = sorter.keys(rays, BOX)
    packets = np.array([0, 1024, 2000], np.int32)
    order, offsets = sorter.sort(rays, packets, BOX)
    plain = isa.module("sorters._keysort").sort_keys(
        keys, packets, sorter._digits, compress=False, packet_size=64,
        split_bits=sorter.split_bits)
    assert np.array_equal(order, plain[0]) and np.array_equal(offsets, plain[1])
    ks = keys[order]
    assert all(len(set(ks[a:b].tolist())) == 1 for a, b in zip(offsets[:-1], offsets[1:])), \
        "split: a sub-packet holds two hashes"


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_layouts_build(layout, rng):
    sorter = OriginDirectionSorter(layout=layout, bits=48)   # origin alone has 3 + 48 bits
    rays = random_rays(rng, 500, BOX)
    order, _ = sorter.sort(rays, np.array([0, 500], np.int32), BOX)
    assert sorted(order.tolist()) == list(range(500))


@pytest.mark.parametrize("spec,match", [
    ("origin_direction:layout=spiral", "layout"),
    ("origin_direction:lead=17", "lead"),
    ("two_point:bits=0", "bits"),
    ("two_point:bits=65", "bits"),
    ("two_point:length=-1", "length"),
    ("termination:scale=-1", "scale"),
    ("garanzha:origin_bits=0", "origin_bits"),
    ("garanzha:direction_bits=9", "direction_bits"),
    ("origin_direction:split_bits=40,bits=32", "split_bits"),
])
def test_bad_parameters(spec, match):
    with pytest.raises(ConfigError, match=match):
        raysort.create("sorters", spec)


def test_bad_packets_are_a_config_error(rng):
    rays = random_rays(rng, 10, BOX)
    with pytest.raises(ConfigError, match="packets"):
        TwoPointSorter().sort(rays, np.array([0, 20], np.int32), BOX)


@pytest.mark.parametrize("name", KEY_SORTERS)
@pytest.mark.parametrize("packets, message", [
    ([5, 40, 100], "must start at 0"),
    ([0, 60, 30, 100], "must not decrease"),
])
def test_bad_plain_packets_name_the_packets(name, packets, message, rng):
    """int32 packets that end at n (the pipeline's kind, which the key sorters hand their
    kernel unchecked: raysort.sdk.plain_packets) but start elsewhere or go back:
    ConfigError saying so."""
    rays = random_rays(rng, 100, BOX)
    with pytest.raises(ConfigError, match=message):
        raysort.create("sorters", name).sort(rays, np.array(packets, np.int32), BOX)


# -- the previous hit distance ------------------------------------------------------

def test_bounce_rays_carry_the_previous_hit_distance(sibenik):
    """First-bounce rays start where their camera ray hit: |origin - camera| = prev_t |d|."""
    from raysort.workloads import workload

    work = workload(sibenik, "diffuse:depth=1", width=32, height=32, spp=1)
    prev_t = work.rays.prev_t
    assert prev_t is not None and len(prev_t) == len(work.rays)
    assert np.isfinite(prev_t).all() and (prev_t > 0).all()
    primary = workload(sibenik, "primary", width=32, height=32, spp=1)
    assert primary.rays.prev_t is None
    cam = primary.rays.origins[:, 0].astype(np.float64)
    assert np.allclose(primary.rays.origins.T, cam), "the pinhole camera has one origin"
    dir_len = np.linalg.norm(primary.rays.directions.astype(np.float64), axis=0)
    assert np.allclose(dir_len, 1, atol=1e-6), "pinhole directions are unit vectors"
    # each bounce ray starts at its camera ray's hit: camera + t * d (up to the small
    # offset a shader adds to leave the surface)
    dist = np.linalg.norm(work.rays.origins.T.astype(np.float64) - cam, axis=1)
    extent = float(np.linalg.norm(sibenik.bvh().bounds[1] - sibenik.bvh().bounds[0]))
    assert np.abs(dist - prev_t).max() <= 1e-3 * extent


# -- every ISA ---------------------------------------------------------------------

@pytest.mark.parametrize("name", KEY_SORTERS)
def test_same_order_on_every_isa(name, rng):
    """The key kernel is built per ISA; every build gives the same keys and order."""
    rays = inside_rays(rng, 3000)
    rays.prev_t = rng.uniform(0, 3, len(rays)).astype(np.float32)
    rays.prev_t[::7] = np.nan
    rays.prev_t[1::11] = -0.0
    rays.prev_t[2::13] = 1e-42
    rays.prev_t[3::17] = np.inf
    packets = np.array([0, 1024, 2048, 3000], np.int32)
    sorter = raysort.create("sorters", name)
    results = {}
    for each in isa.available():
        previous = isa.use(each)
        try:
            assert isa.module("sorters._keysort").__name__.startswith(
                "raysort.sorters" if each == isa.baseline() else f"raysort._isa.{each}.")
            results[each] = sorter.keys(rays, BOX), *sorter.sort(rays, packets, BOX)
        finally:
            isa.use(previous)
    first = next(iter(results.values()))
    for each, got in results.items():
        assert all(np.array_equal(a, b) for a, b in zip(got, first)), each
