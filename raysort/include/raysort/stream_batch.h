/* raysort: the `stream` traversal straight from a ray batch, without packets.
 *
 * The pipeline's gather lays rays out in sub-packets for the packet traversals,
 * and its scatter copies their hits back to batch order.  A stream makes its
 * own copy of every ray (its 64-byte records) and writes every hit back, so for
 * `stream` both are a second copy of the same data.  rs_stream_batch reads
 * the batch's ray rows in the sorter's order instead: each chunk of up to
 * RS_FRUSTUM_CHUNK lanes (rs_batch_chunk) is gathered into a scratch of that many
 * lanes (rs_gather_block: the gather's rules and arithmetic per lane, so the
 * same values), a coherent chunk takes the frustum walk there, the others'
 * active rays become stream records, and hits go from the scratch or the
 * records straight to the batch-order hits.
 *
 * Streams, chunks and counters are those of the packet path (stream.pyx's
 * `trace` over gathered packets): the same rays in the same order, cut at the
 * same places.  The hits are the same bit for bit.
 */
#ifndef RAYSORT_STREAM_BATCH_H
#define RAYSORT_STREAM_BATCH_H

#include "frustum.h"
#include "gather.h"

#if defined(_MSC_VER)
#  define RS_ALIGNED(n) __declspec(align(n))
#else
#  define RS_ALIGNED(n) __attribute__((aligned(n)))
#endif

/* The hits of a batch in batch order: rows t, prim, u, v (a miss: inf, -1, 0,
 * 0) or, for an any-hit query, one flag per ray (1: occluded). */
typedef struct rs_batch_hits {
    float *t;
    int32_t *prim;
    float *u, *v;
    uint8_t *occluded;      /* not NULL: an any-hit query's flags */
} rs_batch_hits;

/* The result of one call: what the packet path's gather and its check of the
 * hits report. */
typedef struct rs_batch_status {
    int64_t active;         /* rays traced (active and valid) */
    int64_t bad_ray;        /* the first ray (batch index) that breaks the ray contract, or -1 */
    int64_t bad_hit;        /* a ray whose hit breaks the hit contract, or -1 */
    int order_bad;          /* an order entry outside [0, n): nothing more traced */
} rs_batch_status;

/* Whether lane j's hit (of the scratch or a one-ray view) breaks the hit
 * contract, as _checks.pxd's closest_bad and any_hit_bad: prim -1 or below
 * n_prim, and (unless any_hit) a hit in (tmin, t0) with finite u, v, t0 the
 * lane's t before the walk.  Without a branch. */
RS_INLINE int rs_batch_bad(const rs_rays *r, int j, float t0, uint32_t n_prim, int any_hit)
{
    const int32_t p = r->prim[j];
    const float t = r->t[j], u = r->u[j], v = r->v[j];
    return ((uint32_t)(p + 1) > n_prim)
           | (!any_hit & (p >= 0)
              & (!(r->tmin[j] < t) | !(t < t0) | ((u - u) + (v - v) != 0.0f)));
}

/* Lane j's closest hit to row `id` of the batch-order hits t, prim, u, v (a miss:
 * inf, -1, 0, 0). */
RS_INLINE void rs_batch_write(const rs_rays *r, int j, int64_t id, float *t, int32_t *prim,
                              float *u, float *v)
{
    const int hit = r->prim[j] >= 0;
    t[id] = hit ? r->t[j] : INFINITY;
    prim[id] = hit ? r->prim[j] : -1;
    u[id] = hit ? r->u[j] : 0.0f;
    v[id] = hit ? r->v[j] : 0.0f;
}

/* Lane j's hit to ray id of the batch; 1 if it breaks the hit contract
 * (rs_batch_bad), which the caller reports. */
RS_INLINE int rs_batch_put(const rs_rays *r, int j, int32_t id, float t0, uint32_t n_prim,
                           rs_batch_hits *out)
{
    if (out->occluded) {
        out->occluded[id] = (uint8_t)(r->prim[j] >= 0);
        return rs_batch_bad(r, j, t0, n_prim, 1);
    }
    rs_batch_write(r, j, id, out->t, out->prim, out->u, out->v);
    return rs_batch_bad(r, j, t0, n_prim, 0);
}

/* rs_batch_put of lanes 0 <= j < n to rays id0 + j (closest hits), in loops
 * without a branch per lane: returns n, or the first lane whose hit breaks the
 * contract (whose rs_batch_put the caller then makes, to report it, as those
 * of the lanes after it). */
