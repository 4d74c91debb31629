"""The contract rules one element (or one run) at a time, for the check kernels
(:mod:`raysort._contract`: the SDK's checks and the pipeline's pass over a
traversal's lanes), the sort-result checks inside the gather
(:mod:`raysort._gather`: :func:`offsets_bad`, :func:`packet_bounds`,
:func:`range_bad`) and the built-in shaders' check of their inputs
(``_shading.pxd``'s ``checked_hits``: :func:`any_hit_bad`, :func:`slot_bad`) and of the
paths they make (``lambert``: :func:`parents_weights_bad`, :func:`slots_bad`), so every
path applies the same rules.

Each returns non-zero when the element breaks its contract, written without
branches so that loops over a block vectorise.  A float ``x`` is finite exactly
when ``x - x == 0``.
"""
from libc.stdint cimport int32_t, uint8_t, uint32_t, uint64_t


cdef inline bint unaligned16(const void *p) noexcept nogil:
    """``p`` is not 16-byte aligned (the SIMD kernels load and store packet rows so)."""
    return (<size_t> p) % 16 != 0


cdef inline int ray_bad(float ox, float oy, float oz, float dx, float dy, float dz, float tmin,
                        float tmax) noexcept nogil:
    """An active ray (tmin < tmax) needs tmin >= 0 and a finite origin and direction."""
    cdef float acc = (ox - ox) + (oy - oy) + (oz - oz) + (dx - dx) + (dy - dy) + (dz - dz)
    return (tmin < tmax) & ((not (tmin >= 0)) | (acc != 0))


cdef inline int closest_bad(int32_t p, float tmin, float t, float t0, float u, float v,
                            uint32_t n_prim) noexcept nogil:
    """A closest hit's lane: prim is -1 or below n_prim; a hit lies in (tmin, t0) with
    finite u, v (t0: the lane's t before the traversal ran, the ray's tmax)."""
    return ((<uint32_t> (p + 1) > n_prim)
            | ((p >= 0) & ((not (tmin < t)) | (not (t < t0)) | ((u - u) + (v - v) != 0))))


cdef inline int any_hit_bad(int32_t p, uint32_t n_prim) noexcept nogil:
    """An any-hit lane: prim is -1 or below n_prim (t is the traversal's business)."""
    return <uint32_t> (p + 1) > n_prim


cdef inline int slot_bad(int32_t s, uint32_t slots) noexcept nogil:
    """A path's accumulator row: one of the ``slots`` rows of the radiance."""
    return <uint32_t> s >= slots


cdef inline Py_ssize_t large_packet(const int32_t *packets, Py_ssize_t n_big,
                                    int32_t j) noexcept nogil:
    """The last p < n_big with packets[p] <= j (packets ascend from 0)."""
    cdef Py_ssize_t lo = 0, hi = n_big, mid
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if packets[mid] <= j:
            lo = mid
        else:
            hi = mid
    return lo


cdef inline int packet_bounds(int32_t first, const int32_t *packets, Py_ssize_t n_big,
                              int32_t n, Py_ssize_t *k_big, int32_t *lo,
                              int32_t *hi) noexcept nogil:
    """The large packet ``[lo, hi)`` holding ray ``first``, the first of a sub-packet
    (``packets``: n_big + 1 valid boundaries ending at n, n_big >= 1; ``k_big``: the
    previous sub-packet's, updated); 1 if ``first`` is not a ray of ``[0, n)``.  ``lo``
    and ``hi`` are kept within ``[0, n]`` (a no-op for valid boundaries), so a ray found
    inside them indexes the batch whatever ``packets`` holds."""
    cdef int32_t a, b
    if first < 0 or first >= n:
        return 1
    if not (packets[k_big[0]] <= first < packets[k_big[0] + 1]):   # usually the same one
        k_big[0] = large_packet(packets, n_big, first)
    a, b = packets[k_big[0]], packets[k_big[0] + 1]
    lo[0], hi[0] = (a if a > 0 else 0), (b if b < n else n)
    return 0


cdef inline int range_bad(const int32_t *order, Py_ssize_t a, Py_ssize_t b, int32_t lo,
                          int32_t hi) noexcept nogil:
    """Any of ``order[a:b]`` outside ``[lo, hi)`` (a loop the compiler vectorises)."""
    cdef Py_ssize_t i
    cdef int bad = 0
    for i in range(a, b):
        bad |= (order[i] < lo) | (order[i] >= hi)
    return bad


cdef inline int32_t checked_ray(int32_t j, int32_t lo, int32_t hi, int32_t n, uint8_t *seen,
                                int *bad) noexcept nogil:
    """``j`` if it is a ray of the large packet ``[lo, hi)`` (within ``[0, n)``), else -1;
    ``*bad`` set unless it is also seen for the first time (``seen``: n + 1 bytes, the
    last a spare), which marks it."""
    cdef int inside = (j >= lo) & (j < hi)
    cdef int32_t slot = j if inside else n
    bad[0] |= (not inside) | seen[slot]
    seen[slot] = 1
    return j if inside else -1


