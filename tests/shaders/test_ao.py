"""The ``ao`` shader against analytic scenes.

* an open plane: nothing above it, every AO ray escapes: exactly 1 everywhere;
* a closed box of size < distance seen from inside: every AO ray hits a wall: exactly 0;
* a floor under a ceiling at height h: a cosine-distributed ray at angle theta reaches
  the ceiling at h / cos(theta), so it is unoccluded within distance d exactly when
  cos(theta) < h / d, which has probability (h / d)^2 (cos^2 theta is uniform);
* pixels that see nothing get ``background``;
* the image is bit-identical for every sorter, traversal and thread count.
"""
import math

import numpy as np
import pytest

import raysort
from raysort.workloads import workload


def box_scene(lo, hi, camera):
    """An axis-aligned box of 12 triangles (closed, shared vertices)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corners = np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])
    quads = [(0, 2, 6, 4), (1, 5, 7, 3), (0, 4, 5, 1), (2, 3, 7, 6), (0, 1, 3, 2), (4, 6, 7, 5)]
    faces = [tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))]
    return raysort.Scene.from_mesh(corners, faces, camera=camera, name="box")


def quad(y, half):
    """Two triangles of the square |x|, |z| <= half at height y."""
    v = [(-half, y, -half), (half, y, -half), (half, y, half), (-half, y, half)]
    return np.array(v, float), np.array([(0, 1, 2), (0, 2, 3)])


def render(scene, shader, size=(32, 24), spp=2, **pipe):
    return raysort.Pipeline(scene, shader=shader, **pipe).render(*size, spp=spp, seed=5)


def test_open_plane_is_one_everywhere():
    """The packaged plane scene: every primary ray hits the plane, no AO ray can hit it
    back (they leave above it), so every pixel is exactly 1, whatever the distance."""
    for shader, samples in (({"type": "ao", "samples": 16}, 16),
                            ({"type": "ao", "distance": math.inf}, 8)):
        result = render("plane", shader)
        assert result.stats.shadow_rays == 32 * 24 * 2 * samples
        np.testing.assert_array_equal(result.image, 1.0)


def test_open_plane_samples_not_a_power_of_two():
    """With 3 samples the weight 1/3 is rounded; the sum stays within one float32 ulp."""
    image = render("plane", "ao:samples=3").image
    np.testing.assert_allclose(image, 1.0, rtol=0, atol=2 ** -23)


def test_inside_a_closed_box_is_zero():
    """Camera inside a unit box, distance 2 > the diagonal sqrt(3): all AO rays are
    occluded, every pixel is exactly 0 (and every primary ray did hit a wall)."""
    cam = raysort.Camera(eye=(0.3, 0.5, 0.4), look_at=(1.0, 0.4, 0.9))
    scene = box_scene((0, 0, 0), (1, 1, 1), cam)
    result = render(scene, {"type": "ao", "samples": 8, "distance": 2.0})
    assert result.stats.shadow_rays == 32 * 24 * 2 * 8
    np.testing.assert_array_equal(result.image, 0.0)


def test_inside_a_box_larger_than_the_distance_is_not_zero():
    """The same box seen with a distance far below its size: most rays escape it."""
    cam = raysort.Camera(eye=(0.3, 0.5, 0.4), look_at=(1.0, 0.4, 0.9))
    scene = box_scene((0, 0, 0), (1, 1, 1), cam)
    image = render(scene, {"type": "ao", "samples": 8, "distance": 0.05}).image
    assert image.mean() > 0.8


@pytest.mark.parametrize("distance", [1.25, 2.0, 4.0])
def test_floor_under_a_ceiling_matches_the_cosine_law(distance):
    """Floor y=0 and ceiling y=1, so large that no AO ray leaves between them: seen
    from between the planes, the floor's unoccluded fraction is (h / d)^2 (within five
    standard deviations of the binomial estimate)."""
    h, half = 1.0, 200.0
    fv, ff = quad(0.0, half)
    cv, cf = quad(h, half)
    cam = raysort.Camera(eye=(0.0, 0.5, 0.0), look_at=(0.0, 0.0, 0.3))
    scene = raysort.Scene.from_mesh(np.vstack([fv, cv]), np.vstack([ff, cf + 4]), camera=cam)
    pipe = raysort.Pipeline(scene, shader={"type": "ao", "samples": 16, "distance": distance})
    result = pipe.render(48, 32, spp=2, seed=3, aov=["prim"])
    floor = np.isin(result.aov["prim"], [0, 1])
    assert floor.sum() > 0.4 * floor.size, "the camera must see mostly the floor"
    rays = floor.sum() * 2 * 16
    expected = (h / distance) ** 2
    sigma = math.sqrt(expected * (1 - expected) / rays)
    assert abs(result.image[floor, 0].mean() - expected) < 5 * sigma + 1e-6


def test_misses_get_the_background():
    """A small triangle in front of the camera: pixels that miss it are `background`
    exactly, pixels that hit it (nothing else around) are 1."""
    cam = raysort.Camera(eye=(0, 0, -3), look_at=(0, 0, 0))
    scene = raysort.Scene.from_mesh([(-1, -1, 0), (1, -1, 0), (0, 1, 0)], [(0, 1, 2)],
                                    camera=cam)
    image = render(scene, {"type": "ao", "background": 0.25}, spp=1).image
    assert set(np.unique(image).tolist()) == {0.25, 1.0}


def test_image_is_the_same_for_every_sorter_traversal_and_thread_count(sibenik):
    """AO rays are any-hit queries through the same pipeline: no configuration may change
    a bit of the image."""
    shader = {"type": "ao", "samples": 4, "distance": 3.0}
    ref = render(sibenik, shader, (40, 24), sorter="none", traversal="single").image
    assert 0.05 < ref.mean() < 0.999, "a flat image would prove nothing"
    for sorter, traversal, threads in (("nah", "ranged", 1), ("nah", "wide", 2),
                                       ("none:packet_size=1024", "partition", 2)):
        image = render(sibenik, shader, (40, 24), sorter=sorter, traversal=traversal,
                       threads=threads).image
        assert np.array_equal(image.view(np.uint32), ref.view(np.uint32)), (sorter, traversal)


def test_ao_rays_are_cosine_distributed_with_the_distance(sibenik):
    """The AO workload of Sibenik: samples rays per primary hit, tmax = distance, unit
    directions with cos(theta) to the facing normal distributed as sqrt(U) (mean 2/3,
    mean square 1/2)."""
    work = workload(sibenik, "ao:samples=4,distance=2.5", width=32, height=24, spp=1, seed=2)
    primary = workload(sibenik, "primary", width=32, height=24, spp=1, seed=2)
    hits, _ = raysort.Pipeline(sibenik).trace(primary.rays, primary.packets)
    assert len(work) == 4 * int((hits.prim >= 0).sum())
    assert work.any_hit
    np.testing.assert_array_equal(work.rays.tmax, np.float32(2.5))
    d = work.rays.directions.astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-6)
    # the normal of the face each AO ray left from, turned toward the camera
    parent = np.repeat(np.flatnonzero(hits.prim >= 0), 4)
    nrm = sibenik.face_normals()[hits.prim[parent]].T.astype(np.float64)
    view = primary.rays.directions[:, parent].astype(np.float64)
    nrm *= np.where((nrm * view).sum(axis=0) > 0, -1.0, 1.0)
    cos = (d * nrm).sum(axis=0)
    assert (cos > 0).all()
    assert abs(cos.mean() - 2 / 3) < 0.02 and abs((cos ** 2).mean() - 0.5) < 0.02


def test_default_distance_is_a_tenth_of_the_scene_diagonal(sibenik):
    lo, hi = sibenik.bounds.astype(np.float64)
    work = workload(sibenik, "ao:samples=1", width=8, height=8)
    np.testing.assert_allclose(work.rays.tmax, 0.1 * np.linalg.norm(hi - lo), rtol=1e-6)


@pytest.mark.parametrize("bad", [{"samples": 0}, {"samples": 257}, {"samples": 2.0},
                                 {"distance": 0}, {"distance": -1.0}, {"distance": "far"},
                                 {"background": -0.5}, {"depth": 2}])
def test_bad_parameters_are_config_errors(bad):
    with pytest.raises(raysort.ConfigError, match=list(bad)[0]):
        raysort.create("shaders", {"type": "ao", **bad})
