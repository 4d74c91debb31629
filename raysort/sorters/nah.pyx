"""``nah``: the ray sorter of Nah, Jung, Park and Han (section 3 of the paper).

Per large packet, in linear time and touching only ray indices:

1. every ray goes to one of 24 direction buckets (octant x major axis), and
   each bucket's origin bounding box is grown in the same pass;
2. each bucket gets an origin grid of 1 to 8 cells: an axis is split in two at
   the middle of the bucket's origin box when the box is wider on that axis
   than ``threshold`` (a quarter) of the scene root box;
3. a counting sort on (bucket, cell) gives the order; every non-empty cell
   becomes sub-packets of at most ``packet_size`` rays (64, Manta's
   ``RayPacket::MaxSize``, which bounded the paper's sub-packets).

Camera rays, and shadow rays toward a light, come in long runs of one bucket:
where a large packet's buckets average ``LONG_RUNS`` rays or more per run, the
origin bounds, the cells and the counting sort go a run at a time (a vector
min and max over the run's origins, one piece of the order per run) instead
of ray by ray, with the same result.  Where a large packet holds at most
``RS_NAH_FEW`` buckets (shadow rays toward a light; also where they alternate between
buckets ray by ray), the avx512 and avx2 builds go a bucket, then a (bucket, cell) key,
at a time over the whole packet, a vector of rays at a time under a mask, with no
branch on the rays; the avx512 build finds every packet's cells a vector at a time.

Rays with NaN components land in a defined bucket and cell (comparisons with
NaN are false), so the sorter never fails on them; the gather marks them
inactive.
"""
from libc.stdint cimport int32_t, uint8_t, uint32_t
from libc.math cimport INFINITY
from raysort._types cimport (rs_minf, rs_maxf, RS_RAY_OX, RS_RAY_DX, RS_RAY_DY, RS_RAY_DZ,
                             RS_RAY_ROWS)

import operator

import numpy as np

from raysort import isa
from raysort.sdk import (MAX_PACKET, ConfigError, Sorter, check_packets, fixed_packets,
                         integer, number, plain_packets)

