"""``stream``: dynamic ray stream traversal (Barringer and Akenine-Moller, SIGGRAPH 2014).

Beyond the paper: instead of one ray (``wide8``, ``wide``) or one packet
(``ranged``) at a time, a large stream of ray ids descends the 8-wide BVH
(``BVH.wide8``; ``tree=4``: the 4-wide ``BVH.wide``) together.  At each node
the stream is split into one sub-stream per child, the rays whose slab test
hits that child, with SIMD tests over rays (16, 8 or 4 lanes on AVX-512, AVX2
and SSE2; one on the scalar build); the sub-streams wait on a task stack, and
leaves test their stream against each of their triangles, again SIMD over
rays.  Small streams finish one ray at a time with the single-ray kernels of
the same tree (``wide8``'s or ``wide``'s).  A stream first copies its rays
into 64-byte records (origin, tmin, 1 / d, t; direction and hit), which its
SIMD tests load with one row load per ray and a transpose; the hits go back
to the rays when the stream is done.  A node's box data is loaded once
for the whole stream, and the lanes are always full whatever the rays'
directions, which is what the paper gains on incoherent rays.  The kernel is
``raysort/include/raysort/stream.h``.

In a render (and ``Pipeline.trace``) the pipeline skips its gather and scatter for
``stream``: ``_intersect_batch`` (:func:`trace_batch`, ``stream_batch.h``) reads the
batch's rows in the sorter's order straight into the records and writes each hit in
batch order, with the same streams, counters and hits as ``intersect`` on packets.

The stream is the whole traversal call, not one sub-packet: every active ray
of every sub-packet passed to ``intersect`` (the pipeline passes a whole
batch, ``batch_rays`` rays, per thread), in the sorter's order, cut into
streams of ``stream_size`` rays.  Sub-packet boundaries do not matter; a
sorter helps through the order (neighbouring rays share nodes and leaves,
so streams stay large deeper in the tree).
"""
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t
from libc.stdlib cimport malloc, free
from raysort._checks cimport offsets_bad
from raysort._types cimport (rs_node8, rs_tri8, rs_rays, rs_counters, rays_view,
                             RS_MAX_PACKET, RS_RAY_ROWS)
from raysort.sdk.driver cimport check_packet_layout

import numpy as np

from raysort import isa
from raysort.bvh import check_tree
from raysort.sdk import ConfigError, Counters, Traversal, boolean, choice, integer


cdef extern from "raysort/stream.h" nogil:
    enum: RS_SW
    enum: RS_ORDER_DIRECTION, RS_ORDER_VOTES
    ctypedef struct rs_stream_scratch:
        int32_t *ids
        int64_t *level_rays
        int depth
    int rs_stream_alloc(rs_stream_scratch *w, int size, int width, int depth)
    void rs_stream_free(rs_stream_scratch *w)
    void rs_stream_trace(int width, const void *tree, const void *leaves, rs_rays *r, int n,
                         int any_hit, int order, int min_stream, rs_stream_scratch *w,
                         rs_counters *c)

cdef extern from "raysort/stream_batch.h" nogil:
    ctypedef struct rs_batch_hits:
        float *t
        int32_t *prim
        float *u
        float *v
        uint8_t *occluded
    ctypedef struct rs_batch_status:
        int64_t active
        int64_t bad_ray
        int64_t bad_hit
        int order_bad
    rs_batch_status rs_stream_batch(int width, const void *tree, const void *leaves,
                                    const float *const *src, int64_t n_src, const int32_t *order,
                                    const int32_t *offsets, int k0, int k1, int any_hit,
                                    int order_kind, int min_stream, int frustum,
                                    uint32_t n_prim, rs_stream_scratch *w, rs_frustum_entry *stack,
                                    rs_batch_hits *out, rs_counters *c)