cdef inline int rays_bad(const int32_t *order, Py_ssize_t a, Py_ssize_t b, int32_t lo,
                         int32_t hi, uint8_t *seen) noexcept nogil:
    """Any of ``order[a:b]`` outside ``[lo, hi)``; marks each (``seen``: a byte per ray,
    set here).  The range first (:func:`range_bad`, a loop the compiler vectorises),
    then a store per ray, rays known to be inside.  A ray seen twice is not tested
    here: n positions whose rays all lie in ``[0, n)`` hold each ray once exactly when
    every ray is marked (:func:`all_marked`).  The stores alone, without a load of the
    byte each one writes, took 0.84-0.92x the whole check's time (the orders ``nah``
    and ``two_point`` give shadow and diffuse rays, AVX-512); eight a loop iteration
    (the compiler unrolls none of it) 0.68-0.75x of that (camera, shadow and diffuse
    rays, the same orders, AVX2 and AVX-512)."""
    cdef Py_ssize_t i = a
    if range_bad(order, a, b, lo, hi):
        return 1
    while i + 8 <= b:
        seen[order[i]] = 1
        seen[order[i + 1]] = 1
        seen[order[i + 2]] = 1
        seen[order[i + 3]] = 1
        seen[order[i + 4]] = 1
        seen[order[i + 5]] = 1
        seen[order[i + 6]] = 1
        seen[order[i + 7]] = 1
        i += 8
    while i < b:
        seen[order[i]] = 1
        i += 1
    return 0


cdef inline int all_marked(const uint8_t *seen, Py_ssize_t n) noexcept nogil:
    """Whether ``seen[0:n]`` are all 1 (a loop the compiler vectorises)."""
    cdef Py_ssize_t i
    cdef uint8_t every = 1
    for i in range(n):
        every &= seen[i]
    return every


cdef inline int sub_packet_bad(const int32_t *order, Py_ssize_t a, Py_ssize_t b,
                               const int32_t *packets, Py_ssize_t n_big, int32_t n,
                               Py_ssize_t *k_big, uint8_t *seen) noexcept nogil:
    """A sorter's sub-packet ``order[a:b]`` (a < b): rays of ``[0, n)``, all in one large
    packet and none seen before (see :func:`packet_bounds`, :func:`checked_ray`)."""
    cdef Py_ssize_t i
    cdef int32_t lo, hi
    cdef int bad = 0
    if packet_bounds(order[a], packets, n_big, n, k_big, &lo, &hi):
        return 1
    for i in range(a, b):
        checked_ray(order[i], lo, hi, n, seen, &bad)
    return bad


cdef inline int offsets_bad(const int32_t *offsets, Py_ssize_t n_sub, int32_t n,
                            int32_t max_packet) noexcept nogil:
    """A sorter's offsets: from 0 to n, sub-packets of 1..max_packet rays."""
    cdef Py_ssize_t k
    cdef long long size
    cdef int bad = (offsets[0] != 0) | (offsets[n_sub] != n)
    for k in range(n_sub):
        size = <long long> offsets[k + 1] - offsets[k]
        bad |= (size <= 0) | (size > max_packet)
    return bad


ctypedef fused float_bits:     # a float32's bits, or a float64's
    uint32_t
    uint64_t


cdef inline int nonfinite(const float_bits *x, Py_ssize_t a, Py_ssize_t b) noexcept nogil:
    """Any of the float values x[a:b] (as bits: uint32 for float32, uint64 for float64)
    infinite or NaN: all exponent bits set."""
    cdef Py_ssize_t i
    cdef int bad = 0
    cdef float_bits ones
    if float_bits is uint32_t:      # (decided when Cython specialises: one branch is C)
        ones = 0x7F800000u
    else:
        ones = 0x7FF0000000000000ull
    for i in range(a, b):
        bad |= (x[i] & ones) == ones
    return bad


cdef inline int parents_weights_bad(const int32_t *parent, const uint32_t *w0,
                                    const uint32_t *w1, const uint32_t *w2, Py_ssize_t a,
                                    Py_ssize_t b, uint32_t n) noexcept nogil:
    """parent[a:b] in [0, n) and ascending (from parent[a - 1] when a > 0), and the
    float32 weights (as bits) w0, w1, w2 [a:b] finite, in one loop."""
    cdef Py_ssize_t i
    cdef int bad = 0
    if a == 0 and b > 0:
        bad = ((<uint32_t> parent[0] >= n) | nonfinite(w0, 0, 1) | nonfinite(w1, 0, 1)
               | nonfinite(w2, 0, 1))
        a = 1
    for i in range(a, b):
        bad |= ((<uint32_t> parent[i] >= n) | (parent[i] < parent[i - 1])
                | ((w0[i] & 0x7F800000u) == 0x7F800000u) | ((w1[i] & 0x7F800000u) == 0x7F800000u)
                | ((w2[i] & 0x7F800000u) == 0x7F800000u))
    return bad


cdef inline int slots_bad(const int32_t *slot, Py_ssize_t a, Py_ssize_t b,
                          uint32_t slots) noexcept nogil:
    """:func:`slot_bad` for any of slot[a:b]."""
    cdef Py_ssize_t i
    cdef int bad = 0
    for i in range(a, b):
        bad |= slot_bad(slot[i], slots)
    return bad