cdef extern from *:
    """
    #include "raysort/lanes.h"
    /* octant * 3 + major axis; octant bit k is set when component k is negative.  The
     * major axis is the first of the largest |components| (y beats x only when larger,
     * z beats the larger of them only when larger), chosen without branches: for
     * diffuse rays a branch on it would mispredict every other ray. */
    static inline int rs_nah_bucket(float dx, float dy, float dz)
    {
        int octant = (dx < 0) | (dy < 0) << 1 | (dz < 0) << 2;
        float ax = fabsf(dx), ay = fabsf(dy), az = fabsf(dz);
        int y_wins = ay > ax;
        int z_wins = az > rs_maxf(ay, ax);
        return octant * 3 + y_wins + z_wins * (2 - y_wins);
    }
    /* key[i] = the bucket of ray i, in a loop the compiler vectorises */
    static void rs_nah_buckets(const float *RS_RESTRICT dx, const float *RS_RESTRICT dy,
                               const float *RS_RESTRICT dz, int n, uint8_t *RS_RESTRICT key)
    {
        for (int i = 0; i < n; ++i)
            key[i] = (uint8_t)rs_nah_bucket(dx[i], dy[i], dz[i]);
    }
    /* How many times key[i] != key[i - 1] in key[0, n): the runs of equal keys, less
     * one (a loop the compiler vectorises). */
    static int rs_nah_changes(const uint8_t *key, int n)
    {
        int c = 0;
        for (int i = 1; i < n; ++i)
            c += key[i] != key[i - 1];
        return c;
    }
    /* The buckets present in key[0, n), bit b for bucket b (a vectorised loop). */
    static uint32_t rs_nah_present(const uint8_t *key, int n)
    {
        uint32_t present = 0;
        for (int i = 0; i < n; ++i)
            present |= 1u << (key[i] & 31);
        return present;
    }
    /* Where the run of key[i] that starts at i ends (i < n): 32 keys at a time with
     * AVX2, else 8, the first that differs found from the lowest set bit of the
     * comparison's mask.  The key buffer has RS_NAH_RUN_SLACK bytes past n, which a
     * load may read (whatever they hold, the end is capped at n).  Runs shorter than
     * the step, most of them, leave the loop at its first test; a loop over the keys
     * one by one missed its exit once per run, which the branch predictor cannot
     * learn after a trace (nah's sort after a trace: Sibenik's and Sponza's shadow rays
     * 0.92x and 0.85x the time, camera rays 0.83x). */
    #define RS_NAH_RUN_SLACK 32
    static inline int rs_nah_run_end(const uint8_t *key, int i, int n)
    {
        int e = i + 1;
    #if RS_ISA_AVX2
        const __m256i same = _mm256_set1_epi8((char)key[i]);
        for (;;) {
            unsigned differ = ~(unsigned)_mm256_movemask_epi8(_mm256_cmpeq_epi8(
                _mm256_loadu_si256((const __m256i *)(key + e)), same));
            if (differ) {
                e += __builtin_ctz(differ);
                break;
            }
            e += 32;
            if (e >= n)
                break;
        }
    #elif (defined(__GNUC__) || defined(__clang__)) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
        const uint64_t same = 0x0101010101010101ull * key[i];
        uint64_t word;
        for (;;) {
            memcpy(&word, key + e, 8);
            if (word != same) {     /* key[e] is the word's lowest byte */
                e += __builtin_ctzll(word ^ same) >> 3;
                break;
            }
            e += 8;
            if (e >= n)
                break;
        }
    #else
        while (e < n && key[e] == key[i])
            ++e;
    #endif
        return e < n ? e : n;
    }
    /* Grow lo, hi (3 each) by rs_minf(x, lo) and rs_maxf(x, hi) over the m values of
     * each row o[a]: RS_SW lanes at a time, then across the lanes.  The same min and
     * max as ray by ray (NaN is skipped either way, as MINPS/MAXPS return the second
     * operand; only the sign of a zero bound may differ, which no cell test sees). */
    static void rs_nah_grow(const float *const o[3], int m, float *lo, float *hi)
    {
        for (int a = 0; a < 3; ++a) {
            const float *x = o[a];
            float l = lo[a], h = hi[a];
            int j = 0;
            if (m >= RS_SW) {
                rs_swf vl = sw_set1(INFINITY), vh = sw_set1(-INFINITY);
                float tl[RS_SW], th[RS_SW];
                for (; j + RS_SW <= m; j += RS_SW) {
                    rs_swf v = sw_loadu(x + j);
                    vl = sw_min(v, vl);
                    vh = sw_max(v, vh);
                }
                sw_store(tl, vl);
                sw_store(th, vh);
                for (int k = 0; k < RS_SW; ++k) {
                    l = rs_minf(tl[k], l);
                    h = rs_maxf(th[k], h);
                }
            }
            for (; j < m; ++j) {
                l = rs_minf(x[j], l);
                h = rs_maxf(x[j], h);
            }
            lo[a] = l;
            hi[a] = h;
        }
    }
    /* Pass 1's bounds for rays whose buckets come in long runs (camera and shadow rays):
     * each run of rays start + [i, e) with one bucket grows that bucket's origin box a
     * vector at a time, instead of every ray updating its bucket's box in turn (a chain
     * through memory). */
    static void rs_nah_run_bounds(const float *const o[3], int start, const uint8_t *key,
                                  int n, float (*lo)[3], float (*hi)[3])
    {
        const float *at[3];
        for (int i = 0, e; i < n; i = e) {
            e = rs_nah_run_end(key, i, n);
            for (int a = 0; a < 3; ++a)
                at[a] = o[a] + start + i;
            rs_nah_grow(at, e - i, lo[key[i]], hi[key[i]]);
        }
    }
    /* Pass 2 for buckets in long runs: key = bucket * 8 + origin-grid cell, a run of
     * one bucket at a time, its grid's middles and split axes fixed (grid_cell's bits:
     * one per split axis, in axis order). */
    static void rs_nah_run_cells(const float *const o[3], int start, uint8_t *key, int n,
                                 const uint8_t *axes, const float (*mid)[3])
    {
        const float *x = o[0] + start, *y = o[1] + start, *z = o[2] + start;
        for (int i = 0, e; i < n; i = e) {
            e = rs_nah_run_end(key, i, n);
            int b = key[i], s0 = axes[b] & 1, s1 = axes[b] >> 1 & 1, s2 = axes[b] >> 2 & 1;
            int bit1 = s0, bit2 = s0 + s1;
            float m0 = mid[b][0], m1 = mid[b][1], m2 = mid[b][2];
            for (int j = i; j < e; ++j)
                key[j] = (uint8_t)(b * 8 + (((x[j] >= m0) & s0) | ((y[j] >= m1) & s1) << bit1
                                           | ((z[j] >= m2) & s2) << bit2));
        }
    }
    /* The counting sort for keys in long runs: the counts by run, then each run's rays
     * written in one piece at its key's place (the same order as ray by ray). */
    static void rs_nah_count_runs(const uint8_t *key, int n, int *count)
    {
        for (int i = 0, e; i < n; i = e) {
            e = rs_nah_run_end(key, i, n);
            count[key[i]] += e - i;
        }
    }
    static void rs_nah_place_runs(const uint8_t *key, int start, int end, const int *count,
                                  int n_keys, int32_t *order)
    {
        int at[256];            /* a key is a byte */
        memcpy(at, count, n_keys * sizeof(int));
        for (int i = 0, e; i < end - start; i = e) {
            e = rs_nah_run_end(key, i, end - start);
            int32_t *out = order + at[key[i]];
            at[key[i]] += e - i;
            for (int j = 0; j < e - i; ++j)
                out[j] = start + i + j;
        }
    }
    /* The counting sort's last step: ray i goes to order[count[key]++].  Functions of
     * their own (not inlined into sort_packet), each a loop that keeps everything in
     * registers.  How fast a count's update reaches the next load of the same count
     * decides the speed, and the best form depends on the rays (Zen 3, AVX2, 65,536
     * Sibenik rays; the whole sort took 0.84 ms on diffuse and 0.69 ms on camera
     * rays with this loop inlined):
     * - the counts through a pointer, for most rays: diffuse rays 0.84 -> 0.67 ms
     *   (camera rays 0.69 -> 0.77 ms);
     * - a copy of the counts on the stack, for coherent rays (camera rays: most rays
     *   update one count, ray after ray), whose store-to-load forwarding the CPU
     *   renames (a stack slot): camera rays 0.69 -> 0.66 ms (diffuse rays 0.84 ->
     *   0.81 ms: there the renaming mispredicts).
     * (Pass 1 written the same two ways measured slower than as it is.) */
    __attribute__((noinline))
    static void rs_nah_place(const uint8_t *key, int start, int end, int *count,
                             int32_t *order)
    {
        for (int i = start; i < end; ++i)
            order[count[key[i - start]]++] = i;
    }
    /* The counts of keys[0, n) into count (zeroed), through a pointer (see above), in a
     * pass of their own: counted in pass 2's loop, in its stack array, the sort took
     * 0.68 ms on diffuse and 0.66 ms on camera rays; so 0.60 and 0.56 ms. */
    __attribute__((noinline))
    static void rs_nah_count(const uint8_t *key, int n, int *count)
    {
        for (int i = 0; i < n; ++i)
            count[key[i]]++;
    }
    __attribute__((noinline))
    static void rs_nah_place_coherent(const uint8_t *key, int start, int end,
                                      const int *count, int n_keys, int32_t *order)
    {
        int at[256];            /* a key is a byte */
        memcpy(at, count, n_keys * sizeof(int));
        for (int i = start; i < end; ++i)
            order[at[key[i - start]]++] = i;
    }
    /* The few-key passes (avx512 and avx2 builds).  Shadow rays toward a light fill few
     * direction buckets of a packet (Sibenik's: two in half the packets, at most seven),
     * but where a packet straddles a bucket's border they alternate between buckets ray
     * by ray: the run passes above then go ray by ray, each ray's box update a chain
     * through memory, and each run's end is a branch a trace leaves unlearnt.  Where a
     * packet holds at most RS_NAH_FEW buckets (and keys), the sort reads the whole
     * packet once per bucket (key), a vector of rays at a time under a mask of its
     * rays, with no branch on the rays (the avx512 build: the cells of any packet
     * sixteen at a time).
     * Results equal the ray-by-ray passes': min and max taken in another order (the
     * same values: NaN skipped, as MINPS returns the second operand; only a zero
     * bound's sign may differ, which no cell test sees), the same comparisons for the
     * cells, each key's rays written in ray order. */
    #define RS_NAH_FEW 8
    /* The cell bit of each axis in a bucket's grid (grid_cell's numbering: one bit per
     * split axis, in axis order; 0 for an axis not split). */
    static inline void rs_nah_cell_bits(uint8_t axes, int32_t bit[3])
    {
        int s0 = axes & 1, s1 = axes >> 1 & 1, s2 = axes >> 2 & 1;
        bit[0] = s0;
        bit[1] = s1 << s0;
        bit[2] = s2 << (s0 + s1);
    }
    static void rs_nah_identity(int start, int n, int32_t *order)   /* one key */
    {
        int32_t *out = order + start;
        for (int i = 0; i < n; ++i)
            out[i] = start + i;
    }
    #if RS_ISA_AVX512
    #define RS_NAH_VECTOR 1
    #define RS_NAH_TABLE_CELLS 1
    static inline __mmask16 rs_nah_lanes(int j, int n)    /* rays j.. of n, at most 16 */
    {
        return n - j >= 16 ? (__mmask16)0xFFFF : (__mmask16)((1u << (n - j)) - 1);
    }
    static inline __m512i rs_nah_keys16(const uint8_t *key)   /* sixteen keys, widened */
    {
        return _mm512_cvtepu8_epi32(_mm_loadu_si128((const __m128i *)key));
    }
    /* Pass 1's bounds: each present bucket's origin box, over the whole packet. */
    static void rs_nah_few_bounds(const float *const o[3], int start, const uint8_t *key,
                                  int n, uint32_t present, float (*lo)[3], float (*hi)[3])
    {
        const float *x = o[0] + start, *y = o[1] + start, *z = o[2] + start;
        float tl[3][16], th[3][16];
        for (; present; present &= present - 1) {
            int b = rs_lowest((int)present);
            const __m512i kb = _mm512_set1_epi32(b);
            __m512 l0 = _mm512_set1_ps(INFINITY), l1 = l0, l2 = l0;
            __m512 h0 = _mm512_set1_ps(-INFINITY), h1 = h0, h2 = h0;
            for (int j = 0; j < n; j += 16) {
                __mmask16 t = rs_nah_lanes(j, n);
                __mmask16 m = _mm512_mask_cmpeq_epi32_mask(t, rs_nah_keys16(key + j), kb);
                __m512 vx = _mm512_maskz_loadu_ps(t, x + j);
                __m512 vy = _mm512_maskz_loadu_ps(t, y + j);
                __m512 vz = _mm512_maskz_loadu_ps(t, z + j);
                l0 = _mm512_mask_min_ps(l0, m, vx, l0);
                h0 = _mm512_mask_max_ps(h0, m, vx, h0);
                l1 = _mm512_mask_min_ps(l1, m, vy, l1);
                h1 = _mm512_mask_max_ps(h1, m, vy, h1);
                l2 = _mm512_mask_min_ps(l2, m, vz, l2);
                h2 = _mm512_mask_max_ps(h2, m, vz, h2);
            }
            _mm512_storeu_ps(tl[0], l0);
            _mm512_storeu_ps(tl[1], l1);
            _mm512_storeu_ps(tl[2], l2);
            _mm512_storeu_ps(th[0], h0);
            _mm512_storeu_ps(th[1], h1);
            _mm512_storeu_ps(th[2], h2);
            for (int a = 0; a < 3; ++a)
                for (int k = 0; k < 16; ++k) {
                    lo[b][a] = rs_minf(tl[a][k], lo[b][a]);
                    hi[b][a] = rs_maxf(th[a][k], hi[b][a]);
                }
        }
    }
    /* Pass 2: key = bucket * 8 + origin-grid cell, sixteen rays at a time, each ray's
     * middles and cell bits (grid_cell's: one per split axis, in axis order) looked up
     * by its bucket in 32-entry tables.  Writes up to 15 keys past n (into the key
     * buffer's slack). */
    static void rs_nah_vector_cells(const float *const o[3], int start, uint8_t *key, int n,
                                    const uint8_t *axes, const float (*mid)[3],
                                    uint32_t present)
    {
        const int buckets = 24;
        (void)present;
        float m[3][32];
        int32_t bit[3][32];
        __m512 mlo[3], mhi[3];
        __m512i blo[3], bhi[3];
        memset(m, 0, sizeof m);
        memset(bit, 0, sizeof bit);
        for (int b = 0; b < buckets; ++b) {
            int32_t cb[3];
            rs_nah_cell_bits(axes[b], cb);
            for (int a = 0; a < 3; ++a) {
                bit[a][b] = cb[a];
                m[a][b] = mid[b][a];
            }
        }
        for (int a = 0; a < 3; ++a) {
            mlo[a] = _mm512_loadu_ps(m[a]);
            mhi[a] = _mm512_loadu_ps(m[a] + 16);
            blo[a] = _mm512_loadu_si512((const void *)bit[a]);
            bhi[a] = _mm512_loadu_si512((const void *)(bit[a] + 16));
        }
        for (int j = 0; j < n; j += 16) {
            __mmask16 t = rs_nah_lanes(j, n);
            __m512i b = rs_nah_keys16(key + j);
            __m512i cell = _mm512_slli_epi32(b, 3);
            for (int a = 0; a < 3; ++a) {
                __m512 v = _mm512_maskz_loadu_ps(t, o[a] + start + j);
                __mmask16 ge = _mm512_cmp_ps_mask(
                    v, _mm512_permutex2var_ps(mlo[a], b, mhi[a]), _CMP_GE_OQ);
                cell = _mm512_mask_or_epi32(cell, ge, cell,
                                            _mm512_permutex2var_epi32(blo[a], b, bhi[a]));
            }
            _mm_storeu_si128((__m128i *)(key + j), _mm512_cvtepi32_epi8(cell));
        }
    }
    static inline __m512i rs_nah_ids(int first)      /* first, first + 1, ... */
    {
        static const int32_t lane[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14,
                                         15};
        return _mm512_add_epi32(_mm512_loadu_si512((const void *)lane),
                                _mm512_set1_epi32(first));
    }
    #define rs_nah_keys_sw rs_nah_keys16
    #elif RS_ISA_AVX2
    /* The avx2 build's forms, eight rays at a time: masks are vectors (blends for the
     * masked min and max: MINPS's operands as above), and the cells a present bucket at
     * a time (so only for packets of few buckets: no 32-entry tables in AVX2). */
    #define RS_NAH_VECTOR 1
    #define RS_NAH_TABLE_CELLS 0
    static inline __m256i rs_nah_lanes8(int j, int n)     /* rays j.. of n, at most 8 */
    {
        return _mm256_cmpgt_epi32(_mm256_set1_epi32(n - j),
                                  _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    }
    static inline __m256i rs_nah_keys8(const uint8_t *key)    /* eight keys, widened */
    {
        return _mm256_cvtepu8_epi32(_mm_loadl_epi64((const __m128i *)key));
    }
    static void rs_nah_few_bounds(const float *const o[3], int start, const uint8_t *key,
                                  int n, uint32_t present, float (*lo)[3], float (*hi)[3])
    {
        float tl[8], th[8];
        for (; present; present &= present - 1) {
            int b = rs_lowest((int)present);
            const __m256i kb = _mm256_set1_epi32(b);
            for (int a = 0; a < 3; ++a) {
                const float *x = o[a] + start;
                __m256 l = _mm256_set1_ps(INFINITY), h = _mm256_set1_ps(-INFINITY);
                for (int j = 0; j < n; j += 8) {
                    __m256i t = rs_nah_lanes8(j, n);
                    __m256 m = _mm256_castsi256_ps(
                        _mm256_and_si256(t, _mm256_cmpeq_epi32(rs_nah_keys8(key + j), kb)));
                    __m256 v = _mm256_maskload_ps(x + j, t);
                    l = _mm256_blendv_ps(l, _mm256_min_ps(v, l), m);
                    h = _mm256_blendv_ps(h, _mm256_max_ps(v, h), m);
                }
                _mm256_storeu_ps(tl, l);
                _mm256_storeu_ps(th, h);
                for (int k = 0; k < 8; ++k) {
                    lo[b][a] = rs_minf(tl[k], lo[b][a]);
                    hi[b][a] = rs_maxf(th[k], hi[b][a]);
                }
            }
        }
    }
    static void rs_nah_vector_cells(const float *const o[3], int start, uint8_t *key, int n,
                                    const uint8_t *axes, const float (*mid)[3],
                                    uint32_t present)
    {
        for (int j = 0; j < n; j += 8) {
            __m256i t = rs_nah_lanes8(j, n);
            __m256i kv = rs_nah_keys8(key + j);
            __m256 v[3];
            for (int a = 0; a < 3; ++a)
                v[a] = _mm256_maskload_ps(o[a] + start + j, t);
            __m256i out = _mm256_slli_epi32(kv, 3);
            for (uint32_t p = present; p; p &= p - 1) {
                int b = rs_lowest((int)p);
                int32_t bit[3];
                rs_nah_cell_bits(axes[b], bit);
                __m256i cell = _mm256_setzero_si256();
                for (int a = 0; a < 3; ++a) {
                    __m256i ge = _mm256_castps_si256(
                        _mm256_cmp_ps(v[a], _mm256_set1_ps(mid[b][a]), _CMP_GE_OQ));
                    cell = _mm256_or_si256(cell, _mm256_and_si256(ge, _mm256_set1_epi32(bit[a])));
                }
                out = _mm256_or_si256(out, _mm256_and_si256(
                    cell, _mm256_cmpeq_epi32(kv, _mm256_set1_epi32(b))));
            }
            /* the low byte of each lane, to eight key bytes (and 8 past n: slack) */
            __m256i bytes = _mm256_shuffle_epi8(out, _mm256_setr_epi8(
                0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1,
                0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1));
            uint32_t lo4 = (uint32_t)_mm256_extract_epi32(bytes, 0);
            uint32_t hi4 = (uint32_t)_mm256_extract_epi32(bytes, 4);
            memcpy(key + j, &lo4, 4);
            memcpy(key + j + 4, &hi4, 4);
        }
    }
    static inline __m256i rs_nah_ids(int first)      /* first, first + 1, ... */
    {
        return _mm256_add_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                                _mm256_set1_epi32(first));
    }
    #define rs_nah_keys_sw rs_nah_keys8
    #else
    #define RS_NAH_VECTOR 0
    #define RS_NAH_TABLE_CELLS 0
    static void rs_nah_few_bounds(const float *const o[3], int start, const uint8_t *key,
                                  int n, uint32_t present, float (*lo)[3], float (*hi)[3]) {}
    static void rs_nah_vector_cells(const float *const o[3], int start, uint8_t *key, int n,
                                    const uint8_t *axes, const float (*mid)[3],
                                    uint32_t present) {}
    #endif
    /* The counting sort for few keys (keys[0, n_keys), ascending): each key's rays, in
     * ray order, a vector of keys at a time, their indices appended (lanes.h's
     * sw_append: a compress, or a permutation looked up by the mask) after the last
     * key's, up to RS_SW - 1 values past the packet's last (the order has RS_NAH_SPILL
     * values of room past its end); count[k] = the rays of key k. */
    #define RS_NAH_SPILL 16      /* every build's (the Python wrapper allocates the order) */
    #if RS_NAH_VECTOR
    static void rs_nah_few_place(const uint8_t *key, int start, int n, const int *keys,
                                 int n_keys, int *count, int32_t *order)
    {
        int32_t *out = order + start;
        int placed = 0;
        for (int c = 0; c < n_keys; ++c) {
            const rs_swi kc = sw_set1i(keys[c]);
            int before = placed;
            for (int j = 0; j < n; j += RS_SW) {
                int bits = sw_eqi_bits(rs_nah_keys_sw(key + j), kc);
                if (n - j < RS_SW)          /* (the last vector: keys past n are slack) */
                    bits &= (1 << (n - j)) - 1;
                sw_append(out, &placed, rs_nah_ids(start + j), bits);
            }
            count[keys[c]] = placed - before;
        }
    }
    #else
    static void rs_nah_few_place(const uint8_t *key, int start, int n, const int *keys,
                                 int n_keys, int *count, int32_t *order) {}
    #endif
    """
    void place "rs_nah_place"(const uint8_t *key, int start, int end, int *count,
                              int32_t *order) noexcept nogil
    void count_keys "rs_nah_count"(const uint8_t *key, int n, int *count) noexcept nogil
    void place_coherent "rs_nah_place_coherent"(const uint8_t *key, int start, int end,
                                                const int *count, int n_keys,
                                                int32_t *order) noexcept nogil
    void buckets "rs_nah_buckets"(const float *dx, const float *dy, const float *dz, int n,
                                  uint8_t *key) noexcept nogil
    int RUN_SLACK "RS_NAH_RUN_SLACK"
    int changes "rs_nah_changes"(const uint8_t *key, int n) noexcept nogil
    uint32_t present_buckets "rs_nah_present"(const uint8_t *key, int n) noexcept nogil
    int lowest_bit "rs_lowest"(int bits) noexcept nogil
    void run_bounds "rs_nah_run_bounds"(const float *const *o, int start, const uint8_t *key,
                                        int n, float (*lo)[3], float (*hi)[3]) noexcept nogil
    void run_cells "rs_nah_run_cells"(const float *const *o, int start, uint8_t *key, int n,
                                      const uint8_t *axes, const float (*mid)[3]) noexcept nogil
    void count_runs "rs_nah_count_runs"(const uint8_t *key, int n, int *count) noexcept nogil
    void place_runs "rs_nah_place_runs"(const uint8_t *key, int start, int end,
                                        const int *count, int n_keys,
                                        int32_t *order) noexcept nogil
    bint VECTOR "RS_NAH_VECTOR"
    int FEW "RS_NAH_FEW"
    void few_bounds "rs_nah_few_bounds"(const float *const *o, int start, const uint8_t *key,
                                        int n, uint32_t present, float (*lo)[3],
                                        float (*hi)[3]) noexcept nogil
    void vector_cells "rs_nah_vector_cells"(const float *const *o, int start, uint8_t *key,
                                            int n, const uint8_t *axes, const float (*mid)[3],
                                            uint32_t present) noexcept nogil
    bint TABLE_CELLS "RS_NAH_TABLE_CELLS"
    int SPILL "RS_NAH_SPILL"
    void few_place "rs_nah_few_place"(const uint8_t *key, int start, int n, const int *keys,
                                      int n_keys, int *count, int32_t *order) noexcept nogil
    int popcount "rs_popcount"(int bits) noexcept nogil
    void identity "rs_nah_identity"(int start, int n, int32_t *order) noexcept nogil


