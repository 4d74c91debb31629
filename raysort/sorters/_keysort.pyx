"""The machinery of the sort-key sorters: per-ray keys, a radix sort, sub-packet cuts.

Shared by ``origin_direction``, ``two_point``, ``termination`` and ``garanzha``
(see those modules for the keys and their papers); built per ISA and called
through :func:`raysort.isa.module` like every kernel.  The keys of a large
packet are made just before it is sorted (they are still in the cache then),
``BLOCK`` rays at a time, each step one loop over the block that the compiler
vectorises:

1. every ray gives up to six coordinates in [0, 1] (``coordinates`` below):
   the origin normalised to the scene box, then either the unit direction's
   components mapped from [-1, 1], its octahedral map (two coordinates), or an
   end point ``o + L * d / |d|`` normalised like the origin;
2. each coordinate is quantised to :data:`COORD_BITS` bits;
3. the key is the OR of per-coordinate lookup tables (two bytes of each
   quantised coordinate index a table of the key bits they set).  Any bit
   split (Morton interleave, a block of one coordinate's bits first, a plain
   concatenation as in a hash) is just a table, built by :func:`key_table`.

A key that reads only the high byte of each coordinate (every default key) is
looked up two coordinates at a time (:func:`plan_lookups`): three loads per ray.
The avx2 and avx512 builds assemble it in vector registers instead where its bits
fit the key's top 32 (:func:`plan_windows`, ``rs_keysort_window_keys``): sixteen
rays at a time, one VPERMT2D lookup in a 32-entry table per coordinate (two for one
whose whole byte counts), or eight rays at a time, one VPERMD lookup in an 8-entry
table per three bits of a coordinate, and the sort reads their high halves (32-bit
keys) as they are.
A sorter's next call with the same table reuses the plan (``last_plan``).

Keys are left aligned in a uint64: the sort looks at the top ``8 * digits``
bits.  Within every large packet, ``(key, ray)`` pairs are sorted stably,
optionally after Garanzha and Loop's compression: runs of equal keys in input
order become one chunk, only chunks are sorted, and the runs are copied back in
chunk order (the result is the same order; the work is on fewer items when the
input has long runs, so it is skipped for a packet with more than half as many
runs as rays).  Whenever the key's low bits, below the sorted ones, have room
for it, the ray's (or chunk's) index rides there: the packed keys are then all
different, and the avx2 and avx512 builds sort them with NumPy's quicksort
(see ``sort_u32`` and ``sort_u64`` below).  Every other case is a stable LSD
radix sort on the bits from the highest to the lowest one that differ between
the packet's keys, in digits of 8 to :data:`MAX_DIGIT_BITS` bits
(:func:`digit_plan`; a pass whose digit is the same for every key is skipped).
The sorted run is then cut into sub-packets of at most ``packet_size`` rays, and
also wherever the top ``split_bits`` bits of the key change.

Coordinates that are NaN map to 0 and everything is clamped to [0, 1], so no
ray (NaN, infinite, zero direction) can make the kernel misbehave; the gather
marks such rays inactive anyway.
"""
from libc.math cimport INFINITY
from libc.stdint cimport int32_t, int64_t, uint32_t, uint64_t
from libc.string cimport memcmp, memset
cimport numpy as cnp
# rs_maxf and rs_minf: for the C below, which calls them
from raysort._types cimport rs_maxf, rs_minf, RS_RAY_ROWS, RS_RAY_OX, RS_RAY_DX, RS_RAY_TMAX  # no-cython-lint

import math

import numpy as np

from raysort import isa
from raysort.sdk import (MAX_PACKET, ConfigError, Sorter, boolean, check_packets, integer,
                         plain_packets)

cdef enum:
    KEY_COORDS = 6          # most coordinates a key draws from
    COORD_BITS_C = 16       # bits each coordinate is quantised to
    TABLE_ROW = 256         # entries of a key table row: one per value of a coordinate byte
    TABLE_BYTES = KEY_COORDS * 2 * TABLE_ROW * 8    # a whole key table
#: bits each coordinate is quantised to (a key table has two byte-tables per coordinate)
COORD_BITS = COORD_BITS_C
#: most coordinates a key draws from
MAX_COORDS = KEY_COORDS

# how the coordinates after the origin's three are made
cdef enum:
    DIR_COMPONENTS = 0      # (d/|d| + 1) / 2 per component: coordinates 3, 4, 5
    DIR_OCTAHEDRAL = 1      # octahedral map of d/|d| to [0,1]^2: coordinates 3, 4
    END_POINT = 2           # o + L d/|d|, normalised like the origin: coordinates 3, 4, 5

COORDINATES = {"components": DIR_COMPONENTS, "octahedral": DIR_OCTAHEDRAL,
               "end_point": END_POINT}

# the end point is pulled this much inside the box it would leave (Meister's hippie does
# the same), so that a ray ending on the far wall keeps its wall's cell
cdef float EXIT_SHRINK = 1.0 - 1.0e-3
cdef float ONE = 1.0        # a float constant: a bare 1.0 would make the C double
cdef enum:
    MIN_DIGIT = 8           # a radix digit's width: at least a byte,
    MAX_DIGIT = 11          # at most 2048 buckets (wider ones cost more than a pass)
    COUNT_SIZE = 8 << MAX_DIGIT         # histogram ints: 64 bits take at most 8 digits
cdef enum:
    BLOCK = 256             # rays whose coordinates are computed together, loop by loop
    MAX_WINDOWS = 3 * KEY_COORDS    # window tables of a key: up to 3 per coordinate (AVX2)
    IOTA_SPILL = 15         # values iota (7) and place_runs (15) may write past their end
    RUNS_PER_RAY = 2        # sort_runs where a packet's keys come in runs of 2 rays or more
#: widest and narrowest radix digit (bits)
MAX_DIGIT_BITS = MAX_DIGIT
MIN_DIGIT_BITS = MIN_DIGIT
#: bits of the octant prefix (the signs of dx, dy, dz)
OCTANT_BITS = 3