cdef extern from "raysort/frustum.h" nogil:
    enum: RS_FRUSTUM_CHUNK
    ctypedef struct rs_frustum_entry:
        pass
    ctypedef struct rs_frustum_bounds:
        pass
    int rs_frustum_bounds_of(const rs_rays *r, int s, int e, rs_frustum_bounds *b)
    int rs_frustum_coherent(const rs_frustum_bounds *b)
    void rs_frustum_walk(const rs_node8 *nodes, const rs_tri8 *groups, rs_rays *r, int s, int e,
                         int any_hit, rs_frustum_bounds *b, rs_frustum_entry *stack,
                         rs_counters *c)


#: the child orders ``order`` accepts, by name
ORDERS = {"direction": RS_ORDER_DIRECTION, "votes": RS_ORDER_VOTES}
#: the trees ``tree`` accepts: children per node
TREES = (4, 8)
#: most rays per stream (ids are int32 offsets into buffers of depth * size ids)
MAX_STREAM = 1 << 20


def lanes():
    """Rays per SIMD test in this ISA build of the kernel."""
    return RS_SW


def _tree(bvh, int width):
    """``(nodes, leaves, depth)`` of the 8-wide or the 4-wide tree of ``bvh``; the
    kernels take no other width (checked at every call: a script may have set the
    plugin's ``tree`` since it was made)."""
    check_tree(bvh)
    if width == 8:
        tree8 = bvh.wide8
        return tree8.nodes, tree8.groups, tree8.depth
    if width == 4:
        return bvh.wide, bvh.triangles, bvh.wide_depth
    raise ConfigError(f"tree must be 4 or 8; got {width!r}")


cdef int check_stream(str name, int stream_size, int order) except -1:
    """ValueError naming ``name`` unless ``stream_size`` is 1..MAX_STREAM (a stream's
    scratch holds that many rays) and ``order`` one of ``ORDERS``."""
    if not 1 <= stream_size <= MAX_STREAM or order not in (RS_ORDER_DIRECTION, RS_ORDER_VOTES):
        raise ValueError(f"{name}: stream_size 1..{MAX_STREAM} and an order of ORDERS "
                         f"expected, got {stream_size} and {order}")
    return 0


cdef _counters(const rs_counters *c, const rs_stream_scratch *w, long long active):
    """The Counters of a call: ``c``, and the stream sizes per level in ``w``."""
    cdef int levels = w.depth + 1
    while levels > 0 and w.level_rays[levels - 1] == 0:
        levels -= 1
    return Counters(rays=active, ia=c.ia, box1=c.box1, box4=c.box4, tri1=c.tri1, tri4=c.tri4,
                    stream_tasks=c.stream_tasks, stream_rays=c.stream_rays,
                    stream_level_rays=tuple([w.level_rays[k] for k in range(levels)]))


cdef int packet_chunk(const int32_t[::1] starts, const int32_t[::1] counts, int *k,
                      int *s) noexcept nogil:
    """The next chunk of the packets, as ``stream_batch.h``'s ``rs_batch_chunk`` cuts it
    from the batch: the rest of packet ``k`` from lane ``s``, ``RS_FRUSTUM_CHUNK`` lanes
    at most, then each following packet whole while it fits in the chunk's lanes and
    starts where the packet before it ends, rounded up to 4 lanes (``_gather.layout``).
    Returns the lane after the chunk's last ray and moves ``k`` and ``s`` past it."""
    cdef int n_packets = starts.shape[0], first = s[0], lanes = 0, e = s[0], rest, count
    while k[0] < n_packets:
        rest = starts[k[0]] + counts[k[0]] - s[0]
        count = max(min(rest, RS_FRUSTUM_CHUNK - lanes), 0)
        if lanes > 0 and (count < rest or starts[k[0]] != first + lanes):
            break                   # a packet joins a chunk only whole and in its place
        if count > 0:
            e = first + lanes + count
        lanes += (count + 3) & ~3
        s[0] += count
        if count < rest:
            break                   # a full chunk inside a long packet
        k[0] += 1
        if k[0] < n_packets:
            s[0] = starts[k[0]]
        if lanes >= RS_FRUSTUM_CHUNK:
            break
    return e


