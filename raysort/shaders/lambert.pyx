"""``lambert``: a Lambertian path tracer (cosine-weighted diffuse bounces)."""
from libc.math cimport sqrtf, M_PI, INFINITY
from libc.string cimport memmove
from libc.stdint cimport int32_t, uint32_t, uint64_t
from raysort._checks cimport parents_weights_bad, slots_bad
from raysort._rng cimport seed_key, uniform_at
from raysort._types cimport (RS_RAY_ROWS, RS_RAY_OX, RS_RAY_DX,
                             RS_DIM_BOUNCE, RS_DIMS_PER_BOUNCE, RS_MAX_DEPTH, rs_prefetch,
                             rs_prefetchw)
from raysort.shaders._shading cimport (LANES, RS_SW, HitBlock, checked_hits, check_shapes,
                                       check_new_rays, consecutive, copy_lanes,
                                       take_rays, take_keys, rs_mask64, rs_list_valid,
                                       rs_record_columns, leave_surfaces, cosine_directions,
                                       keep_lanes, write_ray, write_rays)

import numpy as np

from raysort import isa
from raysort.contract import check_bounce
from raysort.errors import SceneError
from raysort.params import boolean, integer
from raysort.paths import Bounce, ShadowRays
from raysort.plugin import Shader
from raysort.rays import RayBatch, aligned_empty


cdef enum:
    ROWS_AHEAD = 2 * LANES  # rays between a prefetch of the input rows and their use
    LINE_VALUES = 16        # 4-byte values in a 64-byte cache line

# A face's shading data in half a cache line (a hit is one random access, and the
# records of a scene take half the cache they would in a line each): its geometric
# normal, albedo, and which row of the emitters' table holds its emission (int32 bits,
# -1 for a face that does not emit: most faces).
cdef enum:
    FACE_NORMAL = 0
    FACE_EMITTER = 3
    FACE_ALBEDO = 4
    FACE_FLOATS = 8


def _face_records(const float[:, ::1] normals, const float[:, ::1] albedo,
                  const float[:, ::1] emission, float[:, ::1] out, float[:, ::1] emitters):
    """Fill ``out`` (m, FACE_FLOATS) with the face records in one pass: the normal
    (:meth:`raysort.scene.Scene.face_normals`), the albedo, and the row of ``emitters``
    (one per face with an emission other than zero, in face order; (k, 4)) that gets its
    emission.  ValueError if ``emitters`` has not one row per emitting face."""
    cdef Py_ssize_t m = normals.shape[0], f, e = 0
    cdef Py_ssize_t k = emitters.shape[0]
    cdef int a
    cdef bint short = False
    cdef float *rec
    if (normals.shape[1] != 3 or albedo.shape[0] != m or albedo.shape[1] != 3
            or emission.shape[0] != m or emission.shape[1] != 3 or out.shape[0] != m
            or out.shape[1] != FACE_FLOATS or emitters.shape[1] != 4):
        raise ValueError("_face_records: normals, albedo, emission (m, 3), "
                         "out (m, FACE_FLOATS) and emitters (k, 4) expected")
    with nogil:
        for f in range(m):
            rec = &out[f, 0]
            for a in range(FACE_FLOATS):
                rec[a] = 0.0
            for a in range(3):
                rec[FACE_NORMAL + a] = normals[f, a]
                rec[FACE_ALBEDO + a] = albedo[f, a]
            (<int32_t *> rec)[FACE_EMITTER] = -1
            if (emission[f, 0] != 0) | (emission[f, 1] != 0) | (emission[f, 2] != 0):
                if e == k:
                    short = True
                    break
                (<int32_t *> rec)[FACE_EMITTER] = <int32_t> e
                for a in range(4):
                    emitters[e, a] = emission[f, a] if a < 3 else <float>0.0
                e += 1
    if short or e != k:
        raise ValueError(f"_face_records: emitters has {k} rows, not one per emitting face")


# the record columns the shader reads per hit: the normal, the albedo, the emitter row
cdef enum:
    RECORD_READ = 7
