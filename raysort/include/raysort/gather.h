/* raysort: the gather of rays into aligned sub-packets, as wide as the ISA.
 *
 * The framework's gather (raysort/_gather.pyx) first lays the sorter's order
 * out lane by lane (the packets' `index`: the ray of each lane, -1 for
 * padding), then fills every lane's packet rows from that index with
 * rs_gather_lanes: RS_SW lanes at a time (lanes.h: 16 with AVX-512, with the
 * hardware gather; 8 with AVX2, from scalar loads; 4 with SSE2, the paper's
 * 4-ray packet; 1 on the scalar build), loading the eight ray rows of the block's rays and
 * writing the packet rows with full-width stores.
 *
 * The rules per lane, for a lane holding ray s (s = -1: padding): a ray is
 * stored active only if its origin and direction are finite and
 * 0 <= tmin < tmax; otherwise (NaN rays, padding) it is stored inactive:
 * origin, direction and 1 / d zero, tmin +inf, t -inf.  Subnormal direction
 * components are stored as zeros of their sign, so 1 / d is either finite or
 * +-inf.  prim is reset to -1, u and v to 0, and `tmax` (unless NULL) gets a
 * copy of the row t as stored, for the check of the traversal's hits.
 *
 * Exactness: per lane, every width performs the same operations (copies,
 * selects, and one IEEE division 1 / d), so the packets are bit-identical
 * whichever ISA builds them.
 */
#ifndef RAYSORT_GATHER_H
#define RAYSORT_GATHER_H

#include "lanes.h"

/* Rays between a block's first lane and the rays whose rows it prefetches
 * (rs_gather_lanes): one large packet of the pipeline (a 32x32 tile). */
#define RS_GATHER_AHEAD 1024

/* Whether the lanes ids[j..j + RS_SW) hold consecutive rays (no padding): the rays
 * of an unsorted batch (sorter `none`), whose rows load as vectors instead of
 * lane by lane. */
RS_INLINE int rs_gather_is_run(const int32_t *ids, int64_t j)
{
    const int64_t first = ids[j];
    int run = first >= 0;
    for (int k = 1; k < RS_SW; ++k)
        run &= ids[j + k] == first + k;
    return run;
}

/* Lanes [j, j + RS_SW) of the packet rows from the rays ids[j..]: a padding lane
 * reads ray 0 (every batch holds at least one lane) and discards it; a block of
 * consecutive rays is loaded, not gathered (the same values).  Returns the
 * lanes (bits) holding a ray that breaks the ray contract: active (tmin < tmax)
 * yet with tmin < 0 or a non-finite origin or direction (stored inactive). */
RS_INLINE int rs_gather_block(float *const dst[RS_PACKET_ROWS], int32_t *prim, float *u,
                              float *v, float *tmax, const float *const src[RS_RAY_ROWS],
                              const int32_t *ids, int64_t j)
{
    const rs_swi id = sw_ids(ids + j), none = sw_set1i(0);
    const rs_swm padding = sw_lti(id, none);
    const rs_swi ray = sw_blendi(padding, none, id);
    rs_swf row[RS_RAY_ROWS];
    if (rs_gather_is_run(ids, j))
        for (int c = 0; c < RS_RAY_ROWS; ++c)
            row[c] = sw_loadu(src[c] + ids[j]);
    else
        for (int c = 0; c < RS_RAY_ROWS; ++c)
            row[c] = sw_gather(src[c], ray);
    const rs_swf zero = sw_set1(0.0f), inf = sw_set1(INFINITY);
    rs_swm good = sw_ge(row[RS_RAY_TMIN], zero);
    for (int a = 0; a < 3; ++a) {   /* finite: |x| < inf, false for NaN */
        rs_swf o = row[RS_RAY_OX + a], d = row[RS_RAY_DX + a];
        good = sw_and(good, sw_lt(sw_max(o, sw_sub(zero, o)), inf));
        good = sw_and(good, sw_lt(sw_max(d, sw_sub(zero, d)), inf));
    }
    const int present = ~sw_bits(padding) & ((1 << RS_SW) - 1);
    const rs_swm active = sw_lt(row[RS_RAY_TMIN], row[RS_RAY_TMAX]);
    const rs_swm ok = sw_and(sw_from_bits(present), sw_and(good, active));
    for (int a = 0; a < 3; ++a) {
        /* a subnormal d becomes d * 0: the zero of its sign */
        rs_swf d = row[RS_RAY_DX + a];
        d = sw_blend(sw_lt(sw_max(d, sw_sub(zero, d)), sw_set1(FLT_MIN)), sw_mul(d, zero), d);
        d = sw_blend(ok, d, zero);
        sw_store(dst[RS_PACKET_OX + a] + j, sw_blend(ok, row[RS_RAY_OX + a], zero));
        sw_store(dst[RS_PACKET_DX + a] + j, d);
        sw_store(dst[RS_PACKET_IX + a] + j, sw_blend(ok, sw_div(sw_set1(1.0f), d), zero));
    }
    sw_store(dst[RS_PACKET_TMIN] + j, sw_blend(ok, row[RS_RAY_TMIN], inf));
    const rs_swf t = sw_blend(ok, row[RS_RAY_TMAX], sw_set1(-INFINITY));
    sw_store(dst[RS_PACKET_T] + j, t);
    if (tmax)
        sw_store(tmax + j, t);
    sw_storei(prim + j, sw_set1i(-1));
    sw_store(u + j, zero);
    sw_store(v + j, zero);
    return present & sw_bits(active) & ~sw_bits(good);
}

