"""Shared fixtures: packaged scenes, standard ray workloads, plugin names.

Tests run against the installed package (``pip install .[test]``); the
repository root is not put on sys.path.
"""
import numpy as np
import pytest

import raysort
from raysort import isa
from raysort.workloads import workload


@pytest.fixture(scope="session")
def sibenik():
    return raysort.load_scene("sibenik")


@pytest.fixture(scope="session")
def sponza():
    return raysort.load_scene("sponza")


@pytest.fixture(scope="session", params=["sibenik", "sponza"])
def real_scene(request):
    """Each real benchmark mesh in turn."""
    return request.getfixturevalue(request.param)


@pytest.fixture(scope="session")
def workloads():
    """``workloads(scene, kind)``: cached small primary/diffuse workloads (64x48, 1 spp)."""
    cache = {}

    def get(scene, kind):
        key = (scene.name, kind)
        if key not in cache:
            cache[key] = workload(scene, kind, width=64, height=48, spp=1, seed=7)
        return cache[key]

    return get


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(params=isa.ISAS)
def each_isa(request):
    """Switch every kernel to one ISA for the test (skipped where it cannot run)."""
    name = request.param
    if name not in isa.compiled():
        pytest.skip(f"ISA {name} is not compiled into this installation")
    if name not in isa.supported():
        pytest.skip(f"this CPU cannot run ISA {name}")
    previous = isa.use(name)
    yield name
    isa.use(previous)