cdef extern from *:
    """
    #include "raysort/simd.h"
    #include "raysort/lanes.h"
    /* c ? a : b, as a select the compiler vectorises (a Cython conditional is a branch) */
    static inline float rs_keysort_pick(int c, float a, float b) { return c ? a : b; }
    /* q[j] = (int)(min(max(c[j], 0), 1) * 65535): a coordinate clamped to [0, 1] (NaN
     * -> 0) and quantised to 16 bits (COORD_BITS: 65535 = 2^16 - 1).  MAXPS/MINPS
     * return the second operand on NaN, as rs_maxf/rs_minf do, so every ISA gives the
     * same q (sixteen at a time with AVX-512, eight with AVX2, four with SSE); written
     * with intrinsics because the compiler leaves the branchy scalar form unvectorised. */
    #if RS_ISA_AVX512
    /* (int)(min(max(c, 0), 1) * scale), sixteen lanes: scale 65535, or 65535 / 2^shift
     * for the window keys' top bits */
    static inline __m512i rs_keysort_quantise16(__m512 c, __m512 scale)
    {
        __m512 x = _mm512_min_ps(_mm512_max_ps(c, _mm512_set1_ps(0.0f)), _mm512_set1_ps(1.0f));
        return _mm512_cvttps_epi32(_mm512_mul_ps(x, scale));
    }
    #endif
    #if RS_ISA_AVX2
    /* the same, eight lanes (the quantiser's AVX2 tail and the avx2 build's window keys) */
    static inline __m256i rs_keysort_quantise8(__m256 c, __m256 scale)
    {
        __m256 x = _mm256_min_ps(_mm256_max_ps(c, _mm256_setzero_ps()), _mm256_set1_ps(1.0f));
        return _mm256_cvttps_epi32(_mm256_mul_ps(x, scale));
    }
    #endif
    static inline void rs_keysort_quantise(const float *c, int32_t *q, int m)
    {
        int j = 0;
    #if RS_ISA_AVX512
        for (; j + 16 <= m; j += 16)
            _mm512_storeu_si512((void *)(q + j), rs_keysort_quantise16(_mm512_loadu_ps(c + j),
                                                                        _mm512_set1_ps(65535.0f)));
    #endif
    #if RS_ISA_AVX2
        for (; j + 8 <= m; j += 8)
            _mm256_storeu_si256((__m256i *)(q + j), rs_keysort_quantise8(_mm256_loadu_ps(c + j),
                                                                         _mm256_set1_ps(65535.0f)));
    #endif
    #if RS_SSE
        const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), qmax = _mm_set1_ps(65535.0f);
        for (; j + 4 <= m; j += 4) {
            __m128 x = _mm_min_ps(_mm_max_ps(_mm_loadu_ps(c + j), zero), one);
            _mm_storeu_si128((__m128i *)(q + j), _mm_cvttps_epi32(_mm_mul_ps(x, qmax)));
        }
    #endif
        for (; j < m; ++j)
            q[j] = (int32_t)(rs_minf(rs_maxf(c[j], 0.0f), 1.0f) * 65535.0f);
    }
    /* One pass of the packed radix sort: key i goes to dst[h[digit]++], digit = (key >> shift)
     * & dmask; with out, also out[c] = base + (key & low), the ray index a packed key
     * carries, in sorted order.  Its own function, not inlined into the sort's many loops,
     * so that the loop keeps everything in registers (inlined, it reloaded its shift and
     * end from the stack and its speed moved with unrelated edits: up to 40 % slower).
     * (Placing the second half of the keys backwards from each bucket's end, two
     * independent chains of counter updates, was slower.)  ``coherent``: one digit
     * holds most keys, so one counter is updated key after key; the counters are then
     * copied to the stack, whose store-to-load forwarding the CPU renames (as in
     * nah.pyx: camera rays' sort 0.625 -> 0.576 ms, Sibenik, Zen 3, AVX2).  The loops
     * are written out for both: one inline helper called with either array measured
     * 7 % slower on camera rays (0.566 -> 0.607 ms). */
    __attribute__((noinline))
    static void rs_keysort_scatter(const uint64_t *src, uint64_t *dst, int32_t *out, int n,
                                   int shift, uint64_t dmask, int32_t *h, int32_t base,
                                   uint64_t low, int coherent)
    {
        int32_t at[2048];
        if (coherent) {
            memcpy(at, h, (dmask + 1) * sizeof(int32_t));
            if (out == NULL) {
                for (int i = 0; i < n; ++i) {
                    uint64_t k = src[i];
                    dst[at[(k >> shift) & dmask]++] = k;
                }
                return;
            }
            for (int i = 0; i < n; ++i) {
                uint64_t k = src[i];
                int32_t c = at[(k >> shift) & dmask]++;
                dst[c] = k;
                out[c] = base + (int32_t)(k & low);
            }
            return;
        }
        if (out == NULL) {
            for (int i = 0; i < n; ++i) {
                uint64_t k = src[i];
                dst[h[(k >> shift) & dmask]++] = k;
            }
            return;
        }
        for (int i = 0; i < n; ++i) {
            uint64_t k = src[i];
            int32_t c = h[(k >> shift) & dmask]++;
            dst[c] = k;
            out[c] = base + (int32_t)(k & low);
        }
    }
    /* p > 0 and p < inf (false for NaN), as one integer comparison of its bits */
    static inline int rs_keysort_positive_finite(float p)
    {
        uint32_t bits;
        memcpy(&bits, &p, sizeof bits);
        return bits - 1u < 0x7F7FFFFFu;
    }
    /* c ? a : b by the bits (a select of two floats the compiler vectorises in any loop) */
    static inline float rs_keysort_blend(int c, float a, float b)
    {
        uint32_t x, y, m = -(uint32_t)(c != 0);
        memcpy(&x, &a, sizeof x);
        memcpy(&y, &b, sizeof y);
        x = (x & m) | (y & ~m);
        memcpy(&a, &x, sizeof a);
        return a;
    }
    /* Coordinates 0-5 of m rays for END_POINT keys into c[k * stride + j]: the origin,
     * then o + L d/|d|, both normalised to the scene box (lo, hi, scale), where L is the
     * estimated length (length, or prev[j] * prev_scale where prev[j] is positive and
     * finite) clamped to tmax and to where the ray leaves the box, pulled in by shrink.
     * The end point is o + s d with s = min(L / |d|, exit * shrink), the exit in units
     * of d (a slab test on d itself, which needs no |d|): the same point as o + L' d/|d|
     * with L' clamped in world units, but two operations shorter a ray, and the slab
     * test no longer waits for the square root (0.93x the sort's time on shadow rays,
     * AVX-512).  A zero or non-finite direction gives inf or NaN: its key is then
     * arbitrary.  One loop, its temporaries in registers (one loop per step kept them
     * in memory), with the same IEEE operations per ray as a scalar build. */
    static inline void rs_keysort_end_points_loop(
        const float *RS_RESTRICT ox, const float *RS_RESTRICT oy, const float *RS_RESTRICT oz,
        const float *RS_RESTRICT dx, const float *RS_RESTRICT dy, const float *RS_RESTRICT dz,
        const float *RS_RESTRICT tmax, const float *RS_RESTRICT prev, int has_prev, int m,
        float *RS_RESTRICT c0, float *RS_RESTRICT c1, float *RS_RESTRICT c2, float *RS_RESTRICT c3,
        float *RS_RESTRICT c4, float *RS_RESTRICT c5, const float *lo, const float *hi,
        const float *scale, float length, float prev_scale, float shrink)
    {
        const float lo0 = lo[0], lo1 = lo[1], lo2 = lo[2], hi0 = hi[0], hi1 = hi[1],
                    hi2 = hi[2], sc0 = scale[0], sc1 = scale[1], sc2 = scale[2];
        for (int j = 0; j < m; ++j) {
            float x = dx[j], y = dy[j], z = dz[j], L = length, r, leave = INFINITY, t;
            c0[j] = (ox[j] - lo0) * sc0;
            c1[j] = (oy[j] - lo1) * sc1;
            c2[j] = (oz[j] - lo2) * sc2;
            float norm = sqrtf(x * x + y * y + z * z), s;
            if (has_prev) {
                float p = prev[j], scaled = p * prev_scale;
                L = rs_keysort_blend(rs_keysort_positive_finite(p), scaled, length);
            }
            /* where the ray leaves the scene box (for an origin inside it), in units of d */
            r = 1.0f / x;
            leave = rs_minf(leave, rs_maxf((lo0 - ox[j]) * r, (hi0 - ox[j]) * r));
            r = 1.0f / y;
            leave = rs_minf(leave, rs_maxf((lo1 - oy[j]) * r, (hi1 - oy[j]) * r));
            r = 1.0f / z;
            leave = rs_minf(leave, rs_maxf((lo2 - oz[j]) * r, (hi2 - oz[j]) * r));
            t = tmax[j];
            L = rs_keysort_pick(t >= L, L, rs_maxf(t, 0.0f));  /* also for NaN or negative tmax */
            s = rs_minf(rs_maxf(leave * shrink, 0.0f), L / norm);  /* the exit pulled in a little */
            c3[j] = (ox[j] + s * x - lo0) * sc0;
            c4[j] = (oy[j] + s * y - lo1) * sc1;
            c5[j] = (oz[j] + s * z - lo2) * sc2;
        }
    }
    static void rs_keysort_end_points(const float *const o[3], const float *const d[3],
                                      const float *tmax, const float *prev, int m, float *c,
                                      int stride, const float *lo, const float *hi,
                                      const float *scale, float length, float prev_scale,
                                      float shrink)
    {
        /* two copies of the loop, so that neither tests prev per ray */
        if (prev != NULL)
            rs_keysort_end_points_loop(o[0], o[1], o[2], d[0], d[1], d[2], tmax, prev, 1, m,
                                       c, c + stride, c + 2 * stride, c + 3 * stride,
                                       c + 4 * stride, c + 5 * stride, lo, hi, scale,
                                       length, prev_scale, shrink);
        else
            rs_keysort_end_points_loop(o[0], o[1], o[2], d[0], d[1], d[2], tmax, NULL, 0, m,
                                       c, c + stride, c + 2 * stride, c + 3 * stride,
                                       c + 4 * stride, c + 5 * stride, lo, hi, scale,
                                       length, prev_scale, shrink);
    }
    /* Coordinates 0-4 (octahedral) or 0-5 of m rays for the direction keys into
     * c[k * stride + j]: the origin normalised to the scene box (lo, scale), then the
     * octahedral map of d (which divides by |d|_1 itself: no unit vector), its lower
     * hemisphere folded over the diagonals, or each component of d / |d| (inf or NaN
     * for a zero or non-finite direction: its key is then arbitrary), as (x + 1) / 2.
     * One loop, its temporaries in registers (a loop per step, as the Cython had it,
     * took 1.04-1.11x the sort's time on shadow rays, AVX-512), with the same IEEE
     * operations per ray as a scalar build, and so the same keys. */
    static inline void rs_keysort_directions_loop(
        const float *RS_RESTRICT ox, const float *RS_RESTRICT oy, const float *RS_RESTRICT oz,
        const float *RS_RESTRICT dx, const float *RS_RESTRICT dy, const float *RS_RESTRICT dz,
        int octahedral, int m, float *RS_RESTRICT c0, float *RS_RESTRICT c1,
        float *RS_RESTRICT c2, float *RS_RESTRICT c3, float *RS_RESTRICT c4,
        float *RS_RESTRICT c5, const float *lo, const float *scale)
    {
        const float lo0 = lo[0], lo1 = lo[1], lo2 = lo[2], sc0 = scale[0], sc1 = scale[1],
                    sc2 = scale[2];
        for (int j = 0; j < m; ++j) {
            float x = dx[j], y = dy[j], z = dz[j];
            c0[j] = (ox[j] - lo0) * sc0;
            c1[j] = (oy[j] - lo1) * sc1;
            c2[j] = (oz[j] - lo2) * sc2;
            if (octahedral) {
                float s = 1.0f / (fabsf(x) + fabsf(y) + fabsf(z)), u = x * s, v = y * s;
                float below = (float)(z < 0);
                c3[j] = 0.5f * (u + below * (copysignf(1.0f - fabsf(v), u) - u)) + 0.5f;
                c4[j] = 0.5f * (v + below * (copysignf(1.0f - fabsf(u), v) - v)) + 0.5f;
            } else {
                float iv = 1.0f / sqrtf(x * x + y * y + z * z);
                c3[j] = 0.5f * (x * iv) + 0.5f;
                c4[j] = 0.5f * (y * iv) + 0.5f;
                c5[j] = 0.5f * (z * iv) + 0.5f;
            }
        }
    }
    static void rs_keysort_directions(const float *const o[3], const float *const d[3],
                                      int octahedral, int m, float *c, int stride,
                                      const float *lo, const float *scale)
    {
        /* two copies of the loop, so that neither tests the mode per ray */
        if (octahedral)
            rs_keysort_directions_loop(o[0], o[1], o[2], d[0], d[1], d[2], 1, m, c,
                                       c + stride, c + 2 * stride, c + 3 * stride,
                                       c + 4 * stride, NULL, lo, scale);
        else
            rs_keysort_directions_loop(o[0], o[1], o[2], d[0], d[1], d[2], 0, m, c,
                                       c + stride, c + 2 * stride, c + 3 * stride,
                                       c + 4 * stride, c + 5 * stride, lo, scale);
    }
    /* the highest and lowest set bit of a nonzero x */
    static inline int rs_keysort_clz64(uint64_t x)
    {
    #if defined(__GNUC__) || defined(__clang__)
        return __builtin_clzll(x);
    #else
        int n = 0;
        while (!(x >> 63)) { x <<= 1; ++n; }
        return n;
    #endif
    }
    /* Ask for the lines of out[0, n) for writing: a large packet's part of the order,
     * which the last radix pass writes at random within it, and which is not in the
     * cache after a traversal.  Asked before the packet's keys are made, so the lines
     * are there when the pass runs (the sort 0.94-0.98 of before, warm or with 4 or
     * 64 MB read between sorts, Zen 3, AVX2; the same in nah.pyx measured 0.96-1.02). */
    static inline void rs_keysort_prefetch_out(int32_t *out, int n)
    {
        for (int i = 0; i < n; i += 16)
            rs_prefetchw(out + i);
    }
    /* out[0, len) = first, first + 1, ...: a packet kept in order, or a decompressed
     * chunk's rays.  Chunks are short (a few rays), so with AVX2 (and AVX-512) whole
     * vectors of eight, which may write up to IOTA_SPILL values past len (the order
     * has room for them past its end), four with SSE; no loop tail to mispredict. */
    static inline void rs_keysort_iota(int32_t *out, int32_t first, int len)
    {
    #if RS_ISA_AVX2
        const __m256i step = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        for (int k = 0; k < len; k += 8)
            _mm256_storeu_si256((__m256i *)(out + k),
                                _mm256_add_epi32(_mm256_set1_epi32(first + k), step));
    #elif RS_SSE
        const __m128i step = _mm_setr_epi32(0, 1, 2, 3);
        for (int k = 0; k < len; k += 4)
            _mm_storeu_si128((__m128i *)(out + k), _mm_add_epi32(_mm_set1_epi32(first + k), step));
    #else
        for (int k = 0; k < len; ++k)
            out[k] = first + k;
    #endif
    }
    /* out[i] = start + (k32[i] & idx): the rays of sorted compact keys (restrict: a
     * loop the compiler vectorises) */
    static inline void rs_keysort_ray_order(const uint32_t *RS_RESTRICT k32, int n,
                                            uint32_t idx, int32_t start,
                                            int32_t *RS_RESTRICT out)
    {
        for (int i = 0; i < n; ++i)
            out[i] = start + (int32_t)(k32[i] & idx);
    }
    /* Keys of m rays assembled in vector registers (the avx2 and avx512 builds;
     * RS_KEYSORT_WINDOWS): for a short key whose table rows are each the OR of their
     * lookups on windows of the coordinate's high byte (RS_KEYSORT_WINDOW_BITS bits
     * from its top down: 5 and 3 with AVX-512, 3, 3 and 2 with AVX2) and whose bits
     * all lie in the key's high 32 bits (after the octant's shift), the high half of
     * the key is the OR over those windows of a table indexed by the window's bits:
     * 32 entries that VPERMT2D looks up for sixteen rays at once, or 8 that VPERMD
     * looks up for eight (the scalar path reads three 256-entry pair tables per ray).
     * Table t, its entries at tables[32 * t], serves coordinate c[coord[t] * stride +
     * j], quantised as rs_keysort_quantise does, >> shift[t] (8 plus the window's
     * lowest bit; the lookup reads the low five or three bits); n_tables is
     * RS_KEYSORT_TABLE_SLOTS or twice that (unused tables are zero), so that the loop
     * over them unrolls.  With octant, bits 31, 30, 29 are the signs of dx, dy, dz.
     * Writes each key's high half (its low half is zero), which the sort reads as it
     * is (sort_packet of 32-bit keys: half the bytes of 64-bit keys to write and read,
     * 0.87-0.97x the sort's time after a trace, AVX-512); the keys are the scalar
     * path's, bit for bit (plan_windows checks the rows). */
    #define RS_KEYSORT_WINDOWS RS_ISA_AVX2
    #if RS_ISA_AVX512
    #define RS_KEYSORT_WINDOW_BITS 5
    #define RS_KEYSORT_TABLE_SLOTS 6
    #else
    #define RS_KEYSORT_WINDOW_BITS 3
    #define RS_KEYSORT_TABLE_SLOTS 9
    #endif
    /* (int)(x * 65535) >> shift is (int)(x * (65535 / 2^shift)) for x in [0, 1]:
     * scaling by a power of two is exact, and truncation then shift is truncation of
     * the quotient; one multiplication, no shift (the key sorts 0.96-0.99x on shadow
     * and camera rays, AVX-512) */
    static inline float rs_keysort_window_scale(int shift)
    {
        return 65535.0f / (float)(1 << shift);
    }
    #if RS_ISA_AVX512
    RS_INLINE void rs_keysort_window_keys_n(const int n_tables, const float *c, int stride,
                                            int m, const int *coord, const int *shift,
                                            const uint32_t *tables, const float *dx,
                                            const float *dy, const float *dz, int octant,
                                            uint32_t *high_halves)
    {
        const __m512 zero = _mm512_set1_ps(0.0f);
        const __m512i none = _mm512_set1_epi32(0);
        __m512i low[2 * RS_KEYSORT_TABLE_SLOTS], high[2 * RS_KEYSORT_TABLE_SLOTS];
        __m512 scale[2 * RS_KEYSORT_TABLE_SLOTS];
        const float *row[2 * RS_KEYSORT_TABLE_SLOTS];
        for (int t = 0; t < n_tables; ++t) {
            low[t] = _mm512_loadu_si512(tables + 32 * t);
            high[t] = _mm512_loadu_si512(tables + 32 * t + 16);
            scale[t] = _mm512_set1_ps(rs_keysort_window_scale(shift[t]));
            row[t] = c + coord[t] * stride;
        }
        for (int j = 0; j < m; j += 16) {
            /* the last vector's rays past m: not read, not written */
            __mmask16 k = (__mmask16)(m - j >= 16 ? 0xFFFF : (1u << (m - j)) - 1);
            __m512i h = none;
            for (int t = 0; t < n_tables; ++t) {
                __m512i q = rs_keysort_quantise16(_mm512_maskz_loadu_ps(k, row[t] + j),
                                                  scale[t]);
                h = _mm512_or_si512(h, _mm512_permutex2var_epi32(low[t], q, high[t]));
            }
            if (octant) {
                __mmask16 sx = _mm512_cmp_ps_mask(_mm512_maskz_loadu_ps(k, dx + j), zero,
                                                  _CMP_LT_OQ),
                          sy = _mm512_cmp_ps_mask(_mm512_maskz_loadu_ps(k, dy + j), zero,
                                                  _CMP_LT_OQ),
                          sz = _mm512_cmp_ps_mask(_mm512_maskz_loadu_ps(k, dz + j), zero,
                                                  _CMP_LT_OQ);
                h = _mm512_mask_blend_epi32(sx, h, _mm512_or_si512(
                    h, _mm512_set1_epi32((int32_t)0x80000000u)));
                h = _mm512_mask_blend_epi32(sy, h, _mm512_or_si512(h, _mm512_set1_epi32(1 << 30)));
                h = _mm512_mask_blend_epi32(sz, h, _mm512_or_si512(h, _mm512_set1_epi32(1 << 29)));
            }
            /* the key's high half (its low half is zero) */
            _mm512_mask_storeu_epi32(high_halves + j, k, h);
        }
    }
    #elif RS_ISA_AVX2
    /* eight rays' high halves from row[t] + j (masked: only the lanes of mask) */
    RS_INLINE __m256i rs_keysort_window8(const int n_tables, const float *const *row,
                                         const __m256 *scale, const __m256i *table,
                                         const float *dx, const float *dy, const float *dz,
                                         int octant, int j, int masked, __m256i mask)
    {
        const __m256 zero = _mm256_setzero_ps();
        __m256i h = _mm256_setzero_si256();
        for (int t = 0; t < n_tables; ++t) {
            __m256 c = masked ? _mm256_maskload_ps(row[t] + j, mask)
                              : _mm256_loadu_ps(row[t] + j);
            h = _mm256_or_si256(h, _mm256_permutevar8x32_epi32(
                table[t], rs_keysort_quantise8(c, scale[t])));
        }
        if (octant) {
            const float *d[3] = {dx, dy, dz};
            for (int a = 0; a < 3; ++a) {
                __m256 v = masked ? _mm256_maskload_ps(d[a] + j, mask)
                                  : _mm256_loadu_ps(d[a] + j);
                h = _mm256_or_si256(h, _mm256_and_si256(
                    _mm256_castps_si256(_mm256_cmp_ps(v, zero, _CMP_LT_OQ)),
                    _mm256_set1_epi32((int32_t)(0x80000000u >> a))));
            }
        }
        return h;
    }
    RS_INLINE void rs_keysort_window_keys_n(const int n_tables, const float *c, int stride,
                                            int m, const int *coord, const int *shift,
                                            const uint32_t *tables, const float *dx,
                                            const float *dy, const float *dz, int octant,
                                            uint32_t *high_halves)
    {
        __m256i table[2 * RS_KEYSORT_TABLE_SLOTS];
        __m256 scale[2 * RS_KEYSORT_TABLE_SLOTS];
        const float *row[2 * RS_KEYSORT_TABLE_SLOTS];
        for (int t = 0; t < n_tables; ++t) {
            table[t] = _mm256_loadu_si256((const __m256i *)(tables + 32 * t));
            scale[t] = _mm256_set1_ps(rs_keysort_window_scale(shift[t]));
            row[t] = c + coord[t] * stride;
        }
        int j = 0;
        for (; j + 8 <= m; j += 8)
            _mm256_storeu_si256((__m256i *)(high_halves + j), rs_keysort_window8(
                n_tables, row, scale, table, dx, dy, dz, octant, j, 0, _mm256_setzero_si256()));
        if (j < m) {                /* the last rays: not read past m, not written */
            __m256i mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(m - j),
                                              _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
            _mm256_maskstore_epi32((int *)(high_halves + j), mask, rs_keysort_window8(
                n_tables, row, scale, table, dx, dy, dz, octant, j, 1, mask));
        }
    }
    #endif
    #if RS_ISA_AVX2
    static void rs_keysort_window_keys(const float *c, int stride, int m, int n_tables,
                                       const int *coord, const int *shift,
                                       const uint32_t *tables, const float *dx,
                                       const float *dy, const float *dz, int octant,
                                       uint32_t *high_halves)
    {
        if (n_tables == RS_KEYSORT_TABLE_SLOTS)
            rs_keysort_window_keys_n(RS_KEYSORT_TABLE_SLOTS, c, stride, m, coord, shift,
                                     tables, dx, dy, dz, octant, high_halves);
        else
            rs_keysort_window_keys_n(2 * RS_KEYSORT_TABLE_SLOTS, c, stride, m, coord, shift,
                                     tables, dx, dy, dz, octant, high_halves);
    }
    #else
    static void rs_keysort_window_keys(const float *c, int stride, int m, int n_tables,
                                       const int *coord, const int *shift,
                                       const uint32_t *tables, const float *dx,
                                       const float *dy, const float *dz, int octant,
                                       uint32_t *high_halves)
    {
        (void)c; (void)stride; (void)m; (void)n_tables; (void)coord; (void)shift;
        (void)tables; (void)dx; (void)dy; (void)dz; (void)octant; (void)high_halves;
    }
    #endif
    static inline int rs_keysort_popcount64(uint64_t x)
    {
    #if defined(__GNUC__) || defined(__clang__)
        return __builtin_popcountll(x);
    #else
        int n = 0;
        for (; x; x &= x - 1) ++n;
        return n;
    #endif
    }
    static inline int rs_keysort_ctz64(uint64_t x)
    {
    #if defined(__GNUC__) || defined(__clang__)
        return __builtin_ctzll(x);
    #else
        int n = 0;
        while (!(x & 1)) { x >>= 1; ++n; }
        return n;
    #endif
    }
    /* The runs of equal values of k[0, n) (n >= 1): run c starts at pos[c] (and
     * pos[runs] = n), head[c] = its value | c; returns the number of runs.  Sixteen
     * values at a time (eight with AVX2), each vector's run starts compressed to their
     * place, with no branch on the values (RS_KEYSORT_RUN_HEADS: the avx2 and avx512
     * builds). */
    #define RS_KEYSORT_RUN_HEADS RS_ISA_AVX2
    #if RS_ISA_AVX512
    static const int32_t rs_keysort_lane16[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12,
                                                  13, 14, 15};
    static int rs_keysort_run_heads(const uint32_t *k, int n, int32_t *pos, uint32_t *head)
    {
        const __m512i iota = _mm512_loadu_si512((const void *)rs_keysort_lane16);
        __m512i id = iota;
        int r = 0;
        for (int j = 0; j < n; j += 16) {
            __mmask16 t = n - j >= 16 ? (__mmask16)0xFFFF : (__mmask16)((1u << (n - j)) - 1);
            __mmask16 first = j ? (__mmask16)0 : (__mmask16)1;   /* k[-1] is not read */
            __m512i cur = _mm512_maskz_loadu_epi32(t, k + j);
            __m512i prev = _mm512_maskz_loadu_epi32((__mmask16)(t & ~first), k + j - 1);
            __mmask16 h = (__mmask16)(_mm512_mask_cmpneq_epi32_mask(t, cur, prev) | first);
            int got = rs_keysort_popcount64(h);
            __mmask16 put = (__mmask16)((1u << got) - 1);
            _mm512_mask_storeu_epi32(pos + r, put, _mm512_maskz_compress_epi32(h, id));
            _mm512_mask_storeu_epi32(head + r, put, _mm512_or_si512(
                _mm512_maskz_compress_epi32(h, cur),
                _mm512_add_epi32(iota, _mm512_set1_epi32(r))));
            r += got;
            id = _mm512_add_epi32(id, _mm512_set1_epi32(16));
        }
        pos[r] = n;
        return r;
    }
    /* out[0, 16) = first, first + 1, ...: a run's first sixteen rays, one store */
    RS_INLINE void rs_keysort_iota16(int32_t *out, int32_t first)
    {
        _mm512_storeu_si512((void *)out, _mm512_add_epi32(
            _mm512_loadu_si512((const void *)rs_keysort_lane16), _mm512_set1_epi32(first)));
    }
    #elif RS_ISA_AVX2
    /* eight values at a time, the first alone (k[-1] is not read) and the last few
     * (fewer than eight) one by one: a vector's stores, at r <= j, end within [0, n);
     * the compress is a permutation looked up by the mask (lanes.h) */
    static int rs_keysort_run_heads(const uint32_t *k, int n, int32_t *pos, uint32_t *head)
    {
        const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        __m256i id = _mm256_add_epi32(iota, _mm256_set1_epi32(1));
        int r = 1, j = 1;
        pos[0] = 0;
        head[0] = k[0];
        for (; j + 8 <= n; j += 8) {
            __m256i cur = _mm256_loadu_si256((const __m256i *)(k + j));
            __m256i prev = _mm256_loadu_si256((const __m256i *)(k + j - 1));
            int h = 0xFF & ~_mm256_movemask_ps(_mm256_castsi256_ps(
                _mm256_cmpeq_epi32(cur, prev)));
            __m256i lane = sw_compress_lanes(h);
            _mm256_storeu_si256((__m256i *)(pos + r), _mm256_permutevar8x32_epi32(id, lane));
            _mm256_storeu_si256((__m256i *)(head + r), _mm256_or_si256(
                _mm256_permutevar8x32_epi32(cur, lane),
                _mm256_add_epi32(iota, _mm256_set1_epi32(r))));
            r += rs_popcount(h);
            id = _mm256_add_epi32(id, _mm256_set1_epi32(8));
        }
        for (; j < n; ++j)
            if (k[j] != k[j - 1]) {
                pos[r] = j;
                head[r] = k[j] | (uint32_t)r;
                ++r;
            }
        pos[r] = n;
        return r;
    }
    /* out[0, 16) = first, first + 1, ...: a run's first sixteen rays, two stores */
    RS_INLINE void rs_keysort_iota16(int32_t *out, int32_t first)
    {
        const __m256i base = _mm256_set1_epi32(first);
        _mm256_storeu_si256((__m256i *)out, _mm256_add_epi32(
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), base));
        _mm256_storeu_si256((__m256i *)(out + 8), _mm256_add_epi32(
            _mm256_setr_epi32(8, 9, 10, 11, 12, 13, 14, 15), base));
    }
    #endif
    #if RS_ISA_AVX2
    /* The rays of sorted runs (head[j] & idx = the run, at pos[run] .. pos[run + 1]),
     * each run's in order after the last's, to out: sixteen at a time (up to 15 values
     * past the last), a loop only for runs longer than sixteen rays (rare: the loop a
     * run at a time, eight at a time, missed its exit once in four runs after a trace).
     * The positions where the top bits (split) of the sorted keys change go to group
     * (the first at 0, then n after the last); returns their number. */
    static int rs_keysort_place_runs(const uint32_t *head, int runs, const int32_t *pos,
                                     uint32_t idx, uint32_t split, int32_t start,
                                     int32_t *out, int32_t *group)
    {
        int at = 0, ng = 0;
        uint32_t g = 0;
        for (int j = 0; j < runs; ++j) {
            uint32_t key = head[j];
            int c = (int)(key & idx), first = pos[c], len = pos[c + 1] - first;
            rs_keysort_iota16(out + at, start + first);
            for (int k = 16; k < len; k += 16)
                rs_keysort_iota16(out + at + k, start + first + k);
            group[ng] = at;             /* (overwritten unless a group starts here) */
            ng += (j == 0) | ((key & split) != g);
            g = key & split;
            at += len;
        }
        group[ng] = at;
        return ng;
    }
    #else
    static int rs_keysort_run_heads(const uint32_t *k, int n, int32_t *pos, uint32_t *head)
    {
        return -1;
    }
    static int rs_keysort_place_runs(const uint32_t *head, int runs, const int32_t *pos,
                                     uint32_t idx, uint32_t split, int32_t start,
                                     int32_t *out, int32_t *group)
    {
        return -1;
    }
    #endif
    """
    void quantise "rs_keysort_quantise"(const float *c, int32_t *q, int m) noexcept nogil
    int clz64 "rs_keysort_clz64"(uint64_t x) noexcept nogil
    void prefetch_out "rs_keysort_prefetch_out"(int32_t *out, int n) noexcept nogil
    int ctz64 "rs_keysort_ctz64"(uint64_t x) noexcept nogil
    int popcount64 "rs_keysort_popcount64"(uint64_t x) noexcept nogil
    void iota "rs_keysort_iota"(int32_t *out, int32_t first, int len) noexcept nogil
    void ray_order "rs_keysort_ray_order"(const uint32_t *k32, int n, uint32_t idx,
                                          int32_t start, int32_t *out) noexcept nogil
    bint WINDOWS "RS_KEYSORT_WINDOWS"
    bint RUN_HEADS "RS_KEYSORT_RUN_HEADS"
    int run_heads "rs_keysort_run_heads"(const uint32_t *k, int n, int32_t *pos,
                                         uint32_t *head) noexcept nogil
    int place_runs "rs_keysort_place_runs"(const uint32_t *head, int runs, const int32_t *pos,
                                           uint32_t idx, uint32_t split, int32_t start,
                                           int32_t *out, int32_t *group) noexcept nogil
    int TABLE_SLOTS "RS_KEYSORT_TABLE_SLOTS"
    int WINDOW_BITS "RS_KEYSORT_WINDOW_BITS"
    void window_keys "rs_keysort_window_keys"(const float *c, int stride, int m, int n_tables,
                                              const int *coord, const int *shift,
                                              const uint32_t *tables, const float *dx,
                                              const float *dy, const float *dz, bint octant,
                                              uint32_t *high_halves) noexcept nogil
    void directions "rs_keysort_directions"(const float *const *o, const float *const *d,
                                            bint octahedral, int m, float *c, int stride,
                                            const float *lo, const float *scale) noexcept nogil
    void end_points "rs_keysort_end_points"(const float *const *o, const float *const *d,
                                            const float *tmax, const float *prev, int m,
                                            float *c, int stride, const float *lo,
                                            const float *hi, const float *scale,
                                            float length, float prev_scale,
                                            float shrink) noexcept nogil
    void scatter_pass "rs_keysort_scatter"(const uint64_t *src, uint64_t *dst, int32_t *out,
                                           int n, int shift, uint64_t dmask, int32_t *h,
                                           int32_t base, uint64_t low, int coherent) noexcept nogil


