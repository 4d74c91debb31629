"""Binned-SAH BVH construction and refitting (nogil).

The tree is binary and stored depth first: an inner node's left child is the
next node and its right child is ``node.offset``; a leaf holds the triangles
``[offset, offset + count)`` of the BVH-ordered triangle array, sorted by their
input index.  Split costs follow DynBVH's SAH with C_isec = 1 and C_trav =
``trav_cost`` (1 in DynBVH): a node becomes a leaf when it holds at most
``max_leaf`` triangles and no binned split is cheaper than intersecting them
all.
"""
from libc.stdlib cimport malloc, free, qsort
from libc.stdint cimport int32_t
from libc.math cimport INFINITY
from raysort._types cimport rs_node, rs_node4, rs_tri, rs_minf, rs_maxf, RS_DEGENERATE_SIN2

import numpy as np

cdef enum:
    MAX_BINS = 64


cdef struct Box:
    float lo[3]
    float hi[3]


cdef struct Task:
    int start
    int end
    int parent      # node whose `offset` must point here (right children), or -1
    int depth


cdef inline void box_empty(Box *b) noexcept nogil:
    for a in range(3):
        b.lo[a] = INFINITY
        b.hi[a] = -INFINITY


cdef inline void box_grow(Box *b, const float *lo, const float *hi) noexcept nogil:
    for a in range(3):
        b.lo[a] = rs_minf(lo[a], b.lo[a])
        b.hi[a] = rs_maxf(hi[a], b.hi[a])


cdef inline float box_half_area(const Box *b) noexcept nogil:
    cdef float dx = b.hi[0] - b.lo[0], dy = b.hi[1] - b.lo[1], dz = b.hi[2] - b.lo[2]
    if dx < 0:
        return 0
    return dx * dy + dy * dz + dz * dx


cdef int cmp_int32(const void *a, const void *b) noexcept nogil:
    cdef int32_t x = (<const int32_t *> a)[0], y = (<const int32_t *> b)[0]
    return (x > y) - (x < y)


cdef inline int bin_of(float c, float cmin, float scale, int bins) noexcept nogil:
    cdef int k = <int> ((c - cmin) * scale)
    return 0 if k < 0 else (bins - 1 if k >= bins else k)


cdef int find_split(const float *cent, const float *tlo, const float *thi,
                    const int32_t *order, int start, int end, const Box *cbox,
                    const Box *nbox, int bins, float trav_cost, int *axis_out, int *bin_out,
                    float *cost_out) noexcept nogil:
    """Best binned SAH split over all three axes; returns 0 when none exists."""
    cdef Box bin_box[MAX_BINS]
    cdef int bin_count[MAX_BINS]
    cdef float right_area[MAX_BINS]
    cdef int right_count[MAX_BINS]
    cdef Box acc
    cdef int a, i, k, p, n_left, found = 0
    cdef float extent, scale, cost
    cdef float parent_area = box_half_area(nbox)
    cost_out[0] = INFINITY
    for a in range(3):
        extent = cbox.hi[a] - cbox.lo[a]
        if not (extent > 0):
            continue
        scale = bins * (1.0 - 1e-6) / extent
        for k in range(bins):
            box_empty(&bin_box[k])
            bin_count[k] = 0
        for i in range(start, end):
            p = order[i]
            k = bin_of(cent[3 * p + a], cbox.lo[a], scale, bins)
            bin_count[k] += 1
            box_grow(&bin_box[k], &tlo[3 * p], &thi[3 * p])
        # sweep from the right: area and count of bins k .. bins-1
        box_empty(&acc)
        n_left = 0
        for k in range(bins - 1, 0, -1):
            box_grow(&acc, bin_box[k].lo, bin_box[k].hi)
            n_left += bin_count[k]
            right_area[k] = box_half_area(&acc)
            right_count[k] = n_left
        # sweep from the left, evaluating the split after bin k
        box_empty(&acc)
        n_left = 0
        for k in range(bins - 1):
            box_grow(&acc, bin_box[k].lo, bin_box[k].hi)
            n_left += bin_count[k]
            if n_left == 0 or right_count[k + 1] == 0:
                continue
            cost = trav_cost + (n_left * box_half_area(&acc)
                          + right_count[k + 1] * right_area[k + 1]) / parent_area
            if cost < cost_out[0]:
                cost_out[0] = cost
                axis_out[0] = a
                bin_out[0] = k
                found = 1
    return found