RS_INLINE int rs_batch_put_run(const rs_rays *r, int n, int32_t id0, const float *t0,
                               uint32_t n_prim, rs_batch_hits *out)
{
    int bad = 0;
    for (int j = 0; j < n; ++j)
        bad |= rs_batch_bad(r, j, t0[j], n_prim, 0);
    if (bad) {
        int j = 0;
        while (!rs_batch_put(r, j, id0 + j, t0[j], n_prim, out))
            ++j;
        return j;
    }
    float *t = out->t + id0, *u = out->u + id0, *v = out->v + id0;
    int32_t *prim = out->prim + id0;
    for (int j = 0; j < n; ++j)
        rs_batch_write(r, j, j, t, prim, u, v);
    return n;
}

/* The m records of w traced through the tree, their hits to the batch. */
RS_INLINE void rs_batch_stream(const int width, const void *tree, const void *leaves, int m,
                               int any_hit, int order, int min_stream, uint32_t n_prim,
                               rs_stream_scratch *w, rs_batch_hits *out, rs_counters *c,
                               rs_batch_status *status)
{
    rs_rays one;
    rs_stream_walk(width, tree, leaves, m, any_hit, order, min_stream, w, c);
    for (int j = 0; j < m; ++j) {
        rs_stream_ray *x = &w->rec[j];
        rs_stream_view(x, &one);
        if (rs_batch_put(&one, 0, x->ray, x->t0, n_prim, out) && status->bad_hit < 0)
            status->bad_hit = x->ray;
    }
}

/* The next chunk of the sorter's result: the rest of sub-packet *k from ray
 * position *s, RS_FRUSTUM_CHUNK rays at most, then each following sub-packet
 * before k1 whole while its rays fit in the chunk's lanes.  The lanes are those
 * of the packet layout (_gather.layout: each sub-packet at the next multiple of
 * 4 lanes, the lanes between empty), so the packet path (stream.pyx's trace)
 * cuts the same chunks from gathered packets.  Writes ids[0, RS_FRUSTUM_CHUNK)
 * (-1: an empty lane), sets *bad if an entry of the order is not a ray of
 * [0, n_src) (checked without a branch per ray), returns the lanes up to the
 * chunk's last ray, and moves *k and *s past the chunk. */
RS_INLINE int rs_batch_chunk(const int32_t *order, const int32_t *offsets, int k1,
                             int64_t n_src, int *k, int64_t *s, int32_t *ids, int *bad)
{
    int lanes = 0, n = 0, out = 0;
    for (int j = 0; j < RS_FRUSTUM_CHUNK; ++j)
        ids[j] = -1;
    while (*k < k1) {
        const int64_t rest = offsets[*k + 1] - *s;
        const int room = RS_FRUSTUM_CHUNK - lanes;
        const int count = rest < room ? (int)(rest > 0 ? rest : 0) : room;
        if (lanes > 0 && count < rest)
            break;                          /* a sub-packet joins a chunk only whole */
        for (int j = 0; j < count; ++j) {
            const int32_t id = order[*s + j];
            out |= (uint32_t)id >= (uint64_t)n_src;
            ids[lanes + j] = id;
        }
        if (count > 0)
            n = lanes + count;
        lanes += (count + 3) & ~3;
        *s += count;
        if (count < rest)
            break;                          /* a full chunk inside a long sub-packet */
        if (++*k < k1)
            *s = offsets[*k];
        if (lanes >= RS_FRUSTUM_CHUNK)
            break;
    }
    *bad = out;
    return n;
}

/* Sub-packets k0 <= k < k1 of the sorter's result (rays order[offsets[k],
 * offsets[k + 1]) of the batch's ray rows src, n_src rays each) through the
 * tree, in streams of up to w->size rays; every ray's hit goes to out.  With
 * `frustum` (8-wide tree only) coherent chunks take the frustum walk
 * (`stack`: 7 entries per level plus 8). */
