"""``raysort.contract.check_sort`` and its use by the pipeline.

Every broken result must raise :class:`raysort.PluginContractError` naming
the sorter (message, ``.name``, ``.kind``); valid results pass and come back
as int32.  The pipeline checks every untrusted sorter even with
``check_sorters=False``.
"""
import numpy as np
import pytest

import raysort
import raysort.pipeline
from raysort.contract import check_sort
from raysort.errors import PluginContractError, RaysortError
from raysort.rays import MAX_PACKET, RayBatch
from raysort.sorters.none import NoneSorter

NAME = "my_sorter"
N = 10
PACKETS = np.array([0, 6, 10], dtype=np.int32)
ORDER = np.arange(N, dtype=np.int32)
OFFSETS = np.array([0, 3, 6, 10], dtype=np.int32)


def rejects(result, n=N, packets=PACKETS, match=None):
    with pytest.raises(PluginContractError, match=match) as info:
        check_sort(NAME, result, n, packets)
    assert repr(NAME) in str(info.value), str(info.value)
    assert info.value.name == NAME and info.value.kind == "sorters"
    assert isinstance(info.value, RaysortError)
    return info.value


# -- valid results --------------------------------------------------------------------------

@pytest.mark.parametrize("result, n, packets", [
    ((ORDER, OFFSETS), N, PACKETS),
    ((ORDER[::-1], np.array([0, 4, 10])), N, PACKETS),     # reversed: [9..6 | 5..0]
    ((ORDER.astype(np.int64), OFFSETS.astype(np.uint16)), N, PACKETS),
    ((list(range(N)), [0, 6, 10]), N, PACKETS),
    ((np.zeros(0, np.int32), np.array([0], np.int32)), 0, np.array([0], np.int32)),
    ((np.zeros(0, np.int32), np.array([0], np.int32)), 0, np.array([0, 0, 0], np.int32)),
    ((ORDER, OFFSETS), N, np.array([0, 0, 6, 6, 10, 10], np.int32)),   # empty large packets
    ((np.arange(MAX_PACKET + 1), [0, MAX_PACKET, MAX_PACKET + 1]), MAX_PACKET + 1,
     [0, MAX_PACKET + 1]),
], ids=["plain", "reversed", "other-int-dtypes", "lists", "empty", "empty-packets",
        "repeated-boundaries", "4096"])
def test_valid_results_pass(result, n, packets):
    """Valid results are returned unchanged as int32 arrays."""
    order, offsets = check_sort(NAME, result, n, packets)
    assert order.dtype == np.int32 and offsets.dtype == np.int32
    assert np.array_equal(order, np.asarray(result[0]))
    assert np.array_equal(offsets, np.asarray(result[1]))


# -- broken results -------------------------------------------------------------------------

@pytest.mark.parametrize("result", [
    None, [ORDER, OFFSETS], (ORDER,), (ORDER, OFFSETS, OFFSETS), ORDER, "order", {},
    (None, None), ("abc", OFFSETS), (ORDER, {"a": 1}),
], ids=["None", "list", "1-tuple", "3-tuple", "array", "str", "dict", "nones", "str-order",
        "dict-offsets"])
def test_wrong_return_type(result):
    rejects(result)


def test_ragged_order_is_a_contract_error():
    """A ragged nested list (not an array) is the sorter's fault, reported as such."""
    rejects(([0, 1, [2, 3], 4, 5, 6, 7, 8, 9], OFFSETS))


@pytest.mark.parametrize("result", [
    (ORDER.astype(np.float64), OFFSETS),
    (ORDER, OFFSETS.astype(np.float32)),
    (ORDER.astype(bool), OFFSETS),
    (ORDER.astype(np.complex64), OFFSETS),
    (ORDER.astype(str), OFFSETS),
    (ORDER.astype(object), OFFSETS),
], ids=["float-order", "float-offsets", "bool-order", "complex-order", "str-order",
        "object-order"])
def test_non_integer_arrays(result):
    rejects(result, match="integer")


