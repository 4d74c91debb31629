"""Property-based fuzzing of rays in and hits out: ``RayBatch.from_arrays`` and ``trace``.

Whatever the arrays and arguments (NaN, +-inf, zero, subnormal and huge values,
mismatched shapes, junk, random packets, tmin/tmax, any_hit, threads), the
result is either exactly brute force's (``raysort.reference.brute_force``) or
a :class:`raysort.RaysortError`, and the error is raised exactly when an input
breaks the documented rules.
"""
import numbers

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import raysort
from raysort.reference import brute_force

from _helpers import assert_same_hits
from strategies import FLOATS, JUNK, float_arrays, interval, ray_arrays

SCENE = raysort.load_scene("cornell")
EXACT = [t for t in raysort.available("traversals") if raysort.load("traversals", t).exact]
SORTERS = raysort.available("sorters")
_pipes = {}


def pipeline(sorter, traversal):
    if (sorter, traversal) not in _pipes:
        _pipes[sorter, traversal] = raysort.Pipeline(SCENE, sorter=sorter, traversal=traversal,
                                                     tile=4)
    return _pipes[sorter, traversal]


def assert_brute_force(pipe, rays, **kwargs):
    any_hit = kwargs.get("any_hit", False)
    out, counters = pipe.trace(rays, **kwargs)
    ref = brute_force(SCENE.vertices, SCENE.faces, rays, any_hit=any_hit)
    if any_hit:
        assert np.array_equal(out, ref)
    else:
        assert_same_hits(out, ref, f"{pipe.sorter.name} + {pipe.traversal.name}")
    assert isinstance(counters, raysort.Counters)


@given(arrays=ray_arrays(), data=st.data(), sorter=st.sampled_from(SORTERS),
       traversal=st.sampled_from(EXACT))
def test_from_arrays_then_trace(arrays, data, sorter, traversal):
    """from_arrays makes a batch holding the float32 values (or raises ConfigError, exactly
    for junk and mismatched shapes), and tracing it gives brute force's hits."""
    origins, directions = arrays
    n = origins.shape[0] if isinstance(origins, np.ndarray) and origins.ndim else 0
    tmin, tmax = data.draw(interval(n)), data.draw(interval(n))
    valid = (isinstance(origins, np.ndarray) and isinstance(directions, np.ndarray)
             and origins.ndim == 2 and origins.shape[1] == 3
             and directions.shape == origins.shape
             and all(isinstance(v, float) or (isinstance(v, np.ndarray) and v.shape == (n,))
                     for v in (tmin, tmax)))
    try:
        rays = raysort.RayBatch.from_arrays(origins, directions, tmin, tmax)
    except raysort.ConfigError:
        assert not valid
        return
    assert valid
    with np.errstate(over="ignore"):
        for got, given_ in ((rays.origins, origins.T), (rays.directions, directions.T),
                            (rays.tmin, np.broadcast_to(tmin, n)),
                            (rays.tmax, np.broadcast_to(tmax, n))):
            assert np.array_equal(got, np.asarray(given_, np.float32), equal_nan=True)
    assert_brute_force(pipeline(sorter, traversal), rays)


def valid_packets(packets, n):
    """The documented rule, written out independently of raysort.contract."""
    if not isinstance(packets, list) or not packets:
        return False
    if not all(isinstance(p, numbers.Integral) and not isinstance(p, bool) for p in packets):
        return False
    return packets[0] == 0 and packets[-1] == n and all(
        a <= b for a, b in zip(packets, packets[1:]))


def packet_lists(n):
    cuts = st.lists(st.integers(0, n), max_size=6).map(lambda c: [0, *sorted(c), n])
    return st.one_of(st.none(), cuts, cuts, st.lists(st.integers(-3, n + 3), max_size=6),
                     st.lists(FLOATS, max_size=3), JUNK)


@given(data=st.data(), n=st.integers(0, 300), sorter=st.sampled_from(SORTERS),
       traversal=st.sampled_from(EXACT),
       any_hit=st.one_of(st.booleans(), st.booleans(), JUNK),
       threads=st.one_of(st.none(), st.integers(-1, 3), JUNK))
def test_trace_arguments(data, n, sorter, traversal, any_hit, threads):
    """Random packets, intervals, any_hit and threads: brute force's answer, or a
    ConfigError exactly when an argument breaks its rule."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    origins = rng.uniform(-0.5, 1.5, (n, 3))
    directions = rng.normal(size=(n, 3))
    tmin = data.draw(st.one_of(FLOATS, float_arrays((n,))))
    tmax = data.draw(st.one_of(FLOATS, float_arrays((n,))))
    rays = raysort.RayBatch.from_arrays(origins, directions, tmin, tmax)
    packets = data.draw(packet_lists(n))
    valid = ((packets is None or valid_packets(packets, n)) and isinstance(any_hit, bool)
             and (threads is None or (isinstance(threads, int) and not isinstance(threads, bool)
                                      and threads >= 1)))
    pipe = pipeline(sorter, traversal)
    try:
        assert_brute_force(pipe, rays, packets=packets, any_hit=any_hit, threads=threads)
    except raysort.ConfigError:
        assert not valid
        return
    assert valid


@pytest.mark.parametrize("rays", [None, np.zeros((5, 3)), "rays", [[0, 0, 0]]])
def test_trace_needs_a_batch(rays):
    with pytest.raises(raysort.ConfigError, match="RayBatch"):
        pipeline("nah", "wide").trace(rays)