cdef int build_nodes(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
                     int max_leaf, int bins, float trav_cost, rs_node *nodes,
                     int32_t *order, int *depth) except -1 nogil:
    """Build into ``nodes`` (room for 2n - 1) and ``order`` (n); returns the node count."""
    cdef int n = faces.shape[0]
    cdef float *tlo = <float *> malloc(3 * n * sizeof(float))
    cdef float *thi = <float *> malloc(3 * n * sizeof(float))
    cdef float *cent = <float *> malloc(3 * n * sizeof(float))
    cdef Task *stack = <Task *> malloc((n + 64) * sizeof(Task))
    cdef int i, a, c, sp = 0, n_nodes = 0, ni, count, mid, lo_i, hi_i, split_axis, split_bin
    cdef float v, cost, scale
    cdef Task task
    cdef Box nbox, cbox
    cdef rs_node *node
    if tlo == NULL or thi == NULL or cent == NULL or stack == NULL:
        free(tlo); free(thi); free(cent); free(stack)
        with gil:
            raise MemoryError()
    for i in range(n):
        order[i] = i
        for a in range(3):
            tlo[3 * i + a] = INFINITY
            thi[3 * i + a] = -INFINITY
            for c in range(3):
                v = vertices[faces[i, c], a]
                tlo[3 * i + a] = rs_minf(v, tlo[3 * i + a])
                thi[3 * i + a] = rs_maxf(v, thi[3 * i + a])
            cent[3 * i + a] = 0.5 * tlo[3 * i + a] + 0.5 * thi[3 * i + a]
    depth[0] = 0
    stack[0] = Task(0, n, -1, 1)
    sp = 1
    while sp > 0:
        sp -= 1
        task = stack[sp]
        ni = n_nodes
        n_nodes += 1
        if task.parent >= 0:
            nodes[task.parent].offset = ni
        if task.depth > depth[0]:
            depth[0] = task.depth
        box_empty(&nbox)
        box_empty(&cbox)
        for i in range(task.start, task.end):
            box_grow(&nbox, &tlo[3 * order[i]], &thi[3 * order[i]])
            box_grow(&cbox, &cent[3 * order[i]], &cent[3 * order[i]])
        node = &nodes[ni]
        for a in range(3):
            node.lo[a] = nbox.lo[a]
            node.hi[a] = nbox.hi[a]
        node.flags = 0
        count = task.end - task.start
        mid = -1
        if count > 1 and find_split(cent, tlo, thi, order, task.start, task.end,
                                    &cbox, &nbox, bins, trav_cost, &split_axis, &split_bin,
                                    &cost):
            if count > max_leaf or cost < count:
                # partition by bin, exactly as find_split binned them
                scale = bins * (1.0 - 1e-6) / (cbox.hi[split_axis] - cbox.lo[split_axis])
                lo_i = task.start
                hi_i = task.end - 1
                while lo_i <= hi_i:
                    if bin_of(cent[3 * order[lo_i] + split_axis], cbox.lo[split_axis],
                              scale, bins) <= split_bin:
                        lo_i += 1
                    else:
                        order[lo_i], order[hi_i] = order[hi_i], order[lo_i]
                        hi_i -= 1
                mid = lo_i
        elif count > max_leaf:
            # all centroids coincide: split the range in the middle
            split_axis = 0
            for a in range(1, 3):
                if nbox.hi[a] - nbox.lo[a] > nbox.hi[split_axis] - nbox.lo[split_axis]:
                    split_axis = a
            mid = task.start + count // 2
        if mid < 0:
            node.offset = task.start
            node.count = <unsigned short> count
            node.axis = 0
            qsort(&order[task.start], count, sizeof(int32_t), cmp_int32)
        else:
            node.count = 0
            node.axis = <unsigned char> split_axis
            stack[sp] = Task(mid, task.end, ni, task.depth + 1)
            stack[sp + 1] = Task(task.start, mid, -1, task.depth + 1)
            sp += 2
    free(tlo); free(thi); free(cent); free(stack)
    return n_nodes


