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
 * RS_SW consecutive floats from anywhere (unaligned), sw_rows8 the records of
 * the group's ids (eight consecutive floats at base + stride * id, out[c]
 * holding float c of every lane: a transpose), sw_asi reads a float vector's
 * bits as int32 lanes; the other
 * operations are those of simd.h's 4-lane vocabulary, with the same operand
 * semantics (min/max return the second operand when either is NaN; != is true
 * for NaN). */
/* The first two steps of an 8x8 transpose of eight rows r[0..7] (8 floats in each
 * 256-bit half: pfx _mm256, or _mm512 for two at once), through t, into s: within
 * each 128-bit block, s[c] then holds float c of rows 0-3 and s[c + 4] of rows 4-7
 * (floats c + 4 in the block above); sw_rows8 finishes it across the blocks. */
#define RS_TRANSPOSE8_IN_LANES(pfx, r, t, s)                                               \
    do {                                                                                \
        for (int k_ = 0; k_ < 8; k_ += 2) {                                             \
            t[k_] = pfx##_unpacklo_ps(r[k_], r[k_ + 1]);                                \
            t[k_ + 1] = pfx##_unpackhi_ps(r[k_], r[k_ + 1]);                            \
        }                                                                               \
        for (int k_ = 0; k_ < 8; k_ += 4) {                                             \
            s[k_] = pfx##_shuffle_ps(t[k_], t[k_ + 2], _MM_SHUFFLE(1, 0, 1, 0));        \
            s[k_ + 1] = pfx##_shuffle_ps(t[k_], t[k_ + 2], _MM_SHUFFLE(3, 2, 3, 2));    \
            s[k_ + 2] = pfx##_shuffle_ps(t[k_ + 1], t[k_ + 3], _MM_SHUFFLE(1, 0, 1, 0)); \
            s[k_ + 3] = pfx##_shuffle_ps(t[k_ + 1], t[k_ + 3], _MM_SHUFFLE(3, 2, 3, 2)); \
        }                                                                               \
    } while (0)

#if RS_ISA_AVX512
#  define RS_SW 16
typedef __m512 rs_swf;
typedef __mmask16 rs_swm;
typedef __m512i rs_swi;
RS_INLINE rs_swi sw_ids(const int32_t *p) { return _mm512_loadu_si512((const void *)p); }
/* Sixteen scalar loads, not vgatherdps (as AVX2's, below): on Zen 5 the gather of
 * Sibenik's 65,536 nah-sorted diffuse rays took 0.85x the time (BENCHMARKS.md §9). */
RS_INLINE rs_swf sw_gather(const float *base, rs_swi id)
{
    int32_t i[16];
    _mm512_storeu_si512((void *)i, id);
    __m256 a = _mm256_setr_ps(base[i[0]], base[i[1]], base[i[2]], base[i[3]], base[i[4]],
                              base[i[5]], base[i[6]], base[i[7]]);
    __m256 b = _mm256_setr_ps(base[i[8]], base[i[9]], base[i[10]], base[i[11]], base[i[12]],
                              base[i[13]], base[i[14]], base[i[15]]);
    return _mm512_insertf32x8(_mm512_castps256_ps512(a), b, 1);
}
RS_INLINE rs_swf sw_loadu(const float *p) { return _mm512_loadu_ps(p); }
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
RS_INLINE rs_swi sw_asi(rs_swf a) { return _mm512_castps_si512(a); }
/* sw_rows8: sixteen 8-float loads and a transpose, not eight 16-lane gathers: on
 * Zen 5, stream traced first-bounce diffuse rays 1.17-1.21x as fast and lambert
 * shaded in 0.86x the time; on a Sapphire Rapids Xeon, stream 0.99x and lambert
 * 1.025x the time (BENCHMARKS.md §8, §9). */
/* the last step of sw_rows8's transpose: lanes 0-3 and 8-11 (rs_rows8_lo), or
 * 4-7 and 12-15, of two vectors, a block of four from each in turn */
