"""The sorter contract, checked on every registered sorter (built-in or installed plugin).

Every test is parametrised over ``raysort.available("sorters")``, so a
third-party sorter installed next to raysort is held to the same contract:
``sort`` returns a permutation and strictly increasing offsets from 0 to n,
each sub-packet holds 1..4096 rays of one large packet, the result is
deterministic, the batch is left untouched, and rendering with the sorter
gives the bit-identical image of the unsorted (``none``) pipeline.
"""
import numpy as np
import pytest

import raysort
from raysort.contract import check_sort
from raysort.rays import MAX_PACKET, RayBatch

from _helpers import random_rays

SORTERS = raysort.available("sorters")
BOX = np.array([[-3.0, -1.0, 2.0], [5.0, 4.0, 3.5]], dtype=np.float32)


@pytest.fixture(params=SORTERS)
def sorter_name(request):
    return request.param


def make(name):
    return raysort.create("sorters", name)


def assert_valid_sort(name, result, rays, packets):
    """Assert the contract directly (own code), then through ``check_sort``."""
    n = len(rays)
    packets = np.asarray(packets)
    assert isinstance(result, tuple) and len(result) == 2, f"{name}: sort() must return a pair"
    order, offsets = (np.asarray(a) for a in result)
    for label, arr in (("order", order), ("offsets", offsets)):
        assert arr.ndim == 1, f"{name}: {label} is {arr.ndim}-d"
        assert np.issubdtype(arr.dtype, np.integer), f"{name}: {label} dtype {arr.dtype}"
    # permutation of range(n)
    assert len(order) == n, f"{name}: {len(order)} indices for {n} rays"
    assert np.array_equal(np.sort(order.astype(np.int64)), np.arange(n)), \
        f"{name}: order is not a permutation"
    # offsets 0 .. n, strictly increasing, sub-packets of 1..4096 rays
    assert offsets[0] == 0 and offsets[-1] == n, f"{name}: offsets run {offsets[0]}..{offsets[-1]}"
    sizes = np.diff(offsets.astype(np.int64))
    assert (sizes >= 1).all(), f"{name}: empty or negative sub-packet"
    assert (sizes <= MAX_PACKET).all(), f"{name}: sub-packet of {sizes.max()} rays"
    # each sub-packet inside one large packet: label every ray with its large packet
    label = np.repeat(np.arange(len(packets) - 1), np.diff(packets))
    assert len(label) == n
    lab = label[order]
    sub = np.repeat(np.arange(len(sizes)), sizes)      # sub-packet of each sorted position
    first = lab[offsets[:-1].astype(np.int64)]         # large packet of each sub-packet's 1st ray
    bad = np.flatnonzero(lab != first[sub])
    assert len(bad) == 0, (f"{name}: sub-packet {sub[bad[0]]} mixes large packets "
                           f"{first[sub[bad[0]]]} and {lab[bad[0]]}")
    # the framework's checker agrees and returns the same arrays as int32
    o2, f2 = check_sort(name, result, n, packets)
    assert o2.dtype == np.int32 and f2.dtype == np.int32
    assert np.array_equal(o2, order) and np.array_equal(f2, offsets)
    return order, offsets


def run_contract(name, rays, packets, bounds):
    """Sort twice (and with a fresh instance): valid, deterministic, batch untouched."""
    packets = np.asarray(packets, dtype=np.int32)
    bounds = np.asarray(bounds, dtype=np.float32)
    before = rays.data.copy()
    sorter = make(name)
    first = assert_valid_sort(name, sorter.sort(rays, packets.copy(), bounds.copy()), rays,
                              packets)
    assert np.array_equal(rays.data.view(np.uint32), before.view(np.uint32)), \
        f"{name}: sort() modified the ray batch"
    again = assert_valid_sort(name, sorter.sort(rays, packets.copy(), bounds.copy()), rays,
                              packets)
    fresh = assert_valid_sort(name, make(name).sort(rays, packets.copy(), bounds.copy()), rays,
                              packets)
    for other in (again, fresh):
        assert np.array_equal(first[0], other[0]), f"{name}: order is not deterministic"
        assert np.array_equal(first[1], other[1]), f"{name}: offsets are not deterministic"


