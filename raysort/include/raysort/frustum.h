/* raysort: the `frustum` traversal, coherent packets through the 8-wide tree.
 *
 * A chunk of up to RS_FRUSTUM_CHUNK consecutive rays of a sub-packet descends
 * the 8-wide BVH (BVH.wide8) together.  At an inner node one interval-
 * arithmetic test (the chunk's ranges of origins and reciprocal directions,
 * Wald et al. 2007's frustum, as rs_ia_miss) checks all eight child boxes at
 * once, and the children it keeps are visited nearest first by their lower
 * bound of entry.  At a leaf the chunk's rays meet the leaf's box one SIMD
 * group at a time (rs_box1's operations per lane).  A group of RS_SW lanes of
 * which at least half enter it meets the leaf's triangles one at a time, a
 * ray per lane (rs_frustum_leaf_block); each other ray that enters it meets the
 * leaf's triangle groups as in `wide8` (rs_tri8_hit; two rays at a time on
 * AVX-512).  A box waiting
 * on the stack is dropped once every ray of the chunk has a hit closer than
 * where the chunk can first enter it.  A chunk that is not coherent (fewer
 * than RS_FRUSTUM_MIN_RAYS active rays, directions that do not keep their sign
 * on two axes or that spread wider than RS_FRUSTUM_SPREAD, or origins that
 * spread wider than RS_FRUSTUM_ORIGINS of its longest ray: the walk would cost
 * more than it shares) is traced one ray at a time, as `wide8` does.
 *
 * Exactness: the interval test only culls a box that no ray's own slab test
 * would enter (rounding is monotone, so the bounds computed from the ranges'
 * corners bound every ray's value; axes with a sign change, zero or infinite
 * reciprocals do not cull), and a box is dropped from the stack only when its
 * lower bound exceeds every ray's t * RS_BOX_SLACK.  Every ray that could hold
 * a hit in a leaf is tested against all of its triangles, with rs_tri8_hit or
 * rs_stream_tri, both of which keep the lowest (t, id) whatever the order:
 * brute force's hit, bit for bit, on every ISA.
 */
#ifndef RAYSORT_FRUSTUM_H
#define RAYSORT_FRUSTUM_H

#include <stdint.h>
#include <string.h>
#include "stream.h"     /* rs_stream_single8 (and wide8.h, lanes.h) */

/* Rays traced together; a sub-packet is cut into chunks of this many lanes. */
#define RS_FRUSTUM_CHUNK 64

/* The widest spread of a chunk's direction components (max - min, on any axis)
 * that takes the frustum walk: wider chunks cull too little. */
#define RS_FRUSTUM_SPREAD 0.25f

/* The widest spread of a chunk's origins (max - min, on any axis) that takes
 * the frustum walk, as a fraction of the chunk's longest ray (its largest t):
 * shadow rays toward a light from hits far apart (of a bounce, or sorted by
 * direction) share too little of it.  (Zen 5, 256x256 at 4 spp: shadow rays of
 * the camera hits with sorter none 4.8 and 3.5 ms on Sibenik and Sponza,
 * against 5.8 and 5.2 ms without this test and 5.1 and 4.3 ms without the walk;
 * nah-sorted shadow rays of the first bounce 11.3 and 9.0 ms, against 26 ms
 * on Sponza without it.  0.03 to 0.15 measured alike.) */
#define RS_FRUSTUM_ORIGINS 0.1f

/* The fewest active rays of a chunk that take the frustum walk: a few rays
 * share too little of it (nah-sorted second-bounce rays, in sub-packets of a
 * handful of rays, ran 1.2-2x slower through the walk than one at a time). */
#define RS_FRUSTUM_MIN_RAYS 16

/* The fewest of a block's RS_SW lanes entering a leaf (in sixteenths of the
 * block) that take rs_frustum_leaf_block, a triangle at a time for the block,
 * rather than a ray (or, on AVX-512, two) at a time. */
#define RS_FRUSTUM_DENSE 8