static const int32_t rs_rows8_lo[16] = {0, 1, 2, 3, 16, 17, 18, 19, 8, 9, 10, 11, 24, 25, 26, 27};
static const int32_t rs_rows8_hi[16] = {4, 5, 6, 7, 20, 21, 22, 23, 12, 13, 14, 15, 28, 29, 30, 31};
RS_INLINE void sw_rows8(const float *base, int stride, rs_swi id, rs_swf out[8])
{
    int32_t i[16];
    __m512 r[8], t[8], s[8];
    _mm512_storeu_si512((void *)i, id);
    for (int k = 0; k < 8; ++k)         /* record k in lanes 0-7, record k + 8 in 8-15 */
        r[k] = _mm512_insertf32x8(
            _mm512_castps256_ps512(_mm256_loadu_ps(base + (size_t)stride * i[k])),
            _mm256_loadu_ps(base + (size_t)stride * i[k + 8]), 1);
    RS_TRANSPOSE8_IN_LANES(_mm512, r, t, s);   /* the 8x8 transpose of each half */
    const __m512i lo = _mm512_loadu_si512((const void *)rs_rows8_lo);
    const __m512i hi = _mm512_loadu_si512((const void *)rs_rows8_hi);
    for (int c = 0; c < 4; ++c) {
        out[c] = _mm512_permutex2var_ps(s[c], lo, s[c + 4]);
        out[c + 4] = _mm512_permutex2var_ps(s[c], hi, s[c + 4]);
    }
}
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
/* Eight scalar loads, not vgatherdps: on Zen 3 the gather of 65,536 sorted rays
 * (gather.h) took 0.45 ms with the gather instruction and 0.36 ms with these,
 * caches warm (the same values: a load is a load). */
RS_INLINE rs_swf sw_gather(const float *base, rs_swi id)
{
    int32_t i[8];
    _mm256_storeu_si256((__m256i *)i, id);
    return _mm256_setr_ps(base[i[0]], base[i[1]], base[i[2]], base[i[3]], base[i[4]],
                          base[i[5]], base[i[6]], base[i[7]]);
}
RS_INLINE rs_swf sw_loadu(const float *p) { return _mm256_loadu_ps(p); }
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
RS_INLINE rs_swi sw_asi(rs_swf a) { return _mm256_castps_si256(a); }
RS_INLINE void sw_rows8(const float *base, int stride, rs_swi id, rs_swf out[8])
{
    int32_t i[8];
    __m256 r[8], t[8], s[8];
    _mm256_storeu_si256((__m256i *)i, id);
    for (int k = 0; k < 8; ++k)
        r[k] = _mm256_loadu_ps(base + (size_t)stride * i[k]);
    RS_TRANSPOSE8_IN_LANES(_mm256, r, t, s);   /* an 8x8 transpose */
    for (int c = 0; c < 4; ++c) {
        out[c] = _mm256_permute2f128_ps(s[c], s[c + 4], 0x20);
        out[c + 4] = _mm256_permute2f128_ps(s[c], s[c + 4], 0x31);
    }
}
/* rs_compress8[bits]: the lanes set in the 8-bit mask `bits`, lowest first, one
 * per 4-bit digit (the lowest digit is the first lane kept); entry m is
 * sum over the j-th set bit k of m of k << 4j. */
