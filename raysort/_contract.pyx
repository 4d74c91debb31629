"""One-pass contract checks (nogil), called by :mod:`raysort.contract`.

Each function reads its arrays once and returns ``(code, where)``: ``code`` is
0 when the contract holds, otherwise a :class:`Bad` value, and ``where`` the
first offending position; :mod:`raysort.contract` turns that into a message.

The loops are written for speed on valid input, which is every frame: a block
of ``CHUNK`` elements is tested without branches (``bad |= ...``, which the
compiler can vectorise) and only a block found bad is scanned again to find the
first offending element.  A value ``x`` is finite exactly when ``x - x == 0``.
"""
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t
from libc.stdlib cimport calloc, free

ctypedef fused index_t:
    int32_t
    int64_t

ctypedef fused real_t:
    float
    double

cdef enum:
    CHUNK = 64          # elements tested before one branch on the result


cpdef enum Bad:
    # what is wrong (0: nothing), and what ``where`` is
    BAD_OFFSETS_START = 1   # offsets[0] != 0
    BAD_OFFSETS_END         # offsets[-1] != n
    BAD_OFFSETS_ORDER       # offsets[k + 1] <= offsets[k]              (sub-packet k)
    BAD_OFFSETS_RANGE       # offsets[k + 1] > n                        (sub-packet k)
    BAD_PACKET_SIZE         # sub-packet larger than the maximum        (sub-packet k)
    BAD_INDEX_RANGE         # a[i] outside [lo, hi)                     (position i)
    BAD_INDEX_REPEAT        # order[i] seen before                      (position i)
    BAD_MIXED               # sub-packet spans large packets            (sub-packet k)
    BAD_LANE_INDEX          # a lane's ray index was changed            (lane)
    BAD_PADDING             # a padding lane was written                (lane)
    BAD_PRIM                # prim neither -1 nor a triangle index      (lane)
    BAD_T                   # hit t outside (tmin, tmax)                (lane)
    BAD_UV                  # hit u or v not finite                     (lane)
    BAD_TMIN                # an active ray with tmin < 0               (ray)
    BAD_RAY                 # an active ray with a non-finite origin or direction (ray)
    BAD_NOT_FINITE          # a non-finite value                        (position)
    BAD_DESCENDING          # a[i] < a[i - 1]                           (position i)


# ---------------------------------------------------------------------------
# a sorter's order and offsets
# ---------------------------------------------------------------------------

cdef Py_ssize_t large_packet(const int32_t[::1] packets, int64_t j) noexcept nogil:
    """The last p with packets[p] <= j (packets ascend from 0)."""
    cdef Py_ssize_t lo = 0, hi = packets.shape[0] - 1, mid
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if packets[mid] <= j:
            lo = mid
        else:
            hi = mid
    return lo