/* A box the chunk waits to visit: child `slot` of node8 `parent`. */
typedef struct rs_frustum_entry {
    int32_t ref;        /* >= 0: an inner node8; < 0: a leaf, first group -ref - 1 */
    int32_t tris;       /* the leaf's triangle groups */
    int32_t parent;     /* the node8 holding the box */
    int32_t slot;       /* its child slot there */
    float entry;        /* a lower bound of where any ray of the chunk enters it */
} rs_frustum_entry;

/* Bounds of a chunk's active rays. */
typedef struct rs_frustum_bounds {
    float omin[3], omax[3];     /* origins */
    float rmin[3], rmax[3];     /* reciprocal directions */
    float dmin[3], dmax[3];     /* directions */
    int cull[3];                /* the axis culls: one sign, finite and non-zero */
    float tmin;                 /* the smallest tmin */
    float tmax;                 /* the largest t: no ray looks farther */
    int rays;                   /* active rays */
} rs_frustum_bounds;

/* Bounds of the active rays of lanes [s, e); returns how many are active.
 * RS_SW lanes at a time (an inactive or NaN lane leaves a bound as it is), the
 * lanes then reduced by sw_hmin/sw_hmax, and the lanes after the last whole
 * RS_SW one by themselves: the same bounds as one ray after the other, up to
 * the sign of a zero, which no test below sees. */
RS_INLINE int rs_frustum_bounds_of(const rs_rays *r, int s, int e, rs_frustum_bounds *b)
{
    /* rows 0-2 origins, 3-5 reciprocal directions, 6-8 directions */
    const float *row[9] = {r->o[0], r->o[1], r->o[2], r->inv[0], r->inv[1], r->inv[2],
                           r->d[0], r->d[1], r->d[2]};
    float lo[9], hi[9];
    int n = 0, i = s;
    for (int q = 0; q < 9; ++q) {
        lo[q] = INFINITY;
        hi[q] = -INFINITY;
    }
    b->tmin = INFINITY;
    b->tmax = -INFINITY;
#if RS_SW > 1
    if (i + RS_SW <= e) {
        const rs_swf up = sw_set1(INFINITY), down = sw_set1(-INFINITY);
        rs_swf vlo[9], vhi[9], tlo = up, thi = down;
        for (int q = 0; q < 9; ++q) {
            vlo[q] = up;
            vhi[q] = down;
        }
        for (; i + RS_SW <= e; i += RS_SW) {
            rs_swf tmin = sw_loadu(r->tmin + i), t = sw_loadu(r->t + i);
            rs_swm on = sw_lt(tmin, t);
            n += rs_popcount(sw_bits(on));
            for (int q = 0; q < 9; ++q) {
                rs_swf v = sw_loadu(row[q] + i);
                vlo[q] = sw_min(sw_blend(on, v, up), vlo[q]);
                vhi[q] = sw_max(sw_blend(on, v, down), vhi[q]);
            }
            tlo = sw_min(sw_blend(on, tmin, up), tlo);
            thi = sw_max(sw_blend(on, t, down), thi);
        }
        for (int q = 0; q < 9; ++q) {
            lo[q] = sw_hmin(vlo[q]);
            hi[q] = sw_hmax(vhi[q]);
        }
        b->tmin = sw_hmin(tlo);
        b->tmax = sw_hmax(thi);
    }
#endif
    for (; i < e; ++i) {
        if (!(r->tmin[i] < r->t[i]))
            continue;
        ++n;
        for (int q = 0; q < 9; ++q) {
            lo[q] = rs_minf(row[q][i], lo[q]);
            hi[q] = rs_maxf(row[q][i], hi[q]);
        }
        b->tmin = rs_minf(r->tmin[i], b->tmin);
        b->tmax = rs_maxf(r->t[i], b->tmax);
    }
    b->rays = n;
    for (int a = 0; a < 3; ++a) {
        b->omin[a] = lo[a];
        b->omax[a] = hi[a];
        b->rmin[a] = lo[3 + a];
        b->rmax[a] = hi[3 + a];
        b->dmin[a] = lo[6 + a];
        b->dmax[a] = hi[6 + a];
        b->cull[a] = (b->rmin[a] > 0.0f && b->rmax[a] < INFINITY)
                     || (b->rmax[a] < 0.0f && b->rmin[a] > -INFINITY);
    }
    return n;
}

