"""``embree``: Embree 4 via embreex as a raysort traversal (a yardstick)."""
from __future__ import annotations

import threading
import weakref

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from raysort.sdk import LibraryTraversal

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


class EmbreeTraversal(LibraryTraversal):
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

    def scene(self, bvh):
        return _embree_scene(bvh)

    def query(self, scene, origins, directions, far, any_hit):
        return _query(scene, origins, directions, far, any_hit)