# Packed keys are all different, so any correct sort of them gives the stable order.
# The avx2 and avx512 builds sort them with NumPy's own quicksort, which NumPy runs as
# its AVX2 or AVX-512 sort (x86-simd-sort) on a CPU that has them: as 32-bit compact
# keys (sort_compact) where the varying bits and the index fit, which took 0.44-0.65x
# the radix sort's time in place after a trace with AVX-512 and 0.64-0.74x with NumPy's
# AVX2 sort; and, in the avx512 build only, as 64-bit keys where they do not (NumPy's
# AVX2 sort of 64-bit keys took 1.2x the radix's time).  NumPy's scalar sort took 3x:
# the sse2 and scalar builds, for CPUs without AVX2, keep the radix sort (BENCHMARKS.md
# §10).  Reached through NumPy's C API (the dtype's sort functions), so that each large
# packet's call costs no Python call.
ctypedef int (*sort_fn)(void *start, cnp.npy_intp n, void *array) noexcept nogil
cdef extern from "numpy/arrayobject.h":
    ctypedef struct PyArray_ArrFuncs:
        void *sort[3]               # indexed by NPY_SORTKIND
    PyArray_ArrFuncs *PyDataType_GetArrFuncs(cnp.dtype descr)
    enum: NPY_QUICKSORT