cdef enum:
    BUCKETS = 24            # direction buckets: octant x major axis
    KEYS = BUCKETS * 8      # (bucket, origin-grid cell)
    LONG_RUNS = 8           # a packet whose keys' runs average this many rays goes by run


cdef void split_axes(const float *lo, const float *hi, const float *root_extent,
                     float threshold, int max_axes, uint8_t *axes, float *mid) noexcept nogil:
    """Choose the axes a bucket's origin grid splits (bit mask) and where."""
    cdef int a, b, rank
    cdef float ext[3]
    cdef bint wide[3]
    axes[0] = 0
    for a in range(3):
        ext[a] = hi[a] - lo[a]
        wide[a] = ext[a] > threshold * root_extent[a]
        mid[a] = 0.5 * lo[a] + 0.5 * hi[a]
    for a in range(3):
        if not wide[a]:
            continue
        # rank among the wide axes by relative extent (ties: lower axis first)
        rank = 0
        for b in range(3):
            if b != a and wide[b] and (ext[b] * root_extent[a] > ext[a] * root_extent[b]
                                       or (ext[b] * root_extent[a] == ext[a] * root_extent[b]
                                           and b < a)):
                rank += 1
        if rank < max_axes:
            axes[0] |= 1 << a


cdef inline int grid_cell(const float[:, ::1] rays, int i, uint8_t axes,
                          const float *mid) noexcept nogil:
    """One bit per split axis (in axis order): the origin is at or above the middle."""
    cdef int a, split, cell = 0, bit = 0
    for a in range(3):
        split = axes >> a & 1
        cell |= ((rays[RS_RAY_OX + a, i] >= mid[a]) & split) << bit
        bit += split
    return cell


