"""The pinhole camera (frame, validation) and the ``pinhole`` generator's rays.

References are recomputed here in float64 from the camera's definition
(eye, look_at, up, vfov), not taken from the code under test; only the bit-for-bit
check of the generator's arithmetic starts from ``Camera.frame`` (its float32 input).
"""
import math

import numpy as np
import pytest

import raysort
from raysort import Camera
from raysort._layout import RNG_DIMS
from raysort.errors import ConfigError

CAMERAS = [
    Camera((0, 0, 0), (0, 0, 1)),
    Camera((-17.5, -11.5, 0.0), (10.0, -10.5, 0.0), (0, 1, 0), 60.0),   # Sibenik's
    Camera((1, 2, 3), (-2, 0.5, 7), (0.3, 1, -0.2), 35.0),
    Camera((0, 5, 0), (0.1, 0, 0.05), (0, 1, 0), 120.0),                # steep, wide
    Camera((0, 0, 0), (1, 0, 0), (0, 0, 1), 1.0),                       # z up, narrow
]
SIZES = [(320, 240), (17, 31), (1, 1), (64, 48)]


def reference_frame(cam):
    """float64 unit forward, right, up of the camera, built from its definition."""
    f = np.subtract(cam.look_at, cam.eye).astype(np.float64)
    f /= np.linalg.norm(f)
    r = np.cross(f, cam.up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    return np.asarray(cam.eye, np.float64), f, r, u


def pixel_directions(cam, width, height, jx=0.5, jy=0.5):
    """float64 unit directions through sub-pixel position (jx, jy) of every pixel
    (row-major, image row 0 at the top)."""
    _, f, r, u = reference_frame(cam)
    half = math.tan(math.radians(cam.vfov) / 2)
    ys, xs = np.divmod(np.arange(width * height), width)
    sx = (2 * (xs + jx) / width - 1) * half * width / height
    sy = (1 - 2 * (ys + jy) / height) * half
    d = f + sx[:, None] * r + sy[:, None] * u
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# --------------------------------------------------------------------------
# Camera.frame
# --------------------------------------------------------------------------

@pytest.mark.parametrize("cam", CAMERAS)
@pytest.mark.parametrize("size", SIZES)
def test_frame_geometry(cam, size):
    """forward is unit and points at look_at; right and up are perpendicular to
    forward and each other, |up| = tan(vfov/2) and |right| / |up| = aspect;
    right = forward x up (right-handed), up has a positive component along the
    camera's up vector."""
    w, h = size
    eye, fwd, right, up = (np.asarray(v, np.float64) for v in cam.frame(w, h))
    assert all(v.dtype == np.float32 for v in cam.frame(w, h))
    np.testing.assert_array_equal(eye, np.float32(cam.eye))
    _, f_ref, r_ref, u_ref = reference_frame(cam)
    assert abs(np.linalg.norm(fwd) - 1) < 1e-6
    np.testing.assert_allclose(fwd, f_ref, atol=1e-6)
    half = math.tan(math.radians(cam.vfov) / 2)
    assert np.linalg.norm(up) == pytest.approx(half, rel=1e-6)
    assert np.linalg.norm(right) / np.linalg.norm(up) == pytest.approx(w / h, rel=1e-6)
    for a, b in ((right, fwd), (up, fwd), (right, up)):
        assert abs(a @ b) <= 1e-6 * np.linalg.norm(a) * np.linalg.norm(b)
    np.testing.assert_allclose(right / np.linalg.norm(right), r_ref, atol=1e-6)
    np.testing.assert_allclose(up / np.linalg.norm(up), u_ref, atol=1e-6)
    assert up @ np.asarray(cam.up, float) > 0


@pytest.mark.parametrize("cam", CAMERAS)
def test_pixel_centres_lie_inside_the_field_of_view(cam):
    """Every pixel centre maps to a direction whose vertical and horizontal angles
    from forward are within vfov/2 and hfov/2 (tan(hfov/2) = aspect * tan(vfov/2));
    the corners come within one pixel of the edge; row 0 is the top, column 0 the left."""
    w, h = 40, 30
    eye, fwd, right, up = (np.asarray(v, np.float64) for v in cam.frame(w, h))
    rn, un = right / np.linalg.norm(right), up / np.linalg.norm(up)
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    sx = (2 * xs / w - 1).ravel()
    sy = (1 - 2 * ys / h).ravel()
    d = fwd + sx[:, None] * right + sy[:, None] * up
    along = d @ fwd
    assert (along > 0).all()
    tan_v = np.abs(d @ un) / along
    tan_h = np.abs(d @ rn) / along
    half = math.tan(math.radians(cam.vfov) / 2)
    assert tan_v.max() < half and tan_h.max() < half * w / h
    # the outermost centres are half a pixel inside the edge
    assert tan_v.max() == pytest.approx(half * (1 - 1 / h), rel=1e-5)
    assert tan_h.max() == pytest.approx(half * w / h * (1 - 1 / w), rel=1e-5)
    # orientation: the first pixel is top-left
    assert d[0] @ un > 0 and d[0] @ rn < 0
    assert d[-1] @ un < 0 and d[-1] @ rn > 0


@pytest.mark.parametrize("cam", CAMERAS)
def test_centre_ray_looks_at_look_at(cam):
    """With an odd image size the centre pixel's un-jittered ray passes through look_at."""
    w, h = 33, 21
    gen = raysort.create("generators", "pinhole:jitter=False")
    centre = (h // 2) * w + w // 2
    rays = gen.generate(cam, np.array([centre], np.int32), np.array([0], np.int32), w, h, 1, 0)
    d = rays.directions[:, 0].astype(np.float64)
    to_target = np.subtract(cam.look_at, cam.eye)
    to_target /= np.linalg.norm(to_target)
    np.testing.assert_allclose(d, to_target, atol=1e-6)
    np.testing.assert_array_equal(rays.origins[:, 0], np.float32(cam.eye))


# --------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, match", [
    (dict(vfov=0), "vfov"),
    (dict(vfov=-10), "vfov"),
    (dict(vfov=180), "vfov"),
    (dict(vfov=200.0), "vfov"),
    (dict(vfov=float("nan")), "vfov"),
    (dict(vfov=float("inf")), "vfov"),
    (dict(vfov="60"), "vfov"),
    (dict(vfov=None), "vfov"),
    (dict(eye=(1, 2, 3)), "eye and look_at must differ"),
    (dict(up=(2, 4, 6)), "parallel"),
    (dict(up=(-1, -2, -3)), "parallel"),
    (dict(up=(0, 0, 0)), "parallel"),
    (dict(eye=(float("nan"), 0, 0)), "eye must be finite"),
    (dict(look_at=(0, float("inf"), 0)), "look_at must be finite"),
    (dict(up=(0, 1, float("-inf"))), "up must be finite"),
    (dict(eye=(1, 2)), "eye must be 3 numbers"),
    (dict(eye=("a", 0, 0)), "eye must be 3 numbers"),
    (dict(up=None), "up must be 3 numbers"),
])
def test_invalid_cameras_raise_config_error(kwargs, match):
    """Bad camera values are ConfigErrors (ValueErrors) saying what is wrong."""
    args = dict(eye=(0, 0, 0), look_at=(1, 2, 3), up=(0, 1, 0), vfov=60.0)
    args.update(kwargs)
    with pytest.raises(ConfigError, match=match):
        Camera(**args)


