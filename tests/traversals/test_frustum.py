"""The ``frustum`` traversal: coherent chunks of rays through the 8-wide BVH.

Hits are compared with brute force (``raysort.reference``) on every ISA this CPU
runs, for the rays the frustum path is for (camera rays from one point, parallel
rays, rays with a zero direction component, rays from spread origins, shadow rays
from origins close together and far apart), with ties,
zero-area triangles, inactive lanes and short sub-packets; incoherent chunks must
take the single-ray path, whose hits and counters are ``wide8``'s.  (The
conformance suite holds ``frustum`` to the full contract on the active ISA.)
"""
import numpy as np
import pytest

import raysort
from raysort.bvh import BVH
from raysort.reference import brute_force

from _helpers import (assert_same_hits, batch, random_rays, tie_case,
                      trace_one_call, triangle_soup)

F32 = np.float32


def trace(bvh, rays, any_hit=False, size=None, name="frustum"):
    return trace_one_call(name, bvh, rays, any_hit, size)


def camera(eye, target, n, fov=0.6, tile=8):
    """``n`` x ``n`` pinhole rays from ``eye`` toward ``target``, in tile x tile blocks
    (as the ``none`` sorter's packets of camera rays); ``fov`` is the half-width of
    the image plane at distance 1."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    w = target - eye
    w /= np.linalg.norm(w)
    u = np.cross(w, [0.0, 1.0, 0.0] if abs(w[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(u, w)
    s = (np.arange(n) + 0.5) / n * 2 - 1
    by, bx = np.divmod(np.arange(n * n) // (tile * tile), n // tile)
    iy, ix = np.divmod(np.arange(n * n) % (tile * tile), tile)
    x, y = s[bx * tile + ix], s[by * tile + iy]
    d = w + fov * (x[:, None] * u + y[:, None] * v)
    return batch(np.tile(eye, (n * n, 1)), d / np.linalg.norm(d, axis=1, keepdims=True))


@pytest.fixture(scope="module")
def soup_bvh():
    V, F = triangle_soup(np.random.default_rng(7), 800)
    return V, F, BVH(V, F)


@pytest.mark.parametrize("eye", [(-4.0, 5.0, -6.0), (14.0, 3.0, 15.0), (5.0, 20.0, 5.5)])
def test_camera_rays_match_brute_force_on_every_isa(each_isa, soup_bvh, eye):
    V, F, bvh = soup_bvh
    rays = camera(eye, (5.0, 3.0, 5.0), 64)
    ref = brute_force(V, F, rays)
    assert 0.2 < (ref.prim >= 0).mean() < 1.0
    for size in (None, 64, 36, 17, 5):
        hits, counters = trace(bvh, rays, size=size)
        assert_same_hits(hits, ref, f"{each_isa}, sub-packets of {size}")
        assert (counters.ia > 0) == (size != 5)  # chunks of 16 rays or more take the walk
    occluded, _ = trace(bvh, rays, any_hit=True, size=64)
    assert np.array_equal(occluded, ref.prim >= 0)


def test_parallel_and_axis_aligned_rays_on_every_isa(each_isa, soup_bvh, rng):
    """One direction for every ray (the reciprocal ranges are points), from spread
    origins, some with a zero direction component (that axis cannot cull)."""
    V, F, bvh = soup_bvh
    for d in ([0.3, -1.0, 0.2], [0.0, -1.0, 0.4], [0.0, -1.0, -0.0], [-1.0, 0.0, 0.0]):
        o = rng.random((640, 3)) * [10, 0, 10] + [0, 12, 0]
        if d[0] == -1.0:
            o = rng.random((640, 3)) * [0, 10, 10] + [14, 0, 0]
        rays = batch(o, np.tile(np.asarray(d) / np.linalg.norm(d), (640, 1)))
        ref = brute_force(V, F, rays)
        assert (ref.prim >= 0).any()
        hits, counters = trace(bvh, rays, size=64)
        assert_same_hits(hits, ref, f"{each_isa}, direction {d}")
        assert (counters.ia > 0) == (np.count_nonzero(d) >= 2)


def test_ties_and_zero_area_triangles_on_every_isa(each_isa, rng):
    V, F, rays, ref = tie_case(rng, coherent=True)
    for max_leaf in (1, 8):
        bvh = BVH(V, F, max_leaf=max_leaf)
        hits, counters = trace(bvh, rays, size=64)
        assert_same_hits(hits, ref, f"{each_isa} ties, max_leaf {max_leaf}")
        assert counters.ia > 0


def extents_case():
    """Camera rays with tmin > 0, finite tmax, and rays that are empty (tmax <= tmin)
    between them."""
    rays = camera((-4.0, 5.0, -6.0), (5.0, 3.0, 5.0), 32, fov=0.3)
    n = len(rays)
    rays.tmin[:] = np.where(np.arange(n) % 3 == 0, 2.0, 0.0)
    rays.tmax[:] = np.where(np.arange(n) % 5 == 0, 9.0, np.inf)
    rays.tmax[np.arange(n) % 7 == 0] = 1.0
    rays.tmin[np.arange(n) % 7 == 0] = 1.0
    return rays


def test_extents_and_inactive_lanes_on_every_isa(each_isa, soup_bvh):
    V, F, bvh = soup_bvh
    rays = extents_case()
    ref = brute_force(V, F, rays)
    for size in (64, 20, 37):
        hits, counters = trace(bvh, rays, size=size)
        assert_same_hits(hits, ref, f"{each_isa}, sub-packets of {size}")
        assert counters.ia > 0


def test_walk_decisions_do_not_depend_on_the_isa(each_isa, soup_bvh):
    """A chunk's bounds and reach are taken several lanes at a time on a SIMD build
    and one ray at a time on the scalar one: the same values, so the same nodes are
    visited and the same triangles tested (``ia``, ``tri4``; ``box4`` counts one
    test per SIMD group of lanes, so it depends on the width)."""
    V, F, bvh = soup_bvh
    cases = [extents_case(), camera((14.0, 3.0, 15.0), (5.0, 3.0, 5.0), 40)]
    got = [trace(bvh, rays, size=size)[1] for rays in cases for size in (64, 37, 20)]
    previous = raysort.isa.use("scalar")
    try:
        want = [trace(bvh, rays, size=size)[1] for rays in cases for size in (64, 37, 20)]
    finally:
        raysort.isa.use(previous)
    assert [(c.ia, c.tri4) for c in got] == [(c.ia, c.tri4) for c in want]
    assert all(c.ia > 0 for c in want)


def test_incoherent_chunks_trace_one_ray_at_a_time_as_wide8(soup_bvh, rng):
    V, F, bvh = soup_bvh
    rays = random_rays(rng, 2000, bvh.bounds)
    ref = brute_force(V, F, rays)
    hits, counters = trace(bvh, rays, size=64)
    assert_same_hits(hits, ref, "random rays")
    _, wide8 = trace(bvh, rays, size=64, name="wide8")
    assert counters.ia == 0
    assert (counters.box4, counters.tri4) == (wide8.box4, wide8.tri4)


@pytest.mark.parametrize("spread, walked", [(0.02, True), (0.16, False)])
def test_chunks_whose_origins_spread_wide_trace_one_ray_at_a_time(each_isa, soup_bvh, spread,
                                                                  walked):
    """Shadow rays toward one light, their directions within the walk's spread: from
    origins close together (2 % of the ray length) a chunk takes the walk; from origins
    spread wider than a tenth of the longest ray (the hits of a bounce) it goes one ray
    at a time, as ``wide8`` (the walk's interval test would cull almost nothing).
    Brute force's hits either way."""
    V, F, bvh = soup_bvh
    rng = np.random.default_rng(11)
    light = np.array([25.0, 30.0, 25.0])
    centre = np.array([8.0, 5.0, 8.0])
    length = np.linalg.norm(light - centre)
    origins = centre + rng.uniform(-0.5, 0.5, (640, 3)) * spread * length
    d = light - origins
    dist = np.linalg.norm(d, axis=1)
    d /= dist[:, None]
    chunks = d.reshape(-1, 64, 3)
    assert (chunks.max(axis=1) - chunks.min(axis=1)).max() <= 0.25    # directions agree
    assert (d > 0).all()
    rays = batch(origins, d, 1e-3, dist.astype(F32))
    ref = brute_force(V, F, rays)
    assert 0 < (ref.prim >= 0).sum() < len(rays)
    for any_hit in (False, True):
        hits, counters = trace(bvh, rays, any_hit=any_hit, size=64)
        if any_hit:
            assert np.array_equal(hits, ref.prim >= 0)
        else:
            assert_same_hits(hits, ref, f"{each_isa} spread {spread}")
        assert (counters.ia > 0) == walked
        if not walked:
            _, wide8 = trace(bvh, rays, any_hit=any_hit, size=64, name="wide8")
            assert (counters.box4, counters.tri4) == (wide8.box4, wide8.tri4)


def test_camera_chunks_test_fewer_boxes_than_wide8(soup_bvh):
    """Sharing the walk: fewer box tests per ray than one ray at a time (counters,
    not time)."""
    V, F, bvh = soup_bvh
    rays = camera((-4.0, 5.0, -6.0), (5.0, 3.0, 5.0), 64)
    _, frustum = trace(bvh, rays, size=64)
    _, wide8 = trace(bvh, rays, size=64, name="wide8")
    assert frustum.ia + frustum.box4 < wide8.box4 / 2


def test_renders_the_image_of_wide8():
    scene = raysort.load_scene("cornell")
    images = [raysort.Pipeline(scene, traversal=t).render(48, 48, spp=2, seed=3).image
              for t in ("frustum", "wide8")]
    assert np.array_equal(images[0], images[1])