/* Lanes [0, capacity) of the packet rows dst, prim, u, v (and tmax unless NULL)
 * from the rays index[lane] of the rows src, of n_src lanes each.  Every index is
 * -1 or a lane of src, which holds at least one.  Lanes past the last full block go through a
 * block-sized scratch.  Returns the first lane holding a ray that breaks the ray
 * contract (stored inactive), or -1. */
RS_INLINE int64_t rs_gather_lanes(float *const dst[RS_PACKET_ROWS], int32_t *prim, float *u,
                                  float *v, float *tmax, const float *const src[RS_RAY_ROWS],
                                  const int32_t *index, int64_t capacity, int64_t n_src)
{
    int64_t j = 0, first_bad = -1;
    int bits;
    /* Per block, one line of every row RS_GATHER_AHEAD rays past the block's
     * first lane: lanes hold about as many rays as their number, and a sorter
     * reorders rays only within a large packet, so this streams in the rows of
     * the packets to come, sorted or not (the hardware prefetcher follows them
     * only part of the way with 19 rows in flight; prefetching each lane's own
     * ray, random within its packet, made the gather slower).  After a trace,
     * Zen 3, AVX2, against prefetching the rows of one lane's ray per block:
     * sorted rays 0.44-0.61 -> 0.36-0.48 ms per 65,536, unsorted 0.28-0.41 ->
     * 0.23-0.30 ms (512 and 2048 rays ahead measured the same). */
    for (; j + RS_SW <= capacity; j += RS_SW) {
        {
            int64_t r = j + RS_GATHER_AHEAD < n_src ? j + RS_GATHER_AHEAD : n_src - 1;
            for (int c = 0; c < RS_RAY_ROWS; ++c)
                rs_prefetch(src[c] + r);
        }
        if ((bits = rs_gather_block(dst, prim, u, v, tmax, src, index, j)) && first_bad < 0)
            first_bad = j + rs_lowest(bits);
    }
    if (j < capacity) {
        int rest = (int)(capacity - j);
        int32_t ids[RS_SW], p[RS_SW];
        float rows[RS_PACKET_ROWS][RS_SW], uv[3][RS_SW];
        float *scratch[RS_PACKET_ROWS];
        for (int k = 0; k < RS_SW; ++k)
            ids[k] = k < rest ? index[j + k] : -1;
        for (int c = 0; c < RS_PACKET_ROWS; ++c)
            scratch[c] = rows[c];
        bits = rs_gather_block(scratch, p, uv[0], uv[1], uv[2], src, ids, 0);
        for (int c = 0; c < RS_PACKET_ROWS; ++c)
            memcpy(dst[c] + j, rows[c], rest * sizeof(float));
        memcpy(prim + j, p, rest * sizeof(int32_t));
        memcpy(u + j, uv[0], rest * sizeof(float));
        memcpy(v + j, uv[1], rest * sizeof(float));
        if (tmax)
            memcpy(tmax + j, uv[2], rest * sizeof(float));
        if (bits && first_bad < 0)
            first_bad = j + rs_lowest(bits);
    }
    return first_bad;
}

#endif
