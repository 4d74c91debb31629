"""Gather rays into aligned sub-packets and scatter hits back (nogil).

The gather follows the paper's section 3: rays are read through the sorter's
index order and written with full-width SIMD stores into 16-byte aligned
structure-of-arrays sub-packets, computing the inverse direction on the way
(4 rays at a time as in the paper, 8 with AVX2 and 16 with AVX-512: gather.h).
"""
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t
from libc.math cimport INFINITY
from libc.string cimport memcpy
from raysort._checks cimport offsets_bad, packet_bounds, range_bad, slot_bad, unaligned16
from raysort._types cimport (rs_isa_name, RS_MAX_PACKET, RS_RAY_ROWS, RS_RAY_TMIN,
                             RS_RAY_TMAX, RS_PACKET_ROWS, RS_PACKET_T)

import numpy as np


cdef extern from "raysort/gather.h" nogil:
    int64_t rs_gather_lanes(float *const dst[RS_PACKET_ROWS], int32_t *prim, float *u,
                            float *v, float *tmax, const float *const src[RS_RAY_ROWS],
                            const int32_t *index, int64_t capacity, int64_t n_src)


cdef extern from "raysort/lanes.h" nogil:
    int rs_zero_bytes16(const uint8_t *p)
    int rs_lowest(int bits)
    void rs_fill_uncached(float *p, int64_t n, float value)


cdef enum:
    RUN = 64                # parents follow_paths checks for a consecutive run at once

cdef enum:
    UNWRITTEN = -2          # prim of a ray no lane was scattered to (see scatter_each)
    UNWRITTEN_OCCLUDED = 2  # the same for an any-hit query's flags


def sub_packets(const int32_t[::1] offsets, int32_t n, int32_t max_packet=RS_MAX_PACKET):
    """``(counts, starts, lanes)`` of a sorter's ``offsets`` in one pass: sub-packet k's
    rays, where it starts (as :func:`layout`) and the lanes they take; None if the
    offsets do not run from 0 to ``n`` in sub-packets of 1..max_packet rays.  What
    :func:`raysort.rays.gather_checked` needs before the packets are allocated."""
    cdef Py_ssize_t k, m = offsets.shape[0] - 1
    cdef int64_t lanes = 0
    cdef int bad
    if m < 0:
        return None
    with nogil:
        bad = offsets_bad(&offsets[0], m, n, max_packet)
    if bad:
        return None
    counts = np.empty(m, dtype=np.int32)
    starts = np.empty(m, dtype=np.int32)
    cdef int32_t[::1] c = counts, st = starts
    with nogil:
        for k in range(m):
            c[k] = offsets[k + 1] - offsets[k]
            st[k] = <int32_t> lanes
            lanes += (<int64_t> c[k] + 3) & ~3
    return counts, starts, max(lanes, 4)


def fixed_offsets(const int32_t[::1] packets, int32_t size):
    """Sub-packet offsets cutting every large packet ``[packets[i], packets[i + 1])`` into
    runs of ``size`` rays (the last of each may be shorter; an empty packet gets none):
    :func:`raysort.sdk.fixed_packets` in one pass, for sorter ``none``.  ``packets``
    should not decrease (a packet that does gets no sub-packet)."""
    cdef Py_ssize_t i, k = 0, m = packets.shape[0] - 1
    cdef int64_t total = 1, start, length
    if m < 0 or size < 1:
        raise ValueError("fixed_offsets: at least one boundary and a size of 1 or more")
    for i in range(m):
        length = <int64_t> packets[i + 1] - packets[i]
        if length > 0:
            total += (length + size - 1) // size
    out = np.empty(total, dtype=np.int32)
    cdef int32_t[::1] offsets = out
    with nogil:
        for i in range(m):
            start = packets[i]
            while start < packets[i + 1]:
                offsets[k] = <int32_t> start
                k += 1
                start += size
        offsets[k] = packets[m]
    return out


def pad_rays(float[:, ::1] data, Py_ssize_t a, Py_ssize_t b):
    """Make lanes ``a..b`` of a ray batch's rows (``RayBatch.data``) padding: origin and
    direction 0, tmin +inf, tmax -inf (inactive), with stores that bypass the caches
    (nothing reads padding soon)."""
    cdef int r
    if data.shape[0] != RS_RAY_ROWS or not 0 <= a <= b <= data.shape[1]:
        raise ValueError("pad_rays: the rows of a ray batch and 0 <= a <= b <= capacity")
    with nogil:
        for r in range(RS_RAY_ROWS):
            rs_fill_uncached(&data[r, a] if b > a else NULL, b - a,
                             INFINITY if r == RS_RAY_TMIN else
                             -INFINITY if r == RS_RAY_TMAX else 0.0)