static rs_batch_status rs_stream_batch(const int width, const void *tree, const void *leaves,
                                       const float *const src[RS_RAY_ROWS], int64_t n_src,
                                       const int32_t *order, const int32_t *offsets, int k0,
                                       int k1, int any_hit, int order_kind, int min_stream,
                                       int frustum, uint32_t n_prim, rs_stream_scratch *w,
                                       rs_frustum_entry *stack, rs_batch_hits *out,
                                       rs_counters *c)
{
    RS_ALIGNED(64) float rows[RS_PACKET_ROWS][RS_FRUSTUM_CHUNK];
    RS_ALIGNED(64) int32_t prim[RS_FRUSTUM_CHUNK];
    RS_ALIGNED(64) float u[RS_FRUSTUM_CHUNK], v[RS_FRUSTUM_CHUNK];
    int32_t ids[RS_FRUSTUM_CHUNK];
    float *dst[RS_PACKET_ROWS];
    rs_rays chunk;
    rs_frustum_bounds b;
    RS_ALIGNED(64) float t0[RS_FRUSTUM_CHUNK];
    rs_batch_status status = {0, -1, -1, 0};
    int m = 0;
    for (int a = 0; a < RS_PACKET_ROWS; ++a)
        dst[a] = rows[a];
    for (int a = 0; a < 3; ++a) {
        chunk.o[a] = rows[RS_PACKET_OX + a];
        chunk.d[a] = rows[RS_PACKET_DX + a];
        chunk.inv[a] = rows[RS_PACKET_IX + a];
    }
    chunk.tmin = rows[RS_PACKET_TMIN];
    chunk.t = rows[RS_PACKET_T];
    chunk.prim = prim;
    chunk.u = u;
    chunk.v = v;
    int k = k0;
    int64_t s = k0 < k1 ? offsets[k0] : 0;
    while (k < k1) {       /* a chunk at a time */
        const int64_t first = s;
        int bad;
        const int n = rs_batch_chunk(order, offsets, k1, n_src, &k, &s, ids, &bad);
        /* the rows RS_GATHER_AHEAD rays on (as rs_gather_lanes) */
        for (int q = 0; q < n; q += 16) {
            int64_t r = first + q + RS_GATHER_AHEAD < n_src ? first + q + RS_GATHER_AHEAD
                                                            : n_src - 1;
            for (int a = 0; a < RS_RAY_ROWS; ++a)
                rs_prefetch(src[a] + r);
        }
        /* `run`: whether the ids are consecutive (the `none` sorter's, no empty
         * lane among them), as the hits' rows can then be written a vector at a
         * time */
        int run = 1;
        for (int j = 0; j < n; ++j)
            run &= ids[j] == (int64_t)ids[0] + j;
        if (bad) {
            status.order_bad = 1;
            return status;
        }
        for (int j = 0; j < RS_FRUSTUM_CHUNK; j += RS_SW) {
            int bits = rs_gather_block(dst, prim, u, v, NULL, src, ids, j);
            if (bits && status.bad_ray < 0)
                status.bad_ray = ids[j + rs_lowest(bits)];
        }
        const int active = rs_frustum_bounds_of(&chunk, 0, n, &b);
        status.active += active;
        if (frustum && active && rs_frustum_coherent(&b)) {
            memcpy(t0, chunk.t, sizeof t0);
            rs_frustum_walk((const rs_node8 *)tree, (const rs_tri8 *)leaves, &chunk, 0, n,
                            any_hit, &b, stack, c);
            int done = run && !out->occluded ? rs_batch_put_run(&chunk, n, ids[0], t0,
                                                                n_prim, out) : 0;
            for (int j = done; j < n; ++j)
                if (ids[j] >= 0 && rs_batch_put(&chunk, j, ids[j], t0[j], n_prim, out)
                        && status.bad_hit < 0)
                    status.bad_hit = ids[j];
            continue;
        }
        for (int j = 0; j < n; ++j) {
            if (ids[j] < 0)                         /* an empty lane */
                continue;
            if (!(chunk.tmin[j] < chunk.t[j])) {    /* not traced: a miss */
                rs_batch_put(&chunk, j, ids[j], chunk.t[j], n_prim, out);
                continue;
            }
            rs_stream_record(&chunk, j, ids[j], &w->rec[m]);   /* prim -1, u, v 0 */
            w->ids[m] = m;
            if (++m == w->size) {
                rs_batch_stream(width, tree, leaves, m, any_hit, order_kind, min_stream,
                                n_prim, w, out, c, &status);
                m = 0;
            }
        }
    }
    if (m)
        rs_batch_stream(width, tree, leaves, m, any_hit, order_kind, min_stream, n_prim, w,
                        out, c, &status);
    return status;
}

#endif