@pytest.mark.parametrize("result", [
    (ORDER.reshape(2, 5), OFFSETS),
    (ORDER, OFFSETS.reshape(1, 4)),
    (ORDER[None, :], OFFSETS),
    (np.int32(0), OFFSETS),
], ids=["2d-order", "2d-offsets", "row-order", "0d-order"])
def test_not_one_dimensional(result):
    rejects(result, match="1-d")


@pytest.mark.parametrize("order", [ORDER[:9], np.arange(11), np.zeros(0, int)])
def test_wrong_length(order):
    rejects((order, OFFSETS))


@pytest.mark.parametrize("order", [
    [0, 1, 2, 3, 4, 5, 6, 7, 8, 8],      # repeated, 9 missing
    [0, 0, 2, 3, 4, 5, 6, 7, 8, 9],
    [0, 1, 2, 3, 4, 5, 6, 7, 8, 10],     # out of range (high)
    [-1, 1, 2, 3, 4, 5, 6, 7, 8, 9],     # out of range (negative)
    [0, 1, 2, 3, 4, 5, 6, 7, 8, 2 ** 40],
], ids=["repeat-last", "repeat-first", "too-high", "negative", "huge"])
def test_not_a_permutation(order):
    rejects((np.array(order), OFFSETS), match="permutation|range")


@pytest.mark.parametrize("offsets", [
    [1, 3, 6, 10],            # does not start at 0
    [0, 3, 6, 9],             # does not end at n
    [0, 3, 6, 11],
    [0, 3, 6],
    [],
    [10],
    [0],
    [0, 3, 2 ** 32 + 6, 10],  # wraps to 6 in int32
], ids=["start-1", "end-9", "end-11", "short", "empty", "only-n", "only-0", "int32-wrap"])
def test_offsets_range(offsets):
    rejects((ORDER, np.array(offsets, dtype=np.int64)), match="offsets")


@pytest.mark.parametrize("offsets", [[0, 3, 3, 6, 10], [0, 6, 3, 10], [0, 0, 6, 10],
                                     [0, 6, 10, 10]], ids=["repeat", "decrease", "empty-first",
                                                           "empty-last"])
def test_empty_or_decreasing_sub_packets(offsets):
    rejects((ORDER, np.array(offsets)), match="increase")


def test_empty_batch_with_an_empty_sub_packet():
    rejects((np.zeros(0, np.int32), np.array([0, 0])), n=0, packets=np.array([0, 0]))


def test_sub_packet_of_4097_rays():
    n = MAX_PACKET + 1
    rejects((np.arange(n), np.array([0, n])), n=n, packets=np.array([0, n]), match=str(n))


@pytest.mark.parametrize("order, offsets, packets", [
    (ORDER, [0, 7, 10], PACKETS),                               # offsets cross the boundary
    ([0, 1, 2, 3, 4, 7, 6, 5, 8, 9], [0, 6, 10], PACKETS),      # order swaps across it
    (ORDER, [0, 10], PACKETS),
    (ORDER, [0, 5, 10], [0, 5, 5, 6, 10]),                      # with empty large packets
    ([1, 0], [0, 2], [0, 1, 2]),
], ids=["crossing-offsets", "swapped-rays", "whole-batch", "repeated-boundaries", "two-rays"])
def test_sub_packet_mixing_large_packets(order, offsets, packets):
    rejects((np.array(order), np.array(offsets)), packets=np.array(packets),
            n=len(order), match="large packets")


# -- the framework runs the check -----------------------------------------------------------

class BrokenSorter(raysort.Sorter):
    """Returns a non-permutation (every index 0) in valid-looking packets."""

    def sort(self, rays, packets, bounds):
        return np.zeros(len(rays), np.int32), np.append(
            np.arange(0, len(rays), 64), len(rays)).astype(np.int32)


class InheritedTrustSorter(NoneSorter):
    """A third-party subclass of a built-in: inherits ``trusted = True`` but is broken."""

    def sort(self, rays, packets, bounds):
        order, offsets = super().sort(rays, packets, bounds)
        order[:] = 0
        return order, offsets


