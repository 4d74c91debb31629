"""One ray at a time through a wide tree whose leaves are rs_tri8 groups: the loop
the ``wide8`` and ``wide16`` kernels share (compiled into each, specialised for its
node type by a fused type).

Each node's child boxes are tested in one SIMD test (``rs_node8_hit`` or
``rs_node16_hit``), the children hit are visited nearest first, the others wait on
the stack with their entry distance and are dropped if a closer hit has been found
by the time they come up; a leaf's groups are tested eight triangles at a time
(``rs_tri8_hit``).  Counters: SIMD N_B (``box4``) one per node visited, SIMD N_T
(``tri4``) one per group tested.
"""
from raysort._types cimport (rs_node8, rs_node16, rs_tri8, rs_rays, rs_counters, rs_ray8,
                             rs_ray8_load, rs_node8_hit, rs_node16_hit, rs_tri8_hit,
                             rs_lowest_bit, rs_prefetch)
from raysort.sdk.driver cimport Waiting, active, insert_nearest_first, pop_nearest

ctypedef fused wide_node:
    rs_node8
    rs_node16


cdef inline void prefetch_lines(const void *at, int lines) noexcept nogil:
    """Ask for ``lines`` cache lines from ``at``."""
    cdef const char *p = <const char *> at
    cdef int k
    for k in range(lines):
        rs_prefetch(p + 64 * k)


cdef inline void trace_wide_rays(const wide_node *nodes, const rs_tri8 *groups8, rs_rays *r,
                                 int start, int count, int any_hit, Waiting *stack,
                                 rs_counters *counters) noexcept nogil:
    """Trace lanes ``[start, start + count)`` of ``r`` through ``nodes`` (root first);
    ``stack`` holds width - 1 waiting children per level of the tree."""
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef Waiting hit[16]
    cdef Waiting child
    cdef float entry[16]
    cdef rs_ray8 ray
    cdef int i, k, m, mask, sp, ref, groups
    cdef const wide_node *n
    cdef int node_lines = sizeof(wide_node) // 64
    for i in range(start, start + count):
        if not active(r, i):
            continue
        rs_ray8_load(r, i, &ray)
        sp = 0
        ref = 0
        groups = 0
        while True:
            if ref >= 0:
                n = &nodes[ref]
                c.box4 += 1
                if wide_node is rs_node8:
                    mask = rs_node8_hit(r, i, &ray, n, entry)
                else:
                    mask = rs_node16_hit(r, i, &ray, n, entry)
                m = 0                              # the children hit, nearest first
                while mask:
                    k = rs_lowest_bit(mask)
                    mask &= mask - 1
                    if n.child[k] == 0:            # an empty slot (types.h)
                        continue
                    child.ref, child.count, child.entry = n.child[k], n.count[k], entry[k]
                    insert_nearest_first(hit, m, child)
                    m += 1
                for k in range(m - 1, 0, -1):      # farther children wait, farthest deepest
                    stack[sp] = hit[k]
                    sp += 1
                    rs_prefetch(<const void *> &nodes[hit[k].ref] if hit[k].ref >= 0
                                else <const void *> &groups8[-hit[k].ref - 1])
                if m:
                    ref = hit[0].ref
                    groups = hit[0].count
                    if ref >= 0:
                        prefetch_lines(&nodes[ref], node_lines)
                    else:
                        prefetch_lines(&groups8[-ref - 1], 5)      # an rs_tri8: 320 bytes
                    continue
            else:
                for k in range(-ref - 1, -ref - 1 + groups):
                    c.tri4 += 1
                    rs_tri8_hit(r, i, &ray, &groups8[k], any_hit)
                if not active(r, i):        # an any-hit query found its hit
                    break
            if not pop_nearest(stack, &sp, r.t[i], &child):
                break
            ref, groups = child.ref, child.count
    counters[0] = c
