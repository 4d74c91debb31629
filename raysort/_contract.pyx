"""One-pass contract checks (nogil), called by :mod:`raysort.contract`.

Each function reads its arrays once and returns ``(code, where)``: ``code`` is
0 when the contract holds, otherwise a :class:`Bad` value, and ``where`` the
first offending position; :mod:`raysort.contract` turns that into a message.

The loops are written for valid input, which is every frame: a block of
elements (a sub-packet, or ``CHUNK`` values) is tested without branches
(``bad |= ...`` over plain pointers, which the compiler vectorises) and only a
block found bad is scanned again for its first offending element.  A float is
finite exactly when its exponent bits are not all set (tested on its bits, which
vectorises), equivalently when ``x - x == 0``.  The functions take int32 (the
sort result) or int32/int64 index arrays (the caller converts other types).
"""
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t, uint64_t
from libc.stdlib cimport calloc, free
from libc.string cimport memcmp, memset
from raysort._checks cimport (ray_bad, closest_bad, any_hit_bad, large_packet,
                              packet_bounds, slot_bad, sub_packet_bad, rays_bad, all_marked,
                              offsets_bad, nonfinite, parents_weights_bad, slots_bad)
from raysort._types cimport (RS_RAY_OX, RS_RAY_OY, RS_RAY_OZ, RS_RAY_DX, RS_RAY_DY, RS_RAY_DZ,
                             RS_RAY_TMIN, RS_RAY_TMAX, RS_RAY_ROWS, RS_PACKET_ROWS,
                             RS_PACKET_TMIN, RS_PACKET_T)

import numpy as np

ctypedef fused index_t:
    int32_t
    int64_t

ctypedef fused real_t:
    float
    double

cdef enum:
    CHUNK = 1024        # values tested before one branch on the result


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
    BAD_PARENT_RANGE        # parent[i] outside [0, n)                  (path i)
    BAD_PARENT_ORDER        # parent[i] < parent[i - 1]                 (path i)
    BAD_WEIGHT              # a throughput or contribution not finite   (path i)
    BAD_SLOT                # slot[i] outside [0, slots)                (path i)
    BAD_LAYOUT              # packets.starts/counts changed             (sub-packet k)
    BAD_SHAPE               # a packets array reshaped                  (0)


cdef inline Py_ssize_t block_end(Py_ssize_t start, Py_ssize_t n) noexcept nogil:
    return start + CHUNK if start + CHUNK < n else n


# ---------------------------------------------------------------------------
# a sorter's order and offsets
# ---------------------------------------------------------------------------

cdef int is_identity(const int32_t *order, int32_t n) noexcept nogil:
    """``order[i] == i`` for every i < n (an unsorted batch), in blocks that vectorise."""
    cdef Py_ssize_t i, a = 0, b
    cdef int bad
    while a < n:
        b = block_end(a, n)
        bad = 0
        for i in range(a, b):
            bad |= order[i] != i
        if bad:
            return 0
        a = b
    return 1


cdef int runs_bad(const int32_t *order, const int32_t *offsets, Py_ssize_t n_sub,
                  const int32_t *packets, Py_ssize_t n_big, int32_t n,
                  uint8_t *seen) noexcept nogil:
    """Non-zero if the rays of a sort result whose offsets are valid (:func:`offsets_bad`
    passed) break its contract, checked a run of sub-packets at a time: consecutive
    sub-packets whose first rays lie in one large packet form a run, whose rays must all
    lie in that packet, the rules of :func:`sub_packet_bad` for each of its sub-packets
    (each starts in the run's packet) but that of repeats: each ray is marked in
    ``seen``, and the order holds every ray once when :func:`all_marked` then holds.  One
    loop per large packet, as sorters cut them, instead of one per sub-packet;
    :func:`sort_kernel` says what is wrong."""
    cdef Py_ssize_t k, k_big = 0, run = 0
    cdef int64_t a
    cdef int32_t lo = 0, hi = 0, first
    for k in range(n_sub):
        a = offsets[k]
        first = order[a]            # (offsets ascend from 0 to n: a ray of the order)
        if k > 0 and lo <= first < hi:
            continue                # the run goes on
        if k > 0 and rays_bad(order, run, a, lo, hi, seen):
            return 1
        if packet_bounds(first, packets, n_big, n, &k_big, &lo, &hi):
            return 1
        run = a
    return rays_bad(order, run, n, lo, hi, seen) if n_sub > 0 else 0


