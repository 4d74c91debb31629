/* raysort: the one SIMD header.
 *
 * With the wider vocabularies built on it (lanes.h: RS_SW lanes by ISA;
 * wide8.h: 8 lanes), the only files that include compiler intrinsics.  It
 * provides
 *   - a 4-lane float/mask vocabulary (rs_v4f, rs_v4m) with an SSE2 path and a
 *     portable scalar path, chosen at build time: setup.py defines
 *     RAYSORT_NO_SIMD for the "scalar" ISA build, and non-x86 machines get the
 *     scalar path automatically; the avx2 and avx512 builds compile the SSE2
 *     path with VEX/EVEX encoding and may add wider code (RS_ISA_AVX2, ...);
 *   - the numeric kernels every traversal shares: slab tests of one ray or 4
 *     rays against a box, Moller-Trumbore tests of one ray or 4 rays against a
 *     triangle, and the interval-arithmetic (frustum) box test (the gather
 *     that builds aligned sub-packets is in gather.h).
 *
 * Exactness: the 1-ray and 4-ray kernels perform the same IEEE operations in
 * the same order (the build uses -ffp-contract=off, so nothing is fused), and
 * rs_minf/rs_maxf have the operand semantics of MINPS/MAXPS.  Hence a ray gets
 * bit-identical t, u, v whichever kernel tests it, and every traversal returns
 * the same closest hit as brute force.
 */
#ifndef RAYSORT_SIMD_H
#define RAYSORT_SIMD_H

#include <math.h>
#include <float.h>
#include <string.h>
#include "types.h"

#if !defined(RAYSORT_NO_SIMD) && (defined(__SSE2__) || defined(_M_X64))
#  define RS_SSE 1
#  include <emmintrin.h>
#else
#  define RS_SSE 0
#endif

/* The ISA this translation unit is compiled for (setup.py builds each kernel module
 * once per ISA, see raysort/isa.py): RS_ISA_AVX512 implies RS_ISA_AVX2.  Wider code
 * paths test these; they must perform the same IEEE operations per lane. */
#if RS_SSE && defined(__AVX2__)
#  define RS_ISA_AVX2 1
#  include <immintrin.h>
#else
#  define RS_ISA_AVX2 0
#endif
#if RS_ISA_AVX2 && defined(RAYSORT_EMULATE_AVX512)
/* the avx512 code on an AVX2 CPU, its AVX-512 intrinsics emulated (tests only) */
#  define RS_ISA_AVX512 1
#  define RS_ISA_NAME "avx512emu"
#  include "avx512_emu.h"
#elif RS_ISA_AVX2 && defined(__AVX512F__) && defined(__AVX512VL__) && defined(__AVX512BW__) \
    && defined(__AVX512DQ__)
#  define RS_ISA_AVX512 1
#  define RS_ISA_NAME "avx512"
#elif RS_ISA_AVX2
#  define RS_ISA_AVX512 0
#  define RS_ISA_NAME "avx2"
#elif RS_SSE
#  define RS_ISA_AVX512 0
#  define RS_ISA_NAME "sse2"
#else
#  define RS_ISA_AVX512 0
#  define RS_ISA_NAME "scalar"
#endif

#if defined(_MSC_VER)
#  define RS_INLINE static __forceinline
#else
#  define RS_INLINE static inline __attribute__((always_inline))
#endif

/* Box tests compare t_near <= t_far * RS_BOX_SLACK.  The slack (2^-14,
 * relative) keeps the box test conservative with respect to the rounding of
 * the triangle test, so a box is never culled while it holds a hit that brute
 * force would report (thin boxes of axis-aligned floors, ties at equal t). */
#define RS_BOX_SLACK 1.00006103515625f

/* Ask for a node's cache line ahead of its visit (a hint; no effect on results);
 * rs_prefetchw asks for a line that is about to be written (in a state to write). */
#if defined(__GNUC__) || defined(__clang__)
#  define rs_prefetch(p) __builtin_prefetch((p), 0, 3)
#  define rs_prefetchw(p) __builtin_prefetch((p), 1, 3)
#else
#  define rs_prefetch(p) ((void)0)
#  define rs_prefetchw(p) ((void)0)
#endif

/* A pointer no other pointer of the function reaches (C99 restrict, in the spelling
 * every compiler of ours knows), so that a loop storing through several vectorises
 * without run-time overlap checks. */
#if defined(_MSC_VER)
#  define RS_RESTRICT __restrict
#else
#  define RS_RESTRICT __restrict__
#endif

