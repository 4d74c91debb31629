/* raysort: the AVX-512 intrinsics raysort uses, emulated lane by lane in C.
 *
 * For the `avx512emu` ISA only (setup.py builds it on request:
 * RAYSORT_BUILD_ISAS=avx512emu): the avx512 build's hand-written 16-lane code
 * (lanes.h, wide16.h) compiled for a CPU without AVX-512, so that the test suite
 * can run it, lane masks, shuffles and compression included, where no CPU runs
 * AVX-512 (no emulator of ours can run the real instructions: QEMU's cannot).  It
 * is slow and never chosen by default; it tests the code, not the hardware.
 *
 * Each operation follows the Intel SDM's pseudo-code for its instruction, with
 * the same IEEE single-precision operation per lane (the build keeps contraction
 * off): MINPS/MAXPS return the second operand when either is NaN or both are
 * zeros, the _OQ predicates are false on NaN and _NEQ_UQ true, the shuffles
 * move lanes within each 128-bit block as the SDM says (VPERMT2PS across the
 * two sources), and compression packs the selected lanes at the bottom in lane
 * order and zeroes the rest.  simd.h includes this file after
 * <immintrin.h> and before anything that uses the names, which the macros below
 * then send here.  An aligned load of an address that is not aligned, or a
 * predicate this file does not know, traps (SIGILL), as the instruction would fault.
 */
#ifndef RAYSORT_AVX512_EMU_H
#define RAYSORT_AVX512_EMU_H

#include <math.h>
#include <stdint.h>
#include <string.h>

typedef struct { float f[16]; } rs_emu_m512;
typedef struct { int32_t i[16]; } rs_emu_m512i;
typedef uint16_t rs_emu_mask16;

#define RS_EMU static inline

#define RS_EMU_MAP_F(name, expr)                                                    \
    RS_EMU rs_emu_m512 name(rs_emu_m512 a, rs_emu_m512 b)                          \
    {                                                                               \
        rs_emu_m512 r;                                                              \
        for (int j = 0; j < 16; ++j) {                                              \
            float x = a.f[j], y = b.f[j];                                           \
            r.f[j] = (expr);                                                        \
        }                                                                           \
        return r;                                                                   \
    }
RS_EMU_MAP_F(rs_emu_add_ps, x + y)
RS_EMU_MAP_F(rs_emu_sub_ps, x - y)
RS_EMU_MAP_F(rs_emu_mul_ps, x * y)
RS_EMU_MAP_F(rs_emu_div_ps, x / y)
RS_EMU_MAP_F(rs_emu_min_ps, x < y ? x : y)
RS_EMU_MAP_F(rs_emu_max_ps, x > y ? x : y)
#undef RS_EMU_MAP_F

RS_EMU rs_emu_m512 rs_emu_set1_ps(float a)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; ++j)
        r.f[j] = a;
    return r;
}
RS_EMU rs_emu_m512i rs_emu_set1_epi32(int32_t a)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = a;
    return r;
}
RS_EMU rs_emu_m512 rs_emu_loadu_ps(const void *p)
{
    rs_emu_m512 r;
    memcpy(r.f, p, sizeof r.f);
    return r;
}
RS_EMU rs_emu_m512i rs_emu_loadu_si512(const void *p)
{
    rs_emu_m512i r;
    memcpy(r.i, p, sizeof r.i);
    return r;
}
/* VMOVAPS faults on an address that is not 64-byte aligned; so does this */
RS_EMU rs_emu_m512 rs_emu_load_ps(const void *p)
{
    if ((uintptr_t)p & 63)
        __builtin_trap();
    return rs_emu_loadu_ps(p);
}
/* VCVTTPS2DQ: truncation toward zero; NaN and values out of int32 range give INT32_MIN */
RS_EMU rs_emu_m512i rs_emu_cvttps_epi32(rs_emu_m512 a)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j) {
        float x = a.f[j];
        r.i[j] = (x > -2147483904.0f && x < 2147483648.0f) ? (int32_t)x : INT32_MIN;
    }
    return r;
}
RS_EMU void rs_emu_storeu_ps(void *p, rs_emu_m512 a) { memcpy(p, a.f, sizeof a.f); }
RS_EMU void rs_emu_storeu_si512(void *p, rs_emu_m512i a) { memcpy(p, a.i, sizeof a.i); }
RS_EMU rs_emu_m512i rs_emu_castps_si512(rs_emu_m512 a)
{
    rs_emu_m512i r;
    memcpy(r.i, a.f, sizeof r.i);
    return r;
}

