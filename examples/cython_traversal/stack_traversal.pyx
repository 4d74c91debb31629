"""``stack``: the smallest useful traversal, one ray at a time down raysort's BVH.

It uses only raysort's public C layer: the structs and exact box and triangle tests of
``raysort/_types.pxd``, and the SDK's traversal driver (``raysort/sdk/driver.pxd``),
which checks the packets, loops over the sub-packets without the GIL, allocates the
scratch memory the kernel declares and sums the counters.  So its hits are brute
force's, bit for bit, like the built-in traversals'.
"""
from libc.stdint cimport int32_t
from raysort._types cimport rs_node, rs_rays, rs_counters, rs_box1, rs_tri1
from raysort.sdk.driver cimport Kernel, Geometry, Scratch, run, active

from raysort.sdk import Traversal


cdef void trace_packet(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                       Scratch *w, rs_counters *c) noexcept nogil:
    """Each active ray of lanes [start, start + count): depth first, left child first."""
    cdef int32_t *stack = <int32_t *> w.stack    # one entry per level, as declared below
    cdef int i, node, sp, k
    cdef const rs_node *n
    for i in range(start, start + count):
        if not active(r, i):                     # padding, invalid, or already done
            continue
        node = sp = 0
        while True:
            n = &g.nodes[node]
            c.box1 += 1
            if rs_box1(r, i, n):                 # within (tmin, t): t shrinks as hits come
                if n.count == 0:                 # inner node: left is next, right is offset
                    stack[sp] = n.offset
                    sp += 1
                    node = node + 1
                    continue
                for k in range(n.offset, n.offset + n.count):
                    c.tri1 += 1
                    rs_tri1(r, i, &g.tris[k], any_hit)  # keeps the closest hit in r.t, ...
                if not active(r, i):             # an any-hit query found a hit: t = -inf
                    break
            if sp == 0:
                break
            sp -= 1
            node = stack[sp]


# the kernel and the scratch it needs: one int32 stack entry per BVH level
cdef Kernel STACK = Kernel(trace_packet, sizeof(int32_t), 0, 0)


class StackTraversal(Traversal):
    """One ray at a time, depth first with an explicit stack.

    It takes no parameters.
    """

    def intersect(self, bvh, packets, any_hit=False):
        return run(&STACK, bvh, packets, any_hit)
