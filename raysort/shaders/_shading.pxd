"""Inline shading helpers the built-in shaders share (``lambert``, ``ao``).

Where a new ray leaves a surface and in which direction: the facing normal,
the hit point pushed off the surface along it, and a cosine-weighted
direction around that normal.  They are compiled into each shader, so they
cost no call, and every shader that uses them makes bit for bit the same rays.
"""
from libc.math cimport sqrt, cos, sin, fabs, M_PI

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


cdef inline void leave_surface(const float *origin, const float *direction, float t,
                               const float *face_normal, float *nrm, float *o) noexcept nogil:
    """The normal facing the incoming ray (``nrm``) and the hit point ``origin + t *
    direction`` pushed off the surface along it (``o``): where the next rays start."""
    cdef float sgn = 0.0, p[3], eps
    cdef int a
    for a in range(3):
        nrm[a] = face_normal[a]
        sgn = sgn + nrm[a] * direction[a]
    if sgn > 0:
        for a in range(3):
            nrm[a] = -nrm[a]
    for a in range(3):
        p[a] = origin[a] + t * direction[a]
    eps = offset_scale(p)
    for a in range(3):
        o[a] = p[a] + eps * nrm[a]


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
    cdef int a
    tx[0] = 1.0 + sgn * nrm[0] * nrm[0] * aa
    tx[1] = sgn * bb
    tx[2] = -sgn * nrm[0]
    ty[0] = bb
    ty[1] = sgn + nrm[1] * nrm[1] * aa
    ty[2] = -nrm[1]
    for a in range(3):
        w[a] = r * cos(phi) * tx[a] + r * sin(phi) * ty[a] + sqrt(1.0 - u1) * nrm[a]