RS_INLINE float rs_minf(float a, float b) { return a < b ? a : b; }
RS_INLINE float rs_maxf(float a, float b) { return a > b ? a : b; }
RS_INLINE const char *rs_isa_name(void) { return RS_ISA_NAME; }

/* ------------------------------------------------------------------------ */
/* 4-lane vocabulary                                                         */
/* ------------------------------------------------------------------------ */
#if RS_SSE
typedef __m128 rs_v4f;
typedef __m128 rs_v4m;   /* lane mask: all ones or all zeros per lane */
typedef __m128i rs_v4i;

RS_INLINE rs_v4f rs_load(const float *p) { return _mm_load_ps(p); }
RS_INLINE void rs_store(float *p, rs_v4f a) { _mm_store_ps(p, a); }
RS_INLINE rs_v4f rs_set1(float a) { return _mm_set1_ps(a); }
RS_INLINE rs_v4f rs_set4(float a, float b, float c, float d) { return _mm_setr_ps(a, b, c, d); }
RS_INLINE rs_v4f rs_add(rs_v4f a, rs_v4f b) { return _mm_add_ps(a, b); }
RS_INLINE rs_v4f rs_sub(rs_v4f a, rs_v4f b) { return _mm_sub_ps(a, b); }
RS_INLINE rs_v4f rs_mul(rs_v4f a, rs_v4f b) { return _mm_mul_ps(a, b); }
RS_INLINE rs_v4f rs_div(rs_v4f a, rs_v4f b) { return _mm_div_ps(a, b); }
RS_INLINE rs_v4f rs_min(rs_v4f a, rs_v4f b) { return _mm_min_ps(a, b); }
RS_INLINE rs_v4f rs_max(rs_v4f a, rs_v4f b) { return _mm_max_ps(a, b); }
RS_INLINE rs_v4m rs_lt(rs_v4f a, rs_v4f b) { return _mm_cmplt_ps(a, b); }
RS_INLINE rs_v4m rs_le(rs_v4f a, rs_v4f b) { return _mm_cmple_ps(a, b); }
RS_INLINE rs_v4m rs_gt(rs_v4f a, rs_v4f b) { return _mm_cmpgt_ps(a, b); }
RS_INLINE rs_v4m rs_ge(rs_v4f a, rs_v4f b) { return _mm_cmpge_ps(a, b); }
RS_INLINE rs_v4m rs_eq(rs_v4f a, rs_v4f b) { return _mm_cmpeq_ps(a, b); }
RS_INLINE rs_v4m rs_ne(rs_v4f a, rs_v4f b) { return _mm_cmpneq_ps(a, b); }
RS_INLINE rs_v4m rs_and(rs_v4m a, rs_v4m b) { return _mm_and_ps(a, b); }
RS_INLINE rs_v4m rs_or(rs_v4m a, rs_v4m b) { return _mm_or_ps(a, b); }
/* mask ? a : b, lane by lane */
RS_INLINE rs_v4f rs_blend(rs_v4m m, rs_v4f a, rs_v4f b)
{ return _mm_or_ps(_mm_and_ps(m, a), _mm_andnot_ps(m, b)); }
RS_INLINE int rs_movemask(rs_v4m m) { return _mm_movemask_ps(m); }
/* Per lane, the bits of `lo` where `neg` is clear and of `hi` where it is set
 * (and the other one in *other): the near and far planes of a box axis. */