/* The largest t of the active rays of lanes [s, e) (tmin < t, as
 * rs_frustum_bounds_of's tmax): the farthest any ray still looks.  RS_SW lanes
 * at a time, then sw_hmax: the walk takes it after each leaf that changed a
 * hit, and the one-lane chain of 64 dependent maxima took 11 % of its time on
 * Sponza's camera rays (BENCHMARKS.md section 9). */
RS_INLINE float rs_frustum_reach(const rs_rays *r, int s, int e)
{
    float t = -INFINITY;
    int i = s;
#if RS_SW > 1
    if (i + RS_SW <= e) {
        const rs_swf down = sw_set1(-INFINITY);
        rs_swf most = down;
        for (; i + RS_SW <= e; i += RS_SW) {
            rs_swf ti = sw_loadu(r->t + i);
            most = sw_max(sw_blend(sw_lt(sw_loadu(r->tmin + i), ti), ti, down), most);
        }
        t = sw_hmax(most);
    }
#endif
    for (; i < e; ++i)
        if (r->tmin[i] < r->t[i])
            t = rs_maxf(r->t[i], t);
    return t;
}

/* The chunk against the eight child boxes of a node: returns the mask of the
 * boxes some ray may enter and stores a lower bound of the entry into each. */
RS_INLINE int rs_frustum_node8(const rs_frustum_bounds *b, const rs_node8 *n, float entry[8])
{
    rs_v8f tn = rs8_set1(b->tmin), tf = rs8_set1(b->tmax);
    for (int a = 0; a < 3; ++a) {
        if (!b->cull[a])
            continue;
        int neg = b->rmax[a] < 0.0f;
        rs_v8f near_plane = rs8_load(neg ? n->hi[a] : n->lo[a]);
        rs_v8f far_plane = rs8_load(neg ? n->lo[a] : n->hi[a]);
        rs_v8f omin = rs8_set1(b->omin[a]), omax = rs8_set1(b->omax[a]);
        rs_v8f r0 = rs8_set1(b->rmin[a]), r1 = rs8_set1(b->rmax[a]);
        /* every ray's (plane - o) lies in [plane - omax, plane - omin] */
        rs_v8f n0 = rs8_sub(near_plane, omax), n1 = rs8_sub(near_plane, omin);
        rs_v8f f0 = rs8_sub(far_plane, omax), f1 = rs8_sub(far_plane, omin);
        rs_v8f near_t = rs8_min(rs8_min(rs8_mul(n0, r0), rs8_mul(n0, r1)),
                                rs8_min(rs8_mul(n1, r0), rs8_mul(n1, r1)));
        rs_v8f far_t = rs8_max(rs8_max(rs8_mul(f0, r0), rs8_mul(f0, r1)),
                               rs8_max(rs8_mul(f1, r0), rs8_mul(f1, r1)));
        tn = rs8_max(near_t, tn);
        tf = rs8_min(far_t, tf);
    }
    rs8_store(entry, tn);
    return rs8_movemask(rs8_le(tn, rs8_mul(tf, rs8_set1(RS_BOX_SLACK))));
}

/* Lanes [i, i + RS_SW) against one box: rs_box1's operations per lane. */
RS_INLINE int rs_frustum_box_lanes(const rs_rays *r, int i, const float lo[3], const float hi[3])
{
    rs_swf tn = sw_loadu(r->tmin + i), tf = sw_loadu(r->t + i);
    for (int a = 0; a < 3; ++a) {
        rs_swf inv = sw_loadu(r->inv[a] + i), o = sw_loadu(r->o[a] + i);
        rs_swm neg = sw_sign(inv);
        rs_swf l = sw_set1(lo[a]), h = sw_set1(hi[a]);
        tn = sw_max(sw_mul(sw_sub(sw_blend(neg, h, l), o), inv), tn);
        tf = sw_min(sw_mul(sw_sub(sw_blend(neg, l, h), o), inv), tf);
    }
    return sw_bits(sw_le(tn, sw_mul(tf, sw_set1(RS_BOX_SLACK))));
}

