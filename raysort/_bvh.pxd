"""Binned-SAH BVH construction and refitting; see _bvh.pyx."""
from libc.stdint cimport int32_t
from raysort._types cimport rs_node, rs_node4, rs_tri

cdef int build_nodes(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
                     int max_leaf, int bins, float trav_cost, rs_node *nodes,
                     int32_t *order, int *depth) except -1 nogil
cdef void prepare_triangles(const float[:, ::1] vertices, const int32_t[:, ::1] faces,
                            const int32_t *order, int n, rs_tri *out) noexcept nogil
cdef int collapse_nodes(const rs_node *nodes, int n_nodes, rs_node4 *out,
                        int *depth) except -1 nogil
cdef void refit_nodes(rs_node *nodes, int n_nodes, const float[:, ::1] vertices,
                      const int32_t[:, ::1] faces, const int32_t *order) noexcept nogil
