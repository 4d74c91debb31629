"""``raysort.contract.check_sort`` and its use by the pipeline.

Every broken result must raise :class:`raysort.PluginContractError` naming
the sorter (message, ``.name``, ``.kind``); valid results pass and come back
as int32.  The pipeline checks every untrusted sorter even with
``check_plugins=False``.
"""
import re

import numpy as np
import pytest

import raysort
from raysort import contract
from raysort import pipeline as pipeline_module
from raysort.contract import check_sort
from raysort.errors import PluginContractError, RaysortError
from raysort.rays import MAX_PACKET, RayBatch
from raysort.sorters.none import NoneSorter
from raysort.stats import Counters
from raysort.traversals.stream import StreamTraversal

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


def _contract_holds(order, offsets, packets, n):
    """The sort contract rule by rule in NumPy, independent of the check kernels."""
    sizes = np.diff(offsets)
    if len(offsets) < 1 or offsets[0] != 0 or offsets[-1] != n or np.any(sizes <= 0) \
            or np.any(sizes > MAX_PACKET):
        return False
    if not np.array_equal(np.sort(order), np.arange(n)):
        return False
    packet_of = np.searchsorted(packets, order, side="right") - 1
    return all(np.all(packet_of[a:b] == packet_of[a]) for a, b in zip(offsets[:-1], offsets[1:]))


def _random_packets(rng, n, most):
    """Large-packet boundaries of ``n`` rays: 0, fewer than ``most`` inner ones, n."""
    inner = np.sort(rng.choice(np.arange(1, n), size=min(n - 1, int(rng.integers(0, most))),
                               replace=False)) if n > 1 else []
    return np.concatenate([[0], inner, [n]]).astype(np.int32)


def _random_result(rng, n, packets):
    """A valid order: each large packet's rays shuffled and cut into sub-packets, the
    sub-packets of all packets in a random order (the contract allows them interleaved)."""
    pieces = []
    for a, b in zip(packets[:-1], packets[1:]):
        rays = rng.permutation(np.arange(a, b, dtype=np.int32))
        cuts = np.sort(rng.choice(np.arange(1, max(b - a, 1)), size=min(b - a - 1, rng.integers(
            0, 6)), replace=False)) if b - a > 1 else []
        pieces += [p for p in np.split(rays, cuts) if len(p)]
    pieces = [pieces[i] for i in rng.permutation(len(pieces))] if rng.random() < 0.5 else pieces
    order = np.concatenate(pieces) if pieces else np.zeros(0, np.int32)
    return order.astype(np.int32), np.cumsum([0] + [len(p) for p in pieces]).astype(np.int32)


def test_check_agrees_with_the_contract_on_random_results(each_isa):
    """Random valid results (sub-packets of a large packet in a row, or interleaved with
    other packets') pass, and each of their mutations passes exactly when the NumPy
    statement of the contract holds: a ray moved into another sub-packet, a ray repeated,
    an offset moved, two sub-packets joined.  The check reads a large packet's run of
    sub-packets in one loop; the mutations break runs in every place."""
    rng = np.random.default_rng(7)
    verdicts = set()
    for _ in range(400):
        n = int(rng.integers(1, 200))
        packets = _random_packets(rng, n, 5)
        order, offsets = _random_result(rng, n, packets)
        check_sort(NAME, (order, offsets), n, packets)
        mutation = rng.integers(4)
        order, offsets = order.copy(), offsets.copy()
        i, j = rng.integers(n, size=2)
        if mutation == 0:
            order[i], order[j] = order[j], order[i]
        elif mutation == 1:
            order[i] = order[j]
        elif mutation == 2 and len(offsets) > 2:
            k = rng.integers(1, len(offsets) - 1)
            offsets[k] += rng.choice([-1, 1])
        elif len(offsets) > 2:
            offsets = np.delete(offsets, rng.integers(1, len(offsets) - 1))
        holds = _contract_holds(order, offsets, packets, n)
        verdicts.add(holds)
        if holds:
            check_sort(NAME, (order, offsets), n, packets)
        else:
            rejects((order, offsets), n=n, packets=packets)
    assert verdicts == {True, False}


