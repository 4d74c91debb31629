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
from libc.stdint cimport int32_t
from raysort._types cimport (rs_node8, rs_tri8, rs_rays, rs_counters, rs_ray8, rs_ray8_load,
                             rs_node8_hit, rs_tri8_hit, rs_lowest_bit, rs_prefetch)
from raysort.sdk.driver cimport (Kernel, Geometry, Scratch, Waiting, run, active,
                                 insert_nearest_first, pop_nearest)

from raysort import isa
from raysort.plugin import Traversal


cdef inline void prefetch_node8(const rs_node8 *nodes8, int ref) noexcept nogil:
    """Ask for an 8-wide node's four cache lines (boxes, then children)."""
    cdef const char *p = <const char *> &nodes8[ref]
    rs_prefetch(p)
    rs_prefetch(p + 64)
    rs_prefetch(p + 128)
    rs_prefetch(p + 192)


cdef inline void prefetch_group(const rs_tri8 *groups8, int group) noexcept nogil:
    """Ask for a triangle group's five cache lines."""
    cdef const char *p = <const char *> &groups8[group]
    rs_prefetch(p)
    rs_prefetch(p + 64)
    rs_prefetch(p + 128)
    rs_prefetch(p + 192)
    rs_prefetch(p + 256)


cdef void trace_wide8(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                      Scratch *w, rs_counters *counters) noexcept nogil:
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef Waiting *stack = <Waiting *> w.stack     # ref >= 0: an 8-wide node; < 0: groups
    cdef Waiting hit[8]
    cdef Waiting child
    cdef float entry[8]
    cdef rs_ray8 ray
    cdef int i, k, m, mask, sp, ref, groups
    cdef const rs_node8 *n
    cdef const rs_node8 *nodes8 = <const rs_node8 *> g.tree      # BVH.wide8.nodes
    cdef const rs_tri8 *groups8 = <const rs_tri8 *> g.leaves     # BVH.wide8.groups
    for i in range(start, start + count):
        if not active(r, i):
            continue
        rs_ray8_load(r, i, &ray)
        sp = 0
        ref = 0
        groups = 0
        while True:
            if ref >= 0:
                n = &nodes8[ref]
                c.box4 += 1
                mask = rs_node8_hit(r, i, &ray, n, entry)
                m = 0                              # the children hit, nearest first
                while mask:
                    k = rs_lowest_bit(mask)
                    mask &= mask - 1
                    child.ref, child.count, child.entry = n.child[k], n.count[k], entry[k]
                    insert_nearest_first(hit, m, child)
                    m += 1
                for k in range(m - 1, 0, -1):      # farther children wait, farthest deepest
                    stack[sp] = hit[k]
                    sp += 1
                    rs_prefetch(&nodes8[hit[k].ref] if hit[k].ref >= 0
                                else <const rs_node8 *> &groups8[-hit[k].ref - 1])
                if m:
                    ref = hit[0].ref
                    groups = hit[0].count
                    if ref >= 0:
                        prefetch_node8(nodes8, ref)
                    else:
                        prefetch_group(groups8, -ref - 1)
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
