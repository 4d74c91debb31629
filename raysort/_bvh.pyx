"""Binned-SAH BVH construction, optionally with spatial splits, and refitting (nogil).

The tree is binary and stored depth first: an inner node's left child is the
next node and its right child is ``node.offset``; a leaf holds the triangles
``[offset, offset + count)`` of the BVH-ordered triangle array, sorted by their
input index.  Split costs follow DynBVH's SAH with C_isec = 1 and C_trav =
``trav_cost`` (1 in DynBVH): a node becomes a leaf when it holds at most
``max_leaf`` triangles and no binned split is cheaper than intersecting them
all.

With room for more references than triangles (``capacity`` > n, from the BVH's
``spatial_splits`` budget) the builder is an SBVH (Stich, Friedrich and
Dietrich, "Spatial splits in bounding volume hierarchies", HPG 2009): it works
on references (a triangle and a box holding the part of it the node owns), and
besides the object split over the reference centroids it bins the node's box
itself and chops every reference into the bins it spans (the triangle's edges
cut by each bin plane, the parts' boxes intersected with the reference's box).
A spatial split is tried only where the object split's children overlap by more
than ``alpha`` times the root's area, is taken when its SAH cost is lower, and
each reference cut by its plane may still go to one side whole when that is
cheaper (reference unsplitting).  A triangle may then sit in several leaves;
the references never outnumber ``capacity``, the spare room being shared out
between the children in proportion to their references.
"""
from libc.stdlib cimport malloc, free, qsort
from libc.string cimport memmove, memcpy
from libc.stdint cimport int32_t, int64_t, uint32_t
from libc.math cimport INFINITY, fabs, ldexp
from raysort._types cimport (rs_node, rs_node4, rs_node8, rs_tri, rs_tri8, rs_minf, rs_maxf,
                             RS_DEGENERATE_SIN2)


cdef enum:
    MAX_BINS = 64
    STACK_SLACK = 64    # build-stack tasks beyond two per reference
    MAX_CAPACITY = 1 << 30  # references: 2 * capacity + STACK_SLACK tasks fit an int


cdef struct Box:
    float lo[3]
    float hi[3]


cdef struct Ref:
    Box box             # holds the part of triangle `prim` that the node owns
    int32_t prim


cdef struct Task:
    int start       # the task's references: [start, end) of the reference array,
    int end
    int room        # which they may grow into up to index `room` (spatial splits)
    int parent      # node whose `offset` must point here (right children), or -1
    int depth


cdef struct Split:
    int axis
    int bin         # the split lies after bin `bin`
    float cost
    float pos       # spatial splits: the plane
    Box left        # the children's boxes and reference counts as binned
    Box right
    int n_left
    int n_right


cdef inline void box_empty(Box *b) noexcept nogil:
    for a in range(3):
        b.lo[a] = INFINITY
        b.hi[a] = -INFINITY


cdef inline void box_grow(Box *b, const float *lo, const float *hi) noexcept nogil:
    for a in range(3):
        b.lo[a] = rs_minf(lo[a], b.lo[a])
        b.hi[a] = rs_maxf(hi[a], b.hi[a])


cdef inline void box_clip(Box *b, const float *lo, const float *hi) noexcept nogil:
    """Intersect ``b`` with the box (lo, hi)."""
    for a in range(3):
        b.lo[a] = rs_maxf(lo[a], b.lo[a])
        b.hi[a] = rs_minf(hi[a], b.hi[a])


cdef inline bint box_is_empty(const Box *b) noexcept nogil:
    return not (b.lo[0] <= b.hi[0] and b.lo[1] <= b.hi[1] and b.lo[2] <= b.hi[2])


cdef inline float box_half_area(const Box *b) noexcept nogil:
    cdef float dx = b.hi[0] - b.lo[0], dy = b.hi[1] - b.lo[1], dz = b.hi[2] - b.lo[2]
    if dx < 0:
        return 0
    return dx * dy + dy * dz + dz * dx


cdef inline float overlap_half_area(const Box *x, const Box *y) noexcept nogil:
    cdef Box o = x[0]
    box_clip(&o, y.lo, y.hi)
    return 0 if box_is_empty(&o) else box_half_area(&o)


cdef int cmp_ref_prim(const void *a, const void *b) noexcept nogil:
    cdef int32_t x = (<const Ref *> a).prim, y = (<const Ref *> b).prim
    return (x > y) - (x < y)


cdef inline float centroid(const Ref *r, int a) noexcept nogil:
    return 0.5 * r.box.lo[a] + 0.5 * r.box.hi[a]


cdef inline int bin_of(float c, float cmin, float scale, int bins) noexcept nogil:
    cdef int k = <int> ((c - cmin) * scale)
    return 0 if k < 0 else (bins - 1 if k >= bins else k)