def trace(bvh, packets, bint any_hit, int stream_size, int order, int min_stream, int width,
          bint frustum=False):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa);
    with ``frustum`` (8-wide tree only) coherent chunks (:func:`packet_chunk`) take the
    ``frustum`` traversal's walk and only the others join the streams."""
    check_stream("trace", stream_size, order)
    check_packet_layout(packets)
    cdef const int32_t[::1] starts = packets.starts, counts = packets.counts
    cdef int n_packets = starts.shape[0]
    cdef int k, i, m, size, s, e, first
    cdef rs_frustum_bounds bounds
    cdef rs_frustum_entry *chunk_stack = NULL
    cdef long long active = 0
    if n_packets == 0 or len(bvh.triangles) == 0:
        return Counters()
    node_array, leaf_array, depth = _tree(bvh, width)
    cdef const uint8_t[::1] node_bytes = node_array.view("u1").reshape(-1)
    cdef const uint8_t[::1] leaf_bytes = leaf_array.view("u1").reshape(-1)
    cdef const void *tree = <const void *> &node_bytes[0]
    cdef const void *leaves = <const void *> &leaf_bytes[0]
    cdef rs_rays rays = rays_view(packets.rows, packets.prim, packets.u, packets.v)
    cdef rs_counters c
    cdef rs_stream_scratch w
    c.rays = c.ia = c.box1 = c.box4 = c.tri1 = c.tri4 = c.stream_tasks = c.stream_rays = 0

    with nogil:
        for k in range(n_packets):
            for i in range(starts[k], starts[k] + counts[k]):
                if rays.tmin[i] < rays.t[i]:
                    active += 1
    if active == 0:
        return Counters()
    size = <int> min(stream_size, active)
    frustum = frustum and width == 8
    if not rs_stream_alloc(&w, size, width, depth):
        raise MemoryError()
    try:
        if frustum:     # 7 waiting boxes per level, as rs_stream_slots
            chunk_stack = <rs_frustum_entry *> malloc((7 * depth + 8) * sizeof(rs_frustum_entry))
            if chunk_stack == NULL:
                raise MemoryError()
        with nogil:
            m = 0
            k = 0
            s = starts[0]
            while k < n_packets:
                first = s
                e = packet_chunk(starts, counts, &k, &s)
                if frustum and first % 4 == 0 \
                        and rs_frustum_bounds_of(&rays, first, e, &bounds) \
                        and rs_frustum_coherent(&bounds):
                    rs_frustum_walk(<const rs_node8 *> tree, <const rs_tri8 *> leaves,
                                    &rays, first, e, any_hit, &bounds, chunk_stack, &c)
                    continue
                for i in range(first, e):
                    if rays.tmin[i] < rays.t[i]:
                        w.ids[m] = i
                        m += 1
                        if m == size:
                            rs_stream_trace(width, tree, leaves, &rays, m, any_hit, order,
                                            min_stream, &w, &c)
                            m = 0
            if m:
                rs_stream_trace(width, tree, leaves, &rays, m, any_hit, order, min_stream, &w, &c)
        counters = _counters(&c, &w, active)
    finally:
        rs_stream_free(&w)
        free(chunk_stack)
    return counters


