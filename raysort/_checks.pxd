"""The contract rules one element at a time, shared by the stand-alone checks
(:mod:`raysort._contract`) and the checks fused into the gather and the scatter
(:mod:`raysort._gather`), so both apply the same rules.

Each returns non-zero when the element breaks its contract, written without
branches so that loops over a block vectorise.  A float ``x`` is finite exactly
when ``x - x == 0``.
"""
from libc.stdint cimport int32_t, uint8_t, uint32_t


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


cdef inline int sub_packet_bad(const int32_t *order, Py_ssize_t a, Py_ssize_t b,
                               const int32_t *packets, Py_ssize_t n_big, int32_t n,
                               Py_ssize_t *k_big, uint8_t *seen) noexcept nogil:
    """A sorter's sub-packet ``order[a:b]`` (a < b): rays of ``[0, n)``, all in one large
    packet (``packets``: n_big + 1 valid boundaries; ``k_big`` the one of the previous
    sub-packet, updated) and none seen before; marks them seen (``seen``: n + 1 bytes, the
    last a spare)."""
    cdef Py_ssize_t i
    cdef int32_t j = order[a], lo, hi
    cdef int bad = 0, inside
    if j < 0 or j >= n:
        return 1
    if not (packets[k_big[0]] <= j < packets[k_big[0] + 1]):   # usually the same one
        k_big[0] = large_packet(packets, n_big, j)
    lo, hi = packets[k_big[0]], packets[k_big[0] + 1]
    for i in range(a, b):
        j = order[i]
        inside = (j >= lo) & (j < hi)
        j = j if inside else n
        bad |= (not inside) | seen[j]
        seen[j] = 1
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
