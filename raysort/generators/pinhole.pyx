"""``pinhole``: primary rays of a pinhole camera with jittered samples.

A kernel module built per ISA (setup.py's ``ISA_MODULES``): what depends on the pixel
alone is computed once per call, then each sample's rays come from one loop over the
pixels that the compiler vectorises, with the IEEE operations of the scalar formula,
so every ISA makes the same bits.
"""
from libc.math cimport sqrt, INFINITY
from libc.stdint cimport int32_t, uint32_t
from libc.stdlib cimport malloc, free
from raysort._rng cimport mix32, seed_key, pixel_key, uniform_at
from raysort._types cimport (RS_RAY_OX, RS_RAY_OY, RS_RAY_OZ, RS_RAY_DX, RS_RAY_DY, RS_RAY_DZ,
                             RS_RAY_TMIN, RS_RAY_TMAX, RS_RAY_ROWS, RS_DIM_JITTER_X,
                             RS_DIM_JITTER_Y)

import math

import numpy as np

from raysort import isa
from raysort.params import boolean
from raysort.plugin import Generator
from raysort.rays import RayBatch


cdef extern from "raysort/simd.h" nogil:
    # the rows and the scratch never overlap: with restrict the sample loop vectorises
    # without run-time overlap checks
    ctypedef float *float_r "float *RS_RESTRICT"
    ctypedef const float *cfloat_r "const float *RS_RESTRICT"
    ctypedef const uint32_t *cuint32_r "const uint32_t *RS_RESTRICT"


cdef inline void sample_rays(cfloat_r xs, cfloat_r ys, cuint32_r keys, int n, uint32_t sample,
                             float col, float row, float strata, bint jitter, double width,
                             double height, const float *eye, const float *fwd,
                             const float *right, const float *up, float_r ox, float_r oy,
                             float_r oz, float_r dx, float_r dy, float_r dz, float_r tmin,
                             float_r tmax) noexcept nogil:
    """One sample (in stratum (col, row) of ``strata`` x ``strata``) of ``n`` pixels.

    A branch-free loop of contiguous loads and stores that the compiler vectorises
    (``jitter`` is a constant at both call sites).  Each ray takes the IEEE operations,
    types and order of the scalar formula: float jitter, the image-plane position in
    double rounded to float, float direction, double sqrt of a float sum, float
    division; -ffp-contract=off keeps them unfused, so every ISA gives the same bits."""
    cdef float e0 = eye[0], e1 = eye[1], e2 = eye[2], f0 = fwd[0], f1 = fwd[1], f2 = fwd[2]
    cdef float r0 = right[0], r1 = right[1], r2 = right[2], u0 = up[0], u1 = up[1], u2 = up[2]
    cdef float jx, jy, sx, sy, d0, d1, d2, norm
    cdef uint32_t key
    cdef int p
    for p in range(n):
        jx = jy = 0.5
        if jitter:
            key = mix32(keys[p] ^ sample)           # sample_key(seed_k, pixel, sample)
            jx = uniform_at(key, RS_DIM_JITTER_X)
            jy = uniform_at(key, RS_DIM_JITTER_Y)
        jx = (col + jx) / strata
        jy = (row + jy) / strata
        sx = 2.0 * (xs[p] + jx) / width - 1.0
        sy = 1.0 - 2.0 * (ys[p] + jy) / height
        d0 = f0 + sx * r0 + sy * u0
        d1 = f1 + sx * r1 + sy * u1
        d2 = f2 + sx * r2 + sy * u2
        norm = sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        ox[p] = e0
        oy[p] = e1
        oz[p] = e2
        dx[p] = d0 / norm
        dy[p] = d1 / norm
        dz[p] = d2 / norm
        tmin[p] = 0.0
        tmax[p] = INFINITY