cdef int sort_packet(const float[:, ::1] rays, int start, int end, const float *root_extent,
                     float threshold, int max_axes, int packet_size, int32_t *order,
                     int32_t *offsets,
                     uint8_t *key, uint8_t *bucket_out, uint8_t *cell_out) noexcept nogil:
    """Sort rays [start, end) into order[start:end]; returns the number of sub-packets
    written to offsets (their start positions)."""
    cdef float lo[BUCKETS][3]
    cdef float hi[BUCKETS][3]
    cdef float mid[BUCKETS][3]
    cdef uint8_t axes[BUCKETS]
    cdef int count[KEYS]
    cdef int keys[KEYS]                # few: the keys that can occur, ascending
    cdef int i, a, b, c, k, pos, piece, n_sub = 0, most = 0, n_keys = 0, n = end - start
    cdef uint8_t split = 0
    cdef uint32_t present, b_bits      # bit b: some ray is in bucket b
    cdef bint runs = False, few, placed = False
    cdef const float *origin[3]
    if n == 0:
        return 0
    for b in range(BUCKETS):
        for a in range(3):
            lo[b][a] = INFINITY
            hi[b][a] = -INFINITY
    for k in range(KEYS):
        count[k] = 0
    for a in range(3):
        origin[a] = &rays[RS_RAY_OX + a, 0]
    # pass 1: direction buckets (indices only) and per-bucket origin bounds: a bucket at
    # a time where the packet has few (avx512, avx2), by runs of one bucket where they are
    # long (coherent rays), else ray by ray
    buckets(&rays[RS_RAY_DX, start], &rays[RS_RAY_DY, start], &rays[RS_RAY_DZ, start], n, key)
    present = present_buckets(key, n)
    few = VECTOR and bucket_out == NULL and popcount(<int> present) <= FEW
    # (the avx2 build's boxes of few buckets, a pass per axis, cost more than the run
    # pass where runs are long: camera rays, 1.15x the sort)
    if not (few and TABLE_CELLS):
        runs = n >= LONG_RUNS * (changes(key, n) + 1)
    if few and (TABLE_CELLS or not runs):
        few_bounds(origin, start, key, n, present, lo, hi)
    else:
        if runs:
            run_bounds(origin, start, key, n, lo, hi)
        else:
            for i in range(start, end):
                b = key[i - start]
                for a in range(3):
                    lo[b][a] = rs_minf(rays[RS_RAY_OX + a, i], lo[b][a])
                    hi[b][a] = rs_maxf(rays[RS_RAY_OX + a, i], hi[b][a])
    for b in range(BUCKETS):
        split_axes(lo[b], hi[b], root_extent, threshold, max_axes, &axes[b], mid[b])
        split |= axes[b]
    # pass 2: origin-grid cell (always 0 where no bucket splits: camera rays)
    if split == 0 and bucket_out == NULL:
        for i in range(n):
            key[i] = key[i] * 8
    elif VECTOR and bucket_out == NULL and (few or TABLE_CELLS):
        vector_cells(origin, start, key, n, axes, mid, present)
    elif runs and bucket_out == NULL:
        run_cells(origin, start, key, n, axes, mid)
    else:
        for i in range(start, end):
            b = key[i - start]
            k = grid_cell(rays, i, axes[b], mid[b])
            if bucket_out != NULL:
                bucket_out[i] = <uint8_t> b
                cell_out[i] = <uint8_t> k
            key[i - start] = <uint8_t> (b * 8 + k)
    # a counting sort on (bucket, cell): with few keys, placed a key at a time (counts
    # as they go); else counted first
    if few:
        b_bits = present
        while b_bits and n_keys <= FEW:
            b = lowest_bit(<int> b_bits)
            b_bits &= b_bits - 1
            for c in range(1 << popcount(axes[b])):
                keys[n_keys] = b * 8 + c
                n_keys += 1
        placed = n_keys <= FEW
    if placed and n_keys == 1:          # one key: the rays in their order
        count[keys[0]] = n
        identity(start, n, order)
    elif placed:
        few_place(key, start, n, keys, n_keys, count, order)
    else:
        # (key * 8 keeps the runs: their count changes only where a bucket splits)
        runs = n >= LONG_RUNS * (changes(key, n) + 1)
        if runs:
            count_runs(key, n, count)
        else:
            count_keys(key, n, count)
    pos = start
    while present:                      # the buckets some ray is in, in order
        b = lowest_bit(<int> present)
        present &= present - 1
        for k in range(b * 8, b * 8 + 8):
            piece = 0
            while piece < count[k]:
                offsets[n_sub] = pos + piece
                n_sub += 1
                piece += packet_size
            a = count[k]
            count[k] = pos
            pos += a
            most = max(most, a)
    # coherent rays: in long runs of one key, or one key holds most of them (see
    # rs_nah_place)
    if placed:
        pass
    elif runs:
        place_runs(key, start, end, count, KEYS, order)
    elif 2 * most > end - start:
        place_coherent(key, start, end, count, KEYS, order)
    else:
        place(key, start, end, count, order)
    return n_sub


