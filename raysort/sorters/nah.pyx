"""``nah``: the ray sorter of Nah, Jung, Park and Han (section 3 of the paper).

Per large packet, in linear time and touching only ray indices:

1. every ray goes to one of 24 direction buckets (octant x major axis), and
   each bucket's origin bounding box is grown in the same pass;
2. each bucket gets an origin grid of 1 to 8 cells: an axis is split in two at
   the middle of the bucket's origin box when the box is wider on that axis
   than ``threshold`` (a quarter) of the scene root box;
3. a counting sort on (bucket, cell) gives the order; every non-empty cell
   becomes sub-packets of at most ``packet_size`` rays (64, Manta's
   ``RayPacket::MaxSize``, which bounded the paper's sub-packets).

Rays with NaN components land in a defined bucket and cell (comparisons with
NaN are false), so the sorter never fails on them; the gather marks them
inactive.
"""
from libc.stdint cimport int32_t, uint8_t
from libc.math cimport INFINITY, fabsf
from raysort._types cimport (rs_minf, rs_maxf, RS_RAY_OX, RS_RAY_DX, RS_RAY_DY, RS_RAY_DZ,
                             RS_RAY_ROWS)

import numpy as np

from raysort import isa
from raysort.sdk import (MAX_PACKET, ConfigError, Sorter, check_packets, fixed_packets,
                         integer, number)

cdef extern from *:
    """
    /* The counting sort's last step: ray i goes to order[count[key]++].  Functions of
     * their own (not inlined into sort_packet), each a loop that keeps everything in
     * registers.  How fast a count's update reaches the next load of the same count
     * decides the speed, and the best form depends on the rays (Zen 3, AVX2, 65,536
     * Sibenik rays; the whole sort took 0.84 ms on diffuse and 0.69 ms on camera
     * rays with this loop inlined):
     * - the counts through a pointer, for most rays: diffuse rays 0.84 -> 0.67 ms
     *   (camera rays 0.69 -> 0.77 ms);
     * - a copy of the counts on the stack, for coherent rays (camera rays: most rays
     *   update one count, ray after ray), whose store-to-load forwarding the CPU
     *   renames (a stack slot): camera rays 0.69 -> 0.66 ms (diffuse rays 0.84 ->
     *   0.81 ms: there the renaming mispredicts).
     * (Pass 1 written the same two ways measured slower than as it is.) */
    __attribute__((noinline))
    static void rs_nah_place(const uint8_t *key, int start, int end, int *count,
                             int32_t *order)
    {
        for (int i = start; i < end; ++i)
            order[count[key[i - start]]++] = i;
    }
    /* The counts of keys[0, n) into count (zeroed), through a pointer (see above), in a
     * pass of their own: counted in pass 2's loop, in its stack array, the sort took
     * 0.68 ms on diffuse and 0.66 ms on camera rays; so 0.60 and 0.56 ms. */
    __attribute__((noinline))
    static void rs_nah_count(const uint8_t *key, int n, int *count)
    {
        for (int i = 0; i < n; ++i)
            count[key[i]]++;
    }
    __attribute__((noinline))
    static void rs_nah_place_coherent(const uint8_t *key, int start, int end,
                                      const int *count, int n_keys, int32_t *order)
    {
        int at[256];            /* a key is a byte */
        memcpy(at, count, n_keys * sizeof(int));
        for (int i = start; i < end; ++i)
            order[at[key[i - start]]++] = i;
    }
    """
    void place "rs_nah_place"(const uint8_t *key, int start, int end, int *count,
                              int32_t *order) noexcept nogil
    void count_keys "rs_nah_count"(const uint8_t *key, int n, int *count) noexcept nogil
    void place_coherent "rs_nah_place_coherent"(const uint8_t *key, int start, int end,
                                                const int *count, int n_keys,
                                                int32_t *order) noexcept nogil


cdef enum:
    BUCKETS = 24            # direction buckets: octant x major axis
    KEYS = BUCKETS * 8      # (bucket, origin-grid cell)


cdef inline int direction_bucket(float dx, float dy, float dz) noexcept nogil:
    """octant * 3 + major axis; octant bit k is set when component k is negative.

    The major axis is the first of the largest |components| (y beats x only when
    larger, z beats the larger of them only when larger), chosen without branches:
    for diffuse rays a branch on it would mispredict every other ray."""
    cdef int octant = (dx < 0) | (dy < 0) << 1 | (dz < 0) << 2
    cdef float ax = fabsf(dx), ay = fabsf(dy), az = fabsf(dz)
    cdef int y_wins = ay > ax
    cdef int z_wins = az > rs_maxf(ay, ax)      # rs_maxf(ay, ax) = ay > ax ? ay : ax
    return octant * 3 + y_wins + z_wins * (2 - y_wins)


