"""The traversal driver of raysort's plugin SDK, for Cython traversal kernels.

A kernel is one ``packet_fn`` that traces one sub-packet, described by a
:c:type:`Kernel` that also declares the scratch memory it needs.  Its module
hands that to :func:`run`, which checks the packets (:func:`check_packet_layout`: their
arrays fit together, whoever built them), loops over the
sub-packets without the GIL, owns the scratch memory (allocated once per call)
and sums the Table I counters::

    from raysort.sdk.driver cimport Kernel, Geometry, Scratch, run, active

    cdef void trace_mine(const Geometry *g, rs_rays *r, int start, int count,
                         int any_hit, Scratch *w, rs_counters *c) noexcept nogil:
        cdef int32_t *stack = <int32_t *> w.stack     # w.levels entries of 4 bytes
        ...

    cdef Kernel MINE = Kernel(trace_mine, sizeof(int32_t), 0, 0)

    def trace(bvh, packets, bint any_hit):
        return run(&MINE, bvh, packets, any_hit)

A kernel that walks another tree than the binary BVH (the 4-wide ``BVH.wide``,
or a structure of its own) passes its arrays as ``tree`` and ``leaves`` and
reads them from :c:type:`Geometry`.  The inline helpers below (activity tests,
the packet frustum, (node, value) stacks, leaf intersection with DynBVH's
head/SIMD/tail rule, child order) are compiled into each kernel, so they cost
no call.
"""
from libc.stdint cimport int32_t
from raysort._types cimport (rs_node, rs_tri, rs_rays, rs_frustum, rs_counters,
                             rs_tri1, rs_tri4, rs_active4, rs_minf, rs_maxf, rs_prefetch,
                             RS_BOX_SLACK)


cdef struct Geometry:
    const rs_node *nodes    # the binary BVH, flat depth first
    const rs_tri *tris      # its triangles in BVH order
    const void *tree        # the node array passed to run() as ``tree`` (NULL if none)
    const void *leaves      # the array passed to run() as ``leaves`` (NULL if none)


cdef struct Scratch:
    void *stack             # levels * Kernel.stack_bytes
    void *group_data        # groups * Kernel.group_bytes
    void *level_group_data  # levels * groups * Kernel.level_group_bytes
    int levels              # the binary BVH's depth + 2 (a bound for any stack per level)
    int groups              # 4-ray groups of the widest sub-packet


# Trace lanes [start, start + count) (start is a multiple of 4).
ctypedef void (*packet_fn)(const Geometry *g, rs_rays *r, int start, int count,
                           int any_hit, Scratch *w, rs_counters *c) noexcept nogil


cdef struct Kernel:
    packet_fn trace             # traces one sub-packet
    size_t stack_bytes          # scratch bytes per level: a stack's entries pushed per level
    size_t group_bytes          # scratch bytes per 4-ray group (e.g. group ids)
    size_t level_group_bytes    # scratch bytes per level and 4-ray group (e.g. lane masks)


cdef int check_packet_layout(object packets) except -1


cdef object run(const Kernel *kernel, object bvh, object packets, bint any_hit,
                object tree=*, object leaves=*)


cdef struct Waiting:
    # a child box a single-ray kernel of a wide tree will visit, or may skip
    int32_t ref         # >= 0: a node; < 0: a leaf, its first item -ref - 1
    int32_t count       # the leaf's items (triangles, or triangle groups)
    float entry         # where the ray enters the box


cdef inline void insert_nearest_first(Waiting *hit, int m, Waiting child) noexcept nogil:
    """Insert ``child`` into ``hit[0:m]``, which is sorted nearest first."""
    cdef int j = m
    while j > 0 and hit[j - 1].entry > child.entry:
        hit[j] = hit[j - 1]
        j -= 1
    hit[j] = child


cdef inline bint pop_nearest(Waiting *stack, int *sp, float t, Waiting *next) noexcept nogil:
    """Pop waiting boxes until one the ray still enters before its closest hit ``t``
    (``entry <= t * slack`` is exactly the decision a new slab test would make) and put
    it in ``next``; False when the stack runs empty."""
    while sp[0] > 0:
        sp[0] -= 1
        if stack[sp[0]].entry <= t * RS_BOX_SLACK:
            next[0] = stack[sp[0]]
            return True
    return False


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