def test_vfov_limits_just_inside_are_accepted():
    """0 < vfov < 180 is open: values just inside the bounds are fine."""
    for vfov in (1e-3, 179.9, 90):
        Camera((0, 0, 0), (0, 0, 1), vfov=vfov)


def test_vfov_rejects_booleans():
    """True is not a field of view (it would silently mean 1 degree); procedural's
    parameter checks reject booleans the same way."""
    with pytest.raises(ConfigError, match="vfov"):
        Camera((0, 0, 0), (0, 0, 1), vfov=True)


@pytest.mark.parametrize("cam", CAMERAS)
def test_frame_is_made_once_per_size_and_read_only(cam):
    """A render asks once per tile: the same read-only arrays come back, equal bit for
    bit to a fresh computation, and a different size gets its own frame."""
    first, again = cam.frame(7, 5), cam.frame(7, 5)
    assert all(a is b for a, b in zip(first, again))
    assert not any(v.flags.writeable for v in first)
    for a, b in zip(first, cam._make_frame(7, 5)):
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert not np.array_equal(cam.frame(7, 5)[2], cam.frame(5, 5)[2])


@pytest.mark.parametrize("vfov", [np.float32(45.0), np.int64(45), np.float64(45.0)])
def test_vfov_accepts_numpy_scalars(vfov):
    """A NumPy number in range is a valid vfov (e.g. read from an array); the frame matches
    the one of the equivalent Python float."""
    cam = Camera((0, 0, 0), (0, 0, 1), vfov=vfov)
    ref = Camera((0, 0, 0), (0, 0, 1), vfov=45.0)
    for a, b in zip(cam.frame(4, 3), ref.frame(4, 3)):
        np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------
