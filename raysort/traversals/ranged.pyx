"""``ranged``: DynBVH ranged packet traversal (Wald, Boulos, Shirley 2007).

Follows Manta's ``DynBVH::intersectNode`` (see manta-notes section 3.2): a
sub-packet descends as the range [first active ray, end); at each node the
first hitting ray is found by a speculative scalar test of the first active
ray, then an interval-arithmetic frustum cull, then a scalar head, 4-wide
aligned groups and a scalar tail; at a leaf the last hitting ray is found the
same way from the end and the triangles are tested on [first, last].
"""
from libc.stdint cimport int32_t
from raysort._types cimport (rs_node, rs_rays, rs_frustum, rs_counters, rs_box1, rs_box4,
                             rs_ia_miss, rs_active4)
from raysort.sdk.driver cimport (Kernel, Geometry, Scratch, run, stack_root, stack_pop,
                                 push_children, active, align_up, align_down,
                                 lowest_bit, highest_bit, left_first, frustum_of,
                                 leaf_range)

from raysort import isa
from raysort.plugin import Traversal


cdef inline int first_hit(const rs_rays *r, const rs_node *n, int first, int end,
                          const rs_frustum *f, rs_counters *c) noexcept nogil:
    """Index of the first ray of [first, end) that hits the node, or end."""
    cdef int i, m
    while first < end and not active(r, first):
        first += 1
    if first == end:
        return end
    cdef int b = align_up(first), e = align_down(end)
    if b >= e:                      # no whole aligned group: scalar, no IA test
        for i in range(first, end):
            if active(r, i):
                c.box1 += 1
                if rs_box1(r, i, n):
                    return i
        return end
    c.box1 += 1                     # speculative test of the first active ray
    if rs_box1(r, first, n):
        return first
    c.ia += 1                       # does the whole packet miss?
    if rs_ia_miss(f, n):
        return end
    for i in range(first + 1, b):   # scalar head
        if active(r, i):
            c.box1 += 1
            if rs_box1(r, i, n):
                return i
    for i in range(b, e, 4):        # aligned groups; the exact first lane
        if rs_active4(r, i):
            c.box4 += 1
            m = rs_box4(r, i, n)
            if m:
                return i + lowest_bit(m)
    for i in range(e, end):         # scalar tail
        if active(r, i):
            c.box1 += 1
            if rs_box1(r, i, n):
                return i
    return end


cdef inline int last_hit(const rs_rays *r, const rs_node *n, int first, int end,
                         rs_counters *c) noexcept nogil:
    """Index of the last ray of (first, end) that hits the node, or first."""
    cdef int i, m, lo = first + 1
    while end > lo and not active(r, end - 1):
        end -= 1
    if end <= lo:
        return first
    cdef int b = align_up(lo), e = align_down(end)
    if b >= e:
        for i in range(end - 1, lo - 1, -1):
            if active(r, i):
                c.box1 += 1
                if rs_box1(r, i, n):
                    return i
        return first
    for i in range(end - 1, e - 1, -1):     # scalar tail
        if active(r, i):
            c.box1 += 1
            if rs_box1(r, i, n):
                return i
    for i in range(e - 4, b - 1, -4):       # aligned groups, downward
        if rs_active4(r, i):
            c.box4 += 1
            m = rs_box4(r, i, n)
            if m:
                return i + highest_bit(m)
    for i in range(b - 1, lo - 1, -1):      # scalar head
        if active(r, i):
            c.box1 += 1
            if rs_box1(r, i, n):
                return i
    return first


cdef void trace_ranged(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                       Scratch *w, rs_counters *counters) noexcept nogil:
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef int end = start + count, sp = 0, node, first, last
    cdef int32_t *stack = <int32_t *> w.stack
    cdef const rs_node *n
    cdef rs_frustum f
    frustum_of(r, start, count, &f)
    sp = stack_root(stack, start)
    while sp > 0:
        n = stack_pop(g, stack, &sp, &node, &first)
        first = first_hit(r, n, first, end, &f, &c)
        if first == end:
            continue
        if n.count:
            last = last_hit(r, n, first, end, &c)
            leaf_range(g, n, r, first, last + 1, any_hit, &c)
            continue
        # both children get [first, end); the far one is visited second
        sp = push_children(g, node, left_first(n, r, first), stack, sp, first)
    counters[0] = c


cdef Kernel RANGED = Kernel(trace_ranged, 2 * sizeof(int32_t), 0, 0)   # (node, first) pairs


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    return run(&RANGED, bvh, packets, any_hit)


class RangedTraversal(Traversal):
    """DynBVH ranged packet traversal, Manta's default (Wald et al. 2007).

    Counts, at the places manta-notes section 3.7 names: N_IA once per node
    whose speculative first-ray test missed while the range held a whole
    aligned 4-group; scalar N_B for the speculative, head, tail and
    all-scalar tests; SIMD N_B per aligned group tested; scalar/SIMD N_T per
    triangle for head/tail rays and aligned groups of the leaf range.

    It takes no parameters.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.ranged").trace(bvh, packets, any_hit)
