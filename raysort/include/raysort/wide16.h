/* raysort: the node test of the `wide16` traversal.
 *
 * rs_node16_hit tests one ray against the sixteen child boxes of an rs_node16:
 * one 16-lane AVX-512 operation per step on the avx512 build, two 8-lane halves
 * (wide8.h's rs_boxes8_hit) elsewhere.  Lane k performs rs_box1's operations on
 * child k's box in the same order (no FMA), so every ISA takes the same
 * decisions; leaves are wide8's rs_tri8 groups, tested with rs_tri8_hit.
 */
#ifndef RAYSORT_WIDE16_H
#define RAYSORT_WIDE16_H

#include "wide8.h"

/* One ray (lane i of r, broadcast in `ray`) against the sixteen child boxes of
 * n: returns the 16-bit mask of children hit and stores where the ray enters
 * each in entry[]. */
RS_INLINE int rs_node16_hit(const rs_rays *r, int i, const rs_ray8 *ray, const rs_node16 *n,
                            float entry[16])
{
#if RS_ISA_AVX512
    __m512 tn = _mm512_set1_ps(r->tmin[i]), tf = _mm512_set1_ps(r->t[i]);
    for (int a = 0; a < 3; ++a) {
        __m512 o = _mm512_set1_ps(r->o[a][i]), inv = _mm512_set1_ps(r->inv[a][i]);
        __m512 near_plane = _mm512_load_ps(ray->neg[a] ? n->hi[a] : n->lo[a]);
        __m512 far_plane = _mm512_load_ps(ray->neg[a] ? n->lo[a] : n->hi[a]);
        tn = _mm512_max_ps(_mm512_mul_ps(_mm512_sub_ps(near_plane, o), inv), tn);
        tf = _mm512_min_ps(_mm512_mul_ps(_mm512_sub_ps(far_plane, o), inv), tf);
    }
    _mm512_storeu_ps(entry, tn);
    return (int)_mm512_cmp_ps_mask(tn, _mm512_mul_ps(tf, _mm512_set1_ps(RS_BOX_SLACK)),
                                   _CMP_LE_OQ);
#else
    int low = rs_boxes8_hit(r, i, ray, &n->lo[0][0], &n->hi[0][0], 16, entry);
    return low | rs_boxes8_hit(r, i, ray, &n->lo[0][8], &n->hi[0][8], 16, entry + 8) << 8;
#endif
}

#endif
