"""The driver every traversal kernel runs under (see driver.pxd).

:func:`run` turns a :class:`raysort.bvh.BVH` and :class:`raysort.rays.Packets`
into C views, allocates the scratch memory the kernel declares once per call,
releases the GIL and calls the kernel for each sub-packet, summing the Table I
counters into a :class:`raysort.stats.Counters`.
"""
from libc.stdlib cimport malloc, free
from libc.string cimport memset
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport rs_node, rs_tri, rs_rays, rs_counters, RS_MAX_PACKET, rays_view

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


cdef object run(const Kernel *kernel, object bvh, object packets, bint any_hit,
                object tree=None, object leaves=None):
    """Trace ``packets`` through ``bvh`` with ``kernel``; returns the Counters.

    ``tree`` and ``leaves`` (C-contiguous arrays the caller keeps alive, e.g.
    ``bvh.wide``) are handed to the kernel as ``Geometry.tree`` and ``.leaves``.
    """
    cdef const int32_t[::1] starts = packets.starts, counts = packets.counts
    cdef const uint8_t[::1] node_bytes = bvh.nodes.view("u1").reshape(-1)
    cdef const uint8_t[::1] tri_bytes = bvh.triangles.view("u1").reshape(-1)
    cdef Geometry geo
    cdef rs_rays rays = rays_view(packets.rows, packets.prim, packets.u, packets.v)
    cdef Scratch w
    cdef rs_counters c
    cdef int k, i, widest = 0, n = starts.shape[0]
    cdef size_t stack_size, groups_size, level_groups_size
    cdef char *block

    for k in range(n):
        if counts[k] > widest:
            widest = counts[k]
        if starts[k] % 4:
            raise PluginContractError(f"sub-packet {k} starts at lane {starts[k]}, "
                                      "not a multiple of 4")
    if widest > RS_MAX_PACKET:
        raise PluginContractError(f"a sub-packet of {widest} rays is wider than the "
                                  f"{RS_MAX_PACKET} a traversal accepts")
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
