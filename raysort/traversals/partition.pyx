"""``partition``: partition traversal (Overbeck, Ramamoorthi, Mark 2008).

The sub-packet keeps an array of 4-ray group ids whose prefix [0, ie) is
active.  At a node the first active group is tested speculatively; if it
misses, an interval-arithmetic frustum test may cull the node for the whole
packet; otherwise every active group is tested and the groups that hit are
swapped to the front, giving the children's ie.  The stack keeps (node, ie),
so a sibling resumes with its parent's prefix.  Like RTfact's
``BVHPartitionIntersector`` it partitions 4-ray groups, not single rays, so
every test is a SIMD test.
"""
from libc.stdint cimport int32_t
from raysort._types cimport (rs_node, rs_rays, rs_frustum, rs_counters, rs_box4, rs_tri4,
                             rs_ia_miss, rs_active4)
from raysort.sdk.driver cimport (Kernel, Geometry, Scratch, run, stack_root, stack_pop,
                                 push_children, lowest_bit, left_first, frustum_of)

from raysort import isa
from raysort.plugin import Traversal


cdef void trace_partition(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                          Scratch *w, rs_counters *counters) noexcept nogil:
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef int groups = (count + 3) // 4, sp, node, ie, live, j, k, m, m0, tmp
    cdef int32_t *stack = <int32_t *> w.stack
    cdef int32_t *ids = <int32_t *> w.group_data
    cdef const rs_node *n
    cdef rs_frustum f
    frustum_of(r, start, count, &f)
    live = 0
    for j in range(groups):
        if rs_active4(r, start + 4 * j):
            ids[live] = start + 4 * j
            live += 1
    if live == 0:
        counters[0] = c
        return
    sp = stack_root(stack, live)
    while sp > 0:
        n = stack_pop(g, stack, &sp, &node, &ie)
        c.box4 += 1
        m0 = rs_box4(r, ids[0], n)
        if not m0:
            if ie == 1:
                continue
            c.ia += 1
            if rs_ia_miss(&f, n):
                continue
        live = 1 if m0 else 0
        for j in range(1, ie):
            c.box4 += 1
            if rs_box4(r, ids[j], n):
                tmp = ids[j]
                ids[j] = ids[live]
                ids[live] = tmp
                live += 1
        if live == 0:
            continue
        if n.count:
            for k in range(n.offset, n.offset + n.count):
                for j in range(live):
                    c.tri4 += 1
                    rs_tri4(r, ids[j], &g.tris[k], any_hit)
            continue
        m = rs_active4(r, ids[0])
        sp = push_children(g, node, left_first(n, r, ids[0] + (lowest_bit(m) if m else 0)),
                           stack, sp, live)
    counters[0] = c


# (node, live groups) pairs, and the ids of the 4-ray groups
cdef Kernel PARTITION = Kernel(trace_partition, 2 * sizeof(int32_t), sizeof(int32_t), 0)


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    return run(&PARTITION, bvh, packets, any_hit)


class PartitionTraversal(Traversal):
    """Partition traversal (Overbeck et al. 2008) over 4-ray groups, all SIMD.

    Counts one SIMD N_B per active group tested at a node (the speculative
    first group included), one N_IA when the first group misses and more than
    one group is active, and one SIMD N_T per triangle and active group at a
    leaf.  No scalar tests, as in the paper's Table I.

    It takes no parameters.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.partition").trace(bvh, packets, any_hit)