cdef int RECORD_COLUMNS[RECORD_READ]
RECORD_COLUMNS[:] = [FACE_NORMAL, FACE_NORMAL + 1, FACE_NORMAL + 2,
                     FACE_ALBEDO, FACE_ALBEDO + 1, FACE_ALBEDO + 2, FACE_EMITTER]

#: the face record's layout, for Python (tests)
FACE_LAYOUT = dict(normal=FACE_NORMAL, emitter=FACE_EMITTER, albedo=FACE_ALBEDO,
                   floats=FACE_FLOATS)


cdef struct ShadeParams:
    int depth
    int max_depth
    uint32_t seed
    bint russian_roulette
    int rr_depth


cdef inline void prefetch_new_rays(float *rays, Py_ssize_t ray_stride, float *weight,
                                   Py_ssize_t weight_stride, int32_t *parent) noexcept nogil:
    """Ask, for writing, for the cache line at ``rays`` in each of a batch's
    ``RS_RAY_ROWS`` rows (``ray_stride`` bytes apart), at ``weight`` in each of three
    rows (``weight_stride`` bytes apart) and at ``parent``: where new rays go."""
    cdef int r
    for r in range(RS_RAY_ROWS):
        rs_prefetchw(<char *> rays + r * ray_stride)
    for r in range(3):
        rs_prefetchw(<char *> weight + r * weight_stride)
    rs_prefetchw(parent)

cdef enum:
    CHECK_RUN = 512         # new paths checked together (18 kB of parents and weights)


cdef inline int new_paths_bad(const int32_t[::1] parent, const float[:, ::1] weight,
                              const int32_t *slot, int a, int b, int n,
                              uint32_t slots) noexcept nogil:
    """The Bounce contract's rules (``_checks.pxd``, as :func:`raysort.contract.check_bounce`)
    on the new paths ``a..b``: parents ascending in [0, n) (from ``parent[a - 1]``),
    weights finite and, unless ``slot`` is NULL, slots in [0, slots)."""
    if b <= a:
        return 0
    return parents_weights_bad(&parent[0], <const uint32_t *> &weight[0, 0],
                               <const uint32_t *> &weight[1, 0],
                               <const uint32_t *> &weight[2, 0], a, b, n) \
        | (slots_bad(slot, a, b, slots) if slot != NULL else 0)


cdef inline int32_t toward_light(const HitBlock *b, int h, float lx, float ly, float lz,
                                 float *w0, float *w1, float *w2, float *dist,
                                 float *weight) noexcept nogil:
    """Lane ``h``'s shadow ray toward the point light at (lx, ly, lz): its direction, its
    length and its weight, BRDF (albedo / pi aside) * cosine / distance^2; 0 when the
    light is behind the surface or at the hit point (no ray), else 1."""
    cdef float v0 = lx - b.o[0][h]
    cdef float v1 = ly - b.o[1][h]
    cdef float v2 = lz - b.o[2][h]
    cdef float dist2 = v0 * v0 + v1 * v1 + v2 * v2
    cdef float cosl = v0 * b.nrm[0][h] + v1 * b.nrm[1][h] + v2 * b.nrm[2][h]
    cdef float d = sqrtf(dist2)
    cdef float inv_dist = <float>1.0 / d
    w0[0] = v0 * inv_dist
    w1[0] = v1 * inv_dist
    w2[0] = v2 * inv_dist
    dist[0] = d
    weight[0] = cosl * inv_dist * <float>(1.0 / M_PI) / dist2
    return (cosl > 0) & (dist2 > 0)