cdef extern from "raysort/simd.h":
    enum: RS_ISA_AVX2, RS_ISA_AVX512
cnp.import_array()
cdef sort_fn sort_u64 = <sort_fn> PyDataType_GetArrFuncs(np.dtype(np.uint64)).sort[NPY_QUICKSORT]
cdef sort_fn sort_u32 = <sort_fn> PyDataType_GetArrFuncs(np.dtype(np.uint32)).sort[NPY_QUICKSORT]
cdef bint COMPACT_SORT = RS_ISA_AVX2 and sort_u32 != NULL
cdef bint LIBRARY_SORT = RS_ISA_AVX512 and sort_u64 != NULL
#: whether this build sorts 32-bit compact keys with NumPy's sort, where they fit
compact_sort = COMPACT_SORT
#: whether this build sorts the other packed keys with NumPy's sort (else: the radix sort)
library_sort = LIBRARY_SORT


cdef struct KeyInputs:
    # the rays' rows, the scene box and the key's recipe: what ray_keys reads
    const float *o[3]
    const float *d[3]
    const float *tmax
    const float *prev_t         # NULL: no previous hit distances
    int mode                    # a value of COORDINATES
    float lo[3]
    float hi[3]
    float scale[3]              # 1 / box extent, 0 on a flat axis
    float length
    float prev_scale
    const uint64_t *table       # (MAX_COORDS, 2, 256) from key_table
    bint low_bytes              # the table uses the low byte of some coordinate
    bint octant
    # when it does not: the key is the OR of n_lookups entries of pair tables, entry
    # l indexed by the top used bits of coordinates first[l] and second[l] (see
    # plan_lookups)
    int n_lookups
    int first[KEY_COORDS]
    int second[KEY_COORDS]
    int shift_first[KEY_COORDS]
    int shift_second[KEY_COORDS]
    int width_second[KEY_COORDS]
    uint64_t pairs[KEY_COORDS][TABLE_ROW]
    # or, where the build and the table allow (see plan_windows), the high half of the
    # key as the OR of n_windows tables (32 entries each, of which AVX2 reads 8), table
    # t indexed by a window of bits of coordinate win_coord[t]'s high byte (its
    # quantised value >> win_shift[t])
    bint windows
    int n_windows
    int win_coord[MAX_WINDOWS]
    int win_shift[MAX_WINDOWS]
    uint32_t win_tables[MAX_WINDOWS * 32]


cdef void block_coordinates(const KeyInputs *a, int b, int m, float *c) noexcept nogil:
    """The coordinates of rays [b, b + m) (m <= BLOCK) into c[k * BLOCK + j]: one loop
    in C for each mode (rs_keysort_directions, rs_keysort_end_points), which the
    compiler vectorises; every ray gets the same IEEE operations in the same order
    whatever the ISA, so keys are the same on every build."""
    cdef int k
    cdef const float *o_rows[3]
    cdef const float *d_rows[3]
    for k in range(3):
        o_rows[k] = a.o[k] + b
        d_rows[k] = a.d[k] + b
    if a.mode == END_POINT:     # o + L d/|d|
        end_points(o_rows, d_rows, a.tmax + b, a.prev_t + b if a.prev_t != NULL else NULL,
                   m, c, BLOCK, a.lo, a.hi, a.scale, a.length, a.prev_scale, EXIT_SHRINK)
    else:
        directions(o_rows, d_rows, a.mode == DIR_OCTAHEDRAL, m, c, BLOCK, a.lo, a.scale)


cdef int used_bits(const uint64_t *row) noexcept nogil:
    """How many top bits of a coordinate's high byte a table row depends on: 8 - k for
    the largest k such that the row is constant on aligned blocks of 2^k entries, that
    is, every change between neighbours falls on a multiple of 2^k (one pass)."""
    cdef int x, k = 8
    for x in range(1, TABLE_ROW):
        if row[x] != row[x - 1]:
            k = min(k, ctz64(<uint64_t> x))
    return 8 - k


cdef void plan_lookups(KeyInputs *a, int n_coords) noexcept nogil:
    """Pair the coordinates of a short key (the table reads only their high bytes) so
    that one lookup serves two: a coordinate whose row depends on its top ``u`` bits
    and one on its top ``v`` bits, ``u + v <= 8``, share a table of ``2^(u + v)``
    entries (each the OR of their two rows' entries).  The default keys need three
    lookups per ray instead of five or six; the keys are the same."""
    cdef int k, j, l, best, ia, ib
    cdef int u[KEY_COORDS]
    cdef bint done[KEY_COORDS]
    cdef const uint64_t *row_a
    cdef const uint64_t *row_b
    for k in range(KEY_COORDS):
        row_a = a.table + (2 * k + 1) * TABLE_ROW
        u[k] = used_bits(row_a)
        # a coordinate the key does not draw from (or one the mode does not compute)
        done[k] = k >= n_coords or (u[k] == 0 and row_a[0] == 0)
    a.n_lookups = 0
    while True:
        # the widest coordinate left, with the widest partner that fits beside it
        k = -1
        for j in range(KEY_COORDS):
            if not done[j] and (k < 0 or u[j] > u[k]):
                k = j
        if k < 0:
            return
        done[k] = True
        best = -1
        for j in range(KEY_COORDS):
            if not done[j] and u[k] + u[j] <= 8 and (best < 0 or u[j] > u[best]):
                best = j
        l = a.n_lookups
        a.n_lookups += 1
        a.first[l], a.shift_first[l] = k, COORD_BITS_C - u[k]
        row_a = a.table + (2 * k + 1) * TABLE_ROW
        if best < 0:            # alone: the second index is q >> 16 = 0
            a.second[l], a.shift_second[l], a.width_second[l] = k, COORD_BITS_C, 0
            for ia in range(1 << u[k]):
                a.pairs[l][ia] = row_a[(ia << (8 - u[k])) & 0xFF]
            continue
        done[best] = True
        a.second[l], a.shift_second[l], a.width_second[l] = best, COORD_BITS_C - u[best], u[best]
        row_b = a.table + (2 * best + 1) * TABLE_ROW
        for ia in range(1 << u[k]):
            for ib in range(1 << u[best]):
                a.pairs[l][ia << u[best] | ib] = (row_a[(ia << (8 - u[k])) & 0xFF]
                                                  | row_b[(ib << (8 - u[best])) & 0xFF])


