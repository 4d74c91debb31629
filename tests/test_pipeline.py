"""The render pipeline: analytic images, determinism, bounded memory, plugin contracts."""
import time

import numpy as np
import pytest

import raysort
from raysort import output
from raysort.errors import ConfigError, PluginContractError

from _helpers import exact_traversals


# --------------------------------------------------------------------------
# analytic scenes
# --------------------------------------------------------------------------

@pytest.mark.parametrize("depth", [0, 1, 2, 5])
def test_furnace_is_exact_without_roulette(depth):
    """Inside a closed sphere emitting 1 with albedo 0.5, every path collects
    sum(0.5**k, k=0..depth): cosine sampling of a Lambertian BRDF weights each
    bounce by exactly the albedo, so every pixel has that value."""
    pipe = raysort.Pipeline("furnace", shader={"type": "lambert", "max_depth": depth})
    image = pipe.render(24, 16, spp=2).image
    expected = sum(0.5 ** k for k in range(depth + 1))
    np.testing.assert_allclose(image, expected, rtol=1e-6)


def test_furnace_with_russian_roulette_is_unbiased():
    """With Russian roulette paths end at random, but the estimator stays
    unbiased: the image mean matches the closed form within 5 standard errors."""
    depth = 6
    pipe = raysort.Pipeline("furnace", shader={"type": "lambert", "max_depth": depth,
                                               "russian_roulette": True, "rr_depth": 1})
    result = pipe.render(32, 32, spp=16, seed=3)
    pixels = result.image[..., 0].ravel().astype(np.float64)
    expected = sum(0.5 ** k for k in range(depth + 1))
    stderr = pixels.std(ddof=1) / np.sqrt(pixels.size)
    assert stderr > 0, "roulette should make the estimate noisy"
    assert abs(pixels.mean() - expected) < 5 * stderr
    # fewer rays than without roulette: paths really end early
    assert result.stats.rays[depth] < result.stats.rays[0]


def test_plane_under_uniform_sky():
    """A diffuse plane (albedo 0.5) under a sky of radiance 1 reflects exactly 0.5:
    every bounce ray leaves upward and escapes.  With depth 0 nothing is lit."""
    lit = raysort.Pipeline("plane").render(20, 20, spp=2).image
    np.testing.assert_allclose(lit, 0.5, rtol=1e-6)
    dark = raysort.Pipeline("plane", shader={"type": "lambert", "max_depth": 0}).render(
        20, 20, spp=1).image
    assert not dark.any()


def test_point_light_on_plane_matches_closed_form():
    """One bounce-free shadow ray: radiance = albedo/pi * I * cos / r^2 at each hit."""
    scene = raysort.load_scene("plane")
    scene.sky[:] = 0
    scene.lights = [raysort.scene.PointLight((0.0, 1.0, 0.0), (2.0, 2.0, 2.0))]
    pipe = raysort.Pipeline(scene, shader={"type": "lambert", "max_depth": 0},
                            generator={"type": "pinhole", "jitter": False})
    image = pipe.render(9, 9, spp=1).image
    # recompute the centre pixel's hit point independently
    eye, fwd, right, up = (v.astype(np.float64) for v in scene.camera.frame(9, 9))
    d = fwd / np.linalg.norm(fwd)                 # the centre pixel looks along forward
    t = -eye[1] / d[1]
    p = eye + t * d
    to_light = np.array([0.0, 1.0, 0.0]) - p
    r2 = to_light @ to_light
    expected = 0.5 / np.pi * 2.0 * (to_light[1] / np.sqrt(r2)) / r2
    # shadow rays start (1 + max|p|) / 8192 above the surface (lambert's offset),
    # which moves the light by that much relative to r ~ 1: allow 1e-3
    np.testing.assert_allclose(image[4, 4], expected, rtol=1e-3)


