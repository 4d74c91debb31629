/* raysort: the ray-stream traversal kernel (Barringer & Akenine-Moller 2014).
 *
 * A stream of ray ids (lanes of a gathered rs_rays batch) descends a wide BVH
 * together: the 8-wide one (rs_node8 nodes, rs_tri8 leaf groups: BVH.wide8)
 * or the 4-wide one (rs_node4, rs_tri: BVH.wide).  At each node the stream is
 * filtered into one sub-stream per child: the ids of the rays whose slab test
 * hits that child's box, RS_SW rays per SIMD test (16 on AVX-512, 8 on AVX2,
 * 4 on SSE2, 1 on the scalar build).  The sub-streams go on a task stack, the
 * child the stream prefers on top.  A leaf tests the rays of its stream
 * against each of its triangles, RS_SW rays at a time.  Streams smaller than a
 * threshold finish one ray at a time from their node with the tree's
 * single-ray kernels (wide8.h's, or simd.h's 4-wide ones), as bepu's
 * RayBatcher does.
 *
 * A stream first copies its rays into records of 64 bytes (rs_stream_ray), and
 * its ids are then indices of records: a group of RS_SW rays loads the eight
 * floats a box test needs with RS_SW row loads and a transpose (sw_rows8)
 * instead of eight gathers from eight rows of
 * rs_rays; the hits go back to the rays when the stream is done.
 *
 * Exactness: each lane performs rs_box1's slab arithmetic on one child box
 * and rs_tri1's Moller-Trumbore arithmetic on one triangle, in the same order
 * (simd.h; -ffp-contract=off), and a box test uses the ray's current t, which
 * only ever shrinks to a hit brute force accepts.  So a ray meets every box
 * that holds its closest hit, and t, prim, u, v equal brute force bit for bit.
 */
#ifndef RAYSORT_STREAM_H
#define RAYSORT_STREAM_H

#include <stdlib.h>
#include "wide8.h"
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

/* Most children of a node: the 8-wide tree's. */
#define RS_STREAM_MAX_WIDTH 8

/* One ray of a stream: what its box tests read first (o, tmin, inv, t: one
 * sw_rows8), then what its triangle tests read too (d, prim; u, v and the
 * ray's index in rs_rays).  t, prim, u, v are the ray's closest hit so far. */
typedef struct rs_stream_ray {
    float o[3], tmin, inv[3], t;
    float d[3];
    int32_t prim;
    float u, v;
    int32_t ray;
    float t0;           /* t before the walk (the ray's tmax), for a check of the hit */
} rs_stream_ray;

#define RS_STREAM_RAY_FLOATS 16     /* sizeof(rs_stream_ray) / 4: the sw_rows8 stride */

/* A stream waiting on the task stack: its records are ids[first, first + n). */
typedef struct rs_stream_task {
    int32_t ref;        /* >= 0: an inner node; < 0: a leaf, first triangle (4-wide tree)
                         * or triangle group (8-wide tree) -ref - 1 */
    int32_t tris;       /* a leaf's triangles (4-wide) or groups (8-wide) */
    int32_t first;      /* where its ids start in rs_stream_scratch.ids */
    int32_t n;          /* rays in the stream */
    int32_t level;      /* depth of its box in the tree: 0 for the root */
} rs_stream_task;

/* A box one ray waits to visit, for the single-ray finish of small streams. */
typedef struct rs_stream_entry {
    int32_t ref;        /* as rs_stream_task.ref */
    int32_t tris;       /* as rs_stream_task.tris */
    float entry;        /* where the ray enters the box */
} rs_stream_entry;

/* Scratch memory of one traversal call, sized by the stream size, the tree's
 * width and its depth.  Each node popped replaces its stream by at most
 * `width` sub-streams no larger than it, at most width - 1 of which wait while
 * the walk goes one level down; so ((width - 1) * depth + width) streams of
 * `size` ids, and as many tasks, bound the stacks. */