def test_identity_check_agrees_with_the_contract(each_isa):
    """The identity order's check (``identity=True``: the order is not read, each
    large-packet boundary must start a sub-packet) passes exactly when the NumPy
    statement of the contract holds for ``arange(n)``, and finds the same fault, at the
    same place, as the check that reads the order."""
    from raysort import isa
    from raysort.orders import identity_order
    kernel = isa.module("_contract").sort_result
    rng = np.random.default_rng(11)
    verdicts = set()
    for _ in range(600):
        n = int(rng.integers(1, 300))
        packets = _random_packets(rng, n, 6)
        if rng.random() < 0.2 and len(packets) > 2:     # an empty large packet
            packets = np.insert(packets, 1, packets[1])
        if rng.random() < 0.5:      # cut at every boundary, and between them
            cuts = np.union1d(packets, rng.choice(np.arange(n + 1), size=3))
        else:                       # anywhere
            cuts = np.union1d([0, n], rng.choice(np.arange(n + 1), size=int(rng.integers(0, 8))))
        offsets = cuts.astype(np.int32)
        if rng.random() < 0.1 and len(offsets) > 2:     # a sub-packet of no rays
            offsets = np.insert(offsets, 1, offsets[1])
        max_packet = int(rng.choice([MAX_PACKET, 1 + int(rng.integers(n))]))
        order = identity_order(n)
        holds = (_contract_holds(np.arange(n), offsets, packets, n)
                 and np.diff(offsets).max() <= max_packet)
        verdicts.add(bool(holds))
        got = kernel(order, offsets, packets, n, max_packet, True)
        assert (got[0] == 0) == holds, (n, packets, offsets, max_packet)
        assert got == kernel(order, offsets, packets, n, max_packet, False)
    assert verdicts == {True, False}


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


@pytest.mark.parametrize("check_plugins", [True, False])
def test_pipeline_rejects_broken_sorter(registered, check_plugins):
    """render() raises PluginContractError naming the sorter, even with check_plugins=False."""
    registered("broken_test", BrokenSorter)
    assert "broken_test" in raysort.available("sorters")
    pipe = raysort.Pipeline("plane", sorter="broken_test", check_plugins=check_plugins)
    with pytest.raises(PluginContractError, match="'broken_test'") as info:
        pipe.render(8, 8, 1)
    assert info.value.name == "broken_test" and info.value.kind == "sorters"
    assert "permutation" in str(info.value)


@pytest.mark.parametrize("any_hit", [False, True])
def test_trace_rejects_broken_sorter(registered, any_hit):
    """Pipeline.trace on a plain batch runs the same check, for either query."""
    registered("broken_test", BrokenSorter)
    pipe = raysort.Pipeline("plane", sorter="broken_test", check_plugins=False)
    rays = RayBatch.from_arrays(np.tile([0.0, 1.0, 0.0], (5, 1)), np.tile([0, -1.0, 0], (5, 1)))
    with pytest.raises(PluginContractError, match="'broken_test'.*permutation"):
        pipe.trace(rays, any_hit=any_hit)


def test_third_party_subclass_of_trusted_builtin_is_checked(registered):
    """A plugin that merely subclasses a trusted built-in is third-party: still checked with
    check_plugins=False (the Pipeline docstring: "third-party sorters are always checked")."""
    assert InheritedTrustSorter.trusted      # inherited from NoneSorter
    registered("inherits_trust_test", InheritedTrustSorter)
    pipe = raysort.Pipeline("plane", sorter="inherits_trust_test", check_plugins=False)
    with pytest.raises(PluginContractError, match="'inherits_trust_test'"):
        pipe.render(8, 8, 1)


# The check the pipeline runs on each plugin's result, which trusted built-ins skip with
# check_plugins=False (the rest of a sorter's checks runs inside the gather, and a
# traversal's in the scatter: test_fused_checks_catch_builtin_plugins).
CHECKS = {"sorters": "sort_arrays", "traversals": "scatter_checked",
          "shaders": "check_bounce", "generators": "check_generated"}