def _sort(const float[:, ::1] rays, const int32_t[::1] packets, const float[::1] root_extent,
          float threshold, int max_axes, int packet_size, int32_t[::1] order,
          int32_t[::1] offsets,
          uint8_t[::1] bucket_out=None, uint8_t[::1] cell_out=None):
    """Sort every large packet; returns the number of sub-packets (offsets gets them + end).
    ValueError unless ``packets`` ascend from 0 (checked in the pass that finds the widest)
    to an n that ``rays``, ``order`` (n + ``SPILL``: the few-key pass may write past n),
    ``offsets`` (n + 1), ``bucket_out`` and ``cell_out`` hold, ``root_extent`` has 3 values
    and ``packet_size`` >= 1."""
    cdef int p, n_sub = 0, widest = 0, descending = 0
    cdef Py_ssize_t n
    if packets.shape[0] < 1 or root_extent.shape[0] < 3 or packet_size < 1 \
            or rays.shape[0] != RS_RAY_ROWS:
        raise ValueError("_sort: rays (RS_RAY_ROWS, capacity), packets of 1 boundary or more, "
                         "root_extent of 3 values and packet_size >= 1 expected")
    n = packets[packets.shape[0] - 1]
    if (packets[0] != 0 or n > rays.shape[1] or n + SPILL > order.shape[0]
            or n >= offsets.shape[0]
            or (bucket_out is not None and bucket_out.shape[0] < n)
            or (cell_out is not None and cell_out.shape[0] < n)):
        raise ValueError(f"_sort: packets must run from 0 to n = {n}, and rays, order "
                         f"(n + {SPILL}), offsets (n + 1), bucket_out and cell_out hold them")
    for p in range(packets.shape[0] - 1):
        widest = max(widest, packets[p + 1] - packets[p])
        descending |= packets[p + 1] < packets[p]
    if descending:
        raise ValueError("_sort: packets must not descend")
    cdef uint8_t *bucket_ptr = &bucket_out[0] if bucket_out is not None else NULL
    cdef uint8_t *cell_ptr = &cell_out[0] if cell_out is not None else NULL
    key = np.empty(max(widest, 1) + RUN_SLACK, dtype=np.uint8)     # (see rs_nah_run_end)
    cdef uint8_t[::1] key_mv = key
    with nogil:
        for p in range(packets.shape[0] - 1):
            n_sub += sort_packet(rays, packets[p], packets[p + 1], &root_extent[0], threshold,
                                 max_axes, packet_size, &order[0], &offsets[n_sub], &key_mv[0],
                                 bucket_ptr, cell_ptr)
        offsets[n_sub] = packets[packets.shape[0] - 1]
    return n_sub