def sample_paths(const int32_t[::1] pixels, const int32_t[::1] slots,
                 const int32_t[::1] samples, int32_t[::1] pixel, int32_t[::1] sample,
                 int32_t[::1] slot):
    """Write the paths of a batch that holds, sample by sample, a pass over ``pixels``
    (each with its accumulator row in ``slots``) into ``pixel``, ``sample`` and ``slot``:
    ``np.tile(pixels, k)``, ``np.repeat(samples, n)`` and ``np.tile(slots, k)``, in one
    pass.  ValueError at arrays of other lengths."""
    cdef Py_ssize_t n = pixels.shape[0], k = samples.shape[0], s, p, i
    if slots.shape[0] != n:
        raise ValueError("sample_paths: one slot per pixel")
    if pixel.shape[0] != k * n or sample.shape[0] != k * n or slot.shape[0] != k * n:
        raise ValueError("sample_paths: pixel, sample and slot of k * n values expected")
    with nogil:
        for s in range(k):
            for p in range(n):
                i = s * n + p
                pixel[i] = pixels[p]
                sample[i] = samples[s]
                slot[i] = slots[p]


def follow_paths(const int32_t[::1] parent, pixel_array, sample_array, slot_array, t_array):
    """``(pixel, sample, slot, t)`` of the rays ``parent`` (each an index into the four
    arrays: int32, and float32 ``t``): the paths a shader's next rays continue and the
    hit distance each path ended its last ray at, in one pass (``Paths.take`` and
    ``t[parent]``); a run of 64 consecutive parents is copied row by row, and when every
    ray went on (``parent`` is ``0, 1, ..., n - 1``: a closed scene's first bounce, most
    batches) the four arrays are returned themselves.  IndexError, with nothing
    returned, at a parent out of range."""
    cdef const int32_t[::1] pixel = pixel_array, sample = sample_array, slot = slot_array
    cdef const float[::1] t = t_array
    cdef Py_ssize_t i, e, k, m = parent.shape[0]
    cdef uint32_t n = pixel.shape[0]
    cdef int32_t p
    cdef int bad = 0, run
    if sample.shape[0] != n or slot.shape[0] != n or t.shape[0] != n:
        raise ValueError("follow_paths: pixel, sample, slot and t must be of one length")
    if m == n:
        with nogil:
            i = 0
            while i < m and not bad:
                e = min(i + 16 * RUN, m)
                for k in range(i, e):
                    bad |= parent[k] != k
                i = e
        if not bad:
            return pixel_array, sample_array, slot_array, t_array
        bad = 0
    new_pixel = np.empty(m, dtype=np.int32)
    new_sample = np.empty(m, dtype=np.int32)
    new_slot = np.empty(m, dtype=np.int32)
    new_t = np.empty(m, dtype=np.float32)
    cdef int32_t[::1] o_pixel = new_pixel, o_sample = new_sample, o_slot = new_slot
    cdef float[::1] o_t = new_t
    with nogil:
        i = 0
        while i < m:
            p = parent[i]
            e = min(i + RUN, m)
            # a run of consecutive parents (every ray before it went on): copies
            run = (e - i == RUN and <uint32_t> p < n and <uint32_t> p + RUN <= n
                   and parent[e - 1] == p + RUN - 1)
            if run:
                for k in range(RUN):
                    run &= parent[i + k] == p + k
            if run:
                memcpy(&o_pixel[i], &pixel[p], RUN * sizeof(int32_t))
                memcpy(&o_sample[i], &sample[p], RUN * sizeof(int32_t))
                memcpy(&o_slot[i], &slot[p], RUN * sizeof(int32_t))
                memcpy(&o_t[i], &t[p], RUN * sizeof(float))
                i = e
                continue
            for i in range(i, e):
                p = parent[i]
                if <uint32_t> p >= n:
                    bad = 1
                    break
                o_pixel[i] = pixel[p]
                o_sample[i] = sample[p]
                o_slot[i] = slot[p]
                o_t[i] = t[p]
            if bad:
                break
            i = e
    if bad:
        raise IndexError(f"follow_paths: parent[{i}] = {parent[i]} is out of range 0..{n - 1}")
    return new_pixel, new_sample, new_slot, new_t