@pytest.fixture
def check_calls(monkeypatch):
    """Record (check, plugin name) for each plugin check the pipeline runs (the hits
    check, which gets no plugin, as the pipeline's traversal)."""
    calls = []
    for check in ("sort_arrays", "check_bounce", "check_generated", "check_sort",
                  "check_hits"):
        real = getattr(contract, check)

        def spy(plugin, *args, _real=real, _check=check, **kwargs):
            calls.append((_check, plugin if isinstance(plugin, str) else plugin.name))
            return _real(plugin, *args, **kwargs)

        monkeypatch.setattr(contract, check, spy)
    real_scatter = pipeline_module.scatter_checked

    def scatter_spy(*args, **options):
        if options["check_hits"]:
            calls.append(("scatter_checked", "<the pipeline's traversal>"))
        return real_scatter(*args, **options)

    monkeypatch.setattr(pipeline_module, "scatter_checked", scatter_spy)
    return calls


@pytest.mark.parametrize("sorter, check_plugins, checked", [
    ("none", True, True), ("nah", True, True), ("nah_numpy", True, True),
    ("none", False, False), ("nah", False, False),     # trusted built-ins may skip
    ("nah_numpy", False, True),                         # built-in but untrusted
])
def test_which_sorters_are_checked(check_calls, sorter, check_plugins, checked):
    """check_plugins=False skips the check only for built-ins marked trusted."""
    assert raysort.load("sorters", sorter).trusted == (sorter in ("none", "nah"))
    raysort.Pipeline("plane", sorter=sorter, check_plugins=check_plugins).render(8, 8, 1)
    sorts = [name for check, name in check_calls if check == "sort_arrays"]
    assert bool(sorts) == checked
    assert set(sorts) <= {sorter}


@pytest.mark.parametrize("check_plugins", [True, False])
def test_every_kind_is_checked_unless_trusted(check_calls, check_plugins):
    """With check_plugins=True every plugin result is checked; with False none of the
    trusted built-ins (pinhole, nah, wide8, lambert) is; check_sort and check_hits run
    only to name a fault."""
    pipe = raysort.Pipeline("plane", check_plugins=check_plugins)
    for kind in CHECKS:
        plugin = getattr(pipe, kind[:-1])
        assert vars(type(plugin)).get("trusted") is True, plugin
    pipe.render(8, 8, 1)
    expected = {(CHECKS[kind], getattr(pipe, kind[:-1]).name) for kind in CHECKS
                if kind != "traversals"}
    if not pipe._reads_batch():     # stream checks each hit itself as it writes it
        expected.add(("scatter_checked", "<the pipeline's traversal>"))
    assert set(check_calls) == (expected if check_plugins else set())


def _write_prim(value):
    def intersect(self, bvh, packets, any_hit=False):
        packets.prim[packets.starts[0]] = value
        return Counters()
    return intersect


def _move_first_sub_packet(self, bvh, packets, any_hit=False):
    packets.starts[0] = 1_000_000
    return Counters()


def _one_sub_packet(self, rays, packets, bounds):
    return np.arange(len(rays), dtype=np.int32), np.array([0, len(rays)], np.int32)


def _identity_one_sub_packet(self, rays, packets, bounds):
    return raysort.sdk.identity_order(len(rays)), np.array([0, len(rays)], np.int32)


def _repeat_first_ray(self, rays, packets, bounds):
    order = np.arange(len(rays), dtype=np.int32)
    order[1:2] = 0
    return order, np.asarray(packets, np.int32)         # one sub-packet per large packet


@pytest.mark.parametrize("kind, method, broken, match", [
    ("sorters", "sort", _repeat_first_ray, "permutation"),
    ("sorters", "sort", _one_sub_packet, "mixes rays of different large packets"),
    ("traversals", "intersect", _write_prim(50_000_000), "prim = 50000000"),
    ("traversals", "intersect", _write_prim(-7), "prim = -7"),
    ("traversals", "intersect", _move_first_sub_packet, "changed packets.starts"),
])
def test_fused_checks_catch_builtin_plugins(monkeypatch, kind, method, broken, match):
    """A built-in sorter or traversal gone wrong is caught by the checks inside the gather
    and the scatter, and named (``wide8``: a traversal of gathered packets)."""
    pipe = raysort.Pipeline("plane", traversal="wide8")
    plugin = getattr(pipe, kind[:-1])
    monkeypatch.setattr(type(plugin), method, broken)
    with pytest.raises(PluginContractError, match=match) as info:
        pipe.render(8, 8, 2)            # two sample passes: two large packets per batch
    assert (info.value.kind, info.value.name) == (kind, plugin.name)