/* The rays of lanes [s, e) (e - s <= RS_FRUSTUM_CHUNK) that enter child `slot`
 * of node n, as a bit mask over lane - s.  Lanes up to e rounded up to a
 * multiple of 4 are read (rows hold whole 4-lane groups); later ones never. */
RS_INLINE uint64_t rs_frustum_leaf_rays(const rs_rays *r, int s, int e, const rs_node8 *n,
                                        int slot, rs_counters *c)
{
    float lo[3], hi[3];
    uint64_t hit = 0;
    int e4 = (e + 3) & ~3, i = s;
    for (int a = 0; a < 3; ++a) {
        lo[a] = n->lo[a][slot];
        hi[a] = n->hi[a][slot];
    }
    for (; i + RS_SW <= e4; i += RS_SW) {
        c->box4 += 1;
        hit |= (uint64_t)(uint32_t)rs_frustum_box_lanes(r, i, lo, hi) << (i - s);
    }
    if (i < e4) {                       /* whole 4-lane groups past the last RS_SW one */
        rs_node box;
        memset(&box, 0, sizeof box);
        memcpy(box.lo, lo, sizeof lo);
        memcpy(box.hi, hi, sizeof hi);
        for (; i < e4; i += 4) {
            c->box4 += 1;
            hit |= (uint64_t)(uint32_t)rs_box4(r, i, &box) << (i - s);
        }
    }
    return e - s < 64 ? hit & ((UINT64_C(1) << (e - s)) - 1) : hit;
}

/* Index of the lowest set bit of a non-zero 64-bit mask. */
RS_INLINE int rs_lowest64(uint64_t bits)
{
    uint32_t low = (uint32_t)bits;
    return low ? rs_lowest((int)low) : 32 + rs_lowest((int)(uint32_t)(bits >> 32));
}

/* Insert `e` into hit[0, m), sorted nearest first. */
RS_INLINE void rs_frustum_insert(rs_frustum_entry *hit, int m, rs_frustum_entry e)
{
    int j = m;
    while (j > 0 && hit[j - 1].entry > e.entry) {
        hit[j] = hit[j - 1];
        --j;
    }
    hit[j] = e;
}

/* Ray i against the `tris` groups at g, one after the other while it still
 * looks (an any-hit query stops at its hit), as wide8 does; returns whether
 * its hit changed. */
RS_INLINE int rs_frustum_leaf_one(rs_rays *r, int i, const rs_tri8 *g, int tris, int any_hit,
                                  rs_counters *c)
{
    rs_ray8 ray;
    int changed = 0;
    rs_ray8_load(r, i, &ray);
    for (int k = 0; k < tris && r->tmin[i] < r->t[i]; ++k) {
        c->tri4 += 1;
        changed |= rs_tri8_hit(r, i, &ray, &g[k], any_hit);
    }
    return changed;
}

/* The rays of lanes [i, i + RS_SW) set in `bits` (chunk lanes that enter a
 * leaf; the whole block readable) against the leaf's `tris` groups at g, a
 * triangle at a time for the block (rs_stream_tri: rs_tri1's operations and
 * acceptance rule in each lane, so each ray keeps the hit rs_frustum_leaf_one
 * finds, and is counted as it counts: a group per ray while the ray still
 * looks).  Where most of a block's rays enter a leaf, one test serves them all
 * and no lane's hit is picked by a scalar loop.  Returns whether a hit changed. */