cdef int light_lanes(HitBlock *b, float reflect[3][LANES], const int32_t *hit_slot,
                     const float[:, ::1] light_pos, const float[:, ::1] light_int,
                     float[:, ::1] sh_rays, int32_t[::1] sh_parent, int32_t[::1] sh_slot,
                     float[:, ::1] sh_contrib, int m) noexcept nogil:
    """The shadow rays of the block's lit lanes toward the scene's one light, a vector
    at a time, as rays ``m, m + 1, ...``; returns the next free ray."""
    cdef float weight[LANES]           # a shadow ray's BRDF * cosine / distance^2
    cdef int32_t ok[LANES]             # 1 where the lane's shadow ray is made
    cdef float lit[LANES]              # a shadow ray's contribution, lane by lane
    cdef float lx = light_pos[0, 0], ly = light_pos[0, 1], lz = light_pos[0, 2], intensity
    cdef float *row
    cdef uint64_t keep
    cdef int h, j, c, count = 0
    cdef Py_ssize_t room = sh_parent.shape[0] - m     # values each output row can take
    for h in range(b.n):
        ok[h] = toward_light(b, h, lx, ly, lz, &b.w[0][h], &b.w[1][h], &b.w[2][h],
                             &b.tmax[h], &weight[h])
    keep = rs_mask64(ok, b.n)
    for h in range(b.n):
        count += ok[h]
    if count == 0:
        return m
    write_rays(b, keep, count, sh_rays, m, 1, room)
    if count == b.n:        # every lane: copies
        for c in range(3):
            intensity = light_int[0, c]
            row = &sh_contrib[c, m]
            for j in range(count):
                row[j] = reflect[c][j] * intensity * weight[j]
        copy_lanes(&sh_parent[m], b.ray, count)
        copy_lanes(&sh_slot[m], hit_slot, count)
    else:                   # the lit lanes, a vector at a time
        for c in range(3):
            intensity = light_int[0, c]
            for j in range(b.n):
                lit[j] = reflect[c][j] * intensity * weight[j]
            keep_lanes(lit, b.n, keep, &sh_contrib[c, m], count, room)
        keep_lanes(b.ray, b.n, keep, &sh_parent[m], count, room)
        keep_lanes(hit_slot, b.n, keep, &sh_slot[m], count, room)
    return m + count


cdef int light_hits(const HitBlock *b, float reflect[3][LANES], const int32_t *hit_slot,
                    const float[:, ::1] light_pos, const float[:, ::1] light_int,
                    float[:, ::1] sh_rays, int32_t[::1] sh_parent, int32_t[::1] sh_slot,
                    float[:, ::1] sh_contrib, int m) noexcept nogil:
    """The shadow rays of the block's hits toward each of several lights, hit by hit and
    light by light (the lanes' operations of :func:`light_lanes`), as rays ``m, m + 1,
    ...``; returns the next free ray."""
    cdef float w0, w1, w2, dist, weight
    cdef int h, c, L
    for h in range(b.n):
        for L in range(light_pos.shape[0]):
            if not toward_light(b, h, light_pos[L, 0], light_pos[L, 1], light_pos[L, 2],
                                &w0, &w1, &w2, &dist, &weight):
                continue
            write_ray(b, h, w0, w1, w2, dist, sh_rays, m)
            for c in range(3):
                sh_contrib[c, m] = reflect[c][h] * light_int[L, c] * weight
            sh_parent[m] = b.ray[h]
            sh_slot[m] = hit_slot[h]
            m += 1
    return m


