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


class EmbreeTraversal(Traversal):
    """Embree's single-ray traversal (rtcIntersect1 / rtcOccluded1) over its own BVH.

    Rays are read from the gathered packets; a ray with ``tmin > 0`` is
    started at ``o + tmin * d`` (embreex fixes tnear at 0).  Hits agree with
    brute force up to Embree's own rounding; counters are not available.

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
        d = packets.directions[:, lanes]
        o = np.ascontiguousarray((packets.origins[:, lanes] + np.where(tmin > 0, tmin, 0) * d).T)
        d = np.ascontiguousarray(d.T)
        far = np.ascontiguousarray(np.minimum(tmax - tmin, np.float32(1e37)), np.float32)
        scene = _embree_scene(bvh)
        if any_hit:
            hit = scene.run(o, d, dists=far, query="OCCLUDED") >= 0
            packets.prim[lanes[hit]] = 0
            packets.t[lanes[hit]] = -np.inf
        else:
            res = scene.run(o, d, dists=far, query="INTERSECT", output=1)
            hit = res["primID"] >= 0
            got = lanes[hit]
            packets.prim[got] = res["primID"][hit]
            packets.t[got] = res["tfar"][hit] + tmin[hit]
            packets.u[got] = res["u"][hit]
            packets.v[got] = res["v"][hit]
        return Counters(rays=len(lanes), available=False)
