/* raysort: the one owner of every data-layout fact.
 *
 * The structs, the row order of ray batches and gathered packets, the widest
 * packet, the degenerate-triangle threshold and the random-number dimension
 * budget live here and nowhere else.  raysort/_types.pxd declares them for
 * Cython (a field or row it gets wrong fails to compile or fails
 * tests/test_layout.py); raysort/_layout.pyx derives the NumPy dtypes
 * (NODE_DTYPE, NODE4_DTYPE, TRI_DTYPE) and the Python row indices from them.
 */
#ifndef RAYSORT_TYPES_H
#define RAYSORT_TYPES_H

#include <stdint.h>

/* Widest sub-packet a traversal accepts (rays).  Large packets are 32x32 by
 * default; 64x64 tiles are the most the pipeline makes. */
#define RS_MAX_PACKET 4096

/* Rows of a ray batch (raysort.rays.RayBatch.data), one float32 row each. */
typedef enum rs_ray_row {
    RS_RAY_OX, RS_RAY_OY, RS_RAY_OZ,    /* origin */
    RS_RAY_DX, RS_RAY_DY, RS_RAY_DZ,    /* direction */
    RS_RAY_TMIN, RS_RAY_TMAX,           /* the interval a hit must lie in */
    RS_RAY_ROWS
} rs_ray_row;

/* Rows of gathered sub-packets (raysort.rays.Packets.rows), one float32 row
 * each: the ray rows, the inverse direction, and `t`, which starts at the
 * ray's tmax and shrinks as the traversal finds closer hits. */
typedef enum rs_packet_row {
    RS_PACKET_OX, RS_PACKET_OY, RS_PACKET_OZ,
    RS_PACKET_DX, RS_PACKET_DY, RS_PACKET_DZ,
    RS_PACKET_IX, RS_PACKET_IY, RS_PACKET_IZ,   /* 1 / direction */
    RS_PACKET_TMIN, RS_PACKET_T,
    RS_PACKET_ROWS
} rs_packet_row;

/* The rows' names, as Python sees them (raysort.rays.RayRow, PacketRow). */
static const char *const rs_ray_row_names[RS_RAY_ROWS] = {
    "ox", "oy", "oz", "dx", "dy", "dz", "tmin", "tmax"};
static const char *const rs_packet_row_names[RS_PACKET_ROWS] = {
    "ox", "oy", "oz", "dx", "dy", "dz", "ix", "iy", "iz", "tmin", "t"};

/* A triangle is degenerate (kept, never hit) when the squared sine of its
 * angle at the first vertex is at most this, 2^-40: |e1 x e2|^2 <=
 * RS_DEGENERATE_SIN2 |e1|^2 |e2|^2, computed in double (raysort/_bvh.pyx). */
#define RS_DEGENERATE_SIN2 9.094947017729282e-13

/* The random-number dimensions of one (seed, pixel, sample) path
 * (raysort/_rng.pxd): the generator's jitter draws the first two; a shader's
 * bounce at depth d draws RS_DIMS_PER_BOUNCE from RS_DIM_BOUNCE +
 * RS_DIMS_PER_BOUNCE * d (at most RS_MAX_DEPTH bounces, so they end below
 * RS_DIM_AO); ambient occlusion draws its own block of two per sample from
 * RS_DIM_AO. */
enum {
    RS_DIM_JITTER_X = 0,
    RS_DIM_JITTER_Y = 1,
    RS_DIM_BOUNCE = 2,
    RS_DIMS_PER_BOUNCE = 3,
    RS_MAX_DEPTH = 64,
    RS_DIM_AO = 256
};

/* One node of the flat, depth-first binary BVH: 32 bytes.
 * Inner node (count == 0): the left child is the next node, the right child
 * is `offset`.  Leaf (count > 0): triangles [offset, offset + count) of the
 * BVH-ordered triangle array. */
typedef struct rs_node {
    float lo[3];        /* box minimum */
    float hi[3];        /* box maximum */
    int32_t offset;     /* right child (inner) or first triangle (leaf) */
    uint16_t count;     /* 0 for an inner node, else number of triangles */
    uint8_t axis;       /* split axis of an inner node (0, 1, 2) */
    uint8_t flags;      /* reserved, 0 */
} rs_node;

/* A node of the 4-wide BVH collapsed from the binary one (for the `wide`
 * traversal): 128 bytes, child boxes stored structure-of-arrays so one SSE
 * operation tests a ray against all four.  child[k] >= 0 is an inner node,
 * child[k] < 0 a leaf whose triangles are [-child[k] - 1, ... + count[k]);
 * an empty slot has lo = +inf, hi = -inf, so no ray ever enters it, and child 0
 * (the root, no node's child).  A traversal skips a child 0 whatever its box
 * test says: a ray of hand-edited packet values (1 / d = 0
 * where d is not 0) can pass an empty box, as (inf - o) * 0 is NaN and the
 * test's max drops NaN, and would go back to the root again and again. */
