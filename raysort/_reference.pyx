"""Brute-force closest/any hit: every ray against every triangle (nogil)."""
from libc.stdint cimport int32_t, uint8_t
from raysort._types cimport rs_tri, rs_rays, rs_tri1, rays_view, RS_PACKET_ROWS


def brute_force(const uint8_t[::1] tri_bytes, float[:, ::1] rows, int32_t[::1] prim,
                float[::1] u, float[::1] v, bint any_hit):
    """Test every active lane of gathered ``rows`` against every triangle, in input order.
    ValueError unless ``rows`` has the packet rows, ``prim``, ``u`` and ``v`` one value
    per lane and ``tri_bytes`` whole triangles."""
    if (rows.shape[0] != RS_PACKET_ROWS or prim.shape[0] != rows.shape[1]
            or u.shape[0] != rows.shape[1] or v.shape[0] != rows.shape[1]):
        raise ValueError(f"brute_force: rows ({RS_PACKET_ROWS}, lanes) and prim, u, v of one "
                         f"value per lane expected")
    if tri_bytes.shape[0] % sizeof(rs_tri):
        raise ValueError(f"brute_force: tri_bytes must hold whole triangles of "
                         f"{sizeof(rs_tri)} bytes")
    cdef const rs_tri *tris = <const rs_tri *> &tri_bytes[0] if tri_bytes.shape[0] else NULL
    cdef int n_tris = tri_bytes.shape[0] // sizeof(rs_tri), i, k
    cdef rs_rays r = rays_view(rows, prim, u, v)
    with nogil:
        for i in range(rows.shape[1]):
            for k in range(n_tris):
                if not r.tmin[i] < r.t[i]:
                    break
                rs_tri1(&r, i, &tris[k], any_hit)