# the pinhole generator
# --------------------------------------------------------------------------

CAM = Camera((1, 2, 3), (-2, 0.5, 7), (0.3, 1, -0.2), 50.0)


def _gen(**params):
    return raysort.create("generators", {"type": "pinhole", **params})


def _generate(gen, pixels, samples, w, h, spp, seed, cam=CAM):
    return gen.generate(cam, np.asarray(pixels, np.int32), np.asarray(samples, np.int32),
                        w, h, spp, seed)


def test_generated_batch_layout():
    """len(samples) * len(pixels) rays, pass major; origins at the eye; tmin 0, tmax inf;
    directions unit length within 1e-6."""
    w, h, spp = 24, 16, 3
    pixels = np.arange(w * h)[::5]
    samples = [2, 0, 1]
    rays = _generate(_gen(), pixels, samples, w, h, spp, seed=9)
    n = len(pixels) * len(samples)
    assert len(rays) == n
    np.testing.assert_array_equal(rays.origins, np.broadcast_to(np.float32(CAM.eye)[:, None],
                                                                (3, n)))
    assert (rays.tmin == 0).all() and np.isposinf(rays.tmax).all()
    norms = np.linalg.norm(rays.directions.astype(np.float64), axis=0)
    assert np.abs(norms - 1).max() < 1e-6


def test_rays_are_deterministic_per_seed_pixel_and_sample():
    """The same (seed, pixel, sample) gives bit-identical rays alone or inside any
    bigger batch; ray s * len(pixels) + p is sample samples[s] of pixels[p]."""
    w, h, spp, seed = 37, 23, 5, 1234
    gen = _gen()
    rng = np.random.default_rng(0)
    pixels = rng.permutation(w * h)[:200]
    samples = np.array([4, 1, 3])
    big = _generate(gen, pixels, samples, w, h, spp, seed).data
    again = _generate(_gen(), pixels, samples, w, h, spp, seed).data
    np.testing.assert_array_equal(big[:, :600].view(np.uint32), again[:, :600].view(np.uint32))
    for s_idx, p_idx in [(0, 0), (2, 199), (1, 57), (2, 3)]:
        alone = _generate(gen, [pixels[p_idx]], [samples[s_idx]], w, h, spp, seed).data
        i = s_idx * len(pixels) + p_idx
        np.testing.assert_array_equal(alone[:, 0].view(np.uint32), big[:, i].view(np.uint32))
    # a different tile containing the same pixel, at another position in the batch
    p = pixels[57]
    other = np.array([p + 1 if p + 1 < w * h else 0, 5, p], np.int32)
    ray = _generate(gen, other, [0, 3], w, h, spp, seed).data
    np.testing.assert_array_equal(ray[:, 3 + 2].view(np.uint32),
                                  big[:, 2 * len(pixels) + 57].view(np.uint32))  # sample 3


def test_different_seeds_give_different_jitter():
    """Another seed moves (almost) every jittered sample; the same seed does not."""
    w, h = 32, 32
    pixels = np.arange(w * h)
    a = _generate(_gen(), pixels, [0], w, h, 1, seed=1).directions
    b = _generate(_gen(), pixels, [0], w, h, 1, seed=2).directions
    c = _generate(_gen(), pixels, [0], w, h, 1, seed=1).directions
    moved = (a != b).any(axis=0)
    assert moved.mean() > 0.99
    np.testing.assert_array_equal(a, c)
    # and different samples of one pixel differ too
    s = _generate(_gen(), [5], np.arange(8), w, h, 8, seed=1).directions
    assert len({tuple(col) for col in s.T.tolist()}) == 8


def test_seed_is_used_modulo_2_32():
    """Seeds are hashed as 32-bit values: seed and seed + 2**32 give the same rays."""
    a = _generate(_gen(), np.arange(50), [0, 1], 10, 5, 2, seed=7).data
    b = _generate(_gen(), np.arange(50), [0, 1], 10, 5, 2, seed=7 + 2 ** 32).data
    np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32))