# the C kernel's table slots: TABLE_SLOTS or twice that, at most MAX_WINDOWS
assert 2 * TABLE_SLOTS <= MAX_WINDOWS


cdef void plan_windows(KeyInputs *a, int n_coords) noexcept nogil:
    """Set ``a.windows`` where the vectorised lookups give the keys of the scalar path
    (rs_keysort_window_keys): on a build that has them, for a short key whose table
    rows are each the OR of their entries for the windows of the high byte (its top
    ``WINDOW_BITS`` bits, the next ``WINDOW_BITS``, ...; as every interleave is: each
    coordinate bit sets its own key bit) and whose bits all lie in the key's high 32
    bits after the octant's shift.  A coordinate takes its top window, and each lower
    one whose entries are not all its row's first."""
    cdef int k, x, i, w, n = 0, out_shift = 35 if a.octant else 32
    cdef int n_win = (8 + WINDOW_BITS - 1) // WINDOW_BITS     # windows of a byte
    cdef int bottom[8]          # each window's lowest bit in the byte
    cdef int mask[8]            # each window's bits
    cdef uint64_t low = (<uint64_t> 1 << out_shift) - 1
    cdef const uint64_t *row
    cdef uint64_t every, joined
    cdef bint varies[8]
    a.windows = False
    if not WINDOWS or a.low_bytes:
        return
    for w in range(n_win):
        bottom[w] = max(8 - WINDOW_BITS * (w + 1), 0)
        mask[w] = ((1 << (8 - WINDOW_BITS * w)) - 1) & ~((1 << bottom[w]) - 1)
    for k in range(n_coords):
        row = a.table + (2 * k + 1) * TABLE_ROW
        every = 0
        for w in range(n_win):
            varies[w] = False
        for x in range(TABLE_ROW):
            joined = 0
            for w in range(n_win):
                joined |= row[x & mask[w]]
                varies[w] |= row[x & mask[w]] != row[0]
            if row[x] != joined or row[x] & low:
                return
            every |= row[x]
        if every == 0:                  # the key draws nothing from this coordinate
            continue
        for w in range(n_win):
            if w > 0 and not varies[w]:
                continue
            for i in range(32):
                a.win_tables[32 * n + i] = <uint32_t> (row[(i << bottom[w]) & mask[w]]
                                                       >> out_shift)
            a.win_coord[n], a.win_shift[n] = k, 8 + bottom[w]
            n += 1
    # unused tables (zero, of coordinate 0) up to TABLE_SLOTS or twice that: the loop over
    # them is unrolled
    a.n_windows = TABLE_SLOTS if n <= TABLE_SLOTS else 2 * TABLE_SLOTS
    for n in range(n, a.n_windows):
        for i in range(32):
            a.win_tables[32 * n + i] = 0
        a.win_coord[n], a.win_shift[n] = 0, 8
    a.windows = True


cdef void window_high_halves(const KeyInputs *a, int start, int n,
                             uint32_t *high_halves) noexcept nogil:
    """The high halves of the keys of rays [start, start + n) into high_halves[0, n)
    where ``a.windows`` (their low halves are zero), BLOCK rays at a time."""
    cdef float c[KEY_COORDS * BLOCK]
    cdef int b = start, m
    while b < start + n:
        m = min(<int> BLOCK, start + n - b)
        block_coordinates(a, b, m, c)
        window_keys(c, BLOCK, m, a.n_windows, a.win_coord, a.win_shift, a.win_tables,
                    a.d[0] + b, a.d[1] + b, a.d[2] + b, a.octant, high_halves + (b - start))
        b += m


cdef void ray_keys(const KeyInputs *a, int start, int n, uint64_t *keys) noexcept nogil:
    """The keys of rays [start, start + n) into keys[0, n), BLOCK rays at a time."""
    cdef int b, j, k, m, n_coords = 5 if a.mode == DIR_OCTAHEDRAL else 6
    cdef float c[KEY_COORDS * BLOCK]
    cdef int32_t q[KEY_COORDS * BLOCK]
    cdef uint64_t *kb
    cdef int32_t index[KEY_COORDS * BLOCK]
    cdef const int32_t *q0
    cdef const int32_t *r0
    cdef int32_t *out
    cdef const uint64_t *p0
    cdef const uint64_t *p1
    cdef const uint64_t *p2
    cdef int s0, t0, w0
    cdef const float *dx
    cdef const float *dy
    cdef const float *dz
    # the table's rows (see key_table): coordinate k's low byte, then its high byte
    cdef const uint64_t *low[KEY_COORDS]
    cdef const uint64_t *high[KEY_COORDS]
    for k in range(KEY_COORDS):
        low[k] = a.table + (2 * k) * TABLE_ROW
        high[k] = a.table + (2 * k + 1) * TABLE_ROW
    cdef uint32_t *high_halves = <uint32_t *> keys
    if a.windows:
        # the high halves to the buffer's first half, then each widened in place, the
        # last first (key j's bytes hold high halves 2j and 2j + 1, read already)
        window_high_halves(a, start, n, high_halves)
        for j in range(n - 1, -1, -1):
            keys[j] = <uint64_t> high_halves[j] << 32
        return
    b = start
    while b < start + n:
        m = min(<int> BLOCK, start + n - b)
        block_coordinates(a, b, m, c)
        for k in range(n_coords):
            quantise(&c[k * BLOCK], &q[k * BLOCK], m)
        # the key is the OR of one table entry per byte of each quantised coordinate
        kb = keys + (b - start)
        if not a.low_bytes:
            # each lookup's index (a loop the compiler vectorises), then the lookups
            for k in range(a.n_lookups):
                q0, r0, out = &q[a.first[k] * BLOCK], &q[a.second[k] * BLOCK], &index[k * BLOCK]
                s0, t0, w0 = a.shift_first[k], a.shift_second[k], a.width_second[k]
                for j in range(m):
                    out[j] = (q0[j] >> s0) << w0 | r0[j] >> t0
            if a.n_lookups == 3:    # the default keys: one loop, no stores
                p0 = a.pairs[0]
                p1 = a.pairs[1]
                p2 = a.pairs[2]
                for j in range(m):
                    kb[j] = p0[index[j]] | p1[index[BLOCK + j]] | p2[index[2 * BLOCK + j]]
            else:
                for j in range(m):
                    kb[j] = 0
                for k in range(a.n_lookups):
                    p0 = a.pairs[k]
                    out = &index[k * BLOCK]
                    for j in range(m):
                        kb[j] |= p0[out[j]]
        else:                   # a long key: both bytes of every coordinate
            for j in range(m):
                kb[j] = 0
            for k in range(n_coords):
                for j in range(m):
                    kb[j] |= low[k][q[k * BLOCK + j] & 255] | high[k][q[k * BLOCK + j] >> 8]
        if a.octant:            # the direction's octant first (bit k: d[k] < 0)
            dx, dy, dz = a.d[0] + b, a.d[1] + b, a.d[2] + b
            for j in range(m):
                kb[j] = (kb[j] >> 3 | <uint64_t> (dx[j] < 0) << 63
                         | <uint64_t> (dy[j] < 0) << 62 | <uint64_t> (dz[j] < 0) << 61)
        b += m


cdef class _Inputs:
    """A :c:type:`KeyInputs` and the arrays it points into (kept alive with it)."""
    cdef KeyInputs a
    cdef object keep
    cdef readonly int n


def _inputs(rays, str coordinates, bounds, const uint64_t[:, :, ::1] table, float length,
            prev_t, float prev_scale, bint octant):
    """Check the arguments of :func:`make_keys` and :func:`sort_rays` into an :class:`_Inputs`."""
    cdef _Inputs out = _Inputs()
    cdef int n = len(rays), k
    if coordinates not in COORDINATES:
        raise ValueError(f"coordinates must be one of {', '.join(COORDINATES)}; "
                         f"got {coordinates!r}")
    if table.shape[0] != MAX_COORDS or table.shape[1] != 2 or table.shape[2] != 256:
        raise ValueError(f"a key table has shape ({MAX_COORDS}, 2, 256), got "
                         f"{(table.shape[0], table.shape[1], table.shape[2])}")
    cdef const float[:, ::1] box = np.ascontiguousarray(bounds, dtype=np.float32).reshape(2, 3)
    cdef float extent
    cdef float inv[3]
    for k in range(3):
        # 1 / extent, 0 on a flat (or inverted, or non-finite) axis: it carries no order
        extent = box[1, k] - box[0, k]
        inv[k] = ONE / extent if extent > 0 else 0
        if not inv[k] < INFINITY:
            inv[k] = 0
    # the batch's rows themselves (RS_RAY_*), as nah reads them: no view per row
    cdef const float[:, ::1] data = rays.data
    cdef const float[::1] row
    if data.shape[0] != RS_RAY_ROWS or data.shape[1] < n:
        raise ValueError(f"rays.data must hold the {RS_RAY_ROWS} rows of {n} rays")
    if prev_t is not None:
        prev_t = np.ascontiguousarray(prev_t, dtype=np.float32)
        if prev_t.shape != (n,):
            raise ConfigError(f"rays.prev_t has {prev_t.size} values for {n} rays")
    out.keep = (rays.data, prev_t, table)
    out.n = n
    if n == 0:
        return out
    # first: a plan copied from the last one overwrites every field
    plan(&out.a, &table[0, 0, 0], COORDINATES[coordinates], octant)
    for k in range(3):
        out.a.o[k] = &data[RS_RAY_OX + k, 0]
        out.a.d[k] = &data[RS_RAY_DX + k, 0]
        out.a.lo[k] = box[0, k]
        out.a.hi[k] = box[1, k]
        out.a.scale[k] = inv[k]
    out.a.tmax = &data[RS_RAY_TMAX, 0]
    out.a.prev_t = NULL
    if prev_t is not None:
        row = prev_t
        out.a.prev_t = &row[0]
    out.a.length = length
    out.a.prev_scale = prev_scale
    return out


# the last key plan made (its own copy of the table in keep): a sorter's next call, with
# the same table, mode and octant, copies it instead of planning again (3 of the 8 us a
# call cost before the rays: the table scans of plan_lookups and plan_windows)
cdef _Inputs last_plan = None


cdef void plan(KeyInputs *a, const uint64_t *table, int mode, bint octant) except *:
    """The fields of ``a`` that depend only on the table, the mode and the octant flag
    (set first: a plan copied from ``last_plan`` overwrites every field)."""
    global last_plan
    cdef int k, j, n_coords = 5 if mode == DIR_OCTAHEDRAL else 6
    cdef object copy
    cdef const uint64_t[::1] flat
    if (last_plan is not None and last_plan.a.mode == mode and last_plan.a.octant == octant
            and memcmp(last_plan.a.table, table, TABLE_BYTES) == 0):
        a[0] = last_plan.a
        a.table = table
        return
    a.mode = mode
    a.octant = octant
    a.table = table
    a.low_bytes = False
    for k in range(MAX_COORDS):
        for j in range(TABLE_ROW):
            a.low_bytes |= table[2 * k * TABLE_ROW + j] != 0
    plan_windows(a, n_coords)
    if not a.low_bytes and not a.windows:      # (the window keys need no pair tables)
        plan_lookups(a, n_coords)
    copy = np.frombuffer((<const char *> table)[:TABLE_BYTES], np.uint64).copy()
    flat = copy
    last_plan = _Inputs()
    last_plan.a = a[0]
    last_plan.a.table = &flat[0]
    last_plan.keep = copy


