"""Inline shading helpers the built-in shaders share (``lambert``, ``ao``).

Where a new ray leaves a surface, in which direction, and how it is stored: the
facing normal, the hit point pushed off the surface along it, a cosine-weighted
direction around that normal, and the rays written into a batch's rows.  They are
compiled into each shader, so they cost no call, and every shader that uses them
makes bit for bit the same rays.

A shader lists the hits of up to ``LANES`` rays in a :c:type:`HitBlock`'s ``ray``
and ``n``, and ``take_rays`` and ``take_keys`` fill the block's lanes (structure of
arrays, one lane per hit; copies of the rows when every ray of the range hit), the
normals too with ``take_normals`` or from the shader's own face records (lambert
reads its records a vector at a time: ``rs_record_columns``), and works on the whole
block in loops
without branches that the compiler turns into SIMD code; the same IEEE operations
run in every lane, so a hit's new rays do not depend on its lane or its block.
New rays are written out row by row: a batch's rows lie a whole capacity apart,
and writing a dozen of them ray by ray makes a dozen streams that share cache sets.

Everything is single-precision IEEE arithmetic with no library call whose result
could differ between C libraries: the direction's sine and cosine come from a fixed
polynomial (``unit_circle``), so a shader compiled anywhere with contraction off
(``-ffp-contract=off``, as setup.py builds) makes the same rays bit for bit.
"""
from libc.math cimport sqrtf, fabsf
from libc.stdint cimport int32_t, uint32_t, uint64_t
from libc.string cimport memcpy
from raysort._checks cimport any_hit_bad, slot_bad
from raysort._rng cimport sample_key
from raysort._types cimport RS_RAY_OX, RS_RAY_DX, RS_RAY_TMIN, RS_RAY_TMAX, RS_RAY_ROWS

# How far a new origin is pushed off the surface: this fraction of (1 + the
# largest coordinate of the hit point), enough to clear the float32 rounding
# of the hit point so the new ray does not hit its own surface again.
cdef enum:
    OFFSET_DENOMINATOR = 8192

cdef enum:
    LANES = 64          # the hits of a block (a lane mask is a uint64_t)

cdef extern from "raysort/lanes.h" nogil:
    int RS_SW
    int rs_keep32(const int32_t *src, int n, uint64_t keep, int32_t *dst)
    uint64_t rs_mask64(const int32_t *flag, int n)
    int rs_list_valid(const int32_t *ids, int n, const int32_t *lane, int32_t *pos,
                      int32_t *out)
    void rs_record_columns(const float *table, const int32_t *rows, int n, const int *cols,
                           int k, float *const *out)


cdef inline void copy_lanes(void *dst, const void *src, int n) noexcept nogil:
    """``memcpy`` of ``n`` 4-byte values (a lane's worth each).  A whole block (``n ==
    LANES``, the common case) is a copy of constant size, which the compiler writes out
    as a few vector moves instead of a call into the C library: a block makes a dozen
    such copies, and the calls cost a tenth of a shader's time."""
    if n == LANES:
        memcpy(dst, src, LANES * sizeof(int32_t))
    else:
        memcpy(dst, src, n * sizeof(int32_t))


cdef inline int check_shapes(str shader, Py_ssize_t n_rays, const float[:, ::1] rays,
                             const float[::1] t, const int32_t[::1] prim,
                             const int32_t[::1] pixel, const int32_t[::1] sample,
                             const int32_t[::1] slot, const float[:, ::1] thr,
                             const double[:, ::1] radiance) except -1:
    """The shapes :func:`checked_hits` wants (the shaders' kernels check them too):
    ValueError naming ``shader`` unless the batch (``n_rays``, its rows ``rays``), the
    hits' and the paths' arrays hold the n rays of ``prim`` and radiance is (slots, 3)."""
    cdef Py_ssize_t n = prim.shape[0]
    if rays.shape[0] < RS_RAY_TMAX + 1 or rays.shape[1] < n or n_rays != n:
        raise ValueError(f"{shader}: the batch of {n_rays} rays must hold the {n} rays of "
                         f"hits.prim")
    if t.shape[0] != n or pixel.shape[0] != n or sample.shape[0] != n or slot.shape[0] != n \
            or thr.shape[0] != 3 or thr.shape[1] != n:
        raise ValueError(f"{shader}: hits.t and paths.pixel, sample, slot and throughput "
                         f"(3, n) must hold the {n} rays of hits.prim")
    if radiance.shape[1] != 3:
        raise ValueError(f"{shader}: radiance must be (slots, 3), got "
                         f"({radiance.shape[0]}, {radiance.shape[1]})")
    return 0


