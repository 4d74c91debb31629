"""``masked``: masked packet traversal (Wald, Slusallek, Benthin, Wagner 2001).

The whole sub-packet descends together.  At every node each 4-ray group that
still has an active lane gets one SIMD slab test; the lanes that hit form the
mask the children inherit, and a node is entered if any lane hits.
"""
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport rs_node, rs_rays, rs_counters, rs_box4, rs_tri4, rs_active4
from raysort.sdk.driver cimport (Kernel, Geometry, Scratch, run, stack_root, stack_pop,
                                 push_children, lowest_bit, left_first)

from raysort import isa
from raysort.plugin import Traversal


cdef void trace_masked(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                       Scratch *w, rs_counters *counters) noexcept nogil:
    cdef rs_counters c = counters[0]    # a local copy stays in registers
    cdef int groups = (count + 3) // 4, sp, node, level, j, k, hits, lane
    cdef int32_t *stack = <int32_t *> w.stack
    cdef uint8_t *masks = <uint8_t *> w.level_group_data
    cdef uint8_t *parent
    cdef uint8_t *mask
    cdef const rs_node *n
    # level 0 holds the lanes active on entry; a node at level L reads the
    # masks of level L and writes its children's masks into level L + 1
    for j in range(groups):
        masks[j] = <uint8_t> rs_active4(r, start + 4 * j)
    sp = stack_root(stack, 0)
    while sp > 0:
        n = stack_pop(g, stack, &sp, &node, &level)
        parent = masks + level * groups
        mask = parent + groups
        hits = 0
        for j in range(groups):
            if parent[j]:
                c.box4 += 1
                mask[j] = <uint8_t> (rs_box4(r, start + 4 * j, n) & parent[j])
                hits |= mask[j]
            else:
                mask[j] = 0
        if not hits:
            continue
        if n.count:
            for k in range(n.offset, n.offset + n.count):
                for j in range(groups):
                    if mask[j]:
                        c.tri4 += 1
                        rs_tri4(r, start + 4 * j, &g.tris[k], any_hit)
            continue
        j = 0
        while not mask[j]:
            j += 1
        lane = start + 4 * j + lowest_bit(mask[j])
        sp = push_children(g, node, left_first(n, r, lane), stack, sp, level + 1)
    counters[0] = c


# (node, level) pairs, and a lane mask per 4-ray group at each level
cdef Kernel MASKED = Kernel(trace_masked, 2 * sizeof(int32_t), 0, sizeof(uint8_t))


def trace(bvh, packets, bint any_hit):
    """Trace ``packets`` with this ISA build of the kernel (called through raysort.isa)."""
    return run(&MASKED, bvh, packets, any_hit)


class MaskedTraversal(Traversal):
    """Masked packet traversal (Wald et al. 2001), all SIMD.

    Every node visit costs one SIMD box test per 4-ray group that still has
    an active lane; every leaf costs one SIMD triangle test per triangle and
    per group whose mask is non-empty.  No IA tests, no scalar tests.

    It takes no parameters.
    """

    trusted = True

    def intersect(self, bvh, packets, any_hit=False):
        return isa.module("traversals.masked").trace(bvh, packets, any_hit)
