/* raysort: the ray-stream traversal kernel (Barringer & Akenine-Moller 2014).
 *
 * A stream of ray ids (lanes of a gathered rs_rays batch) descends the 4-wide
 * BVH (rs_node4) together.  At each node the stream is filtered into one
 * sub-stream per child: the ids of the rays whose slab test hits that child's
 * box, RS_SW rays per SIMD test (16 on AVX-512, 8 on AVX2, 4 on SSE2, 1 on the
 * scalar build).  The sub-streams go on a task stack, nearest child (by the
 * stream's majority) on top.  A leaf tests the rays of its stream against its
 * triangles, RS_SW rays at a time.  Streams smaller than a threshold finish
 * one ray at a time from their node, as bepu's RayBatcher does.
 *
 * Exactness: each lane performs rs_node4_hit's slab arithmetic on one child box
 * and rs_tri1's Moller-Trumbore arithmetic on one triangle, in the same order
 * (simd.h; -ffp-contract=off), and a box test uses the ray's current t, which
 * only ever shrinks to a hit brute force accepts.  So a ray meets every box
 * that holds its closest hit, and t, prim, u, v equal brute force bit for bit.
 */
#ifndef RAYSORT_STREAM_H
#define RAYSORT_STREAM_H

#include <stdlib.h>
#include "lanes.h"

/* The ids of the group of RS_SW rays that starts at ids[g] of a stream of n:
 * a short last group repeats its first id in the missing lanes, and *valid
 * masks them off. */
RS_INLINE rs_swi rs_stream_group(const int32_t *ids, int g, int n, int *valid)
{
    if (n - g >= RS_SW) {
        *valid = (1 << RS_SW) - 1;
        return sw_ids(ids + g);
    }
    int32_t lane[RS_SW];
    for (int k = 0; k < RS_SW; ++k)
        lane[k] = ids[g + (g + k < n ? k : 0)];
    *valid = (1 << (n - g)) - 1;
    return sw_ids(lane);
}

/* ------------------------------------------------------------------------ */
/* Scratch memory and tasks                                                 */
/* ------------------------------------------------------------------------ */

/* How the children of a node are ordered for a stream (the first is visited first). */
enum rs_stream_order {
    RS_ORDER_DIRECTION = 0, /* near corner first along the stream's majority octant */
    RS_ORDER_VOTES = 1      /* the child most rays enter first, first */
};

/* A stream waiting on the task stack: its ray ids are ids[first, first + n). */
typedef struct rs_stream_task {
    int32_t ref;        /* >= 0: a 4-wide node; < 0: a leaf, first triangle -ref - 1 */
    int32_t tris;       /* leaf triangles */
    int32_t first;      /* where its ids start in rs_stream_scratch.ids */
    int32_t n;          /* rays in the stream */
    int32_t level;      /* depth of its box in the 4-wide tree: 0 for the root */
} rs_stream_task;

/* A box one ray waits to visit, for the single-ray finish of small streams. */
typedef struct rs_stream_entry {
    int32_t ref;        /* as rs_stream_task.ref */
    int32_t tris;       /* leaf triangles */
    float entry;        /* where the ray enters the box */
} rs_stream_entry;

/* Scratch memory of one traversal call, sized by the stream size and the
 * depth of the 4-wide tree.  Each node popped replaces its stream by at most
 * four sub-streams no larger than it, at most three of which wait while the
 * walk goes one level down; so (3 * depth + 4) streams of `size` ids, and as
 * many tasks, bound the stacks. */
typedef struct rs_stream_scratch {
    int32_t *ids;           /* stack of id slices */
    int32_t *sub[4];        /* a node's per-child sub-streams while it is filtered */
    rs_stream_task *tasks;  /* task stack */
    rs_stream_entry *single;/* stack of the single-ray finish */
    int64_t *level_rays;    /* rays of the streams popped at each level, summed over the
                             * call (depth + 1 entries: the root is level 0, a leaf is one
                             * below its node; anything deeper counts in the last) */
    int size;               /* stream size (rays) */
    int depth;              /* levels of the 4-wide tree */
} rs_stream_scratch;