cdef void split_axes(const float *lo, const float *hi, const float *root_extent,
                     float threshold, int max_axes, uint8_t *axes, float *mid) noexcept nogil:
    """Choose the axes a bucket's origin grid splits (bit mask) and where."""
    cdef int a, b, rank
    cdef float ext[3]
    cdef bint wide[3]
    axes[0] = 0
    for a in range(3):
        ext[a] = hi[a] - lo[a]
        wide[a] = ext[a] > threshold * root_extent[a]
        mid[a] = 0.5 * lo[a] + 0.5 * hi[a]
    for a in range(3):
        if not wide[a]:
            continue
        # rank among the wide axes by relative extent (ties: lower axis first)
        rank = 0
        for b in range(3):
            if b != a and wide[b] and (ext[b] * root_extent[a] > ext[a] * root_extent[b]
                                       or (ext[b] * root_extent[a] == ext[a] * root_extent[b]
                                           and b < a)):
                rank += 1
        if rank < max_axes:
            axes[0] |= 1 << a


cdef inline int grid_cell(const float[:, ::1] rays, int i, uint8_t axes,
                          const float *mid) noexcept nogil:
    """One bit per split axis (in axis order): the origin is at or above the middle."""
    cdef int a, split, cell = 0, bit = 0
    for a in range(3):
        split = axes >> a & 1
        cell |= ((rays[RS_RAY_OX + a, i] >= mid[a]) & split) << bit
        bit += split
    return cell


cdef int sort_packet(const float[:, ::1] rays, int start, int end, const float *root_extent,
                     float threshold, int max_axes, int packet_size, int32_t *order,
                     int32_t *offsets,
                     uint8_t *key, uint8_t *bucket_out, uint8_t *cell_out) noexcept nogil:
    """Sort rays [start, end) into order[start:end]; returns the number of sub-packets
    written to offsets (their start positions)."""
    cdef float lo[BUCKETS][3]
    cdef float hi[BUCKETS][3]
    cdef float mid[BUCKETS][3]
    cdef uint8_t axes[BUCKETS]
    cdef int count[KEYS]
    cdef int i, a, b, k, pos, piece, n_sub = 0, most = 0
    for b in range(BUCKETS):
        for a in range(3):
            lo[b][a] = INFINITY
            hi[b][a] = -INFINITY
    for k in range(KEYS):
        count[k] = 0
    # pass 1: direction buckets (indices only) and per-bucket origin bounds
    for i in range(start, end):
        b = direction_bucket(rays[RS_RAY_DX, i], rays[RS_RAY_DY, i], rays[RS_RAY_DZ, i])
        key[i - start] = <uint8_t> b
        for a in range(3):
            lo[b][a] = rs_minf(rays[RS_RAY_OX + a, i], lo[b][a])
            hi[b][a] = rs_maxf(rays[RS_RAY_OX + a, i], hi[b][a])
    for b in range(BUCKETS):
        split_axes(lo[b], hi[b], root_extent, threshold, max_axes, &axes[b], mid[b])
    # pass 2: origin-grid cell; then a counting sort on (bucket, cell)
    for i in range(start, end):
        b = key[i - start]
        k = grid_cell(rays, i, axes[b], mid[b])
        if bucket_out != NULL:
            bucket_out[i] = <uint8_t> b
            cell_out[i] = <uint8_t> k
        key[i - start] = <uint8_t> (b * 8 + k)
    count_keys(key, end - start, count)
    pos = start
    for k in range(KEYS):
        piece = 0
        while piece < count[k]:
            offsets[n_sub] = pos + piece
            n_sub += 1
            piece += packet_size
        a = count[k]
        count[k] = pos
        pos += a
        most = max(most, a)
    # coherent rays: one key holds most of them (see rs_nah_place)
    if 2 * most > end - start:
        place_coherent(key, start, end, count, KEYS, order)
    else:
        place(key, start, end, count, order)
    return n_sub