def layout(const int32_t[::1] counts, int32_t[::1] starts):
    """``starts[k]``: where sub-packet k of ``counts[k]`` rays starts, each at a multiple
    of 4 after the one before; returns the lanes they take (at least 4)."""
    cdef Py_ssize_t k
    cdef int64_t lanes = 0
    if starts.shape[0] != counts.shape[0]:
        raise ValueError("layout: one start per sub-packet")
    with nogil:
        for k in range(counts.shape[0]):
            starts[k] = <int32_t> lanes
            lanes += (<int64_t> counts[k] + 3) & ~3
    return max(lanes, 4)


def gather(const float[:, ::1] src, const int32_t[::1] order, const int32_t[::1] offsets,
           const int32_t[::1] starts, float[:, ::1] dst, int32_t[::1] prim, float[::1] u,
           float[::1] v, int32_t[::1] index, const int32_t[::1] packets, float[::1] t0=None,
           bint check_order=True):
    """Gather ``order[offsets[k]:offsets[k + 1]]`` into sub-packet k, checking the sorter's
    order on the way (unless ``check_order`` is False, for a trusted sorter): each
    sub-packet must hold rays of ``[0, n)`` from one large packet (``packets``: valid
    boundaries ending at n).  (That no ray comes twice is left to the scatter, which
    writes each ray once: see :func:`unwritten`.)  ``offsets`` must be valid
    (:func:`sub_packets`; ValueError unless they ascend from 0 to n), ``len(order) == n``,
    and ``starts``/``dst``/... sized for them and 16-byte aligned.  With ``t0``, the row
    ``t`` as gathered (each ray's tmax) is written there too.

    Two passes: the order is laid out lane by lane into ``index`` (checked on the way),
    then every lane's rows are gathered from it, as wide as the ISA allows
    (``rs_gather_lanes`` in gather.h).

    Returns ``(order_ok, bad_ray)``: ``order_ok`` is False at the first sub-packet that
    breaks the order contract (the gather stops there); ``bad_ray`` is a ray that breaks
    the ray contract (active, yet tmin < 0 or not finite; stored inactive), or -1.
    """
    cdef Py_ssize_t n_packets = starts.shape[0], capacity = dst.shape[1], k, k_big = 0, j
    cdef Py_ssize_t count, base, s, end = 0
    cdef Py_ssize_t checked = 0     # sub-packets before it: order checked
    cdef int32_t n = order.shape[0]
    cdef const float *src_rows[RS_RAY_ROWS]
    cdef float *dst_rows[RS_PACKET_ROWS]
    cdef int c, order_bad = 0, offsets_wrong = 0
    cdef int64_t bad_lane = -1
    cdef int32_t lo = 0, hi = 0
    cdef float *tmax = NULL
    if src.shape[0] != RS_RAY_ROWS or dst.shape[0] != RS_PACKET_ROWS or src.shape[1] < max(n, 1):
        raise ValueError("gather: src must hold the ray rows of the n rays, dst the packet rows")
    if (prim.shape[0] != capacity or u.shape[0] != capacity or v.shape[0] != capacity
            or index.shape[0] != capacity or offsets.shape[0] != n_packets + 1):
        raise ValueError("gather: prim, u, v and index must hold one value per lane, "
                         "offsets one more than starts")
    if n_packets and starts[n_packets - 1] + (
            (offsets[n_packets] - offsets[n_packets - 1] + 3) & ~3) > capacity:
        raise ValueError("gather: the last sub-packet ends beyond the lanes")
    if offsets[0] != 0 or offsets[n_packets] != n or (n_packets and packets.shape[0] < 2):
        raise ValueError("gather: offsets must run from 0 to len(order), packets hold at "
                         "least 2 boundaries (if there are sub-packets)")
    if t0 is not None:
        if t0.shape[0] != capacity:
            raise ValueError("t0 must hold one value per lane")
        tmax = &t0[0]
    if capacity % 4 or capacity and (unaligned16(&dst[0, 0]) or unaligned16(&prim[0])
                                     or unaligned16(&u[0]) or unaligned16(&v[0])
                                     or unaligned16(tmax)):
        raise ValueError("gather: dst, prim, u, v and t0 must start 16-byte aligned, with a "
                         "multiple of 4 lanes")
    for c in range(RS_RAY_ROWS):
        src_rows[c] = &src[c, 0]
    for c in range(RS_PACKET_ROWS):
        dst_rows[c] = &dst[c, 0]
    with nogil:
        for k in range(n_packets):
            base = offsets[k]
            count = offsets[k + 1] - base
            if count < 1 or offsets[k + 1] > n:
                offsets_wrong = 1   # so every offset read lies in [0, n]
                break
            if check_order and k >= checked:
                # the run of sub-packets from k whose first rays share a large packet, then
                # every ray of the run in it: one long loop rather than one per sub-packet
                if packet_bounds(order[base], &packets[0], packets.shape[0] - 1, n, &k_big,
                                 &lo, &hi):
                    order_bad = 1
                    break
                checked = k + 1
                while (checked < n_packets and offsets[checked - 1] < offsets[checked] < n
                       and lo <= order[offsets[checked]] < hi):
                    checked += 1
                if not offsets[checked - 1] < offsets[checked] <= n:
                    offsets_wrong = 1
                    break
                if range_bad(&order[0], base, offsets[checked], lo, hi):
                    order_bad = 1
                    break
            s = starts[k]
            if s < end or s + ((count + 3) & ~3) > capacity:
                order_bad = 1       # sub-packets overlap or leave the lanes: starts do not
                break               # fit offsets
            end = s + ((count + 3) & ~3)
            if not check_order and range_bad(&order[0], base, base + count, 0, n):
                order_bad = 1       # a trusted order is not checked, but never read beyond n
                break
            memcpy(&index[s], &order[base], count * sizeof(int32_t))
            for j in range(s + count, end):
                index[j] = -1
        if not order_bad:
            for j in range(end, capacity):      # lanes after the last sub-packet
                index[j] = -1
            bad_lane = rs_gather_lanes(dst_rows, &prim[0], &u[0], &v[0], tmax, src_rows,
                                       &index[0], capacity, src.shape[1])
    if offsets_wrong:
        raise ValueError("gather: offsets must ascend, each sub-packet 1 ray or more")
    if order_bad:
        return False, -1
    return True, (index[bad_lane] if bad_lane >= 0 else -1)