typedef struct rs_node4 {
    float lo[3][4];     /* lo[axis][child] */
    float hi[3][4];     /* hi[axis][child] */
    int32_t child[4];
    uint16_t count[4];  /* triangles of a leaf child, 0 otherwise */
    int32_t pad[2];
} rs_node4;

/* A node of the 8-wide BVH collapsed from the binary one by a SAH-optimal
 * dynamic program (for the `wide8` traversal): 256 bytes, child boxes
 * structure-of-arrays so one 8-lane operation tests a ray against all eight.
 * child[k] >= 0 is an inner node8, child[k] < 0 a leaf whose triangle groups
 * are [-child[k] - 1, ... + count[k]) of the rs_tri8 array; an empty slot has
 * lo = +inf, hi = -inf, so no ray ever enters it. */
typedef struct rs_node8 {
    float lo[3][8];     /* lo[axis][child]: box minimum of each child */
    float hi[3][8];     /* hi[axis][child]: box maximum of each child */
    int32_t child[8];   /* inner node8 index (>= 0) or -(first group) - 1 (leaf) */
    uint16_t count[8];  /* rs_tri8 groups of a leaf child, 0 otherwise */
    int32_t pad[4];     /* 0 */
} rs_node8;

/* A node of the 16-wide BVH widened from the 8-wide one (for the `wide16`
 * traversal): 512 bytes, the same layout as rs_node8 with sixteen slots, so one
 * AVX-512 operation tests a ray against all sixteen child boxes.  Leaf children
 * point into the 8-wide tree's rs_tri8 groups; an empty slot has lo = +inf,
 * hi = -inf. */
typedef struct rs_node16 {
    float lo[3][16];    /* lo[axis][child] */
    float hi[3][16];    /* hi[axis][child] */
    int32_t child[16];  /* inner node16 index (>= 0) or -(first group) - 1 (leaf) */
    uint16_t count[16]; /* rs_tri8 groups of a leaf child, 0 otherwise */
    int32_t pad[8];     /* 0 */
} rs_node16;

/* Up to eight triangles of one leaf, structure-of-arrays, prepared for
 * Moller-Trumbore so one 8-lane test checks a ray against all of them: 320
 * bytes.  Lane k holds the rs_tri fields of one triangle; an unused lane has
 * zero edges (its determinant is 0, so it is never hit) and id INT32_MAX. */
typedef struct rs_tri8 {
    float v0[3][8];     /* v0[axis][lane]: first vertex */
    float e1[3][8];     /* v1 - v0 */
    float e2[3][8];     /* v2 - v0 */
    int32_t id[8];      /* primitive index in the input mesh */
} rs_tri8;

/* A triangle prepared for Moller-Trumbore: 48 bytes.  `id` is the index of
 * the triangle in the input mesh; ties in t go to the lower id. */
typedef struct rs_tri {
    float v0[3];        /* first vertex */
    float e1[3];        /* v1 - v0 */
    float e2[3];        /* v2 - v0 */
    int32_t id;         /* primitive index in the input mesh */
    int32_t pad[2];
} rs_tri;

/* A batch of gathered rays in structure-of-arrays form.  Every row has the
 * batch capacity (a multiple of 4) and starts 16-byte aligned, so lanes
 * [4k, 4k+4) can be loaded with one aligned SSE load.
 *
 * A lane is active while tmin[i] < t[i].  Padding lanes and invalid rays are
 * stored inactive (tmin = +inf, t = -inf).  Traversals shrink t[i] as they
 * find closer hits; an any-hit query sets t[i] = -inf when it finds one. */
typedef struct rs_rays {
    const float *o[3];  /* origin */
    const float *d[3];  /* direction */
    const float *inv[3];/* 1 / direction, computed during the gather */
    const float *tmin;  /* hits need t > tmin */
    float *t;           /* closest hit so far; starts at the ray's tmax */
    int32_t *prim;      /* primitive of the closest hit, -1 while none */
    float *u;           /* barycentric coordinates of the hit */
    float *v;
} rs_rays;

/* Conservative interval-arithmetic bounds of one packet (Wald et al. 2007):
 * the ranges of origins and reciprocal directions over its active rays. */
typedef struct rs_frustum {
    float omin[3], omax[3];
    float rmin[3], rmax[3];
} rs_frustum;

/* The work counters of the paper's Table I, per traversal call. */
typedef struct rs_counters {
    int64_t rays;       /* rays submitted (active lanes) */
    int64_t ia;         /* interval-arithmetic (frustum) box tests */
    int64_t box1;       /* scalar ray-box tests */
    int64_t box4;       /* SIMD ray-box tests (one per 4-wide test, or per 8-wide test in wide8) */
    int64_t tri1;       /* scalar ray-triangle tests */
    int64_t tri4;       /* SIMD ray-triangle tests (4-wide, or 8-wide in wide8) */
    int64_t stream_tasks;   /* streams of rays popped at a node (stream traversal) */
    int64_t stream_rays;    /* rays those streams held */
} rs_counters;

#endif