RS_INLINE rs_v4f rs_pick(rs_v4m neg, rs_v4f lo, rs_v4f hi, rs_v4f *other)
{
    rs_v4f x = _mm_xor_ps(lo, hi);
    rs_v4f near = _mm_xor_ps(lo, _mm_and_ps(neg, x));
    *other = _mm_xor_ps(near, x);
    return near;
}
/* Lanes whose sign bit is set. */
RS_INLINE rs_v4m rs_signmask(rs_v4f a)
{ return _mm_castsi128_ps(_mm_srai_epi32(_mm_castps_si128(a), 31)); }
/* Subnormal lanes become a zero of the same sign. */
RS_INLINE rs_v4f rs_flush_subnormal(rs_v4f a)
{
    rs_v4f sign = _mm_and_ps(a, _mm_set1_ps(-0.0f));
    rs_v4m tiny = _mm_cmplt_ps(_mm_andnot_ps(_mm_set1_ps(-0.0f), a), _mm_set1_ps(FLT_MIN));
    return rs_blend(tiny, sign, a);
}
RS_INLINE rs_v4m rs_mask_from_bits(int bits)
{
    const __m128i lanes = _mm_setr_epi32(1, 2, 4, 8);
    __m128i b = _mm_and_si128(_mm_set1_epi32(bits), lanes);
    return _mm_castsi128_ps(_mm_cmpeq_epi32(b, lanes));
}
RS_INLINE rs_v4i rs_loadi(const int32_t *p) { return _mm_load_si128((const __m128i *)p); }
RS_INLINE void rs_storei(int32_t *p, rs_v4i a) { _mm_store_si128((__m128i *)p, a); }
RS_INLINE rs_v4i rs_set1i(int32_t a) { return _mm_set1_epi32(a); }
RS_INLINE rs_v4m rs_lti(rs_v4i a, rs_v4i b) { return _mm_castsi128_ps(_mm_cmplt_epi32(a, b)); }
RS_INLINE rs_v4i rs_blendi(rs_v4m m, rs_v4i a, rs_v4i b)
{
    __m128i mi = _mm_castps_si128(m);
    return _mm_or_si128(_mm_and_si128(mi, a), _mm_andnot_si128(mi, b));
}
#else
typedef struct { float f[4]; } rs_v4f;
typedef struct { int32_t m[4]; } rs_v4m;
typedef struct { int32_t i[4]; } rs_v4i;

#define RS_LANES(k) for (int k = 0; k < 4; ++k)
#define RS_FOP(name, expr) \
    RS_INLINE rs_v4f name(rs_v4f a, rs_v4f b) { rs_v4f r; RS_LANES(k) r.f[k] = (expr); return r; }
#define RS_CMP(name, expr) \
    RS_INLINE rs_v4m name(rs_v4f a, rs_v4f b) { rs_v4m r; RS_LANES(k) r.m[k] = (expr) ? -1 : 0; return r; }

RS_INLINE rs_v4f rs_load(const float *p) { rs_v4f r; memcpy(r.f, p, sizeof r.f); return r; }
RS_INLINE void rs_store(float *p, rs_v4f a) { memcpy(p, a.f, sizeof a.f); }
RS_INLINE rs_v4f rs_set1(float a) { rs_v4f r; RS_LANES(k) r.f[k] = a; return r; }
RS_INLINE rs_v4f rs_set4(float a, float b, float c, float d)
{ rs_v4f r; r.f[0] = a; r.f[1] = b; r.f[2] = c; r.f[3] = d; return r; }
RS_FOP(rs_add, a.f[k] + b.f[k])
RS_FOP(rs_sub, a.f[k] - b.f[k])
RS_FOP(rs_mul, a.f[k] * b.f[k])
RS_FOP(rs_div, a.f[k] / b.f[k])
RS_FOP(rs_min, rs_minf(a.f[k], b.f[k]))
RS_FOP(rs_max, rs_maxf(a.f[k], b.f[k]))
RS_CMP(rs_lt, a.f[k] < b.f[k])
RS_CMP(rs_le, a.f[k] <= b.f[k])
RS_CMP(rs_gt, a.f[k] > b.f[k])
RS_CMP(rs_ge, a.f[k] >= b.f[k])
RS_CMP(rs_eq, a.f[k] == b.f[k])
RS_CMP(rs_ne, a.f[k] != b.f[k])
RS_INLINE rs_v4m rs_and(rs_v4m a, rs_v4m b) { rs_v4m r; RS_LANES(k) r.m[k] = a.m[k] & b.m[k]; return r; }
RS_INLINE rs_v4m rs_or(rs_v4m a, rs_v4m b) { rs_v4m r; RS_LANES(k) r.m[k] = a.m[k] | b.m[k]; return r; }
RS_INLINE rs_v4f rs_blend(rs_v4m m, rs_v4f a, rs_v4f b)
{ rs_v4f r; RS_LANES(k) r.f[k] = m.m[k] ? a.f[k] : b.f[k]; return r; }
RS_INLINE int rs_movemask(rs_v4m m)
{ int bits = 0; RS_LANES(k) bits |= (m.m[k] ? 1 : 0) << k; return bits; }
RS_INLINE rs_v4f rs_pick(rs_v4m neg, rs_v4f lo, rs_v4f hi, rs_v4f *other)
{
    rs_v4f near;
    RS_LANES(k) { near.f[k] = neg.m[k] ? hi.f[k] : lo.f[k];
                  other->f[k] = neg.m[k] ? lo.f[k] : hi.f[k]; }
    return near;
}
RS_INLINE rs_v4m rs_signmask(rs_v4f a)
{ rs_v4m r; RS_LANES(k) r.m[k] = signbit(a.f[k]) ? -1 : 0; return r; }
RS_INLINE rs_v4f rs_flush_subnormal(rs_v4f a)
{ rs_v4f r; RS_LANES(k) r.f[k] = fabsf(a.f[k]) < FLT_MIN ? copysignf(0.0f, a.f[k]) : a.f[k]; return r; }
RS_INLINE rs_v4m rs_mask_from_bits(int bits)
{ rs_v4m r; RS_LANES(k) r.m[k] = (bits >> k) & 1 ? -1 : 0; return r; }
RS_INLINE rs_v4i rs_loadi(const int32_t *p) { rs_v4i r; memcpy(r.i, p, sizeof r.i); return r; }
RS_INLINE void rs_storei(int32_t *p, rs_v4i a) { memcpy(p, a.i, sizeof a.i); }
RS_INLINE rs_v4i rs_set1i(int32_t a) { rs_v4i r; RS_LANES(k) r.i[k] = a; return r; }
RS_INLINE rs_v4m rs_lti(rs_v4i a, rs_v4i b) { rs_v4m r; RS_LANES(k) r.m[k] = a.i[k] < b.i[k] ? -1 : 0; return r; }
RS_INLINE rs_v4i rs_blendi(rs_v4m m, rs_v4i a, rs_v4i b)
{ rs_v4i r; RS_LANES(k) r.i[k] = m.m[k] ? a.i[k] : b.i[k]; return r; }