def scatter(const float[:, ::1] rows, const int32_t[::1] prim, const float[::1] u,
            const float[::1] v, const int32_t[::1] index, float[::1] t_out,
            int32_t[::1] prim_out, float[::1] u_out, float[::1] v_out):
    """Every lane's hit to its ray ``index[lane]`` (-1: none); False, with nothing more
    written, at a lane whose index is beyond the outputs.  ValueError if the lanes'
    arrays or the outputs differ in length."""
    cdef Py_ssize_t s
    cdef int32_t i
    cdef uint32_t n = t_out.shape[0]
    cdef bint ok = True
    if (rows.shape[0] <= RS_PACKET_T or rows.shape[1] < index.shape[0]
            or prim.shape[0] < index.shape[0] or u.shape[0] < index.shape[0]
            or v.shape[0] < index.shape[0] or prim_out.shape[0] != n or u_out.shape[0] != n
            or v_out.shape[0] != n):
        raise ValueError("scatter: the packets' rows, prim, u and v must hold every lane of "
                         "index, and the hits' t, prim, u and v one value per ray")
    with nogil:
        for s in range(index.shape[0]):
            i = index[s]
            if i < 0:
                continue
            if <uint32_t> i >= n:
                ok = False
                break
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
    return ok


def scatter_occluded(const int32_t[::1] prim, const int32_t[::1] index, unsigned char[::1] out):
    """``out[index[lane]]``: the lane found a hit; False at an index beyond ``out``.
    ValueError if ``prim`` holds fewer lanes than ``index``."""
    cdef Py_ssize_t s
    cdef uint32_t n = out.shape[0]
    cdef bint ok = True
    if prim.shape[0] < index.shape[0]:
        raise ValueError("scatter_occluded: prim must hold every lane of index")
    with nogil:
        for s in range(index.shape[0]):
            if index[s] >= 0:
                if <uint32_t> index[s] >= n:
                    ok = False
                    break
                out[index[s]] = prim[s] >= 0
    return ok


