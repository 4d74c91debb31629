/* raysort: the 8-lane kernels of the `wide8` traversal.
 *
 * An 8-lane float vocabulary (rs_v8f) with an AVX path (the avx2 and avx512
 * builds: one __m256 per operation) and a path of two 4-lane halves built on
 * simd.h's vocabulary (SSE2, or the portable scalar path of the "scalar"
 * build), chosen by the ISA macros of simd.h.  On it, two kernels:
 *   - rs_node8_hit: one ray against the eight child boxes of an rs_node8;
 *   - rs_tri8_hit: one ray against the eight triangles of an rs_tri8 group.
 *
 * Exactness: lane k of rs_node8_hit performs rs_box1's operations on child
 * k's box, and lane k of rs_tri8_hit performs rs_tri1's operations on
 * triangle k, in the same order (no FMA: the build uses -ffp-contract=off and
 * no -mfma).  rs_tri8_hit then takes, among the lanes that beat the ray's
 * current hit, the lowest (t, id): what rs_tri1 applied to the lanes one
 * after the other would keep.  So wide8 returns brute force's hits bit for
 * bit on every ISA.
 */
#ifndef RAYSORT_WIDE8_H
#define RAYSORT_WIDE8_H

#include "simd.h"

/* ------------------------------------------------------------------------ */
/* 8-lane vocabulary                                                         */
/* ------------------------------------------------------------------------ */
#if RS_ISA_AVX2
typedef __m256 rs_v8f;
typedef __m256 rs_v8m;   /* lane mask: all ones or all zeros per lane */

