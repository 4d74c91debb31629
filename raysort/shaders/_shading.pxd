"""Inline shading helpers the built-in shaders share (``lambert``, ``ao``).

Where a new ray leaves a surface, in which direction, and how it is stored: the
facing normal, the hit point pushed off the surface along it, a cosine-weighted
direction around that normal, and the ray staged, then written into a batch's rows.  They are
compiled into each shader, so they cost no call, and every shader that uses them
makes bit for bit the same rays.

Everything is single-precision IEEE arithmetic with no library call whose result
could differ between C libraries: the direction's sine and cosine come from a fixed
polynomial (``unit_circle``), so a shader compiled anywhere with contraction off
(``-ffp-contract=off``, as setup.py builds) makes the same rays bit for bit.
"""
from libc.math cimport sqrtf, fabsf
from libc.stdint cimport int32_t
from libc.string cimport memcpy
from raysort._types cimport RS_RAY_OX, RS_RAY_DX, RS_RAY_TMIN, RS_RAY_TMAX, RS_RAY_ROWS

# How far a new origin is pushed off the surface: this fraction of (1 + the
# largest coordinate of the hit point), enough to clear the float32 rounding
# of the hit point so the new ray does not hit its own surface again.
cdef enum:
    OFFSET_DENOMINATOR = 8192


cdef inline float offset_scale(const float *p) noexcept nogil:
    """How far to push a new origin off the surface, relative to the coordinates."""
    cdef float m = fabsf(p[0])
    if fabsf(p[1]) > m:
        m = fabsf(p[1])
    if fabsf(p[2]) > m:
        m = fabsf(p[2])
    return (<float>1.0 + m) * <float>(1.0 / OFFSET_DENOMINATOR)


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


# New rays are staged STAGE_RAYS at a time in rows of their own and written out one row
# at a time: a batch's rows lie a whole capacity apart, and writing a dozen of them ray by
# ray makes a dozen streams whose addresses share cache sets.
cdef enum:
    STAGE_RAYS = 64


cdef struct RayStage:
    float rows[RS_RAY_ROWS][STAGE_RAYS]     # the RS_RAY_* rows of the staged rays
    float weight[3][STAGE_RAYS]             # what each ray carries (throughput, contribution)
    int32_t parent[STAGE_RAYS]              # the shaded ray it leaves from
    int32_t slot[STAGE_RAYS]                # its path's accumulator row
    int count                               # rays staged
    int written                             # rays written out before them


cdef inline int stage_ray(RayStage *s, const float *o, const float *w, float tmax,
                          int parent, int slot) noexcept nogil:
    """Stage a ray from ``o`` along ``w`` over (0, ``tmax``); returns its column, whose
    ``weight`` the caller fills.  The stage must not be full (``write_staged`` empties it)."""
    cdef int j = s.count, a
    for a in range(3):
        s.rows[RS_RAY_OX + a][j] = o[a]
        s.rows[RS_RAY_DX + a][j] = w[a]
    s.rows[RS_RAY_TMIN][j] = 0.0
    s.rows[RS_RAY_TMAX][j] = tmax
    s.parent[j] = parent
    s.slot[j] = slot
    s.count = j + 1
    return j


cdef inline void write_staged(RayStage *s, float[:, ::1] rays, float[:, ::1] weight,
                              int32_t[::1] parent, int32_t *slot) noexcept nogil:
    """Write the staged rays after those already written, row by row (``slot`` may be
    NULL: the slots are not wanted), and empty the stage."""
    cdef int k = s.written, n = s.count, r
    cdef size_t floats = n * sizeof(float), ints = n * sizeof(int32_t)
    for r in range(RS_RAY_ROWS):
        memcpy(&rays[r, k], &s.rows[r][0], floats)
    for r in range(3):
        memcpy(&weight[r, k], &s.weight[r][0], floats)
    memcpy(&parent[k], &s.parent[0], ints)
    if slot != NULL:
        memcpy(&slot[k], &s.slot[0], ints)
    s.written = k + n
    s.count = 0


cdef inline void unit_circle(float u, float *c, float *s) noexcept nogil:
    """The point (``c``, ``s``) of the unit circle at the angle ``2 pi u - pi / 4``, for
    ``u`` in [0, 1): uniform ``u`` gives a uniform angle over a whole turn.

    ``4u`` splits exactly into a quadrant ``q`` and an offset in it; the offset is an
    angle in [-pi/4, pi/4), where Cephes' single-precision minimax polynomials for sin
    and cos (``sinf.c``, S. L. Moshier) are accurate to about one ulp, and swapping and
    negating them turns the point by ``q`` quarter turns (exact)."""
    cdef float v = u * <float>4.0
    cdef int q = <int>v
    cdef float x = (v - <float>q - <float>0.5) * <float>1.5707963267948966
    cdef float z = x * x
    cdef float sin_x = ((<float>-1.9515295891e-4 * z + <float>8.3321608736e-3) * z
                        - <float>1.6666654611e-1) * z * x + x
    cdef float cos_x = (((<float>2.443315711809948e-5 * z - <float>1.388731625493765e-3) * z
                         + <float>4.166664568298827e-2) * z * z - <float>0.5 * z) + <float>1.0
    # (cos, sin) of x + q quarter turns: (c, s), (-s, c), (-c, -s), (s, -c)
    cdef float a = sin_x if q & 1 else cos_x
    cdef float b = cos_x if q & 1 else sin_x
    c[0] = -a if q == 1 or q == 2 else a
    s[0] = -b if q >= 2 else b


cdef inline void cosine_direction(const float *nrm, float u1, float u2,
                                  float *w) noexcept nogil:
    """A cosine-weighted direction ``w`` around the unit normal ``nrm`` from two uniform
    numbers in [0, 1): ``cos(angle to nrm) = sqrt(1 - u1)``, so it is never tangent, and
    the azimuth is ``unit_circle(u2)``.  The tangent frame is Duff et al. 2017's
    branchless orthonormal basis."""
    cdef float r = sqrtf(u1), along = sqrtf(<float>1.0 - u1)
    cdef float sgn = <float>1.0 if nrm[2] >= 0 else <float>-1.0
    cdef float aa = <float>-1.0 / (sgn + nrm[2])
    cdef float bb = nrm[0] * nrm[1] * aa
    cdef float cos_phi, sin_phi, x, y
    unit_circle(u2, &cos_phi, &sin_phi)
    x = r * cos_phi
    y = r * sin_phi
    # x * tangent + y * bitangent + along * normal, the basis written out
    w[0] = x * (<float>1.0 + sgn * nrm[0] * nrm[0] * aa) + y * bb + along * nrm[0]
    w[1] = x * (sgn * bb) + y * (sgn + nrm[1] * nrm[1] * aa) + along * nrm[1]
    w[2] = x * (-sgn * nrm[0]) - y * nrm[1] + along * nrm[2]