RS_INLINE int rs_frustum_leaf_block(rs_rays *r, int i, int bits, const rs_tri8 *g, int tris,
                                    int any_hit, rs_counters *c)
{
    rs_stream_lanes s;
    for (int a = 0; a < 3; ++a) {
        s.o[a] = sw_loadu(r->o[a] + i);
        s.d[a] = sw_loadu(r->d[a] + i);
    }
    s.tmin = sw_loadu(r->tmin + i);
    s.best = sw_loadu(r->t + i);
    s.u = sw_loadu(r->u + i);
    s.v = sw_loadu(r->v + i);
    s.prim = sw_ids(r->prim + i);
    s.changed = 0;
    for (int k = 0; k < tris; ++k) {
        int live = bits & sw_bits(sw_lt(s.tmin, s.best));
        if (!live)
            break;
        c->tri4 += rs_popcount(live);
        s.valid = sw_from_bits(live);
        for (int j = 0; j < 8; ++j)
            if (g[k].id[j] != INT32_MAX)
                rs_stream_tri(&s, &g[k].v0[0][j], &g[k].e1[0][j], &g[k].e2[0][j], 8,
                              g[k].id[j], any_hit);
    }
    if (!s.changed)
        return 0;
    /* the lanes whose hit did not change hold the values just read */
    sw_store(r->t + i, s.best);
    sw_store(r->u + i, s.u);
    sw_store(r->v + i, s.v);
    sw_storei(r->prim + i, s.prim);
    return 1;
}

#if RS_ISA_AVX512
/* The 16-lane operations RS_MT_UV and RS_MT_T take (simd.h). */
RS_INLINE __m512 rs16_add(__m512 a, __m512 b) { return _mm512_add_ps(a, b); }
RS_INLINE __m512 rs16_sub(__m512 a, __m512 b) { return _mm512_sub_ps(a, b); }
RS_INLINE __m512 rs16_mul(__m512 a, __m512 b) { return _mm512_mul_ps(a, b); }
RS_INLINE __m512 rs16_div(__m512 a, __m512 b) { return _mm512_div_ps(a, b); }
RS_INLINE __m512 rs16_set1(float a) { return _mm512_set1_ps(a); }

/* Rays i and j against the eight triangles of group g at once: ray i in lanes
 * 0-7 and ray j in lanes 8-15 of 16-lane operations (o, d: their origins and
 * directions so), each lane performing rs_tri8_hit's operations (rs_tri1's) on
 * its triangle, so each ray keeps exactly rs_tri8_hit's hit.  On AVX-512 the
 * 8-lane test leaves half of every register idle; a leaf of a coherent chunk is
 * nearly always entered by several rays.  `live` says which rays still look
 * (bit 0: i, bit 1: j); returns which hits changed (the same bits). */
RS_INLINE int rs_tri8_hit_pair(rs_rays *r, int i, int j, const __m512 o[3], const __m512 d[3],
                               const rs_tri8 *g, int live, int any_hit)
{
#define RS_PAIR(row) _mm512_broadcast_f32x8(_mm256_load_ps(row))
    __m512 e1x = RS_PAIR(g->e1[0]), e1y = RS_PAIR(g->e1[1]), e1z = RS_PAIR(g->e1[2]);
    __m512 e2x = RS_PAIR(g->e2[0]), e2y = RS_PAIR(g->e2[1]), e2z = RS_PAIR(g->e2[2]);
    __m512 v0x = RS_PAIR(g->v0[0]), v0y = RS_PAIR(g->v0[1]), v0z = RS_PAIR(g->v0[2]);
#undef RS_PAIR
    RS_MT_UV(rs16, __m512, o, d);
    const __m512 zero = _mm512_set1_ps(0.0f), one = _mm512_set1_ps(1.0f);
    __mmask16 ok = (__mmask16)((live & 1 ? 0x00FF : 0) | (live & 2 ? 0xFF00 : 0));
    ok &= _mm512_cmp_ps_mask(det, zero, _CMP_NEQ_UQ) & _mm512_cmp_ps_mask(u, zero, _CMP_GE_OQ)
          & _mm512_cmp_ps_mask(v, zero, _CMP_GE_OQ)
          & _mm512_cmp_ps_mask(_mm512_add_ps(u, v), one, _CMP_LE_OQ);
    if (!ok)                    /* both rays pass outside all eight: t is not needed */
        return 0;
    __m512 t = RS_MT_T(rs16);
    __m512 tmin = _mm512_mask_blend_ps(0xFF00, _mm512_set1_ps(r->tmin[i]),
                                       _mm512_set1_ps(r->tmin[j]));
    __m512 best = _mm512_mask_blend_ps(0xFF00, _mm512_set1_ps(r->t[i]), _mm512_set1_ps(r->t[j]));
    ok &= _mm512_cmp_ps_mask(t, tmin, _CMP_GT_OQ) & _mm512_cmp_ps_mask(t, best, _CMP_LE_OQ);
    if (!ok)
        return 0;
    float tl[16], ul[16], vl[16];
    _mm512_storeu_ps(tl, t);
    _mm512_storeu_ps(ul, u);
    _mm512_storeu_ps(vl, v);
    int changed = 0;
    for (int h = 0; h < 2; ++h) {
        int ray = h ? j : i, pick = rs_tri8_pick(r, ray, ok >> (8 * h) & 0xFF, tl + 8 * h, g->id);
        if (pick >= 0) {
            rs_tri8_keep(r, ray, tl[8 * h + pick], g->id[pick], ul[8 * h + pick],
                         vl[8 * h + pick], any_hit);
            changed |= 1 << h;
        }
    }
    return changed;
}