/* the predicates raysort uses (_CMP_* from <immintrin.h>) */
RS_EMU rs_emu_mask16 rs_emu_cmp_ps_mask(rs_emu_m512 a, rs_emu_m512 b, int predicate)
{
    unsigned bits = 0;
    for (int j = 0; j < 16; ++j) {
        float x = a.f[j], y = b.f[j];
        int set;
        switch (predicate) {
        case _CMP_LT_OQ: set = x < y; break;
        case _CMP_LE_OQ: set = x <= y; break;
        case _CMP_GT_OQ: set = x > y; break;
        case _CMP_GE_OQ: set = x >= y; break;
        case _CMP_EQ_OQ: set = x == y; break;
        case _CMP_NEQ_UQ: set = x != y; break;
        default: __builtin_trap();      /* a predicate this file does not emulate */
        }
        bits |= (unsigned)set << j;
    }
    return (rs_emu_mask16)bits;
}
RS_EMU rs_emu_mask16 rs_emu_cmpeq_epi32_mask(rs_emu_m512i a, rs_emu_m512i b)
{
    unsigned bits = 0;
    for (int j = 0; j < 16; ++j)
        bits |= (unsigned)(a.i[j] == b.i[j]) << j;
    return (rs_emu_mask16)bits;
}
RS_EMU rs_emu_mask16 rs_emu_cmplt_epi32_mask(rs_emu_m512i a, rs_emu_m512i b)
{
    unsigned bits = 0;
    for (int j = 0; j < 16; ++j)
        bits |= (unsigned)(a.i[j] < b.i[j]) << j;
    return (rs_emu_mask16)bits;
}
/* VPMOVD2M: each lane's sign bit */
RS_EMU rs_emu_mask16 rs_emu_movepi32_mask(rs_emu_m512i a)
{
    unsigned bits = 0;
    for (int j = 0; j < 16; ++j)
        bits |= ((uint32_t)a.i[j] >> 31) << j;
    return (rs_emu_mask16)bits;
}
/* lane j: mask bit j ? b : a */
RS_EMU rs_emu_m512 rs_emu_mask_blend_ps(rs_emu_mask16 k, rs_emu_m512 a, rs_emu_m512 b)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; ++j)
        r.f[j] = (k >> j & 1) ? b.f[j] : a.f[j];
    return r;
}
RS_EMU rs_emu_m512i rs_emu_mask_blend_epi32(rs_emu_mask16 k, rs_emu_m512i a, rs_emu_m512i b)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = (k >> j & 1) ? b.i[j] : a.i[j];
    return r;
}
/* VPCOMPRESSD with a zero mask: the lanes in k, in order, then zeros */
RS_EMU rs_emu_m512i rs_emu_maskz_compress_epi32(rs_emu_mask16 k, rs_emu_m512i a)
{
    rs_emu_m512i r;
    int n = 0;
    for (int j = 0; j < 16; ++j)
        if (k >> j & 1)
            r.i[n++] = a.i[j];
    for (; n < 16; ++n)
        r.i[n] = 0;
    return r;
}
/* VEXTRACTF32X8 and the cast to the low half: lanes 8-15 (imm 1) or 0-7 as an
 * __m256 (the emulation build has AVX2) */