cdef void prepare_triangles(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
                            const int32_t *order, int n, rs_tri *out) noexcept nogil:
    """Fill ``out[p]`` with triangle ``order[p]`` (or p when order is NULL).

    A degenerate triangle gets zero edges, so its determinant is exactly 0 and
    it is never hit: one whose area is below float32 precision, i.e.
    |e1 x e2|^2 <= RS_DEGENERATE_SIN2 |e1|^2 |e2|^2 (types.h: the sine of its angle
    is at most 2^-20; exactly zero-area triangles included).  For such slivers the
    Moller-Trumbore determinant is rounding noise and would report hits far
    from the triangle.  Computed in double from the float32 vertices.
    """
    cdef int p, f, a
    cdef double e1[3]
    cdef double e2[3]
    cdef double cx, cy, cz
    cdef bint flat
    for p in range(n):
        f = order[p] if order != NULL else p
        for a in range(3):
            e1[a] = <double> vertices[faces[f, 1], a] - <double> vertices[faces[f, 0], a]
            e2[a] = <double> vertices[faces[f, 2], a] - <double> vertices[faces[f, 0], a]
        cx = e1[1] * e2[2] - e1[2] * e2[1]
        cy = e1[2] * e2[0] - e1[0] * e2[2]
        cz = e1[0] * e2[1] - e1[1] * e2[0]
        flat = (cx * cx + cy * cy + cz * cz <= RS_DEGENERATE_SIN2
                * (e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
                * (e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]))
        for a in range(3):
            out[p].v0[a] = vertices[faces[f, 0], a]
            out[p].e1[a] = 0 if flat else vertices[faces[f, 1], a] - vertices[faces[f, 0], a]
            out[p].e2[a] = 0 if flat else vertices[faces[f, 2], a] - vertices[faces[f, 0], a]
        out[p].id = f
        out[p].pad[0] = 0
        out[p].pad[1] = 0


cdef void refit_nodes(rs_node *nodes, int n_nodes, const float[:, ::1] vertices,
                      const int32_t[:, ::1] faces, const int32_t *order) noexcept nogil:
    """Recompute every box bottom up (children follow their parent)."""
    cdef int i, k, a, c, child
    cdef float p
    cdef rs_node *node
    for i in range(n_nodes - 1, -1, -1):
        node = &nodes[i]
        for a in range(3):
            node.lo[a] = INFINITY
            node.hi[a] = -INFINITY
        if node.count:
            for k in range(node.offset, node.offset + node.count):
                for c in range(3):
                    for a in range(3):
                        p = vertices[faces[order[k], c], a]
                        node.lo[a] = rs_minf(p, node.lo[a])
                        node.hi[a] = rs_maxf(p, node.hi[a])
        else:
            for c in range(2):
                child = i + 1 if c == 0 else node.offset
                for a in range(3):
                    node.lo[a] = rs_minf(nodes[child].lo[a], node.lo[a])
                    node.hi[a] = rs_maxf(nodes[child].hi[a], node.hi[a])


cdef inline float node_area(const rs_node *n) noexcept nogil:
    cdef float dx = n.hi[0] - n.lo[0], dy = n.hi[1] - n.lo[1], dz = n.hi[2] - n.lo[2]
    return dx * dy + dy * dz + dz * dx