cdef int identity_cuts_bad(const int32_t *offsets, Py_ssize_t n_sub, const int32_t *packets,
                           Py_ssize_t n_big, int32_t n) noexcept nogil:
    """Non-zero if the identity order, its offsets valid (:func:`offsets_bad` passed),
    breaks the contract: a sub-packet holding rays of two large packets, that is, a
    boundary of a large packet inside (0, n) that no sub-packet starts at (both ascend:
    one walk over the offsets).  For ``none``'s result the loop over the sub-packets
    that finds what is wrong took 5 us of every 7 us call (131,072 rays in sub-packets
    of 64); :func:`sort_kernel` says what is wrong."""
    cdef Py_ssize_t j = 0, k
    cdef int32_t p
    for k in range(n_big + 1):
        p = packets[k]
        if p <= 0 or p >= n:
            continue
        while j < n_sub and offsets[j] < p:
            j += 1
        if offsets[j] != p:         # (j <= n_sub, and offsets[n_sub] = n)
            return 1
    return 0


cdef int sort_kernel(const int32_t *order, const int32_t *offsets, Py_ssize_t n_sub,
                     const int32_t *packets, Py_ssize_t n_big, int32_t n, int64_t max_packet,
                     bint known_identity, uint8_t *seen, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t k, k_big = 0
    cdef int64_t a, b
    cdef int32_t lo, hi
    # the identity is a permutation: a sub-packet need only end in its first ray's packet
    cdef int identity = known_identity or is_identity(order, n)
    if offsets[0] != 0:
        return BAD_OFFSETS_START
    if offsets[n_sub] != n:
        return BAD_OFFSETS_END
    # the offsets' rules in one vectorised pass (no sub-packet is longer than n: max_packet
    # capped there fits offsets_bad's int32), then the rays a run at a time (the identity:
    # its cuts at the large packets); a result found bad is checked again below,
    # sub-packet by sub-packet, to say what is wrong and where
    if not offsets_bad(offsets, n_sub, n, <int32_t> min(max_packet, <int64_t> n)):
        if identity:
            if not identity_cuts_bad(offsets, n_sub, packets, n_big, n):
                return 0
        elif not runs_bad(order, offsets, n_sub, packets, n_big, n, seen) and all_marked(seen, n):
            return 0
    if not identity:
        memset(seen, 0, n + 1)      # (runs_bad may have marked rays)
    for k in range(n_sub):
        where[0] = k
        a, b = offsets[k], offsets[k + 1]
        if b <= a:
            return BAD_OFFSETS_ORDER
        if b > n:
            return BAD_OFFSETS_RANGE
        if b - a > max_packet:
            return BAD_PACKET_SIZE
        if identity:
            if packet_bounds(<int32_t> a, packets, n_big, n, &k_big, &lo, &hi) or b > hi:
                return sort_fault(order, a, b, packets, n_big, n, seen, k, where)
        elif sub_packet_bad(order, a, b, packets, n_big, n, &k_big, seen):
            return sort_fault(order, a, b, packets, n_big, n, seen, k, where)
    return 0


cdef int sort_fault(const int32_t *order, int64_t a, int64_t b, const int32_t *packets,
                    Py_ssize_t n_big, int32_t n, uint8_t *seen, Py_ssize_t k,
                    Py_ssize_t *where) noexcept nogil:
    """What is wrong in sub-packet k, known bad, and where.  Sub-packets before it are
    valid, so every ray of order[:b] is in range when the range test passed here."""
    cdef int64_t i, lo, hi
    cdef Py_ssize_t k_big
    if order[a] < 0 or order[a] >= n:
        where[0] = a
        return BAD_INDEX_RANGE
    k_big = large_packet(packets, n_big, order[a])
    lo, hi = max(packets[k_big], 0), min(packets[k_big + 1], n)    # as packet_bounds
    for i in range(a, b):
        if order[i] < lo or order[i] >= hi:
            where[0] = i
            if order[i] < 0 or order[i] >= n:
                return BAD_INDEX_RANGE
            where[0] = k
            return BAD_MIXED
    if seen == NULL:            # (the identity: not reached, its rays are all in range)
        return BAD_MIXED
    memset(seen, 0, n)
    for i in range(b):
        if seen[order[i]]:
            where[0] = i
            return BAD_INDEX_REPEAT
        seen[order[i]] = 1
    return BAD_INDEX_REPEAT     # not reached


def sort_result(const int32_t[::1] order, const int32_t[::1] offsets,
                const int32_t[::1] packets, int32_t n, int64_t max_packet,
                bint identity=False):
    """A sorter's ``order``/``offsets`` (contiguous int32) for ``n`` rays in the (valid)
    large packets ``packets``: a permutation of ``range(n)`` cut into sub-packets of
    1..max_packet rays, each inside one large packet.  The caller checks
    ``len(order) == n`` and ``len(offsets) >= 1``; ``identity`` True says the order is
    known to be ``0, 1, ..., n - 1`` (:func:`raysort.orders.is_identity_order`), so it
    is not read, and only the offsets are checked.  ValueError if ``order`` (unless
    ``identity``) does not hold n values, ``offsets`` none or ``packets`` fewer than 2 for
    n > 0 (their values need not be valid for the kernel to stay inside the arrays: see
    ``packet_bounds``)."""
    cdef Py_ssize_t where = 0
    cdef int code
    if n < 0 or (not identity and order.shape[0] != n) or offsets.shape[0] < 1 \
            or (n and packets.shape[0] < 2):
        raise ValueError(f"sort_result: order of n = {n} values, offsets of 1 value or more "
                         f"and packets of 2 boundaries or more (for n > 0) expected")
    cdef uint8_t *seen = NULL if identity else <uint8_t *> calloc(n + 1, 1)
    if seen == NULL and not identity:
        raise MemoryError()
    try:
        with nogil:
            code = sort_kernel(&order[0] if n else NULL, &offsets[0], offsets.shape[0] - 1,
                               &packets[0], packets.shape[0] - 1, n, max_packet, identity, seen,
                               &where)
    finally:
        free(seen)
    return code, where


# ---------------------------------------------------------------------------
# a traversal's hits
# ---------------------------------------------------------------------------

cdef int lanes_kernel(const int32_t *prim, const int32_t *index, const float *tmin,
                      const float *t, const float *t0, const float *u, const float *v,
                      Py_ssize_t capacity, uint32_t n_prim, bint any_hit, Py_ssize_t *held,
                      Py_ssize_t *where) noexcept nogil:
    """Every lane's hit, in one pass that also counts the lanes holding a ray (``held``)
    and returns BAD_PADDING when a lane holding none has a prim (which lane:
    :func:`padding_fault`)."""
    cdef Py_ssize_t a = 0, b, lane, holding = 0
    cdef int bad, pad, empty
    cdef int32_t p
    while a < capacity:
        b = block_end(a, capacity)
        bad = pad = 0
        if any_hit:             # a hit is any valid prim; t is the traversal's business
            for lane in range(a, b):
                p = prim[lane]
                empty = index[lane] == -1
                holding += not empty
                pad |= empty & (p != -1)
                bad |= any_hit_bad(p, n_prim)
        else:
            for lane in range(a, b):
                p = prim[lane]
                empty = index[lane] == -1
                holding += not empty
                pad |= empty & (p != -1)
                bad |= closest_bad(p, tmin[lane], t[lane], t0[lane], u[lane], v[lane], n_prim)
        if pad:
            return BAD_PADDING
        if bad:
            for lane in range(a, b):
                where[0] = lane
                if <uint32_t> (prim[lane] + 1) > n_prim:
                    return BAD_PRIM
                if any_hit or not closest_bad(prim[lane], tmin[lane], t[lane], t0[lane],
                                              u[lane], v[lane], n_prim):
                    continue
                return BAD_UV if tmin[lane] < t[lane] < t0[lane] else BAD_T
        a = b
    held[0] = holding
    return 0


cdef int index_lanes_kernel(const int32_t *prim, const int32_t *index, const int32_t *starts,
                            const int32_t *counts, Py_ssize_t n_sub, const int32_t *order,
                            Py_ssize_t n_order, const int32_t *offsets, Py_ssize_t capacity,
                            Py_ssize_t *where) noexcept nogil:
    """Sub-packet k still starts and ends where the gather put it (from ``offsets``: its
    rays padded to a multiple of 4 lanes) and each of its lanes holds
    ``order[offsets[k] + j]`` (compared sub-packet by sub-packet).  That the other lanes
    hold no ray is left to :func:`lanes_kernel`'s pass over all lanes: as the rays'
    lanes hold n rays (order's values are rays, checked by the gather), the padding is
    untouched exactly when n lanes in all hold a ray and every lane holding none has
    prim -1.  Offsets outside ``order`` (``n_order`` values) are a BAD_LAYOUT."""
    cdef Py_ssize_t k, j, s, c, next_start = 0
    for k in range(n_sub):
        s, c = next_start, offsets[k + 1] - offsets[k]
        next_start = s + ((c + 3) & ~3)
        if (starts[k] != s or counts[k] != c or next_start > capacity or c < 0
                or offsets[k] < 0 or offsets[k + 1] > n_order):
            where[0] = k
            return BAD_LAYOUT
        if memcmp(index + s, order + offsets[k], c * sizeof(int32_t)):
            for j in range(c):
                if index[s + j] != order[offsets[k] + j]:
                    where[0] = s + j
                    return BAD_LANE_INDEX
    return 0


cdef int padding_fault(const int32_t *prim, const int32_t *index, const int32_t *starts,
                       const int32_t *counts, Py_ssize_t n_sub, Py_ssize_t capacity,
                       Py_ssize_t *where) noexcept nogil:
    """The first padding lane written into (one is known to be)."""
    cdef Py_ssize_t k, lane, s, end = 0
    for k in range(n_sub + 1):
        s = starts[k] if k < n_sub else capacity
        for lane in range(end, s):
            if index[lane] != -1 or prim[lane] != -1:
                where[0] = lane
                return BAD_PADDING
        end = s + (counts[k] if k < n_sub else 0)
    return BAD_PADDING      # not reached


def hits(const float[:, ::1] rows not None, const float[::1] t0 not None,
         const int32_t[::1] prim not None, const float[::1] u not None,
         const float[::1] v not None, const int32_t[::1] index not None,
         const int32_t[::1] starts not None, const int32_t[::1] counts not None,
         const int32_t[::1] order not None, const int32_t[::1] offsets not None,
         int64_t n_prim, bint any_hit):
    """A traversal's hits in gathered packets, ``t0`` being the row ``t`` before it ran
    (the ray's tmax; -inf on an invalid ray).  Every lane still holds the ray the gather
    put there (``order[offsets[k]:offsets[k + 1]]`` in sub-packet k; other lanes index and
    prim -1), prim is -1 or a triangle index below ``n_prim``, and a closest hit has
    ``tmin < t < t0`` and finite u, v.  An any-hit query marks a hit by any valid prim."""
    cdef Py_ssize_t where = 0, capacity = rows.shape[1], held = 0
    cdef int code
    if (rows.shape[0] != RS_PACKET_ROWS or prim.shape[0] != capacity
            or u.shape[0] != capacity or v.shape[0] != capacity
            or index.shape[0] != capacity or t0.shape[0] != capacity):
        return BAD_SHAPE, 0
    if (offsets.shape[0] < 1 or starts.shape[0] != offsets.shape[0] - 1
            or counts.shape[0] != starts.shape[0]):
        return BAD_LAYOUT, 0
    with nogil:
        code = index_lanes_kernel(&prim[0], &index[0], &starts[0] if starts.shape[0] else NULL,
                                  &counts[0] if counts.shape[0] else NULL, starts.shape[0],
                                  &order[0] if order.shape[0] else NULL, order.shape[0],
                                  &offsets[0], capacity, &where)
        if not code:
            code = lanes_kernel(&prim[0], &index[0], &rows[RS_PACKET_TMIN, 0],
                                &rows[RS_PACKET_T, 0], &t0[0], &u[0], &v[0], capacity,
                                <uint32_t> n_prim, any_hit, &held, &where)
        if code == BAD_PADDING or (not code and held != offsets[starts.shape[0]]):
            code = padding_fault(&prim[0], &index[0], &starts[0] if starts.shape[0] else NULL,
                                 &counts[0] if counts.shape[0] else NULL, starts.shape[0],
                                 capacity, &where)
    return code, where


# ---------------------------------------------------------------------------
# rays made by a plugin
# ---------------------------------------------------------------------------

cdef int rays_kernel(const float *ox, const float *oy, const float *oz, const float *dx,
                     const float *dy, const float *dz, const float *tmin, const float *tmax,
                     Py_ssize_t n, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t a = 0, b, i
    cdef int bad
    while a < n:
        b = block_end(a, n)
        bad = 0
        for i in range(a, b):
            bad |= ray_bad(ox[i], oy[i], oz[i], dx[i], dy[i], dz[i], tmin[i], tmax[i])
        if bad:
            for i in range(a, b):
                if ray_bad(ox[i], oy[i], oz[i], dx[i], dy[i], dz[i], tmin[i], tmax[i]):
                    where[0] = i
                    return BAD_RAY if tmin[i] >= 0 else BAD_TMIN
        a = b
    return 0


def rays(const float[:, ::1] data, Py_ssize_t n):
    """Rays ``[0, n)`` of a batch (the ``RS_RAY_*`` rows): each one is either active
    (``tmin < tmax``) with ``tmin >= 0`` and a finite origin and direction, or marked
    invalid (``not tmin < tmax``), which the gather stores inactive.  ValueError unless
    ``data`` has the ray rows of n rays or more."""
    cdef Py_ssize_t where = 0
    cdef int code
    if data.shape[0] != RS_RAY_ROWS or not 0 <= n <= data.shape[1]:
        raise ValueError(f"rays: data ({RS_RAY_ROWS}, capacity) with 0 <= n <= capacity "
                         f"expected")
    with nogil:
        code = rays_kernel(&data[RS_RAY_OX, 0], &data[RS_RAY_OY, 0], &data[RS_RAY_OZ, 0],
                           &data[RS_RAY_DX, 0], &data[RS_RAY_DY, 0], &data[RS_RAY_DZ, 0],
                           &data[RS_RAY_TMIN, 0], &data[RS_RAY_TMAX, 0], n, &where)
    return code, where


# ---------------------------------------------------------------------------
# index and value arrays
# ---------------------------------------------------------------------------

cdef int index_kernel(const index_t *x, Py_ssize_t n, index_t lo, index_t hi, bint ascending,
                      Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t a = 0, b, i
    cdef int bad
    while a < n:
        b = block_end(a, n)
        bad = 0
        for i in range(a, b):
            bad |= (x[i] < lo) | (x[i] >= hi)
        if ascending:
            for i in range(a if a else 1, b):
                bad |= x[i] < x[i - 1]
        if bad:
            for i in range(a, b):
                where[0] = i
                if x[i] < lo or x[i] >= hi:
                    return BAD_INDEX_RANGE
                if ascending and i and x[i] < x[i - 1]:
                    return BAD_DESCENDING
        a = b
    return 0


def index_array(x, int64_t lo, int64_t hi, bint ascending):
    """Every ``x[i]`` in ``[lo, hi)`` and, with ``ascending``, ``x[i - 1] <= x[i]``
    (``x``: a contiguous int32 or int64 array; for int32, ``lo`` and ``hi`` must fit)."""
    cdef Py_ssize_t where = 0
    cdef int code
    cdef const int32_t[::1] x32
    cdef const int64_t[::1] x64
    if x.dtype == np.int32:
        x32 = x
        with nogil:
            code = index_kernel(&x32[0] if x32.shape[0] else NULL, x32.shape[0], <int32_t> lo,
                                <int32_t> hi, ascending, &where)
    else:
        x64 = x
        with nogil:
            code = index_kernel(&x64[0] if x64.shape[0] else NULL, x64.shape[0], lo, hi,
                                ascending, &where)
    return code, where


cdef int finite_kernel(const real_t *x, Py_ssize_t n, Py_ssize_t *where) noexcept nogil:
    cdef Py_ssize_t a = 0, b, i
    cdef int bad
    while a < n:
        b = block_end(a, n)
        if real_t is float:
            bad = nonfinite(<const uint32_t *> x, a, b)
        else:
            bad = nonfinite(<const uint64_t *> x, a, b)
        if bad:
            for i in range(a, b):
                if (x[i] - x[i]) != 0:
                    where[0] = i
                    return BAD_NOT_FINITE
        a = b
    return 0


def finite(x):
    """Every value of ``x`` (a contiguous 1-d float32 or float64 array) finite."""
    cdef Py_ssize_t where = 0
    cdef int code
    cdef const float[::1] x32
    cdef const double[::1] x64
    if x.dtype == np.float32:
        x32 = x
        with nogil:
            code = finite_kernel(&x32[0] if x32.shape[0] else NULL, x32.shape[0], &where)
    else:
        x64 = x
        with nogil:
            code = finite_kernel(&x64[0] if x64.shape[0] else NULL, x64.shape[0], &where)
    return code, where


# ---------------------------------------------------------------------------
# a shader's next paths and shadow rays, in one pass
# ---------------------------------------------------------------------------

cdef inline int row_ray_bad(const float *const *r, Py_ssize_t i) noexcept nogil:
    """:func:`ray_bad` of ray ``i``, ``r`` pointing at the ``RS_RAY_*`` rows."""
    return ray_bad(r[RS_RAY_OX][i], r[RS_RAY_OY][i], r[RS_RAY_OZ][i], r[RS_RAY_DX][i],
                   r[RS_RAY_DY][i], r[RS_RAY_DZ][i], r[RS_RAY_TMIN][i], r[RS_RAY_TMAX][i])


cdef int paths_kernel(const float *const *r, const int32_t *parent, const float *const *w,
                      const int32_t *slot, Py_ssize_t m, uint32_t n, uint32_t slots,
                      Py_ssize_t *where) noexcept nogil:
    """Each part in its own loop over a block (which the compiler vectorises); a bad block
    is searched again for its first bad path.  ``r`` or ``slot`` NULL: not checked."""
    cdef Py_ssize_t a = 0, b, i
    cdef int bad
    while a < m:
        b = block_end(a, m)
        bad = parents_weights_bad(parent, <const uint32_t *> w[0], <const uint32_t *> w[1],
                                  <const uint32_t *> w[2], a, b, n)
        if slot != NULL:
            bad |= slots_bad(slot, a, b, slots)
        if r != NULL:
            for i in range(a, b):
                bad |= row_ray_bad(r, i)
        if bad:
            for i in range(a, b):
                where[0] = i
                if r != NULL and row_ray_bad(r, i):
                    return BAD_RAY if r[RS_RAY_TMIN][i] >= 0 else BAD_TMIN
                if <uint32_t> parent[i] >= n:
                    return BAD_PARENT_RANGE
                if i and parent[i] < parent[i - 1]:
                    return BAD_PARENT_ORDER
                if nonfinite(<const uint32_t *> w[0], i, i + 1) \
                        | nonfinite(<const uint32_t *> w[1], i, i + 1) \
                        | nonfinite(<const uint32_t *> w[2], i, i + 1):
                    return BAD_WEIGHT
                if slot != NULL and slot_bad(slot[i], slots):
                    return BAD_SLOT
        a = b
    return 0


def paths(const float[:, ::1] data, Py_ssize_t m, const int32_t[::1] parent,
          const float[:, :] weight, slot, int64_t n, int64_t slots, bint with_rays=True):
    """``m`` rays that continue paths (a shader's next bounce, or its shadow rays) in one
    pass: each ray finite or marked invalid (see :func:`rays`; skipped without
    ``with_rays``, when the gather checks them); ``parent`` ascending in
    ``[0, n)``; ``weight`` (3, m; rows contiguous) finite; ``slot`` (None, or int32)
    in ``[0, slots)``; ValueError unless ``data`` holds the ray rows of m rays and
    ``parent`` and ``slot`` m values or more."""
    cdef Py_ssize_t where = 0
    cdef int code, c
    cdef const float *r[RS_RAY_ROWS]
    cdef const float *w[3]
    cdef const int32_t[::1] slot32
    cdef const int32_t *slot_ptr = NULL
    if m < 0 or data.shape[0] != RS_RAY_ROWS or data.shape[1] < m or parent.shape[0] < m:
        raise ValueError(f"paths: data ({RS_RAY_ROWS}, capacity >= m) and parent of m values "
                         f"expected, m >= 0")
    if m == 0:
        return 0, 0
    if weight.shape[0] != 3 or weight.shape[1] < m or weight.strides[1] != sizeof(float):
        raise ValueError("weight must be (3, m) with contiguous rows")
    for c in range(RS_RAY_ROWS):
        r[c] = &data[c, 0]
    for c in range(3):
        w[c] = &weight[c, 0]
    if slot is not None:
        slot32 = slot
        if slot32.shape[0] < m:
            raise ValueError("paths: slot must hold m values")
        slot_ptr = &slot32[0]
    with nogil:
        code = paths_kernel(<const float *const *> r if with_rays else NULL, &parent[0], w,
                            slot_ptr, m, <uint32_t> n, <uint32_t> slots, &where)
    return code, where


# ---------------------------------------------------------------------------
# a shader's Bounce of exactly the pipeline's types, without leaving C
# ---------------------------------------------------------------------------

cdef bint paths_ok(object rays, object parent, object slot, object weight, int64_t n,
                   int64_t slots, bint with_rays, bint with_values, type batch_type):
    """:func:`paths` of a RayBatch and arrays already of the pipeline's types (int32,
    float32 (3, m) with contiguous rows), all valid (without ``with_values``: of those
    types and shapes, their values checked by their maker); False for anything else."""
    cdef const float[:, ::1] data
    cdef const int32_t[::1] p
    cdef const int32_t[::1] s
    cdef const float[:, :] w
    cdef Py_ssize_t m, where = 0
    cdef const float *r[RS_RAY_ROWS]
    cdef const float *wr[3]
    cdef int c, code
    if type(rays) is not batch_type or type(rays.n) is not int:
        return False
    try:
        data, p, w = rays.data, parent, weight
        if slot is not None:
            s = slot
    except (TypeError, ValueError):
        return False
    m = rays.n
    if (data.shape[0] != RS_RAY_ROWS or not 0 <= m <= data.shape[1] or p.shape[0] != m
            or w.shape[0] != 3 or w.shape[1] != m or (m and w.strides[1] != sizeof(float))
            or (slot is not None and s.shape[0] != m)):
        return False
    if m == 0 or not with_values:
        return True
    for c in range(RS_RAY_ROWS):
        r[c] = &data[c, 0]
    for c in range(3):
        wr[c] = &w[c, 0]
    with nogil:
        code = paths_kernel(<const float *const *> r if with_rays else NULL, &p[0], wr,
                            &s[0] if slot is not None else NULL, m, <uint32_t> n,
                            <uint32_t> slots, &where)
    return code == 0


def bounce_ok(bounce, int64_t n, int64_t slots, const double[:, ::1] radiance not None,
              bint with_rays, type bounce_type, type shadow_type, type batch_type,
              bint with_paths=True):
    """True when a shader's ``bounce`` is exactly of the pipeline's types (``bounce_type``,
    ``shadow_type``, ``batch_type``, int32 and float32 arrays) and keeps its contract
    (see :func:`raysort.contract.check_bounce`; without ``with_paths``, the values of
    the parents, weights and slots are left to the shader, which checked them as it
    wrote them), and ``radiance`` is finite: the common case, checked without running
    Python.  False means: let ``check_bounce`` say."""
    cdef Py_ssize_t where = 0
    cdef int code
    if type(bounce) is not bounce_type:
        return False
    with nogil:
        code = finite_kernel(&radiance[0, 0], radiance.shape[0] * radiance.shape[1], &where) \
            if radiance.shape[0] * radiance.shape[1] else 0
    if code or not paths_ok(bounce.rays, bounce.parent, None, bounce.throughput, n, slots,
                            with_rays, with_paths, batch_type):
        return False
    shadow = bounce.shadow
    return shadow is None or (type(shadow) is shadow_type and paths_ok(
        shadow.rays, shadow.parent, shadow.slot, shadow.contribution, n, slots, with_rays,
        with_paths, batch_type))


# ---------------------------------------------------------------------------
# the bounds-checked build's probe
# ---------------------------------------------------------------------------

cdef extern from *:
    """
    #ifdef RAYSORT_DEBUG_CYTHON
    #define RS_BOUNDS_CHECKED 1
    #else
    #define RS_BOUNDS_CHECKED 0
    #endif
    """
    bint RS_BOUNDS_CHECKED


def _bounds_probe(const int32_t[::1] values, Py_ssize_t i):
    """``values[i]`` through Cython's indexing, for tests/test_debug_build.py: the
    bounds-checked build (``RAYSORT_DEBUG_CYTHON=1``) raises IndexError for an ``i``
    outside ``values`` by its own check; the normal build, which compiles none, refuses
    it first with ValueError."""
    if not RS_BOUNDS_CHECKED and not 0 <= i < values.shape[0]:
        raise ValueError(f"_bounds_probe: index {i} outside the {values.shape[0]} values")
    return values[i]
