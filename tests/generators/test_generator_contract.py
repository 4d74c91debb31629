"""The generator contract, checked on every registered generator (built-in or installed).

Every test is parametrised over ``raysort.available("generators")``, so an
outside generator installed next to raysort is held to the same contract:
``generate`` returns a :class:`RayBatch` of ``len(pixels) * len(samples)`` rays,
pass major, each finite or marked invalid; the ray of (seed, pixel, sample) is
bit-identical whatever else is in the batch, whichever instance and thread
makes it; its inputs are left untouched; and a render with it passes the
pipeline's checks.
"""
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import raysort
from raysort import contract
from raysort.camera import Camera

GENERATORS = raysort.available("generators")
CAMERA = Camera((0.5, 2.0, -3.0), (0.0, 0.2, 0.5), (0.0, 1.0, 0.0), 55.0)
WIDTH, HEIGHT, SPP, SEED = 37, 23, 9, 11


@pytest.fixture(params=GENERATORS)
def name(request):
    return request.param


def generate(name, pixels, samples, seed=SEED, generator=None):
    generator = generator or raysort.create("generators", name)
    return generator.generate(CAMERA, np.asarray(pixels, np.int32),
                              np.asarray(samples, np.int32), WIDTH, HEIGHT, SPP, seed)


def columns(rays):
    """(8, n) ray data as uint32 bit patterns, for exact comparison."""
    return rays.data[:, :len(rays)].view(np.uint32)


ALL_PIXELS = np.arange(WIDTH * HEIGHT, dtype=np.int32)
ALL_SAMPLES = np.arange(SPP, dtype=np.int32)


@pytest.mark.parametrize("pixels, samples", [
    (ALL_PIXELS[:64], ALL_SAMPLES), (ALL_PIXELS[::-7], [3]), ([WIDTH * HEIGHT - 1], [0, 8]),
    (ALL_PIXELS[:0], ALL_SAMPLES), (ALL_PIXELS[:5], []),
], ids=["tile", "scattered", "last-pixel", "no-pixels", "no-samples"])
def test_output_shape_and_contract(name, pixels, samples):
    """A RayBatch of pixels x samples rays that passes the pipeline's check."""
    rays = generate(name, pixels, samples)
    assert isinstance(rays, raysort.RayBatch)
    contract.check_generated(name, rays, len(pixels) * len(samples))


def test_deterministic_per_seed_pixel_and_sample(name):
    """The ray of (seed, pixel, sample) does not depend on the rest of the batch, on the
    order of pixels and samples, or on the instance."""
    full = columns(generate(name, ALL_PIXELS, ALL_SAMPLES))      # ray s * n_pix + p
    rng = np.random.default_rng(0)
    pixels = rng.choice(ALL_PIXELS, 50, replace=False)
    samples = rng.choice(ALL_SAMPLES, 4, replace=False)
    part = columns(generate(name, pixels, samples))
    expected = full[:, (samples[:, None] * len(ALL_PIXELS) + pixels[None, :]).reshape(-1)]
    assert np.array_equal(part, expected)
    again = columns(generate(name, pixels, samples))
    assert np.array_equal(part, again)


def test_same_rays_from_many_threads(name):
    """One instance called from several threads at once makes the rays it makes alone."""
    generator = raysort.create("generators", name)
    tiles = np.array_split(ALL_PIXELS, 8)
    alone = [columns(generate(name, tile, ALL_SAMPLES, generator=generator)) for tile in tiles]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(
            lambda tile: columns(generate(name, tile, ALL_SAMPLES, generator=generator)),
            tiles * 3))
    for k, rays in enumerate(together):
        assert np.array_equal(rays, alone[k % len(tiles)]), f"tile {k % len(tiles)}"


def test_inputs_are_left_untouched(name):
    pixels, samples = ALL_PIXELS[10:90].copy(), ALL_SAMPLES.copy()
    generate(name, pixels, samples)
    assert np.array_equal(pixels, ALL_PIXELS[10:90]) and np.array_equal(samples, ALL_SAMPLES)


def test_renders_through_the_checks(name):
    """A whole render with the generator passes every contract check, with a finite image."""
    result = raysort.Pipeline("cornell", generator=name, check_plugins=True).render(40, 24, 2)
    assert np.isfinite(result.image).all() and result.image.max() > 0
