"""The Nah et al. sorter (paper section 3): ``nah`` (Cython) and ``nah_numpy``.

Three kinds of checks:

* ``nah`` and ``nah_numpy`` give identical ``classify`` (bucket and cell of
  every ray) and identical ``sort`` output over a grid of parameters;
* both equal an independent, loop-based transcription of section 3 written
  here (direction bucket = octant * 3 + major axis; per bucket an origin grid
  split at the middle of the bucket's origin box on every axis wider than
  ``threshold`` of the scene box, widest relative extents first, at most
  ``max_cells`` cells; a stable counting sort on (bucket, cell); every
  non-empty cell cut into sub-packets of at most ``packet_size`` rays);
* hand-built ray sets whose buckets and cells are known in advance.

The cell number of the reference is the bit pattern of the ``>= middle``
tests of the split axes, in axis order (lowest split axis = bit 0).  The
hand-built tests only rely on which rays share a cell.
"""
import functools
import itertools

import numpy as np
import pytest

import raysort
from raysort.contract import check_sort
from raysort.errors import ConfigError
from raysort.rays import RayBatch
from raysort.sorters.nah import NahSorter
from raysort.sorters.nah_numpy import NahNumpySorter

from _helpers import random_rays

UNIT = np.array([[0, 0, 0], [1, 1, 1]], dtype=np.float32)
IMPLS = {"nah": NahSorter, "nah_numpy": NahNumpySorter}
THRESHOLDS = [0, 0.25, 1, 10]
MAX_CELLS = [1, 2, 4, 8]
PACKET_SIZES = [1, 7, 64, 4096]
LARGE_PACKETS = [None, 100]


# -- an independent reference of section 3 -------------------------------------------

def expected_bucket(dx, dy, dz):
    """octant * 3 + major axis; octant bit k when component k < 0; ties to the lower axis.

    The major axis is found by the documented comparisons: start with x, take y
    when |dy| > best, then z when |dz| > best (comparisons with NaN are false).
    """
    octant = int(dx < 0) | int(dy < 0) << 1 | int(dz < 0) << 2
    mags = [abs(float(dx)), abs(float(dy)), abs(float(dz))]
    major = 0
    for axis in (1, 2):
        if mags[axis] > mags[major]:
            major = axis
    return octant * 3 + major


def expected_buckets(rays):
    d = rays.directions
    return np.array([expected_bucket(*d[:, i]) for i in range(len(rays))], dtype=np.int64)


def runs_of(packets, large_packet):
    """The (start, end) runs sorted independently: large packets, cut to ``large_packet``."""
    runs = []
    for s, e in zip(packets[:-1], packets[1:]):
        s, e = int(s), int(e)
        step = large_packet if large_packet else max(e - s, 1)
        runs.extend((r, min(r + step, e)) for r in range(s, e, step))
    return runs


def split_axes(lo, hi, root, threshold, max_cells):
    """Axes (ascending) whose origin extent exceeds threshold * root, widest relative first."""
    f32 = np.float32
    with np.errstate(invalid="ignore", over="ignore"):
        ext = [f32(hi[a]) - f32(lo[a]) for a in range(3)]
        wide = [a for a in range(3) if ext[a] > f32(threshold) * f32(root[a])]

    def wider_first(a, b):   # exact cross-multiplied comparison of ext/root (float64)
        lhs, rhs = float(ext[a]) * float(root[b]), float(ext[b]) * float(root[a])
        if lhs != rhs:
            return -1 if lhs > rhs else 1
        return -1 if a < b else 1

    keep = {1: 0, 2: 1, 4: 2, 8: 3}[max_cells]
    return sorted(sorted(wide, key=functools.cmp_to_key(wider_first))[:keep])


def reference_classify(rays, packets, bounds, threshold, max_cells, large_packet, buckets=None):
    """Bucket and cell of every ray, by loops over runs and buckets."""
    n = len(rays)
    bucket = expected_buckets(rays) if buckets is None else buckets
    cell = np.zeros(n, dtype=np.int64)
    o = rays.origins
    root = np.asarray(bounds, np.float32)[1] - np.asarray(bounds, np.float32)[0]
    for s, e in runs_of(packets, large_packet):
        for b in np.unique(bucket[s:e]):
            idx = s + np.flatnonzero(bucket[s:e] == b)
            lo, hi = [], []
            for a in range(3):
                v = o[a, idx]
                v = v[~np.isnan(v)]                      # NaN origins do not grow the box
                lo.append(v.min() if len(v) else np.float32(np.inf))
                hi.append(v.max() if len(v) else np.float32(-np.inf))
            axes = split_axes(lo, hi, root, threshold, max_cells)
            for bit, a in enumerate(axes):
                with np.errstate(invalid="ignore"):     # (-inf + inf: no ray >= NaN)
                    mid = np.float32((np.float64(lo[a]) + np.float64(hi[a])) / 2)
                    cell[idx] |= (o[a, idx] >= mid).astype(np.int64) << bit
    return bucket, cell