@pytest.mark.parametrize("kind", ["primary", "diffuse"])
def test_workloads(sorter_name, real_scene, workloads, kind):
    """Sibenik/Sponza camera and first-bounce workloads: valid, deterministic sort."""
    work = workloads(real_scene, kind)
    assert len(work.rays) > 0 and len(work.packets) > 2
    run_contract(sorter_name, work.rays, work.packets, real_scene.bvh().bounds)


def test_random_rays(sorter_name, rng):
    """Incoherent random rays in 1024-ray large packets (last one short)."""
    rays = random_rays(rng, 2500, BOX)
    run_contract(sorter_name, rays, [0, 1024, 2048, 2500], BOX)


@pytest.mark.parametrize("packets", [[0], [0, 0], [0, 0, 0]], ids=["no-packet", "one-empty",
                                                                 "two-empty"])
def test_empty_batch(sorter_name, packets):
    """No rays at all: an empty order and offsets == [0]."""
    rays = RayBatch(0)
    run_contract(sorter_name, rays, packets, BOX)
    order, offsets = make(sorter_name).sort(rays, np.asarray(packets, np.int32), BOX)
    assert len(order) == 0 and list(np.asarray(offsets)) == [0]


@pytest.mark.parametrize("packets", [[0, 1], [0, 0, 1, 1]], ids=["plain", "empty-around"])
def test_one_ray(sorter_name, rng, packets):
    """A single ray: order [0], offsets [0, 1]."""
    rays = random_rays(rng, 1, BOX)
    run_contract(sorter_name, rays, packets, BOX)
    order, offsets = make(sorter_name).sort(rays, np.asarray(packets, np.int32), BOX)
    assert list(np.asarray(order)) == [0] and list(np.asarray(offsets)) == [0, 1]


@pytest.mark.parametrize("packets", [
    # uneven large packets, with empty ones first, in the middle and last
    [0, 0, 1, 1, 7, 300, 300, 1324, 5400, 5400, 6000, 6000],
    # one large packet bigger than MAX_PACKET: sub-packets must still be <= 4096
    [0, 3, 4100, 6000],
    # every large packet a single ray
    list(range(0, 301)),
], ids=["uneven-with-empty", "oversized", "singletons"])
def test_uneven_large_packets(sorter_name, rng, packets):
    """Large packets of different sizes, including empty ones (repeated boundaries)."""
    n = packets[-1]
    rays = random_rays(rng, n, BOX)
    run_contract(sorter_name, rays, packets, BOX)


def test_coherent_rays(sorter_name):
    """Identical rays (one bucket, one cell): sub-packets still within the limits."""
    rays = RayBatch.from_arrays(np.full((5000, 3), 0.5), np.tile([0.2, -0.9, 0.1], (5000, 1)))
    run_contract(sorter_name, rays, [0, 4096, 5000], BOX)


# -- rendering: a sorter must never change the image ---------------------------------

@pytest.fixture(scope="module")
def reference_images(sibenik):
    """Images rendered with the ``none`` sorter, per traversal."""
    cache = {}

    def get(traversal):
        if traversal not in cache:
            cache[traversal] = raysort.Pipeline(sibenik, sorter="none",
                                                traversal=traversal).render(48, 32, 2, seed=3)
        return cache[traversal]

    return get


@pytest.mark.parametrize("traversal", ["single", "ranged"])
def test_render_bit_identical(sorter_name, traversal, sibenik, reference_images):
    """Sibenik 48x32 at 2 spp: the image is bit-identical to the unsorted pipeline's."""
    ref = reference_images(traversal)
    assert ref.image.shape == (32, 48, 3) and ref.image.dtype == np.float32
    assert np.isfinite(ref.image).all() and ref.image.max() > 0, "reference render is empty"
    result = raysort.Pipeline(sibenik, sorter=sorter_name, traversal=traversal).render(
        48, 32, 2, seed=3)
    assert result.image.shape == ref.image.shape and result.image.dtype == ref.image.dtype
    diff = np.flatnonzero(result.image.view(np.uint32) != ref.image.view(np.uint32))
    assert result.image.tobytes() == ref.image.tobytes(), (
        f"sorter {sorter_name!r} with {traversal!r} changed {len(diff)} image values")
    assert result.stats.rays == ref.stats.rays, "a different number of rays was traced"