cdef int find_split(const Ref *refs, int start, int end, const Box *cbox, const Box *nbox,
                    int bins, float trav_cost, Split *best) noexcept nogil:
    """Best binned SAH object split over all three axes; returns 0 when none exists."""
    cdef Box bin_box[MAX_BINS]
    cdef int bin_count[MAX_BINS]
    cdef Box right_box[MAX_BINS]
    cdef int right_count[MAX_BINS]
    cdef Box acc
    cdef int a, i, k, n_left, found = 0
    cdef float extent, scale, cost
    cdef float parent_area = box_half_area(nbox)
    best.cost = INFINITY
    for a in range(3):
        extent = cbox.hi[a] - cbox.lo[a]
        if not (extent > 0):
            continue
        scale = bins * (1.0 - 1e-6) / extent
        for k in range(bins):
            box_empty(&bin_box[k])
            bin_count[k] = 0
        for i in range(start, end):
            k = bin_of(centroid(&refs[i], a), cbox.lo[a], scale, bins)
            bin_count[k] += 1
            box_grow(&bin_box[k], refs[i].box.lo, refs[i].box.hi)
        # sweep from the right: box and count of bins k .. bins-1
        box_empty(&acc)
        n_left = 0
        for k in range(bins - 1, 0, -1):
            box_grow(&acc, bin_box[k].lo, bin_box[k].hi)
            n_left += bin_count[k]
            right_box[k] = acc
            right_count[k] = n_left
        # sweep from the left, evaluating the split after bin k
        box_empty(&acc)
        n_left = 0
        for k in range(bins - 1):
            box_grow(&acc, bin_box[k].lo, bin_box[k].hi)
            n_left += bin_count[k]
            if n_left == 0 or right_count[k + 1] == 0:
                continue
            cost = trav_cost + (n_left * box_half_area(&acc) + right_count[k + 1]
                                * box_half_area(&right_box[k + 1])) / parent_area
            if cost < best.cost:
                best[0] = Split(a, k, cost, 0, acc, right_box[k + 1], n_left, right_count[k + 1])
                found = 1
    return found


cdef union FloatBits:
    float f
    uint32_t u


cdef inline float next_down(float f) noexcept nogil:
    """The float32 just below finite ``f``."""
    cdef FloatBits b
    b.f = f
    if f > 0:
        b.u -= 1
    elif f < 0:
        b.u += 1
    else:
        b.u = 0x80000001        # -0 and +0: the smallest negative subnormal
    return b.f


cdef inline float lower_float(double x) noexcept nogil:
    """The largest float32 <= ``x``."""
    cdef float f = <float> x
    return next_down(f) if f > x else f


cdef inline float upper_float(double x) noexcept nogil:
    """The smallest float32 >= ``x``."""
    return -lower_float(-x)


cdef enum:
    # |error| of a plane crossing computed in double is below 2^-49 (|x0| + |x1|) for the
    # edge's end coordinates x0, x1 (a few roundings of 2^-53, |t| <= 1); the crossing's
    # box is widened by 2^-46 (|x0| + |x1|) before it is rounded outward to float32
    CROSSING_ERROR_EXPONENT = -46


cdef void split_ref(const float *tri, const Ref *ref, int axis, float pos, Ref *left,
                    Ref *right) noexcept nogil:
    """Cut reference ``ref`` of triangle ``tri`` (its three vertices, 9 floats) by the
    plane ``x[axis] = pos``: boxes of the triangle's parts on either side (its vertices
    there and its edges' crossings of the plane, computed in double and rounded outward
    to float32), each intersected with the reference's box.  A part the box does not
    meet comes back empty (lo > hi)."""
    cdef Box lb, rb
    cdef int e, c
    cdef const float *p0
    cdef const float *p1
    cdef float x0, x1
    cdef float qlo[3]
    cdef float qhi[3]
    cdef double t, q, err
    cdef double err_scale = ldexp(1.0, CROSSING_ERROR_EXPONENT)
    box_empty(&lb)
    box_empty(&rb)
    for e in range(3):
        p0 = &tri[3 * e]
        p1 = &tri[3 * ((e + 1) % 3)]
        x0 = p0[axis]
        x1 = p1[axis]
        if x0 <= pos:
            box_grow(&lb, p0, p0)
        if x0 >= pos:
            box_grow(&rb, p0, p0)
        if (x0 < pos and x1 > pos) or (x0 > pos and x1 < pos):
            t = (<double> pos - x0) / (<double> x1 - x0)
            for c in range(3):
                if c == axis:
                    qlo[c] = qhi[c] = pos
                else:
                    q = p0[c] + t * (<double> p1[c] - p0[c])
                    err = err_scale * (fabs(p0[c]) + fabs(p1[c]))
                    qlo[c] = lower_float(q - err)
                    qhi[c] = upper_float(q + err)
            box_grow(&lb, qlo, qhi)
            box_grow(&rb, qlo, qhi)
    box_clip(&lb, ref.box.lo, ref.box.hi)
    box_clip(&rb, ref.box.lo, ref.box.hi)
    lb.hi[axis] = rs_minf(lb.hi[axis], pos)
    rb.lo[axis] = rs_maxf(rb.lo[axis], pos)
    left[0] = Ref(lb, ref.prim)
    right[0] = Ref(rb, ref.prim)


cdef inline int plane_bin(float x, const float *pos, int bins, float scale,
                          bint upper) noexcept nogil:
    """The spatial bin of coordinate ``x``: k with pos[k] <= x < pos[k + 1] (a box's lower
    side), or pos[k] < x <= pos[k + 1] (``upper``, a box's upper side), within 0..bins-1."""
    cdef int k = bin_of(x, pos[0], scale, bins)
    if upper:
        while k > 0 and x <= pos[k]:
            k -= 1
        while k < bins - 1 and x > pos[k + 1]:
            k += 1
    else:
        while k > 0 and x < pos[k]:
            k -= 1
        while k < bins - 1 and x >= pos[k + 1]:
            k += 1
    return k


