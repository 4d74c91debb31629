"""``single``: one ray at a time, the scalar reference traversal."""
from libc.stdint cimport int32_t
from raysort._types cimport rs_node, rs_rays, rs_counters, rs_box1, rs_prefetch
from raysort.sdk.driver cimport (Kernel, Geometry, Scratch, run, active, left_first,
                                 prefetch_leaf, leaf_ray)

from raysort import isa
from raysort.plugin import Traversal


cdef void trace_single(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                       Scratch *w, rs_counters *counters) noexcept nogil:
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef int i, node, sp
    cdef const rs_node *n
    cdef int32_t *stack = <int32_t *> w.stack
    for i in range(start, start + count):
        if not active(r, i):
            continue
        sp = 0
        node = 0
        while True:
            n = &g.nodes[node]
            prefetch_leaf(g, n)
            c.box1 += 1
            if rs_box1(r, i, n):
                if n.count == 0:
                    rs_prefetch(&g.nodes[n.offset])
                    if left_first(n, r, i):
                        stack[sp] = n.offset
                        node = node + 1
                    else:
                        stack[sp] = node + 1
                        node = n.offset
                    sp += 1
                    continue
                leaf_ray(g, r, i, n.offset, n.count, any_hit, &c)
                if not active(r, i):    # an any-hit query found its hit
                    break
            if sp == 0:
                break
            sp -= 1
            node = stack[sp]
    counters[0] = c


cdef Kernel SINGLE = Kernel(trace_single, sizeof(int32_t), 0, 0)    # a stack of nodes


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    return run(&SINGLE, bvh, packets, any_hit)


class SingleTraversal(Traversal):
    """Scalar depth-first traversal of one ray at a time.

    The reference every packet traversal is compared with: each ray walks the
    BVH alone, testing every node it reaches with a scalar slab test and
    visiting the child on the side its direction points to first.  Counts
    scalar N_B and scalar N_T only.

    It takes no parameters.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.single").trace(bvh, packets, any_hit)
