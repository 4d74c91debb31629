"""C-level layouts and kernels of raysort, for Cython modules to cimport.

Declares the layout facts of ``raysort/include/raysort/types.h`` (their one owner:
structs, row enums, limits) and the shared
numeric kernels of ``raysort/include/raysort/simd.h`` (the one SIMD header) and
the 8-lane kernels of ``raysort/include/raysort/wide8.h`` (and ``wide16.h``'s node test).
An outside plugin compiled with ``include_dirs=[raysort.get_include()]`` can
``from raysort._types cimport rs_rays, rs_box4`` and use exactly the arithmetic
the built-in traversals use.
"""
from libc.stdint cimport int32_t, int64_t, uint8_t, uint16_t

ctypedef float float32_t


cdef extern from "raysort/types.h" nogil:
    enum: RS_MAX_PACKET

    # rs_ray_row and rs_packet_row, declared as plain ints to index memoryviews
    enum:
        RS_RAY_OX, RS_RAY_OY, RS_RAY_OZ
        RS_RAY_DX, RS_RAY_DY, RS_RAY_DZ
        RS_RAY_TMIN, RS_RAY_TMAX
        RS_RAY_ROWS

    enum:
        RS_PACKET_OX, RS_PACKET_OY, RS_PACKET_OZ
        RS_PACKET_DX, RS_PACKET_DY, RS_PACKET_DZ
        RS_PACKET_IX, RS_PACKET_IY, RS_PACKET_IZ
        RS_PACKET_TMIN, RS_PACKET_T
        RS_PACKET_ROWS

    const char *const rs_ray_row_names[]
    const char *const rs_packet_row_names[]

    double RS_DEGENERATE_SIN2

    enum:
        RS_DIM_JITTER_X
        RS_DIM_JITTER_Y
        RS_DIM_BOUNCE
        RS_DIMS_PER_BOUNCE
        RS_MAX_DEPTH
        RS_DIM_AO

    ctypedef struct rs_node:
        float lo[3]
        float hi[3]
        int32_t offset      # right child (inner) or first triangle (leaf)
        uint16_t count      # 0 for an inner node
        uint8_t axis
        uint8_t flags

    ctypedef struct rs_node4:
        float lo[3][4]      # lo[axis][child]
        float hi[3][4]
        int32_t child[4]    # >= 0 inner node4, < 0 leaf: triangles from -child - 1
        uint16_t count[4]   # leaf triangle count, 0 otherwise
        int32_t pad[2]

    ctypedef struct rs_node8:
        float lo[3][8]      # lo[axis][child]
        float hi[3][8]
        int32_t child[8]    # >= 0 inner node8, < 0 leaf: groups from -child - 1
        uint16_t count[8]   # rs_tri8 groups of a leaf child, 0 otherwise
        int32_t pad[4]

    ctypedef struct rs_node16:
        float lo[3][16]     # lo[axis][child]
        float hi[3][16]
        int32_t child[16]   # >= 0 inner node16, < 0 leaf: rs_tri8 groups from -child - 1
        uint16_t count[16]  # rs_tri8 groups of a leaf child, 0 otherwise
        int32_t pad[8]

    ctypedef struct rs_tri8:
        float v0[3][8]      # v0[axis][lane]
        float e1[3][8]
        float e2[3][8]
        int32_t id[8]       # index in the input mesh; INT32_MAX in an unused lane

    ctypedef struct rs_tri:
        float v0[3]
        float e1[3]
        float e2[3]
        int32_t id          # index in the input mesh
        int32_t pad[2]

    ctypedef struct rs_rays:
        const float *o[3]
        const float *d[3]
        const float *inv[3]
        const float *tmin
        float *t
        int32_t *prim
        float *u
        float *v

    ctypedef struct rs_frustum:
        float omin[3]
        float omax[3]
        float rmin[3]
        float rmax[3]

    ctypedef struct rs_counters:
        int64_t rays
        int64_t ia
        int64_t box1
        int64_t box4
        int64_t tri1
        int64_t tri4
        int64_t stream_tasks
        int64_t stream_rays


cdef extern from "raysort/simd.h" nogil:
    const char *rs_isa_name()
    void rs_prefetch(const void *p)
    void rs_prefetchw(const void *p)
    float rs_minf(float a, float b)
    float rs_maxf(float a, float b)
    int rs_active4(const rs_rays *r, int i)
    int rs_box1(const rs_rays *r, int i, const rs_node *n)
    int rs_box4(const rs_rays *r, int i, const rs_node *n)
    int rs_ia_miss(const rs_frustum *f, const rs_node *n)
    int rs_node4_hit(const rs_rays *r, int i, const rs_node4 *n, float entry[4])
    float RS_BOX_SLACK
    int rs_tri1(const rs_rays *r, int i, const rs_tri *tr, int any_hit)
    int rs_tri4(const rs_rays *r, int i, const rs_tri *tr, int any_hit)


cdef inline rs_rays rays_view(float[:, ::1] rows, int32_t[::1] prim, float[::1] u,
                              float[::1] v):
    """The C view of gathered packets (``rows``: the ``RS_PACKET_*`` rows)."""
    cdef rs_rays r
    cdef int a
    for a in range(3):
        r.o[a] = &rows[RS_PACKET_OX + a, 0]
        r.d[a] = &rows[RS_PACKET_DX + a, 0]
        r.inv[a] = &rows[RS_PACKET_IX + a, 0]
    r.tmin = &rows[RS_PACKET_TMIN, 0]
    r.t = &rows[RS_PACKET_T, 0]
    r.prim = &prim[0]
    r.u = &u[0]
    r.v = &v[0]
    return r


cdef extern from "raysort/wide8.h" nogil:
    ctypedef struct rs_ray8:
        pass
    int rs_lowest_bit(unsigned m)
    void rs_ray8_load(const rs_rays *r, int i, rs_ray8 *ray)
    int rs_node8_hit(const rs_rays *r, int i, const rs_ray8 *ray, const rs_node8 *n,
                     float entry[8])
    int rs_tri8_hit(rs_rays *r, int i, const rs_ray8 *ray, const rs_tri8 *g, int any_hit)


cdef extern from "raysort/wide16.h" nogil:
    int rs_node16_hit(const rs_rays *r, int i, const rs_ray8 *ray, const rs_node16 *n,
                      float entry[16])