typedef struct rs_stream_scratch {
    rs_stream_ray *rec;     /* the records of the stream's rays (64-byte aligned) */
    void *rec_block;        /* the allocation rec lies in */
    int32_t *ids;           /* stack of slices of record indices */
    int32_t *sub[RS_STREAM_MAX_WIDTH];  /* a node's per-child sub-streams while it is filtered */
    rs_stream_task *tasks;  /* task stack */
    rs_stream_entry *single;/* stack of the single-ray finish */
    int64_t *level_rays;    /* rays of the streams popped at each level, summed over the
                             * call (depth + 1 entries: the root is level 0, a leaf is one
                             * below its node; anything deeper counts in the last) */
    int size;               /* stream size (rays) */
    int width;              /* children per node: 4 or 8 */
    int depth;              /* levels of the tree */
} rs_stream_scratch;

RS_INLINE int rs_stream_slots(int width, int depth) { return (width - 1) * depth + width; }

RS_INLINE void rs_stream_free(rs_stream_scratch *w)
{
    free(w->rec_block);
    free(w->ids);
    for (int k = 0; k < RS_STREAM_MAX_WIDTH; ++k)
        free(w->sub[k]);
    free(w->tasks);
    free(w->single);
    free(w->level_rays);
}

/* Allocate the scratch memory for a tree of `width` (4 or 8) children per node;
 * returns 0 when out of memory (nothing held). */
