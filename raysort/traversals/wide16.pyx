"""``wide16``: one ray at a time through the BVH widened to 16-wide nodes.

The 8-wide tree of ``wide8`` with each node's largest inner children opened
into their own while sixteen slots hold them (``BVH.wide16``), so a ray visits
fewer, wider nodes; one 16-lane slab test (AVX-512: one instruction per step;
other ISAs: two 8-lane halves) checks a ray against all sixteen child boxes.
Leaves are ``wide8``'s SoA groups of eight triangles.  Every lane performs
``rs_box1``'s or ``rs_tri1``'s arithmetic, so the hits equal brute force bit
for bit (see wide16.h and wide8.h).
"""
from raysort._types cimport rs_node16, rs_tri8, rs_rays, rs_counters
from raysort.sdk.driver cimport Kernel, Geometry, Scratch, Waiting, run
from raysort.traversals._wide_ray cimport trace_wide_rays

from raysort import isa
from raysort.plugin import Traversal


cdef void trace_wide16(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                       Scratch *w, rs_counters *counters) noexcept nogil:
    trace_wide_rays(<const rs_node16 *> g.tree, <const rs_tri8 *> g.leaves, r, start, count,
                    any_hit, <Waiting *> w.stack, counters)     # BVH.wide16's nodes, groups


# up to fifteen waiting children per level (the tree is no deeper than the binary one)
cdef Kernel WIDE16 = Kernel(trace_wide16, 15 * sizeof(Waiting), 0, 0)


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    tree = bvh.wide16
    return run(&WIDE16, bvh, packets, any_hit, tree.nodes, tree.groups)


class Wide16Traversal(Traversal):
    """One ray at a time through a 16-wide BVH with SIMD triangle leaves.

    Beyond the paper, and an experiment on the width: ``wide8``'s tree with
    each node widened to sixteen children (its largest inner children opened
    first), sixteen child boxes tested in one 16-lane SIMD test, nearest
    child first, leaves of up to eight triangles tested eight at a time.
    Counts SIMD N_B (one 16-wide test per node visited) and SIMD N_T (one
    8-wide test of a leaf group).  Exact on every ISA.  It takes no
    parameters; the 8-wide tree it widens is tuned as for ``wide8``.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.wide16").trace(bvh, packets, any_hit)