def _break_first_hit(value):
    real = StreamTraversal._intersect_batch

    def intersect_batch(self, bvh, rays, order, offsets, k0, k1, any_hit, out):
        counters, bad_ray, bad_hit, order_ok = real(self, bvh, rays, order, offsets, k0, k1,
                                                    any_hit, out)
        out[1].view(np.int32)[order[offsets[k0]]] = value
        return counters, bad_ray, order[offsets[k0]], order_ok
    return intersect_batch


@pytest.mark.parametrize("sorter, broken, match", [
    ("none", _repeat_first_ray, "permutation"),
    ("nah", _repeat_first_ray, "permutation"),
    ("none", _one_sub_packet, "mixes rays of different large packets"),
    ("none", _identity_one_sub_packet, "mixes rays of different large packets"),
])
def test_stream_reading_the_batch_checks_the_sorter(monkeypatch, sorter, broken, match):
    """Without packets (``stream`` reads the batch in the sorter's order) a built-in
    sorter gone wrong is still caught before the trace, and named."""
    pipe = raysort.Pipeline("plane", sorter=sorter, traversal="stream")
    assert pipe._reads_batch()
    monkeypatch.setattr(type(pipe.sorter), "sort", broken)
    with pytest.raises(PluginContractError, match=match) as info:
        pipe.render(8, 8, 2)
    assert (info.value.kind, info.value.name) == ("sorters", sorter)


def _offsets_beyond(self, rays, packets, bounds):
    return np.arange(len(rays), dtype=np.int32), np.array([0, len(rays) + 64], np.int32)


def test_stream_reading_the_batch_refuses_a_trusted_sorters_bad_offsets(monkeypatch):
    """With check_plugins=False a trusted sorter's result is not checked, but offsets
    beyond the batch still stop ``stream`` before it reads there, and the sorter is named."""
    pipe = raysort.Pipeline("plane", traversal="stream", check_plugins=False)
    monkeypatch.setattr(NoneSorter, "sort", _offsets_beyond)
    with pytest.raises(PluginContractError) as info:
        pipe.render(8, 8, 1)
    assert (info.value.kind, info.value.name) == ("sorters", "none")


@pytest.mark.parametrize("check_plugins", [True, False])
def test_stream_reading_the_batch_reports_a_hit_it_flags(monkeypatch, check_plugins):
    """A hit that ``stream``'s kernel flags as it writes it (the rules of check_hits, on
    every hit whatever check_plugins says) is reported with the ray and the traversal."""
    pipe = raysort.Pipeline("plane", traversal="stream", check_plugins=check_plugins)
    monkeypatch.setattr(StreamTraversal, "_intersect_batch", _break_first_hit(50_000_000))
    with pytest.raises(PluginContractError, match="prim = 50000000") as info:
        pipe.render(8, 8, 1)
    assert (info.value.kind, info.value.name) == ("traversals", "stream")


def test_untrusted_valid_sorter_is_checked_and_works(registered, check_calls):
    """A correct third-party sorter is checked (check_plugins=False) and renders the same
    image as ``none``."""
    registered("counting_test", CountingSorter)
    image = raysort.Pipeline("plane", sorter="counting_test",
                             check_plugins=False).render(8, 8, 1).image
    assert ("sort_arrays", "counting_test") in check_calls
    assert {name for check, name in check_calls if check == "sort_arrays"} == {"counting_test"}
    assert not {check for check, name in check_calls} & {"check_sort", "check_hits"}
    ref = raysort.Pipeline("plane", sorter="none").render(8, 8, 1).image
    assert image.tobytes() == ref.tobytes()