RS_INLINE rs_v8f rs8_load(const float *p) { return _mm256_load_ps(p); }
RS_INLINE void rs8_store(float *p, rs_v8f a) { _mm256_storeu_ps(p, a); }
RS_INLINE rs_v8f rs8_set1(float a) { return _mm256_set1_ps(a); }
RS_INLINE rs_v8f rs8_add(rs_v8f a, rs_v8f b) { return _mm256_add_ps(a, b); }
RS_INLINE rs_v8f rs8_sub(rs_v8f a, rs_v8f b) { return _mm256_sub_ps(a, b); }
RS_INLINE rs_v8f rs8_mul(rs_v8f a, rs_v8f b) { return _mm256_mul_ps(a, b); }
RS_INLINE rs_v8f rs8_div(rs_v8f a, rs_v8f b) { return _mm256_div_ps(a, b); }
/* MAXPS/MINPS semantics: a > b ? a : b and a < b ? a : b (rs_maxf, rs_minf) */
RS_INLINE rs_v8f rs8_max(rs_v8f a, rs_v8f b) { return _mm256_max_ps(a, b); }
RS_INLINE rs_v8f rs8_min(rs_v8f a, rs_v8f b) { return _mm256_min_ps(a, b); }
RS_INLINE rs_v8m rs8_le(rs_v8f a, rs_v8f b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
RS_INLINE rs_v8m rs8_gt(rs_v8f a, rs_v8f b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
RS_INLINE rs_v8m rs8_ge(rs_v8f a, rs_v8f b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
RS_INLINE rs_v8m rs8_ne(rs_v8f a, rs_v8f b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
RS_INLINE rs_v8m rs8_and(rs_v8m a, rs_v8m b) { return _mm256_and_ps(a, b); }
RS_INLINE int rs8_movemask(rs_v8m m) { return _mm256_movemask_ps(m); }
#else
typedef struct { rs_v4f h[2]; } rs_v8f;
typedef struct { rs_v4m h[2]; } rs_v8m;

#define RS8_OP(name, op4, R, A) \
    RS_INLINE R name(A a, A b) \
    { R r; r.h[0] = op4(a.h[0], b.h[0]); r.h[1] = op4(a.h[1], b.h[1]); return r; }

RS_INLINE rs_v8f rs8_load(const float *p)
{ rs_v8f r; r.h[0] = rs_load(p); r.h[1] = rs_load(p + 4); return r; }
RS_INLINE void rs8_store(float *p, rs_v8f a) { rs_store(p, a.h[0]); rs_store(p + 4, a.h[1]); }
RS_INLINE rs_v8f rs8_set1(float a) { rs_v8f r; r.h[0] = r.h[1] = rs_set1(a); return r; }
RS8_OP(rs8_add, rs_add, rs_v8f, rs_v8f)
RS8_OP(rs8_sub, rs_sub, rs_v8f, rs_v8f)
RS8_OP(rs8_mul, rs_mul, rs_v8f, rs_v8f)
RS8_OP(rs8_div, rs_div, rs_v8f, rs_v8f)
RS8_OP(rs8_max, rs_max, rs_v8f, rs_v8f)
RS8_OP(rs8_min, rs_min, rs_v8f, rs_v8f)
RS8_OP(rs8_le, rs_le, rs_v8m, rs_v8f)
RS8_OP(rs8_gt, rs_gt, rs_v8m, rs_v8f)
RS8_OP(rs8_ge, rs_ge, rs_v8m, rs_v8f)
RS8_OP(rs8_ne, rs_ne, rs_v8m, rs_v8f)
RS8_OP(rs8_and, rs_and, rs_v8m, rs_v8m)
RS_INLINE int rs8_movemask(rs_v8m m) { return rs_movemask(m.h[0]) | rs_movemask(m.h[1]) << 4; }
#undef RS8_OP
#endif

/* Index of the lowest set bit of a non-zero mask. */
#if defined(_MSC_VER)
#  include <intrin.h>
RS_INLINE int rs_lowest_bit(unsigned m) { unsigned long k; _BitScanForward(&k, m); return (int)k; }
#else
RS_INLINE int rs_lowest_bit(unsigned m) { return __builtin_ctz(m); }
#endif

/* ------------------------------------------------------------------------ */
/* One ray, broadcast to 8 lanes                                             */
/* ------------------------------------------------------------------------ */
typedef struct rs_ray8 {
    rs_v8f o[3], d[3], inv[3];  /* origin, direction, 1 / direction in every lane */
    int neg[3];                 /* sign bit of 1 / direction per axis: near plane is hi */
} rs_ray8;

RS_INLINE void rs_ray8_load(const rs_rays *r, int i, rs_ray8 *ray)
{
    for (int a = 0; a < 3; ++a) {
        ray->o[a] = rs8_set1(r->o[a][i]);
        ray->d[a] = rs8_set1(r->d[a][i]);
        ray->inv[a] = rs8_set1(r->inv[a][i]);
        ray->neg[a] = signbit(r->inv[a][i]) != 0;
    }
}

/* One ray (lane i of r, broadcast in `ray`) against eight boxes stored
 * structure-of-arrays, axis a's minima at lo + a * stride (maxima likewise):
 * returns the 8-bit mask of boxes hit and stores where the ray enters each in
 * entry[].  Lane k performs exactly rs_box1's operations on box k, so the
 * decision equals a scalar slab test's.  lo and hi are 32-byte aligned. */
RS_INLINE int rs_boxes8_hit(const rs_rays *r, int i, const rs_ray8 *ray, const float *lo,
                            const float *hi, int stride, float entry[8])
{
    rs_v8f tn = rs8_set1(r->tmin[i]), tf = rs8_set1(r->t[i]);
    for (int a = 0; a < 3; ++a) {
        rs_v8f near_plane = rs8_load((ray->neg[a] ? hi : lo) + a * stride);
        rs_v8f far_plane = rs8_load((ray->neg[a] ? lo : hi) + a * stride);
        tn = rs8_max(rs8_mul(rs8_sub(near_plane, ray->o[a]), ray->inv[a]), tn);
        tf = rs8_min(rs8_mul(rs8_sub(far_plane, ray->o[a]), ray->inv[a]), tf);
    }
    rs8_store(entry, tn);
    return rs8_movemask(rs8_le(tn, rs8_mul(tf, rs8_set1(RS_BOX_SLACK))));
}

/* The eight child boxes of a node (rs_boxes8_hit). */
RS_INLINE int rs_node8_hit(const rs_rays *r, int i, const rs_ray8 *ray, const rs_node8 *n,
                           float entry[8])
{
    return rs_boxes8_hit(r, i, ray, &n->lo[0][0], &n->hi[0][0], 8, entry);
}

/* Of the lanes in `bits` (t in tl[], primitive ids in id[]), all with t <=
 * ray i's t, the one with the lowest (t, id) that beats ray i's hit (a t equal
 * to the ray's needs a lower id): its lane, or -1.  What rs_tri1 applied to the
 * lanes one after the other would keep. */
RS_INLINE int rs_tri8_pick(const rs_rays *r, int i, int bits, const float tl[8],
                           const int32_t id[8])
{
    float best = r->t[i];
    int32_t prim = r->prim[i];
    int pick = -1;
    for (; bits; bits &= bits - 1) {
        int k = rs_lowest_bit((unsigned)bits);
        if (tl[k] < best || (tl[k] == best && id[k] < prim)) {
            best = tl[k];
            prim = id[k];
            pick = k;
        }
    }
    return pick;
}

/* Ray i's new hit (with any_hit its t becomes -inf: the query is answered). */
RS_INLINE void rs_tri8_keep(rs_rays *r, int i, float t, int32_t prim, float u, float v,
                            int any_hit)
{
    r->t[i] = any_hit ? -INFINITY : t;
    r->prim[i] = prim;
    r->u[i] = u;
    r->v[i] = v;
}

/* One ray against the eight triangles of a group (Moller-Trumbore, two-sided,
 * rs_tri1's operations per lane).  Of the lanes that beat the ray's current
 * hit, the lowest (t, id) is recorded; with any_hit the ray's t becomes -inf.
 * Returns 1 when the ray's hit changed. */
RS_INLINE int rs_tri8_hit(rs_rays *r, int i, const rs_ray8 *ray, const rs_tri8 *g, int any_hit)
{
    rs_v8f e1x = rs8_load(g->e1[0]), e1y = rs8_load(g->e1[1]), e1z = rs8_load(g->e1[2]);
    rs_v8f e2x = rs8_load(g->e2[0]), e2y = rs8_load(g->e2[1]), e2z = rs8_load(g->e2[2]);
    rs_v8f v0x = rs8_load(g->v0[0]), v0y = rs8_load(g->v0[1]), v0z = rs8_load(g->v0[2]);
    RS_MT_UV(rs8, rs_v8f, ray->o, ray->d);
    const rs_v8f zero = rs8_set1(0.0f), one = rs8_set1(1.0f);
    rs_v8m ok = rs8_and(rs8_and(rs8_ne(det, zero), rs8_ge(u, zero)),
                        rs8_and(rs8_ge(v, zero), rs8_le(rs8_add(u, v), one)));
    if (!rs8_movemask(ok))      /* the ray passes outside all eight: t is not needed */
        return 0;
    rs_v8f t = RS_MT_T(rs8);
    float best = r->t[i];
    /* t > tmin and t <= best; t == best with a higher id is dropped below */
    ok = rs8_and(ok, rs8_and(rs8_gt(t, rs8_set1(r->tmin[i])), rs8_le(t, rs8_set1(best))));
    int bits = rs8_movemask(ok);
    if (!bits)
        return 0;
    float tl[8], ul[8], vl[8];
    rs8_store(tl, t);
    int pick = rs_tri8_pick(r, i, bits, tl, g->id);
    if (pick < 0)
        return 0;
    rs8_store(ul, u);
    rs8_store(vl, v);
    rs_tri8_keep(r, i, tl[pick], g->id[pick], ul[pick], vl[pick], any_hit);
    return 1;
}

#endif
