"""Brute-force intersection, the reference every traversal is tested against.

:func:`brute_force` tests every ray against every triangle with the shared
scalar Moller-Trumbore kernel (Cython, nogil), so it depends on no BVH and no
traversal.  :func:`brute_force_numpy` is an independent NumPy transcription of
the same arithmetic (float32, the same operation order), used to check the
Cython kernel itself on small scenes.

Hit rule (all traversals obey it): the closest hit with ``tmin < t < tmax``;
on equal ``t`` the lower triangle index wins; a ray is invalid (never hits) if
its origin or direction is not finite or unless ``0 <= tmin < tmax``;
subnormal direction components count as zero; a degenerate triangle (the sine
of its angle at most 2^-20, zero area included) is never hit.
"""
from __future__ import annotations

import numpy as np

from raysort import _reference
from raysort.bvh import prepare_triangles
from raysort.rays import gather, scatter, scatter_occluded

__all__ = ["brute_force", "brute_force_numpy"]


def _packets_in_order(rays):
    n = len(rays)
    order = np.arange(n, dtype=np.int32)
    offsets = np.array([0, n] if n else [0], dtype=np.int32)
    return gather(rays, order, offsets)


def brute_force(vertices, faces, rays, any_hit=False):
    """Closest hits (:class:`raysort.rays.Hits`) or, with ``any_hit``, occlusion flags."""
    tris = prepare_triangles(vertices, faces)
    packets = _packets_in_order(rays)
    _reference.brute_force(tris.view(np.uint8).reshape(-1), packets.rows, packets.prim,
                           packets.u, packets.v, bool(any_hit))
    if any_hit:
        return scatter_occluded(packets, len(rays))
    return scatter(packets, len(rays))


def brute_force_numpy(vertices, faces, rays):
    """The same closest hits computed with NumPy float32 arithmetic (slow; small scenes)."""
    f32 = np.float32
    tris = prepare_triangles(vertices, faces)
    n = len(rays)
    t_best = np.full(n, np.inf, dtype=f32)
    prim = np.full(n, -1, dtype=np.int32)
    u_best = np.zeros(n, dtype=f32)
    v_best = np.zeros(n, dtype=f32)
    o = rays.origins.astype(f32)
    d = rays.directions.astype(f32)
    d = np.where(np.abs(d) < np.finfo(f32).tiny, np.copysign(f32(0), d), d).astype(f32)
    tmin, tmax = rays.tmin.astype(f32), rays.tmax.astype(f32)
    with np.errstate(all="ignore"):
        valid = (np.isfinite(o).all(0) & np.isfinite(d).all(0) & (tmin >= 0) & (tmin < tmax))
        cur = np.where(valid, tmax, -np.inf).astype(f32)
        for k in range(len(tris)):
            v0, e1, e2 = tris["v0"][k], tris["e1"][k], tris["e2"][k]
            px = d[1] * e2[2] - d[2] * e2[1]
            py = d[2] * e2[0] - d[0] * e2[2]
            pz = d[0] * e2[1] - d[1] * e2[0]
            det = e1[0] * px + e1[1] * py + e1[2] * pz
            inv = f32(1.0) / det
            sx, sy, sz = o[0] - v0[0], o[1] - v0[1], o[2] - v0[2]
            u = (sx * px + sy * py + sz * pz) * inv
            qx = sy * e1[2] - sz * e1[1]
            qy = sz * e1[0] - sx * e1[2]
            qz = sx * e1[1] - sy * e1[0]
            v = (d[0] * qx + d[1] * qy + d[2] * qz) * inv
            t = (e2[0] * qx + e2[1] * qy + e2[2] * qz) * inv
            ok = ((det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > tmin)
                  & ((t < cur) | ((t == cur) & (k < prim))))
            cur[ok], prim[ok], u_best[ok], v_best[ok] = t[ok], k, u[ok], v[ok]
    hit = prim >= 0
    t_best[hit] = cur[hit]
    from raysort.rays import Hits
    hits = Hits(n)
    hits.t[:], hits.prim[:], hits.u[:], hits.v[:] = t_best, prim, np.where(hit, u_best, 0), \
        np.where(hit, v_best, 0)
    return hits