static const uint32_t rs_compress8[256] = {
    0x00000000, 0x00000000, 0x00000001, 0x00000010, 0x00000002, 0x00000020,
    0x00000021, 0x00000210, 0x00000003, 0x00000030, 0x00000031, 0x00000310,
    0x00000032, 0x00000320, 0x00000321, 0x00003210, 0x00000004, 0x00000040,
    0x00000041, 0x00000410, 0x00000042, 0x00000420, 0x00000421, 0x00004210,
    0x00000043, 0x00000430, 0x00000431, 0x00004310, 0x00000432, 0x00004320,
    0x00004321, 0x00043210, 0x00000005, 0x00000050, 0x00000051, 0x00000510,
    0x00000052, 0x00000520, 0x00000521, 0x00005210, 0x00000053, 0x00000530,
    0x00000531, 0x00005310, 0x00000532, 0x00005320, 0x00005321, 0x00053210,
    0x00000054, 0x00000540, 0x00000541, 0x00005410, 0x00000542, 0x00005420,
    0x00005421, 0x00054210, 0x00000543, 0x00005430, 0x00005431, 0x00054310,
    0x00005432, 0x00054320, 0x00054321, 0x00543210, 0x00000006, 0x00000060,
    0x00000061, 0x00000610, 0x00000062, 0x00000620, 0x00000621, 0x00006210,
    0x00000063, 0x00000630, 0x00000631, 0x00006310, 0x00000632, 0x00006320,
    0x00006321, 0x00063210, 0x00000064, 0x00000640, 0x00000641, 0x00006410,
    0x00000642, 0x00006420, 0x00006421, 0x00064210, 0x00000643, 0x00006430,
    0x00006431, 0x00064310, 0x00006432, 0x00064320, 0x00064321, 0x00643210,
    0x00000065, 0x00000650, 0x00000651, 0x00006510, 0x00000652, 0x00006520,
    0x00006521, 0x00065210, 0x00000653, 0x00006530, 0x00006531, 0x00065310,
    0x00006532, 0x00065320, 0x00065321, 0x00653210, 0x00000654, 0x00006540,
    0x00006541, 0x00065410, 0x00006542, 0x00065420, 0x00065421, 0x00654210,
    0x00006543, 0x00065430, 0x00065431, 0x00654310, 0x00065432, 0x00654320,
    0x00654321, 0x06543210, 0x00000007, 0x00000070, 0x00000071, 0x00000710,
    0x00000072, 0x00000720, 0x00000721, 0x00007210, 0x00000073, 0x00000730,
    0x00000731, 0x00007310, 0x00000732, 0x00007320, 0x00007321, 0x00073210,
    0x00000074, 0x00000740, 0x00000741, 0x00007410, 0x00000742, 0x00007420,
    0x00007421, 0x00074210, 0x00000743, 0x00007430, 0x00007431, 0x00074310,
    0x00007432, 0x00074320, 0x00074321, 0x00743210, 0x00000075, 0x00000750,
    0x00000751, 0x00007510, 0x00000752, 0x00007520, 0x00007521, 0x00075210,
    0x00000753, 0x00007530, 0x00007531, 0x00075310, 0x00007532, 0x00075320,
    0x00075321, 0x00753210, 0x00000754, 0x00007540, 0x00007541, 0x00075410,
    0x00007542, 0x00075420, 0x00075421, 0x00754210, 0x00007543, 0x00075430,
    0x00075431, 0x00754310, 0x00075432, 0x00754320, 0x00754321, 0x07543210,
    0x00000076, 0x00000760, 0x00000761, 0x00007610, 0x00000762, 0x00007620,
    0x00007621, 0x00076210, 0x00000763, 0x00007630, 0x00007631, 0x00076310,
    0x00007632, 0x00076320, 0x00076321, 0x00763210, 0x00000764, 0x00007640,
    0x00007641, 0x00076410, 0x00007642, 0x00076420, 0x00076421, 0x00764210,
    0x00007643, 0x00076430, 0x00076431, 0x00764310, 0x00076432, 0x00764320,
    0x00764321, 0x07643210, 0x00000765, 0x00007650, 0x00007651, 0x00076510,
    0x00007652, 0x00076520, 0x00076521, 0x00765210, 0x00007653, 0x00076530,
    0x00076531, 0x00765310, 0x00076532, 0x00765320, 0x00765321, 0x07653210,
    0x00007654, 0x00076540, 0x00076541, 0x00765410, 0x00076542, 0x00765420,
    0x00765421, 0x07654210, 0x00076543, 0x00765430, 0x00765431, 0x07654310,
    0x00765432, 0x07654320, 0x07654321, 0x76543210,
};
/* The permutation (for VPERMD) that moves the lanes set in `bits` to the bottom,
 * lowest first: AVX-512's compress on eight lanes. */
RS_INLINE __m256i sw_compress_lanes(int bits)
{
    __m256i lane = _mm256_srlv_epi32(_mm256_set1_epi32((int)rs_compress8[bits]),
                                     _mm256_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28));
    return _mm256_and_si256(lane, _mm256_set1_epi32(7));
}
/* Append the ids of the lanes in `bits` to out[*n] (out has RS_SW slots of
 * slack): one lane permutation and one store, as AVX-512's compress.  The eight
 * scalar stores it replaces took 28 % of the stream filter's samples on Zen 3
 * (BENCHMARKS.md section 14). */