RS_EMU __m256 rs_emu_extractf32x8_ps(rs_emu_m512 a, int imm)
{
    return _mm256_loadu_ps(a.f + (imm & 1) * 8);
}
RS_EMU __m256 rs_emu_castps512_ps256(rs_emu_m512 a) { return _mm256_loadu_ps(a.f); }
/* VBROADCASTF32X8: the eight lanes of a in lanes 0-7 and again in 8-15 */
RS_EMU rs_emu_m512 rs_emu_broadcast_f32x8(__m256 a)
{
    rs_emu_m512 r;
    _mm256_storeu_ps(r.f, a);
    _mm256_storeu_ps(r.f + 8, a);
    return r;
}

/* VINSERTF32X8 and the cast from the low half: b in lanes 8-15 (imm 1) or 0-7 of a;
 * a cast leaves lanes 8-15 undefined (zero here) */
RS_EMU rs_emu_m512 rs_emu_insertf32x8(rs_emu_m512 a, __m256 b, int imm)
{
    _mm256_storeu_ps(a.f + (imm & 1) * 8, b);
    return a;
}
RS_EMU rs_emu_m512 rs_emu_castps256_ps512(__m256 a)
{
    rs_emu_m512 r = rs_emu_set1_ps(0.0f);
    _mm256_storeu_ps(r.f, a);
    return r;
}
/* VUNPCKLPS, VUNPCKHPS and VSHUFPS: in each 128-bit block (lanes 4j..4j+3) on
 * its own, the low (high) two lanes of a and b interleaved; lanes imm[1:0] and
 * imm[3:2] of a's block, then imm[5:4] and imm[7:6] of b's */
RS_EMU rs_emu_m512 rs_emu_unpack_ps(rs_emu_m512 a, rs_emu_m512 b, int high)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; j += 4)
        for (int k = 0; k < 2; ++k) {
            r.f[j + 2 * k] = a.f[j + 2 * high + k];
            r.f[j + 2 * k + 1] = b.f[j + 2 * high + k];
        }
    return r;
}
RS_EMU rs_emu_m512 rs_emu_shuffle_ps(rs_emu_m512 a, rs_emu_m512 b, int imm)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; j += 4) {
        r.f[j] = a.f[j + (imm & 3)];
        r.f[j + 1] = a.f[j + (imm >> 2 & 3)];
        r.f[j + 2] = b.f[j + (imm >> 4 & 3)];
        r.f[j + 3] = b.f[j + (imm >> 6 & 3)];
    }
    return r;
}
/* VSQRTPS: each lane's correctly rounded square root, as sqrtf (and SQRTPS) gives it */
RS_EMU rs_emu_m512 rs_emu_sqrt_ps(rs_emu_m512 a)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; ++j)
        r.f[j] = sqrtf(a.f[j]);
    return r;
}

/* VPERMT2PS: lane j is lane idx[j] & 15 of b when bit 4 of idx[j] is set, else of a */
RS_EMU rs_emu_m512 rs_emu_permutex2var_ps(rs_emu_m512 a, rs_emu_m512i idx, rs_emu_m512 b)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; ++j)
        r.f[j] = (idx.i[j] & 16) ? b.f[idx.i[j] & 15] : a.f[idx.i[j] & 15];
    return r;
}

/* VPERMT2D: lane j is lane idx[j] & 15 of b when bit 4 of idx[j] is set, else of a */
RS_EMU rs_emu_m512i rs_emu_permutex2var_epi32(rs_emu_m512i a, rs_emu_m512i idx, rs_emu_m512i b)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = (idx.i[j] & 16) ? b.i[idx.i[j] & 15] : a.i[idx.i[j] & 15];
    return r;
}
/* VPSRLVD by each lane's count (zeros past 31) and VPORD */
RS_EMU rs_emu_m512i rs_emu_srlv_epi32(rs_emu_m512i a, rs_emu_m512i count)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = (uint32_t)count.i[j] > 31 ? 0 : (int32_t)((uint32_t)a.i[j] >> count.i[j]);
    return r;
}
RS_EMU rs_emu_m512i rs_emu_or_si512(rs_emu_m512i a, rs_emu_m512i b)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = a.i[j] | b.i[j];
    return r;
}
/* VMOVUPS with a zero mask and VMOVDQU32 with a mask: the lanes outside k are not
 * read (zero) or not written, so neither touches memory past them */