cdef void shade_batch(const float[:, ::1] rays, const float[::1] t, const int32_t[::1] prim,
                      const float[:, ::1] faces, const float[:, ::1] emitters,
                      const float[::1] sky,
                      const int32_t[::1] pixel, const int32_t[::1] sample,
                      const int32_t[::1] slot, const float[:, ::1] thr, ShadeParams prm,
                      const float[:, ::1] light_pos, const float[:, ::1] light_int,
                      double[:, ::1] radiance,
                      float[:, ::1] next_rays, int32_t[::1] next_parent, float[:, ::1] next_thr,
                      float[:, ::1] sh_rays, int32_t[::1] sh_parent, int32_t[::1] sh_slot,
                      float[:, ::1] sh_contrib, int *n_next, int *n_shadow,
                      int *paths_bad) noexcept nogil:
    cdef int n = prim.shape[0], blk, i0, i, c, h, j, line, count, k = 0, m = 0, e
    cdef int bad = 0                   # a new path breaks the Bounce contract (see below)
    cdef int k_done = 0, m_done = 0    # the new paths before these are checked
    cdef uint32_t slots = <uint32_t> radiance.shape[0]
    cdef uint32_t dim = RS_DIM_BOUNCE + RS_DIMS_PER_BOUNCE * prm.depth   # types.h's budget
    cdef uint32_t seed_k = seed_key(prm.seed)
    cdef bint bounce = prm.depth < prm.max_depth
    cdef bint roulette = bounce and prm.russian_roulette and prm.depth >= prm.rr_depth
    cdef float q, best
    cdef HitBlock b
    cdef float reflect[3][LANES]       # the path's weight after this bounce (thr * albedo)
    cdef uint32_t key[LANES]           # the path's random-number key
    cdef uint64_t keep                 # the lanes that make a ray (bit h: lane h)
    cdef int32_t face[LANES]           # the face each lane's ray hit
    cdef float albedo[3][LANES]        # and its albedo
    cdef int32_t emitter[LANES]        # and its row of the emitters' table (-1: none)
    cdef float *columns[RECORD_READ]   # where rs_record_columns puts a record's columns
    cdef int32_t iota[LANES]           # 0, 1, 2, ...
    cdef int nb
    cdef bint special
    cdef int32_t hit_slot[LANES]       # the path's accumulator row
    for c in range(3):
        columns[c] = b.nrm[c]
        columns[3 + c] = albedo[c]
    columns[6] = <float *> emitter
    for h in range(LANES):
        iota[h] = h
    for blk in range((n + LANES - 1) // LANES):
        i0 = blk * LANES
        # the Bounce contract's rules on the paths written since the last check, while
        # they are in L1 (the pipeline's check_bounce need not read them again)
        if k - k_done >= CHECK_RUN:
            bad |= new_paths_bad(next_parent, next_thr, NULL, k_done, k, n, slots)
            k_done = k
        if m - m_done >= CHECK_RUN:
            bad |= new_paths_bad(sh_parent, sh_contrib, &sh_slot[0], m_done, m, n, slots)
            m_done = m
        # Prefetches (hints; the results do not depend on them).  The kernel reads
        # fourteen rows and writes up to twenty-five side by side, more streams than
        # the hardware prefetchers follow: a later block's input lines, the next
        # block's output lines (for writing), and the next block's face records.
        for line in range(LANES // LINE_VALUES):
            j = i0 + ROWS_AHEAD + line * LINE_VALUES
            if j < n:
                for c in range(3):
                    rs_prefetch(&rays[RS_RAY_OX + c, j])
                    rs_prefetch(&rays[RS_RAY_DX + c, j])
                    rs_prefetch(&thr[c, j])
                rs_prefetch(&t[j])
                rs_prefetch(&prim[j])
                rs_prefetch(&pixel[j])
                rs_prefetch(&sample[j])
                rs_prefetch(&slot[j])
        for line in range(LANES // LINE_VALUES):
            j = LANES + line * LINE_VALUES
            if m + j < sh_parent.shape[0]:
                prefetch_new_rays(&sh_rays[0, m + j], sh_rays.strides[0],
                                  &sh_contrib[0, m + j], sh_contrib.strides[0],
                                  &sh_parent[m + j])
                rs_prefetchw(&sh_slot[m + j])
            if k + j < next_parent.shape[0]:
                prefetch_new_rays(&next_rays[0, k + j], next_rays.strides[0],
                                  &next_thr[0, k + j], next_thr.strides[0], &next_parent[k + j])
        for i in range(i0 + LANES, min(i0 + 2 * LANES, n)):
            if prim[i] >= 0:
                rs_prefetch(&faces[prim[i], 0])
        # the hits of the next LANES rays into a block, listed a vector at a time, with
        # their faces' records; then, in ray order, misses add the sky and emitters
        # their light (a block's sums in the same order as ray by ray)
        nb = min(LANES, n - i0)
        b.n = rs_list_valid(&prim[i0], nb, iota, b.ray, face)
        if b.n:
            for h in range(b.n):
                b.ray[h] += i0
            for h in range(b.n, (b.n + RS_SW - 1) // RS_SW * RS_SW):
                face[h] = face[0]       # whole lane groups are read
            rs_record_columns(&faces[0, 0], face, b.n, RECORD_COLUMNS, RECORD_READ, columns)
        special = b.n < nb
        for h in range(b.n):
            special |= emitter[h] >= 0
        if special:
            h = 0
            for i in range(i0, i0 + nb):
                if prim[i] < 0:
                    for c in range(3):
                        radiance[slot[i], c] += thr[c, i] * sky[c]
                    continue
                e = emitter[h]
                h += 1
                if e >= 0:
                    for c in range(3):
                        radiance[slot[i], c] += thr[c, i] * emitters[e, c]
        if b.n == 0:
            continue
        take_rays(&b, rays, t)
        if consecutive(&b):         # every ray of the block hit: copies of the rows
            i = b.ray[0]
            for c in range(3):
                copy_lanes(reflect[c], &thr[c, i], b.n)
            copy_lanes(hit_slot, &slot[i], b.n)
        else:
            for h in range(b.n):
                i = b.ray[h]
                for c in range(3):
                    reflect[c][h] = thr[c, i]
                hit_slot[h] = slot[i]
        if bounce:
            take_keys(&b, seed_k, pixel, sample, key)
        for c in range(3):
            for h in range(b.n):
                reflect[c][h] = reflect[c][h] * albedo[c][h]
        leave_surfaces(&b)
        # next-event estimation toward point lights: a shadow ray per lit hit and light,
        # in the order of the hits (the shadow rays' parents ascend)
        if light_pos.shape[0] == 1:
            m = light_lanes(&b, reflect, hit_slot, light_pos, light_int, sh_rays, sh_parent,
                            sh_slot, sh_contrib, m)
        elif light_pos.shape[0] > 1:
            m = light_hits(&b, reflect, hit_slot, light_pos, light_int, sh_rays, sh_parent,
                           sh_slot, sh_contrib, m)
        if not bounce:
            continue
        # a cosine-weighted bounce per hit (per survivor of Russian roulette, off by default)
        for h in range(b.n):
            b.u1[h] = uniform_at(key[h], dim)
            b.u2[h] = uniform_at(key[h], dim + 1)
            b.tmax[h] = INFINITY
        cosine_directions(&b)
        keep = 0                    # (unused when every lane goes on)
        count = b.n
        if roulette:
            count = 0
            for h in range(b.n):
                best = reflect[0][h]
                for c in range(1, 3):
                    if reflect[c][h] > best:
                        best = reflect[c][h]
                q = best if best < <float>0.95 else <float>0.95
                if uniform_at(key[h], dim + 2) >= q:
                    continue
                for c in range(3):
                    reflect[c][h] = reflect[c][h] / q
                keep |= <uint64_t> 1 << h
                count += 1
        if count == 0:
            continue
        write_rays(&b, keep, count, next_rays, k, 1, next_parent.shape[0] - k)
        if count == b.n:            # every lane: copies
            for c in range(3):
                copy_lanes(&next_thr[c, k], reflect[c], count)
            copy_lanes(&next_parent[k], b.ray, count)
        else:
            for c in range(3):
                keep_lanes(reflect[c], b.n, keep, &next_thr[c, k], count, next_parent.shape[0] - k)
            keep_lanes(b.ray, b.n, keep, &next_parent[k], count, next_parent.shape[0] - k)
        k += count
    bad |= new_paths_bad(next_parent, next_thr, NULL, k_done, k, n, slots) \
        | new_paths_bad(sh_parent, sh_contrib, &sh_slot[0] if m else NULL, m_done, m, n, slots)
    n_next[0] = k
    n_shadow[0] = m
    paths_bad[0] = bad


def _pack_rows(float[::1] flat, Py_ssize_t rows, Py_ssize_t n):
    """The first ``n`` values of each of the ``rows`` rows of ``flat`` (a whole
    ``len(flat) // rows`` apart) moved together in place: returns ``flat[:rows * n]`` as a
    C-contiguous (rows, n) array, so the paths need not copy a slice of rows."""
    cdef Py_ssize_t r, capacity = flat.shape[0] // rows
    if not 0 <= n <= capacity:
        raise ValueError("_pack_rows: 0 <= n <= len(flat) // rows expected")
    with nogil:
        for r in range(1, rows if 0 < n < capacity else 0):
            memmove(&flat[r * n], &flat[r * capacity], n * sizeof(float))
    return np.asarray(flat)[:rows * n].reshape(rows, n)


def _shade(const float[:, ::1] rays, const float[::1] t, const int32_t[::1] prim,
           const float[:, ::1] faces, const float[:, ::1] emitters, const float[::1] sky,
           const int32_t[::1] pixel,
           const int32_t[::1] sample, const int32_t[::1] slot, const float[:, ::1] thr,
           int depth, int max_depth,
           uint32_t seed, bint russian_roulette, int rr_depth,
           const float[:, ::1] light_pos, const float[:, ::1] light_int,
           double[:, ::1] radiance, float[:, ::1] next_rays, int32_t[::1] next_parent,
           float[:, ::1] next_thr, float[:, ::1] sh_rays, int32_t[::1] sh_parent,
           int32_t[::1] sh_slot, float[:, ::1] sh_contrib):
    """Typed entry point: shade a batch without the GIL; returns (next rays, shadow rays,
    whether a new path breaks the Bounce contract: a parent out of order or range, a
    weight not finite, a slot out of range).  ValueError at arrays of inconsistent shapes;
    trusts the values that ``LambertShader.shade`` checks (``checked_hits``) or makes:
    prim (a row of ``faces``), slot (of ``radiance``), the records' emitter rows (of
    ``emitters``: ``_face_records``), room for a next ray per hit and a shadow ray per hit
    and light."""
    cdef ShadeParams prm = ShadeParams(depth, max_depth, seed, russian_roulette, rr_depth)
    cdef int k = 0, m = 0, bad = 0
    check_shapes("_shade", prim.shape[0], rays, t, prim, pixel, sample, slot, thr, radiance)
    if (faces.shape[1] != FACE_FLOATS or emitters.shape[1] < 3 or sky.shape[0] < 3
            or light_pos.shape[1] != 3 or light_int.shape[0] != light_pos.shape[0]
            or light_int.shape[1] != 3):
        raise ValueError("_shade: faces (m, FACE_FLOATS), emitters (k, >= 3), sky (3,) and "
                         "light_pos, light_int (lights, 3) expected")
    check_new_rays("_shade", "next", next_rays, next_parent, next_thr)
    check_new_rays("_shade", "shadow", sh_rays, sh_parent, sh_contrib)
    if sh_slot.shape[0] < sh_parent.shape[0]:
        raise ValueError("_shade: sh_slot must hold a value per shadow ray's parent")
    with nogil:
        shade_batch(rays, t, prim, faces, emitters, sky, pixel, sample, slot, thr,
                    prm, light_pos, light_int, radiance, next_rays, next_parent, next_thr,
                    sh_rays, sh_parent, sh_slot, sh_contrib, &k, &m, &bad)
    return k, m, bool(bad)


class LambertShader(Shader):
    """Lambertian path tracing: emission, a sky for escaped rays, diffuse bounces.

    At each hit the path adds the face's emission, optionally one shadow ray
    per point light (next-event estimation), and continues with a
    cosine-weighted direction, its throughput multiplied by the albedo.  A
    ray that escapes adds the sky radiance.  Random numbers are a hash of
    (seed, pixel, sample, bounce), so ray order and threads cannot change
    the image.  With the defaults it matches the paper's setup (depth 2, no
    Russian roulette) and, with ``shadow_rays=False``, no shadow rays.

    ================  ======  =======  ======================================
    parameter         type    default  meaning
    ================  ======  =======  ======================================
    max_depth         int     2        diffuse bounces after the primary hit
                                       (rays are traced at depths 0..max_depth)
    shadow_rays       bool    None     trace a shadow ray to each point light;
                                       None: when the scene has point lights
    russian_roulette  bool    False    end paths at random by throughput
    rr_depth          int     1        first depth at which roulette applies
    ================  ======  =======  ======================================
    """

    trusted = True
    # the kernel checks the parents, weights and slots of the paths it makes by the
    # Bounce contract's rules as it writes them (the pipeline's check_bounce need not)
    _checks_its_paths = True

    def __init__(self, *, max_depth=2, shadow_rays=None, russian_roulette=False, rr_depth=1):
        self.max_depth = integer("max_depth", max_depth, 0, RS_MAX_DEPTH)
        self.shadow_rays = boolean("shadow_rays", shadow_rays, allow_none=True)
        self.russian_roulette = boolean("russian_roulette", russian_roulette)
        self.rr_depth = integer("rr_depth", rr_depth, 0, RS_MAX_DEPTH)
        self._prepared = None

    def prepare(self, scene):
        """Cache the scene's face records and lights (``render`` calls this first)."""
        lights = scene.lights if self.shadow_rays in (None, True) else []
        emission = np.ascontiguousarray(scene.emission, dtype=np.float32)
        faces = aligned_empty((len(scene.faces), FACE_FLOATS), np.float32, FACE_FLOATS * 4)
        emitters = np.empty((np.count_nonzero(emission.any(axis=1)), 4), np.float32)
        _face_records(scene.face_normals(),
                      np.ascontiguousarray(scene.albedo, dtype=np.float32), emission, faces,
                      emitters)
        self._prepared = (
            scene,
            faces,
            emitters,
            np.ascontiguousarray([lt.position for lt in lights], dtype=np.float32).reshape(-1, 3),
            np.ascontiguousarray([lt.intensity for lt in lights], dtype=np.float32).reshape(-1, 3),
        )

    def shade(self, scene, rays, hits, paths, depth, seed, radiance):
        if self._prepared is None or self._prepared[0] is not scene:
            self.prepare(scene)
        _, faces, emitters, light_pos, light_int = self._prepared
        # the rays that make new ones (each at most one bounce ray and one shadow ray
        # per light, so the new batches are made no larger), the inputs checked
        n_hit = checked_hits("lambert", len(rays), rays.data, hits.t, hits.prim, paths.pixel,
                             paths.sample, paths.slot, paths.throughput, len(faces), radiance)
        k_max = n_hit if depth < self.max_depth else 0  # the last depth makes no bounce
        next_rays = RayBatch._unfilled(k_max)    # _shade writes every row of its rays
        next_parent = np.empty(k_max, dtype=np.int32)
        next_thr = np.empty(3 * k_max, dtype=np.float32)     # rows k_max apart, then packed
        m_max = n_hit * len(light_pos)
        sh_rays = RayBatch._unfilled(m_max)
        sh_parent = np.empty(m_max, dtype=np.int32)
        sh_slot = np.empty(m_max, dtype=np.int32)
        sh_contrib = np.empty((3, m_max), dtype=np.float32)
        k, m, paths_bad = isa.module("shaders.lambert")._shade(
            rays.data, hits.t, hits.prim, faces, emitters, scene.sky, paths.pixel, paths.sample,
            paths.slot, paths.throughput, depth, self.max_depth, seed & 0xFFFFFFFF,
            self.russian_roulette, self.rr_depth, light_pos, light_int, radiance,
            next_rays.data, next_parent, next_thr.reshape(3, k_max), sh_rays.data, sh_parent,
            sh_slot, sh_contrib)
        shadow = None
        if m:
            shadow = ShadowRays(sh_rays.truncate(m), sh_parent[:m], sh_slot[:m],
                                sh_contrib[:, :m])
        bounce = Bounce(next_rays.truncate(k), next_parent[:k], _pack_rows(next_thr, 3, k),
                        shadow)
        if paths_bad:       # the contract's check says what is wrong, naming the shader
            if m and not np.isfinite(sh_contrib[:, :m]).all():  # the scene's lights, not a bug
                raise SceneError("a shadow ray's contribution is not a float32 number (inf "
                                 "or NaN): a point light of the scene is too bright, too far "
                                 "away or too close to a surface")
            check_bounce(self, bounce, len(rays), len(radiance), radiance)
            raise AssertionError("lambert's own check found a path that check_bounce passes")
        return bounce