RS_INLINE void sw_append(int32_t *out, int *n, rs_swi id, int bits)
{
    _mm256_storeu_si256((__m256i *)(out + *n),
                        _mm256_permutevar8x32_epi32(id, sw_compress_lanes(bits)));
    *n += rs_popcount(bits);
}
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
RS_INLINE rs_swi sw_set1i(int32_t a) { rs_swi r; for (int k = 0; k < RS_SW; ++k) r.i[k] = a; return r; }
RS_INLINE int sw_eqi_bits(rs_swi a, rs_swi b)
{ int bits = 0; for (int k = 0; k < RS_SW; ++k) bits |= (a.i[k] == b.i[k]) << k; return bits; }
RS_INLINE void sw_storei(int32_t *p, rs_swi a) { memcpy(p, a.i, sizeof a.i); }
RS_INLINE rs_swi sw_asi(rs_swf a) { rs_swi r; memcpy(r.i, &a, sizeof r.i); return r; }
RS_INLINE void sw_rows8(const float *base, int stride, rs_swi id, rs_swf out[8])
{
#  if RS_SSE
    __m128 r[4], q[4];
    for (int k = 0; k < 4; ++k) {
        r[k] = _mm_loadu_ps(base + (size_t)stride * id.i[k]);
        q[k] = _mm_loadu_ps(base + (size_t)stride * id.i[k] + 4);
    }
    _MM_TRANSPOSE4_PS(r[0], r[1], r[2], r[3]);
    _MM_TRANSPOSE4_PS(q[0], q[1], q[2], q[3]);
    for (int c = 0; c < 4; ++c) {
        out[c] = r[c];
        out[c + 4] = q[c];
    }
#  else
    for (int c = 0; c < 8; ++c)
        out[c] = base[(size_t)stride * id.i[0] + c];
#  endif
}
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

#if !RS_ISA_AVX512 && !RS_ISA_AVX2
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

/* The largest and the smallest of a vector's lanes (none may be NaN): halves
 * folded onto each other, log2(RS_SW) dependent steps rather than RS_SW.  The
 * maximum of the same values whatever the order, up to the sign of a zero,
 * which no comparison sees. */
#if RS_ISA_AVX512 || RS_ISA_AVX2 || RS_SSE
#  if RS_ISA_AVX512
#    define RS_SW_FOLD(name, op256, op128)                                         \
RS_INLINE float name(rs_swf a)                                                        \
{                                                                                     \
    __m256 h = op256(_mm512_extractf32x8_ps(a, 1), _mm512_castps512_ps256(a));        \
    __m128 q = op128(_mm256_extractf128_ps(h, 1), _mm256_castps256_ps128(h));         \
    q = op128(_mm_movehl_ps(q, q), q);                                                \
    return _mm_cvtss_f32(op128(_mm_shuffle_ps(q, q, 1), q));                          \
}
#  elif RS_ISA_AVX2
#    define RS_SW_FOLD(name, op256, op128)                                         \
RS_INLINE float name(rs_swf a)                                                        \
{                                                                                     \
    __m128 q = op128(_mm256_extractf128_ps(a, 1), _mm256_castps256_ps128(a));         \
    q = op128(_mm_movehl_ps(q, q), q);                                                \
    return _mm_cvtss_f32(op128(_mm_shuffle_ps(q, q, 1), q));                          \
}
#  else
#    define RS_SW_FOLD(name, op256, op128)                                         \
RS_INLINE float name(rs_swf a)                                                        \
{                                                                                     \
    __m128 q = op128(_mm_movehl_ps(a, a), a);                                         \
    return _mm_cvtss_f32(op128(_mm_shuffle_ps(q, q, 1), q));                          \
}
#  endif
RS_SW_FOLD(sw_hmax, _mm256_max_ps, _mm_max_ps)
RS_SW_FOLD(sw_hmin, _mm256_min_ps, _mm_min_ps)
#  undef RS_SW_FOLD
#else
RS_INLINE float sw_hmax(rs_swf a) { return a; }
RS_INLINE float sw_hmin(rs_swf a) { return a; }
#endif

/* The lanes h of [0, n) where ids[h] >= 0, in order: lane[h] to pos and ids[h]
 * to out (each with RS_SW slots of slack); returns how many.  RS_SW lanes at a
 * time by sw_append: the shaders' hits (prim >= 0) of a block of rays. */