def trace_batch(bvh, const float[:, ::1] src, const int32_t[::1] order,
                const int32_t[::1] offsets, int k0, int k1, bint any_hit, out, int stream_size,
                int order_kind, int min_stream, int width, bint frustum=False):
    """Sub-packets ``k0 <= k < k1`` of a sorter's result (``order``, ``offsets``: the
    offsets and the range of the order are checked here, that the order is a permutation
    keeping to the large packets by the caller) straight from the batch's ray rows
    ``src`` (``RayBatch.data``), without packets: their hits to ``out``,
    a float32 (4, n) block (rows t, prim as int32 bits, u, v) or, with ``any_hit``,
    a uint8 (n,) array (1: occluded).  The rays get the gather's rules (a ray that
    breaks the ray contract is traced as a miss) and the streams, chunks, counters and
    hits of :func:`trace` over the gathered packets (stream_batch.h).

    Returns ``(Counters, bad_ray, bad_hit, order_ok)``: ``bad_ray`` as the gather's (a
    ray that breaks the ray contract, or -1); ``bad_hit`` a ray whose hit breaks the hit
    contract (the rules of :func:`raysort.contract.check_hits`), or -1; ``order_ok``
    False when ``offsets`` do not run from 0 to n in sub-packets of 1..RS_MAX_PACKET
    rays or at an order entry outside ``[0, n)`` (nothing more is traced)."""
    cdef Py_ssize_t n = order.shape[0]
    cdef float[:, ::1] block
    cdef uint8_t[::1] flags
    cdef int32_t[::1] prim
    cdef rs_batch_hits hits
    cdef rs_batch_status status
    cdef const float *rows[RS_RAY_ROWS]
    cdef rs_counters c
    cdef rs_stream_scratch w
    cdef rs_frustum_entry *stack = NULL
    cdef int a, size
    cdef uint32_t n_prim
    check_stream("trace_batch", stream_size, order_kind)
    check_tree(bvh)
    n_prim = len(bvh.faces)
    if src.shape[0] != RS_RAY_ROWS or src.shape[1] < n or n == 0:
        raise ValueError("trace_batch: src must hold the ray rows of the n >= 1 rays of order")
    if not (0 <= k0 <= k1 < offsets.shape[0]):
        raise ValueError(f"trace_batch: sub-packets {k0}..{k1} of {offsets.shape[0] - 1}")
    if any_hit:
        flags = out
        if flags.shape[0] != n:
            raise ValueError("trace_batch: one flag per ray")
        hits.occluded = &flags[0]
        hits.t = hits.u = hits.v = NULL
        hits.prim = NULL
    else:
        block = out
        if block.shape[0] != 4 or block.shape[1] != n:
            raise ValueError("trace_batch: out must be a (4, n) block")
        prim = out[1].view(np.int32)
        hits.occluded = NULL
        hits.t, hits.prim, hits.u, hits.v = &block[0, 0], &prim[0], &block[2, 0], &block[3, 0]
    if len(bvh.triangles) == 0:
        raise ValueError("trace_batch: the scene has no triangles (trace its packets instead)")
    for a in range(RS_RAY_ROWS):
        rows[a] = &src[a, 0]
    node_array, leaf_array, depth = _tree(bvh, width)
    cdef const uint8_t[::1] node_bytes = node_array.view("u1").reshape(-1)
    cdef const uint8_t[::1] leaf_bytes = leaf_array.view("u1").reshape(-1)
    c.rays = c.ia = c.box1 = c.box4 = c.tri1 = c.tri4 = c.stream_tasks = c.stream_rays = 0
    if offsets_bad(&offsets[0], offsets.shape[0] - 1, <int32_t> n, RS_MAX_PACKET):
        return Counters(), -1, -1, False    # never read beyond the order, whoever sorted
    size = <int> min(stream_size, offsets[k1] - offsets[k0])
    if size < 1:
        return Counters(), -1, -1, True
    frustum = frustum and width == 8
    if not rs_stream_alloc(&w, size, width, depth):
        raise MemoryError()
    try:
        stack = <rs_frustum_entry *> malloc((7 * depth + 8) * sizeof(rs_frustum_entry))
        if stack == NULL:
            raise MemoryError()
        with nogil:
            status = rs_stream_batch(width, <const void *> &node_bytes[0],
                                     <const void *> &leaf_bytes[0], rows, n, &order[0],
                                     &offsets[0], k0, k1, any_hit, order_kind, min_stream,
                                     frustum, n_prim, &w, stack, &hits, &c)
        counters = _counters(&c, &w, status.active)
    finally:
        rs_stream_free(&w)
        free(stack)
    return counters, status.bad_ray, status.bad_hit, not status.order_bad


