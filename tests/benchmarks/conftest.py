"""Fixtures of the pytest-benchmark suite (not part of the default test run).

Run it with::

    pytest tests/benchmarks/bench_*.py --benchmark-only

and compare saved runs with ``pytest-benchmark compare``.  Workloads are the
ray kinds of :data:`raysort.workloads.KINDS` ( camera rays, ambient-occlusion
rays, first-bounce diffuse rays, shadow rays) taken from a 256x256, 1 spp render
(65,536 camera rays), in the large packets the render makes.
"""
import pytest

import raysort
from raysort.workloads import workload

SIZE = dict(width=256, height=256, spp=1, seed=1)


@pytest.fixture(scope="session")
def scene_cache():
    cache = {}

    def get(name):
        if name not in cache:
            scene = raysort.load_scene(name)
            scene.bvh()
            cache[name] = scene
        return cache[name]

    return get


@pytest.fixture(scope="session")
def workload_cache(scene_cache):
    cache = {}

    def get(scene_name, kind):
        if (scene_name, kind) not in cache:
            cache[scene_name, kind] = workload(scene_cache(scene_name), kind, **SIZE)
        return cache[scene_name, kind]

    return get