def make_keys(rays, str coordinates, bounds, const uint64_t[:, :, ::1] table, *,
              float length=0, prev_t=None, float prev_scale=1, bint octant=False):
    """uint64 keys of a :class:`~raysort.rays.RayBatch` (see the module docstring).

    ``coordinates``: a key of :data:`COORDINATES`; ``bounds``: the (2, 3) scene box;
    ``table``: from :func:`key_table`; ``length``: the end-point distance (world
    units) where ``prev_t`` (float32 per ray, or None) is not a positive finite
    number, which otherwise gives ``prev_t * prev_scale``; ``octant``: the top
    :data:`OCTANT_BITS` bits are the signs of the direction, the table's key follows.
    """
    cdef _Inputs inputs = _inputs(rays, coordinates, bounds, table, length, prev_t,
                                  prev_scale, octant)
    out = np.empty(inputs.n, dtype=np.uint64)
    cdef uint64_t[::1] keys = out
    if inputs.n:
        with nogil:
            ray_keys(&inputs.a, 0, inputs.n, &keys[0])
    return out


def key_table(levels):
    """The lookup table of a bit split: ``levels`` lists, most significant first, the
    coordinates that give their next most significant bit at each level.

    ``[(0, 1, 2)] * 3 + [(0, 1, 2, 3, 4, 5)] * 8`` is three levels of origin bits
    followed by eight levels of 6-D interleave (Meister's AILA layout).  Key bits
    run from bit 63 down; at most 64 bits and :data:`COORD_BITS` levels of a
    coordinate.  Returns ``(table, bits)``.
    """
    table = np.zeros((MAX_COORDS, 2, 256), dtype=np.uint64)
    used = [0] * MAX_COORDS
    pos = 63
    byte = np.arange(256, dtype=np.uint64)
    for level in levels:
        for coord in level:
            if not 0 <= coord < MAX_COORDS:
                raise ValueError(f"a key draws from coordinates 0..{MAX_COORDS - 1}, got {coord}")
            if used[coord] == COORD_BITS:
                raise ValueError(f"coordinate {coord} has only {COORD_BITS} bits")
            if pos < 0:
                raise ValueError("a key holds at most 64 bits")
            bit = COORD_BITS - 1 - used[coord]            # next most significant bit
            half, b = divmod(bit, 8)
            table[coord, half] |= ((byte >> np.uint64(b)) & np.uint64(1)) << np.uint64(pos)
            used[coord] += 1
            pos -= 1
    return table, 63 - pos


# ---------------------------------------------------------------------------------------
# sorting

cdef void digit_plan(uint64_t vary, int n, int floor, int *low_bit, int *width,
                     int *passes) noexcept nogil:
    """The radix digits that sort keys whose varying bits are ``vary``: ``passes``
    digits of ``width`` bits, the lowest starting at bit ``low_bit``, covering every
    bit from the highest to the lowest set bit of ``vary`` (bits that are the same in
    every key cannot change the order).  A digit is at most :data:`MAX_DIGIT_BITS`
    bits and has at most about as many buckets as there are keys (a histogram much
    larger than the keys costs more to sum than a pass saves).  No digit reaches
    below bit ``floor`` (the bottom of the sorted bits of a key that carries no
    index in its low bits), nor above bit 63."""
    cdef int top, bottom, span, widest = MIN_DIGIT
    if vary == 0:
        low_bit[0], width[0], passes[0] = 0, 1, 0
        return
    while widest < MAX_DIGIT and (1 << (widest + 1)) <= n:
        widest += 1
    top = 63 - clz64(vary)
    bottom = ctz64(vary)
    span = top - bottom + 1
    passes[0] = (span + widest - 1) // widest
    width[0] = (span + passes[0] - 1) // passes[0]
    # the digits end at the top bit; the lowest may reach below the bottom one (those
    # bits are the same in every key, or the ray index of a packed key: both keep the
    # sort stable), but not below floor (then the top digit holds a few constant bits)
    low_bit[0] = max(top + 1 - passes[0] * width[0], floor)


def _windows(str coordinates, const uint64_t[:, :, ::1] table, bint octant):
    """Whether this build makes the keys of ``table`` in vector registers (and sorts their
    high halves): :func:`plan_windows` (for the tests)."""
    cdef KeyInputs a
    plan(&a, &table[0, 0, 0], COORDINATES[coordinates], octant)
    return bool(a.windows)


def _digit_plan(uint64_t vary, int n, int floor=0):
    """``(low_bit, width, passes)`` of :func:`digit_plan` (for the tests)."""
    cdef int low_bit, width, passes
    digit_plan(vary, n, floor, &low_bit, &width, &passes)
    return low_bit, width, passes


cdef int radix_sort(uint64_t *key, int32_t *item, uint64_t *key_tmp, int32_t *item_tmp,
                    int n, int low_bit, int width, int passes, int32_t *count,
                    int32_t *out, int32_t base, uint64_t low) noexcept nogil:
    """Stable LSD radix sort of (key, item) by ``passes`` digits of ``width`` bits,
    the lowest at bit ``low_bit``; item may be NULL (the item is then in the key's
    low bits).  ``count[p << width:(p + 1) << width]`` holds the histogram of digit
    p of the keys; the sort uses it up.

    With ``out`` (only when item is NULL), the sort also writes ``base + (key & low)``
    of each sorted key to out (the ray index a packed key carries), in its last pass.

    Returns 1 when the result is in the tmp arrays, 0 when in key/item."""
    cdef int i, p, shift, flip = 0, last = -1, buckets = 1 << width
    cdef int32_t pos, c, most
    cdef int32_t *h
    cdef uint64_t *ks = key
    cdef uint64_t *kd = key_tmp
    cdef int32_t *is_ = item
    cdef int32_t *id_ = item_tmp
    cdef uint64_t *kt
    cdef int32_t *it
    cdef uint64_t k, dmask = <uint64_t> buckets - 1
    for p in range(passes):
        # every key has this digit: the pass would not move anything
        if count[p * buckets + ((key[0] >> (low_bit + p * width)) & dmask)] != n:
            last = p
    if out != NULL and last < 0:
        for i in range(n):
            out[i] = base + <int32_t> (ks[i] & low)
    for p in range(last + 1):
        shift = low_bit + p * width
        h = count + p * buckets
        if h[(key[0] >> shift) & dmask] == n:
            continue
        pos = 0
        most = 0
        for i in range(buckets):
            c = h[i]
            h[i] = pos
            pos += c
            most = max(most, c)
        if item == NULL:
            scatter_pass(ks, kd, out if p == last else NULL, n, shift, dmask, h, base, low,
                         2 * most > n)
        else:
            for i in range(n):
                k = ks[i]
                c = h[(k >> shift) & dmask]
                h[(k >> shift) & dmask] = c + 1
                kd[c] = k
                id_[c] = is_[i]
            it = is_
            is_ = id_
            id_ = it
        kt = ks
        ks = kd
        kd = kt
        flip ^= 1
    return flip


ctypedef fused key_t:
    uint32_t                # compact keys, and the window keys (their high halves)
    uint64_t


cdef int sort_packet(const key_t *keys, int start, int end, int digits, bint compress,
                     int packet_size, int split_bits, int32_t *order, int32_t *offsets,
                     uint64_t *ckey, int32_t *citem, uint64_t *ckey_tmp, int32_t *citem_tmp,
                     int32_t *cstart, uint64_t *skey, int32_t *count) noexcept nogil:
    """Sort rays [start, end), whose keys are keys[0, end - start), into
    order[start:end]; write sub-packet starts to offsets and return their number.
    Work buffers hold end - start (+1) items, ``count`` :data:`COUNT_SIZE` ints.
    32-bit keys are the high halves of 64-bit keys whose low halves are zero (the
    window keys: half the bytes to write and read); where neither the packet's order
    nor a 32-bit compact sort serves, they are widened and :func:`sort_wide` sorts
    them."""
    cdef int i, c, runs
    cdef int descents
    cdef key_t all_and, all_or, kmask
    cdef uint64_t mask, vary
    cdef int n = end - start, bits = 8 * digits
    # (sort_wide's rule: the chunk's index fits below the key)
    cdef bint packed = bits <= 48 and split_bits <= bits and n <= (<int64_t> 1) << (64 - bits)
    mask = (~(<uint64_t> 0) << (64 - bits)) if bits < 64 else ~(<uint64_t> 0)
    kmask = <key_t> (mask >> (64 - 8 * sizeof(key_t)))
    # the bits that differ between keys: only those are sorted on; the runs of equal
    # keys: compression pays only when they are long (the order is the same); and
    # whether the sorted bits ever descend (one loop the compiler vectorises)
    all_and, all_or = keys[0], keys[0]
    runs = 1
    descents = 0
    for i in range(1, n):
        all_and &= keys[i]
        all_or |= keys[i]
        runs += keys[i] != keys[i - 1]
        descents |= (keys[i] & kmask) < (keys[i - 1] & kmask)
    vary = (<uint64_t> (all_and ^ all_or) << (64 - 8 * sizeof(key_t))) & mask
    compress = compress and 2 * runs <= n
    if not compress and not descents:
        # already in order (coherent rays often are: camera rays in their tile's Morton
        # order): the stable sort leaves every ray where it is.  (Not where long runs of
        # equal keys make the compressed sort cheap anyway.)
        iota(order + start, start, n)
        return cut_packets(keys, n, start, packet_size, split_bits, split_bits <= bits,
                           offsets)
    if RUN_HEADS and COMPACT_SORT and packed and RUNS_PER_RAY * runs <= n:
        c = sort_runs(keys, n, start, vary, runs, split_bits, packet_size, order, offsets,
                      <uint32_t *> citem, <uint32_t *> citem_tmp, cstart)
        if c >= 0:
            return c
    if packed and not compress and COMPACT_SORT:
        c = sort_compact(keys, n, start, vary, split_bits, packet_size, order, offsets,
                         <uint32_t *> citem)
        if c >= 0:
            return c
    if key_t is uint64_t:
        return sort_wide(keys, start, end, digits, compress, runs, vary, packet_size,
                         split_bits, order, offsets, ckey, citem, ckey_tmp, citem_tmp, cstart,
                         skey, count)
    else:
        for i in range(n):
            ckey[i] = <uint64_t> keys[i] << 32
        return sort_wide(ckey, start, end, digits, compress, runs, vary, packet_size,
                         split_bits, order, offsets, ckey, citem, ckey_tmp, citem_tmp, cstart,
                         skey, count)