cdef int collapse_nodes(const rs_node *nodes, int n_nodes, rs_node4 *out,
                        int *depth) except -1 nogil:
    """Collapse the binary BVH into 4-wide nodes; returns how many were written.

    Each 4-wide node takes up to four descendants: the binary node's two
    children, then repeatedly the two children of the inner child with the
    largest surface area replace it (Embree's collapse).  Leaves keep their
    triangle ranges.  ``out`` needs room for n_nodes entries.
    """
    cdef int *work = <int *> malloc(2 * (n_nodes + 1) * sizeof(int))
    cdef int sp = 0, n_out = 1, b, w, d, k, m, pick, a
    cdef int kids[4]
    cdef float best
    cdef const rs_node *c
    cdef rs_node4 *o
    if work == NULL:
        with gil:
            raise MemoryError()
    depth[0] = 1
    work[0] = 0            # (binary node, 4-wide slot) pairs to fill
    work[1] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        b = work[2 * sp]
        w = work[2 * sp + 1]
        o = &out[w]
        # gather up to four descendants of binary node b
        if nodes[b].count:
            kids[0] = b                      # a leaf root: one leaf child
            m = 1
        else:
            kids[0] = b + 1
            kids[1] = nodes[b].offset
            m = 2
            while m < 4:
                pick = -1
                best = -1
                for k in range(m):
                    if nodes[kids[k]].count == 0 and node_area(&nodes[kids[k]]) > best:
                        best = node_area(&nodes[kids[k]])
                        pick = k
                if pick < 0:
                    break
                d = kids[pick]
                kids[pick] = d + 1
                kids[m] = nodes[d].offset
                m += 1
        for k in range(4):
            for a in range(3):
                o.lo[a][k] = INFINITY
                o.hi[a][k] = -INFINITY
            o.child[k] = 0
            o.count[k] = 0
        o.pad[0] = 0
        o.pad[1] = 0
        for k in range(m):
            c = &nodes[kids[k]]
            for a in range(3):
                o.lo[a][k] = c.lo[a]
                o.hi[a][k] = c.hi[a]
            if c.count:
                o.child[k] = -c.offset - 1
                o.count[k] = c.count
            else:
                o.child[k] = n_out
                work[2 * sp] = kids[k]
                work[2 * sp + 1] = n_out
                sp += 1
                n_out += 1
    # depth: longest chain of 4-wide nodes
    cdef int *level = <int *> malloc(n_out * sizeof(int))
    if level == NULL:
        free(work)
        with gil:
            raise MemoryError()
    level[0] = 1
    for w in range(n_out):              # children are always written after parents
        for k in range(4):
            if out[w].child[k] > 0:
                level[out[w].child[k]] = level[w] + 1
                if level[w] + 1 > depth[0]:
                    depth[0] = level[w] + 1
    free(level)
    free(work)
    return n_out


def collapse(unsigned char[::1] node_bytes, unsigned char[::1] out_bytes):
    """Collapse binary nodes into 4-wide nodes; returns (count, depth)."""
    cdef int n_nodes = node_bytes.shape[0] // sizeof(rs_node), n_out, depth = 0
    with nogil:
        n_out = collapse_nodes(<const rs_node *> &node_bytes[0], n_nodes,
                               <rs_node4 *> &out_bytes[0], &depth)
    return n_out, depth


def build(const float[:, ::1] vertices, const int32_t[:, ::1] faces, int max_leaf, int bins,
          float trav_cost,
          unsigned char[::1] node_bytes, int32_t[::1] order, unsigned char[::1] tri_bytes):
    """Build a BVH into preallocated buffers; returns (node count, depth)."""
    cdef int n = faces.shape[0], n_nodes, depth = 0
    if not 1 <= bins <= MAX_BINS:
        raise ValueError(f"bins must be in 1..{MAX_BINS}, got {bins}")
    cdef rs_node *nodes = <rs_node *> &node_bytes[0]
    cdef rs_tri *tris = <rs_tri *> &tri_bytes[0]
    with nogil:
        n_nodes = build_nodes(vertices, faces, max_leaf, bins, trav_cost, nodes, &order[0],
                              &depth)
        prepare_triangles(vertices, faces, &order[0], n, tris)
    return n_nodes, depth


def triangles(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
              unsigned char[::1] tri_bytes):
    """Prepare triangles in input order (for brute force)."""
    with nogil:
        prepare_triangles(vertices, faces, NULL, faces.shape[0], <rs_tri *> &tri_bytes[0])


def refit(const float[:, ::1] vertices, const int32_t[:, ::1] faces, const int32_t[::1] order,
          unsigned char[::1] node_bytes, unsigned char[::1] tri_bytes):
    """Move the triangles to new vertex positions and refit every box."""
    cdef int n = faces.shape[0]
    cdef int n_nodes = node_bytes.shape[0] // sizeof(rs_node)
    with nogil:
        prepare_triangles(vertices, faces, &order[0], n, <rs_tri *> &tri_bytes[0])
        refit_nodes(<rs_node *> &node_bytes[0], n_nodes, vertices, faces, &order[0])
