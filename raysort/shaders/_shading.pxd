"""Inline shading helpers the built-in shaders share (``lambert``, ``ao``).

Where a new ray leaves a surface, in which direction, and how it is stored: the
facing normal, the hit point pushed off the surface along it, a cosine-weighted
direction around that normal, and the ray written into a batch's rows.  They are
compiled into each shader, so they cost no call, and every shader that uses them
makes bit for bit the same rays.
"""
from libc.math cimport sqrt, cos, sin, fabs, M_PI
from raysort._types cimport RS_RAY_OX, RS_RAY_DX, RS_RAY_TMIN, RS_RAY_TMAX

# How far a new origin is pushed off the surface: this fraction of (1 + the
# largest coordinate of the hit point), enough to clear the float32 rounding
# of the hit point so the new ray does not hit its own surface again.
cdef enum:
    OFFSET_DENOMINATOR = 8192


cdef inline float offset_scale(const float *p) noexcept nogil:
    """How far to push a new origin off the surface, relative to the coordinates."""
    cdef float m = fabs(p[0])
    if fabs(p[1]) > m:
        m = fabs(p[1])
    if fabs(p[2]) > m:
        m = fabs(p[2])
    return (1.0 + m) * (1.0 / OFFSET_DENOMINATOR)


cdef inline void leave_surface(const float[:, ::1] rays, const float[::1] t,
                               const float[:, ::1] normals, int i, int f, float *nrm,
                               float *o) noexcept nogil:
    """Where ray ``i`` of a batch (the ``RS_RAY_*`` rows), which hit face ``f``
    at ``t[i]``, goes on: the face normal turned toward the incoming ray (``nrm``) and the
    hit point pushed off the surface along it (``o``)."""
    cdef float sgn = 0.0, p[3], eps
    cdef int a
    for a in range(3):
        nrm[a] = normals[f, a]
        sgn = sgn + nrm[a] * rays[RS_RAY_DX + a, i]
    if sgn > 0:
        for a in range(3):
            nrm[a] = -nrm[a]
    for a in range(3):
        p[a] = rays[RS_RAY_OX + a, i] + t[i] * rays[RS_RAY_DX + a, i]
    eps = offset_scale(p)
    for a in range(3):
        o[a] = p[a] + eps * nrm[a]


cdef inline void store_ray(float[:, ::1] out, int k, const float *o, const float *w,
                           float tmax) noexcept nogil:
    """Write ray ``k`` of a batch's rows: origin ``o``, direction ``w``, (0, ``tmax``)."""
    cdef int a
    for a in range(3):
        out[RS_RAY_OX + a, k] = o[a]
        out[RS_RAY_DX + a, k] = w[a]
    out[RS_RAY_TMIN, k] = 0.0
    out[RS_RAY_TMAX, k] = tmax


cdef inline void cosine_direction(const float *nrm, float u1, float u2,
                                  float *w) noexcept nogil:
    """A cosine-weighted direction ``w`` around the unit normal ``nrm`` from two uniform
    numbers in [0, 1): ``cos(angle to nrm) = sqrt(1 - u1)``, so it is never tangent.
    The tangent frame is Duff et al. 2017's branchless orthonormal basis."""
    cdef float r = sqrt(u1)
    cdef float phi = 2.0 * M_PI * u2
    cdef float sgn = 1.0 if nrm[2] >= 0 else -1.0
    cdef float aa = -1.0 / (sgn + nrm[2])
    cdef float bb = nrm[0] * nrm[1] * aa
    cdef float tx[3], ty[3]
    cdef double cos_phi = cos(phi), sin_phi = sin(phi), along = sqrt(1.0 - u1)
    cdef int a
    tx[0] = 1.0 + sgn * nrm[0] * nrm[0] * aa
    tx[1] = sgn * bb
    tx[2] = -sgn * nrm[0]
    ty[0] = bb
    ty[1] = sgn + nrm[1] * nrm[1] * aa
    ty[2] = -nrm[1]
    for a in range(3):
        w[a] = r * cos_phi * tx[a] + r * sin_phi * ty[a] + along * nrm[a]
