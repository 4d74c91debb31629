"""``embree``: Embree 4 via embreex as a raysort traversal (a yardstick)."""
from __future__ import annotations

import threading
import weakref

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from raysort.sdk import Counters, Traversal

__all__ = ["EmbreeTraversal"]

_scenes = weakref.WeakKeyDictionary()
_lock = threading.Lock()
#: a hit at t <= 0 from the shifted origin (Embree's tnear is 0 and inclusive) is
#: traced again from a little further along the ray: this many times, each step
#: NUDGE times the origin's magnitude, doubled each time
NUDGES, NUDGE = 4, 2.0 ** -20


def _embree_scene(bvh):
    """One Embree scene per raysort BVH (built on first use, shared by threads)."""
    with _lock:
        scene = _scenes.get(bvh)
        if scene is None:
            scene = rtcore_scene.EmbreeScene()
            TriangleMesh(scene, np.ascontiguousarray(bvh.vertices, dtype=np.float32),
                         np.ascontiguousarray(bvh.faces, dtype=np.int32))
            _scenes[bvh] = scene
        return scene


def _query(scene, o, d, far, any_hit):
    """(t, prim, u, v) from ``o`` (t relative to it, inf and -1 on a miss)."""
    far = far.copy()                    # embreex writes the hit distances into it
    if any_hit:
        prim = (scene.run(o, d, dists=far, query="OCCLUDED") >= 0).astype(np.int32) - 1
        t = np.where(prim >= 0, np.float32(np.nan), np.float32(np.inf)).astype(np.float32)
        return t, prim, None, None
    res = scene.run(o, d, dists=far, query="INTERSECT", output=1)
    prim = np.asarray(res["primID"], np.int32)
    t = np.where(prim >= 0, res["tfar"], np.inf).astype(np.float32)
    return t, prim, res["u"], res["v"]


class EmbreeTraversal(Traversal):
    """Embree's single-ray traversal (rtcIntersect1 / rtcOccluded1) over its own BVH.

    Rays are read from the gathered packets; a ray with ``tmin > 0`` is
    started at ``o + tmin * d`` (embreex fixes tnear at 0).  raysort's
    contract counts only hits with ``t > tmin``, while Embree's tnear is
    inclusive: a ray starting in a triangle's plane reports ``t = 0`` on it.
    Such rays are traced again from a little further along (up to ``NUDGES``
    times, ``NUDGE`` times the origin's magnitude, doubled each time).  Any-hit
    queries use rtcOccluded1, which reports no distance, so an any-hit ray
    starting in a triangle's plane may still count that triangle.  Hits agree
    with brute force up to Embree's own rounding; counters are not available.

    ==========  ======  =======  ==========================================
    parameter   type    default  meaning
    ==========  ======  =======  ==========================================
    (none)
    ==========  ======  =======  ==========================================
    """

    exact = False

    def intersect(self, bvh, packets, any_hit=False):
        lanes = np.flatnonzero((packets.index >= 0) & packets.active())
        if len(lanes) == 0:
            return Counters(available=False)
        tmin, tmax = packets.tmin[lanes], packets.t[lanes]
        start = np.where(tmin > 0, tmin, np.float32(0)).astype(np.float32)
        d = np.ascontiguousarray(packets.directions[:, lanes].T)
        o = np.ascontiguousarray((packets.origins[:, lanes] + start * packets.directions[:, lanes]).T)
        far = np.ascontiguousarray(np.minimum(tmax - start, np.float32(1e37)), np.float32)
        scene = _embree_scene(bvh)
        t, prim, u, v = _query(scene, o, d, far, any_hit)
        if not any_hit:
            again = np.flatnonzero((prim >= 0) & (t <= 0))
            step = NUDGE * (np.abs(o).max(axis=1) + 1) / np.maximum(
                np.linalg.norm(d, axis=1), np.float32(1e-30))
            for _ in range(NUDGES):
                if len(again) == 0:
                    break
                shift = step[again].astype(np.float32)
                o2 = np.ascontiguousarray(o[again] + shift[:, None] * d[again], np.float32)
                f2 = np.ascontiguousarray(far[again] - shift, np.float32)
                t2, p2, u2, v2 = _query(scene, o2, d[again], f2, False)
                t[again], prim[again], u[again], v[again] = t2 + shift, p2, u2, v2
                step[again] *= 2
                again = again[(p2 >= 0) & (t2 <= 0)]
            prim[again] = -1            # still in the plane: not a hit past tmin
        hit = prim >= 0
        got = lanes[hit]
        packets.prim[got] = prim[hit] if not any_hit else 0
        if any_hit:
            packets.t[got] = -np.inf
        else:
            packets.t[got] = t[hit] + start[hit]
            packets.u[got] = u[hit]
            packets.v[got] = v[hit]
        return Counters(rays=len(lanes), available=False)