RS_EMU rs_emu_m512 rs_emu_maskz_loadu_ps(rs_emu_mask16 k, const void *p)
{
    rs_emu_m512 r;
    for (int j = 0; j < 16; ++j)
        r.f[j] = (k >> j & 1) ? ((const float *)p)[j] : 0.0f;
    return r;
}
RS_EMU void rs_emu_mask_storeu_epi32(void *p, rs_emu_mask16 k, rs_emu_m512i a)
{
    for (int j = 0; j < 16; ++j)
        if (k >> j & 1)
            memcpy((char *)p + 4 * j, &a.i[j], 4);
}

/* VMINPS and VMAXPS under a mask: lanes in k get the operation's result (the second
 * operand when either is NaN or both are zeros), the others src's */
RS_EMU rs_emu_m512 rs_emu_mask_min_ps(rs_emu_m512 src, rs_emu_mask16 k, rs_emu_m512 a,
                                      rs_emu_m512 b)
{
    return rs_emu_mask_blend_ps(k, src, rs_emu_min_ps(a, b));
}
RS_EMU rs_emu_m512 rs_emu_mask_max_ps(rs_emu_m512 src, rs_emu_mask16 k, rs_emu_m512 a,
                                      rs_emu_m512 b)
{
    return rs_emu_mask_blend_ps(k, src, rs_emu_max_ps(a, b));
}
/* VPCMPEQD under a mask (lanes outside k compare false), VPADDD, VPSLLD by an
 * immediate (zeros past 31), VPORD under a mask (src's lanes outside k) */
RS_EMU rs_emu_mask16 rs_emu_mask_cmpeq_epi32_mask(rs_emu_mask16 k, rs_emu_m512i a,
                                                  rs_emu_m512i b)
{
    return (rs_emu_mask16)(k & rs_emu_cmpeq_epi32_mask(a, b));
}
RS_EMU rs_emu_m512i rs_emu_add_epi32(rs_emu_m512i a, rs_emu_m512i b)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = (int32_t)((uint32_t)a.i[j] + (uint32_t)b.i[j]);
    return r;
}
RS_EMU rs_emu_m512i rs_emu_slli_epi32(rs_emu_m512i a, unsigned imm)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = imm > 31 ? 0 : (int32_t)((uint32_t)a.i[j] << imm);
    return r;
}
RS_EMU rs_emu_m512i rs_emu_mask_or_epi32(rs_emu_m512i src, rs_emu_mask16 k, rs_emu_m512i a,
                                         rs_emu_m512i b)
{
    return rs_emu_mask_blend_epi32(k, src, rs_emu_or_si512(a, b));
}
/* VPMOVZXBD: sixteen bytes widened to 32-bit lanes; VPMOVDB: each lane's low byte
 * (the emulation build has SSE2's __m128i) */
RS_EMU rs_emu_m512i rs_emu_cvtepu8_epi32(__m128i a)
{
    uint8_t b[16];
    rs_emu_m512i r;
    _mm_storeu_si128((__m128i *)b, a);
    for (int j = 0; j < 16; ++j)
        r.i[j] = b[j];
    return r;
}
RS_EMU __m128i rs_emu_cvtepi32_epi8(rs_emu_m512i a)
{
    uint8_t b[16];
    for (int j = 0; j < 16; ++j)
        b[j] = (uint8_t)a.i[j];
    return _mm_loadu_si128((const __m128i *)b);
}

/* VMOVDQU32 with a zero mask (lanes outside k not read: zero) and VPCMPD's NEQ under
 * a mask (lanes outside k false) */
RS_EMU rs_emu_m512i rs_emu_maskz_loadu_epi32(rs_emu_mask16 k, const void *p)
{
    rs_emu_m512i r;
    for (int j = 0; j < 16; ++j)
        r.i[j] = 0;
    for (int j = 0; j < 16; ++j)
        if (k >> j & 1)
            memcpy(&r.i[j], (const char *)p + 4 * j, 4);
    return r;
}
RS_EMU rs_emu_mask16 rs_emu_mask_cmpneq_epi32_mask(rs_emu_mask16 k, rs_emu_m512i a,
                                                   rs_emu_m512i b)
{
    return (rs_emu_mask16)(k & ~rs_emu_cmpeq_epi32_mask(a, b));
}

