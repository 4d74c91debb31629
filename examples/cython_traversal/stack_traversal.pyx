"""``stack``: the smallest useful traversal, one ray at a time down raysort's BVH.

It uses only raysort's public C layer: the structs of ``raysort/_types.pxd`` (nodes,
triangles, the ray view) and its exact box and triangle tests, so its hits are brute
force's, bit for bit, like the built-in traversals'.
"""
from libc.stdint cimport int32_t, int64_t, uint8_t
from raysort._types cimport rs_node, rs_tri, rs_rays, rs_box1, rs_tri1, rays_view

import numpy as np

from raysort.sdk import Counters, Traversal


cdef void trace_ray(const rs_node *nodes, const rs_tri *tris, rs_rays *r, int i,
                    int any_hit, int32_t *stack, int64_t *boxes,
                    int64_t *triangles) noexcept nogil:
    """Depth first, left child first; a leaf tests each of its triangles."""
    cdef int node = 0, sp = 0, k
    cdef const rs_node *n
    while True:
        n = &nodes[node]
        boxes[0] += 1
        if rs_box1(r, i, n):                     # within (tmin, t): t shrinks as hits come
            if n.count == 0:                     # inner node: left is next, right is offset
                stack[sp] = n.offset
                sp += 1
                node = node + 1
                continue
            for k in range(n.offset, n.offset + n.count):
                triangles[0] += 1
                rs_tri1(r, i, &tris[k], any_hit)  # keeps the closest hit in r.t, r.prim, ...
            if r.t[i] <= r.tmin[i]:              # an any-hit query found a hit: t = -inf
                return
        if sp == 0:
            return
        sp -= 1
        node = stack[sp]


class StackTraversal(Traversal):
    """One ray at a time, depth first with an explicit stack.

    It takes no parameters.
    """

    def intersect(self, bvh, packets, any_hit=False):
        # The C views of the BVH and of the gathered sub-packets, and the loop over every
        # active lane: the scaffolding around trace_ray that every traversal needs.
        cdef const uint8_t[::1] node_bytes = bvh.nodes.view(np.uint8).reshape(-1)
        cdef const uint8_t[::1] tri_bytes = bvh.triangles.view(np.uint8).reshape(-1)
        cdef const int32_t[::1] starts = packets.starts, counts = packets.counts
        cdef int32_t[::1] stack = np.empty(bvh.depth + 1, np.int32)
        cdef rs_rays r = rays_view(packets.rows, packets.prim, packets.u, packets.v)
        cdef int64_t rays = 0, boxes = 0, triangles = 0
        cdef int k, i, hit_any = any_hit
        if node_bytes.shape[0] == 0 or tri_bytes.shape[0] == 0:
            return Counters()
        cdef const rs_node *nodes = <const rs_node *> &node_bytes[0]
        cdef const rs_tri *tris = <const rs_tri *> &tri_bytes[0]
        with nogil:
            for k in range(starts.shape[0]):      # every sub-packet, every active lane
                for i in range(starts[k], starts[k] + counts[k]):
                    if r.tmin[i] < r.t[i]:
                        rays += 1
                        trace_ray(nodes, tris, &r, i, hit_any, &stack[0], &boxes, &triangles)
        return Counters(rays=rays, box1=boxes, tri1=triangles)