#undef RS_FOP
#undef RS_CMP
#endif

/* Lanes [i, i+4) that are still active (tmin < t), as a 4-bit mask. */
RS_INLINE int rs_active4(const rs_rays *r, int i)
{
    return rs_movemask(rs_lt(rs_load(r->tmin + i), rs_load(r->t + i)));
}

/* ------------------------------------------------------------------------ */
/* Ray-box slab tests                                                        */
/* ------------------------------------------------------------------------ */

/* Slab tests choose each axis's near and far plane by the sign of 1/d (the
 * near plane is lo for a positive direction, hi for a negative one) and then
 * take tn = max(t_near, tn), tf = min(t_far, tf).  A NaN slab distance, which
 * only arises as 0 * inf (an origin exactly on a box plane with a zero or
 * subnormal direction component: the ray lies in the plane), is the first
 * operand of that max/min and so constrains nothing: the test stays
 * conservative, never culling a box the ray touches. */

/* Does active ray i hit the box before its current t?  (scalar) */
RS_INLINE int rs_box1(const rs_rays *r, int i, const rs_node *n)
{
    float tn = r->tmin[i], tf = r->t[i];
    for (int a = 0; a < 3; ++a) {
        float inv = r->inv[a][i], o = r->o[a][i];
        int neg = signbit(inv) != 0;
        float t_near = ((neg ? n->hi[a] : n->lo[a]) - o) * inv;
        float t_far = ((neg ? n->lo[a] : n->hi[a]) - o) * inv;
        tn = rs_maxf(t_near, tn);
        tf = rs_minf(t_far, tf);
    }
    return tn <= tf * RS_BOX_SLACK;
}

/* The same test for the 4 lanes [i, i+4); i is a multiple of 4.  Returns a
 * 4-bit lane mask.  Inactive lanes never hit (tmin = +inf or t = -inf). */
RS_INLINE int rs_box4(const rs_rays *r, int i, const rs_node *n)
{
    rs_v4f tn = rs_load(r->tmin + i), tf = rs_load(r->t + i);
    for (int a = 0; a < 3; ++a) {
        rs_v4f o = rs_load(r->o[a] + i), inv = rs_load(r->inv[a] + i);
        rs_v4f far_plane;
        rs_v4f near_plane = rs_pick(rs_signmask(inv), rs_set1(n->lo[a]), rs_set1(n->hi[a]),
                                    &far_plane);
        tn = rs_max(rs_mul(rs_sub(near_plane, o), inv), tn);
        tf = rs_min(rs_mul(rs_sub(far_plane, o), inv), tf);
    }
    return rs_movemask(rs_le(tn, rs_mul(tf, rs_set1(RS_BOX_SLACK))));
}

