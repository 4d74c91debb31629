"""``frustum``: coherent packets through the 8-wide BVH with interval-arithmetic culling.

Beyond the paper, for coherent rays (camera rays, rays of one light): a chunk of up
to 64 consecutive rays of a sub-packet descends ``BVH.wide8`` together.  One
interval-arithmetic test of the chunk's frustum (the ranges of its origins and
reciprocal directions, as DynBVH's IA test) checks all eight child boxes of a node
at once, and the children kept are visited nearest first; at a leaf, the chunk's
rays meet the leaf's box in SIMD groups of rays and each ray that enters it meets
the leaf's triangle groups as in ``wide8``.  A chunk that is not coherent (fewer
than 16 active rays, directions that change sign on two axes or more or spread by
more than 0.25 in a component, or origins that spread by more than a tenth of its
longest ray on an axis) is traced one ray at a time as ``wide8`` does.
The kernel is ``raysort/include/raysort/frustum.h``.
"""
from raysort._types cimport rs_node8, rs_tri8, rs_rays, rs_counters
from raysort.sdk.driver cimport Kernel, Geometry, Scratch, run

from raysort import isa
from raysort.plugin import Traversal


cdef extern from "raysort/frustum.h" nogil:
    enum: RS_FRUSTUM_CHUNK
    ctypedef struct rs_frustum_entry:
        pass
    ctypedef struct rs_stream_entry:
        pass
    void rs_frustum_trace8(const rs_node8 *nodes, const rs_tri8 *groups, rs_rays *r, int start,
                           int count, int any_hit, rs_frustum_entry *stack,
                           rs_stream_entry *single, rs_counters *c)


cdef void trace_frustum(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                        Scratch *w, rs_counters *c) noexcept nogil:
    # the scratch stack: 7 chunk entries per level, then 7 single-ray entries per level
    cdef rs_frustum_entry *stack = <rs_frustum_entry *> w.stack
    cdef rs_stream_entry *single = <rs_stream_entry *> (
        <char *> w.stack + 7 * w.levels * sizeof(rs_frustum_entry))
    rs_frustum_trace8(<const rs_node8 *> g.tree, <const rs_tri8 *> g.leaves, r, start, count,
                      any_hit, stack, single, c)


# a node pops one box and pushes at most eight: 7 waiting boxes per level (the
# driver's levels, the binary depth + 2, bound the 8-wide tree's depth + 1)
cdef Kernel FRUSTUM = Kernel(trace_frustum,
                             7 * (sizeof(rs_frustum_entry) + sizeof(rs_stream_entry)), 0, 0)


def chunk():
    """Rays traced together (a sub-packet is cut into chunks of this many)."""
    return RS_FRUSTUM_CHUNK


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    tree = bvh.wide8
    return run(&FRUSTUM, bvh, packets, any_hit, tree.nodes, tree.groups)


class FrustumTraversal(Traversal):
    """Coherent chunks of 64 rays through the 8-wide BVH, culled by their frustum.

    Beyond the paper, for coherent rays: consecutive rays of a sub-packet (64 at
    a time; the ``none`` sorter's 8x8 camera-ray packets are one chunk each) share
    the walk down ``BVH.wide8``.  One interval-arithmetic test of the chunk's
    frustum checks a node's eight child boxes, children are visited nearest
    first, and boxes behind every ray's closest hit are skipped; at a leaf, each
    ray that enters the leaf's box (SIMD over rays) meets its triangle groups
    eight triangles at a time, as in ``wide8`` (with AVX-512, two rays per
    16-lane test).  Chunks that are not coherent
    (fewer than 16 active rays, directions that change sign on two axes or more,
    or whose components spread by more than 0.25, or origins that spread by more
    than a tenth of the longest ray on an axis) are traced one ray at a time,
    as ``wide8`` does, so
    incoherent rays cost about what ``wide8`` costs.  Exact on every ISA.

    Counts N_IA (one 8-box interval test per node visited by a chunk), SIMD N_B
    (one per SIMD group of rays tested against a leaf's box, and as ``wide8``
    for rays traced one at a time) and SIMD N_T (one per ray and triangle group).

    It takes no parameters; the chunk is the sorter's sub-packet, cut into
    pieces of 64 rays.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.frustum").trace(bvh, packets, any_hit)
