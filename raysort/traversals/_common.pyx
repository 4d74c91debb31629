"""The driver every traversal kernel runs under.

:func:`run` turns a :class:`raysort.bvh.BVH` and :class:`raysort.rays.Packets`
into C views, allocates the scratch memory once per call, releases the GIL and
calls the kernel's ``packet_fn`` for each sub-packet, summing the Table I
counters into a :class:`raysort.stats.Counters`.
"""
from libc.stdlib cimport malloc, free
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport (rs_node, rs_node4, rs_node8, rs_tri, rs_tri8, rs_rays, rs_counters,
                             RS_MAX_PACKET, rays_view)

from raysort.errors import PluginContractError
from raysort.stats import Counters


cdef object run(packet_fn fn, object bvh, object packets, bint any_hit, bint wide=False,
                bint wide8=False):
    cdef const int32_t[::1] starts = packets.starts, counts = packets.counts
    cdef const uint8_t[::1] node_bytes = bvh.nodes.view("u1").reshape(-1)
    cdef const uint8_t[::1] tri_bytes = bvh.triangles.view("u1").reshape(-1)
    cdef const uint8_t[::1] node4_bytes = (bvh.wide if wide else bvh.nodes[:0]).view("u1").reshape(-1)
    none = bvh.nodes[:0]
    tree8 = bvh.wide8 if wide8 else None
    cdef const uint8_t[::1] node8_bytes = (tree8.nodes if wide8 else none).view("u1").reshape(-1)
    cdef const uint8_t[::1] group8_bytes = (tree8.groups if wide8 else none).view("u1").reshape(-1)
    cdef Geometry geo
    cdef rs_rays rays = rays_view(packets.rows, packets.prim, packets.u, packets.v)
    cdef Scratch w
    cdef rs_counters c
    cdef int k, i, widest = 0, n = starts.shape[0]

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
    geo.nodes4 = <const rs_node4 *> &node4_bytes[0] if node4_bytes.shape[0] else NULL
    geo.nodes8 = <const rs_node8 *> &node8_bytes[0] if node8_bytes.shape[0] else NULL
    geo.groups8 = <const rs_tri8 *> &group8_bytes[0] if group8_bytes.shape[0] else NULL

    w.stack_size = bvh.depth + 2
    w.groups = (widest + 3) // 4
    w.stack = <int32_t *> malloc(24 * w.stack_size * sizeof(int32_t))
    w.masks = <uint8_t *> malloc(w.stack_size * w.groups * sizeof(uint8_t) + 1)
    w.ids = <int32_t *> malloc(w.groups * sizeof(int32_t) + 4)
    if w.stack == NULL or w.masks == NULL or w.ids == NULL:
        free(w.stack); free(w.masks); free(w.ids)
        raise MemoryError()
    c.rays = c.ia = c.box1 = c.box4 = c.tri1 = c.tri4 = 0
    try:
        with nogil:
            for k in range(n):
                for i in range(starts[k], starts[k] + counts[k]):
                    if active(&rays, i):
                        c.rays += 1
                if counts[k] > 0:
                    fn(&geo, &rays, starts[k], counts[k], any_hit, &w, &c)
    finally:
        free(w.stack); free(w.masks); free(w.ids)
    return Counters(rays=c.rays, ia=c.ia, box1=c.box1, box4=c.box4, tri1=c.tri1, tri4=c.tri4)