def test_several_lights_add_up():
    """Light is additive: a scene lit by three point lights renders as the sum of the
    scene lit by each alone, less twice the scene without lights (its sky and emitters
    counted once).  The paths and their bounces do not depend on the lights, so the
    sums differ only by float64 rounding."""
    def render(lights):
        scene = raysort.load_scene("cornell")
        scene.lights = lights
        return raysort.Pipeline(scene).render(24, 24, spp=2, seed=5).image.astype(np.float64)

    base = raysort.load_scene("cornell").lights
    lights = base + [raysort.scene.PointLight((-0.4, 0.9, 0.2), (0.6, 0.8, 1.0)),
                     raysort.scene.PointLight((0.3, 0.5, -0.1), (1.0, 0.3, 0.2))]
    together = render(lights)
    apart = sum(render([light]) for light in lights) - 2 * render([])
    assert (apart > 0).mean() > 0.5
    np.testing.assert_allclose(together, apart, rtol=1e-5, atol=1e-7)


# --------------------------------------------------------------------------
# determinism: the image cannot depend on sorter, traversal or threads
# --------------------------------------------------------------------------

def _render(scene, **kw):
    size = kw.pop("size", (40, 30))
    spp = kw.pop("spp", 2)
    seed = kw.pop("seed", 11)
    return raysort.Pipeline(scene, **kw).render(*size, spp=spp, seed=seed)


@pytest.fixture(scope="module")
def sibenik_reference(sibenik):
    return _render(sibenik).image


@pytest.mark.parametrize("traversal", exact_traversals())
@pytest.mark.parametrize("sorter", ["none", "none:packet_size=1024", "nah", "nah_numpy"])
def test_image_identical_for_every_sorter_and_traversal(sibenik, sibenik_reference,
                                                         traversal, sorter):
    image = _render(sibenik, sorter=sorter, traversal=traversal).image
    assert np.array_equal(image.view(np.uint32), sibenik_reference.view(np.uint32))


@pytest.mark.parametrize("traversal", exact_traversals())
def test_shadow_rays_identical_for_every_traversal(sibenik, traversal):
    """Shadow rays use the any-hit path of each traversal."""
    base = _render(sibenik, shader={"type": "lambert", "shadow_rays": True}, size=(24, 16))
    other = _render(sibenik, shader={"type": "lambert", "shadow_rays": True}, size=(24, 16),
                    traversal=traversal, sorter="nah")
    assert base.stats.shadow_rays > 0
    assert np.array_equal(base.image.view(np.uint32), other.image.view(np.uint32))


@pytest.fixture(scope="module")
def forest():
    return raysort.load_scene("forest")


@pytest.mark.parametrize("shader", ["lambert", {"type": "lambert", "shadow_rays": True},
                                    {"type": "lambert", "max_depth": 0}, "ao"])
@pytest.mark.parametrize("scene_name", ["sibenik", "forest"])
def test_the_lean_paths_leave_the_image_unchanged(request, scene_name, shader):
    """The frame's fast paths (sorter none's consecutive rays loaded, not gathered; the
    shaders' rays written once; the checks skipped for trusted plugins) against the
    general path: rays sorted by nah, gathered one by one, every result checked."""
    scene = request.getfixturevalue(scene_name)
    images = [_render(scene, shader=shader, size=(37, 29), spp=3, **kw).image
              for kw in ({}, {"check_plugins": False}, {"sorter": "nah"},
                         {"sorter": "none:packet_size=1024", "check_plugins": False})]
    for image in images[1:]:
        assert np.array_equal(image.view(np.uint32), images[0].view(np.uint32))
    assert images[0].any()


def test_thread_count_does_not_change_the_image(sibenik, sibenik_reference):
    for threads in (2, 3):
        image = _render(sibenik, threads=threads, traversal="ranged", sorter="nah").image
        assert np.array_equal(image.view(np.uint32), sibenik_reference.view(np.uint32))


