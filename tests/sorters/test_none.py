"""Sorter ``none``: the input order, cut as :func:`raysort.sdk.fixed_packets` cuts it."""
import numpy as np
import pytest

import raysort
from raysort.rays import RayBatch
from raysort.sdk import check_sort, fixed_packets


def large_packets(rng, size):
    """Boundaries of a few large packets: some start on multiples of ``size`` (a render's
    primary rays), some anywhere (bounces, shadow rays), some are empty."""
    cuts = np.sort(rng.integers(0, 8, rng.integers(0, 6)) * size if rng.random() < 0.5
                   else rng.integers(0, 300, rng.integers(0, 6)))
    n = int(cuts.max(initial=0) + rng.integers(0, 100))
    return np.concatenate([[0], cuts, [n]]).astype(np.int32)


@pytest.mark.parametrize("seed", range(4))
def test_offsets_are_fixed_packets_and_the_order_is_the_input(seed):
    rng = np.random.default_rng(seed)
    for _ in range(300):
        size = int(rng.integers(1, 80))
        packets = large_packets(rng, size)
        n = int(packets[-1])
        sorter = raysort.create("sorters", f"none:packet_size={size}")
        want = fixed_packets(packets.tolist(), size)     # the NumPy path: a list
        for given in (packets, packets.astype(np.int64), packets.tolist()):
            order, offsets = sorter.sort(RayBatch(n), given, None)
            assert order.dtype == offsets.dtype == np.int32
            assert np.array_equal(order, np.arange(n))
            assert np.array_equal(offsets, want)
        if n:
            check_sort("none", (order, offsets), n, packets)


def test_a_frame_of_packets_is_cut_on_its_boundaries():
    """1024-ray large packets in 64-ray sub-packets, and a ragged set (shadow rays)."""
    sorter = raysort.create("sorters", "none")
    _, offsets = sorter.sort(RayBatch(4096), np.arange(0, 4097, 1024, dtype=np.int32), None)
    assert np.array_equal(offsets, np.arange(0, 4097, 64))
    _, offsets = sorter.sort(RayBatch(200), np.array([0, 70, 70, 200], np.int32), None)
    assert offsets.tolist() == [0, 64, 70, 134, 198, 200]


def test_the_order_is_read_only_and_shared_batch_to_batch():
    """The order is a read-only view of one arange kept for the largest batch so far: a
    smaller batch's is a prefix of it, a larger one's is made anew and right."""
    sorter = raysort.create("sorters", "none")
    big, _ = sorter.sort(RayBatch(5000), np.array([0, 5000], np.int32), None)
    small, _ = sorter.sort(RayBatch(300), np.array([0, 300], np.int32), None)
    assert not big.flags.writeable and not small.flags.writeable
    assert np.shares_memory(big, small) and np.array_equal(small, np.arange(300))
    with pytest.raises(ValueError):
        small[0] = 1
    bigger, _ = sorter.sort(RayBatch(9000), np.array([0, 9000], np.int32), None)
    assert np.array_equal(bigger, np.arange(9000)) and np.array_equal(big, np.arange(5000))