# -- caller arguments -----------------------------------------------------------------------

@pytest.mark.parametrize("packets, n", [
    ([0, 10], 10), ([0, 0, 4, 4, 10, 10], 10), (np.array([0, 3, 10], np.uint8), 10),
    ([0], 0), ([0, 0], 0), (range(0, 11, 5), 10),
])
def test_valid_packets(packets, n):
    out = contract.check_packets(packets, n)
    assert out.dtype == np.int32 and out.tolist() == list(packets)


@pytest.mark.parametrize("packets, n, match", [
    ([], 1000, "start at 0 and end at 1000"),
    ([0, 500], 1000, "end at 1000, the number of rays; got \\[0, 500\\]"),
    ([0, 100000], 1024, "end at 1024"),
    ([5, 1000], 1000, "start at 0"),
    ([0, 600, 200, 1000], 1000, "must not decrease, got 600 then 200"),
    ([0.0, 10.0], 10, "integer"),
    ([[0, 10]], 10, "1-d"),
    (["0", "10"], 10, "integer"),
    ([0, 2**32 + 5, 10], 10, "must not decrease"),
    ([True, False], 1, "integer"),
    (None, 10, "integer"),
], ids=["empty", "short", "past-the-end", "not-from-0", "decreasing", "floats", "2-d",
        "strings", "int32-wrap", "bools", "None"])
def test_bad_packets_name_the_argument(packets, n, match):
    """A caller's bad packets: ConfigError naming 'packets' (not the sorter)."""
    with pytest.raises(raysort.ConfigError, match=match) as info:
        contract.check_packets(packets, n)
    assert str(info.value).startswith("packets ")


def test_too_many_rays_for_int32_packets():
    with pytest.raises(raysort.ConfigError, match="int32"):
        contract.check_packets([0, 2**31], 2**31)


@pytest.mark.parametrize("rays", [None, np.zeros((8, 4), np.float32), [[0, 0, 0]], "rays"])
def test_trace_needs_a_ray_batch(rays):
    with pytest.raises(raysort.ConfigError, match="RayBatch.from_arrays"):
        contract.check_ray_batch(rays)


# -- traversal results ----------------------------------------------------------------------

def plane_trace(traversal="single", any_hit=False, n=40):
    """Gather n rays at the plane scene (every other one pointing away, a few invalid), run
    ``traversal``; returns (packets, before, order, offsets, n_prim)."""
    scene = raysort.load_scene("plane")
    rng = np.random.default_rng(5)
    down = np.where(np.arange(n)[:, None] % 2 == 0, [0, -1.0, 0], [0, 1.0, 0])
    rays = RayBatch.from_arrays(rng.uniform(-3, 3, (n, 3)) + [0, 4, 0],
                                down + rng.normal(0, 0.1, (n, 3)))
    rays.tmin[::7] = np.inf                      # some invalid rays
    order = rng.permutation(n).astype(np.int32)
    offsets = np.array([0, 3, 17, 18, n], np.int32)   # padding after 3, 17 and 18 rays
    packets = raysort.gather(rays, order, offsets)
    before = contract.before_traversal(packets)
    raysort.create("traversals", traversal).intersect(scene.bvh(), packets, any_hit)
    return packets, before, order, offsets, len(scene.faces)


def hits_error(packets, before, order, offsets, n_prim, any_hit=False):
    with pytest.raises(PluginContractError) as info:
        contract.check_hits("my_traversal", packets, before, order, offsets, n_prim, any_hit)
    assert info.value.kind == "traversals" and info.value.name == "my_traversal"
    return str(info.value)


@pytest.mark.parametrize("any_hit", [False, True])
def test_valid_hits_pass(any_hit):
    args = plane_trace(any_hit=any_hit)
    assert (args[0].prim >= 0).any() and (args[0].prim < 0).any()
    contract.check_hits("my_traversal", *args, any_hit)