def test_tiles_share_batches_at_low_spp():
    """As many whole tiles as fill batch_rays share a batch, but no more than leave
    MIN_RUNS runs; never fewer than one; the runs do not depend on the thread count;
    with a tap, one tile per run."""
    assert raysort.pipeline.MIN_RUNS == 16
    tiles = [(x, y) for y in range(0, 96, 16) for x in range(0, 80, 16)]     # 30 tiles
    for spp, batch_rays, per_run in ((1, 16384, 2), (4, 16384, 2), (4, 2048, 2),
                                     (16, 2048, 1), (64, 256, 1), (1, 512, 2), (1, 256, 1)):
        for threads in (1, 2):
            pipe = raysort.Pipeline("plane", tile=16, batch_rays=batch_rays, threads=threads)
            runs = pipe._tile_groups(tiles, spp)
            assert [t for run in runs for t in run] == tiles
            assert [len(run) for run in runs[:-1]] == [per_run] * (len(runs) - 1)
            assert 1 <= len(runs[-1]) <= per_run
            assert pipe._tile_groups(tiles, spp, join=False) == [[t] for t in tiles]
    many = [(x, 0) for x in range(0, 16 * 400, 16)]                          # 400 tiles
    pipe = raysort.Pipeline("plane", tile=16, batch_rays=16384)
    assert {len(run) for run in pipe._tile_groups(many, 4)} == {16}          # batch_rays
    assert {len(run) for run in pipe._tile_groups(many, 1)} == {25}          # MIN_RUNS


@pytest.fixture
def generated():
    """The number of rays the generator ``recording_test`` (``pinhole``) is asked for,
    call by call."""
    sizes = []

    class Recording(raysort.load("generators", "pinhole")):
        def generate(self, camera, pixels, samples, width, height, spp, seed):
            sizes.append(len(pixels) * len(samples))
            return super().generate(camera, pixels, samples, width, height, spp, seed)

    raysort.register("generators", "recording_test", Recording)
    try:
        yield sizes
    finally:
        raysort.unregister("generators", "recording_test")


def test_tiles_sharing_batches_give_the_same_image(sibenik, generated):
    """Partial tiles, several per batch or one: the same pixels bit for bit, and the
    generator is asked for several tiles' passes at once."""
    images = []
    for batch_rays, threads in ((64, 1), (512, 1), (512, 2), (65536, 1)):
        generated.clear()
        result = _render(sibenik, generator="recording_test", tile=8, size=(45, 37),
                         spp=4, batch_rays=batch_rays, threads=threads)
        images.append(result.image)
        # 8x8 tiles at 4 spp: up to 256 rays a tile; the 45x37 frame has 30 tiles, so
        # MIN_RUNS (16) lets at most two share a batch
        assert sum(generated) == 45 * 37 * 4
        if batch_rays == 64:        # one pass of one tile at a time
            assert max(generated) <= 64
        else:                       # runs of two tiles, all four passes
            assert max(generated) == 2 * 256
    for image in images[1:]:
        assert np.array_equal(image.view(np.uint32), images[0].view(np.uint32))