@pytest.mark.parametrize("cam", CAMERAS)
def test_unjittered_sample_is_the_pixel_centre(cam):
    """jitter=False at 1 spp puts the ray exactly through the pixel centre
    (float64 reference from the camera definition, within 1e-6)."""
    w, h = 20, 14
    rays = _generate(_gen(jitter=False), np.arange(w * h), [0], w, h, 1, seed=3, cam=cam)
    ref = pixel_directions(cam, w, h)
    np.testing.assert_allclose(rays.directions.T.astype(np.float64), ref, atol=1e-6, rtol=0)
    # and it does not depend on the seed
    other = _generate(_gen(jitter=False), np.arange(w * h), [0], w, h, 1, seed=99, cam=cam)
    np.testing.assert_array_equal(rays.data, other.data)


def _image_plane_position(cam, w, h, directions):
    """(x, y) in pixel units of where each float64 direction crosses the image plane."""
    _, f, r, u = reference_frame(cam)
    half = math.tan(math.radians(cam.vfov) / 2)
    d = directions / (directions @ f)[:, None]        # scale onto the plane at distance 1
    sx = (d @ r) / (half * w / h)
    sy = (d @ u) / half
    return (sx + 1) * w / 2, (1 - sy) * h / 2


def test_jittered_samples_stay_inside_their_pixel():
    """Every jittered sample crosses the image plane inside its own pixel."""
    w, h = 16, 12
    pixels = np.arange(w * h)
    rays = _generate(_gen(), pixels, [0, 1, 2], w, h, 3, seed=5)
    x, y = _image_plane_position(CAM, w, h, rays.directions.T.astype(np.float64))
    px, py = np.tile(pixels % w, 3), np.tile(pixels // w, 3)
    eps = 1e-4
    assert ((x > px - eps) & (x < px + 1 + eps) & (y > py - eps) & (y < py + 1 + eps)).all()
    # and they are spread over the pixel, not all at the centre
    fx = x - px
    assert fx.min() < 0.2 and fx.max() > 0.8


@pytest.mark.parametrize("spp, root", [(4, 2), (9, 3)])
def test_square_spp_samples_are_stratified(spp, root):
    """With spp = k*k, the k*k samples of a pixel fall in the k*k different strata
    of the pixel (sample s in stratum (s % k, s // k)), as jittered sampling does."""
    w, h = 12, 9
    pixels = np.arange(w * h)
    rays = _generate(_gen(), pixels, np.arange(spp), w, h, spp, seed=21)
    x, y = _image_plane_position(CAM, w, h, rays.directions.T.astype(np.float64))
    fx = (x - np.tile(pixels % w, spp)) * root          # stratum coordinates in [0, root)
    fy = (y - np.tile(pixels // w, spp)) * root
    sample = np.repeat(np.arange(spp), len(pixels))
    eps = 1e-3
    sx, sy = sample % root, sample // root
    assert ((fx > sx - eps) & (fx < sx + 1 + eps)).all()
    assert ((fy > sy - eps) & (fy < sy + 1 + eps)).all()
    # per pixel, the strata (rounded from the centre of each sample's cell) are all different
    cells = np.floor(np.clip(fy, 0, root - 1e-9)) * root + np.floor(np.clip(fx, 0, root - 1e-9))
    per_pixel = cells.reshape(spp, len(pixels)).T
    assert all(len(set(row)) == spp for row in per_pixel.tolist())


def test_non_square_spp_is_not_stratified_but_stays_in_the_pixel():
    """spp = 3 (not a square) jitters over the whole pixel."""
    w, h = 6, 6
    rays = _generate(_gen(), np.arange(w * h), np.arange(3), w, h, 3, seed=4)
    x, y = _image_plane_position(CAM, w, h, rays.directions.T.astype(np.float64))
    fx = x - np.tile(np.arange(w * h) % w, 3)
    assert (fx > -1e-4).all() and (fx < 1 + 1e-4).all()


def test_unjittered_strata_centres():
    """jitter=False with spp 4 puts sample s at the centre of stratum s (quarter points)."""
    w, h = 8, 6
    pixels = np.arange(w * h)
    rays = _generate(_gen(jitter=False), pixels, np.arange(4), w, h, 4, seed=0)
    got = rays.directions.T.astype(np.float64)
    for s in range(4):
        ref = pixel_directions(CAM, w, h, jx=(s % 2 + 0.5) / 2, jy=(s // 2 + 0.5) / 2)
        np.testing.assert_allclose(got[s * len(pixels):(s + 1) * len(pixels)], ref, atol=1e-6)


def _mix32(x):
    """``mix32`` of raysort/_rng.pxd on a uint32 array (products wrap as in C)."""
    x = x ^ (x >> 16)
    x = x * np.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * np.uint32(0x846CA68B)
    return x ^ (x >> 16)


def _uniform(key, dim):
    """``uniform_at``: the hash's top 24 bits times 2^-24, in float32 (exact)."""
    return (_mix32(key ^ np.uint32(dim)) >> 8).astype(np.float32) * np.float32(2.0 ** -24)


def reference_rays(cam, pixels, samples, w, h, spp, seed, jitter):
    """The generator's rays, (8, n) in RayBatch row order, from its formula in NumPy with
    the kernel's types, in its order: float32 jitter, the image-plane position in float64
    rounded to float32, a float32 direction, its norm as the float64 square root of a
    float32 sum, rounded to float32."""
    eye, fwd, right, up = cam.frame(w, h)
    root = math.isqrt(spp)
    strata = root if root * root == spp else 1
    pix = np.tile(np.asarray(pixels, np.int32), len(samples))     # pass major
    smp = np.repeat(np.asarray(samples, np.int32), len(pixels))
    stratum = smp % (strata * strata)
    if jitter:
        seed_k = _mix32(np.array([seed & 0xFFFFFFFF], np.uint32) ^ np.uint32(0x9E3779B9))
        key = _mix32(_mix32(seed_k ^ pix.astype(np.uint32)) ^ smp.astype(np.uint32))
        jx, jy = _uniform(key, RNG_DIMS["jitter_x"]), _uniform(key, RNG_DIMS["jitter_y"])
    else:
        jx = jy = np.full(len(pix), 0.5, np.float32)
    jx = ((stratum % strata).astype(np.float32) + jx) / np.float32(strata)
    jy = ((stratum // strata).astype(np.float32) + jy) / np.float32(strata)
    x, y = (pix % w).astype(np.float32), (pix // w).astype(np.float32)
    sx = (2.0 * (x + jx).astype(np.float64) / w - 1.0).astype(np.float32)
    sy = (1.0 - 2.0 * (y + jy).astype(np.float64) / h).astype(np.float32)
    d = fwd[:, None] + sx * right[:, None] + sy * up[:, None]
    norm = np.sqrt((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).astype(np.float64))
    n = len(pix)
    return np.vstack([np.broadcast_to(eye[:, None], (3, n)), d / norm.astype(np.float32),
                      np.zeros((1, n), np.float32), np.full((1, n), np.inf, np.float32)])


@pytest.mark.parametrize("jitter", [True, False])
def test_rays_match_the_formula_bit_for_bit_on_every_isa(each_isa, jitter):
    """Every ISA's build of the kernel (vectorised as the compiler likes) gives the
    formula's bits, for square and other spp, scattered pixels, repeated samples and
    samples beyond spp."""
    rng = np.random.default_rng(17)
    for cam, (w, h) in [(CAM, (37, 23)), (CAMERAS[1], (64, 48)), (CAMERAS[3], (17, 31))]:
        for spp in (1, 4, 5, 16):
            pixels = np.concatenate([rng.permutation(w * h)[:300], rng.integers(0, w * h, 5)])
            samples = [spp - 1, 0, spp - 1, spp + 1, 2]
            for seed in (0, 2 ** 32 - 1, 2 ** 40 + 5):
                rays = _generate(_gen(jitter=jitter), pixels, samples, w, h, spp, seed, cam)
                ref = reference_rays(cam, pixels, samples, w, h, spp, seed, jitter)
                assert rays.data.dtype == ref.dtype == np.float32
                got = rays.data[:, :len(rays)].view(np.uint32)
                assert np.array_equal(got, ref.view(np.uint32)), (each_isa, cam, spp, seed)


@pytest.mark.parametrize("jitter", [1, "yes", None])
def test_pinhole_jitter_must_be_bool(jitter):
    """jitter takes only true/false; anything else is a ConfigError naming pinhole."""
    with pytest.raises(ConfigError, match="pinhole"):
        _gen(jitter=jitter)
