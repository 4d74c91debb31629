"""Gather rays into aligned sub-packets and scatter hits back (nogil).

The gather follows the paper's section 3: rays are read through the sorter's
index order into a temporary 4-ray packet and written with 4-wide stores into
16-byte aligned structure-of-arrays sub-packets, computing the inverse
direction on the way (``rs_gather4`` in simd.h).
"""
from libc.stdint cimport int32_t
from libc.math cimport INFINITY
from raysort._types cimport (rs_gather4, rs_isa_name, RS_RAY_ROWS, RS_PACKET_ROWS,
                             RS_PACKET_T)


def gather(const float[:, ::1] src, const int32_t[::1] order, const int32_t[::1] offsets,
           const int32_t[::1] starts, float[:, ::1] dst, int32_t[::1] prim, float[::1] u,
           float[::1] v, int32_t[::1] index):
    cdef int n_packets = starts.shape[0], k, j, lane, count, base, s
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


def compiled_isa():
    """The ISA this build of the kernels was compiled for (see raysort.isa)."""
    return rs_isa_name().decode()