def test_same_seed_same_exr_bytes_and_other_seed_differs(sibenik, tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    _render(sibenik, seed=5).write(a)
    _render(sibenik, seed=5, threads=2).write(b)
    assert a.read_bytes() == b.read_bytes()
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    other = _render(sibenik, seed=6).image
    assert not np.array_equal(other, output.read_exr(a))


def test_partial_tiles_cover_the_image(sibenik):
    """An image size that is no multiple of the tile still renders every pixel."""
    result = _render(sibenik, size=(45, 37), spp=1, tile=16)
    assert result.image.shape == (37, 45, 3)
    assert result.stats.rays[0] == 45 * 37
    assert (result.image.sum(axis=2) > 0).mean() > 0.5


@pytest.mark.parametrize("traversal", ["single", "ranged"])
def test_threaded_trace_gives_the_same_hits_and_counts(sibenik, workloads, traversal):
    """Pipeline.trace splits the traversal over threads without changing anything."""
    work = workloads(sibenik, "diffuse")
    pipe = raysort.Pipeline(sibenik, sorter="nah", traversal=traversal)
    one, c1 = pipe.trace(work.rays, work.packets, threads=1)
    two, c2 = pipe.trace(work.rays, work.packets, threads=3)
    for field in ("t", "prim", "u", "v"):
        assert np.array_equal(getattr(one, field).view(np.uint32),
                              getattr(two, field).view(np.uint32))
    assert c1 == c2 and c1.rays == len(work)


# --------------------------------------------------------------------------
# stats and memory
# --------------------------------------------------------------------------

def test_stats_account_for_every_ray(sibenik):
    result = _render(sibenik, traversal="ranged", sorter="nah", size=(32, 32), spp=2)
    st = result.stats
    assert st.rays[0] == 32 * 32 * 2
    assert sorted(st.rays) == [0, 1, 2]
    for depth, n in st.rays.items():
        assert st.counters[depth].rays <= n and st.counters[depth].rays > 0.99 * n
    total = st.closest_hit_counters()
    assert total.box1 > 0 and total.box4 > 0 and total.ia > 0
    assert st.total_rays == sum(st.rays.values()) + st.shadow_rays
    assert st.stage_seconds["traverse"] > 0 and st.wall_seconds > 0
    assert set(st.as_dict()) >= {"rays_per_depth", "counters_per_ray", "stage_seconds"}


def test_stage_seconds_split_the_render_thread_cpu(sibenik):
    """With one thread the stages are disjoint stretches of the calling thread's CPU time
    that, with ``other`` (the bookkeeping between them), cover the render but for its
    set-up: their sum is at most the render's thread CPU time and most of it."""
    pipe = raysort.Pipeline(sibenik, threads=1)
    pipe.render(8, 8, spp=1)                    # the BVH and the shader's tables
    start = time.thread_time()
    st = pipe.render(96, 64, spp=2, seed=3).stats
    spent = time.thread_time() - start
    assert set(st.stage_seconds) == set(raysort.pipeline.STAGES)
    assert min(st.stage_seconds.values()) >= 0 and st.stage_seconds["other"] > 0
    assert 0.5 * spent < sum(st.stage_seconds.values()) <= spent + 1e-6


def test_memory_is_bounded_by_the_batch(sibenik, generated):
    """The generator is never asked for more than batch_rays rays at once
    (rounded up to one whole pass), whatever the image size x spp."""
    pipe = raysort.Pipeline(sibenik, generator="recording_test", batch_rays=2048,
                            shader={"type": "lambert", "max_depth": 0})
    pipe.render(64, 64, spp=16)
    assert max(generated) == 2048
    assert sum(generated) == 64 * 64 * 16


# --------------------------------------------------------------------------
# bad settings and broken plugins
# --------------------------------------------------------------------------

@pytest.mark.parametrize("kw, name", [
    (dict(tile=0), "tile"), (dict(tile=65), "tile"), (dict(threads=0), "threads"),
    (dict(batch_rays=0), "batch_rays"), (dict(bvh={"max_leaf": 0}), "max_leaf"),
    (dict(bvh=5), "bvh"), (dict(bvh={"leaf": 2}), "'leaf'"), (dict(scene=42), "scene"),
    (dict(scene=b"plane"), "scene"), (dict(check_plugins="yes"), "check_plugins"),
    (dict(threads=2.0), "threads"), (dict(sorter=5), "sorter"),
])
def test_bad_pipeline_settings(kw, name):
    """A ConfigError naming the argument, never a raw TypeError or ValueError."""
    kw = {"scene": "plane"} | kw
    with pytest.raises(ConfigError, match=name):
        raysort.Pipeline(kw.pop("scene"), **kw).render(4, 4, 1)


@pytest.mark.parametrize("kw, name", [
    (dict(width=0), "width"), (dict(spp=0), "spp"), (dict(seed=-1), "seed"),
    (dict(seed=2**32), "seed"), (dict(height=2.5), "height"), (dict(progress=5), "progress"),
    (dict(width=100000, height=100000), "pixels"),
])
def test_bad_render_settings(kw, name):
    args = dict(width=4, height=4, spp=1, seed=0) | kw
    with pytest.raises(ConfigError, match=name):
        raysort.Pipeline("plane").render(**args)


def test_an_image_too_big_for_memory_is_refused_up_front(monkeypatch):
    """render() compares the image buffer with the machine's memory before allocating."""
    monkeypatch.setattr("os.sysconf", lambda name: {"SC_PHYS_PAGES": 1000,
                                                   "SC_PAGE_SIZE": 4096}[name])
    with pytest.raises(ConfigError, match=r"1024x1024 needs 0.0117 GiB .* more than this "
                                          r"machine's 0.00381 GiB"):
        raysort.Pipeline("plane").render(1024, 1024, 1)


@pytest.mark.parametrize("kw, name", [
    (dict(threads=0), "threads"), (dict(threads=True), "threads"), (dict(any_hit=1), "any_hit"),
    (dict(packets=[0, 3]), "packets"), (dict(timings=[]), "timings"),
])
def test_bad_trace_arguments(kw, name):
    rays = raysort.RayBatch.from_arrays(np.zeros((4, 3)), np.tile([0, -1.0, 0], (4, 1)))
    with pytest.raises(ConfigError, match=name):
        raysort.Pipeline("plane").trace(rays, **kw)


@pytest.mark.parametrize("check_plugins", [True, False])
def test_bad_packets_are_the_callers_fault_not_the_sorters(check_plugins):
    """trace(packets=...) that would crash or silently drop rays: a ConfigError naming
    'packets', even with the checks of trusted plugins off."""
    rays = raysort.RayBatch.from_arrays(np.tile([0, 1.0, 0], (1000, 1)),
                                        np.tile([0, -1.0, 0], (1000, 1)))
    pipe = raysort.Pipeline("plane", check_plugins=check_plugins)
    for packets in ([0, 100000], [], [0, 500], [0, 600, 200, 1000]):
        with pytest.raises(ConfigError, match="^packets"):
            pipe.trace(rays, packets)


def _with_plugin(kind, name, cls, **pipe_kw):
    raysort.register(kind, name, cls)
    try:
        return raysort.Pipeline("plane", **{kind[:-1]: name}, **pipe_kw).render(8, 8, 1)
    finally:
        raysort.unregister(kind, name)


def test_traversal_that_returns_no_counters_is_named():
    class NoCounters(raysort.Traversal):
        def intersect(self, bvh, packets, any_hit=False):
            return None

    with pytest.raises(PluginContractError, match="no_counters_test"):
        _with_plugin("traversals", "no_counters_test", NoCounters)


def test_generator_with_wrong_ray_count_is_named():
    class Short(raysort.Generator):
        def generate(self, camera, pixels, samples, width, height, spp, seed):
            return raysort.RayBatch(1)

    with pytest.raises(PluginContractError, match="short_test"):
        _with_plugin("generators", "short_test", Short)


def test_shader_that_returns_garbage_is_named():
    class Garbage(raysort.Shader):
        def shade(self, scene, rays, hits, paths, depth, seed, radiance):
            return "nope"

    with pytest.raises(PluginContractError, match="garbage_test"):
        _with_plugin("shaders", "garbage_test", Garbage)


@pytest.mark.parametrize("size", [(1, 1), (3, 5), (8, 8), (32, 32), (17, 32)])
def test_morton_order_is_the_z_order_of_the_tile(size):
    """Every pixel of the tile once, in the order of its interleaved bits (x in the even
    bits), ties impossible; the array is made once per size and read-only."""
    from raysort.pipeline import morton_order
    w, h = size
    order = morton_order(w, h)

    def z(index):
        y, x = divmod(index, w)
        return sum(((x >> b) & 1) << (2 * b) | ((y >> b) & 1) << (2 * b + 1) for b in range(8))

    assert sorted(order.tolist()) == list(range(w * h))
    assert order.tolist() == sorted(range(w * h), key=z)
    assert morton_order(w, h) is order and not order.flags.writeable
