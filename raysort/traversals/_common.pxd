"""Scaffolding shared by every traversal kernel (see _common.pyx).

A traversal module implements one ``packet_fn`` that traces one sub-packet
and hands it to :func:`run`, which loops over the sub-packets without the GIL,
owns the scratch memory and collects the counters.  The inline helpers below
(activity tests, the packet frustum, leaf intersection with DynBVH's
head/SIMD/tail rule, child order) are compiled into each kernel, so they cost
no call.
"""
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport (rs_node, rs_node4, rs_node8, rs_tri, rs_tri8, rs_rays, rs_frustum,
                             rs_counters, rs_tri1, rs_tri4, rs_active4, rs_minf, rs_maxf,
                             rs_prefetch)


cdef struct Geometry:
    const rs_node *nodes    # flat depth-first BVH
    const rs_tri *tris      # triangles in BVH order
    const rs_node4 *nodes4  # the BVH collapsed to 4-wide nodes (NULL unless asked for)
    const rs_node8 *nodes8  # the BVH collapsed to 8-wide nodes (NULL unless asked for)
    const rs_tri8 *groups8  # their leaves' SoA triangle groups


cdef struct Scratch:
    int32_t *stack          # 24 * stack_size ints: (node, int) pairs, or wider entries
    int stack_size          # BVH depth + 2
    uint8_t *masks          # stack_size * groups lane masks (masked traversal)
    int32_t *ids            # groups ids (partition traversal)
    int groups              # 4-ray groups of the widest sub-packet


# Trace lanes [start, start + count) (start is a multiple of 4).
ctypedef void (*packet_fn)(const Geometry *g, rs_rays *r, int start, int count,
                           int any_hit, Scratch *w, rs_counters *c) noexcept nogil


cdef object run(packet_fn fn, object bvh, object packets, bint any_hit, bint wide=*,
                bint wide8=*)


cdef inline bint active(const rs_rays *r, int i) noexcept nogil:
    """A lane is active while its tmin is below its current t."""
    return r.tmin[i] < r.t[i]


cdef inline int align_up(int i) noexcept nogil:
    return (i + 3) & ~3


cdef inline int align_down(int i) noexcept nogil:
    return i & ~3


cdef inline int lowest_bit(int mask) noexcept nogil:
    cdef int k = 0
    while not (mask >> k) & 1:
        k += 1
    return k


cdef inline int highest_bit(int mask) noexcept nogil:
    cdef int k = 3
    while not (mask >> k) & 1:
        k -= 1
    return k


cdef inline bint left_first(const rs_node *node, const rs_rays *r, int i) noexcept nogil:
    """Visit the left child first when ray i travels up the node's split axis."""
    return r.d[node.axis][i] >= 0


cdef inline void prefetch_leaf(const Geometry *g, const rs_node *n) noexcept nogil:
    """Ask for a leaf's first triangles before its box test runs."""
    if n.count:
        rs_prefetch(&g.tris[n.offset])
        rs_prefetch(<const char *> &g.tris[n.offset] + 64)


cdef inline int stack_root(int32_t *stack, int32_t value) noexcept nogil:
    """Start a (node, value) stack with the root; returns its depth, 1."""
    stack[0] = 0
    stack[1] = value
    return 1


cdef inline const rs_node *stack_pop(const Geometry *g, int32_t *stack, int *sp, int *node,
                                     int *value) noexcept nogil:
    """Pop (node, value) from the stack and return the node, its leaf triangles prefetched."""
    sp[0] -= 1
    node[0] = stack[2 * sp[0]]
    value[0] = stack[2 * sp[0] + 1]
    cdef const rs_node *n = &g.nodes[node[0]]
    prefetch_leaf(g, n)
    return n


cdef inline int push_children(const Geometry *g, int node, bint left_first_, int32_t *stack,
                              int sp, int32_t value) noexcept nogil:
    """Push an inner node's far child, then its near child, as (node, value) pairs on
    ``stack`` (pairs of ints) at depth ``sp``; prefetch both; return the new depth."""
    cdef int right = g.nodes[node].offset
    rs_prefetch(&g.nodes[node + 1])
    rs_prefetch(&g.nodes[right])
    stack[2 * sp] = right if left_first_ else node + 1
    stack[2 * sp + 2] = node + 1 if left_first_ else right
    stack[2 * sp + 1] = value
    stack[2 * sp + 3] = value
    return sp + 2


cdef inline void frustum_of(const rs_rays *r, int start, int count, rs_frustum *f) noexcept nogil:
    """Interval bounds of origins and reciprocal directions over the active lanes."""
    cdef int i, a
    for a in range(3):
        f.omin[a] = f.rmin[a] = 3.4028234663852886e38
        f.omax[a] = f.rmax[a] = -3.4028234663852886e38
    for i in range(start, start + count):
        if active(r, i):
            for a in range(3):
                f.omin[a] = rs_minf(r.o[a][i], f.omin[a])
                f.omax[a] = rs_maxf(r.o[a][i], f.omax[a])
                f.rmin[a] = rs_minf(r.inv[a][i], f.rmin[a])
                f.rmax[a] = rs_maxf(r.inv[a][i], f.rmax[a])


cdef inline void leaf_ray(const Geometry *g, rs_rays *r, int i, int first, int count,
                          int any_hit, rs_counters *c) noexcept nogil:
    """Test ray i against triangles [first, first + count), one scalar test each."""
    cdef int k
    for k in range(first, first + count):
        c.tri1 += 1
        rs_tri1(r, i, &g.tris[k], any_hit)


cdef inline void leaf_range(const Geometry *g, const rs_node *leaf, rs_rays *r, int first,
                            int end, int any_hit, rs_counters *c) noexcept nogil:
    """Test lanes [first, end) against every triangle of a leaf.

    DynBVH's rule on absolute lane indices: with no whole aligned 4-group in
    the range every ray is tested alone; otherwise a scalar head, 4-wide
    groups, and a scalar tail.  Inactive rays and all-inactive groups are
    skipped and not counted.
    """
    cdef int b = align_up(first), e = align_down(end), k, i
    cdef const rs_tri *tri
    for k in range(leaf.offset, leaf.offset + leaf.count):
        tri = &g.tris[k]
        if b >= e:
            for i in range(first, end):
                if active(r, i):
                    c.tri1 += 1
                    rs_tri1(r, i, tri, any_hit)
            continue
        for i in range(first, b):
            if active(r, i):
                c.tri1 += 1
                rs_tri1(r, i, tri, any_hit)
        for i in range(b, e, 4):
            if rs_active4(r, i):
                c.tri4 += 1
                rs_tri4(r, i, tri, any_hit)
        for i in range(e, end):
            if active(r, i):
                c.tri1 += 1
                rs_tri1(r, i, tri, any_hit)