class StreamTraversal(Traversal):
    """A stream of rays through the wide BVH together (Barringer & Akenine-Moller 2014).

    Every active ray of the call, in the sorter's order, is cut into streams
    of ``stream_size`` rays; each stream descends ``BVH.wide8`` (or
    ``BVH.wide``) as a task stack of (node, sub-stream) pairs, filtered at
    each node by SIMD slab tests over rays (16/8/4/1 lanes on
    AVX-512/AVX2/SSE2/scalar) and tested at leaves SIMD over rays, one
    triangle at a time.  Children are visited in an order chosen per stream;
    streams smaller than ``min_stream`` finish one ray at a time as ``wide8``
    (``wide``) does.  Exact: each lane performs the scalar kernels' operations.

    Counters (the same on every ISA): SIMD N_B is one per ray and node it
    visits (the node's eight or four child boxes, as ``wide8`` / ``wide``);
    SIMD N_T at a leaf of the 8-wide tree one per ray and group of up to
    eight triangles (as ``wide8``), of the 4-wide tree one per triangle and 4
    rays (rounded up); the single-ray finish counts as ``wide8`` / ``wide``.
    ``stream_tasks`` / ``stream_rays`` give the mean stream size;
    ``stream_level_rays[d]`` counts the rays of the streams popped at depth
    ``d`` of the tree (0: the root; a leaf is one level below its node).
    With ``frustum``, coherent chunks count as in ``frustum`` (N_IA per node,
    SIMD N_B per group of rays at a leaf's box, SIMD N_T per ray and group).

    ===========  ======  ==========  ========================================
    parameter    type    default     meaning
    ===========  ======  ==========  ========================================
    stream_size  int     16384       most rays per stream (capped by the
                                     rays of the call, i.e. the batch)
    order        str     "votes"     child order per stream: ``votes`` (the
                                     child most of its rays enter first,
                                     first) or ``direction`` (nearest box
                                     corner along the stream's majority
                                     octant first)
    min_stream   int     8           streams of fewer rays finish one ray
                                     at a time from their node (0: never)
    tree         int     8           8: the 8-wide BVH (``BVH.wide8``,
                                     leaves of rs_tri8 groups); 4: the
                                     4-wide one (``BVH.wide``), slower with
                                     every SIMD ISA on every scene measured
                                     (BENCHMARKS.md §7)
    frustum      bool    True        coherent chunks of up to 64 rays
                                     (a long sub-packet cut, short ones
                                     together; camera rays, shadow rays to
                                     one light) take the ``frustum``
                                     traversal's walk, only the others
                                     form streams (8-wide tree only)
    ===========  ======  ==========  ========================================
    """

    trusted = True

    def __init__(self, *, stream_size=16384, order="votes", min_stream=8, tree=8, frustum=True):
        self.stream_size = integer("stream_size", stream_size, 1, MAX_STREAM)
        self.order = choice("order", order, ORDERS)
        self.min_stream = integer("min_stream", min_stream, 0, MAX_STREAM)
        self.tree = integer("tree", tree, min(TREES), max(TREES))
        if self.tree not in TREES:
            raise ConfigError(f"tree must be 4 or 8; got {tree!r}")
        self.frustum = boolean("frustum", frustum)

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.stream").trace(bvh, packets, any_hit, self.stream_size,
                                                     ORDERS[self.order], self.min_stream,
                                                     self.tree, self.frustum)

    def _intersect_batch(self, bvh, rays, order, offsets, k0, k1, any_hit, out):
        """The pipeline's path without packets (raysort.pipeline, ``_reads_batch``):
        sub-packets ``k0..k1`` of the sorter's result straight from the batch's rows
        ``rays`` into the batch-order hits ``out`` (:func:`trace_batch`)."""
        return isa.module("traversals.stream").trace_batch(
            bvh, rays, order, offsets, k0, k1, any_hit, out, self.stream_size,
            ORDERS[self.order], self.min_stream, self.tree, self.frustum)