cdef int sort_wide(const uint64_t *keys, int start, int end, int digits, bint compress,
                   int runs, uint64_t vary, int packet_size, int split_bits, int32_t *order,
                   int32_t *offsets, uint64_t *ckey, int32_t *citem, uint64_t *ckey_tmp,
                   int32_t *citem_tmp, int32_t *cstart, uint64_t *skey,
                   int32_t *count) noexcept nogil:
    """:func:`sort_packet` of 64-bit keys by NumPy's sort of 64-bit keys (avx512 builds)
    or the radix sort, ``runs``, ``vary`` (the sorted bits that differ between keys) and
    ``compress`` (whether to sort runs as chunks) as sort_packet found them."""
    cdef int i, j, nc = 0, flip, low_bit, width, passes, buckets, shift1, shift2
    cdef uint64_t mask, low, key, dmask
    cdef int32_t *h1
    cdef int32_t *h2
    # a chunk is every ray, or (compress) every run of equal keys in input order
    cdef int n = end - start, bits = 8 * digits
    # the chunk's index goes into the key's low bits, which the sort does not look at,
    # when they have room for it (so one array moves instead of two); the index is in
    # input order, so the sort stays stable
    cdef bint packed = bits <= 48 and split_bits <= bits and n <= (<int64_t> 1) << (64 - bits)
    cdef int32_t *items = NULL if packed else citem
    mask = (~(<uint64_t> 0) << (64 - bits)) if bits < 64 else ~(<uint64_t> 0)
    low = ~mask
    cdef bint simple = packed and not compress, library = LIBRARY_SORT and packed
    if library:
        # the packed keys are all different: NumPy's sort of them is the stable sort
        if simple:
            for i in range(n):
                ckey[i] = (keys[i] & mask) | <uint64_t> i
            nc = n
        else:
            nc = make_chunks(keys, start, end, compress, runs, True, mask, ckey, citem, cstart)
        sort_u64(ckey, nc, NULL)
        if simple:
            for i in range(n):
                order[start + i] = start + <int32_t> (ckey[i] & low)
            return cut_packets(ckey, n, start, packet_size, split_bits, split_bits <= bits,
                               offsets)
        return finish_packet(ckey, citem, nc, n, start, compress, packed, low, cstart,
                             packet_size, split_bits, split_bits <= bits, order, offsets, skey)
    digit_plan(vary, n, 0 if packed else 64 - bits, &low_bit, &width, &passes)
    buckets = 1 << width
    dmask = <uint64_t> buckets - 1
    # up to three digits are counted in one loop without tests (the histograms of
    # digits beyond passes are counted too, and not used)
    memset(count, 0, max(passes, 3) * buckets * sizeof(int32_t))
    shift1 = min(low_bit + width, 63)       # (a shift by 64 would be undefined)
    shift2 = min(low_bit + 2 * width, 63)
    h1, h2 = count + buckets, count + 2 * buckets
    # chunks and the radix sort's histograms (keys may be ckey itself: chunk nc <= ray
    # i is written after ray i is read)
    if simple:                      # the common case, in one tight loop
        if passes <= 3:
            for i in range(n):
                key = keys[i]
                ckey[i] = (key & mask) | <uint64_t> i
                count[(key >> low_bit) & dmask] += 1
                h1[(key >> shift1) & dmask] += 1
                h2[(key >> shift2) & dmask] += 1
        else:
            for i in range(n):
                key = keys[i]
                ckey[i] = (key & mask) | <uint64_t> i
                for j in range(passes):
                    count[j * buckets + ((key >> (low_bit + j * width)) & dmask)] += 1
        nc = n
    else:
        nc = make_chunks(keys, start, end, compress, runs, packed, mask, ckey, citem, cstart)
        for i in range(nc):
            key = ckey[i]
            count[(key >> low_bit) & dmask] += 1
            h1[(key >> shift1) & dmask] += 1
            h2[(key >> shift2) & dmask] += 1
            for j in range(3, passes):
                count[j * buckets + ((key >> (low_bit + j * width)) & dmask)] += 1
    # (a packed sort writes the order in its last pass)
    flip = radix_sort(ckey, items, ckey_tmp, citem_tmp, nc, low_bit, width, passes, count,
                      order + start if simple else NULL, start, low)
    if simple:
        return cut_packets(ckey_tmp if flip else ckey, n, start, packet_size, split_bits,
                           split_bits <= bits, offsets)
    return finish_packet(ckey_tmp if flip else ckey, citem_tmp if flip else citem, nc, n,
                         start, compress, packed, low, cstart, packet_size, split_bits,
                         split_bits <= bits, order, offsets, skey)


cdef int compact_plan(uint64_t vary, int index_bits, int split_bits, int *top,
                      int *bottom, int *q) noexcept nogil:
    """Where the bits of a 32-bit compact key come from: the bits that vary between the
    packet's keys (``vary``), in their order, at its top, ``index_bits`` below them.
    Returns the number of runs of key bits [bottom[r], top[r]] (highest first) to
    gather, or -1 when they do not fit; ``q`` = the compact key's top bits that hold the
    key's top ``split_bits`` (their varying bits).

    Bits that are the same in every key cannot change the order; a gather of each run of
    set bits of ``vary`` would take several passes over the keys, so the gaps between
    runs (constant bits) are kept, smallest first, as long as the key still fits, which
    leaves the keys of a bounce's 1024-ray packet one to three runs."""
    cdef int nrun = 0, j, r, gap, width, lowest, p
    cdef uint64_t v = vary, run, splits
    if vary and 64 - clz64(vary) - ctz64(vary) + index_bits <= 32:
        # every gap fits: the joins below would end in this one run
        top[0], bottom[0] = 63 - clz64(vary), ctz64(vary)
        nrun = 1
        v = 0
    # the runs of set bits of vary, highest first
    while v:
        top[nrun] = 63 - clz64(v)
        run = ~v & ((<uint64_t> 2 << top[nrun]) - 1)    # the clear bits below the top
        bottom[nrun] = 0 if run == 0 else 64 - clz64(run)
        v &= ~(((<uint64_t> 2 << top[nrun]) - 1) ^ ((<uint64_t> 1 << bottom[nrun]) - 1))
        nrun += 1
    width = popcount64(vary)
    if width + index_bits > 32:
        return -1
    while nrun > 1:             # join the two runs with the smallest gap, if it fits
        j = 0
        for r in range(1, nrun - 1):
            if bottom[r] - top[r + 1] < bottom[j] - top[j + 1]:
                j = r
        gap = bottom[j] - top[j + 1] - 1
        if width + gap + index_bits > 32:
            break
        width += gap
        bottom[j] = bottom[j + 1]
        for r in range(j + 1, nrun - 1):
            top[r], bottom[r] = top[r + 1], bottom[r + 1]
        nrun -= 1
    # the key's top split_bits: their varying bits are the compact key's top q bits
    splits = 0 if split_bits == 0 else vary & (~(<uint64_t> 0) << (64 - split_bits))
    lowest = ctz64(splits) if splits else 64
    p = 32                      # the top of the next run in the compact key
    q[0] = 0
    for r in range(nrun):
        p -= top[r] - bottom[r] + 1
        if bottom[r] <= lowest <= top[r]:
            q[0] = 32 - p - (lowest - bottom[r])
    return nrun


cdef void compact_keys(const key_t *keys, int n, int nrun, const int *top,
                       const int *bottom, bint with_index, uint32_t *k32) noexcept nogil:
    """k32[i] = the runs of bits of keys[i] that :func:`compact_plan` chose, from the top,
    and (``with_index``) i below them: the first run's pass writes k32, the others OR
    into it."""
    cdef int r, i, p = 32
    if nrun == 0:
        for i in range(n):
            k32[i] = <uint32_t> i if with_index else 0
    for r in range(nrun):
        p -= top[r] - bottom[r] + 1
        gather_run(keys, n, bottom[r], top[r] - bottom[r] + 1, p, r == 0, with_index, k32)


cdef int bits_for(int n) noexcept nogil:
    """The bits an index below n takes."""
    cdef int b = 0
    while (<int64_t> 1 << b) < n:
        b += 1
    return b


cdef int sort_compact(const key_t *keys, int n, int start, uint64_t vary, int split_bits,
                      int packet_size, int32_t *order, int32_t *offsets,
                      uint32_t *k32) noexcept nogil:
    """:func:`sort_packet` of rays [start, start + n) with 32-bit compact keys
    (:func:`compact_plan`), each ray's index below its bits, when they fit; returns the
    number of sub-packets, or -1 (nothing written) when they do not fit.  NumPy sorts
    32-bit keys in half the time of 64-bit ones."""
    cdef int top[64]
    cdef int bottom[64]
    cdef int q, index_bits = bits_for(n)
    cdef int nrun = compact_plan(vary, index_bits, split_bits, top, bottom, &q)
    if nrun < 0:
        return -1
    compact_keys(keys, n, nrun, top, bottom, True, k32)
    sort_u32(k32, n, NULL)
    ray_order(k32, n, (<uint32_t> 1 << index_bits) - 1, start, order + start)
    return cut_packets(k32, n, start, packet_size, q, True, offsets)


cdef int sort_runs(const key_t *keys, int n, int start, uint64_t vary, int runs,
                   int split_bits, int packet_size, int32_t *order, int32_t *offsets,
                   uint32_t *k32, uint32_t *head, int32_t *pos) noexcept nogil:
    """:func:`sort_compact` by runs of equal keys (avx2 and avx512 builds: RUN_HEADS), for
    packets whose keys come in runs (shadow rays: one run in 4 to 7 rays): each run's
    compact key, its run number below its bits, sorted (the run number keeps the sort
    stable), then each run's rays written in order at its place (IOTA_SPILL past).
    ``runs`` bounds the number of runs.  Returns the number of sub-packets, or -1
    (nothing written) when the compact keys do not fit."""
    cdef int top[64]
    cdef int bottom[64]
    cdef int i, j, q, groups, n_sub = 0, index_bits = bits_for(runs)
    cdef int nrun = compact_plan(vary, index_bits, split_bits, top, bottom, &q)
    cdef int32_t *group = <int32_t *> k32
    cdef uint32_t idx = (<uint32_t> 1 << index_bits) - 1
    cdef uint32_t split = 0 if q == 0 else ~(<uint32_t> 0) << (32 - q)
    if nrun < 0:
        return -1
    compact_keys(keys, n, nrun, top, bottom, False, k32)
    runs = run_heads(k32, n, pos, head)
    sort_u32(head, runs, NULL)
    # each run's rays at its place; a sub-packet where the top q bits change (the
    # groups, their starts to k32, free now), and after every packet_size rays of the
    # same top bits (cut_packets' rule)
    groups = place_runs(head, runs, pos, idx, split, start, order + start, group)
    for j in range(groups):
        i = group[j]
        while i < group[j + 1]:
            offsets[n_sub] = start + i
            n_sub += 1
            i += packet_size
    return n_sub


cdef inline void gather_run(const key_t *keys, int n, int bottom, int length, int at,
                            bint first, bint with_index, uint32_t *k32) noexcept nogil:
    """k32[i] |= bits [bottom, bottom + length) of keys[i], placed at bit ``at`` (``first``:
    k32[i] =, with i itself below them where ``with_index``); 32-bit keys are the high
    halves of 64-bit keys (bottom >= 32)."""
    cdef uint64_t m = (<uint64_t> 1 << length) - 1
    cdef int i
    bottom -= 64 - 8 * sizeof(key_t)
    if first and with_index:
        for i in range(n):
            k32[i] = <uint32_t> ((keys[i] >> bottom) & m) << at | <uint32_t> i
    elif first:
        for i in range(n):
            k32[i] = <uint32_t> ((keys[i] >> bottom) & m) << at
    else:
        for i in range(n):
            k32[i] |= <uint32_t> ((keys[i] >> bottom) & m) << at


cdef inline void put_chunk(int nc, uint64_t key, int32_t first, bint packed, uint64_t mask,
                           uint64_t *ckey, int32_t *citem, int32_t *cstart) noexcept nogil:
    """Chunk nc's key (packed: with nc in the low bits, else nc to citem) and first ray."""
    if packed:
        ckey[nc] = (key & mask) | <uint64_t> nc
    else:
        ckey[nc] = key
        citem[nc] = nc
    cstart[nc] = first


