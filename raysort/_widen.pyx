"""Widen the 8-wide BVH to 16-wide nodes (``BVH.wide16``, for the ``wide16`` traversal).

Each 16-wide node starts from an 8-wide node's children and opens its inner
children, largest surface area first, into their own children while the sixteen
slots hold them (the greedy widening of Wald et al.'s wide BVHs).  Every slot
keeps a box of the 8-wide tree as it is, and leaves keep its rs_tri8 groups, so a
ray meets the same leaf boxes as in the 8-wide tree, each behind fewer nodes.
"""
from libc.math cimport INFINITY
from libc.stdint cimport int32_t
from libc.stdlib cimport calloc, malloc, free
from raysort._types cimport rs_node8, rs_node16

cdef enum:
    WIDTH8 = 8
    WIDTH16 = 16


cdef inline double slot_area(const float *lo, const float *hi, int k, int stride) noexcept nogil:
    """Half the surface area of the box of slot ``k`` (``lo[a * stride + k]``)."""
    cdef double dx = hi[k] - lo[k]
    cdef double dy = hi[stride + k] - lo[stride + k]
    cdef double dz = hi[2 * stride + k] - lo[2 * stride + k]
    return dx * dy + dy * dz + dz * dx


cdef struct Slots:
    # the children of one 16-wide node being formed
    int m
    int32_t child[WIDTH16]
    unsigned short count[WIDTH16]
    float lo[3][WIDTH16]
    float hi[3][WIDTH16]


cdef inline void take(Slots *s, int to, const float *lo, const float *hi, int stride, int k,
                      int32_t child, unsigned short count) noexcept nogil:
    """Slot ``to`` gets box ``k`` (``lo[a * stride + k]``, ...) and its child and count."""
    cdef int a
    s.child[to], s.count[to] = child, count
    for a in range(3):
        s.lo[a][to], s.hi[a][to] = lo[a * stride + k], hi[a * stride + k]


cdef inline void append_children(Slots *s, const rs_node8 *n) noexcept nogil:
    """Append the used slots (child != 0) of an 8-wide node."""
    cdef int k
    for k in range(WIDTH8):
        if n.child[k] != 0:
            take(s, s.m, &n.lo[0][0], &n.hi[0][0], WIDTH8, k, n.child[k], n.count[k])
            s.m += 1


cdef int widen_nodes(const rs_node8 *nodes8, int n8, rs_node16 *out, int *depth) except -1 nogil:
    """Write the 16-wide tree (root first, children after parents) into ``out``, which
    needs room for ``n8`` nodes; returns the number of nodes written."""
    cdef int *work = <int *> malloc(2 * (n8 + 1) * sizeof(int))   # (node8, node16) pairs
    cdef int *level
    cdef int sp, src, dst, m, k, j, a, best, kids, n_out = 1, ref
    cdef double area, best_area
    cdef Slots slots
    cdef rs_node16 *o
    if work == NULL:
        with gil:
            raise MemoryError()
    work[0] = 0
    work[1] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        src = work[2 * sp]
        dst = work[2 * sp + 1]
        slots.m = 0
        append_children(&slots, &nodes8[src])
        while True:                             # open the largest inner slot that fits
            best, best_area = -1, -1.0
            for k in range(slots.m):
                if slots.child[k] > 0:
                    kids = 0
                    for j in range(WIDTH8):
                        kids += nodes8[slots.child[k]].child[j] != 0
                    area = slot_area(&slots.lo[0][0], &slots.hi[0][0], k, WIDTH16)
                    if slots.m - 1 + kids <= WIDTH16 and area > best_area:
                        best, best_area = k, area
            if best < 0:
                break
            ref = slots.child[best]
            slots.m -= 1                        # the last slot moves into the opened one
            take(&slots, best, &slots.lo[0][0], &slots.hi[0][0], WIDTH16, slots.m,
                 slots.child[slots.m], slots.count[slots.m])
            append_children(&slots, &nodes8[ref])
        m = slots.m
        o = &out[dst]
        for k in range(WIDTH16):
            for a in range(3):
                o.lo[a][k] = slots.lo[a][k] if k < m else INFINITY
                o.hi[a][k] = slots.hi[a][k] if k < m else -INFINITY
            o.count[k] = slots.count[k] if k < m else 0
            o.child[k] = 0
        for k in range(8):
            o.pad[k] = 0
        for k in range(m):
            if slots.child[k] < 0:
                o.child[k] = slots.child[k]
            else:
                o.child[k] = n_out
                work[2 * sp] = slots.child[k]
                work[2 * sp + 1] = n_out
                sp += 1
                n_out += 1
    free(work)
    level = <int *> malloc(n_out * sizeof(int))
    if level == NULL:
        with gil:
            raise MemoryError()
    level[0] = 1
    depth[0] = 1
    for dst in range(n_out):
        for k in range(WIDTH16):
            ref = out[dst].child[k]
            if ref > 0:
                level[ref] = level[dst] + 1
                if level[ref] > depth[0]:
                    depth[0] = level[ref]
    free(level)
    return n_out


cdef int check_tree8(const rs_node8 *nodes8, Py_ssize_t n8) except -1:
    """ValueError unless every inner child (child > 0) of the ``n8`` 8-wide nodes comes
    after its parent, within the nodes, and is no other slot's child too (so the nodes
    reached from the root form a tree)."""
    cdef unsigned char *seen = <unsigned char *> calloc(n8, 1)
    cdef Py_ssize_t w, bad = -1
    cdef int k
    cdef int32_t c
    if seen == NULL:
        raise MemoryError()
    with nogil:
        for w in range(n8):
            for k in range(WIDTH8):
                c = nodes8[w].child[k]
                if c > 0:
                    if c <= w or c >= n8 or seen[c]:
                        bad = w
                        break
                    seen[c] = 1
            if bad >= 0:
                break
    free(seen)
    if bad >= 0:
        raise ValueError(f"widen16: node {bad} of the 8-wide tree has a child that is not a "
                         f"later node of the {n8} or is another slot's child too")
    return 0


def widen16(const unsigned char[::1] node8_bytes, unsigned char[::1] out_bytes):
    """Widen 8-wide nodes into 16-wide ones; returns (nodes written, depth).  ValueError
    for an empty tree, an output too small or nodes that form no tree (a child that does
    not follow its parent or is reached twice)."""
    cdef int n8 = node8_bytes.shape[0] // sizeof(rs_node8), n_out, depth = 0
    if n8 == 0 or out_bytes.shape[0] < n8 * sizeof(rs_node16):
        raise ValueError("widen16: the 8-wide tree is empty or the output too small")
    check_tree8(<const rs_node8 *> &node8_bytes[0], n8)
    with nogil:
        n_out = widen_nodes(<const rs_node8 *> &node8_bytes[0], n8,
                            <rs_node16 *> &out_bytes[0], &depth)
    return n_out, depth
