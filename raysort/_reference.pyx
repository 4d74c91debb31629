# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Brute-force closest/any hit: every ray against every triangle (nogil)."""
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport rs_tri, rs_rays, rs_tri1


def brute_force(const uint8_t[::1] tri_bytes, float[:, ::1] rows, int32_t[::1] prim,
                float[::1] u, float[::1] v, bint any_hit):
    """Test every active lane of gathered ``rows`` against every triangle, in input order."""
    cdef const rs_tri *tris = <const rs_tri *> &tri_bytes[0] if tri_bytes.shape[0] else NULL
    cdef int n_tris = tri_bytes.shape[0] // sizeof(rs_tri), i, k, a
    cdef rs_rays r
    for a in range(3):
        r.o[a] = &rows[a, 0]
        r.d[a] = &rows[3 + a, 0]
        r.inv[a] = &rows[6 + a, 0]
    r.tmin = &rows[9, 0]
    r.t = &rows[10, 0]
    r.prim = &prim[0]
    r.u = &u[0]
    r.v = &v[0]
    with nogil:
        for i in range(rows.shape[1]):
            for k in range(n_tris):
                if not r.tmin[i] < r.t[i]:
                    break
                rs_tri1(&r, i, &tris[k], any_hit)
