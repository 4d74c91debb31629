"""Gather rays into aligned sub-packets and scatter hits back (nogil).

The gather follows the paper's section 3: rays are read through the sorter's
index order into a temporary 4-ray packet and written with 4-wide stores into
16-byte aligned structure-of-arrays sub-packets, computing the inverse
direction on the way (``rs_gather4`` in simd.h).
"""
from libc.stdint cimport int32_t
from libc.math cimport INFINITY
from raysort._types cimport (rs_gather4, rs_isa_name, rs_prefetch, RS_RAY_ROWS,
                             RS_PACKET_ROWS, RS_PACKET_T)

cdef enum:
    PREFETCH_AHEAD = 16     # rays (in the sorter's order) between a prefetch and its use


def gather(const float[:, ::1] src, const int32_t[::1] order, const int32_t[::1] offsets,
           const int32_t[::1] starts, float[:, ::1] dst, int32_t[::1] prim, float[::1] u,
           float[::1] v, int32_t[::1] index):
    cdef int n_packets = starts.shape[0], k, j, lane, count, base, s, ahead
    cdef int n_rays = offsets[n_packets] if n_packets else 0
    cdef const float *src_rows[RS_RAY_ROWS]
    cdef float *dst_rows[RS_PACKET_ROWS]
    cdef int32_t idx[4]
    cdef int c
    for c in range(RS_RAY_ROWS):
        src_rows[c] = &src[c, 0]
    for c in range(RS_PACKET_ROWS):
        dst_rows[c] = &dst[c, 0]
    with nogil:
        for k in range(n_packets):
            base = offsets[k]
            count = offsets[k + 1] - base
            for j in range(0, count, 4):
                # the rows of rays further on, which the order makes random accesses
                for lane in range(4):
                    ahead = base + j + lane + PREFETCH_AHEAD
                    if ahead < n_rays:
                        for c in range(RS_RAY_ROWS):
                            rs_prefetch(&src[c, order[ahead]])
                for lane in range(4):
                    idx[lane] = order[base + j + lane] if j + lane < count else -1
                s = starts[k] + j
                rs_gather4(dst_rows, &prim[0], &u[0], &v[0], s, src_rows, idx)
                for lane in range(4):
                    index[s + lane] = idx[lane]
        # lanes after the last sub-packet (an empty batch still has 4 lanes)
        s = starts[n_packets - 1] + ((offsets[n_packets] - offsets[n_packets - 1] + 3) & ~3) \
            if n_packets else 0
        for j in range(s, dst.shape[1], 4):
            for lane in range(4):
                idx[lane] = -1
            rs_gather4(dst_rows, &prim[0], &u[0], &v[0], j, src_rows, idx)
            for lane in range(4):
                index[j + lane] = -1


def scatter(const float[:, ::1] rows, const int32_t[::1] prim, const float[::1] u,
            const float[::1] v, const int32_t[::1] index, float[::1] t_out,
            int32_t[::1] prim_out, float[::1] u_out, float[::1] v_out):
    cdef int s, i
    with nogil:
        for s in range(index.shape[0]):
            i = index[s]
            if i < 0:
                continue
            if prim[s] >= 0:
                t_out[i] = rows[RS_PACKET_T, s]
                prim_out[i] = prim[s]
                u_out[i] = u[s]
                v_out[i] = v[s]
            else:
                t_out[i] = INFINITY
                prim_out[i] = -1
                u_out[i] = 0
                v_out[i] = 0


def scatter_occluded(const int32_t[::1] prim, const int32_t[::1] index, unsigned char[::1] out):
    cdef int s
    with nogil:
        for s in range(index.shape[0]):
            if index[s] >= 0:
                out[index[s]] = prim[s] >= 0


def add_unoccluded(double[:, ::1] radiance, const int32_t[::1] slot,
                   const float[:, :] contribution, const unsigned char[::1] occluded):
    """``radiance[slot[i]] += contribution[:, i]`` for every ray i not occluded, in order
    (what ``np.add.at`` does, without its per-element overhead)."""
    cdef Py_ssize_t i, n = slot.shape[0]
    cdef int c
    if contribution.shape[0] != 3 or contribution.shape[1] != n or occluded.shape[0] != n \
            or radiance.shape[1] != 3:
        raise ValueError("add_unoccluded: radiance (k, 3), slot (n,), contribution (3, n) and "
                         "occluded (n,) expected")
    for i in range(n):
        if not 0 <= slot[i] < radiance.shape[0]:
            raise IndexError(f"add_unoccluded: slot[{i}] = {slot[i]} is out of range")
    with nogil:
        for i in range(n):
            if not occluded[i]:
                for c in range(3):
                    radiance[slot[i], c] += contribution[c, i]


def compiled_isa():
    """The ISA this build of the kernels was compiled for (see raysort.isa)."""
    return rs_isa_name().decode()
