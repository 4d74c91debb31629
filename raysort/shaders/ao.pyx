"""``ao``: ambient occlusion, the fraction of the hemisphere above each primary hit that is
unoccluded within a distance.

The standard "AO" ray kind of ray-traversal studies (Aila and Laine, "Understanding the
efficiency of ray traversal on GPUs", HPG 2009, and most ray-sorting work since): short
any-hit rays, cosine distributed around the surface normal, from every primary hit.
"""
from libc.stdint cimport int32_t, uint32_t
from raysort._rng cimport seed_key, uniform_at
from raysort._types cimport RS_DIM_AO
from raysort.shaders._shading cimport (LANES, HitBlock, checked_hits, check_shapes,
                                       check_new_rays, take_rays, take_normals,
                                       take_keys, leave_surfaces, cosine_directions,
                                       write_rays)

import numpy as np

from raysort import isa
from raysort.params import integer, number
from raysort.paths import Bounce, ShadowRays
from raysort.plugin import Shader
from raysort.rays import RayBatch

# Random-number dimensions (the budget of types.h): AO ray k of a path draws RS_DIM_AO + 2k
# and RS_DIM_AO + 2k + 1, a block of its own that no generator or bounce shares.  The cap
# on samples also bounds memory: a batch of n primary rays makes up to n * samples AO
# rays at once.
cdef enum:
    MAX_SAMPLES = 256

#: the scene's bounding-box diagonal times this is the default occlusion distance
DEFAULT_DISTANCE_FRACTION = 0.1