def scatter_each(const float[:, ::1] rows, const int32_t[::1] prim, const float[::1] u,
                 const float[::1] v, const int32_t[::1] index, Py_ssize_t n, bint any_hit):
    """Every lane's hit to its ray ``index[lane]`` (-1: none), for lanes that hold each of
    the ``n`` rays once: ``(out, fault)``, ``out`` a new float32 (4, n) block of the rows
    t, prim (int32 bits), u, v, or with ``any_hit`` a uint8 (n,) array (1: occluded);
    ``fault`` 0, ``1`` at a lane whose index is beyond ``n`` (nothing more written), or
    ``2`` when a ray got no lane (so another came twice: a sorter's order that is no
    permutation)."""
    cdef Py_ssize_t s
    cdef int32_t i
    cdef int fault = 0, left = 0
    cdef int32_t[::1] out_prim
    cdef float[:, ::1] rows_out
    cdef uint8_t[::1] flags
    if n < 0 or prim.shape[0] != index.shape[0] or (not any_hit and (
            rows.shape[0] != RS_PACKET_ROWS or rows.shape[1] != index.shape[0]
            or u.shape[0] != index.shape[0] or v.shape[0] != index.shape[0])):
        raise ValueError("scatter_each: rows, prim, u, v and index must hold one value per lane")
    if any_hit:
        out = np.empty(n, dtype=np.uint8)
        flags = out
        with nogil:
            for s in range(n):
                flags[s] = UNWRITTEN_OCCLUDED
            for s in range(index.shape[0]):
                i = index[s]
                if i >= 0:
                    if i >= n:
                        fault = 1
                        break
                    flags[i] = prim[s] >= 0
            if not fault:
                for s in range(n):
                    left |= flags[s] == UNWRITTEN_OCCLUDED
        return out, fault or 2 * left
    out = np.empty((4, n), dtype=np.float32)
    rows_out = out
    out_prim = out[1].view(np.int32)
    with nogil:
        for s in range(n):
            out_prim[s] = UNWRITTEN
        for s in range(index.shape[0]):
            i = index[s]
            if i < 0:
                continue
            if i >= n:
                fault = 1
                break
            if prim[s] >= 0:
                rows_out[0, i] = rows[RS_PACKET_T, s]
                out_prim[i] = prim[s]
                rows_out[2, i] = u[s]
                rows_out[3, i] = v[s]
            else:
                rows_out[0, i] = INFINITY
                out_prim[i] = -1
                rows_out[2, i] = 0
                rows_out[3, i] = 0
        if not fault:
            for s in range(n):
                left |= out_prim[s] == UNWRITTEN
    return out, fault or 2 * left


def add_unoccluded(double[:, ::1] radiance, const int32_t[::1] slot,
                   const float[:, :] contribution, const unsigned char[::1] occluded):
    """``radiance[slot[i]] += contribution[:, i]`` for every ray i not occluded, in order
    (what ``np.add.at`` does, without its per-element overhead).  The unoccluded rays of
    every 16 are found by one comparison and visited by their bits, so the loop has no
    branch for a test that goes either way at random."""
    cdef Py_ssize_t i, j, n = slot.shape[0], rows = radiance.shape[0], step
    cdef int bad = 0, lit
    cdef double *row
    cdef const float *c0
    cdef const float *c1
    cdef const float *c2
    if contribution.shape[0] != 3 or contribution.shape[1] != n or occluded.shape[0] != n \
            or radiance.shape[1] != 3:
        raise ValueError("add_unoccluded: radiance (k, 3), slot (n,), contribution (3, n) and "
                         "occluded (n,) expected")
    if n == 0:
        return
    with nogil:
        for i in range(n):
            bad |= slot_bad(slot[i], <uint32_t> rows)
    if bad:
        for i in range(n):
            if not 0 <= slot[i] < rows:
                raise IndexError(f"add_unoccluded: slot[{i}] = {slot[i]} is out of range")
    step = contribution.strides[1] // sizeof(float)
    c0, c1, c2 = &contribution[0, 0], &contribution[1, 0], &contribution[2, 0]
    with nogil:
        i = 0
        while i < n:
            if i + 16 <= n:
                lit = rs_zero_bytes16(&occluded[i])
            else:                       # the last few rays
                lit = 0
                for j in range(i, n):
                    lit |= (occluded[j] == 0) << (j - i)
            while lit:
                j = i + rs_lowest(lit)
                lit &= lit - 1
                row = &radiance[0, 0] + 3 * slot[j]
                row[0] += c0[j * step]
                row[1] += c1[j * step]
                row[2] += c2[j * step]
            i += 16


def compiled_isa():
    """The ISA this build of the kernels was compiled for (see raysort.isa)."""
    return rs_isa_name().decode()