def test_an_any_hit_query_may_mark_hits_like_embree():
    """prim = 0 and t = -inf for every occluded ray (plugins/raysort-embree) is valid."""
    packets, before, order, offsets, n_prim = plane_trace(any_hit=True)
    hit = packets.prim >= 0
    packets.prim[hit], packets.t[hit] = 0, -np.inf
    contract.check_hits("my_traversal", packets, before, order, offsets, n_prim, True)


@pytest.mark.parametrize("corrupt, match", [
    (lambda p, hit: p.prim.__setitem__(hit, 2), "prim = 2 is neither -1"),
    (lambda p, hit: p.prim.__setitem__(hit, -2), "prim = -2"),
    (lambda p, hit: p.t.__setitem__(hit, np.nan), "outside the ray's interval"),
    (lambda p, hit: p.t.__setitem__(hit, -1.0), "outside the ray's interval"),
    (lambda p, hit: p.t.__setitem__(hit, np.inf), "outside the ray's interval"),
    (lambda p, hit: p.v.__setitem__(hit, np.inf), "must be finite"),
    (lambda p, hit: p.prim.__setitem__(3, 0), "padding lane 3"),
    (lambda p, hit: p.index.__setitem__(3, 5), "padding lane 3"),
    (lambda p, hit: p.index.__setitem__(hit[0], 10**6), "was changed to 1000000"),
    (lambda p, hit: setattr(p, "u", p.u.copy()), "replaced packets.u"),
    (lambda p, hit: setattr(p.prim, "shape", (2, -1)), "reshaped or retyped"),
], ids=["prim-high", "prim-negative", "t-nan", "t-behind", "t-infinite", "v-inf",
        "padding-prim", "padding-index", "index", "replaced", "reshaped"])
def test_broken_hits(corrupt, match):
    packets, before, order, offsets, n_prim = plane_trace()
    hit = np.flatnonzero(packets.prim >= 0)
    corrupt(packets, hit)
    assert re.search(match, hits_error(packets, before, order, offsets, n_prim)), match


def test_a_hit_on_an_invalid_ray_is_broken():
    """An invalid ray (tmin = inf here) has an empty interval: no t can be a hit."""
    packets, before, order, offsets, n_prim = plane_trace()
    lane = np.flatnonzero((packets.index >= 0) & (packets.tmin == np.inf))[0]
    packets.prim[lane], packets.t[lane] = 0, 1.0
    assert "outside the ray's interval (inf" in hits_error(packets, before, order, offsets,
                                                           n_prim)


@pytest.mark.parametrize("counters, match", [
    (None, "must return raysort.stats.Counters"),
    (raysort.Counters(box1=-1), "box1 must be a whole number >= 0, got -1"),
    (raysort.Counters(tri4=1.5), "tri4"),
    (raysort.Counters(rays=True), "rays"),
    (raysort.Counters(available=1), "available"),
    (raysort.Counters(stream_level_rays=[4, 2]), "stream_level_rays must be a tuple"),
    (raysort.Counters(stream_level_rays=(4, -2)), r"stream_level_rays\[1\] must be a whole"),
    (raysort.Counters(stream_level_rays=(4, 2.0)), r"stream_level_rays\[1\]"),
])
def test_broken_counters(counters, match):
    with pytest.raises(PluginContractError, match=match):
        contract.check_counters("my_traversal", counters)


# -- generator and shader results -----------------------------------------------------------

def test_generated_rays():
    rays = RayBatch.from_arrays(np.zeros((6, 3)), np.tile([0, 0, 1.0], (6, 1)))
    assert contract.check_generated("my_generator", rays, 6) is rays
    rays.origins[1, 4] = np.nan
    with pytest.raises(PluginContractError, match="ray 4 .* not finite, yet not marked"):
        contract.check_generated("my_generator", rays, 6)
    rays.tmin[4], rays.tmax[4] = 1.0, 1.0            # marked invalid: legal
    contract.check_generated("my_generator", rays, 6)
    rays.tmin[2] = -0.5
    with pytest.raises(PluginContractError, match="ray 2 has tmin = -0.5"):
        contract.check_generated("my_generator", rays, 6)
    with pytest.raises(PluginContractError, match="must return 7 rays"):
        contract.check_generated("my_generator", RayBatch(6), 7)