cdef int sort_kernel(const index_t[::1] order, const index_t[::1] offsets,
                     const int32_t[::1] packets, int64_t n, int64_t max_packet,
                     uint8_t *seen, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t n_sub = offsets.shape[0] - 1, k, i, p
    cdef int64_t a, b, j, lo, hi
    if offsets[0] != 0:
        return BAD_OFFSETS_START
    if offsets[n_sub] != n:
        return BAD_OFFSETS_END
    for k in range(n_sub):
        where[0] = k
        a = offsets[k]
        b = offsets[k + 1]
        if b <= a:
            return BAD_OFFSETS_ORDER
        if b > n:
            return BAD_OFFSETS_RANGE
        if b - a > max_packet:
            return BAD_PACKET_SIZE
        j = order[a]
        if j < 0 or j >= n:
            where[0] = a
            return BAD_INDEX_RANGE
        p = large_packet(packets, j)
        lo, hi = packets[p], packets[p + 1]       # 0 <= lo <= j < hi <= n
        for i in range(a, b):
            j = order[i]
            if j < lo or j >= hi or seen[j]:
                where[0] = i
                if j < 0 or j >= n:
                    return BAD_INDEX_RANGE
                if seen[j]:
                    return BAD_INDEX_REPEAT
                where[0] = k
                return BAD_MIXED
            seen[j] = 1
    return 0


def sort_result(const index_t[::1] order, const index_t[::1] offsets,
                const int32_t[::1] packets, int64_t n, int64_t max_packet):
    """A sorter's ``order``/``offsets`` for ``n`` rays in the (valid) large packets
    ``packets``: a permutation of ``range(n)`` cut into sub-packets of 1..max_packet rays,
    each inside one large packet.  The caller checks ``len(order) == n`` and
    ``len(offsets) >= 1``."""
    cdef Py_ssize_t where = 0
    cdef int code
    cdef uint8_t *seen = <uint8_t *> calloc(n + 1, 1)
    if seen == NULL:
        raise MemoryError()
    with nogil:
        code = sort_kernel(order, offsets, packets, n, max_packet, seen, &where)
    free(seen)
    return code, where


# ---------------------------------------------------------------------------
# a traversal's hits
# ---------------------------------------------------------------------------

cdef inline bint lane_bad(int32_t p, float tmin, float t, float t0, float u, float v,
                          uint32_t n_prim, bint any_hit) noexcept nogil:
    """prim is -1 or < n_prim; a closest hit lies in (tmin, t0) with finite u, v."""
    return ((<uint32_t> (p + 1) > n_prim)
            | ((p >= 0) & (not any_hit)
               & ((not (tmin < t)) | (not (t < t0)) | (not ((u - u) + (v - v) == 0)))))


cdef int lanes_kernel(const int32_t *prim, const float *tmin, const float *t, const float *t0,
                      const float *u, const float *v, Py_ssize_t capacity, uint32_t n_prim,
                      bint any_hit, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t block, a, b, lane
    cdef bint bad
    for block in range((capacity + CHUNK - 1) // CHUNK):
        a = block * CHUNK
        b = a + CHUNK if a + CHUNK < capacity else capacity
        bad = False
        for lane in range(a, b):
            bad |= lane_bad(prim[lane], tmin[lane], t[lane], t0[lane], u[lane], v[lane],
                            n_prim, any_hit)
        if not bad:
            continue
        for lane in range(a, b):
            if lane_bad(prim[lane], tmin[lane], t[lane], t0[lane], u[lane], v[lane], n_prim,
                        any_hit):
                where[0] = lane
                if <uint32_t> (prim[lane] + 1) > n_prim:
                    return BAD_PRIM
                if tmin[lane] < t[lane] < t0[lane]:
                    return BAD_UV
                return BAD_T
    return 0


cdef int index_lanes_kernel(const int32_t *prim, const int32_t *index, const int32_t *starts,
                            const int32_t *counts, Py_ssize_t n_sub, const int32_t *order,
                            const int32_t *offsets, Py_ssize_t capacity,
                            Py_ssize_t *where) noexcept nogil:
    """Each lane of sub-packet k holds ``order[offsets[k] + j]``; others hold no ray."""
    cdef Py_ssize_t k, j, s, end = 0, lane
    cdef bint bad = False
    for k in range(n_sub):
        s = starts[k]
        for lane in range(end, s):
            bad |= (index[lane] != -1) | (prim[lane] != -1)
        for j in range(counts[k]):
            bad |= index[s + j] != order[offsets[k] + j]
        end = s + counts[k]
    for lane in range(end, capacity):
        bad |= (index[lane] != -1) | (prim[lane] != -1)
    if not bad:
        return 0
    end = 0                     # find the first bad lane
    for k in range(n_sub + 1):
        s = starts[k] if k < n_sub else capacity
        for lane in range(end, s):
            if index[lane] != -1 or prim[lane] != -1:
                where[0] = lane
                return BAD_PADDING
        if k == n_sub:
            break
        for j in range(counts[k]):
            if index[s + j] != order[offsets[k] + j]:
                where[0] = s + j
                return BAD_LANE_INDEX
        end = s + counts[k]
    return 0


def hits(const float[:, ::1] rows, const float[::1] t0, const int32_t[::1] prim,
         const float[::1] u, const float[::1] v, const int32_t[::1] index,
         const int32_t[::1] starts, const int32_t[::1] counts, const int32_t[::1] order,
         const int32_t[::1] offsets, int64_t n_prim, bint any_hit, int tmin_row, int t_row):
    """A traversal's hits in gathered packets, ``t0`` being the row ``t`` before it ran
    (the ray's tmax; -inf on an invalid ray).  Every lane still holds the ray the gather
    put there (``order[offsets[k]:offsets[k + 1]]`` in sub-packet k; other lanes index and
    prim -1), prim is -1 or a triangle index below ``n_prim``, and a closest hit has
    ``tmin < t < t0`` and finite u, v.  An any-hit query marks a hit by any valid prim."""
    cdef Py_ssize_t where = 0, capacity = prim.shape[0]
    cdef int code
    with nogil:
        code = index_lanes_kernel(&prim[0], &index[0], &starts[0] if starts.shape[0] else NULL,
                                  &counts[0] if counts.shape[0] else NULL, starts.shape[0],
                                  &order[0] if order.shape[0] else NULL, &offsets[0], capacity,
                                  &where)
        if not code:
            code = lanes_kernel(&prim[0], &rows[tmin_row, 0], &rows[t_row, 0], &t0[0], &u[0],
                                &v[0], capacity, <uint32_t> n_prim, any_hit, &where)
    return code, where


# ---------------------------------------------------------------------------
# rays made by a plugin
# ---------------------------------------------------------------------------

cdef inline bint ray_bad(const float *const *o, const float *const *d, float tmin, float tmax,
                         Py_ssize_t i) noexcept nogil:
    """An active ray (tmin < tmax) needs tmin >= 0 and a finite origin and direction."""
    cdef float acc = ((o[0][i] - o[0][i]) + (o[1][i] - o[1][i]) + (o[2][i] - o[2][i])
                      + (d[0][i] - d[0][i]) + (d[1][i] - d[1][i]) + (d[2][i] - d[2][i]))
    return (tmin < tmax) & ((not (tmin >= 0)) | (not (acc == 0)))


cdef int rays_kernel(const float *const *o, const float *const *d, const float *tmin,
                     const float *tmax, Py_ssize_t n, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t block, a, b, i
    cdef bint bad
    for block in range((n + CHUNK - 1) // CHUNK):
        a = block * CHUNK
        b = a + CHUNK if a + CHUNK < n else n
        bad = False
        for i in range(a, b):
            bad |= ray_bad(o, d, tmin[i], tmax[i], i)
        if not bad:
            continue
        for i in range(a, b):
            if ray_bad(o, d, tmin[i], tmax[i], i):
                where[0] = i
                return BAD_RAY if tmin[i] >= 0 else BAD_TMIN
    return 0


def rays(const float[:, ::1] data, Py_ssize_t n, int origin_row, int direction_row,
         int tmin_row, int tmax_row):
    """Rays ``[0, n)`` of a batch: each one is either active (``tmin < tmax``) with
    ``tmin >= 0`` and a finite origin and direction (three rows each, from ``origin_row``
    and ``direction_row``), or marked invalid (``not tmin < tmax``), which the gather
    stores inactive."""
    cdef Py_ssize_t where = 0
    cdef const float *o[3]
    cdef const float *d[3]
    cdef int code, a
    for a in range(3):
        o[a] = &data[origin_row + a, 0]
        d[a] = &data[direction_row + a, 0]
    with nogil:
        code = rays_kernel(o, d, &data[tmin_row, 0], &data[tmax_row, 0], n, &where)
    return code, where


# ---------------------------------------------------------------------------
# index and value arrays
# ---------------------------------------------------------------------------

cdef int index_kernel(const index_t[::1] a, int64_t lo, int64_t hi, bint ascending,
                      Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t block, start, end, i, n = a.shape[0]
    cdef bint bad
    for block in range((n + CHUNK - 1) // CHUNK):
        start = block * CHUNK
        end = start + CHUNK if start + CHUNK < n else n
        bad = False
        for i in range(start, end):
            bad |= (a[i] < lo) | (a[i] >= hi)
        if ascending:
            for i in range(start if start else 1, end):
                bad |= a[i] < a[i - 1]
        if not bad:
            continue
        for i in range(start, end):
            where[0] = i
            if a[i] < lo or a[i] >= hi:
                return BAD_INDEX_RANGE
            if ascending and i and a[i] < a[i - 1]:
                return BAD_DESCENDING
    return 0


def index_array(const index_t[::1] a, int64_t lo, int64_t hi, bint ascending):
    """Every ``a[i]`` in ``[lo, hi)`` and, with ``ascending``, ``a[i - 1] <= a[i]``."""
    cdef Py_ssize_t where = 0
    cdef int code
    with nogil:
        code = index_kernel(a, lo, hi, ascending, &where)
    return code, where


cdef int finite_kernel(const real_t[::1] a, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t block, start, end, i, n = a.shape[0]
    cdef bint bad
    for block in range((n + CHUNK - 1) // CHUNK):
        start = block * CHUNK
        end = start + CHUNK if start + CHUNK < n else n
        bad = False
        for i in range(start, end):
            bad |= not (a[i] - a[i] == 0)
        if not bad:
            continue
        for i in range(start, end):
            if not (a[i] - a[i] == 0):
                where[0] = i
                return BAD_NOT_FINITE
    return 0


def finite(const real_t[::1] a):
    """Every value finite (a flat view of any float array)."""
    cdef Py_ssize_t where = 0
    cdef int code
    with nogil:
        code = finite_kernel(a, &where)
    return code, where