class NahSorter(Sorter):
    """Direction buckets and origin grids (Nah et al.), in Cython.

    Sorts every large packet (by default one 32x32 tile pass, 1024 rays) into
    coherent sub-packets: 24 direction buckets (octant x major axis), then per
    bucket an origin grid of 1-8 cells, each cell cut into sub-packets of at
    most ``packet_size`` rays.  Linear time; only indices move.

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    threshold    float   0.25     split a bucket's origin grid on an axis
                                  when its origin extent exceeds this
                                  fraction of the scene box's extent
    max_cells    int     8        most cells per bucket grid: 1, 2, 4 or 8
                                  (the widest axes are split first)
    packet_size  int     64       most rays per sub-packet (Manta's
                                  RayPacket::MaxSize); 4096 = whole cells
    large_packet int     None     sort within runs of at most this many rays
                                  of each large packet (None: the whole
                                  large packet, i.e. the pipeline's tile)
    ===========  ======  =======  ==========================================
    """

    trusted = True

    def __init__(self, *, threshold=0.25, max_cells=8, packet_size=64, large_packet=None):
        self.threshold, self.max_cells, self.packet_size, self.large_packet = \
            threshold, max_cells, packet_size, large_packet
        self.threshold, self.max_cells, self.packet_size, self.large_packet = self._params()

    def _params(self):
        """The parameters, checked (again at every sort where an attribute is not the
        object last checked: the kernel's bounds rest on them, and a script may have
        set one since)."""
        raw = (self.threshold, self.max_cells, self.packet_size, self.large_packet)
        last = self.__dict__.get("_checked")
        if last is not None and all(map(operator.is_, raw, last[0])):
            return last[1]
        max_cells = self.max_cells
        if isinstance(max_cells, bool) or max_cells not in (1, 2, 4, 8):
            raise ConfigError(f"max_cells must be 1, 2, 4 or 8, got {max_cells!r}")
        params = (number("threshold", self.threshold, 0), int(max_cells),
                  integer("packet_size", self.packet_size, 1, MAX_PACKET),
                  None if self.large_packet is None else
                  integer("large_packet", self.large_packet, 1, MAX_PACKET))
        self._checked = (raw, params)
        return params

    def _packets(self, packets, n, params=None):
        """The large packets of ``n`` rays, checked, cut to ``large_packet`` (of
        ``params``, the checked parameters, when the caller has them)."""
        packets = check_packets(packets, n)
        large_packet = (params or self._params())[3]
        return packets if large_packet is None else fixed_packets(packets, large_packet)

    def _run(self, rays, packets, bounds, bucket=None, cell=None):
        params = threshold, max_cells, packet_size, large_packet = self._params()
        n = len(rays)
        # the pipeline's packets (int32, ending at n) go straight to the kernel, which
        # checks the rest (from 0, never decreasing); check_packets names what is wrong
        plain = large_packet is None and plain_packets(packets, n)
        if not plain:
            packets = self._packets(packets, n, params)
        bounds = np.asarray(bounds, dtype=np.float32)
        extent = np.ascontiguousarray(bounds[1] - bounds[0], dtype=np.float32)
        order = np.empty(n + SPILL, dtype=np.int32)     # (room for few_place past n)
        offsets = np.empty(n + 1, dtype=np.int32)
        try:
            n_sub = isa.module("sorters.nah")._sort(
                rays.data, packets, extent, threshold, max_cells.bit_length() - 1,
                packet_size, order, offsets, bucket, cell)
        except ValueError:
            if plain:
                check_packets(packets, n)
            raise
        return order[:n], offsets[:n_sub + 1].copy()

    def sort(self, rays, packets, bounds):
        return self._run(rays, packets, bounds)

    def classify(self, rays, packets, bounds):
        """``(bucket, cell)`` of every ray (uint8 arrays), as the sort uses them."""
        bucket = np.zeros(max(len(rays), 1), dtype=np.uint8)
        cell = np.zeros(max(len(rays), 1), dtype=np.uint8)
        self._run(rays, packets, bounds, bucket, cell)
        return bucket[:len(rays)], cell[:len(rays)]