cdef inline void ref_bins(const Ref *r, int axis, const float *pos, int bins, float scale,
                          int *first, int *last) noexcept nogil:
    """The spatial bins ``first .. last`` that reference ``r`` spans on ``axis``."""
    first[0] = plane_bin(r.box.lo[axis], pos, bins, scale, False)
    last[0] = plane_bin(r.box.hi[axis], pos, bins, scale, True)
    if last[0] < first[0]:
        last[0] = first[0]


cdef void bin_planes(const Box *nbox, int axis, int bins, float *pos) noexcept nogil:
    """The ``bins + 1`` planes (non-decreasing) that cut the node's box into equal bins."""
    cdef float lo = nbox.lo[axis], hi = nbox.hi[axis], step = (hi - lo) / bins
    cdef int k
    pos[0] = lo
    for k in range(1, bins):
        pos[k] = rs_minf(lo + k * step, hi)
    pos[bins] = hi


cdef void chop_into_bins(const float *tri, const Box *box, int axis, const float *pos,
                         int first, int last, Box *bin_box) noexcept nogil:
    """Grow bins ``first .. last`` by the boxes of the parts of triangle ``tri`` (within
    ``box``) that lie in them.  For the SAH estimate only: the edges' crossings of the
    bin planes are computed in float32 and not rounded outward (split_ref makes the
    references' conservative boxes)."""
    cdef Box piece, crossing
    cdef int j, e, c
    cdef float lo_plane, hi_plane, x0, x1, t
    cdef float q[3]
    cdef const float *p0
    cdef const float *p1
    box_empty(&crossing)
    for j in range(first, last + 1):
        piece = crossing                # the crossings of the plane below (none at first)
        lo_plane = pos[j] if j > first else -INFINITY
        hi_plane = pos[j + 1] if j < last else INFINITY
        for e in range(3):
            if lo_plane <= tri[3 * e + axis] <= hi_plane:
                box_grow(&piece, &tri[3 * e], &tri[3 * e])
        box_empty(&crossing)
        if j < last:
            for e in range(3):
                p0 = &tri[3 * e]
                p1 = &tri[3 * ((e + 1) % 3)]
                x0 = p0[axis]
                x1 = p1[axis]
                if (x0 < hi_plane and x1 > hi_plane) or (x0 > hi_plane and x1 < hi_plane):
                    t = (hi_plane - x0) / (x1 - x0)
                    for c in range(3):
                        q[c] = p0[c] + t * (p1[c] - p0[c])
                    q[axis] = hi_plane
                    box_grow(&crossing, q, q)
            box_grow(&piece, crossing.lo, crossing.hi)
        box_clip(&piece, box.lo, box.hi)
        piece.lo[axis] = rs_maxf(piece.lo[axis], pos[j])
        piece.hi[axis] = rs_minf(piece.hi[axis], pos[j + 1])
        if not box_is_empty(&piece):
            box_grow(&bin_box[j], piece.lo, piece.hi)


cdef int find_spatial_split(const float *corners, const Ref *refs, int start, int end,
                            int room, const Box *nbox, int bins, float trav_cost,
                            Split *best) noexcept nogil:
    """Best binned SAH spatial split with at most ``room`` references in the children;
    returns 0 when none exists."""
    cdef Box bin_box[MAX_BINS]
    cdef int n_enter[MAX_BINS]
    cdef int n_exit[MAX_BINS]
    cdef Box right_box[MAX_BINS]
    cdef int right_count[MAX_BINS]
    cdef float pos[MAX_BINS + 1]
    cdef Box acc
    cdef int a, i, k, first, last, n_left, found = 0
    cdef float extent, scale, cost
    cdef float parent_area = box_half_area(nbox)
    best.cost = INFINITY
    for a in range(3):
        extent = nbox.hi[a] - nbox.lo[a]
        if not (extent > 0):
            continue
        scale = bins * (1.0 - 1e-6) / extent
        bin_planes(nbox, a, bins, pos)
        for k in range(bins):
            box_empty(&bin_box[k])
            n_enter[k] = n_exit[k] = 0
        for i in range(start, end):
            ref_bins(&refs[i], a, pos, bins, scale, &first, &last)
            n_enter[first] += 1
            n_exit[last] += 1
            if first == last:
                box_grow(&bin_box[first], refs[i].box.lo, refs[i].box.hi)
            else:
                chop_into_bins(&corners[9 * refs[i].prim], &refs[i].box, a, pos, first, last,
                               bin_box)
        box_empty(&acc)
        n_left = 0
        for k in range(bins - 1, 0, -1):
            box_grow(&acc, bin_box[k].lo, bin_box[k].hi)
            n_left += n_exit[k]
            right_box[k] = acc
            right_count[k] = n_left
        box_empty(&acc)
        n_left = 0
        for k in range(bins - 1):
            box_grow(&acc, bin_box[k].lo, bin_box[k].hi)
            n_left += n_enter[k]
            if n_left == 0 or right_count[k + 1] == 0 or n_left + right_count[k + 1] > room:
                continue
            if box_is_empty(&acc) or box_is_empty(&right_box[k + 1]):
                continue
            cost = trav_cost + (n_left * box_half_area(&acc) + right_count[k + 1]
                                * box_half_area(&right_box[k + 1])) / parent_area
            if cost < best.cost:
                best[0] = Split(a, k, cost, pos[k + 1], acc, right_box[k + 1], n_left,
                                right_count[k + 1])
                found = 1
    return found


