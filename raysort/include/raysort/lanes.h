/* raysort: an RS_SW-lane vocabulary over rays gathered by id.
 *
 * RS_SW is the widest lane count of the ISA a file is compiled for (simd.h's
 * RS_ISA_* macros): 16 on AVX-512 (__m512, __mmask16), 8 on AVX2 (__m256), 4 on
 * SSE2 (simd.h's 4-lane vocabulary) and 1 on the portable scalar build.  Used
 * by the stream traversal (stream.h) and the gather (gather.h); every
 * operation has the operand semantics of simd.h's 4-lane one, so a kernel
 * written on it performs the same IEEE operations per lane on every ISA.
 */
#ifndef RAYSORT_LANES_H
#define RAYSORT_LANES_H

#include "simd.h"

/* Set bits of a lane mask, and the lowest one's index (bits != 0). */
RS_INLINE int rs_popcount(int bits)
{
#if defined(__GNUC__) || defined(__clang__)
    return __builtin_popcount((unsigned)bits);
#else
    int n = 0;
    for (; bits; bits &= bits - 1) ++n;
    return n;
#endif
}
RS_INLINE int rs_lowest(int bits)
{
#if defined(__GNUC__) || defined(__clang__)
    return __builtin_ctz((unsigned)bits);
#else
    int k = 0;
    while (!(bits >> k & 1)) ++k;
    return k;
#endif
}

/* ------------------------------------------------------------------------ */
/* RS_SW-lane vocabulary over rays gathered by id                           */
/* ------------------------------------------------------------------------ */
/* sw_gather loads one row of rs_rays for the RS_SW ids of a group, sw_loadu
 * RS_SW consecutive floats from anywhere (unaligned); the other
 * operations are those of simd.h's 4-lane vocabulary, with the same operand
 * semantics (min/max return the second operand when either is NaN; != is true
 * for NaN). */
