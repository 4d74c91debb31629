"""The identity order: its values, its memory that cannot be written, and how the
contract tells it from an order that only looks like it."""
import numpy as np
import pytest

from raysort import contract
from raysort.errors import PluginContractError
from raysort.orders import identity_order, is_identity_order
from raysort.sorters.none import NoneSorter


@pytest.mark.parametrize("n", [0, 1, 5, 1000, 70_001])
def test_identity_order_is_an_arange(n):
    order = identity_order(n)
    np.testing.assert_array_equal(order, np.arange(n))
    assert order.dtype == np.int32 and order.flags.c_contiguous and is_identity_order(order)


def test_identity_order_cannot_be_written():
    order = identity_order(100)
    with pytest.raises(ValueError):
        order[3] = 7
    for array in (order, order.base):
        with pytest.raises(ValueError):
            array.flags.writeable = True
    np.testing.assert_array_equal(identity_order(100), np.arange(100))


def test_older_blocks_stay_identities_when_a_larger_one_is_made():
    small = identity_order(10)
    large = identity_order(len(identity_order(0).base) * 2 + 3)
    assert is_identity_order(small) and is_identity_order(large)
    np.testing.assert_array_equal(large, np.arange(len(large)))


@pytest.mark.parametrize("make", [
    lambda: np.arange(50, dtype=np.int32),                         # equal values, own memory
    lambda: identity_order(60)[10:],                               # not from the start
    lambda: identity_order(60)[::2],                               # strided
    lambda: identity_order(60)[::-1],
    lambda: identity_order(60).copy(),
    lambda: identity_order(60).astype(np.int64),
    lambda: identity_order(60).reshape(6, 10),
    lambda: list(range(60)),
], ids=["arange", "offset", "strided", "reversed", "copy", "int64", "2-d", "list"])
def test_look_alikes_are_not_the_identity(make):
    assert not is_identity_order(make())


def test_the_check_reads_a_look_alike_in_full():
    """An order equal to the identity but for one swap, in memory of its own, is still
    read and refused; the identity itself passes without being read."""
    n, packets = 64, np.array([0, 64], np.int32)
    offsets = np.array([0, 32, 64], np.int32)
    contract.check_sort(NoneSorter(), (identity_order(n), offsets), n, packets)
    swapped = np.arange(n, dtype=np.int32)
    swapped[[5, 40]] = 5
    with pytest.raises(PluginContractError, match="permutation"):
        contract.check_sort(NoneSorter(), (swapped, offsets), n, packets)