RS_INLINE int rs_stream_alloc(rs_stream_scratch *w, int size, int width, int depth)
{
    int slots = rs_stream_slots(width, depth), ok = 1;
    w->size = size;
    w->width = width;
    w->depth = depth;
    w->rec_block = malloc(((size_t)size + 1) * sizeof(rs_stream_ray));
    w->rec = w->rec_block ? (rs_stream_ray *)(((uintptr_t)w->rec_block + 63) & ~(uintptr_t)63)
                          : NULL;
    w->ids = (int32_t *)malloc(((size_t)slots * size + RS_SW) * sizeof(int32_t));
    for (int k = 0; k < RS_STREAM_MAX_WIDTH; ++k) {
        w->sub[k] = k < width ? (int32_t *)malloc(((size_t)size + RS_SW) * sizeof(int32_t)) : NULL;
        ok &= k >= width || w->sub[k] != NULL;
    }
    w->tasks = (rs_stream_task *)malloc((size_t)slots * sizeof(rs_stream_task));
    w->single = (rs_stream_entry *)malloc((size_t)slots * sizeof(rs_stream_entry));
    w->level_rays = (int64_t *)calloc((size_t)depth + 1, sizeof(int64_t));
    if (!ok || !w->rec_block || !w->ids || !w->tasks || !w->single || !w->level_rays) {
        rs_stream_free(w);
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------------ */
/* A stream at an inner node: filter it into the children's sub-streams      */
/* ------------------------------------------------------------------------ */

/* Split ids[0, n) into sub[k] (cnt[k] ids each), k < width: the rays (records
 * of rec) that hit child k's box before their current t.  The boxes are
 * structure-of-arrays, lo[a * width + k] and hi[a * width + k] (rs_node4 or
 * rs_node8).  votes[k] counts the rays for which child k is the nearest box
 * hit; negative[a] the rays travelling down axis a. */
RS_INLINE void rs_stream_filter(const rs_stream_ray *rec, int width, const float *lo,
                                const float *hi, const int32_t *ids, int n,
                                int32_t *const *sub, int *cnt, int *votes, int negative[3])
{
    int live[RS_STREAM_MAX_WIDTH], m = 0, down[3] = {0, 0, 0};
    for (int k = 0; k < width; ++k) {
        cnt[k] = votes[k] = 0;
        if (lo[k] <= hi[k])                 /* an empty slot has lo > hi */
            live[m++] = k;
    }
    const rs_swf slack = sw_set1(RS_BOX_SLACK), inf = sw_set1(INFINITY);
    for (int g = 0; g < n; g += RS_SW) {
        int valid;
        rs_swi id = rs_stream_group(ids, g, n, &valid);
        rs_swf f[8], o[3], inv[3];
        rs_swm neg[3];
        sw_rows8(rec->o, RS_STREAM_RAY_FLOATS, id, f);      /* o, tmin, inv, t */
        for (int a = 0; a < 3; ++a) {
            o[a] = f[a];
            inv[a] = f[4 + a];
            neg[a] = sw_sign(inv[a]);
            down[a] += rs_popcount(sw_bits(neg[a]) & valid);
        }
        rs_swf tmin = f[3], t = f[7], best = inf;
        rs_swi nearest = sw_set1i(-1);      /* per lane: j of the nearest live child hit */
        for (int j = 0; j < m; ++j) {
            int k = live[j];
            rs_swf tn = tmin, tf = t;
            for (int a = 0; a < 3; ++a) {
                rs_swf t_lo = sw_mul(sw_sub(sw_set1(lo[a * width + k]), o[a]), inv[a]);
                rs_swf t_hi = sw_mul(sw_sub(sw_set1(hi[a * width + k]), o[a]), inv[a]);
                tn = sw_max(sw_blend(neg[a], t_hi, t_lo), tn);
                tf = sw_min(sw_blend(neg[a], t_lo, t_hi), tf);
            }
            rs_swm hit = sw_and(sw_le(tn, sw_mul(tf, slack)), sw_from_bits(valid));
            int bits = sw_bits(hit);
            sw_append(sub[k], &cnt[k], id, bits);
            rs_swm closer = sw_and(hit, sw_lt(tn, best));
            best = sw_blend(closer, tn, best);
            nearest = sw_blendi(closer, sw_set1i(j), nearest);
        }
        for (int j = 0; j < m; ++j)
            votes[live[j]] += rs_popcount(sw_eqi_bits(nearest, sw_set1i(j)));
    }
    for (int a = 0; a < 3; ++a)
        negative[a] = down[a];
}

/* Order the children with a non-empty sub-stream, the one to visit first first;
 * returns how many.  Ties keep the node's child order. */
RS_INLINE int rs_stream_order(int width, const float *lo, const float *hi, const int *cnt,
                              const int *votes, const int negative[3], int n, int order,
                              int *visit)
{
    float key[RS_STREAM_MAX_WIDTH];
    int m = 0;
    for (int k = 0; k < width; ++k) {
        if (!cnt[k])
            continue;
        if (order == RS_ORDER_VOTES) {
            key[k] = (float)-votes[k];
        } else {
            key[k] = 0.0f;
            for (int a = 0; a < 3; ++a)
                key[k] += 2 * negative[a] > n ? -hi[a * width + k] : lo[a * width + k];
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

/* RS_SW rays of a stream at a leaf, gathered, with their closest hits so far. */
typedef struct rs_stream_lanes {
    rs_swi id;
    rs_swf o[3], d[3], tmin, best, u, v;
    rs_swi prim;
    rs_swm valid;
    int changed;        /* lanes whose hit changed */
} rs_stream_lanes;

RS_INLINE void rs_stream_lanes_load(const rs_stream_ray *rec, const int32_t *ids, int g, int n,
                                    rs_stream_lanes *s)
{
    int valid;
    rs_swf f[8], h[8];
    s->id = rs_stream_group(ids, g, n, &valid);
    sw_rows8(rec->o, RS_STREAM_RAY_FLOATS, s->id, f);       /* o, tmin, inv, t */
    sw_rows8(rec->d, RS_STREAM_RAY_FLOATS, s->id, h);       /* d, prim, u, v, ray */
    for (int a = 0; a < 3; ++a) {
        s->o[a] = f[a];
        s->d[a] = h[a];
    }
    s->tmin = f[3];
    s->best = f[7];
    s->prim = sw_asi(h[3]);
    s->u = s->v = sw_set1(0.0f);
    s->valid = sw_from_bits(valid);
    s->changed = 0;
}

/* Write the lanes whose hit changed back to their records. */
RS_INLINE void rs_stream_lanes_store(rs_stream_ray *rec, const rs_stream_lanes *s)
{
    int changed = s->changed;
    if (!changed)
        return;
    float lt[RS_SW], lu[RS_SW], lv[RS_SW];
    int32_t lp[RS_SW], li[RS_SW];
    sw_store(lt, s->best);
    sw_store(lu, s->u);
    sw_store(lv, s->v);
    sw_storei(lp, s->prim);
    sw_storei(li, s->id);
    for (; changed; changed &= changed - 1) {
        int k = rs_lowest(changed);
        rs_stream_ray *x = &rec[li[k]];
        x->t = lt[k];
        x->prim = lp[k];
        x->u = lu[k];
        x->v = lv[k];
    }
}

/* The lanes against one triangle (component a of v0, e1, e2 at [a * stride]):
 * each lane performs rs_tri1's operations and acceptance rule. */
RS_INLINE void rs_stream_tri(rs_stream_lanes *s, const float *v0, const float *e1,
                             const float *e2, int stride, int32_t prim, int any_hit)
{
    const rs_swf zero = sw_set1(0.0f), one = sw_set1(1.0f);
    rs_swf e1x = sw_set1(e1[0]), e1y = sw_set1(e1[stride]), e1z = sw_set1(e1[2 * stride]);
    rs_swf e2x = sw_set1(e2[0]), e2y = sw_set1(e2[stride]), e2z = sw_set1(e2[2 * stride]);
    rs_swf v0x = sw_set1(v0[0]), v0y = sw_set1(v0[stride]), v0z = sw_set1(v0[2 * stride]);
    RS_MT_UV(sw, rs_swf, s->o, s->d);
    rs_swf t = RS_MT_T(sw);
    rs_swi tid = sw_set1i(prim);
    rs_swm ok = sw_and(sw_and(sw_ne(det, zero), sw_ge(u, zero)),
                       sw_and(sw_ge(v, zero), sw_le(sw_add(u, v), one)));
    ok = sw_and(ok, sw_gt(t, s->tmin));
    ok = sw_and(ok, sw_or(sw_lt(t, s->best), sw_and(sw_eq(t, s->best), sw_lti(tid, s->prim))));
    ok = sw_and(ok, s->valid);
    s->best = sw_blend(ok, any_hit ? sw_set1(-INFINITY) : t, s->best);
    s->prim = sw_blendi(ok, tid, s->prim);
    s->u = sw_blend(ok, u, s->u);
    s->v = sw_blend(ok, v, s->v);
    s->changed |= sw_bits(ok);
}

/* Test the rays ids[0, n) against triangles tris[0, count) (the 4-wide tree's
 * leaves), RS_SW rays at a time. */
RS_INLINE void rs_stream_leaf4(rs_stream_ray *rec, const rs_tri *tris, int count,
                               const int32_t *ids, int n, int any_hit)
{
    rs_stream_lanes s;
    for (int g = 0; g < n; g += RS_SW) {
        rs_stream_lanes_load(rec, ids, g, n, &s);
        for (int k = 0; k < count; ++k)
            rs_stream_tri(&s, tris[k].v0, tris[k].e1, tris[k].e2, 1, tris[k].id, any_hit);
        rs_stream_lanes_store(rec, &s);
    }
}

/* Test the rays ids[0, n) against the triangles of groups[0, count) (the 8-wide
 * tree's leaves), RS_SW rays per triangle; a group's unused lanes (id
 * INT32_MAX, zero edges: never hit) are skipped. */
RS_INLINE void rs_stream_leaf8(rs_stream_ray *rec, const rs_tri8 *groups, int count,
                               const int32_t *ids, int n, int any_hit)
{
    rs_stream_lanes s;
    for (int g = 0; g < n; g += RS_SW) {
        rs_stream_lanes_load(rec, ids, g, n, &s);
        for (int j = 0; j < count; ++j) {
            const rs_tri8 *tr = &groups[j];
            for (int k = 0; k < 8; ++k)
                if (tr->id[k] != INT32_MAX)
                    rs_stream_tri(&s, &tr->v0[0][k], &tr->e1[0][k], &tr->e2[0][k], 8,
                                  tr->id[k], any_hit);
        }
        rs_stream_lanes_store(rec, &s);
    }
}

/* ------------------------------------------------------------------------ */
/* A small stream: one ray at a time from its node                          */
/* ------------------------------------------------------------------------ */

/* Ask for a box's data ahead of its visit (hints; no effect on results):
 * `lines` cache lines of an inner node or of a leaf's first triangles. */
RS_INLINE void rs_stream_prefetch(const void *node, int lines)
{
    const char *p = (const char *)node;
    for (int k = 0; k < lines; ++k)
        rs_prefetch(p + 64 * k);
}

/* Insert (ref, tris, entry) into hit[0, m), which is sorted nearest first. */
RS_INLINE void rs_stream_insert(rs_stream_entry *hit, int m, int32_t ref, int32_t tris,
                                float entry)
{
    int j = m;
    while (j > 0 && hit[j - 1].entry > entry) {
        hit[j] = hit[j - 1];
        --j;
    }
    hit[j].ref = ref;
    hit[j].tris = tris;
    hit[j].entry = entry;
}

/* Pop waiting boxes until one ray i still enters before its closest hit
 * (entry <= t * slack: what a new slab test would decide); 0 when none is left. */
RS_INLINE int rs_stream_pop(const rs_rays *r, int i, const rs_stream_entry *stack, int *sp,
                            int32_t *ref, int32_t *tris)
{
    while (*sp > 0) {
        const rs_stream_entry *e = &stack[--*sp];
        if (e->entry <= r->t[i] * RS_BOX_SLACK) {
            *ref = e->ref;
            *tris = e->tris;
            return 1;
        }
    }
    return 0;
}

/* Ray i from box (ref, count) of the 4-wide tree down, as the `wide`
 * traversal walks from the root: children hit are visited nearest first,
 * waiting boxes are dropped once the ray's t is closer than where it enters
 * them. */
RS_INLINE void rs_stream_single4(const rs_node4 *nodes, const rs_tri *tris, rs_rays *r, int i,
                                 int32_t ref, int32_t count, int any_hit,
                                 rs_stream_entry *stack, rs_counters *c)
{
    rs_stream_entry hit[4];
    float entry[4];
    int sp = 0;
    for (;;) {
        if (ref >= 0) {
            const rs_node4 *n = &nodes[ref];
            c->box4 += 1;
            int mask = rs_node4_hit(r, i, n, entry), m = 0;
            for (; mask; mask &= mask - 1) {
                int k = rs_lowest(mask);
                if (!n->child[k])               /* an empty slot (types.h) */
                    continue;
                rs_stream_insert(hit, m++, n->child[k], n->count[k], entry[k]);
                rs_stream_prefetch(n->child[k] >= 0 ? (const void *)&nodes[n->child[k]]
                                   : (const void *)&tris[-n->child[k] - 1], 2);
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
        if (!rs_stream_pop(r, i, stack, &sp, &ref, &count))
            return;
    }
}

/* Ray i from box (ref, count) of the 8-wide tree down, as the `wide8`
 * traversal walks from the root (one ray against a node's eight boxes, and
 * against a leaf's groups of eight triangles). */
RS_INLINE void rs_stream_single8(const rs_node8 *nodes, const rs_tri8 *groups, rs_rays *r, int i,
                                 int32_t ref, int32_t count, int any_hit,
                                 rs_stream_entry *stack, rs_counters *c)
{
    rs_stream_entry hit[8];
    float entry[8];
    rs_ray8 ray;
    int sp = 0;
    rs_ray8_load(r, i, &ray);
    for (;;) {
        if (ref >= 0) {
            const rs_node8 *n = &nodes[ref];
            c->box4 += 1;
            int mask = rs_node8_hit(r, i, &ray, n, entry), m = 0;
            for (; mask; mask &= mask - 1) {
                int k = rs_lowest(mask);
                if (n->child[k])                /* not an empty slot (types.h) */
                    rs_stream_insert(hit, m++, n->child[k], n->count[k], entry[k]);
            }
            for (int k = m - 1; k > 0; --k) {   /* farther children wait, farthest deepest */
                stack[sp++] = hit[k];
                rs_prefetch(hit[k].ref >= 0 ? (const void *)&nodes[hit[k].ref]
                            : (const void *)&groups[-hit[k].ref - 1]);
            }
            if (m) {
                ref = hit[0].ref;
                count = hit[0].tris;
                if (ref >= 0)
                    rs_stream_prefetch(&nodes[ref], 4);
                else
                    rs_stream_prefetch(&groups[-ref - 1], 5);
                continue;
            }
        } else {
            const rs_tri8 *g = &groups[-ref - 1];
            for (int k = 0; k < count; ++k) {
                c->tri4 += 1;
                rs_tri8_hit(r, i, &ray, &g[k], any_hit);
            }
            if (!(r->tmin[i] < r->t[i]))        /* an any-hit query found its hit */
                return;
        }
        if (!rs_stream_pop(r, i, stack, &sp, &ref, &count))
            return;
    }
}

/* ------------------------------------------------------------------------ */
/* The traversal of one stream                                              */
/* ------------------------------------------------------------------------ */

/* Lane i of r into the record x of ray `ray` (its index in whatever r was gathered
 * from), its hit so far included. */
RS_INLINE void rs_stream_record(const rs_rays *r, int i, int32_t ray, rs_stream_ray *x)
{
    for (int a = 0; a < 3; ++a) {
        x->o[a] = r->o[a][i];
        x->inv[a] = r->inv[a][i];
        x->d[a] = r->d[a][i];
    }
    x->tmin = r->tmin[i];
    x->t = r->t[i];
    x->prim = r->prim[i];
    x->u = r->u[i];
    x->v = r->v[i];
    x->ray = ray;
    x->t0 = x->t;
}

/* Copy rays ids[0, n) into the records rec[0, n) and make ids[j] = j. */
RS_INLINE void rs_stream_records(const rs_rays *r, int32_t *ids, int n, rs_stream_ray *rec)
{
    for (int j = 0; j < n; ++j) {
        rs_stream_record(r, ids[j], ids[j], &rec[j]);
        ids[j] = j;
    }
}

/* Copy the closest hit of record x to its ray of r. */
RS_INLINE void rs_stream_sync(rs_rays *r, const rs_stream_ray *x)
{
    int32_t i = x->ray;
    r->t[i] = x->t;
    r->prim[i] = x->prim;
    r->u[i] = x->u;
    r->v[i] = x->v;
}

/* The record x as a batch of one ray (ray 0), for the single-ray kernels: they
 * read and shrink its hit in place. */
RS_INLINE void rs_stream_view(rs_stream_ray *x, rs_rays *one)
{
    for (int a = 0; a < 3; ++a) {
        one->o[a] = &x->o[a];
        one->d[a] = &x->d[a];
        one->inv[a] = &x->inv[a];
    }
    one->tmin = &x->tmin;
    one->t = &x->t;
    one->prim = &x->prim;
    one->u = &x->u;
    one->v = &x->v;
}

/* Trace the n <= w->size rays of the records w->rec[0, n), whose ids w->ids[0, n)
 * are 0, 1, ..., n - 1 (the caller builds both), from the root of a tree of
 * w->width children per node: rs_node4 nodes and rs_tri leaves
 * (width 4) or rs_node8 nodes and rs_tri8 leaf groups (width 8).  Streams of
 * fewer than min_stream rays finish one ray at a time.
 *
 * Counters, the same on every ISA: one SIMD N_B per ray and node a stream
 * visits (the ray meets the node's child boxes, as in `wide` / `wide8`); at a
 * leaf of the 4-wide tree one SIMD N_T per triangle and 4 rays (rounded up)
 * of its stream, of the 8-wide tree one per ray and triangle group (as in
 * `wide8`); the single-ray finish counts as `wide` / `wide8` does.
 * stream_tasks and stream_rays count the streams popped and the rays they
 * held, w->level_rays the same rays by the level of the box the stream was
 * popped at (they add up to stream_rays). */
RS_INLINE void rs_stream_walk(const int width, const void *tree, const void *leaves, int n,
                              int any_hit, int order, int min_stream, rs_stream_scratch *w,
                              rs_counters *c)
{
    int cnt[RS_STREAM_MAX_WIDTH], votes[RS_STREAM_MAX_WIDTH], visit[RS_STREAM_MAX_WIDTH];
    int negative[3];
    const rs_node4 *nodes4 = (const rs_node4 *)tree;
    const rs_node8 *nodes8 = (const rs_node8 *)tree;
    const rs_tri *tris = (const rs_tri *)leaves;
    const rs_tri8 *groups = (const rs_tri8 *)leaves;
    rs_stream_ray *rec = w->rec;
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
                rs_stream_ray *x = &rec[ids[j]];
                rs_rays one;
                if (!(x->tmin < x->t))
                    continue;
                rs_stream_view(x, &one);
                if (width == 8)
                    rs_stream_single8(nodes8, groups, &one, 0, task.ref, task.tris, any_hit,
                                      w->single, c);
                else
                    rs_stream_single4(nodes4, tris, &one, 0, task.ref, task.tris, any_hit,
                                      w->single, c);
            }
            continue;
        }
        c->stream_tasks += 1;
        c->stream_rays += task.n;
        w->level_rays[task.level < w->depth ? task.level : w->depth] += task.n;
        if (task.ref < 0) {
            if (width == 8) {
                c->tri4 += (int64_t)task.tris * task.n;
                rs_stream_leaf8(rec, &groups[-task.ref - 1], task.tris, ids, task.n, any_hit);
            } else {
                c->tri4 += (int64_t)task.tris * ((task.n + 3) / 4);
                rs_stream_leaf4(rec, &tris[-task.ref - 1], task.tris, ids, task.n, any_hit);
            }
            continue;
        }
        const float *lo = width == 8 ? &nodes8[task.ref].lo[0][0] : &nodes4[task.ref].lo[0][0];
        const float *hi = width == 8 ? &nodes8[task.ref].hi[0][0] : &nodes4[task.ref].hi[0][0];
        const int32_t *child = width == 8 ? nodes8[task.ref].child : nodes4[task.ref].child;
        const uint16_t *count = width == 8 ? nodes8[task.ref].count : nodes4[task.ref].count;
        c->box4 += task.n;
        rs_stream_filter(rec, width, lo, hi, ids, task.n, w->sub, cnt, votes, negative);
        int m = rs_stream_order(width, lo, hi, cnt, votes, negative, task.n, order, visit);
        /* the parent's ids are read: its slice takes the sub-streams, the one
         * to visit first last, so it is popped first */
        int first = task.first;
        for (int j = m - 1; j >= 0; --j) {
            int k = visit[j];
            memcpy(w->ids + first, w->sub[k], (size_t)cnt[k] * sizeof(int32_t));
            rs_stream_task *next = &w->tasks[nt++];
            next->ref = child[k];
            next->tris = count[k];
            next->first = first;
            next->n = cnt[k];
            next->level = task.level + 1;
            first += cnt[k];
        }
        if (m) {
            int32_t ref = child[visit[0]];
            if (width == 8)
                rs_stream_prefetch(ref >= 0 ? (const void *)&nodes8[ref]
                                   : (const void *)&groups[-ref - 1], 4);
            else
                rs_stream_prefetch(ref >= 0 ? (const void *)&nodes4[ref]
                                   : (const void *)&tris[-ref - 1], 2);
        }
    }
}

/* Trace the rays ids[0, n) of r (n <= w->size; the ids are overwritten) through
 * the 4-wide tree (BVH.wide, BVH.triangles) or the 8-wide one (BVH.wide8's
 * nodes and groups): their records, the walk, their hits back to r. */
static inline void rs_stream_trace(const int width, const void *tree, const void *leaves,
                                   rs_rays *r, int n, int any_hit, int order, int min_stream,
                                   rs_stream_scratch *w, rs_counters *c)
{
    rs_stream_records(r, w->ids, n, w->rec);
    rs_stream_walk(width, tree, leaves, n, any_hit, order, min_stream, w, c);
    for (int j = 0; j < n; ++j)
        rs_stream_sync(r, &w->rec[j]);
}

#endif
