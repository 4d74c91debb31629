"""``wide``: one ray at a time through the BVH collapsed to 4-wide nodes.

Embree's design for incoherent rays, beyond the paper: each node holds four
child boxes in structure-of-arrays form, and one 4-wide slab test checks a ray
against all four.  The children it hits are visited nearest first; the others
wait on the stack with their entry distance and are dropped if a closer hit
has been found by the time they come up (``entry <= t * slack`` is exactly the
decision a new slab test would make).  Each lane of the 4-wide test performs
``rs_box1``'s arithmetic on one child box and triangles use ``rs_tri1``, so
the hits equal brute force bit for bit.
"""
from raysort._types cimport rs_node4, rs_rays, rs_counters, rs_node4_hit, rs_prefetch
from raysort.sdk.driver cimport (Kernel, Geometry, Scratch, Waiting, run, active, leaf_ray,
                                 insert_nearest_first, pop_nearest)

from raysort import isa
from raysort.plugin import Traversal


cdef void trace_wide(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                     Scratch *w, rs_counters *counters) noexcept nogil:
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef Waiting *stack = <Waiting *> w.stack     # ref >= 0: a 4-wide node; < 0: a leaf
    cdef Waiting hit[4]
    cdef Waiting child
    cdef float entry[4]
    cdef int i, k, m, mask, sp, ref, first
    cdef const rs_node4 *n
    cdef const rs_node4 *nodes4 = <const rs_node4 *> g.tree   # BVH.wide
    for i in range(start, start + count):
        if not active(r, i):
            continue
        sp = 0
        ref = 0
        while True:
            if ref >= 0:
                n = &nodes4[ref]
                c.box4 += 1
                mask = rs_node4_hit(r, i, n, entry)
                m = 0                              # the children hit, nearest first
                for k in range(4):
                    if mask >> k & 1 and n.child[k] != 0:     # child 0: an empty slot
                        child.ref, child.count, child.entry = n.child[k], n.count[k], entry[k]
                        insert_nearest_first(hit, m, child)
                        m += 1
                for k in range(m - 1, 0, -1):      # farther children wait, farthest deepest
                    stack[sp] = hit[k]
                    sp += 1
                if m:
                    ref = hit[0].ref
                    first = hit[0].count
                    if ref >= 0:
                        rs_prefetch(&nodes4[ref])
                    continue
            else:
                leaf_ray(g, r, i, -ref - 1, first, any_hit, &c)
                if not active(r, i):        # an any-hit query found its hit
                    break
            if not pop_nearest(stack, &sp, r.t[i], &child):
                break
            ref, first = child.ref, child.count
    counters[0] = c


# up to three waiting children per level of the 4-wide tree
cdef Kernel WIDE = Kernel(trace_wide, 3 * sizeof(Waiting), 0, 0)


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    return run(&WIDE, bvh, packets, any_hit, bvh.wide)


class WideTraversal(Traversal):
    """One ray at a time through a 4-wide BVH, four child boxes per SIMD test.

    Beyond the paper: the structure Embree uses for incoherent rays, built by
    collapsing raysort's binary BVH (``BVH.wide``).  Counts SIMD N_B (one
    4-wide test of four child boxes per node visited) and scalar N_T.  Sorting
    helps it only through memory locality.

    It takes no parameters.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.wide").trace(bvh, packets, any_hit)