#undef RS_EMU

/* the names the avx512 code is written with, sent here */
#define __m512 rs_emu_m512
#define __m512i rs_emu_m512i
#define __mmask16 rs_emu_mask16
#define _mm512_add_ps rs_emu_add_ps
#define _mm512_sub_ps rs_emu_sub_ps
#define _mm512_mul_ps rs_emu_mul_ps
#define _mm512_div_ps rs_emu_div_ps
#define _mm512_sqrt_ps rs_emu_sqrt_ps
#define _mm512_min_ps rs_emu_min_ps
#define _mm512_max_ps rs_emu_max_ps
#define _mm512_set1_ps rs_emu_set1_ps
#define _mm512_set1_epi32 rs_emu_set1_epi32
#define _mm512_load_ps rs_emu_load_ps
#define _mm512_loadu_ps rs_emu_loadu_ps
#define _mm512_loadu_si512 rs_emu_loadu_si512
#define _mm512_storeu_ps rs_emu_storeu_ps
#define _mm512_storeu_si512 rs_emu_storeu_si512
#define _mm512_castps_si512 rs_emu_castps_si512
#define _mm512_cmp_ps_mask rs_emu_cmp_ps_mask
#define _mm512_cmpeq_epi32_mask rs_emu_cmpeq_epi32_mask
#define _mm512_cmplt_epi32_mask rs_emu_cmplt_epi32_mask
#define _mm512_movepi32_mask rs_emu_movepi32_mask
#define _mm512_mask_blend_ps rs_emu_mask_blend_ps
#define _mm512_mask_blend_epi32 rs_emu_mask_blend_epi32
#define _mm512_cvttps_epi32 rs_emu_cvttps_epi32
#define _mm512_maskz_compress_epi32 rs_emu_maskz_compress_epi32
#define _mm512_extractf32x8_ps rs_emu_extractf32x8_ps
#define _mm512_castps512_ps256 rs_emu_castps512_ps256
#define _mm512_broadcast_f32x8 rs_emu_broadcast_f32x8
#define _mm512_insertf32x8 rs_emu_insertf32x8
#define _mm512_castps256_ps512 rs_emu_castps256_ps512
#define _mm512_unpacklo_ps(a, b) rs_emu_unpack_ps(a, b, 0)
#define _mm512_unpackhi_ps(a, b) rs_emu_unpack_ps(a, b, 1)
#define _mm512_shuffle_ps rs_emu_shuffle_ps
#define _mm512_permutex2var_ps rs_emu_permutex2var_ps
#define _mm512_permutex2var_epi32 rs_emu_permutex2var_epi32
#define _mm512_srlv_epi32 rs_emu_srlv_epi32
#define _mm512_or_si512 rs_emu_or_si512
#define _mm512_maskz_loadu_ps rs_emu_maskz_loadu_ps
#define _mm512_mask_storeu_epi32 rs_emu_mask_storeu_epi32
#define _mm512_mask_min_ps rs_emu_mask_min_ps
#define _mm512_mask_max_ps rs_emu_mask_max_ps
#define _mm512_mask_cmpeq_epi32_mask rs_emu_mask_cmpeq_epi32_mask
#define _mm512_add_epi32 rs_emu_add_epi32
#define _mm512_slli_epi32 rs_emu_slli_epi32
#define _mm512_mask_or_epi32 rs_emu_mask_or_epi32
#define _mm512_cvtepu8_epi32 rs_emu_cvtepu8_epi32
#define _mm512_cvtepi32_epi8 rs_emu_cvtepi32_epi8
#define _mm512_maskz_loadu_epi32 rs_emu_maskz_loadu_epi32
#define _mm512_mask_cmpneq_epi32_mask rs_emu_mask_cmpneq_epi32_mask

#endif
