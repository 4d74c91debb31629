"""The wide8 traversal kernel; see wide8.pyx."""
from raysort._types cimport rs_rays, rs_counters
from raysort.traversals._common cimport Geometry, Scratch

cdef void trace_wide8(const Geometry *g, rs_rays *r, int start, int count, int any_hit,
                      Scratch *w, rs_counters *c) noexcept nogil
