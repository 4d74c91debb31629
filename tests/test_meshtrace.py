"""raysort.trace, the one-call API: brute force's hits, and a bounded, thread-safe BVH cache."""
import threading

import numpy as np
import pytest

import raysort
from raysort import meshtrace
from raysort.errors import ConfigError, SceneError
from raysort.reference import brute_force

from _helpers import assert_same_hits, random_rays


@pytest.fixture(autouse=True)
def empty_cache():
    meshtrace.clear_cache()
    yield
    meshtrace.clear_cache()


def _arrays(rays):
    return rays.origins.T.copy(), rays.directions.T.copy()


@pytest.fixture(scope="module")
def sibenik_rays(sibenik):
    """1000 random rays over Sibenik and their brute-force hits (computed once)."""
    rays = random_rays(np.random.default_rng(5), 1000, sibenik.bounds)
    return rays, brute_force(sibenik.vertices, sibenik.faces, rays)


@pytest.mark.parametrize("pipeline", [{}, {"sorter": "none", "traversal": "ranged"},
                                      {"sorter": "nah", "traversal": "single", "threads": 2,
                                       "tile": 16}])
def test_hits_are_brute_force(sibenik, sibenik_rays, pipeline):
    rays, ref = sibenik_rays
    origins, directions = _arrays(rays)
    hits = raysort.trace(sibenik.vertices, sibenik.faces, origins, directions, **pipeline)
    assert isinstance(hits, meshtrace.TraceHits)
    t, prim, u, v = hits
    assert (t.dtype, prim.dtype, u.dtype, v.dtype) == (np.float32, np.int32, np.float32,
                                                       np.float32)
    assert 0 < (prim >= 0).sum() < len(prim)
    assert_same_hits(hits, ref, str(pipeline))
    occluded = raysort.trace(sibenik.vertices, sibenik.faces, origins, directions,
                             any_hit=True, **pipeline)
    assert np.array_equal(occluded, ref.prim >= 0)


def test_interval_and_lists(rng):
    """tmin/tmax per ray or scalar; plain lists work; float64 inputs are rounded to float32."""
    vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    faces = [[0, 1, 2]]
    origins = [[0.25, 0.25, 1.0]] * 3
    directions = [[0, 0, -1.0]] * 3
    t, prim, u, v = raysort.trace(vertices, faces, origins, directions,
                                  tmin=[0.0, 1.0, 0.0], tmax=[2.0, 2.0, 0.5])
    assert prim.tolist() == [0, -1, -1] and t[0] == 1.0
    assert (u[0], v[0]) == (0.25, 0.25)
    with pytest.raises(ConfigError, match="tmin"):
        raysort.trace(vertices, faces, origins, directions, tmin=[0.0, 1.0])
    with pytest.raises(ConfigError, match=r"\(n, 3\)"):
        raysort.trace(vertices, faces, origins, [[0, 0, 1]])
    with pytest.raises(SceneError):
        raysort.trace(vertices, [[0, 1, 5]], origins, directions)
    assert len(raysort.trace(vertices, faces, np.zeros((0, 3)), np.zeros((0, 3))).t) == 0


def test_bvh_is_cached_by_content_and_bounded(sibenik):
    first = meshtrace.mesh_pipeline(sibenik.vertices, sibenik.faces).bvh
    again = meshtrace.mesh_pipeline(sibenik.vertices.astype(np.float64).copy(),
                                    sibenik.faces.astype(np.int64)).bvh
    assert again is first
    other_params = meshtrace.mesh_pipeline(sibenik.vertices, sibenik.faces,
                                           bvh={"max_leaf": 4}).bvh
    assert other_params is not first
    moved = sibenik.vertices.copy()
    moved[0, 0] += 1
    assert meshtrace.mesh_pipeline(moved, sibenik.faces).bvh is not first
    triangle = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    for k in range(meshtrace.CACHE_SIZE):
        meshtrace.mesh_pipeline(triangle + k, [[0, 1, 2]])
    assert meshtrace.mesh_pipeline(sibenik.vertices, sibenik.faces).bvh is not first


def test_threads_share_one_bvh_build(sponza, rng, monkeypatch):
    """Eight threads tracing a new mesh at once build its BVH once and all get brute
    force's hits."""
    builds = []
    real = raysort.scene.BVH

    def counting(*args, **kwargs):
        builds.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(raysort.scene, "BVH", counting)
    rays = random_rays(rng, 500, sponza.bounds)
    origins, directions = _arrays(rays)
    results, errors = [None] * 8, []

    def work(k):
        try:
            results[k] = raysort.trace(sponza.vertices, sponza.faces, origins, directions)
        except Exception as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors and len(builds) == 1
    ref = brute_force(sponza.vertices, sponza.faces, rays)
    for hits in results:
        assert_same_hits(hits, ref)


def test_outside_sorters_are_still_checked():
    """trace skips the contract check for raysort's trusted sorters only: a sorter from
    elsewhere that returns a non-permutation is caught and named."""
    from raysort.errors import PluginContractError
    from raysort.sdk import Sorter, fixed_packets

    class Duplicating(Sorter):
        def sort(self, rays, packets, bounds):
            return np.zeros(len(rays), np.int32), fixed_packets(packets, 64)

    raysort.register("sorters", "duplicating_for_test", Duplicating)
    try:
        with pytest.raises(PluginContractError, match="duplicating_for_test"):
            raysort.trace([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], [[0, 0, 1]] * 4,
                          [[0, 0, -1]] * 4, sorter="duplicating_for_test")
    finally:
        raysort.unregister("sorters", "duplicating_for_test")
