"""The shader contract, checked on every registered shader (built-in or installed).

Every test is parametrised over ``raysort.available("shaders")``, so an outside
shader installed next to raysort is held to the same contract: ``shade``
returns a :class:`Bounce` whose ``parent`` ascends within the batch, whose rays
are finite or marked invalid, whose throughput and shadow contributions are
finite (3, m) arrays, and it keeps the radiance finite; what a path adds and
where it goes next depend only on (seed, pixel, sample, depth) and its own
ray and hit, not on the rest of the batch, the instance or the thread; its
inputs are left untouched; and whole renders pass the pipeline's checks.
"""
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import raysort
from raysort import contract
from raysort.camera import Camera
from raysort.paths import Paths
from raysort.procedural import PLANE_CAMERA, plane_under_sky
from raysort.scene import PointLight, Scene

SHADERS = raysort.available("shaders")
WIDTH, HEIGHT, SEED = 24, 16, 5


@pytest.fixture(params=SHADERS)
def name(request):
    return request.param


@pytest.fixture(scope="module")
def lit_plane():
    """A small plane under the sky with a point light: hits, misses and shadow rays."""
    mesh = plane_under_sky(size=3.0)
    return Scene.from_mesh(mesh.vertices, mesh.faces, camera=Camera(**PLANE_CAMERA),
                           albedo=0.5, lights=[PointLight((0, 3, 0), (5, 5, 5))], name="lit")


@pytest.fixture(scope="module", params=["lit", "cornell"])
def batch(request, lit_plane):
    """(scene, rays, hits, paths) of one sample of every pixel, traced in the scene."""
    scene = lit_plane if request.param == "lit" else raysort.load_scene("cornell")
    pipe = raysort.Pipeline(scene, sorter="none", traversal="single")
    pixels = np.arange(WIDTH * HEIGHT, dtype=np.int32)
    samples = np.array([3], np.int32)
    rays = pipe.generator.generate(scene.camera, pixels, samples, WIDTH, HEIGHT, 4, SEED)
    hits, _ = pipe.trace(rays)
    assert (hits.prim >= 0).any() and (hits.prim < 0).any()
    rng = np.random.default_rng(1)
    throughput = rng.uniform(0.2, 1.0, (3, len(pixels))).astype(np.float32)
    return scene, rays, hits, Paths(pixels, np.repeat(samples, len(pixels)), pixels, throughput)


def shade(name, scene, rays, hits, paths, depth=0, shader=None):
    """Shade into a fresh accumulator; returns (bounce checked and normalised, radiance)."""
    shader = shader or raysort.create("shaders", name)
    shader.prepare(scene)
    radiance = np.zeros((WIDTH * HEIGHT, 3))
    bounce = shader.shade(scene, rays, hits, paths, depth, SEED, radiance)
    return contract.check_bounce(name, bounce, len(rays), len(radiance), radiance), radiance


def subset(rays, hits, paths, index):
    part = raysort.Hits(len(index))
    part.t[:], part.prim[:], part.u[:], part.v[:] = (hits.t[index], hits.prim[index],
                                                     hits.u[index], hits.v[index])
    return rays.take(index), part, paths.take(index)


def by_path(bounce, paths):
    """Next rays and throughputs keyed by the (pixel, sample) of the path they continue."""
    out = {}
    for k, parent in enumerate(bounce.parent):
        key = (int(paths.pixel[parent]), int(paths.sample[parent]))
        out.setdefault(key, []).append((bounce.rays.data[:, k].view(np.uint32).tobytes(),
                                        bounce.throughput[:, k].view(np.uint32).tobytes()))
    return out


@pytest.mark.parametrize("depth", [0, 1])
def test_output_contract(name, batch, depth):
    """The Bounce passes the pipeline's check (done in shade()) at depth 0 and 1."""
    scene, rays, hits, paths = batch
    bounce, radiance = shade(name, scene, rays, hits, paths, depth)
    assert np.isfinite(radiance).all()
    assert len(bounce.rays) == len(bounce.parent) == bounce.throughput.shape[1]


def test_each_path_depends_only_on_itself(name, batch):
    """Shading every third path alone gives those paths the radiance and next rays they
    get in the full batch, bit for bit (so no ray order or batch split changes an image)."""
    scene, rays, hits, paths = batch
    full, full_radiance = shade(name, scene, rays, hits, paths, 1)
    index = np.arange(0, len(rays), 3)
    part_rays, part_hits, part_paths = subset(rays, hits, paths, index)
    part, part_radiance = shade(name, scene, part_rays, part_hits, part_paths, 1)
    slots = paths.slot[index]
    assert np.array_equal(part_radiance[slots].view(np.uint64),
                          full_radiance[slots].view(np.uint64))
    full_next = by_path(full, paths)
    for key, value in by_path(part, part_paths).items():
        assert full_next.get(key) == value, f"path {key} continues differently"


def test_deterministic_across_instances_and_calls(name, batch):
    scene, rays, hits, paths = batch
    first, r1 = shade(name, scene, rays, hits, paths)
    second, r2 = shade(name, scene, rays, hits, paths)
    assert np.array_equal(r1, r2)
    assert np.array_equal(first.parent, second.parent)
    assert np.array_equal(columns(first.rays), columns(second.rays))


def columns(rays):
    return rays.data[:, :len(rays)].view(np.uint32)


def test_same_result_from_many_threads(name, batch):
    """One prepared instance shading different batches from several threads at once gives
    what it gives alone (the pipeline shades tiles in parallel)."""
    scene, rays, hits, paths = batch
    shader = raysort.create("shaders", name)
    parts = [np.arange(k, len(rays), 4) for k in range(4)]
    args = [subset(rays, hits, paths, index) for index in parts]
    alone = [shade(name, scene, *a, shader=shader) for a in args]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(lambda k: shade(name, scene, *args[k % 4], shader=shader),
                                 range(12)))
    for k, (bounce, radiance) in enumerate(together):
        ref_bounce, ref_radiance = alone[k % 4]
        assert np.array_equal(radiance, ref_radiance)
        assert np.array_equal(columns(bounce.rays), columns(ref_bounce.rays))


def test_inputs_are_left_untouched(name, batch):
    scene, rays, hits, paths = batch
    saved = (rays.data.copy(), hits.t.copy(), hits.prim.copy(), paths.pixel.copy(),
             paths.slot.copy(), paths.throughput.copy())
    shade(name, scene, rays, hits, paths)
    now = (rays.data, hits.t, hits.prim, paths.pixel, paths.slot, paths.throughput)
    for before, after in zip(saved, now):
        assert np.array_equal(before, after)


@pytest.mark.parametrize("scene", ["cornell", "furnace"])
def test_renders_through_the_checks(name, scene):
    """Whole renders (emitters, closed scenes, several bounces) pass every check and give
    a finite image, identical on one and on two threads."""
    one = raysort.Pipeline(scene, shader=name).render(40, 24, 2, seed=3)
    two = raysort.Pipeline(scene, shader=name, threads=2).render(40, 24, 2, seed=3)
    assert np.isfinite(one.image).all() and one.image.max() > 0
    assert one.image.tobytes() == two.image.tobytes()