#if RS_ISA_AVX512
#  define RS_SW 16
typedef __m512 rs_swf;
typedef __mmask16 rs_swm;
typedef __m512i rs_swi;
RS_INLINE rs_swi sw_ids(const int32_t *p) { return _mm512_loadu_si512((const void *)p); }
RS_INLINE rs_swf sw_gather(const float *base, rs_swi id) { return _mm512_i32gather_ps(id, base, 4); }
RS_INLINE rs_swf sw_loadu(const float *p) { return _mm512_loadu_ps(p); }
RS_INLINE rs_swi sw_gatheri(const int32_t *base, rs_swi id)
{ return _mm512_i32gather_epi32(id, base, 4); }
RS_INLINE rs_swf sw_set1(float a) { return _mm512_set1_ps(a); }
RS_INLINE rs_swi sw_set1i(int32_t a) { return _mm512_set1_epi32(a); }
RS_INLINE int sw_eqi_bits(rs_swi a, rs_swi b) { return (int)_mm512_cmpeq_epi32_mask(a, b); }
RS_INLINE rs_swf sw_add(rs_swf a, rs_swf b) { return _mm512_add_ps(a, b); }
RS_INLINE rs_swf sw_sub(rs_swf a, rs_swf b) { return _mm512_sub_ps(a, b); }
RS_INLINE rs_swf sw_mul(rs_swf a, rs_swf b) { return _mm512_mul_ps(a, b); }
RS_INLINE rs_swf sw_div(rs_swf a, rs_swf b) { return _mm512_div_ps(a, b); }
RS_INLINE rs_swf sw_min(rs_swf a, rs_swf b) { return _mm512_min_ps(a, b); }
RS_INLINE rs_swf sw_max(rs_swf a, rs_swf b) { return _mm512_max_ps(a, b); }
RS_INLINE rs_swm sw_lt(rs_swf a, rs_swf b) { return _mm512_cmp_ps_mask(a, b, _CMP_LT_OQ); }
RS_INLINE rs_swm sw_le(rs_swf a, rs_swf b) { return _mm512_cmp_ps_mask(a, b, _CMP_LE_OQ); }
RS_INLINE rs_swm sw_gt(rs_swf a, rs_swf b) { return _mm512_cmp_ps_mask(a, b, _CMP_GT_OQ); }
RS_INLINE rs_swm sw_ge(rs_swf a, rs_swf b) { return _mm512_cmp_ps_mask(a, b, _CMP_GE_OQ); }
RS_INLINE rs_swm sw_eq(rs_swf a, rs_swf b) { return _mm512_cmp_ps_mask(a, b, _CMP_EQ_OQ); }
RS_INLINE rs_swm sw_ne(rs_swf a, rs_swf b) { return _mm512_cmp_ps_mask(a, b, _CMP_NEQ_UQ); }
RS_INLINE rs_swm sw_lti(rs_swi a, rs_swi b) { return _mm512_cmplt_epi32_mask(a, b); }
RS_INLINE rs_swm sw_and(rs_swm a, rs_swm b) { return a & b; }
RS_INLINE rs_swm sw_or(rs_swm a, rs_swm b) { return a | b; }
RS_INLINE int sw_bits(rs_swm m) { return (int)m; }
RS_INLINE rs_swm sw_from_bits(int bits) { return (rs_swm)bits; }
RS_INLINE rs_swm sw_sign(rs_swf a) { return _mm512_movepi32_mask(_mm512_castps_si512(a)); }
RS_INLINE rs_swf sw_blend(rs_swm m, rs_swf a, rs_swf b) { return _mm512_mask_blend_ps(m, b, a); }
RS_INLINE rs_swi sw_blendi(rs_swm m, rs_swi a, rs_swi b) { return _mm512_mask_blend_epi32(m, b, a); }
RS_INLINE void sw_store(float *p, rs_swf a) { _mm512_storeu_ps(p, a); }
RS_INLINE void sw_storei(int32_t *p, rs_swi a) { _mm512_storeu_si512((void *)p, a); }
/* Append the ids of the lanes in `bits` to out[*n] (out has RS_SW slots of slack). */
RS_INLINE void sw_append(int32_t *out, int *n, rs_swi id, int bits)
{
    _mm512_storeu_si512((void *)(out + *n), _mm512_maskz_compress_epi32((__mmask16)bits, id));
    *n += rs_popcount(bits);
}
#elif RS_ISA_AVX2
#  define RS_SW 8
typedef __m256 rs_swf;
typedef __m256 rs_swm;
typedef __m256i rs_swi;
RS_INLINE rs_swi sw_ids(const int32_t *p) { return _mm256_loadu_si256((const __m256i *)p); }
RS_INLINE rs_swf sw_gather(const float *base, rs_swi id) { return _mm256_i32gather_ps(base, id, 4); }
/* The same lanes as sw_gather by eight scalar loads: on Zen 3 the stream traversal,
 * which gathers seven rows per group of rays at every node, ran 8-15 % faster so
 * (BENCHMARKS.md §13); AVX-512's gathers are kept. */