cdef int make_chunks(const uint64_t *keys, int start, int end, bint compress, int runs,
                     bint packed, uint64_t mask, uint64_t *ckey, int32_t *citem,
                     int32_t *cstart) noexcept nogil:
    """The chunks of rays [start, end) (keys[0, end - start)) to sort: every ray, or
    (compress) every run of equal keys in input order (``runs`` of them).  Writes each
    chunk's key (packed: with its index in the low bits, else the index to citem) and
    its first ray to cstart (and the end after the last); returns their number.  keys
    may be ckey: chunk nc <= ray i is written after ray i is read.

    Where runs are long (camera rays: one run in 20 to 1,000 rays), a test per ray
    that rarely changes its answer; else without branches: every ray writes the next
    chunk's slot and the count moves on where a run starts, so that a later run's
    first ray overwrites the slot.  Run starts are data the branch predictor cannot
    learn (except from the same keys sorted again and again, as a warm loop of sorts
    does): after a trace, the branchy loop took 0.21 ms of garanzha's sort of
    Sibenik's shadow rays (one run in 3 rays), the branchless one 0.17 ms, and 1.34x
    the time on its camera rays."""
    cdef int i, n = end - start, nc = 0, every = not compress
    cdef uint64_t key, prev = ~keys[0] if n else 0     # the first ray starts a run
    if compress and 8 * runs <= n:
        for i in range(n):
            key = keys[i]
            if key != prev:
                put_chunk(nc, key, start + i, packed, mask, ckey, citem, cstart)
                nc += 1
            prev = key
    else:
        for i in range(n):
            key = keys[i]
            put_chunk(nc, key, start + i, packed, mask, ckey, citem, cstart)
            nc += (key != prev) | every
            prev = key
    cstart[nc] = end
    return nc


cdef int finish_packet(const uint64_t *sk, const int32_t *si, int nc, int n, int start,
                       bint compress, bint packed, uint64_t low, const int32_t *cstart,
                       int packet_size, int split_bits, bint grouped, int32_t *order,
                       int32_t *offsets, uint64_t *skey) noexcept nogil:
    """The order of rays [start, start + n) from their nc sorted chunks (keys ``sk``,
    and with unpacked keys, indices ``si``), then :func:`cut_packets`."""
    cdef int i, j, c, pos
    if compress:
        # decompress: each chunk's rays, in input order, at the chunk's sorted place
        pos = start
        for j in range(nc):
            c = <int> (sk[j] & low) if packed else si[j]
            iota(order + pos, cstart[c], cstart[c + 1] - cstart[c])
            pos += cstart[c + 1] - cstart[c]
        if split_bits:      # (cut_packets reads the keys only to cut at their top bits)
            pos = 0
            for j in range(nc):
                c = <int> (sk[j] & low) if packed else si[j]
                for i in range(pos, pos + cstart[c + 1] - cstart[c]):
                    skey[i] = sk[j]
                pos += cstart[c + 1] - cstart[c]
            sk = skey
    else:
        for j in range(nc):
            order[start + j] = start + si[j]
    return cut_packets(sk, n, start, packet_size, split_bits, grouped, offsets)


cdef int cut_packets(const key_t *sk, int n, int start, int packet_size, int split_bits,
                     bint grouped, int32_t *offsets) noexcept nogil:
    """Cut keys ``sk[0, n)`` of rays [start, start + n) into sub-packets: a new one
    where the key's top ``split_bits`` bits change, and after every ``packet_size``
    rays of the same top bits.  Writes the sub-packets' starts to ``offsets`` and
    returns their number.  ``grouped``: keys with the same top bits are next to each
    other (they are sorted on them), so each group's end is found by a search, not
    by looking at every key."""
    cdef key_t mask = 0 if split_bits == 0 else ~(<key_t> 0) << (8 * sizeof(key_t) - split_bits)
    cdef key_t top
    cdef int c = 0, g = 0, i, end, lo, hi, mid, step
    while g < n:
        # the group of keys with sk[g]'s top bits: [g, end)
        end = n
        if mask != 0:
            top = sk[g] & mask
            if grouped:
                # doubling steps, then halving: sk[lo] is in the group, hi is past it
                step = 1
                while g + step < n and (sk[g + step] & mask) == top:
                    step *= 2
                lo, hi = g + step // 2, min(g + step, n)
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    if (sk[mid] & mask) == top:
                        lo = mid
                    else:
                        hi = mid
                end = hi
            else:
                end = g + 1
                while end < n and (sk[end] & mask) == top:
                    end += 1
        i = g
        while i < end:
            offsets[c] = start + i
            c += 1
            i += packet_size
        g = end
    return c


cdef object sort_packets(const KeyInputs *a, const uint64_t *keys, const int32_t[::1] packets,
                         int n, int digits, bint compress, int packet_size, int split_bits):
    """``(order, offsets)`` of every large packet, from ``keys`` or, when ``a`` is not
    NULL, from keys computed packet by packet just before the packet is sorted (they
    are still in the cache then)."""
    cdef int n_packets = packets.shape[0] - 1, p, n_sub = 0, widest = 1
    if not 1 <= digits <= 8 or not 1 <= packet_size or not 0 <= split_bits <= 64:
        raise ValueError(f"digits 1..8, packet_size >= 1, split_bits 0..64; got {digits}, "
                         f"{packet_size}, {split_bits}")
    if n_packets < 0 or packets[0] != 0 or packets[n_packets] != n:
        raise ValueError(f"large packets must start at 0 and end at the {n} rays")
    for p in range(n_packets):
        if packets[p + 1] < packets[p]:
            raise ValueError(f"large packet {p} ends before it starts")
        widest = max(widest, packets[p + 1] - packets[p])
    order = np.empty(n + IOTA_SPILL + 1, dtype=np.int32)     # (room for iota past the end)
    offsets = np.empty(n + 1, dtype=np.int32)
    cdef int32_t[::1] order_mv = order, offsets_mv = offsets
    # the work buffers, in one allocation: three of uint64 keys, then of int32 items (two,
    # the chunk starts, the radix counts)
    cdef uint64_t[::1] work = np.empty(3 * widest + (3 * widest + 1 + COUNT_SIZE + 1) // 2,
                                       np.uint64)
    cdef uint64_t *ckey = &work[0]
    cdef uint64_t *ckey_tmp = ckey + widest
    cdef uint64_t *skey = ckey_tmp + widest
    cdef int32_t *citem = <int32_t *> (skey + widest)
    cdef int32_t *citem_tmp = citem + widest
    cdef int32_t *cstart = citem_tmp + widest
    cdef int32_t *count = cstart + widest + 1
    cdef const uint64_t *kp
    with nogil:
        for p in range(n_packets):
            if packets[p + 1] > packets[p]:
                prefetch_out(&order_mv[packets[p]], packets[p + 1] - packets[p])
                if a != NULL and a.windows and split_bits <= 32:   # the keys' high halves
                    window_high_halves(a, packets[p], packets[p + 1] - packets[p],
                                       <uint32_t *> skey)
                    n_sub += sort_packet(<const uint32_t *> skey, packets[p], packets[p + 1],
                                         digits, compress, packet_size, split_bits,
                                         &order_mv[0], &offsets_mv[n_sub], ckey, citem,
                                         ckey_tmp, citem_tmp, cstart, skey, count)
                    continue
                if a != NULL:       # sort_packet reads the keys from its own work buffer
                    ray_keys(a, packets[p], packets[p + 1] - packets[p], ckey)
                    kp = ckey
                else:
                    kp = keys + packets[p]
                n_sub += sort_packet(kp, packets[p], packets[p + 1], digits, compress,
                                     packet_size, split_bits, &order_mv[0], &offsets_mv[n_sub],
                                     ckey, citem, ckey_tmp, citem_tmp, cstart, skey, count)
    offsets_mv[n_sub] = n
    return order[:n], offsets[:n_sub + 1].copy()


def sort_keys(const uint64_t[::1] keys, const int32_t[::1] packets, int digits, *,
              bint compress=False, int packet_size=64, int split_bits=0):
    """``(order, offsets)``: rays sorted by key within each large packet (see the module
    docstring); ``digits`` = how many top bytes of the key are sorted (1..8)."""
    return sort_packets(NULL, &keys[0] if keys.shape[0] else NULL, packets, keys.shape[0],
                        digits, compress, packet_size, split_bits)


def sort_rays(rays, str coordinates, bounds, const uint64_t[:, :, ::1] table,
              const int32_t[::1] packets, int digits, *, float length=0, prev_t=None,
              float prev_scale=1, bint octant=False, bint compress=False, int packet_size=64,
              int split_bits=0):
    """:func:`sort_keys` of the keys :func:`make_keys` gives (the same order and
    offsets), each large packet's keys made just before it is sorted."""
    cdef _Inputs inputs = _inputs(rays, coordinates, bounds, table, length, prev_t,
                                  prev_scale, octant)
    return sort_packets(&inputs.a, NULL, packets, inputs.n, digits, compress, packet_size,
                        split_bits)


# ---------------------------------------------------------------------------------------
# the plugin base

class KeySorter(Sorter):
    """A sorter that orders each large packet by a uint64 key per ray.

    A subclass sets ``self.levels`` (the bit split, see :func:`key_table`),
    ``self.coordinates`` (a key of :data:`COORDINATES`), ``self.packet_size`` and
    ``self.split_bits``, and may override :meth:`end_length` (two-point keys) and
    :attr:`compress`.
    """

    trusted = True
    #: Garanzha and Loop's compress-sort-decompress (same order, fewer items to sort)
    compress = False

    def _setup(self, levels, bits, packet_size, split_bits, octant=False):
        """Validate the common parameters and build the key table.

        ``octant``: prefix the key with the direction's octant and never let a
        sub-packet mix octants (the key's ``bits`` then include the 3 octant bits)."""
        self.packet_size = integer("packet_size", packet_size, 1, MAX_PACKET)
        self.octant = boolean("octant", octant)
        prefix = OCTANT_BITS if self.octant else 0
        levels = _truncate(levels, 64 - prefix)
        self.bits = integer("bits", bits, 1 + prefix, prefix + sum(len(lv) for lv in levels))
        self._table, _ = key_table(_truncate(levels, self.bits - prefix))
        self.split_bits = integer("split_bits", split_bits, 0, self.bits)
        self._split = max(self.split_bits, prefix)
        self._digits = (self.bits + 7) // 8

    def end_length(self, rays, bounds):
        """``(length, prev_t, prev_scale)`` for end-point keys (world units)."""
        return 0.0, None, 1.0

    def keys(self, rays, bounds):
        """The uint64 key of every ray (left aligned, ``bits`` significant bits)."""
        length, prev_t, prev_scale = self.end_length(rays, bounds)
        return isa.module("sorters._keysort").make_keys(
            rays, self.coordinates, bounds, self._table, length=length, prev_t=prev_t,
            prev_scale=prev_scale, octant=self.octant)

    def sort(self, rays, packets, bounds):
        # the pipeline's packets go straight to the kernel, which checks the rest (from
        # 0, never decreasing); check_packets names what is wrong
        plain = plain_packets(packets, len(rays))
        if not plain:
            packets = check_packets(packets, len(rays))
        length, prev_t, prev_scale = self.end_length(rays, bounds)
        try:
            return isa.module("sorters._keysort").sort_rays(
                rays, self.coordinates, bounds, self._table, packets, self._digits,
                length=length, prev_t=prev_t, prev_scale=prev_scale, octant=self.octant,
                compress=self.compress, packet_size=self.packet_size, split_bits=self._split)
        except ValueError:
            if plain:
                check_packets(packets, len(rays))
            raise


def _truncate(levels, bits):
    """The first ``bits`` key bits of a bit split (the last level may be cut short)."""
    out = []
    for level in levels:
        if bits <= 0:
            break
        level = tuple(level)[:bits]
        out.append(level)
        bits -= len(level)
    return out


def scene_diagonal(bounds):
    """Length of the scene box's diagonal (0 for an empty or non-finite box)."""
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3).tolist()
    diag = math.sqrt(sum((b - a) * (b - a) for a, b in zip(lo, hi)))
    return diag if math.isfinite(diag) else 0.0
