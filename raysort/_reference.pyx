"""Brute-force closest/any hit: every ray against every triangle (nogil)."""
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport rs_tri, rs_rays, rs_tri1, rays_view


def brute_force(const uint8_t[::1] tri_bytes, float[:, ::1] rows, int32_t[::1] prim,
                float[::1] u, float[::1] v, bint any_hit):
    """Test every active lane of gathered ``rows`` against every triangle, in input order."""
    cdef const rs_tri *tris = <const rs_tri *> &tri_bytes[0] if tri_bytes.shape[0] else NULL
    cdef int n_tris = tri_bytes.shape[0] // sizeof(rs_tri), i, k
    cdef rs_rays r = rays_view(rows, prim, u, v)
    with nogil:
        for i in range(rows.shape[1]):
            for k in range(n_tris):
                if not r.tmin[i] < r.t[i]:
                    break
                rs_tri1(&r, i, &tris[k], any_hit)
