"""The built-in shaders' own inputs (``_shading.pxd``'s ``checked_hits``): a shader called
from a script with hits, paths or an accumulator that do not fit the scene or each other
raises a ValueError naming the shader and the argument, before its kernel reads or
writes anything, instead of reading or writing outside its arrays."""
import numpy as np
import pytest

import raysort
from raysort.paths import Paths
from raysort.workloads import workload

SHADERS = ["lambert", "ao"]


@pytest.fixture(scope="module")
def cornell():
    scene = raysort.load_scene("cornell")
    rays = workload(scene, "primary", width=16, height=16, seed=2).rays
    hits, _ = raysort.Pipeline(scene, sorter="none", traversal="single").trace(rays)
    assert (hits.prim >= 0).any()
    return scene, rays, hits


def hostile(case, scene, rays, hits):
    """(hits, paths, radiance) of the batch, broken as ``case`` says."""
    n = len(rays)
    bad_hits = raysort.Hits(n)
    bad_hits.t[:], bad_hits.prim[:] = hits.t, hits.prim
    paths = Paths(np.arange(n), np.zeros(n), np.arange(n))
    radiance = np.zeros((n, 3))
    if case == "prim beyond the faces":
        bad_hits.prim[n // 2] = len(scene.faces)
    elif case == "prim far beyond":
        bad_hits.prim[:] = 2_000_000_000
    elif case == "prim below -1":
        bad_hits.prim[1] = -5
    elif case == "slot beyond the radiance":
        paths.slot[-1] = n
    elif case == "negative slot":
        paths.slot[3] = -1
    elif case == "short hits":
        bad_hits.t = bad_hits.t[:-1]
    elif case == "short throughput":
        paths.throughput = np.ones((3, n - 1), np.float32)
    elif case == "radiance of two channels":
        radiance = np.zeros((n, 2))
    return bad_hits, paths, radiance


CASES = {"prim beyond the faces": "hits.prim", "prim far beyond": "hits.prim",
         "prim below -1": "hits.prim",
         "slot beyond the radiance": "paths.slot", "negative slot": "paths.slot",
         "short hits": "must hold", "short throughput": "must hold",
         "radiance of two channels": "radiance must be"}


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("name", SHADERS)
def test_a_shader_refuses_inputs_that_do_not_fit(each_isa, cornell, name, case):
    scene, rays, hits = cornell
    bad_hits, paths, radiance = hostile(case, scene, rays, hits)
    before = radiance.copy()
    shader = raysort.create("shaders", name)
    with pytest.raises(ValueError, match=f"{name}: .*{CASES[case]}"):
        shader.shade(scene, rays, bad_hits, paths, 0, 1, radiance)
    assert np.array_equal(radiance, before)         # nothing added before the error


@pytest.mark.parametrize("name", SHADERS)
def test_the_same_inputs_unbroken_are_shaded(cornell, name):
    """The control: the batch the cases break is shaded without an error."""
    scene, rays, hits = cornell
    n = len(rays)
    bounce = raysort.create("shaders", name).shade(
        scene, rays, hits, Paths(np.arange(n), np.zeros(n), np.arange(n)), 0, 1,
        np.zeros((n, 3)))
    assert len(bounce.rays) + (0 if bounce.shadow is None else len(bounce.shadow.rays)) > 0
