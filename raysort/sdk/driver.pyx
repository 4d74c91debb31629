"""The driver every traversal kernel runs under (see driver.pxd).

:func:`run` turns a :class:`raysort.bvh.BVH` and :class:`raysort.rays.Packets`
into C views, allocates the scratch memory the kernel declares once per call,
releases the GIL and calls the kernel for each sub-packet, summing the Table I
counters into a :class:`raysort.stats.Counters`.
"""
from libc.stdlib cimport malloc, free
from libc.string cimport memset
from libc.stdint cimport int32_t, uint8_t
from raysort._checks cimport unaligned16
from raysort._types cimport (rs_node, rs_tri, rs_rays, rs_counters, RS_MAX_PACKET,
                             RS_PACKET_ROWS, rays_view)

from raysort.bvh import check_tree
from raysort.errors import PluginContractError
from raysort.stats import Counters

cdef enum:
    SLACK = 64          # bytes after each scratch region, which also keeps them 16-aligned


cdef inline size_t region(size_t n) noexcept nogil:
    return (n + 2 * SLACK - 1) // SLACK * SLACK


cdef const void *array_start(object array, object name) except? NULL:
    """The first byte of a C-contiguous NumPy array (NULL when None or empty)."""
    if array is None:
        return NULL
    cdef const uint8_t[::1] raw
    if not getattr(getattr(array, "flags", None), "c_contiguous", False):
        raise PluginContractError(f"run(): {name} must be a C-contiguous NumPy array, got "
                                  f"{type(array).__name__}")
    raw = array.view("u1").reshape(-1)      # a view: the caller keeps the array alive
    return <const void *> &raw[0] if raw.shape[0] else NULL


cdef int check_packet_layout(object packets) except -1:
    """ValueError unless the arrays of ``packets`` fit together, so that a kernel stays
    inside them whoever built them (a script may hand a traversal packets of its own):
    ``rows`` (``RS_PACKET_ROWS``, capacity) float32; ``prim``, ``u``, ``v`` and
    ``index`` one value per lane, rows, prim, u and v 16-byte aligned with a multiple
    of 4 lanes; ``starts`` and ``counts`` one per sub-packet; each
    sub-packet 0..RS_MAX_PACKET rays from a lane that is a multiple of 4, its lanes
    rounded up to 4 inside the capacity.  Returns the widest sub-packet's rays."""
    cdef const float[:, ::1] rows = packets.rows
    cdef const int32_t[::1] prim = packets.prim, index = packets.index
    cdef const float[::1] u = packets.u, v = packets.v
    cdef const int32_t[::1] starts = packets.starts, counts = packets.counts
    cdef Py_ssize_t k, capacity = rows.shape[1]
    cdef int widest = 0
    if rows.shape[0] != RS_PACKET_ROWS:
        raise ValueError(f"packets.rows must have {RS_PACKET_ROWS} rows, got {rows.shape[0]}")
    if not (prim.shape[0] == u.shape[0] == v.shape[0] == index.shape[0] == capacity):
        raise ValueError(f"packets.prim, u, v and index must hold one value per lane "
                         f"({capacity}), got {prim.shape[0]}, {u.shape[0]}, {v.shape[0]} "
                         f"and {index.shape[0]}")
    if capacity % 4 or capacity and (unaligned16(&rows[0, 0]) or unaligned16(&prim[0])
                                     or unaligned16(&u[0]) or unaligned16(&v[0])):
        raise ValueError(f"packets.rows, prim, u and v must start 16-byte aligned (the SIMD "
                         f"kernels load them so), with a multiple of 4 lanes, got {capacity}")
    if counts.shape[0] != starts.shape[0]:
        raise ValueError(f"packets.starts and counts must be of one length, got "
                         f"{starts.shape[0]} and {counts.shape[0]}")
    for k in range(starts.shape[0]):
        if (starts[k] < 0 or starts[k] % 4 or not 0 <= counts[k] <= RS_MAX_PACKET
                or starts[k] + ((<Py_ssize_t> counts[k] + 3) & ~3) > capacity):
            raise ValueError(f"packets: sub-packet {k} of {counts[k]} rays from lane "
                             f"{starts[k]} is not 0..{RS_MAX_PACKET} rays from a multiple "
                             f"of 4 inside the {capacity} lanes")
        if counts[k] > widest:
            widest = counts[k]
    return widest


cdef object run(const Kernel *kernel, object bvh, object packets, bint any_hit,
                object tree=None, object leaves=None):
    """Trace ``packets`` through ``bvh`` with ``kernel``; returns the Counters.

    ``tree`` and ``leaves`` (C-contiguous arrays the caller keeps alive, e.g.
    ``bvh.wide``) are handed to the kernel as ``Geometry.tree`` and ``.leaves``.
    """
    check_tree(bvh)
    cdef int widest = check_packet_layout(packets)
    cdef const int32_t[::1] starts = packets.starts, counts = packets.counts
    cdef const uint8_t[::1] node_bytes = bvh.nodes.view("u1").reshape(-1)
    cdef const uint8_t[::1] tri_bytes = bvh.triangles.view("u1").reshape(-1)
    cdef Geometry geo
    cdef rs_rays rays = rays_view(packets.rows, packets.prim, packets.u, packets.v)
    cdef Scratch w
    cdef rs_counters c
    cdef int k, i, n = starts.shape[0]
    cdef size_t stack_size, groups_size, level_groups_size
    cdef char *block

    if n == 0 or node_bytes.shape[0] == 0:
        return Counters()

    geo.nodes = <const rs_node *> &node_bytes[0]
    geo.tris = <const rs_tri *> &tri_bytes[0] if tri_bytes.shape[0] else NULL
    geo.tree = array_start(tree, "tree")
    geo.leaves = array_start(leaves, "leaves")

    w.levels = bvh.depth + 2
    w.groups = (widest + 3) // 4
    stack_size = region(w.levels * kernel.stack_bytes)
    groups_size = region(w.groups * kernel.group_bytes)
    level_groups_size = region(<size_t> w.levels * w.groups * kernel.level_group_bytes)
    block = <char *> malloc(stack_size + groups_size + level_groups_size)
    if block == NULL:
        raise MemoryError()
    w.stack = block
    w.group_data = block + stack_size
    w.level_group_data = block + stack_size + groups_size
    memset(&c, 0, sizeof(c))       # every counter, including any a kernel adds
    try:
        with nogil:
            for k in range(n):
                for i in range(starts[k], starts[k] + counts[k]):
                    if active(&rays, i):
                        c.rays += 1
                if counts[k] > 0:
                    kernel.trace(&geo, &rays, starts[k], counts[k], any_hit, &w, &c)
    finally:
        free(block)
    return Counters(rays=c.rays, ia=c.ia, box1=c.box1, box4=c.box4, tri1=c.tri1, tri4=c.tri4)