def bounce(n_next=4, *, parent=None, shadow=None):
    rays = RayBatch.from_arrays(np.zeros((n_next, 3)), np.tile([0, 0, 1.0], (n_next, 1)))
    parent = np.arange(n_next, dtype=np.int32) if parent is None else parent
    return raysort.Bounce(rays, parent, np.ones((3, n_next), np.float32), shadow)


def shadow(k=3, *, slot=None, parent=None, contribution=None):
    rays = RayBatch.from_arrays(np.zeros((k, 3)), np.tile([0, 1.0, 0], (k, 1)))
    return raysort.ShadowRays(rays, np.arange(k) if parent is None else parent,
                              np.zeros(k, int) if slot is None else slot,
                              np.ones((3, k)) if contribution is None else contribution)


def test_valid_bounce_comes_back_with_pipeline_types():
    out = contract.check_bounce("my_shader", bounce(shadow=shadow(slot=[0, 7, 2])), 6, 8,
                                np.zeros((8, 3)))
    assert out.parent.dtype == np.int32 and out.throughput.dtype == np.float32
    assert out.shadow.slot.dtype == np.int32 and out.shadow.contribution.dtype == np.float32


@pytest.mark.parametrize("result, match", [
    (None, "must return raysort.paths.Bounce"),
    (bounce(parent=np.array([0, 2, 1, 3])), "Bounce.parent must ascend, got 2 then 1"),
    (bounce(parent=np.array([0, 1, 2, 6])), r"Bounce.parent\[3\] = 6 is out of range 0..5"),
    (bounce(parent=np.array([-1, 1, 2, 3])), "out of range"),
    (bounce(parent=np.array([0, 1, 2])), "3 entries, expected 4"),
    (bounce(parent=np.arange(4.0)), "integer"),
    (bounce(shadow=shadow(slot=[0, 8, 1])), r"ShadowRays.slot\[1\] = 8 is out of range 0..7"),
    (bounce(shadow=shadow(parent=[2, 1, 0])), "ShadowRays.parent must ascend"),
    (bounce(shadow=shadow(contribution=np.ones((3, 2)))), "contribution must be a float array"),
    (bounce(shadow=shadow(contribution=np.full((3, 3), np.nan))), "must be finite"),
], ids=["None", "descending", "parent-high", "parent-negative", "parent-short",
        "parent-float", "slot", "shadow-parent", "contribution-shape", "contribution-nan"])
def test_broken_bounce(result, match):
    with pytest.raises(PluginContractError, match=match) as info:
        contract.check_bounce("my_shader", result, 6, 8, np.zeros((8, 3)))
    assert info.value.kind == "shaders" and "'my_shader'" in str(info.value)


def test_non_finite_radiance_is_the_shaders_fault():
    radiance = np.zeros((8, 3))
    radiance[5, 2] = np.inf
    with pytest.raises(PluginContractError, match=r"radiance\[5, 2\] is inf"):
        contract.check_bounce("my_shader", bounce(), 6, 8, radiance)


# -- naming the plugin ----------------------------------------------------------------------

def test_a_raising_plugin_is_named_with_its_distribution(registered):
    """call_plugin turns any exception into a PluginContractError naming the plugin and
    where it comes from; the original exception is its cause."""
    class Exploding(raysort.Sorter):
        def sort(self, rays, packets, bounds):
            return 1 / 0

    registered("exploding_test", Exploding)
    pipe = raysort.Pipeline("plane", sorter="exploding_test")
    with pytest.raises(PluginContractError) as info:
        pipe.render(8, 8, 1)
    assert str(info.value) == ("sorter 'exploding_test' (registered in process) failed: sort() "
                               "raised ZeroDivisionError: division by zero")
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    assert info.value.distribution == "<in-process>"


def test_an_installed_plugin_is_named_with_its_distribution():
    error = contract.plugin_error("sorters", raysort.create("sorters", "nah"), "test")
    assert str(error) == (f"sorter 'nah' (from distribution 'raysort' {raysort.__version__}) "
                          f"broke its contract: test")
    assert error.distribution == "raysort"