cdef int ao_batch(const float[:, ::1] rays, const float[::1] t, const int32_t[::1] prim,
                  const float[:, ::1] normals, const int32_t[::1] pixel,
                  const int32_t[::1] sample, const int32_t[::1] slot, const float[:, ::1] thr,
                  int samples, float distance, float background, uint32_t seed,
                  double[:, ::1] radiance, float[:, ::1] ao_rays, int32_t[::1] ao_parent,
                  int32_t[::1] ao_slot, float[:, ::1] ao_weight) noexcept nogil:
    """Make ``samples`` AO rays per hit (misses add the background); returns how many."""
    cdef int n = prim.shape[0], blk, i0, i, f, c, h, k, m = 0
    cdef uint32_t seed_k = seed_key(seed)
    cdef HitBlock b
    cdef uint32_t key[LANES]
    for blk in range((n + LANES - 1) // LANES):
        i0 = blk * LANES
        b.n = 0
        for i in range(i0, min(i0 + LANES, n)):
            f = prim[i]
            if f < 0:
                for c in range(3):
                    radiance[slot[i], c] += thr[c, i] * background
                continue
            b.ray[b.n] = i
            b.n += 1
        if b.n == 0:
            continue
        take_rays(&b, rays, t)
        take_normals(&b, prim, &normals[0, 0], 3)
        take_keys(&b, seed_k, pixel, sample, key)
        leave_surfaces(&b)
        for h in range(b.n):
            b.tmax[h] = distance
        # the samples of a hit are consecutive rays (their parents ascend)
        for k in range(samples):
            for h in range(b.n):
                b.u1[h] = uniform_at(key[h], RS_DIM_AO + 2 * k)
                b.u2[h] = uniform_at(key[h], RS_DIM_AO + 2 * k + 1)
            cosine_directions(&b)
            write_rays(&b, 0, b.n, ao_rays, m + k, samples, 0)   # every lane
        for h in range(b.n):
            i = b.ray[h]
            for k in range(samples):
                for c in range(3):
                    ao_weight[c, m + k] = thr[c, i] / samples
                ao_parent[m + k] = i
                ao_slot[m + k] = slot[i]
            m += samples
    return m


def _ao(const float[:, ::1] rays, const float[::1] t, const int32_t[::1] prim,
        const float[:, ::1] normals, const int32_t[::1] pixel, const int32_t[::1] sample,
        const int32_t[::1] slot, const float[:, ::1] thr, int samples, float distance,
        float background, uint32_t seed, double[:, ::1] radiance, float[:, ::1] ao_rays,
        int32_t[::1] ao_parent, int32_t[::1] ao_slot, float[:, ::1] ao_weight):
    """Typed entry point: make the AO rays of a batch without the GIL; returns their count.
    ValueError at arrays of inconsistent shapes or ``samples`` out of 1..MAX_SAMPLES;
    trusts the values that ``AOShader.shade`` checks (``checked_hits``) or makes: prim (a
    row of ``normals``), slot (of ``radiance``), room for ``samples`` AO rays per hit."""
    cdef int m
    check_shapes("_ao", prim.shape[0], rays, t, prim, pixel, sample, slot, thr, radiance)
    if normals.shape[1] != 3 or not 1 <= samples <= MAX_SAMPLES:
        raise ValueError(f"_ao: normals (m, 3) and samples 1..{MAX_SAMPLES} expected")
    check_new_rays("_ao", "AO", ao_rays, ao_parent, ao_weight)
    if ao_slot.shape[0] < ao_parent.shape[0]:
        raise ValueError("_ao: ao_slot must hold a value per AO ray's parent")
    with nogil:
        m = ao_batch(rays, t, prim, normals, pixel, sample, slot, thr, samples, distance,
                     background, seed, radiance, ao_rays, ao_parent, ao_slot, ao_weight)
    return m


class AOShader(Shader):
    """Ambient occlusion: the unoccluded fraction of the hemisphere at each primary hit.

    At every primary hit, ``samples`` any-hit rays leave the surface (on the side the
    camera sees, from the same offset point ``lambert`` uses) in cosine-distributed
    directions and look for geometry closer than ``distance``; each unoccluded one adds
    ``1 / samples`` to the pixel, so a pixel's value (all three channels) is the
    cosine-weighted unoccluded fraction, averaged over the pixel's samples.  A primary ray
    that hits nothing adds ``background``.  Paths end at the primary hit (no bounces).
    Random numbers are a hash of (seed, pixel, sample, AO ray), as in ``lambert``, so the
    image is bit-identical for every sorter, traversal and thread count.

    ==========  ======  =======  =====================================================
    parameter   type    default  meaning
    ==========  ======  =======  =====================================================
    samples     int     8        AO rays per primary hit (1..256)
    distance    float   None     occlusion distance (> 0, may be inf); None: a tenth
                                 of the scene's bounding-box diagonal
    background  float   1.0      value of pixels whose primary ray hits nothing
    ==========  ======  =======  =====================================================
    """

    def __init__(self, *, samples=8, distance=None, background=1.0):
        self.samples = integer("samples", samples, 1, MAX_SAMPLES)
        self.distance = None if distance is None else number("distance", distance, 0,
                                                             lo_open=True, allow_inf=True)
        self.background = number("background", background, 0)
        self._prepared = None

    def distance_for(self, scene):
        """The occlusion distance used in ``scene`` (resolves ``distance=None``)."""
        if self.distance is not None:
            return self.distance
        lo, hi = scene.bounds.astype(np.float64)
        return float(np.linalg.norm(hi - lo)) * DEFAULT_DISTANCE_FRACTION

    def prepare(self, scene):
        self._prepared = (scene, scene.face_normals(), self.distance_for(scene))

    def shade(self, scene, rays, hits, paths, depth, seed, radiance):
        if self._prepared is None or self._prepared[0] is not scene:
            self.prepare(scene)
        _, normals, distance = self._prepared
        n_hit = checked_hits("ao", len(rays), rays.data, hits.t, hits.prim, paths.pixel,
                             paths.sample, paths.slot, paths.throughput, len(normals), radiance)
        samples = integer("samples", self.samples, 1, MAX_SAMPLES)     # a script may set it
        m_max = n_hit * samples                 # at most `samples` rays per hit
        ao_rays = RayBatch._unfilled(m_max)      # _ao writes every row of its rays
        ao_parent = np.empty(m_max, dtype=np.int32)
        ao_slot = np.empty(m_max, dtype=np.int32)
        ao_weight = np.empty((3, m_max), dtype=np.float32)
        m = isa.module("shaders.ao")._ao(
            rays.data, hits.t, hits.prim, normals, paths.pixel, paths.sample, paths.slot,
            paths.throughput, samples, distance, self.background, seed & 0xFFFFFFFF,
            radiance, ao_rays.data, ao_parent, ao_slot, ao_weight)
        shadow = None
        if m:
            shadow = ShadowRays(ao_rays.truncate(m), ao_parent[:m], ao_slot[:m],
                                ao_weight[:, :m])
        return Bounce(RayBatch(0), np.zeros(0, np.int32), np.zeros((3, 0), np.float32), shadow)