cdef int spatial_partition(const float *corners, Ref *refs, Ref *spill, int start, int end,
                           const Box *nbox, int bins, Split *s) noexcept nogil:
    """Apply spatial split ``s``: the left references (cut ones clipped) stay at
    ``refs[start:]``, the right ones go to ``spill[0:]``; returns how many stay left
    (``s.n_right`` gets how many went right).  A cut reference goes whole to one side
    when that costs less than having it on both (Stich et al.'s unsplitting), unless
    that would empty the other side."""
    cdef float pos[MAX_BINS + 1]
    cdef float scale = bins * (1.0 - 1e-6) / (nbox.hi[s.axis] - nbox.lo[s.axis])
    cdef int i, first, last, n_left = start, n_right = 0
    cdef int count_left = s.n_left, count_right = s.n_right
    cdef float area_left = box_half_area(&s.left), area_right = box_half_area(&s.right)
    cdef float both, only_left, only_right
    cdef Box grown_left, grown_right
    cdef Ref r, lp, rp
    bin_planes(nbox, s.axis, bins, pos)
    for i in range(start, end):
        r = refs[i]
        ref_bins(&r, s.axis, pos, bins, scale, &first, &last)
        if last <= s.bin:
            refs[n_left] = r
            n_left += 1
            continue
        if first > s.bin:
            spill[n_right] = r
            n_right += 1
            continue
        split_ref(&corners[9 * r.prim], &r, s.axis, s.pos, &lp, &rp)
        if box_is_empty(&lp.box) or box_is_empty(&rp.box):
            # the box is looser than the part it holds: that part lies on one side
            if box_is_empty(&lp.box):
                spill[n_right] = r
                n_right += 1
                count_left -= 1
            else:
                refs[n_left] = r
                n_left += 1
                count_right -= 1
            continue
        grown_left = s.left
        box_grow(&grown_left, r.box.lo, r.box.hi)
        grown_right = s.right
        box_grow(&grown_right, r.box.lo, r.box.hi)
        both = area_left * count_left + area_right * count_right
        only_left = box_half_area(&grown_left) * count_left + area_right * (count_right - 1)
        only_right = area_left * (count_left - 1) + box_half_area(&grown_right) * count_right
        if only_left < both and only_left <= only_right and count_right > 1:
            refs[n_left] = r
            n_left += 1
            s.left = grown_left
            area_left = box_half_area(&grown_left)
            count_right -= 1
        elif only_right < both and count_left > 1:
            spill[n_right] = r
            n_right += 1
            s.right = grown_right
            area_right = box_half_area(&grown_right)
            count_left -= 1
        else:
            refs[n_left] = lp
            n_left += 1
            spill[n_right] = rp
            n_right += 1
    s.n_right = n_right
    return n_left - start


