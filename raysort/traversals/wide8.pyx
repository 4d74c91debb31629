"""``wide8``: one ray at a time through the BVH collapsed to 8-wide nodes with SIMD leaves.

Each node holds eight child boxes in structure-of-arrays form and one 8-lane
slab test (AVX2/AVX-512: one instruction per step; SSE2 and scalar builds:
two 4-lane halves) checks a ray against all eight.  The children it hits are
visited nearest first; the others wait on the stack with their entry distance
and are dropped if a closer hit has been found by the time they come up.
Leaves hold their triangles in SoA groups of eight with Moller-Trumbore's
inputs (v0, e1, e2) precomputed, tested eight at a time.  Every lane performs
``rs_box1``'s or ``rs_tri1``'s arithmetic and the group keeps the lowest
(t, id), so the hits equal brute force bit for bit (see wide8.h).
"""
from raysort._types cimport rs_node8, rs_tri8, rs_rays, rs_counters
from raysort.sdk.driver cimport Kernel, Geometry, Scratch, Waiting, run
from raysort.traversals._wide_ray cimport trace_wide_rays

from raysort import isa
from raysort.plugin import Traversal


cdef void trace_wide8(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                      Scratch *w, rs_counters *counters) noexcept nogil:
    trace_wide_rays(<const rs_node8 *> g.tree, <const rs_tri8 *> g.leaves, r, start, count,
                    any_hit, <Waiting *> w.stack, counters)     # BVH.wide8's nodes, groups


# up to seven waiting children per level (the 8-wide tree is no deeper than the binary one)
cdef Kernel WIDE8 = Kernel(trace_wide8, 7 * sizeof(Waiting), 0, 0)


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    tree = bvh.wide8
    return run(&WIDE8, bvh, packets, any_hit, tree.nodes, tree.groups)


class Wide8Traversal(Traversal):
    """One ray at a time through an 8-wide BVH with SIMD triangle leaves.

    Beyond the paper: eight child boxes per node tested in one 8-lane SIMD
    test, nearest child first, and leaves of up to eight triangles tested
    eight at a time (``BVH.wide8``: the binary BVH collapsed by a SAH-optimal
    dynamic program).  Counts SIMD N_B (one 8-wide test of eight child boxes
    per node visited) and SIMD N_T (one 8-wide test of a leaf group).  Exact
    on every ISA; AVX2 and AVX-512 run each step as one 256-bit instruction,
    SSE2 and the scalar build as two 4-lane halves.

    It takes no parameters; the collapse is tuned by the BVH:

    ========================== ======= ==========================================
    ``BVH`` attribute          default meaning
    ========================== ======= ==========================================
    ``WIDE8_GROUP_COST``       0.4     SAH cost of one 8-triangle group test
                                       relative to one 8-box node test
    ``WIDE8_MAX_LEAF``         32      most triangles of a leaf merged from
                                       several binary leaves
    ========================== ======= ==========================================
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.wide8").trace(bvh, packets, any_hit)