RS_INLINE rs_swf sw_gather_loads(const float *base, rs_swi id)
{
    int32_t i[8];
    _mm256_storeu_si256((__m256i *)i, id);
    return _mm256_setr_ps(base[i[0]], base[i[1]], base[i[2]], base[i[3]], base[i[4]], base[i[5]],
                          base[i[6]], base[i[7]]);
}
RS_INLINE rs_swf sw_loadu(const float *p) { return _mm256_loadu_ps(p); }
RS_INLINE rs_swi sw_gatheri(const int32_t *base, rs_swi id)
{ return _mm256_i32gather_epi32((const int *)base, id, 4); }
RS_INLINE rs_swf sw_set1(float a) { return _mm256_set1_ps(a); }
RS_INLINE rs_swi sw_set1i(int32_t a) { return _mm256_set1_epi32(a); }
RS_INLINE int sw_eqi_bits(rs_swi a, rs_swi b)
{ return _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(a, b))); }
RS_INLINE rs_swf sw_add(rs_swf a, rs_swf b) { return _mm256_add_ps(a, b); }
RS_INLINE rs_swf sw_sub(rs_swf a, rs_swf b) { return _mm256_sub_ps(a, b); }
RS_INLINE rs_swf sw_mul(rs_swf a, rs_swf b) { return _mm256_mul_ps(a, b); }
RS_INLINE rs_swf sw_div(rs_swf a, rs_swf b) { return _mm256_div_ps(a, b); }
RS_INLINE rs_swf sw_min(rs_swf a, rs_swf b) { return _mm256_min_ps(a, b); }
RS_INLINE rs_swf sw_max(rs_swf a, rs_swf b) { return _mm256_max_ps(a, b); }
RS_INLINE rs_swm sw_lt(rs_swf a, rs_swf b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
RS_INLINE rs_swm sw_le(rs_swf a, rs_swf b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
RS_INLINE rs_swm sw_gt(rs_swf a, rs_swf b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
RS_INLINE rs_swm sw_ge(rs_swf a, rs_swf b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
RS_INLINE rs_swm sw_eq(rs_swf a, rs_swf b) { return _mm256_cmp_ps(a, b, _CMP_EQ_OQ); }
RS_INLINE rs_swm sw_ne(rs_swf a, rs_swf b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
RS_INLINE rs_swm sw_lti(rs_swi a, rs_swi b) { return _mm256_castsi256_ps(_mm256_cmpgt_epi32(b, a)); }
RS_INLINE rs_swm sw_and(rs_swm a, rs_swm b) { return _mm256_and_ps(a, b); }
RS_INLINE rs_swm sw_or(rs_swm a, rs_swm b) { return _mm256_or_ps(a, b); }
RS_INLINE int sw_bits(rs_swm m) { return _mm256_movemask_ps(m); }
RS_INLINE rs_swm sw_from_bits(int bits)
{
    const __m256i lanes = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    __m256i b = _mm256_and_si256(_mm256_set1_epi32(bits), lanes);
    return _mm256_castsi256_ps(_mm256_cmpeq_epi32(b, lanes));
}
RS_INLINE rs_swm sw_sign(rs_swf a)
{ return _mm256_castsi256_ps(_mm256_srai_epi32(_mm256_castps_si256(a), 31)); }
RS_INLINE rs_swf sw_blend(rs_swm m, rs_swf a, rs_swf b) { return _mm256_blendv_ps(b, a, m); }
RS_INLINE rs_swi sw_blendi(rs_swm m, rs_swi a, rs_swi b)
{
    return _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(b), _mm256_castsi256_ps(a), m));
}
RS_INLINE void sw_store(float *p, rs_swf a) { _mm256_storeu_ps(p, a); }
RS_INLINE void sw_storei(int32_t *p, rs_swi a) { _mm256_storeu_si256((__m256i *)p, a); }
#else
/* SSE2 (4 lanes, simd.h's vocabulary) and the scalar build (1 lane). */
#  if RS_SSE
#    define RS_SW 4
typedef rs_v4f rs_swf;
typedef rs_v4m rs_swm;
#  else
#    define RS_SW 1
typedef float rs_swf;
typedef int rs_swm;
#  endif
typedef struct { int32_t i[RS_SW]; } rs_swi;
RS_INLINE rs_swi sw_ids(const int32_t *p) { rs_swi r; memcpy(r.i, p, sizeof r.i); return r; }
RS_INLINE rs_swi sw_gatheri(const int32_t *base, rs_swi id)
{ rs_swi r; for (int k = 0; k < RS_SW; ++k) r.i[k] = base[id.i[k]]; return r; }
RS_INLINE rs_swi sw_set1i(int32_t a) { rs_swi r; for (int k = 0; k < RS_SW; ++k) r.i[k] = a; return r; }
RS_INLINE int sw_eqi_bits(rs_swi a, rs_swi b)
{ int bits = 0; for (int k = 0; k < RS_SW; ++k) bits |= (a.i[k] == b.i[k]) << k; return bits; }
RS_INLINE void sw_storei(int32_t *p, rs_swi a) { memcpy(p, a.i, sizeof a.i); }
#  if RS_SSE
RS_INLINE rs_swf sw_gather(const float *base, rs_swi id)
{ return rs_set4(base[id.i[0]], base[id.i[1]], base[id.i[2]], base[id.i[3]]); }
RS_INLINE rs_swf sw_loadu(const float *p) { return _mm_loadu_ps(p); }
#    define sw_set1 rs_set1
#    define sw_add rs_add
#    define sw_sub rs_sub
#    define sw_mul rs_mul
#    define sw_div rs_div
#    define sw_min rs_min
#    define sw_max rs_max
#    define sw_lt rs_lt
#    define sw_le rs_le
#    define sw_gt rs_gt
#    define sw_ge rs_ge
#    define sw_eq rs_eq
#    define sw_ne rs_ne
#    define sw_and rs_and
#    define sw_or rs_or
#    define sw_bits rs_movemask
#    define sw_from_bits rs_mask_from_bits
#    define sw_sign rs_signmask
#    define sw_blend rs_blend
#    define sw_store rs_store
RS_INLINE rs_swm sw_lti(rs_swi a, rs_swi b)
{ return rs_mask_from_bits((a.i[0] < b.i[0]) | (a.i[1] < b.i[1]) << 1 | (a.i[2] < b.i[2]) << 2
                           | (a.i[3] < b.i[3]) << 3); }
RS_INLINE rs_swi sw_blendi(rs_swm m, rs_swi a, rs_swi b)
{
    int bits = rs_movemask(m);
    rs_swi r;
    for (int k = 0; k < 4; ++k) r.i[k] = (bits >> k) & 1 ? a.i[k] : b.i[k];
    return r;
}
#  else
RS_INLINE rs_swf sw_gather(const float *base, rs_swi id) { return base[id.i[0]]; }
RS_INLINE rs_swf sw_loadu(const float *p) { return *p; }
RS_INLINE rs_swf sw_set1(float a) { return a; }
RS_INLINE rs_swf sw_add(rs_swf a, rs_swf b) { return a + b; }
RS_INLINE rs_swf sw_sub(rs_swf a, rs_swf b) { return a - b; }
RS_INLINE rs_swf sw_mul(rs_swf a, rs_swf b) { return a * b; }
RS_INLINE rs_swf sw_div(rs_swf a, rs_swf b) { return a / b; }
RS_INLINE rs_swf sw_min(rs_swf a, rs_swf b) { return rs_minf(a, b); }
RS_INLINE rs_swf sw_max(rs_swf a, rs_swf b) { return rs_maxf(a, b); }
RS_INLINE rs_swm sw_lt(rs_swf a, rs_swf b) { return a < b; }
RS_INLINE rs_swm sw_le(rs_swf a, rs_swf b) { return a <= b; }
RS_INLINE rs_swm sw_gt(rs_swf a, rs_swf b) { return a > b; }
RS_INLINE rs_swm sw_ge(rs_swf a, rs_swf b) { return a >= b; }
RS_INLINE rs_swm sw_eq(rs_swf a, rs_swf b) { return a == b; }
RS_INLINE rs_swm sw_ne(rs_swf a, rs_swf b) { return a != b; }
RS_INLINE rs_swm sw_and(rs_swm a, rs_swm b) { return a & b; }
RS_INLINE rs_swm sw_or(rs_swm a, rs_swm b) { return a | b; }
RS_INLINE int sw_bits(rs_swm m) { return m; }
RS_INLINE rs_swm sw_from_bits(int bits) { return bits & 1; }
RS_INLINE rs_swm sw_sign(rs_swf a) { return signbit(a) != 0; }
RS_INLINE rs_swf sw_blend(rs_swm m, rs_swf a, rs_swf b) { return m ? a : b; }
RS_INLINE void sw_store(float *p, rs_swf a) { *p = a; }
RS_INLINE rs_swm sw_lti(rs_swi a, rs_swi b) { return a.i[0] < b.i[0]; }
RS_INLINE rs_swi sw_blendi(rs_swm m, rs_swi a, rs_swi b) { return m ? a : b; }
#  endif
#endif

#if !RS_ISA_AVX2 || RS_ISA_AVX512
#  define sw_gather_loads sw_gather
#endif

#if !RS_ISA_AVX512
/* Append the ids of the lanes in `bits` to out[*n], without branches (out has
 * RS_SW slots of slack). */
RS_INLINE void sw_append(int32_t *out, int *n, rs_swi id, int bits)
{
    int32_t lane[RS_SW];
    int m = *n;
    sw_storei(lane, id);
    for (int k = 0; k < RS_SW; ++k) {
        out[m] = lane[k];
        m += (bits >> k) & 1;
    }
    *n = m;
}
#endif

#endif