/* One ray (lane i) against the four child boxes of a 4-wide node: returns the
 * 4-bit mask of children hit and stores where the ray enters each in entry[].
 * Each lane performs exactly rs_box1's operations on that child's box. */
RS_INLINE int rs_node4_hit(const rs_rays *r, int i, const rs_node4 *n, float entry[4])
{
    rs_v4f tn = rs_set1(r->tmin[i]), tf = rs_set1(r->t[i]);
    for (int a = 0; a < 3; ++a) {
        float inv = r->inv[a][i];
        int neg = signbit(inv) != 0;
        rs_v4f o = rs_set1(r->o[a][i]), iv = rs_set1(inv);
        rs_v4f near_plane = rs_load(neg ? n->hi[a] : n->lo[a]);
        rs_v4f far_plane = rs_load(neg ? n->lo[a] : n->hi[a]);
        tn = rs_max(rs_mul(rs_sub(near_plane, o), iv), tn);
        tf = rs_min(rs_mul(rs_sub(far_plane, o), iv), tf);
    }
    rs_store(entry, tn);
    return rs_movemask(rs_le(tn, rs_mul(tf, rs_set1(RS_BOX_SLACK))));
}

/* Interval-arithmetic test of a whole packet (its frustum) against a box:
 * returns 1 when no ray of the packet can hit the box.  Axes on which the
 * direction changes sign (or is zero or infinite) do not cull, as in DynBVH. */
RS_INLINE int rs_ia_miss(const rs_frustum *f, const rs_node *n)
{
    float tn = 0.0f, tf = INFINITY;
    for (int a = 0; a < 3; ++a) {
        float r0 = f->rmin[a], r1 = f->rmax[a];
        if (!((r0 > 0.0f && r1 < INFINITY) || (r1 < 0.0f && r0 > -INFINITY)))
            continue;
        float lo = n->lo[a] - f->omax[a], hi = n->hi[a] - f->omin[a];
        float p0 = lo * r0, p1 = lo * r1, p2 = hi * r0, p3 = hi * r1;
        tn = rs_maxf(rs_minf(rs_minf(p0, p1), rs_minf(p2, p3)), tn);
        tf = rs_minf(rs_maxf(rs_maxf(p0, p1), rs_maxf(p2, p3)), tf);
    }
    return tn > tf * RS_BOX_SLACK;
}

/* ------------------------------------------------------------------------ */
/* Ray-triangle tests (Moller-Trumbore, two-sided)                           */
/* ------------------------------------------------------------------------ */
/* A hit is accepted when det != 0, u >= 0, v >= 0, u + v <= 1, t > tmin and
 * (t < best t, or t == best t and a lower primitive id): the closest hit in
 * the open interval (tmin, tmax), ties to the lower id.  With any_hit the
 * accepted lane's t becomes -inf, which retires the ray. */

RS_INLINE int rs_tri1(const rs_rays *r, int i, const rs_tri *tr, int any_hit)
{
    float dx = r->d[0][i], dy = r->d[1][i], dz = r->d[2][i];
    float px = dy * tr->e2[2] - dz * tr->e2[1];
    float py = dz * tr->e2[0] - dx * tr->e2[2];
    float pz = dx * tr->e2[1] - dy * tr->e2[0];
    float det = tr->e1[0] * px + tr->e1[1] * py + tr->e1[2] * pz;
    float inv = 1.0f / det;
    float sx = r->o[0][i] - tr->v0[0];
    float sy = r->o[1][i] - tr->v0[1];
    float sz = r->o[2][i] - tr->v0[2];
    float u = (sx * px + sy * py + sz * pz) * inv;
    float qx = sy * tr->e1[2] - sz * tr->e1[1];
    float qy = sz * tr->e1[0] - sx * tr->e1[2];
    float qz = sx * tr->e1[1] - sy * tr->e1[0];
    float v = (dx * qx + dy * qy + dz * qz) * inv;
    float t = (tr->e2[0] * qx + tr->e2[1] * qy + tr->e2[2] * qz) * inv;
    float best = r->t[i];
    if (det != 0.0f && u >= 0.0f && v >= 0.0f && u + v <= 1.0f && t > r->tmin[i]
        && (t < best || (t == best && tr->id < r->prim[i]))) {
        r->t[i] = any_hit ? -INFINITY : t;
        r->prim[i] = tr->id;
        r->u[i] = u;
        r->v[i] = v;
        return 1;
    }
    return 0;
}