RS_INLINE int rs_stream_slots(int depth) { return 3 * depth + 4; }

RS_INLINE void rs_stream_free(rs_stream_scratch *w)
{
    free(w->ids);
    for (int k = 0; k < 4; ++k)
        free(w->sub[k]);
    free(w->tasks);
    free(w->single);
    free(w->level_rays);
}

/* Allocate the scratch memory; returns 0 when out of memory (nothing held). */
RS_INLINE int rs_stream_alloc(rs_stream_scratch *w, int size, int depth)
{
    int slots = rs_stream_slots(depth);
    w->size = size;
    w->depth = depth;
    w->ids = (int32_t *)malloc(((size_t)slots * size + RS_SW) * sizeof(int32_t));
    for (int k = 0; k < 4; ++k)
        w->sub[k] = (int32_t *)malloc(((size_t)size + RS_SW) * sizeof(int32_t));
    w->tasks = (rs_stream_task *)malloc((size_t)slots * sizeof(rs_stream_task));
    w->single = (rs_stream_entry *)malloc((size_t)slots * sizeof(rs_stream_entry));
    w->level_rays = (int64_t *)calloc((size_t)depth + 1, sizeof(int64_t));
    if (!w->ids || !w->sub[0] || !w->sub[1] || !w->sub[2] || !w->sub[3] || !w->tasks
        || !w->single || !w->level_rays) {
        rs_stream_free(w);
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------------ */
/* A stream at an inner node: filter it into the children's sub-streams      */
/* ------------------------------------------------------------------------ */

/* Split ids[0, n) into w->sub[k] (cnt[k] ids each): the rays that hit child k's
 * box before their current t.  votes[k] counts the rays for which child k is
 * the nearest box hit; negative[a] the rays travelling down axis a. */
RS_INLINE void rs_stream_filter(const rs_rays *r, const rs_node4 *node, const int32_t *ids,
                                int n, rs_stream_scratch *w, int cnt[4], int votes[4],
                                int negative[3])
{
    int live[4], m = 0;
    for (int k = 0; k < 4; ++k) {
        cnt[k] = votes[k] = 0;
        if (node->lo[0][k] <= node->hi[0][k])    /* an empty slot has lo > hi */
            live[m++] = k;
    }
    negative[0] = negative[1] = negative[2] = 0;
    const rs_swf slack = sw_set1(RS_BOX_SLACK), inf = sw_set1(INFINITY);
    for (int g = 0; g < n; g += RS_SW) {
        int valid;
        rs_swi id = rs_stream_group(ids, g, n, &valid);
        rs_swf o[3], inv[3];
        rs_swm neg[3];
        for (int a = 0; a < 3; ++a) {
            o[a] = sw_gather(r->o[a], id);
            inv[a] = sw_gather(r->inv[a], id);
            neg[a] = sw_sign(inv[a]);
            negative[a] += rs_popcount(sw_bits(neg[a]) & valid);
        }
        rs_swf tmin = sw_gather(r->tmin, id), t = sw_gather(r->t, id), best = inf;
        int nearest[4] = {0, 0, 0, 0};
        for (int j = 0; j < m; ++j) {
            int k = live[j];
            rs_swf tn = tmin, tf = t;
            for (int a = 0; a < 3; ++a) {
                rs_swf t_lo = sw_mul(sw_sub(sw_set1(node->lo[a][k]), o[a]), inv[a]);
                rs_swf t_hi = sw_mul(sw_sub(sw_set1(node->hi[a][k]), o[a]), inv[a]);
                tn = sw_max(sw_blend(neg[a], t_hi, t_lo), tn);
                tf = sw_min(sw_blend(neg[a], t_lo, t_hi), tf);
            }
            rs_swm hit = sw_and(sw_le(tn, sw_mul(tf, slack)), sw_from_bits(valid));
            int bits = sw_bits(hit);
            sw_append(w->sub[k], &cnt[k], id, bits);
            int closer = sw_bits(sw_and(hit, sw_lt(tn, best)));
            best = sw_blend(sw_from_bits(closer), tn, best);
            for (int i = 0; i < j; ++i)
                nearest[i] &= ~closer;
            nearest[j] = closer;
        }
        for (int j = 0; j < m; ++j)
            votes[live[j]] += rs_popcount(nearest[j]);
    }
}

/* Order the children with a non-empty sub-stream, the one to visit first first;
 * returns how many.  Ties keep the node's child order. */
RS_INLINE int rs_stream_order(const rs_node4 *node, const int cnt[4], const int votes[4],
                              const int negative[3], int n, int order, int visit[4])
{
    float key[4];
    int m = 0;
    for (int k = 0; k < 4; ++k) {
        if (!cnt[k])
            continue;
        if (order == RS_ORDER_VOTES) {
            key[k] = (float)-votes[k];
        } else {
            key[k] = 0.0f;
            for (int a = 0; a < 3; ++a)
                key[k] += 2 * negative[a] > n ? -node->hi[a][k] : node->lo[a][k];
        }
        int j = m++;
        while (j > 0 && key[visit[j - 1]] > key[k]) {
            visit[j] = visit[j - 1];
            --j;
        }
        visit[j] = k;
    }
    return m;
}

/* ------------------------------------------------------------------------ */
/* A stream at a leaf                                                       */
/* ------------------------------------------------------------------------ */

/* Test the rays ids[0, n) against triangles tris[0, count), RS_SW rays at a
 * time; each lane performs rs_tri1's operations and acceptance rule. */
RS_INLINE void rs_stream_leaf(rs_rays *r, const rs_tri *tris, int count, const int32_t *ids,
                              int n, int any_hit)
{
    const rs_swf zero = sw_set1(0.0f), one = sw_set1(1.0f), retired = sw_set1(-INFINITY);
    for (int g = 0; g < n; g += RS_SW) {
        int valid;
        rs_swi id = rs_stream_group(ids, g, n, &valid);
        rs_swf ox = sw_gather(r->o[0], id), oy = sw_gather(r->o[1], id),
               oz = sw_gather(r->o[2], id);
        rs_swf dx = sw_gather(r->d[0], id), dy = sw_gather(r->d[1], id),
               dz = sw_gather(r->d[2], id);
        rs_swf tmin = sw_gather(r->tmin, id), best = sw_gather(r->t, id);
        rs_swi bprim = sw_gatheri(r->prim, id);
        rs_swf bu = zero, bv = zero;
        rs_swm lanes = sw_from_bits(valid);
        int changed = 0;
        for (int k = 0; k < count; ++k) {
            const rs_tri *tr = &tris[k];
            rs_swf e1x = sw_set1(tr->e1[0]), e1y = sw_set1(tr->e1[1]), e1z = sw_set1(tr->e1[2]);
            rs_swf e2x = sw_set1(tr->e2[0]), e2y = sw_set1(tr->e2[1]), e2z = sw_set1(tr->e2[2]);
            rs_swf px = sw_sub(sw_mul(dy, e2z), sw_mul(dz, e2y));
            rs_swf py = sw_sub(sw_mul(dz, e2x), sw_mul(dx, e2z));
            rs_swf pz = sw_sub(sw_mul(dx, e2y), sw_mul(dy, e2x));
            rs_swf det = sw_add(sw_add(sw_mul(e1x, px), sw_mul(e1y, py)), sw_mul(e1z, pz));
            rs_swf inv = sw_div(one, det);
            rs_swf sx = sw_sub(ox, sw_set1(tr->v0[0]));
            rs_swf sy = sw_sub(oy, sw_set1(tr->v0[1]));
            rs_swf sz = sw_sub(oz, sw_set1(tr->v0[2]));
            rs_swf u = sw_mul(sw_add(sw_add(sw_mul(sx, px), sw_mul(sy, py)), sw_mul(sz, pz)), inv);
            rs_swf qx = sw_sub(sw_mul(sy, e1z), sw_mul(sz, e1y));
            rs_swf qy = sw_sub(sw_mul(sz, e1x), sw_mul(sx, e1z));
            rs_swf qz = sw_sub(sw_mul(sx, e1y), sw_mul(sy, e1x));
            rs_swf v = sw_mul(sw_add(sw_add(sw_mul(dx, qx), sw_mul(dy, qy)), sw_mul(dz, qz)), inv);
            rs_swf t = sw_mul(sw_add(sw_add(sw_mul(e2x, qx), sw_mul(e2y, qy)), sw_mul(e2z, qz)),
                              inv);
            rs_swi tid = sw_set1i(tr->id);
            rs_swm ok = sw_and(sw_and(sw_ne(det, zero), sw_ge(u, zero)),
                               sw_and(sw_ge(v, zero), sw_le(sw_add(u, v), one)));
            ok = sw_and(ok, sw_gt(t, tmin));
            ok = sw_and(ok, sw_or(sw_lt(t, best), sw_and(sw_eq(t, best), sw_lti(tid, bprim))));
            ok = sw_and(ok, lanes);
            int bits = sw_bits(ok);
            if (bits) {
                best = sw_blend(ok, any_hit ? retired : t, best);
                bprim = sw_blendi(ok, tid, bprim);
                bu = sw_blend(ok, u, bu);
                bv = sw_blend(ok, v, bv);
                changed |= bits;
            }
        }
        if (changed) {
            float lt[RS_SW], lu[RS_SW], lv[RS_SW];
            int32_t lp[RS_SW], li[RS_SW];
            sw_store(lt, best);
            sw_store(lu, bu);
            sw_store(lv, bv);
            sw_storei(lp, bprim);
            sw_storei(li, id);
            for (; changed; changed &= changed - 1) {
                int k = rs_lowest(changed);
                int32_t i = li[k];
                r->t[i] = lt[k];
                r->prim[i] = lp[k];
                r->u[i] = lu[k];
                r->v[i] = lv[k];
            }
        }
    }
}

/* ------------------------------------------------------------------------ */
/* A small stream: one ray at a time from its node                          */
/* ------------------------------------------------------------------------ */

/* Ask for a box's data ahead of its visit: a 4-wide node's two cache lines, or
 * a leaf's first triangles (hints; no effect on results). */
RS_INLINE void rs_stream_prefetch(const rs_node4 *nodes, const rs_tri *tris, int32_t ref)
{
    const char *p = ref >= 0 ? (const char *)&nodes[ref] : (const char *)&tris[-ref - 1];
    rs_prefetch(p);
    rs_prefetch(p + 64);
}

/* Ray i from box (ref, tris) down, as the `wide` traversal walks from the root:
 * children hit are visited nearest first, waiting boxes are dropped once the
 * ray's t is closer than where it enters them. */
RS_INLINE void rs_stream_single(const rs_node4 *nodes, const rs_tri *tris, rs_rays *r, int i,
                                int32_t ref, int32_t count, int any_hit,
                                rs_stream_entry *stack, rs_counters *c)
{
    rs_stream_entry hit[4], tmp;
    float entry[4];
    int sp = 0;
    while (1) {
        if (ref >= 0) {
            const rs_node4 *n = &nodes[ref];
            c->box4 += 1;
            int mask = rs_node4_hit(r, i, n, entry), m = 0;
            for (int k = 0; k < 4; ++k) {
                if (!(mask >> k & 1))
                    continue;
                hit[m].ref = n->child[k];
                hit[m].tris = n->count[k];
                hit[m].entry = entry[k];
                rs_stream_prefetch(nodes, tris, hit[m].ref);
                for (int j = m; j > 0 && hit[j - 1].entry > hit[j].entry; --j) {
                    tmp = hit[j - 1];
                    hit[j - 1] = hit[j];
                    hit[j] = tmp;
                }
                ++m;
            }
            for (int k = m - 1; k > 0; --k)     /* farther children wait, farthest deepest */
                stack[sp++] = hit[k];
            if (m) {
                ref = hit[0].ref;
                count = hit[0].tris;
                continue;
            }
        } else {
            const rs_tri *leaf = &tris[-ref - 1];
            for (int k = 0; k < count; ++k) {
                c->tri1 += 1;
                rs_tri1(r, i, &leaf[k], any_hit);
            }
            if (!(r->tmin[i] < r->t[i]))        /* an any-hit query found its hit */
                return;
        }
        /* the nearest waiting box the ray still reaches before its closest hit */
        for (;;) {
            if (sp == 0)
                return;
            --sp;
            if (stack[sp].entry <= r->t[i] * RS_BOX_SLACK)
                break;
        }
        ref = stack[sp].ref;
        count = stack[sp].tris;
    }
}

/* ------------------------------------------------------------------------ */
/* The traversal of one stream                                              */
/* ------------------------------------------------------------------------ */

/* Trace the n <= w->size rays whose ids are w->ids[0, n) from the root of
 * `nodes`.  Streams of fewer than min_stream rays finish one ray at a time.
 *
 * Counters, the same on every ISA: one SIMD N_B per ray and node a stream
 * visits (the ray meets the node's four child boxes, as in `wide`), one SIMD
 * N_T per triangle and 4 rays (rounded up) a leaf's stream holds, and the
 * single-ray finish counts as `wide` does.  stream_tasks and stream_rays count
 * the streams popped and the rays they held, w->level_rays the same rays by the
 * level of the box the stream was popped at (they add up to stream_rays). */
RS_INLINE void rs_stream_trace(const rs_node4 *nodes, const rs_tri *tris, rs_rays *r, int n,
                               int any_hit, int order, int min_stream, rs_stream_scratch *w,
                               rs_counters *c)
{
    int cnt[4], votes[4], negative[3], visit[4];
    int nt = 1;
    w->tasks[0].ref = 0;
    w->tasks[0].tris = 0;
    w->tasks[0].first = 0;
    w->tasks[0].n = n;
    w->tasks[0].level = 0;
    while (nt > 0) {
        rs_stream_task task = w->tasks[--nt];
        int32_t *ids = w->ids + task.first;
        if (task.n < min_stream) {
            for (int j = 0; j < task.n; ++j) {
                int i = ids[j];
                if (r->tmin[i] < r->t[i])
                    rs_stream_single(nodes, tris, r, i, task.ref, task.tris, any_hit, w->single,
                                     c);
            }
            continue;
        }
        c->stream_tasks += 1;
        c->stream_rays += task.n;
        w->level_rays[task.level < w->depth ? task.level : w->depth] += task.n;
        if (task.ref < 0) {
            c->tri4 += (int64_t)task.tris * ((task.n + 3) / 4);
            rs_stream_leaf(r, &tris[-task.ref - 1], task.tris, ids, task.n, any_hit);
            continue;
        }
        const rs_node4 *node = &nodes[task.ref];
        c->box4 += task.n;
        rs_stream_filter(r, node, ids, task.n, w, cnt, votes, negative);
        int m = rs_stream_order(node, cnt, votes, negative, task.n, order, visit);
        /* the parent's ids are read: its slice takes the sub-streams, the one
         * to visit first last, so it is popped first */
        int first = task.first;
        for (int j = m - 1; j >= 0; --j) {
            int k = visit[j];
            memcpy(w->ids + first, w->sub[k], (size_t)cnt[k] * sizeof(int32_t));
            rs_stream_task *child = &w->tasks[nt++];
            child->ref = node->child[k];
            child->tris = node->count[k];
            child->first = first;
            child->n = cnt[k];
            child->level = task.level + 1;
            first += cnt[k];
        }
        if (m)
            rs_stream_prefetch(nodes, tris, node->child[visit[0]]);
    }
}

#endif