def _sort(const float[:, ::1] rays, const int32_t[::1] packets, const float[::1] root_extent,
          float threshold, int max_axes, int packet_size, int32_t[::1] order,
          int32_t[::1] offsets,
          uint8_t[::1] bucket_out=None, uint8_t[::1] cell_out=None):
    """Sort every large packet; returns the number of sub-packets (offsets gets them + end).
    ValueError unless ``packets`` ascend from 0 (checked in the pass that finds the widest)
    to an n that ``rays``, ``order``, ``offsets`` (n + 1), ``bucket_out`` and ``cell_out``
    hold, ``root_extent`` has 3 values and ``packet_size`` >= 1."""
    cdef int p, n_sub = 0, widest = 0, descending = 0
    cdef Py_ssize_t n
    if packets.shape[0] < 1 or root_extent.shape[0] < 3 or packet_size < 1 \
            or rays.shape[0] != RS_RAY_ROWS:
        raise ValueError("_sort: rays (RS_RAY_ROWS, capacity), packets of 1 boundary or more, "
                         "root_extent of 3 values and packet_size >= 1 expected")
    n = packets[packets.shape[0] - 1]
    if (packets[0] != 0 or n > rays.shape[1] or n > order.shape[0] or n >= offsets.shape[0]
            or (bucket_out is not None and bucket_out.shape[0] < n)
            or (cell_out is not None and cell_out.shape[0] < n)):
        raise ValueError(f"_sort: packets must run from 0 to n = {n}, and rays, order, "
                         f"offsets (n + 1), bucket_out and cell_out hold them")
    for p in range(packets.shape[0] - 1):
        widest = max(widest, packets[p + 1] - packets[p])
        descending |= packets[p + 1] < packets[p]
    if descending:
        raise ValueError("_sort: packets must not descend")
    cdef uint8_t *bucket_ptr = &bucket_out[0] if bucket_out is not None else NULL
    cdef uint8_t *cell_ptr = &cell_out[0] if cell_out is not None else NULL
    key = np.empty(max(widest, 1), dtype=np.uint8)
    cdef uint8_t[::1] key_mv = key
    with nogil:
        for p in range(packets.shape[0] - 1):
            n_sub += sort_packet(rays, packets[p], packets[p + 1], &root_extent[0], threshold,
                                 max_axes, packet_size, &order[0], &offsets[n_sub], &key_mv[0],
                                 bucket_ptr, cell_ptr)
        offsets[n_sub] = packets[packets.shape[0] - 1]
    return n_sub


class NahSorter(Sorter):
    """Direction buckets and origin grids (Nah et al.), in Cython.

    Sorts every large packet (by default one 32x32 tile pass, 1024 rays) into
    coherent sub-packets: 24 direction buckets (octant x major axis), then per
    bucket an origin grid of 1-8 cells, each cell cut into sub-packets of at
    most ``packet_size`` rays.  Linear time; only indices move.

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    threshold    float   0.25     split a bucket's origin grid on an axis
                                  when its origin extent exceeds this
                                  fraction of the scene box's extent
    max_cells    int     8        most cells per bucket grid: 1, 2, 4 or 8
                                  (the widest axes are split first)
    packet_size  int     64       most rays per sub-packet (Manta's
                                  RayPacket::MaxSize); 4096 = whole cells
    large_packet int     None     sort within runs of at most this many rays
                                  of each large packet (None: the whole
                                  large packet, i.e. the pipeline's tile)
    ===========  ======  =======  ==========================================
    """

    trusted = True

    def __init__(self, *, threshold=0.25, max_cells=8, packet_size=64, large_packet=None):
        self.threshold, self.max_cells, self.packet_size, self.large_packet = \
            threshold, max_cells, packet_size, large_packet
        self.threshold, self.max_cells, self.packet_size, self.large_packet = self._params()

    def _params(self):
        """The parameters, checked (again at every sort: the kernel's bounds rest on
        them, and a script may have set an attribute since)."""
        max_cells = self.max_cells
        if isinstance(max_cells, bool) or max_cells not in (1, 2, 4, 8):
            raise ConfigError(f"max_cells must be 1, 2, 4 or 8, got {max_cells!r}")
        return (number("threshold", self.threshold, 0), int(max_cells),
                integer("packet_size", self.packet_size, 1, MAX_PACKET),
                None if self.large_packet is None else
                integer("large_packet", self.large_packet, 1, MAX_PACKET))

    def _packets(self, packets, n, params=None):
        """The large packets of ``n`` rays, checked, cut to ``large_packet`` (of
        ``params``, the checked parameters, when the caller has them)."""
        packets = check_packets(packets, n)
        large_packet = (params or self._params())[3]
        return packets if large_packet is None else fixed_packets(packets, large_packet)

    def _run(self, rays, packets, bounds, bucket=None, cell=None):
        params = threshold, max_cells, packet_size, _ = self._params()
        packets = self._packets(packets, len(rays), params)
        bounds = np.asarray(bounds, dtype=np.float32)
        extent = np.ascontiguousarray(bounds[1] - bounds[0], dtype=np.float32)
        n = len(rays)
        order = np.empty(max(n, 1), dtype=np.int32)
        offsets = np.empty(n + 1, dtype=np.int32)
        n_sub = isa.module("sorters.nah")._sort(
            rays.data, packets, extent, threshold, max_cells.bit_length() - 1, packet_size,
            order, offsets, bucket, cell)
        return order[:n], offsets[:n_sub + 1].copy()

    def sort(self, rays, packets, bounds):
        return self._run(rays, packets, bounds)

    def classify(self, rays, packets, bounds):
        """``(bucket, cell)`` of every ray (uint8 arrays), as the sort uses them."""
        bucket = np.zeros(max(len(rays), 1), dtype=np.uint8)
        cell = np.zeros(max(len(rays), 1), dtype=np.uint8)
        self._run(rays, packets, bounds, bucket, cell)
        return bucket[:len(rays)], cell[:len(rays)]