/* Rays i and j against the `tris` groups at g, a group at a time for both
 * while either still looks: rs_frustum_leaf_one's tests and counts for each. */
RS_INLINE int rs_frustum_leaf_pair(rs_rays *r, int i, int j, const rs_tri8 *g, int tris,
                                   int any_hit, rs_counters *c)
{
    __m512 o[3], d[3];
    int changed = 0;
    for (int a = 0; a < 3; ++a) {
        o[a] = _mm512_mask_blend_ps(0xFF00, _mm512_set1_ps(r->o[a][i]), _mm512_set1_ps(r->o[a][j]));
        d[a] = _mm512_mask_blend_ps(0xFF00, _mm512_set1_ps(r->d[a][i]), _mm512_set1_ps(r->d[a][j]));
    }
    for (int k = 0; k < tris; ++k) {
        int live = (r->tmin[i] < r->t[i]) | (r->tmin[j] < r->t[j]) << 1;
        if (!live)
            break;
        c->tri4 += rs_popcount(live);
        changed |= rs_tri8_hit_pair(r, i, j, o, d, &g[k], live, any_hit);
    }
    return changed != 0;
}
#endif

/* Does the frustum of a chunk pay (RS_FRUSTUM_MIN_RAYS active rays or more,
 * whose directions keep their sign, finite and non-zero, on two axes or more,
 * and spread by at most RS_FRUSTUM_SPREAD on every axis, and whose origins
 * spread by at most RS_FRUSTUM_ORIGINS of the longest ray on every axis)?
 * (Measured on Sibenik: with 0.25 camera rays and shadow rays
 * to the lamp take the walk, direction-sorted diffuse rays, which it would slow
 * down several times, do not.)  Otherwise it is traced one ray at a time. */
RS_INLINE int rs_frustum_coherent(const rs_frustum_bounds *b)
{
    if (b->rays < RS_FRUSTUM_MIN_RAYS)
        return 0;
    for (int a = 0; a < 3; ++a)
        if (!(b->dmax[a] - b->dmin[a] <= RS_FRUSTUM_SPREAD)
                || !(b->omax[a] - b->omin[a] <= RS_FRUSTUM_ORIGINS * b->tmax))
            return 0;
    return b->cull[0] + b->cull[1] + b->cull[2] >= 2;
}

/* A coherent chunk, lanes [s, e) with bounds b, through the tree.  `stack`
 * holds 7 entries per level of the tree plus 8. */