cdef inline int check_new_rays(str shader, str name, const float[:, ::1] rays,
                               const int32_t[::1] parent, const float[:, ::1] weight) except -1:
    """ValueError naming ``shader`` and the batch ``name`` unless the new rays' rows,
    their parents and their (3, m) weights hold as many rays (m: ``len(parent)``)."""
    cdef Py_ssize_t m = parent.shape[0]
    if rays.shape[0] != RS_RAY_ROWS or rays.shape[1] < m or weight.shape[0] != 3 \
            or weight.shape[1] < m:
        raise ValueError(f"{shader}: {name} rays ({RS_RAY_ROWS}, >= m) and weights "
                         f"(3, >= m) expected for the m = {m} values of its parents")
    return 0


cdef inline Py_ssize_t checked_hits(str shader, Py_ssize_t n_rays, const float[:, ::1] rays,
                                    const float[::1] t,
                                    const int32_t[::1] prim, const int32_t[::1] pixel,
                                    const int32_t[::1] sample, const int32_t[::1] slot,
                                    const float[:, ::1] thr, Py_ssize_t n_faces,
                                    const double[:, ::1] radiance) except -1:
    """How many of the n rays hit something, after checking what a shader's kernel reads
    (its caller's input, so a shader called from a script cannot read or write outside
    its arrays): the batch (``n_rays``, its rows ``rays``), the hits' and the paths'
    arrays hold the same n rays, every ``prim`` is -1 or a
    face of the scene (fewer than ``n_faces``) and every ``slot`` a row of ``radiance``.
    ValueError, naming the shader and the argument, otherwise.  One pass over prim and
    slot, the one that counts the hits."""
    cdef Py_ssize_t i, n = prim.shape[0], rows = radiance.shape[0], hits = 0
    cdef int bad = 0
    check_shapes(shader, n_rays, rays, t, prim, pixel, sample, slot, thr, radiance)
    with nogil:
        for i in range(n):
            hits += prim[i] >= 0
            bad |= any_hit_bad(prim[i], <uint32_t> n_faces) | slot_bad(slot[i], <uint32_t> rows)
    if bad:
        for i in range(n):
            if any_hit_bad(prim[i], <uint32_t> n_faces):
                raise ValueError(f"{shader}: hits.prim[{i}] = {prim[i]} is neither -1 nor a "
                                 f"face of the scene's {n_faces}")
            if slot_bad(slot[i], <uint32_t> rows):
                raise ValueError(f"{shader}: paths.slot[{i}] = {slot[i]} is not a row of "
                                 f"radiance (0..{rows - 1})")
    return hits


cdef struct HitBlock:
    int n                       # lanes in use
    int32_t ray[LANES]          # the hit ray's index in its batch
    float t[LANES]              # its hit distance
    float d[3][LANES]           # its direction
    float nrm[3][LANES]         # the face normal; after leave_surfaces, facing the ray
    float o[3][LANES]           # the ray's origin; after leave_surfaces, a new ray's
    float u1[LANES]             # two uniform numbers for cosine_directions
    float u2[LANES]
    float w[3][LANES]           # a new ray's direction
    float tmax[LANES]           # and its tmax


cdef inline bint consecutive(const HitBlock *b) noexcept nogil:
    """Whether the block's lanes hold consecutive rays of their batch (every ray of
    a range hit: the common case), so that their values are copied row by row."""
    return b.n > 0 and b.ray[b.n - 1] - b.ray[0] == b.n - 1


cdef inline void take_rays(HitBlock *b, const float[:, ::1] rays,
                           const float[::1] t) noexcept nogil:
    """Fill each lane's ``t``, origin and direction from the rays ``b.ray[:b.n]`` of a
    batch (the ``RS_RAY_*`` rows): copies of the rows when the rays are consecutive,
    else ray by ray."""
    cdef int h, a, i, n = b.n
    if consecutive(b):
        i = b.ray[0]
        copy_lanes(b.t, &t[i], n)
        for a in range(3):
            copy_lanes(b.o[a], &rays[RS_RAY_OX + a, i], n)
            copy_lanes(b.d[a], &rays[RS_RAY_DX + a, i], n)
        return
    for h in range(n):
        i = b.ray[h]
        b.t[h] = t[i]
        for a in range(3):
            b.o[a][h] = rays[RS_RAY_OX + a, i]
            b.d[a][h] = rays[RS_RAY_DX + a, i]


