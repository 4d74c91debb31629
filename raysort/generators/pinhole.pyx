"""``pinhole``: primary rays of a pinhole camera with jittered samples."""
from libc.math cimport sqrt, INFINITY
from libc.stdint cimport int32_t, uint32_t
from raysort._rng cimport seed_key, sample_key, uniform_at
from raysort._types cimport (RS_RAY_OX, RS_RAY_DX, RS_RAY_TMIN, RS_RAY_TMAX, RS_DIM_JITTER_X,
                             RS_DIM_JITTER_Y)

import math

import numpy as np

from raysort.params import boolean
from raysort.plugin import Generator
from raysort.rays import RayBatch


cdef void make_rays(const float[::1] eye, const float[::1] fwd, const float[::1] right,
                    const float[::1] up, const int32_t[::1] pixels, const int32_t[::1] samples,
                    int width, int height, int strata, bint jitter, uint32_t seed,
                    float[:, ::1] out) noexcept nogil:
    cdef int n_pix = pixels.shape[0], s, p, i, x, y, a, stratum
    cdef uint32_t seed_k = seed_key(seed), key
    cdef float jx, jy, sx, sy, d[3], norm
    for s in range(samples.shape[0]):
        stratum = samples[s] % (strata * strata)
        for p in range(n_pix):
            i = s * n_pix + p
            x = pixels[p] % width
            y = pixels[p] // width
            jx = jy = 0.5
            if jitter:
                key = sample_key(seed_k, pixels[p], samples[s])
                jx = uniform_at(key, RS_DIM_JITTER_X)
                jy = uniform_at(key, RS_DIM_JITTER_Y)
            # stratified within the pixel when spp is a square number
            jx = (stratum % strata + jx) / strata
            jy = (stratum // strata + jy) / strata
            sx = 2.0 * (x + jx) / width - 1.0
            sy = 1.0 - 2.0 * (y + jy) / height
            for a in range(3):
                d[a] = fwd[a] + sx * right[a] + sy * up[a]
            norm = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            for a in range(3):
                out[RS_RAY_OX + a, i] = eye[a]
                out[RS_RAY_DX + a, i] = d[a] / norm
            out[RS_RAY_TMIN, i] = 0.0
            out[RS_RAY_TMAX, i] = INFINITY


def _generate(const float[::1] eye, const float[::1] fwd, const float[::1] right,
              const float[::1] up, const int32_t[::1] pixels, const int32_t[::1] samples,
              int width, int height, int strata, bint jitter, uint32_t seed,
              float[:, ::1] out):
    """Typed entry point: make the rays without the GIL."""
    with nogil:
        make_rays(eye, fwd, right, up, pixels, samples, width, height, strata, jitter, seed,
                  out)


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
        _generate(eye, fwd, right, up, pixels, samples, width, height, strata, self.jitter,
                  seed & 0xFFFFFFFF, rays.data)
        return rays