RS_INLINE int rs_list_valid(const int32_t *ids, int n, const int32_t *lane, int32_t *pos,
                            int32_t *out)
{
    int m = 0, i = 0;
    const int all = (int)((UINT64_C(1) << RS_SW) - 1);
    for (; i + RS_SW <= n; i += RS_SW) {
        rs_swi id = sw_ids(ids + i);
        int bits = ~sw_bits(sw_lti(id, sw_set1i(0))) & all;
        int k = m;
        sw_append(pos, &k, sw_ids(lane + i), bits);
        sw_append(out, &m, id, bits);
    }
    for (; i < n; ++i) {
        pos[m] = lane[i];
        out[m] = ids[i];
        m += ids[i] >= 0;
    }
    return m;
}

/* Columns cols[0, k) (each < 8) of the 8-float records table + 8 * rows[h], for
 * h in [0, n), into out[c][h]: RS_SW records at a time by sw_rows8 (gathers on
 * AVX-512, a transpose of the rows on AVX2).  Lanes up to n rounded up to RS_SW
 * are read and written: rows[] holds valid rows there too. */
RS_INLINE void rs_record_columns(const float *table, const int32_t *rows, int n,
                                 const int *cols, int k, float *const *out)
{
    for (int h = 0; h < n; h += RS_SW) {
        rs_swf rec[8];
        sw_rows8(table, 8, sw_ids(rows + h), rec);
        for (int c = 0; c < k; ++c)
            sw_store(out[c] + h, rec[cols[c]]);
    }
}

/* Bit k set where p[k] == 0, for the 16 bytes at p: one SSE2 comparison where
 * there is SSE2 (add_unoccluded's unoccluded shadow rays). */
RS_INLINE int rs_zero_bytes16(const uint8_t *p)
{
#if RS_SSE
    return _mm_movemask_epi8(_mm_cmpeq_epi8(_mm_loadu_si128((const __m128i *)p),
                                            _mm_setzero_si128()));
#else
    int bits = 0;
    for (int k = 0; k < 16; ++k)
        bits |= (p[k] == 0) << k;
    return bits;
#endif
}

/* p[0, n) = value with stores that bypass the caches where there is SSE2 (and a
 * plain loop elsewhere): for memory no one reads soon, such as the padding lanes
 * past a truncated ray batch's rays, so that it costs no read of the lines first
 * and evicts nothing.  Ends with a store fence. */
RS_INLINE void rs_fill_uncached(float *p, int64_t n, float value)
{
    int64_t i = 0;
#if RS_SSE
    __m128 v = _mm_set1_ps(value);
    for (; i < n && ((uintptr_t)(p + i) & 15); ++i)
        p[i] = value;
    for (; i + 4 <= n; i += 4)
        _mm_stream_ps(p + i, v);
#endif
    for (; i < n; ++i)
        p[i] = value;
#if RS_SSE
    _mm_sfence();
#endif
}

/* The lanes h of [0, n) (n <= 64) whose flag[h] is not 0, as bit h of a mask:
 * RS_SW lanes at a time (one comparison each). */
RS_INLINE uint64_t rs_mask64(const int32_t *flag, int n)
{
    uint64_t mask = 0;
    int i = 0;
    for (; i + RS_SW <= n; i += RS_SW)
        mask |= (uint64_t)(uint32_t)sw_bits(sw_lti(sw_set1i(0), sw_ids(flag + i))) << i;
    for (; i < n; ++i)
        mask |= (uint64_t)(flag[i] != 0) << i;
    return mask;
}

/* The values of src[0, n) whose bit is set in `keep` (bit h for src[h]; n <=
 * 64), in order, to dst, which has RS_SW slots of slack; returns how many.
 * RS_SW lanes at a time by sw_append (a compress on AVX-512): the shaders' new
 * rays of the lanes that make one. */
RS_INLINE int rs_keep32(const int32_t *src, int n, uint64_t keep, int32_t *dst)
{
    int m = 0, i = 0;
    for (; i + RS_SW <= n; i += RS_SW)
        sw_append(dst, &m, sw_ids(src + i), (int)((keep >> i) & ((UINT64_C(1) << RS_SW) - 1)));
    for (; i < n; ++i) {
        dst[m] = src[i];
        m += (int)((keep >> i) & 1);
    }
    return m;
}

#endif