cdef inline void take_normals(HitBlock *b, const int32_t[::1] prim, const float *table,
                              int stride) noexcept nogil:
    """Fill each lane's normal from row ``prim[b.ray[h]]`` of a face table whose rows are
    ``stride`` floats apart and start with the normal."""
    cdef int h, a
    cdef const float *rec
    for h in range(b.n):
        rec = table + <Py_ssize_t> prim[b.ray[h]] * stride
        for a in range(3):
            b.nrm[a][h] = rec[a]


cdef inline void take_keys(const HitBlock *b, uint32_t seed_k, const int32_t[::1] pixel,
                           const int32_t[::1] sample, uint32_t *key) noexcept nogil:
    """``key[h]``: the random-number key (``sample_key``) of each lane's path, from the
    rays' ``pixel`` and ``sample`` (in one loop over consecutive rays that the compiler
    vectorises, when they are)."""
    cdef int h, i
    if consecutive(b):
        i = b.ray[0]
        for h in range(b.n):
            key[h] = sample_key(seed_k, pixel[i + h], sample[i + h])
        return
    for h in range(b.n):
        i = b.ray[h]
        key[h] = sample_key(seed_k, pixel[i], sample[i])


cdef inline void leave_surfaces(HitBlock *b) noexcept nogil:
    """Where each hit goes on: the face normal turned toward the incoming ray and the
    hit point pushed off the surface along it, by ``(1 + its largest coordinate) /
    OFFSET_DENOMINATOR``."""
    cdef int h, n = b.n
    cdef float n0, n1, n2, p0, p1, p2, facing, m, eps
    for h in range(n):
        n0 = b.nrm[0][h]
        n1 = b.nrm[1][h]
        n2 = b.nrm[2][h]
        facing = n0 * b.d[0][h] + n1 * b.d[1][h] + n2 * b.d[2][h]
        n0 = -n0 if facing > 0 else n0
        n1 = -n1 if facing > 0 else n1
        n2 = -n2 if facing > 0 else n2
        p0 = b.o[0][h] + b.t[h] * b.d[0][h]
        p1 = b.o[1][h] + b.t[h] * b.d[1][h]
        p2 = b.o[2][h] + b.t[h] * b.d[2][h]
        m = fabsf(p0)
        m = fabsf(p1) if fabsf(p1) > m else m
        m = fabsf(p2) if fabsf(p2) > m else m
        eps = (<float>1.0 + m) * <float>(1.0 / OFFSET_DENOMINATOR)
        b.nrm[0][h] = n0
        b.nrm[1][h] = n1
        b.nrm[2][h] = n2
        b.o[0][h] = p0 + eps * n0
        b.o[1][h] = p1 + eps * n1
        b.o[2][h] = p2 + eps * n2


cdef inline void unit_circle(float u, float *c, float *s) noexcept nogil:
    """The point (``c``, ``s``) of the unit circle at the angle ``2 pi u - pi / 4``, for
    ``u`` in [0, 1): uniform ``u`` gives a uniform angle over a whole turn.

    ``4u`` splits exactly into a quadrant ``q`` and an offset in it; the offset is an
    angle in [-pi/4, pi/4), where Cephes' single-precision minimax polynomials for sin
    and cos (``sinf.c``, S. L. Moshier) are accurate to about one ulp, and swapping and
    negating them turns the point by ``q`` quarter turns (exact)."""
    cdef float v = u * <float>4.0
    cdef int q = <int>v
    cdef float x = (v - <float>q - <float>0.5) * <float>1.5707963267948966
    cdef float z = x * x
    cdef float sin_x = ((<float>-1.9515295891e-4 * z + <float>8.3321608736e-3) * z
                        - <float>1.6666654611e-1) * z * x + x
    cdef float cos_x = (((<float>2.443315711809948e-5 * z - <float>1.388731625493765e-3) * z
                         + <float>4.166664568298827e-2) * z * z - <float>0.5 * z) + <float>1.0
    # (cos, sin) of x + q quarter turns: (c, s), (-s, c), (-c, -s), (s, -c)
    cdef float a = sin_x if q & 1 else cos_x
    cdef float b = cos_x if q & 1 else sin_x
    c[0] = -a if q == 1 or q == 2 else a
    s[0] = -b if q >= 2 else b