def reference_sort(packets, bucket, cell, packet_size, large_packet):
    """Stable sort on (bucket, cell) inside every run; cells cut into packet_size pieces."""
    order, offsets = [], []
    for s, e in runs_of(packets, large_packet):
        idx = sorted(range(s, e), key=lambda i: (bucket[i], cell[i]))     # stable
        for _, group in itertools.groupby(idx, key=lambda i: (bucket[i], cell[i])):
            group = list(group)
            for k in range(0, len(group), packet_size):
                offsets.append(len(order))
                order.extend(group[k:k + packet_size])
    offsets.append(len(order))
    return np.array(order, dtype=np.int64), np.array(offsets, dtype=np.int64)


# -- data sets --------------------------------------------------------------------------

def tricky_random(seed=99, n=2000):
    """Random rays with exact ties, zeros and -0.0 in directions, repeated origin values,
    and uneven large packets (including empty ones)."""
    rng = np.random.default_rng(seed)
    box = np.array([[-2, -1, 0], [6, 1, 0.5]], dtype=np.float32)
    origins = box[0] + rng.random((n, 3)) * (box[1] - box[0]) * 1.2
    origins[::3] = np.round(origins[::3] * 4) / 4          # many equal origin values
    directions = rng.normal(size=(n, 3))
    directions[::2] = rng.choice([-2.0, -1.0, -0.0, 0.0, 1.0, 2.0], size=(n // 2, 3))
    rays = RayBatch.from_arrays(origins, directions)
    packets = np.array([0, 0, 1, 150, 150, 1174, 1900, 1900, n], dtype=np.int32)
    return rays, packets, box


def coherent_runs(seed=5):
    """Rays in runs of one direction bucket, as camera and shadow rays come: runs of 1 to
    600 rays (around the kernel's run rule of 8 on average, and its vector widths), some
    packets with one origin (no grid split), some whose origins alternate across a
    bucket's middle inside long runs (long bucket runs, short cell runs), NaN, infinite,
    -0.0 and +0.0 origin components inside runs, and uneven large packets."""
    rng = np.random.default_rng(seed)
    heads = np.array([[1, 0.1, 0.2], [-1, 0.3, 0.1], [0.1, 1, 0], [0.2, -0.3, -1],
                      [0.5, 0.5, 0.5], [-0.7, -0.7, 0.1]], dtype=np.float64)
    lengths = [1, 7, 8, 9, 15, 16, 17, 33, 200, 600, 3, 64, 5, 2, 31, 120]
    dirs, origins = [], []
    for j, length in enumerate(lengths * 3):
        d = np.repeat(heads[j % len(heads)][None], length, axis=0)
        d += rng.normal(scale=1e-3, size=d.shape)                # the same bucket
        o = rng.random((length, 3)) * [4, 2, 1] - [2, 1, 0]
        if j % 5 == 0:
            o[:] = [0.25, -0.5, 0.5]                             # one origin
        if j % 7 == 3:
            o[:, 0] = np.where(np.arange(length) % 2, -1.5, 1.5)  # alternate across the middle
        dirs.append(d)
        origins.append(o)
    d, o = np.concatenate(dirs), np.concatenate(origins)
    n = len(d)
    o[rng.choice(n, 40, replace=False), rng.integers(0, 3, 40)] = np.nan
    o[rng.choice(n, 20, replace=False), rng.integers(0, 3, 20)] = np.inf
    o[rng.choice(n, 60, replace=False), rng.integers(0, 3, 60)] = rng.choice([-0.0, 0.0], 60)
    rays = RayBatch.from_arrays(o, d)
    packets = np.array([0, 1, 9, 700, 700, 1724, 2500, 3100, n], dtype=np.int32)
    return rays, packets, np.array([[-2, -1, 0], [2, 1, 1]], dtype=np.float32)


def few_buckets(seed=13):
    """Packets of one to nine direction buckets whose rays alternate between them ray by
    ray, in runs of 3, or at random, as shadow rays come where a packet straddles a
    bucket's border: around the avx512 build's few-key passes (at most eight buckets and
    eight keys) and past them.  Origins spread on none to three axes (grids of 1 to 8
    cells: 1 to 72 keys), NaN, infinite and signed-zero origin components, and packets
    of lengths around the 16-lane vector (1, 15, 16, 17, ...)."""
    rng = np.random.default_rng(seed)
    heads = np.array([[(-1) ** (o & 1), (-1) ** (o >> 1 & 1), (-1) ** (o >> 2 & 1)]
                      for o in range(8)], dtype=np.float64)
    lengths = [1, 15, 16, 17, 31, 33, 200, 1024, 333, 64, 700, 129, 48, 1000, 257, 90]
    dirs, origins, packets = [], [], [0]
    for p, length in enumerate(lengths * 2):
        n_buckets = 1 + p % 9
        chosen = rng.choice(24, n_buckets, replace=False)
        pattern = [np.arange(length) % n_buckets, np.arange(length) // 3 % n_buckets,
                   rng.integers(0, n_buckets, length)][p % 3]
        bucket = chosen[pattern]
        d = heads[bucket // 3] * 0.5
        d[np.arange(length), bucket % 3] *= 2                     # the major axis
        d += rng.normal(scale=1e-3, size=d.shape)
        o = rng.random((length, 3)) * [4, 2, 1] - [2, 1, 0]
        spread = p % 4                                              # axes left spread
        o[:, spread:] = np.float64([0.25, -0.5, 0.5])[spread:]
        dirs.append(d)
        origins.append(o)
        packets.append(packets[-1] + length)
    d, o = np.concatenate(dirs), np.concatenate(origins)
    n = len(d)
    o[rng.choice(n, 40, replace=False), rng.integers(0, 3, 40)] = np.nan
    o[rng.choice(n, 20, replace=False), rng.integers(0, 3, 20)] = rng.choice([np.inf, -np.inf],
                                                                             20)
    o[rng.choice(n, 60, replace=False), rng.integers(0, 3, 60)] = rng.choice([-0.0, 0.0], 60)
    rays = RayBatch.from_arrays(o, d)
    return rays, np.array(packets, dtype=np.int32), np.array([[-2, -1, 0], [2, 1, 1]],
                                                             dtype=np.float32)


@pytest.fixture(scope="module")
def datasets(sibenik, sponza, workloads):
    sets = {}
    for scene in (sibenik, sponza):
        for kind in ("primary", "diffuse", "shadow"):
            w = workloads(scene, kind)
            sets[f"{scene.name}-{kind}"] = (w.rays, w.packets, scene.bvh().bounds)
    sets["random"] = tricky_random()
    sets["coherent"] = coherent_runs()
    sets["few"] = few_buckets()
    return sets


DATASETS = ["sibenik-primary", "sibenik-diffuse", "sibenik-shadow", "sponza-primary",
            "sponza-diffuse", "sponza-shadow", "random", "coherent", "few"]


@pytest.fixture(scope="module")
def bucket_cache(datasets):
    return {key: expected_buckets(rays) for key, (rays, _, _) in datasets.items()}


def classify_both(rays, packets, bounds, **params):
    out = {}
    for name, cls in IMPLS.items():
        bucket, cell = cls(**params).classify(rays, packets, bounds)
        assert bucket.dtype == np.uint8 and cell.dtype == np.uint8, name
        assert len(bucket) == len(rays) and len(cell) == len(rays), name
        out[name] = (bucket, cell)
    return out


def sort_both(rays, packets, bounds, **params):
    out = {}
    for name, cls in IMPLS.items():
        result = cls(**params).sort(rays, packets, bounds)
        check_sort(name, result, len(rays), packets)
        out[name] = tuple(np.asarray(a) for a in result)
    return out


# -- nah == nah_numpy == reference --------------------------------------------------------

@pytest.mark.parametrize("data", DATASETS)
def test_every_isa_sorts_like_nah_numpy(each_isa, datasets, data):
    """The kernel is built per ISA: every build gives nah_numpy's buckets, cells and
    order."""
    rays, packets, bounds = datasets[data]
    got = classify_both(rays, packets, bounds)
    for a, b in zip(got["nah"], got["nah_numpy"]):
        assert np.array_equal(a, b), each_isa
    out = sort_both(rays, packets, bounds)
    for a, b in zip(out["nah"], out["nah_numpy"]):
        assert np.array_equal(a, b), each_isa


@pytest.mark.parametrize("large_packet", LARGE_PACKETS)
@pytest.mark.parametrize("max_cells", MAX_CELLS)
@pytest.mark.parametrize("threshold", THRESHOLDS)
@pytest.mark.parametrize("data", DATASETS)
def test_matches_reference(datasets, bucket_cache, data, threshold, max_cells, large_packet):
    """Both sorters: same buckets/cells as each other and as the reference; same order and
    offsets for packet_size 1, 7, 64 and 4096."""
    rays, packets, bounds = datasets[data]
    params = dict(threshold=threshold, max_cells=max_cells, large_packet=large_packet)
    got = classify_both(rays, packets, bounds, **params)
    (b1, c1), (b2, c2) = got["nah"], got["nah_numpy"]
    assert np.array_equal(b1, b2), "nah and nah_numpy disagree on buckets"
    assert np.array_equal(c1, c2), "nah and nah_numpy disagree on cells"
    rb, rc = reference_classify(rays, packets, bounds, threshold, max_cells, large_packet,
                                bucket_cache[data])
    bad = np.flatnonzero(b1 != rb)
    assert len(bad) == 0, f"ray {bad[0]}: bucket {b1[bad[0]]}, expected {rb[bad[0]]}"
    bad = np.flatnonzero(c1 != rc)
    assert len(bad) == 0, f"{len(bad)} rays in another cell, e.g. ray {bad[0]}: " \
                          f"{c1[bad[0]]}, expected {rc[bad[0]]}"
    assert (c1 < max_cells).all()
    for packet_size in PACKET_SIZES:
        out = sort_both(rays, packets, bounds, packet_size=packet_size, **params)
        o1, f1 = out["nah"]
        o2, f2 = out["nah_numpy"]
        assert np.array_equal(o1, o2) and np.array_equal(f1, f2), \
            f"nah and nah_numpy sort differently (packet_size={packet_size})"
        ro, rf = reference_sort(packets, rb, rc, packet_size, large_packet)
        assert np.array_equal(o1, ro), f"order differs from the reference (ps={packet_size})"
        assert np.array_equal(f1, rf), f"offsets differ from the reference (ps={packet_size})"


def test_random_rays_default_params(rng):
    """Default parameters on plain random rays: both equal the reference."""
    rays = random_rays(rng, 3000, UNIT)
    packets = np.array([0, 1024, 2048, 3000], dtype=np.int32)
    got = classify_both(rays, packets, UNIT)
    rb, rc = reference_classify(rays, packets, UNIT, 0.25, 8, None)
    for name, (b, c) in got.items():
        assert np.array_equal(b, rb) and np.array_equal(c, rc), name
    ro, rf = reference_sort(packets, rb, rc, 64, None)
    for name, (o, f) in sort_both(rays, packets, UNIT).items():
        assert np.array_equal(o, ro) and np.array_equal(f, rf), name
    assert len(np.unique(rb)) == 24, "random directions should reach all 24 buckets"


@pytest.mark.parametrize("max_cells", [2, 8])
def test_flat_scene_box(max_cells):
    """A scene box with zero extent on y (a flat scene): any y spread counts as infinitely
    wide relative to it and is split first; both sorters equal the reference."""
    rng = np.random.default_rng(11)
    flat = np.array([[0, 0.5, 0], [4, 0.5, 2]], dtype=np.float32)
    origins = rng.random((400, 3)) * [4, 0.01, 2]
    origins[:200, 1] = 0.5                      # half the rays have no y spread at all
    rays = RayBatch.from_arrays(origins, rng.normal(size=(400, 3)))
    packets = np.array([0, 200, 400], np.int32)
    rb, rc = reference_classify(rays, packets, flat, 0.25, max_cells, None)
    for name, (b, c) in classify_both(rays, packets, flat, max_cells=max_cells).items():
        assert np.array_equal(b, rb) and np.array_equal(c, rc), name
    ro, rf = reference_sort(packets, rb, rc, 64, None)
    for name, (o, f) in sort_both(rays, packets, flat, max_cells=max_cells).items():
        assert np.array_equal(o, ro) and np.array_equal(f, rf), name
    if max_cells == 2:   # the second large packet splits y only (y is the first bit)
        for b in np.unique(rb[200:]):
            sel = 200 + np.flatnonzero(rb[200:] == b)
            if len(sel) > 1:
                ys = rays.origins[1, sel]
                mid = np.float32((np.float64(ys.min()) + np.float64(ys.max())) / 2)
                assert np.array_equal(rc[sel], (ys >= mid).astype(int))


# -- hand-built rules -------------------------------------------------------------------

def one_bucket_rays(origins, direction=(1.0, 0.5, 0.25)):
    origins = np.asarray(origins, dtype=np.float32)
    return RayBatch.from_arrays(origins, np.tile(direction, (len(origins), 1)))


def same_partition(cells, sides):
    """Rays share a cell exactly when they are on the same side of every split."""
    cells = np.asarray(cells)
    sides = [tuple(s) for s in np.asarray(sides)]
    for i in range(len(cells)):
        for j in range(len(cells)):
            if (cells[i] == cells[j]) != (sides[i] == sides[j]):
                return False
    return True


def test_bucket_is_octant_times_three_plus_major_axis():
    """Every sign pattern and major axis, with ties, zeros and -0.0."""
    dirs = []
    for signs in itertools.product((1, -1), repeat=3):
        for mags in ((3, 2, 1), (1, 3, 2), (2, 1, 3), (1, 1, 0), (1, 1, 1), (0, 2, 2),
                     (2, 0, 2), (0, 0, 0), (0.5, 0.25, 0.5)):
            dirs.append(np.multiply(signs, mags))
    dirs += [(-0.0, 1, 0), (-0.0, -0.0, -0.0), (0, -0.0, -1)]
    dirs = np.array(dirs, dtype=np.float32)
    rays = RayBatch.from_arrays(np.zeros_like(dirs), dirs)
    want = np.array([expected_bucket(*d) for d in dirs])
    # hand-computed spot checks of the rule itself
    assert expected_bucket(3, 2, 1) == 0 and expected_bucket(-1, 3, 2) == 1 * 3 + 1
    assert expected_bucket(2, -1, -3) == 6 * 3 + 2 and expected_bucket(-1, -1, 0) == 3 * 3 + 0
    assert expected_bucket(-0.0, -0.0, -0.0) == 0 and expected_bucket(0, 2, 2) == 1
    packets = np.array([0, len(rays)], dtype=np.int32)
    for name, (bucket, _) in classify_both(rays, packets, UNIT).items():
        bad = np.flatnonzero(bucket != want)
        assert len(bad) == 0, f"{name}: direction {dirs[bad[0]]} in bucket {bucket[bad[0]]}, " \
                              f"expected {want[bad[0]]}"
    assert set(want) == set(range(24))


def test_eight_cells_split_at_middle_of_bucket_box():
    """One bucket, origins wide on every axis: 8 cells split at the middle of the bucket's
    origin box (not of the scene box)."""
    scene = np.array([[0, 0, 0], [4, 4, 4]], dtype=np.float32)
    lo, hi = np.array([1.25, 0.5, 2.0]), np.array([3.25, 2.5, 3.5])   # extents 2, 2, 1.5 > 1
    mid = (lo + hi) / 2                                                 # 2.25, 1.5, 2.75
    xs, ys, zs = [1.25, 2.1, 2.2, 2.3, 3.25], [0.5, 1.4, 1.6, 2.5], [2.0, 2.6, 2.9, 3.5]
    origins = np.array(list(itertools.product(xs, ys, zs)))
    rays = one_bucket_rays(origins)
    sides = origins >= mid
    assert sides.any(axis=0).all() and (~sides).any(axis=0).all()
    for name, (bucket, cell) in classify_both(rays, np.array([0, len(rays)], np.int32),
                                              scene).items():
        assert (bucket == 0).all(), name
        assert len(np.unique(cell)) == 8, f"{name}: {len(np.unique(cell))} cells"
        assert same_partition(cell, sides), f"{name}: cells are not the 8 octants around {mid}"
        # x = 2.1 and 2.2 are right of the scene box's middle (2) but left of the bucket's
        assert len(set(cell[origins[:, 0] < 2.25]) & set(cell[origins[:, 0] > 2.25])) == 0


def test_one_wide_axis_gives_two_cells():
    """Origins spread on x only: 2 cells, split at the middle of the x range."""
    xs = np.array([0.0, 0.1, 0.3, 0.45, 0.55, 0.8, 1.0])
    origins = np.column_stack([xs, np.full(7, 0.5), np.full(7, 0.25)])
    rays = one_bucket_rays(origins, (-0.1, 0.3, -0.9))
    for name, (bucket, cell) in classify_both(rays, np.array([0, 7], np.int32), UNIT).items():
        assert (bucket == expected_bucket(-0.1, 0.3, -0.9)).all(), name
        assert len(np.unique(cell)) == 2, name
        assert same_partition(cell, (xs >= 0.5)[:, None]), name


def test_narrow_spread_gives_one_cell():
    """Origin extents below a quarter of the scene box (0.2, and exactly 0.25): one cell."""
    for width in (0.2, 0.25):
        rng = np.random.default_rng(5)
        origins = 0.25 + rng.random((50, 3)) * width
        origins[0], origins[1] = 0.25, 0.25 + width
        rays = one_bucket_rays(origins)
        extent = rays.origins.max(axis=1) - rays.origins.min(axis=1)
        assert (extent < 0.25).all() if width < 0.25 else (extent == 0.25).all()
        for name, (_, cell) in classify_both(rays, np.array([0, 50], np.int32), UNIT).items():
            assert (cell == 0).all(), f"{name}: extent {width} split (needs > 0.25)"
    # just over the quarter on y only: split there
    origins = np.zeros((4, 3))
    origins[:, 1] = [0.25, 0.3, 0.45, np.nextafter(np.float32(0.5), np.float32(1))]
    rays = one_bucket_rays(origins)
    for name, (_, cell) in classify_both(rays, np.array([0, 4], np.int32), UNIT).items():
        assert len(np.unique(cell)) == 2, name


@pytest.mark.parametrize("max_cells, split", [(1, []), (2, [1]), (4, [1, 2]), (8, [0, 1, 2])])
def test_max_cells_splits_widest_relative_extents_first(max_cells, split):
    """Scene box 8x1x2, origin extents 4, 0.75, 1.25 (relative 0.5, 0.75, 0.625): y first,
    then z, then x (x is widest in absolute terms but not relative to the scene)."""
    scene = np.array([[0, 0, 0], [8, 1, 2]], dtype=np.float32)
    lo, hi = np.array([1.0, 0.125, 0.5]), np.array([5.0, 0.875, 1.75])
    origins = np.array(list(itertools.product(*[[lo[a], (lo[a] + hi[a]) / 2 - 0.0625,
                                                 (lo[a] + hi[a]) / 2 + 0.0625, hi[a]]
                                                for a in range(3)])))
    rays = one_bucket_rays(origins)
    sides = (origins >= (lo + hi) / 2)[:, split]
    for name, (_, cell) in classify_both(rays, np.array([0, len(rays)], np.int32), scene,
                                         max_cells=max_cells).items():
        assert len(np.unique(cell)) == 2 ** len(split), name
        assert same_partition(cell, sides), f"{name}: not split on axes {split}"


def test_max_cells_tie_goes_to_lower_axis():
    """Equal relative extents on x and z, max_cells=2: x is split."""
    origins = np.array(list(itertools.product([0.0, 0.4, 0.6, 1.0], [0.5], [0.0, 0.4, 0.6, 1.0])))
    rays = one_bucket_rays(origins)
    for name, (_, cell) in classify_both(rays, np.array([0, len(rays)], np.int32), UNIT,
                                         max_cells=2).items():
        assert same_partition(cell, (origins[:, [0]] >= 0.5)), name


def test_threshold_zero_splits_any_spread_but_not_a_point():
    """threshold=0: any spread splits; a zero extent does not."""
    origins = np.column_stack([[0.5, 0.5, 0.5, 0.5], [0.1, 0.1, 0.11, 0.11], [0.3] * 4])
    rays = one_bucket_rays(origins)
    for name, (_, cell) in classify_both(rays, np.array([0, 4], np.int32), UNIT,
                                         threshold=0).items():
        assert same_partition(cell, origins[:, [1]] >= 0.105), name


def test_single_ray():
    """One ray: its bucket, cell 0, order [0], offsets [0, 1]."""
    rays = RayBatch.from_arrays([[0.3, 0.2, 0.1]], [[0.1, -0.7, -0.2]])
    packets = np.array([0, 1], np.int32)
    for name, (bucket, cell) in classify_both(rays, packets, UNIT).items():
        assert list(bucket) == [expected_bucket(0.1, -0.7, -0.2)] == [6 * 3 + 1], name
        assert list(cell) == [0], name
    for name, (order, offsets) in sort_both(rays, packets, UNIT).items():
        assert list(order) == [0] and list(offsets) == [0, 1], name


@pytest.mark.parametrize("packets", [[0], [0, 0], [0, 0, 0]])
def test_empty_packet(packets):
    """No rays: empty classify arrays, order [] and offsets [0]."""
    rays, packets = RayBatch(0), np.array(packets, np.int32)
    for name, (bucket, cell) in classify_both(rays, packets, UNIT).items():
        assert len(bucket) == 0 and len(cell) == 0, name
    for large_packet in (None, 100):
        for name, (order, offsets) in sort_both(rays, packets, UNIT,
                                                large_packet=large_packet).items():
            assert len(order) == 0 and list(offsets) == [0], name


def test_empty_large_packets_between_rays():
    """Empty large packets among full ones make no sub-packets."""
    rays = tricky_random(n=40)[0]
    packets = np.array([0, 0, 10, 10, 10, 40, 40], np.int32)
    rb, rc = reference_classify(rays, packets, UNIT, 0.25, 8, None)
    ro, rf = reference_sort(packets, rb, rc, 64, None)
    for name, (order, offsets) in sort_both(rays, packets, UNIT).items():
        assert np.array_equal(order, ro) and np.array_equal(offsets, rf), name


def test_nan_direction_and_origin():
    """NaN components: a defined bucket (octant bit 0, major axis by the comparisons),
    no crash, a valid sort; NaN origins do not break the cell grid."""
    nan = np.nan
    dirs = np.array([[nan, -1, 0.5], [1, nan, -2], [-3, 1, nan], [nan, nan, nan],
                     [-1, nan, nan], [nan, -2, -1], [0.5, -0.25, 0.1], [-1, -1, -1]],
                    dtype=np.float32)
    origins = np.array([[0.1, 0.9, 0.5]] * 8, dtype=np.float32)
    origins[2] = [nan, 0.2, 0.3]
    origins[6] = [nan, nan, nan]
    rays = RayBatch.from_arrays(origins, dirs)
    want = np.array([expected_bucket(*d) for d in dirs])
    # by hand: [nan,-1,.5] octant 2, major x (|-1| > NaN is false) -> 6;
    # [1,nan,-2] octant 4, |nan|>1 false, 2>1 -> z -> 14; [-3,1,nan] octant 1, x -> 3
    assert list(want[:3]) == [6, 14, 3] and want[3] == 0
    packets = np.array([0, 3, 8], np.int32)
    for name, (bucket, cell) in classify_both(rays, packets, UNIT, threshold=0).items():
        assert np.array_equal(bucket, want), f"{name}: {bucket} vs {want}"
        assert (cell < 8).all()
    got = classify_both(rays, packets, UNIT, threshold=0)
    assert np.array_equal(got["nah"][1], got["nah_numpy"][1])
    out = sort_both(rays, packets, UNIT, threshold=0, packet_size=1)
    assert all(np.array_equal(a, b) for a, b in zip(out["nah"], out["nah_numpy"]))


def test_infinite_components_agree():
    """Infinite origins/directions: both sorters agree with each other and make a valid sort."""
    rays, packets, box = tricky_random(seed=3, n=300)
    rays.origins[0, ::7] = np.inf
    rays.origins[1, ::11] = -np.inf
    rays.directions[2, ::5] = -np.inf
    rays.directions[:, ::13] = np.nan
    packets = np.array([0, 100, 300], np.int32)
    for threshold in (0, 0.25):
        got = classify_both(rays, packets, box, threshold=threshold)
        assert np.array_equal(got["nah"][0], got["nah_numpy"][0])
        assert np.array_equal(got["nah"][1], got["nah_numpy"][1])
        out = sort_both(rays, packets, box, threshold=threshold)
        assert all(np.array_equal(a, b) for a, b in zip(out["nah"], out["nah_numpy"]))
        assert np.array_equal(got["nah"][0], expected_buckets(rays))


def groups_of(order, bucket, cell, run_of):
    """(run, bucket, cell) key of each sorted position."""
    return np.stack([run_of[order], bucket[order], cell[order]], axis=1)


@pytest.mark.parametrize("large_packet", LARGE_PACKETS)
@pytest.mark.parametrize("packet_size", PACKET_SIZES)
@pytest.mark.parametrize("data", ["sibenik-diffuse", "random", "coherent"])
def test_sub_packet_rules(datasets, data, packet_size, large_packet):
    """Sub-packets: one cell of one run each, at most packet_size rays, only the last piece
    of a cell shorter, no sub-packet for an empty cell, ray indices increasing in a cell."""
    rays, packets, bounds = datasets[data]
    runs = runs_of(packets, large_packet)
    run_of = np.repeat(np.arange(len(runs)), [e - s for s, e in runs])
    for name, cls in IMPLS.items():
        sorter = cls(packet_size=packet_size, large_packet=large_packet)
        bucket, cell = sorter.classify(rays, packets, bounds)
        order, offsets = (np.asarray(a, np.int64) for a in sorter.sort(rays, packets, bounds))
        sizes = np.diff(offsets)
        assert (sizes >= 1).all() and (sizes <= packet_size).all(), name
        key = groups_of(order, bucket.astype(np.int64), cell.astype(np.int64), run_of)
        seen = set()
        for k, (s, e) in enumerate(zip(offsets[:-1], offsets[1:])):
            assert (key[s:e] == key[s]).all(), f"{name}: sub-packet {k} mixes cells or runs"
            g = tuple(key[s])
            if g in seen:   # a continuation piece: the previous piece of this cell was full
                assert tuple(key[s - 1]) == g and offsets[k] - offsets[k - 1] == packet_size
            seen.add(g)
        # as many sub-packets as sum(ceil(count / packet_size)) over non-empty cells
        _, counts = np.unique(key, axis=0, return_counts=True)
        assert len(sizes) == int(((counts + packet_size - 1) // packet_size).sum()), name
        # stable: inside a (run, bucket, cell) group the ray indices increase
        for g in np.unique(key, axis=0):
            idx = order[(key == g).all(axis=1)]
            assert (np.diff(idx) > 0).all(), f"{name}: unstable inside cell {g}"


def test_cell_cut_into_packet_size_pieces():
    """150 rays in one cell and 5 in another, packet_size 64: pieces 64, 64, 22 and 5."""
    origins = np.zeros((155, 3))
    origins[150:, 0] = 1.0                                   # 2 cells on x
    rays = one_bucket_rays(origins)
    packets = np.array([0, 155], np.int32)
    for name, (order, offsets) in sort_both(rays, packets, UNIT, packet_size=64).items():
        assert sorted(np.diff(offsets).tolist()) == [5, 22, 64, 64], name
        pieces = [order[s:e].tolist() for s, e in zip(offsets[:-1], offsets[1:])]
        assert sorted(pieces) == [list(range(0, 64)), list(range(64, 128)),
                                  list(range(128, 150)), list(range(150, 155))], name


def test_whole_cells_with_packet_size_4096():
    """packet_size=4096: one coherent cell of 5000 rays becomes pieces of 4096 and 904."""
    rays = one_bucket_rays(np.full((5000, 3), 0.5))
    for name, (order, offsets) in sort_both(rays, np.array([0, 5000], np.int32), UNIT,
                                            packet_size=4096).items():
        assert list(offsets) == [0, 4096, 5000] and np.array_equal(order, np.arange(5000)), name


def test_large_packet_runs_start_at_each_large_packet():
    """large_packet=100 on packets [0, 150, 400]: runs [0,100) [100,150) [150,250) [250,350)
    [350,400); identical rays still never share a sub-packet across runs."""
    rays = one_bucket_rays(np.full((400, 3), 0.5))
    packets = np.array([0, 150, 400], np.int32)
    for name, (order, offsets) in sort_both(rays, packets, UNIT, packet_size=4096,
                                            large_packet=100).items():
        assert list(offsets) == [0, 100, 150, 250, 350, 400], name
        assert np.array_equal(order, np.arange(400)), name


# -- parameters -----------------------------------------------------------------------

@pytest.mark.parametrize("impl", sorted(IMPLS))
@pytest.mark.parametrize("params", [
    {"threshold": -1}, {"threshold": float("nan")}, {"threshold": "big"},
    {"max_cells": 3}, {"max_cells": 0}, {"max_cells": 16},
    {"packet_size": 0}, {"packet_size": 4097}, {"packet_size": 2.5},
    {"large_packet": 5000}, {"large_packet": 0},
], ids=lambda p: ",".join(f"{k}={v}" for k, v in p.items()))
def test_bad_parameters_raise_config_error(impl, params):
    """Out-of-range parameters: ConfigError, both directly and through raysort.create."""
    with pytest.raises(ConfigError):
        IMPLS[impl](**params)
    with pytest.raises(ConfigError, match=impl):
        raysort.create("sorters", {"type": impl, **params})


@pytest.mark.parametrize("impl", sorted(IMPLS))
def test_good_parameters_accepted(impl):
    """Every documented value is accepted and kept."""
    for t, m, p, lp in itertools.product(THRESHOLDS, MAX_CELLS, (1, 4096), (None, 1, 4096)):
        s = raysort.create("sorters", {"type": impl, "threshold": t, "max_cells": m,
                                       "packet_size": p, "large_packet": lp})
        assert s.params() == {"threshold": t, "max_cells": m, "packet_size": p,
                              "large_packet": lp}


@pytest.mark.parametrize("impl", sorted(IMPLS))
def test_float_max_cells_is_rejected_or_works(impl):
    """max_cells=2.0 (e.g. from a spec "nah:max_cells=2.0") must raise ConfigError at
    construction or sort correctly -- not fail later inside sort()."""
    try:
        sorter = raysort.create("sorters", f"{impl}:max_cells=2.0")
    except ConfigError:
        return
    rays = one_bucket_rays([[0, 0, 0], [1, 1, 1]])
    check_sort(impl, sorter.sort(rays, np.array([0, 2], np.int32), UNIT), 2, [0, 2])


@pytest.mark.parametrize("impl", sorted(IMPLS))
@pytest.mark.parametrize("packets, message", [
    ([5, 40, 100], "must start at 0"),
    ([0, 60, 30, 100], "must not decrease"),
])
def test_bad_large_packets_name_the_packets(impl, packets, message):
    """int32 packets that end at n (the pipeline's kind, which nah hands its kernel
    unchecked) but start elsewhere or go back: ConfigError saying so."""
    rays = random_rays(np.random.default_rng(3), 100, UNIT)
    with pytest.raises(ConfigError, match=message):
        raysort.create("sorters", impl).sort(rays, np.array(packets, np.int32), UNIT)


@pytest.mark.parametrize("impl", sorted(IMPLS))
def test_strided_packets_sort_as_contiguous_ones(impl):
    """A strided view of int32 packets sorts as its contiguous copy."""
    rays = random_rays(np.random.default_rng(4), 300, UNIT)
    strided = np.array([0, -1, 100, -1, 300], np.int32)[::2]
    sorter = raysort.create("sorters", impl)
    for a, b in zip(sorter.sort(rays, strided, UNIT),
                    sorter.sort(rays, np.ascontiguousarray(strided), UNIT)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("impl", sorted(IMPLS))
def test_parameters_set_after_construction_are_checked_and_used(impl):
    """A parameter set on the sorter after it was made is checked at the next sort
    (ConfigError for a bad value) and used (a new packet_size cuts the sub-packets)."""
    rays = one_bucket_rays([[0, 0, 0]] * 50)
    packets = np.array([0, 50], np.int32)
    sorter = raysort.create("sorters", impl)
    assert np.diff(sorter.sort(rays, packets, UNIT)[1]).max() == 50
    sorter.packet_size = 7
    assert np.diff(sorter.sort(rays, packets, UNIT)[1]).max() == 7
    sorter.max_cells = 3
    with pytest.raises(ConfigError, match="max_cells"):
        sorter.sort(rays, packets, UNIT)