/* Moller-Trumbore's operations, rs_tri1's in its order, in a lane vocabulary:
 * the prefix P names its operations (P##_add, _sub, _mul, _div, _set1) and T its
 * vector type.  RS_MT_UV declares det, inv, u, v (and px..qz) from the origin
 * o[3] and direction d[3] and the group's rows e1x..e2z, v0x..v0z (in scope);
 * RS_MT_T is then the hit distance.  The SIMD triangle tests share them (rs_tri4
 * below, wide8.h's rs_tri8_hit, stream.h's rs_stream_tri, frustum.h's pair
 * test), so every width performs rs_tri1's operations per lane. */
#define RS_MT_UV(P, T, o, d)                                                               \
    T px = P##_sub(P##_mul((d)[1], e2z), P##_mul((d)[2], e2y));                            \
    T py = P##_sub(P##_mul((d)[2], e2x), P##_mul((d)[0], e2z));                            \
    T pz = P##_sub(P##_mul((d)[0], e2y), P##_mul((d)[1], e2x));                            \
    T det = P##_add(P##_add(P##_mul(e1x, px), P##_mul(e1y, py)), P##_mul(e1z, pz));        \
    T inv = P##_div(P##_set1(1.0f), det);                                                  \
    T sx = P##_sub((o)[0], v0x), sy = P##_sub((o)[1], v0y), sz = P##_sub((o)[2], v0z);     \
    T u = P##_mul(P##_add(P##_add(P##_mul(sx, px), P##_mul(sy, py)), P##_mul(sz, pz)), inv); \
    T qx = P##_sub(P##_mul(sy, e1z), P##_mul(sz, e1y));                                    \
    T qy = P##_sub(P##_mul(sz, e1x), P##_mul(sx, e1z));                                    \
    T qz = P##_sub(P##_mul(sx, e1y), P##_mul(sy, e1x));                                    \
    T v = P##_mul(P##_add(P##_add(P##_mul((d)[0], qx), P##_mul((d)[1], qy)),               \
                          P##_mul((d)[2], qz)), inv)
#define RS_MT_T(P) \
    P##_mul(P##_add(P##_add(P##_mul(e2x, qx), P##_mul(e2y, qy)), P##_mul(e2z, qz)), inv)

/* The same test for lanes [i, i+4); i is a multiple of 4.  Returns the mask
 * of lanes that accepted the hit. */
RS_INLINE int rs_tri4(const rs_rays *r, int i, const rs_tri *tr, int any_hit)
{
    const rs_v4f o[3] = {rs_load(r->o[0] + i), rs_load(r->o[1] + i), rs_load(r->o[2] + i)};
    const rs_v4f d[3] = {rs_load(r->d[0] + i), rs_load(r->d[1] + i), rs_load(r->d[2] + i)};
    rs_v4f e1x = rs_set1(tr->e1[0]), e1y = rs_set1(tr->e1[1]), e1z = rs_set1(tr->e1[2]);
    rs_v4f e2x = rs_set1(tr->e2[0]), e2y = rs_set1(tr->e2[1]), e2z = rs_set1(tr->e2[2]);
    rs_v4f v0x = rs_set1(tr->v0[0]), v0y = rs_set1(tr->v0[1]), v0z = rs_set1(tr->v0[2]);
    RS_MT_UV(rs, rs_v4f, o, d);
    rs_v4f t = RS_MT_T(rs);

    const rs_v4f zero = rs_set1(0.0f), one = rs_set1(1.0f);
    rs_v4f best = rs_load(r->t + i);
    rs_v4i bprim = rs_loadi(r->prim + i), id = rs_set1i(tr->id);
    rs_v4m ok = rs_and(rs_and(rs_ne(det, zero), rs_ge(u, zero)),
                       rs_and(rs_ge(v, zero), rs_le(rs_add(u, v), one)));
    ok = rs_and(ok, rs_gt(t, rs_load(r->tmin + i)));
    ok = rs_and(ok, rs_or(rs_lt(t, best), rs_and(rs_eq(t, best), rs_lti(id, bprim))));
    int bits = rs_movemask(ok);
    if (bits) {
        rs_store(r->t + i, rs_blend(ok, any_hit ? rs_set1(-INFINITY) : t, best));
        rs_storei(r->prim + i, rs_blendi(ok, id, bprim));
        rs_store(r->u + i, rs_blend(ok, u, rs_load(r->u + i)));
        rs_store(r->v + i, rs_blend(ok, v, rs_load(r->v + i)));
    }
    return bits;
}

#endif