RS_INLINE void rs_frustum_walk(const rs_node8 *nodes, const rs_tri8 *groups, rs_rays *r, int s,
                               int e, int any_hit, rs_frustum_bounds *b,
                               rs_frustum_entry *stack, rs_counters *c)
{
    rs_frustum_entry hit[8];
    float entry[8];
    int sp = 0;
    stack[sp].ref = 0;
    stack[sp].tris = 0;
    stack[sp].parent = -1;
    stack[sp].slot = 0;
    stack[sp].entry = -INFINITY;
    ++sp;
    while (sp > 0) {
        rs_frustum_entry top = stack[--sp];
        if (top.entry > b->tmax * RS_BOX_SLACK) /* every ray has a closer hit */
            continue;
        if (top.ref >= 0) {
            const rs_node8 *n = &nodes[top.ref];
            c->ia += 1;
            int mask = rs_frustum_node8(b, n, entry), m = 0;
            for (; mask; mask &= mask - 1) {
                int k = rs_lowest(mask);
                if (!n->child[k])               /* an empty slot (types.h) */
                    continue;
                rs_frustum_entry child = {n->child[k], n->count[k], top.ref, k, entry[k]};
                rs_frustum_insert(hit, m++, child);
            }
            /* The nearest is popped first.  No prefetch of the children: a coherent
             * chunk's nodes are those its neighbours just walked, in cache, and the
             * prefetches cost camera rays 2-3 % (BENCHMARKS.md §9). */
            for (int k = m - 1; k >= 0; --k)
                stack[sp++] = hit[k];
            continue;
        }
        uint64_t rays = rs_frustum_leaf_rays(r, s, e, &nodes[top.parent], top.slot, c);
        if (!rays)
            continue;
        const rs_tri8 *g = &groups[-top.ref - 1];
        int changed = 0;
        for (int i = s; i + RS_SW <= ((e + 3) & ~3); i += RS_SW) {   /* dense blocks */
            int bits = (int)((rays >> (i - s)) & ((UINT64_C(1) << RS_SW) - 1));
            if (16 * rs_popcount(bits) >= RS_FRUSTUM_DENSE * RS_SW) {
                changed |= rs_frustum_leaf_block(r, i, bits, g, top.tris, any_hit, c);
                rays &= ~((uint64_t)(unsigned)bits << (i - s));
            }
        }
#if RS_ISA_AVX512
        for (; rays & (rays - 1); rays &= rays - 1) {   /* two rays or more: a pair */
            int i = s + rs_lowest64(rays);
            rays &= rays - 1;
            changed |= rs_frustum_leaf_pair(r, i, s + rs_lowest64(rays), g, top.tris, any_hit,
                                            c);
        }
#endif
        for (; rays; rays &= rays - 1)
            changed |= rs_frustum_leaf_one(r, s + rs_lowest64(rays), g, top.tris, any_hit, c);
        if (changed)                            /* t only falls where a hit changed */
            b->tmax = rs_frustum_reach(r, s, e);
    }
}

/* One chunk, lanes [s, e): together if coherent, else one ray at a time as
 * wide8 (`single` is rs_stream_single8's stack). */
RS_INLINE void rs_frustum_chunk(const rs_node8 *nodes, const rs_tri8 *groups, rs_rays *r, int s,
                                int e, int any_hit, rs_frustum_entry *stack,
                                rs_stream_entry *single, rs_counters *c)
{
    rs_frustum_bounds b;
    if (!rs_frustum_bounds_of(r, s, e, &b))
        return;
    if (rs_frustum_coherent(&b)) {
        rs_frustum_walk(nodes, groups, r, s, e, any_hit, &b, stack, c);
        return;
    }
    for (int i = s; i < e; ++i)
        if (r->tmin[i] < r->t[i])
            rs_stream_single8(nodes, groups, r, i, 0, 0, any_hit, single, c);
}

/* Lanes [start, start + count) in chunks of RS_FRUSTUM_CHUNK. */
RS_INLINE void rs_frustum_trace8(const rs_node8 *nodes, const rs_tri8 *groups, rs_rays *r,
                                 int start, int count, int any_hit, rs_frustum_entry *stack,
                                 rs_stream_entry *single, rs_counters *c)
{
    for (int s = start; s < start + count; s += RS_FRUSTUM_CHUNK) {
        int e = s + RS_FRUSTUM_CHUNK < start + count ? s + RS_FRUSTUM_CHUNK : start + count;
        rs_frustum_chunk(nodes, groups, r, s, e, any_hit, stack, single, c);
    }
}

#endif
