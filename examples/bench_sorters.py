"""Compare two sorters on your own mesh with pytest-benchmark.

Run it (``pip install pytest-benchmark`` first), save the run, and compare saved runs::

    RAYSORT_MESH=my_mesh.ply pytest examples/bench_sorters.py --benchmark-only \\
        --benchmark-save=mine
    pytest-benchmark compare --group-by=group --columns=median,iqr,rounds

Settings come from the environment:

=================  ======================================================  ==============
variable           meaning                                                 default
=================  ======================================================  ==============
RAYSORT_MESH       a mesh file trimesh reads, or a packaged scene name     a trimesh torus
RAYSORT_SORTERS    the two (or more) sorter specs, separated by ``;``      ``none;nah``
RAYSORT_SIZE       edge of the image the rays come from, in pixels         128
=================  ======================================================  ==============

Each benchmark times one ``Pipeline.trace`` (sort, gather, traverse, scatter) of one ray
kind, as a render makes it (``raysort.workloads``): camera rays, ambient-occlusion rays and
first-bounce diffuse rays.  Benchmarks are grouped by ray kind, so ``compare`` puts the
sorters side by side; ``extra_info`` holds the traversal's work per ray.
"""
import os

import numpy as np
import pytest
import trimesh

import raysort
from raysort.workloads import workload

SORTERS = os.environ.get("RAYSORT_SORTERS", "none;nah").split(";")
SIZE = int(os.environ.get("RAYSORT_SIZE", "128"))
KINDS = ["primary", "ao:samples=4", "diffuse"]


@pytest.fixture(scope="module")
def scene():
    mesh = os.environ.get("RAYSORT_MESH")
    if mesh:
        return raysort.load_scene(mesh)                   # camera framing the mesh
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.4)
    return raysort.Scene.from_mesh(torus.vertices, torus.faces, name="torus")


@pytest.fixture(scope="module")
def workloads(scene):
    cache = {}

    def get(kind):
        if kind not in cache:
            cache[kind] = workload(scene, kind, width=SIZE, height=SIZE)
        return cache[kind]

    return get


@pytest.mark.parametrize("sorter", SORTERS)
@pytest.mark.parametrize("kind", KINDS)
def test_trace(benchmark, scene, workloads, kind, sorter):
    work = workloads(kind)
    pipe = raysort.Pipeline(scene, sorter=sorter, traversal="ranged")
    reference = raysort.Pipeline(scene, sorter="none", traversal="single")
    result = benchmark.pedantic(pipe.trace, args=(work.rays, work.packets),
                                kwargs={"any_hit": work.any_hit}, rounds=5, warmup_rounds=1)
    benchmark.group = f"{scene.name} {kind}"
    benchmark.extra_info.update(rays=len(work), **result[1].per_ray())
    # a sorter may not change a single answer
    expected, _ = reference.trace(work.rays, work.packets, any_hit=work.any_hit)
    got = result[0]
    assert np.array_equal(got if work.any_hit else got.prim,
                          expected if work.any_hit else expected.prim)
