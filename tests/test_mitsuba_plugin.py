"""The raysort-mitsuba plugin (a yardstick): found by name, hits within tolerance of
brute force, with and without its ``coherent`` hint.

Skips unless the plugin (``pip install ./plugins/raysort-mitsuba``) and Mitsuba 3 with
its LLVM back end are installed.
"""
import numpy as np
import pytest

import raysort
from raysort.errors import ConfigError
from raysort.rays import gather, scatter
from raysort.reference import brute_force

plugin = pytest.importorskip("raysort_mitsuba")


@pytest.fixture(scope="module")
def mitsuba():
    try:
        plugin._mitsuba()
    except Exception as exc:        # no libLLVM: Mitsuba's llvm variants cannot run
        pytest.skip(f"Mitsuba's {plugin.VARIANT} variant does not run here: {exc}")
    return plugin


def _trace(bvh, work, **params):
    n = len(work)
    order = np.arange(n, dtype=np.int32)
    offsets = np.append(np.arange(0, n, 64), n).astype(np.int32)
    packets = gather(work.rays, order, offsets)
    counters = raysort.create("traversals", {"type": "mitsuba", **params}).intersect(bvh, packets)
    return scatter(packets, n), counters


def test_found_by_name(mitsuba):
    info = {i.name: i for i in raysort.list_plugins("traversals", load=True)}
    assert info["mitsuba"].distribution == "raysort-mitsuba"
    assert raysort.load("traversals", "mitsuba").exact is False


def test_coherent_is_a_boolean(mitsuba):
    assert raysort.create("traversals", "mitsuba:coherent=true").coherent is True
    with pytest.raises(ConfigError, match="coherent"):
        raysort.create("traversals", "mitsuba:coherent=often")


@pytest.mark.parametrize("coherent", [False, True])
@pytest.mark.parametrize("kind", ["primary", "diffuse"])
def test_hits_match_brute_force_within_tolerance(mitsuba, sibenik, workloads, kind, coherent):
    work = workloads(sibenik, kind)
    hits, counters = _trace(sibenik.bvh(), work, coherent=coherent)
    ref = brute_force(sibenik.vertices, sibenik.faces, work.rays)
    assert not counters.available and counters.rays == len(work)
    assert np.mean((hits.prim >= 0) != (ref.prim >= 0)) < 1e-3
    both = (hits.prim >= 0) & (ref.prim >= 0)
    assert (np.abs(hits.t[both] - ref.t[both]) / ref.t[both]).max() < 1e-4
    other = both & (hits.prim != ref.prim)
    # a different primitive only where the two are at (numerically) the same distance
    assert other.mean() < 0.01
    assert (np.abs(hits.t[other] - ref.t[other]) / ref.t[other] < 1e-4).all()