cdef inline void cosine_directions(HitBlock *b) noexcept nogil:
    """A cosine-weighted direction ``w`` around each (unit, facing) normal from the lane's
    ``u1``, ``u2`` in [0, 1): ``cos(angle to the normal) = sqrt(1 - u1)``, so it is never
    tangent, and the azimuth is ``unit_circle(u2)``.  The tangent frame is Duff et al.
    2017's branchless orthonormal basis; ``tmax`` is left to the caller."""
    cdef int h, n = b.n
    cdef float n0, n1, n2, u1, r, along, sgn, aa, bb, cos_phi, sin_phi, x, y
    for h in range(n):
        n0 = b.nrm[0][h]
        n1 = b.nrm[1][h]
        n2 = b.nrm[2][h]
        u1 = b.u1[h]
        r = sqrtf(u1)
        along = sqrtf(<float>1.0 - u1)
        sgn = <float>1.0 if n2 >= 0 else <float>-1.0
        aa = <float>-1.0 / (sgn + n2)
        bb = n0 * n1 * aa
        unit_circle(b.u2[h], &cos_phi, &sin_phi)
        x = r * cos_phi
        y = r * sin_phi
        # x * tangent + y * bitangent + along * normal, the basis written out
        b.w[0][h] = x * (<float>1.0 + sgn * n0 * n0 * aa) + y * bb + along * n0
        b.w[1][h] = x * (sgn * bb) + y * (sgn + n1 * n1 * aa) + along * n1
        b.w[2][h] = x * (-sgn * n0) - y * n1 + along * n2


cdef inline void keep_lanes(const void *src, int n, uint64_t keep, void *dst,
                            int count, Py_ssize_t room) noexcept nogil:
    """Copy the ``count`` 4-byte values of ``src[0, n)`` whose bit is set in ``keep``, in
    order, to ``dst``, which can take ``room`` values: a compress a vector at a time,
    straight into ``dst`` where it has ``n + RS_SW`` values of room (the values past
    ``count`` are scratch, which the next block's rays or the batch's truncation
    overwrite), else through a block-sized stage (a copy of variable size, a call into
    the C library: the last blocks of a batch)."""
    cdef int32_t stage[2 * LANES]
    if room >= n + RS_SW:
        rs_keep32(<const int32_t *> src, n, keep, <int32_t *> dst)
        return
    rs_keep32(<const int32_t *> src, n, keep, stage)
    memcpy(dst, stage, count * sizeof(int32_t))


cdef inline void write_ray(const HitBlock *b, int h, float w0, float w1, float w2, float tmax,
                           float[:, ::1] out, int k) noexcept nogil:
    """Write one new ray, from lane ``h``'s point ``o`` along ``(w0, w1, w2)`` over
    ``(0, tmax)``, as ray ``k`` of a batch's rows (:func:`write_rays` for one lane with a
    direction and tmax of its own: a lane's rays toward several lights)."""
    cdef int a
    for a in range(3):
        out[RS_RAY_OX + a, k] = b.o[a][h]
    out[RS_RAY_DX, k] = w0
    out[RS_RAY_DX + 1, k] = w1
    out[RS_RAY_DX + 2, k] = w2
    out[RS_RAY_TMIN, k] = 0.0
    out[RS_RAY_TMAX, k] = tmax


cdef inline void write_rays(const HitBlock *b, uint64_t keep, int count,
                            float[:, ::1] out, int k, int step, Py_ssize_t room) noexcept nogil:
    """Write the new rays (``o``, ``w``, 0, ``tmax``) of the ``count`` lanes set in
    ``keep`` as rays ``k, k + step, k + 2 step, ...`` of a batch's rows (``step`` 1
    unless every lane makes a ray; otherwise each row can take ``room`` values from
    ray ``k`` on, as :func:`keep_lanes` says)."""
    cdef int a, j
    cdef float *row
    if count == b.n:       # every lane
        for a in range(3):
            row = &out[RS_RAY_OX + a, k]
            for j in range(count):
                row[j * step] = b.o[a][j]
            row = &out[RS_RAY_DX + a, k]
            for j in range(count):
                row[j * step] = b.w[a][j]
        row = &out[RS_RAY_TMAX, k]
        for j in range(count):
            row[j * step] = b.tmax[j]
    else:
        for a in range(3):
            keep_lanes(b.o[a], b.n, keep, &out[RS_RAY_OX + a, k], count, room)
            keep_lanes(b.w[a], b.n, keep, &out[RS_RAY_DX + a, k], count, room)
        keep_lanes(b.tmax, b.n, keep, &out[RS_RAY_TMAX, k], count, room)
    row = &out[RS_RAY_TMIN, k]
    for j in range(count):
        row[j * step] = 0.0