cdef int make_rays(const float[::1] eye, const float[::1] fwd, const float[::1] right,
                   const float[::1] up, const int32_t[::1] pixels, const int32_t[::1] samples,
                   int width, int height, int strata, bint jitter, uint32_t seed,
                   float[:, ::1] out) noexcept nogil:
    """Ray ``s * len(pixels) + p`` is sample ``samples[s]`` of pixel ``pixels[p]``; -1 when
    out of memory."""
    cdef int n_pix = pixels.shape[0], s, p, y, stratum
    cdef Py_ssize_t base
    cdef uint32_t seed_k = seed_key(seed)
    if n_pix == 0 or samples.shape[0] == 0:
        return 0
    # what depends on the pixel alone, once per call rather than per sample: its column
    # and row (as the floats the formula converts them to) and its hash prefix
    cdef float *xs = <float *> malloc(3 * <size_t> n_pix * sizeof(float))
    if xs == NULL:
        return -1
    cdef float *ys = xs + n_pix
    cdef uint32_t *keys = <uint32_t *> (xs + 2 * n_pix)
    for p in range(n_pix):
        # pixels[p] // width (C's, truncated) as a double division, which vectorises: for
        # 32-bit operands its rounding error (under 2^-22 / width) cannot reach the next
        # integer (at least 1 / width away), so the quotient is exact
        y = <int32_t> (<double> pixels[p] / <double> width)
        xs[p] = pixels[p] - y * width       # pixels[p] % width
        ys[p] = y
    if jitter:
        for p in range(n_pix):
            keys[p] = pixel_key(seed_k, pixels[p])
    for s in range(samples.shape[0]):
        # stratified within the pixel when spp is a square number
        stratum = samples[s] % (strata * strata)
        base = s * <Py_ssize_t> n_pix
        if jitter:      # two copies of the loop, so that neither tests jitter per ray
            sample_rays(xs, ys, keys, n_pix, samples[s], stratum % strata, stratum // strata,
                        strata, True, width, height, &eye[0], &fwd[0], &right[0], &up[0],
                        &out[RS_RAY_OX, base], &out[RS_RAY_OY, base], &out[RS_RAY_OZ, base],
                        &out[RS_RAY_DX, base], &out[RS_RAY_DY, base], &out[RS_RAY_DZ, base],
                        &out[RS_RAY_TMIN, base], &out[RS_RAY_TMAX, base])
        else:
            sample_rays(xs, ys, keys, n_pix, samples[s], stratum % strata, stratum // strata,
                        strata, False, width, height, &eye[0], &fwd[0], &right[0], &up[0],
                        &out[RS_RAY_OX, base], &out[RS_RAY_OY, base], &out[RS_RAY_OZ, base],
                        &out[RS_RAY_DX, base], &out[RS_RAY_DY, base], &out[RS_RAY_DZ, base],
                        &out[RS_RAY_TMIN, base], &out[RS_RAY_TMAX, base])
    free(xs)
    return 0


cdef enum:
    MAX_STRATA = 46340      # strata * strata (make_rays' divisor) fits an int


def _generate(const float[::1] eye, const float[::1] fwd, const float[::1] right,
              const float[::1] up, const int32_t[::1] pixels, const int32_t[::1] samples,
              int width, int height, int strata, bint jitter, uint32_t seed,
              float[:, ::1] out):
    """Typed entry point: make the rays without the GIL."""
    cdef int status
    # the kernel writes through raw pointers: refuse arrays it would overrun
    if (min(eye.shape[0], fwd.shape[0], right.shape[0], up.shape[0]) < 3
            or out.shape[0] < RS_RAY_ROWS
            or out.shape[1] < <Py_ssize_t> pixels.shape[0] * samples.shape[0]):
        raise ValueError("_generate needs 3-element frame vectors and an out of at least "
                         "(8, len(pixels) * len(samples))")
    if width < 1 or height < 1 or not 1 <= strata <= MAX_STRATA:     # integer divisors
        raise ValueError(f"_generate: width, height >= 1 and strata 1..{MAX_STRATA} (strata "
                         f"squared an int) expected, got {width}, {height}, {strata}")
    with nogil:
        status = make_rays(eye, fwd, right, up, pixels, samples, width, height, strata, jitter,
                           seed, out)
    if status < 0:
        raise MemoryError()


class PinholeGenerator(Generator):
    """Pinhole-camera primary rays with jittered sub-pixel samples.

    Sample ``s`` of pixel ``p`` is placed at a uniformly random point of the
    pixel (or of its stratum when ``spp`` is a square number, as the paper's
    jittered sampling), drawn from a hash of (seed, pixel, sample): the same
    ray is produced whatever the batch, tile or thread.

    ==========  ======  =======  ==========================================
    parameter   type    default  meaning
    ==========  ======  =======  ==========================================
    jitter      bool    True     random position in the pixel/stratum;
                                 False puts every sample at its centre
    ==========  ======  =======  ==========================================
    """

    trusted = True

    def __init__(self, *, jitter=True):
        self.jitter = boolean("jitter", jitter)

    def generate(self, camera, pixels, samples, width, height, spp, seed):
        pixels = np.ascontiguousarray(pixels, dtype=np.int32)
        samples = np.ascontiguousarray(samples, dtype=np.int32)
        eye, fwd, right, up = camera.frame(width, height)
        root = math.isqrt(spp)
        strata = root if root * root == spp else 1
        rays = RayBatch._unfilled(len(pixels) * len(samples))    # _generate writes every row
        isa.module("generators.pinhole")._generate(eye, fwd, right, up, pixels, samples, width,
                                                   height, strata, self.jitter,
                                                   seed & 0xFFFFFFFF, rays.data)
        return rays