class CountingSorter(raysort.Sorter):
    """A correct untrusted sorter (identity order, one sub-packet per large packet)."""

    def sort(self, rays, packets, bounds):
        return np.arange(len(rays), dtype=np.int32), np.asarray(packets, np.int32)


@pytest.fixture
def registered():
    """Register in-process sorters; unregister them afterwards whatever happens."""
    names = []

    def add(name, cls):
        raysort.register("sorters", name, cls)
        names.append(name)
        return name

    yield add
    for name in names:
        raysort.unregister("sorters", name)
    assert not set(names) & set(raysort.available("sorters"))


@pytest.mark.parametrize("check_sorters", [True, False])
def test_pipeline_rejects_broken_sorter(registered, check_sorters):
    """render() raises PluginContractError naming the sorter, even with check_sorters=False."""
    registered("broken_test", BrokenSorter)
    assert "broken_test" in raysort.available("sorters")
    pipe = raysort.Pipeline("plane", sorter="broken_test", check_sorters=check_sorters)
    with pytest.raises(PluginContractError, match="'broken_test'") as info:
        pipe.render(8, 8, 1)
    assert info.value.name == "broken_test" and info.value.kind == "sorters"
    assert "permutation" in str(info.value)


def test_trace_rejects_broken_sorter(registered):
    """Pipeline.trace on a plain batch runs the same check."""
    registered("broken_test", BrokenSorter)
    pipe = raysort.Pipeline("plane", sorter="broken_test", check_sorters=False)
    rays = RayBatch.from_arrays(np.tile([0.0, 1.0, 0.0], (5, 1)), np.tile([0, -1.0, 0], (5, 1)))
    with pytest.raises(PluginContractError, match="'broken_test'"):
        pipe.trace(rays)


def test_third_party_subclass_of_trusted_builtin_is_checked(registered):
    """A plugin that merely subclasses a trusted built-in is third-party: still checked with
    check_sorters=False (the Pipeline docstring: "third-party sorters are always checked")."""
    assert InheritedTrustSorter.trusted      # inherited from NoneSorter
    registered("inherits_trust_test", InheritedTrustSorter)
    pipe = raysort.Pipeline("plane", sorter="inherits_trust_test", check_sorters=False)
    with pytest.raises(PluginContractError, match="'inherits_trust_test'"):
        pipe.render(8, 8, 1)


@pytest.fixture
def check_calls(monkeypatch):
    """Record the sorter names the pipeline passes to check_sort."""
    calls = []

    def spy(name, result, n, packets):
        calls.append(name)
        return check_sort(name, result, n, packets)

    monkeypatch.setattr(raysort.pipeline, "check_sort", spy)
    return calls


@pytest.mark.parametrize("sorter, check_sorters, checked", [
    ("none", True, True), ("nah", True, True), ("nah_numpy", True, True),
    ("none", False, False), ("nah", False, False),     # trusted built-ins may skip
    ("nah_numpy", False, True),                         # built-in but untrusted
])
def test_which_sorters_are_checked(check_calls, sorter, check_sorters, checked):
    """check_sorters=False skips the check only for built-ins marked trusted."""
    assert raysort.load("sorters", sorter).trusted == (sorter in ("none", "nah"))
    raysort.Pipeline("plane", sorter=sorter, check_sorters=check_sorters).render(8, 8, 1)
    assert bool(check_calls) == checked
    assert set(check_calls) <= {sorter}


def test_untrusted_valid_sorter_is_checked_and_works(registered, check_calls):
    """A correct third-party sorter is checked (check_sorters=False) and renders the same
    image as ``none``."""
    registered("counting_test", CountingSorter)
    image = raysort.Pipeline("plane", sorter="counting_test",
                             check_sorters=False).render(8, 8, 1).image
    assert check_calls and set(check_calls) == {"counting_test"}
    ref = raysort.Pipeline("plane", sorter="none").render(8, 8, 1).image
    assert image.tobytes() == ref.tobytes()