cdef int build_nodes(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
                     int max_leaf, int bins, float trav_cost, int capacity, float alpha,
                     rs_node *nodes, int32_t *order, int *n_refs, int *depth) except -1 nogil:
    """Build into ``nodes`` (room for 2 * capacity - 1) and ``order`` (capacity); returns
    the node count, ``n_refs`` gets the references written to ``order``.

    ``capacity`` (at least the triangle count n) bounds the references: with
    capacity > n, spatial splits are tried where the object split's children
    overlap by more than ``alpha`` times the root's area.
    """
    cdef int n = faces.shape[0]
    cdef Ref *refs = <Ref *> malloc((capacity + 1) * sizeof(Ref))
    cdef bint spatial_on = capacity > n
    cdef Ref *spill = <Ref *> malloc(capacity * sizeof(Ref)) if spatial_on else NULL
    cdef float *corners = <float *> malloc(9 * n * sizeof(float)) if spatial_on else NULL
    cdef Task *stack = <Task *> malloc((2 * capacity + STACK_SLACK) * sizeof(Task))
    cdef int i, a, c, k, sp = 0, n_nodes = 0, ni, count, mid, lo_i, hi_i, n_left, n_right
    cdef int room_left, right_start
    cdef int64_t spare
    cdef float v, scale, root_area = 0
    cdef bint spatial
    cdef Task task
    cdef Box nbox, cbox
    cdef Split obj, spat
    cdef rs_node *node
    if refs == NULL or stack == NULL or (spatial_on and (spill == NULL or corners == NULL)):
        free(refs); free(spill); free(corners); free(stack)
        with gil:
            raise MemoryError()
    for i in range(n):
        refs[i].prim = i
        for a in range(3):
            refs[i].box.lo[a] = INFINITY
            refs[i].box.hi[a] = -INFINITY
            for c in range(3):
                v = vertices[faces[i, c], a]
                if spatial_on:
                    corners[9 * i + 3 * c + a] = v
                refs[i].box.lo[a] = rs_minf(v, refs[i].box.lo[a])
                refs[i].box.hi[a] = rs_maxf(v, refs[i].box.hi[a])
    depth[0] = 0
    stack[0] = Task(0, n, capacity, -1, 1)
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
            box_grow(&nbox, refs[i].box.lo, refs[i].box.hi)
            for a in range(3):
                v = centroid(&refs[i], a)
                cbox.lo[a] = rs_minf(v, cbox.lo[a])
                cbox.hi[a] = rs_maxf(v, cbox.hi[a])
        if ni == 0:
            root_area = box_half_area(&nbox)
        node = &nodes[ni]
        for a in range(3):
            node.lo[a] = nbox.lo[a]
            node.hi[a] = nbox.hi[a]
        node.flags = 0
        count = task.end - task.start
        mid = -1
        spatial = False
        if count > 1:
            if not find_split(refs, task.start, task.end, &cbox, &nbox, bins, trav_cost, &obj):
                obj.cost = INFINITY
            if (spatial_on and task.room - task.start > count
                    and (obj.cost == INFINITY
                         or overlap_half_area(&obj.left, &obj.right) > alpha * root_area)
                    and find_spatial_split(corners, refs, task.start, task.end,
                                           task.room - task.start, &nbox, bins, trav_cost,
                                           &spat)
                    and spat.cost < obj.cost and (count > max_leaf or spat.cost < count)):
                n_left = spatial_partition(corners, refs, spill, task.start, task.end,
                                           &nbox, bins, &spat)
                n_right = spat.n_right
                spatial = n_left > 0 and n_right > 0
                if not spatial and n_left == 0:
                    # every cut reference's part left of the plane fell outside its box,
                    # so all went right whole: put them back and split by objects
                    memcpy(&refs[task.start], spill, count * sizeof(Ref))
            if spatial:
                mid = task.start + n_left
            elif obj.cost < INFINITY and (count > max_leaf or obj.cost < count):
                # partition by bin, exactly as find_split binned them
                scale = bins * (1.0 - 1e-6) / (cbox.hi[obj.axis] - cbox.lo[obj.axis])
                lo_i = task.start
                hi_i = task.end - 1
                while lo_i <= hi_i:
                    if bin_of(centroid(&refs[lo_i], obj.axis), cbox.lo[obj.axis],
                              scale, bins) <= obj.bin:
                        lo_i += 1
                    else:
                        refs[lo_i], refs[hi_i] = refs[hi_i], refs[lo_i]
                        hi_i -= 1
                mid = lo_i
            elif obj.cost == INFINITY and count > max_leaf:
                # all centroids coincide: split the range in the middle
                obj.axis = 0
                for a in range(1, 3):
                    if nbox.hi[a] - nbox.lo[a] > nbox.hi[obj.axis] - nbox.lo[obj.axis]:
                        obj.axis = a
                mid = task.start + count // 2
            if mid >= 0 and not spatial:
                n_left = mid - task.start
                n_right = task.end - mid
        if mid < 0:
            node.offset = task.start
            node.count = <unsigned short> count
            node.axis = 0
            qsort(&refs[task.start], count, sizeof(Ref), cmp_ref_prim)
        else:
            # share the spare room out in proportion to the children's references
            spare = task.room - task.start - n_left - n_right
            room_left = task.start + n_left + <int> (spare * n_left // (n_left + n_right))
            right_start = room_left
            if spatial:
                memcpy(&refs[right_start], spill, n_right * sizeof(Ref))
            elif right_start != mid:
                memmove(&refs[right_start], &refs[mid], n_right * sizeof(Ref))
            node.count = 0
            node.axis = <unsigned char> (spat.axis if spatial else obj.axis)
            stack[sp] = Task(right_start, right_start + n_right, task.room, ni, task.depth + 1)
            stack[sp + 1] = Task(task.start, task.start + n_left, room_left, -1, task.depth + 1)
            sp += 2
    # the leaves, in node order, hold increasing reference ranges: close the gaps
    n_refs[0] = 0
    for i in range(n_nodes):
        if nodes[i].count:
            for k in range(nodes[i].count):
                order[n_refs[0] + k] = refs[nodes[i].offset + k].prim
            nodes[i].offset = n_refs[0]
            n_refs[0] += nodes[i].count
    free(refs); free(spill); free(corners); free(stack)
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


cdef int check_mesh(str name, const float[:, ::1] vertices,
                    const int32_t[:, ::1] faces) except -1:
    """ValueError naming ``name`` unless ``vertices`` (n, 3) are finite and ``faces``
    (m, 3, m >= 1) index them (:func:`raysort.mesh.check_mesh`'s rules)."""
    cdef Py_ssize_t nv = vertices.shape[0], i, bad_face = -1, bad_vertex = -1
    cdef int c
    if vertices.shape[1] != 3 or faces.shape[1] != 3 or faces.shape[0] == 0:
        raise ValueError(f"{name}: vertices (n, 3) and faces (m, 3) with m >= 1 expected")
    with nogil:
        for i in range(faces.shape[0]):
            for c in range(3):
                if not 0 <= faces[i, c] < nv:
                    bad_face = i
            if bad_face >= 0:
                break
        for i in range(nv):
            if (vertices[i, 0] - vertices[i, 0]) + (vertices[i, 1] - vertices[i, 1]) \
                    + (vertices[i, 2] - vertices[i, 2]) != 0:
                bad_vertex = i
                break
    if bad_face >= 0:
        raise ValueError(f"{name}: faces[{bad_face}] names a vertex beyond the {nv} vertices")
    if bad_vertex >= 0:
        raise ValueError(f"{name}: vertices[{bad_vertex}] is not finite")
    return 0


cdef Py_ssize_t check_layout(str name, const unsigned char[::1] node_bytes,
                             Py_ssize_t n_tris) except -1:
    """The ``rs_tri8`` groups the leaves of ``node_bytes`` fill (a leaf's triangles in
    groups of 8); ValueError naming ``name`` unless it holds whole nodes, at least one,
    laid out as the builder lays them: depth first (inner node b: left child b + 1, right
    child ``offset``, where b's left subtree ends), so every node is reached once and
    children follow their parent, and the leaves in node order hold consecutive ranges of
    the first ``n_tris`` or fewer triangles from 0."""
    cdef Py_ssize_t n = node_bytes.shape[0] // sizeof(rs_node), b, bad = -1, groups = 0
    cdef int64_t running = 0
    cdef int32_t right
    if n == 0 or node_bytes.shape[0] % sizeof(rs_node) or n >= 2147483647:
        raise ValueError(f"{name}: node_bytes must hold whole nodes, at least one")
    cdef const rs_node *nodes = <const rs_node *> &node_bytes[0]
    cdef int32_t *end = <int32_t *> malloc(n * sizeof(int32_t))
    if end == NULL:
        raise MemoryError()
    with nogil:
        for b in range(n - 1, -1, -1):      # end[b]: where b's subtree ends
            if nodes[b].count:
                end[b] = <int32_t> (b + 1)
                continue
            right = nodes[b].offset
            if not (b + 1 < right < n and end[b + 1] == right):
                bad = b
                break
            end[b] = end[right]
        if bad < 0 and end[0] != n:
            bad = 0
        for b in range(n if bad < 0 else 0):
            if nodes[b].count:
                if nodes[b].offset != running:
                    bad = b
                    break
                running += nodes[b].count
                groups += (nodes[b].count + 7) // 8
        if bad < 0 and running > n_tris:
            bad = n - 1
    free(end)
    if bad >= 0:
        raise ValueError(f"{name}: node {bad} breaks the tree's layout (depth first, "
                         f"right child after the left subtree, leaves holding consecutive "
                         f"triangles of the {n_tris})")
    return groups


def collapse(const unsigned char[::1] node_bytes, unsigned char[::1] out_bytes):
    """Collapse binary nodes into 4-wide nodes; returns (count, depth).  ValueError unless
    the nodes form a tree as the builder lays it out (see :func:`check_layout`) and
    ``out_bytes`` has room for as many 4-wide nodes."""
    cdef int n_nodes = node_bytes.shape[0] // sizeof(rs_node), n_out, depth = 0
    check_layout("collapse", node_bytes, 2147483647)
    if out_bytes.shape[0] < n_nodes * <Py_ssize_t> sizeof(rs_node4):
        raise ValueError(f"collapse: out_bytes must have room for {n_nodes} 4-wide nodes")
    with nogil:
        n_out = collapse_nodes(<const rs_node *> &node_bytes[0], n_nodes,
                               <rs_node4 *> &out_bytes[0], &depth)
    return n_out, depth


def build(const float[:, ::1] vertices, const int32_t[:, ::1] faces, int max_leaf, int bins,
          float trav_cost, int capacity, float alpha,
          unsigned char[::1] node_bytes, int32_t[::1] order, unsigned char[::1] tri_bytes):
    """Build a BVH into preallocated buffers (nodes: 2 * capacity, order and triangles:
    capacity >= the triangle count; capacity > it allows spatial splits);
    returns (node count, reference count, depth).  ValueError at a mesh
    :func:`check_mesh` refuses, or buffers or parameters out of range."""
    cdef int n = faces.shape[0], n_nodes, n_refs = 0, depth = 0
    check_mesh("build", vertices, faces)
    if not 1 <= bins <= MAX_BINS:
        raise ValueError(f"bins must be in 1..{MAX_BINS}, got {bins}")
    if not 1 <= max_leaf <= 65535:
        raise ValueError(f"build: max_leaf must be in 1..65535 (a leaf's count), got {max_leaf}")
    if not (n <= capacity <= MAX_CAPACITY and order.shape[0] >= capacity
            and node_bytes.shape[0] >= 2 * <Py_ssize_t> capacity * sizeof(rs_node)
            and tri_bytes.shape[0] >= capacity * <Py_ssize_t> sizeof(rs_tri)):
        raise ValueError(f"build: buffers too small for a capacity of {capacity} references")
    cdef rs_node *nodes = <rs_node *> &node_bytes[0]
    cdef rs_tri *tris = <rs_tri *> &tri_bytes[0]
    with nogil:
        n_nodes = build_nodes(vertices, faces, max_leaf, bins, trav_cost, capacity, alpha,
                              nodes, &order[0], &n_refs, &depth)
        prepare_triangles(vertices, faces, &order[0], n_refs, tris)
    return n_nodes, n_refs, depth


def triangles(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
              unsigned char[::1] tri_bytes):
    """Prepare triangles in input order (for brute force); ValueError at a mesh
    :func:`check_mesh` refuses or a ``tri_bytes`` too small for its faces."""
    check_mesh("triangles", vertices, faces)
    if tri_bytes.shape[0] < faces.shape[0] * <Py_ssize_t> sizeof(rs_tri):
        raise ValueError(f"triangles: tri_bytes must have room for {faces.shape[0]} triangles")
    with nogil:
        prepare_triangles(vertices, faces, NULL, faces.shape[0], <rs_tri *> &tri_bytes[0])


def refit(const float[:, ::1] vertices, const int32_t[:, ::1] faces, const int32_t[::1] order,
          unsigned char[::1] node_bytes, unsigned char[::1] tri_bytes):
    """Move the triangles to new vertex positions and refit every box (a leaf's box from
    its triangles' whole boxes, also where spatial splits had cut them).  ValueError at a
    mesh :func:`check_mesh` refuses, an ``order`` entry that is no face, nodes that are
    no tree of ``order``'s references (:func:`check_layout`) or a ``tri_bytes`` too small."""
    cdef int n = order.shape[0]
    cdef int n_nodes = node_bytes.shape[0] // sizeof(rs_node)
    cdef Py_ssize_t i, m = faces.shape[0], bad = -1
    check_mesh("refit", vertices, faces)
    with nogil:
        for i in range(n):
            if not 0 <= order[i] < m:
                bad = i
                break
    if bad >= 0:
        raise ValueError(f"refit: order[{bad}] = {order[bad]} is not a face of the {m}")
    check_layout("refit", node_bytes, n)
    if tri_bytes.shape[0] < n * <Py_ssize_t> sizeof(rs_tri):
        raise ValueError(f"refit: tri_bytes must have room for the {n} triangles of order")
    with nogil:
        prepare_triangles(vertices, faces, &order[0], n, <rs_tri *> &tri_bytes[0])
        refit_nodes(<rs_node *> &node_bytes[0], n_nodes, vertices, faces, &order[0])


cdef inline int groups_of(int n_tris) noexcept nogil:
    """rs_tri8 groups needed for a leaf of ``n_tris`` triangles."""
    return (n_tris + 7) // 8


cdef enum:
    WIDTH8 = 8      # children of an rs_node8, lanes of an rs_tri8
    SLOTS = 9       # DP entries per binary node: slots 1..8 (index 0 unused)
    AS_LEAF = 1     # choice[n][1]: the subtree becomes one leaf
    AS_NODE = 2     # choice[n][1]: the subtree becomes one rs_node8


cdef int collect_slots(const rs_node *nodes, const unsigned char *choice, int b, int i,
                       int *kids, int m) noexcept nogil:
    """Append to kids[m...] the binary nodes that the DP's best cover of subtree ``b``
    with at most ``i`` slots uses; returns the new count."""
    while i > 1 and choice[SLOTS * b + i] == 0:
        i -= 1
    if i == 1:
        kids[m] = b
        return m + 1
    cdef int k = choice[SLOTS * b + i]
    m = collect_slots(nodes, choice, b + 1, k, kids, m)
    return collect_slots(nodes, choice, nodes[b].offset, i - k, kids, m)


cdef void pack_group(const rs_tri *tris, int first, int count, rs_tri8 *g) noexcept nogil:
    """Triangles [first, first + count) (count <= 8) into one SoA group; unused lanes
    get zero edges (never hit) and id INT32_MAX."""
    cdef int k, a
    for k in range(WIDTH8):
        for a in range(3):
            g.v0[a][k] = tris[first + k].v0[a] if k < count else 0
            g.e1[a][k] = tris[first + k].e1[a] if k < count else 0
            g.e2[a][k] = tris[first + k].e2[a] if k < count else 0
        g.id[k] = tris[first + k].id if k < count else 2147483647


cdef int collapse8_nodes(const rs_node *nodes, int n_nodes, const rs_tri *tris,
                         double node_cost, double group_cost, int max_leaf,
                         rs_node8 *out, rs_tri8 *groups, int *n_groups, int *depth,
                         double *sah) except -1 nogil:
    """Collapse the binary BVH into 8-wide nodes by SAH-optimal dynamic programming.

    The DP of Ylitie et al. 2017: cost[b][i] is the least SAH cost of covering
    binary subtree ``b`` with at most ``i`` children of the parent 8-wide node;
    one slot holds either a leaf (``group_cost`` per rs_tri8 group, allowed up to
    ``max_leaf`` triangles; binary leaves always) or an 8-wide node
    (``node_cost`` plus the best cover of its subtree with 8 slots), each
    weighted by its surface area.  Leaves' triangles are packed into SoA groups
    of 8.  ``out`` needs room for the binary inner nodes + 1, ``groups`` for
    n_tris / 8 + binary leaves.  Returns the number of nodes written; ``sah``
    gets the tree's cost relative to the root's area.
    """
    cdef double *area = <double *> malloc(n_nodes * sizeof(double))
    cdef int *ntri = <int *> malloc(n_nodes * sizeof(int))
    cdef double *cost = <double *> malloc(SLOTS * n_nodes * sizeof(double))
    cdef unsigned char *choice = <unsigned char *> malloc(SLOTS * n_nodes)
    cdef unsigned char *split8 = <unsigned char *> malloc(n_nodes)
    cdef int *work = <int *> malloc(2 * (n_nodes + 1) * sizeof(int))
    cdef int *level = NULL
    cdef int b, i, j, k, a, L, R, best_k, sp, n_out, w, m, c, ng, first, kid
    cdef int kids[WIDTH8]
    cdef double dist[SLOTS]
    cdef double leaf, inner, s, dx, dy, dz, root_dist = 0
    cdef rs_node8 *o
    if (area == NULL or ntri == NULL or cost == NULL or choice == NULL or split8 == NULL
            or work == NULL):
        free(area); free(ntri); free(cost); free(choice); free(split8); free(work)
        with gil:
            raise MemoryError()
    # bottom up (children follow their parent in the depth-first array)
    for b in range(n_nodes - 1, -1, -1):
        dx = <double> nodes[b].hi[0] - nodes[b].lo[0]
        dy = <double> nodes[b].hi[1] - nodes[b].lo[1]
        dz = <double> nodes[b].hi[2] - nodes[b].lo[2]
        area[b] = dx * dy + dy * dz + dz * dx
        if area[b] < 0:
            area[b] = 0
        for i in range(SLOTS):
            choice[SLOTS * b + i] = 0
        if nodes[b].count:
            ntri[b] = nodes[b].count
            leaf = area[b] * group_cost * groups_of(ntri[b])
            for i in range(1, SLOTS):
                cost[SLOTS * b + i] = leaf
            choice[SLOTS * b + 1] = AS_LEAF
            continue
        L = b + 1
        R = nodes[b].offset
        ntri[b] = ntri[L] + ntri[R]
        best_k = 1
        for j in range(2, SLOTS):
            dist[j] = INFINITY
            for k in range(1, j):
                s = cost[SLOTS * L + k] + cost[SLOTS * R + j - k]
                if s < dist[j]:
                    dist[j] = s
                    best_k = k
            choice[SLOTS * b + j] = <unsigned char> best_k
        split8[b] = <unsigned char> best_k     # the 8-slot cover below b (j == 8 last)
        if b == 0:
            root_dist = dist[WIDTH8]
        inner = area[b] * node_cost + dist[WIDTH8]
        leaf = area[b] * group_cost * groups_of(ntri[b]) if ntri[b] <= max_leaf else INFINITY
        cost[SLOTS * b + 1] = leaf if leaf <= inner else inner
        choice[SLOTS * b + 1] = AS_LEAF if leaf <= inner else AS_NODE
        for j in range(2, SLOTS):
            if dist[j] < cost[SLOTS * b + j - 1]:
                cost[SLOTS * b + j] = dist[j]
            else:
                cost[SLOTS * b + j] = cost[SLOTS * b + j - 1]
                choice[SLOTS * b + j] = 0
    # the root is always an 8-wide node
    s = cost[SLOTS * 0 + 1] if nodes[0].count else root_dist
    sah[0] = (area[0] * node_cost + s) / (area[0] if area[0] > 0 else 1.0)

    # top down: write the nodes and leaf groups
    n_out = 1
    ng = 0
    work[0] = 0                 # (binary node, node8 slot) pairs to fill
    work[1] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        b = work[2 * sp]
        w = work[2 * sp + 1]
        o = &out[w]
        if nodes[b].count:
            kids[0] = b         # a leaf root: one leaf child
            m = 1
        else:               # b's subtree below b, covered with 8 slots
            m = collect_slots(nodes, choice, b + 1, split8[b], kids, 0)
            m = collect_slots(nodes, choice, nodes[b].offset, WIDTH8 - split8[b], kids, m)
        for k in range(WIDTH8):
            for a in range(3):
                o.lo[a][k] = INFINITY
                o.hi[a][k] = -INFINITY
            o.child[k] = 0
            o.count[k] = 0
        for k in range(4):
            o.pad[k] = 0
        for k in range(m):
            kid = kids[k]
            for a in range(3):
                o.lo[a][k] = nodes[kid].lo[a]
                o.hi[a][k] = nodes[kid].hi[a]
            if nodes[kid].count or choice[SLOTS * kid + 1] == AS_LEAF:
                # the subtree's triangles are contiguous, from its leftmost leaf on
                c = kid
                while nodes[c].count == 0:
                    c += 1
                first = nodes[c].offset
                o.child[k] = -ng - 1
                o.count[k] = <unsigned short> groups_of(ntri[kid])
                j = 0
                while j < ntri[kid]:
                    pack_group(tris, first + j, ntri[kid] - j if ntri[kid] - j < WIDTH8 else WIDTH8,
                               &groups[ng])
                    ng += 1
                    j += WIDTH8
            else:
                o.child[k] = n_out
                work[2 * sp] = kid
                work[2 * sp + 1] = n_out
                sp += 1
                n_out += 1
    n_groups[0] = ng
    # depth: longest chain of 8-wide nodes (children are written after parents)
    level = <int *> malloc(n_out * sizeof(int))
    if level == NULL:
        free(area); free(ntri); free(cost); free(choice); free(split8); free(work)
        with gil:
            raise MemoryError()
    level[0] = 1
    depth[0] = 1
    for w in range(n_out):
        for k in range(WIDTH8):
            if out[w].child[k] > 0:
                level[out[w].child[k]] = level[w] + 1
                if level[w] + 1 > depth[0]:
                    depth[0] = level[w] + 1
    free(level); free(area); free(ntri); free(cost); free(choice); free(split8); free(work)
    return n_out


def collapse8(const unsigned char[::1] node_bytes, const unsigned char[::1] tri_bytes,
              unsigned char[::1] out_bytes, unsigned char[::1] group_bytes,
              double node_cost, double group_cost, int max_leaf):
    """Collapse binary nodes into 8-wide nodes and SoA leaf groups;
    returns (nodes, groups, depth, SAH cost).  ValueError unless the nodes form a tree
    of the triangles of ``tri_bytes`` as the builder lays it out (:func:`check_layout`),
    ``out_bytes`` has room for as many 8-wide nodes and ``group_bytes`` for the groups
    of its leaves."""
    cdef int n_nodes = node_bytes.shape[0] // sizeof(rs_node), n_out, n_groups = 0, depth = 0
    cdef double sah = 0
    cdef Py_ssize_t groups = check_layout("collapse8", node_bytes,
                                          tri_bytes.shape[0] // sizeof(rs_tri))
    if (out_bytes.shape[0] < n_nodes * <Py_ssize_t> sizeof(rs_node8)
            or group_bytes.shape[0] < groups * <Py_ssize_t> sizeof(rs_tri8)):
        raise ValueError(f"collapse8: out_bytes must have room for {n_nodes} 8-wide nodes "
                         f"and group_bytes for {groups} triangle groups")
    with nogil:
        n_out = collapse8_nodes(<const rs_node *> &node_bytes[0], n_nodes,
                                <const rs_tri *> &tri_bytes[0], node_cost, group_cost, max_leaf,
                                <rs_node8 *> &out_bytes[0], <rs_tri8 *> &group_bytes[0],
                                &n_groups, &depth, &sah)
    return n_out, n_groups, depth, sah
