"""``mitsuba``: Mitsuba 3's ray queries as a raysort traversal (a yardstick).

Mitsuba 3 (``pip install mitsuba``) traces a whole array of rays per call:
``Scene.ray_intersect_preliminary`` (closest hit: distance, primitive and
barycentrics) and ``Scene.ray_test`` (any hit).  Its ``llvm_ad_rgb`` variant
compiles those calls with Dr.Jit's LLVM back end over Embree's BVH; it needs
the LLVM shared library (``libLLVM``) at run time.
"""
from __future__ import annotations

import threading
import weakref

import numpy as np

from raysort.sdk import LibraryTraversal, boolean

__all__ = ["MitsubaTraversal", "VARIANT"]

#: the Mitsuba variant used: vectorised over rays (LLVM), RGB, differentiable build
VARIANT = "llvm_ad_rgb"

_lock = threading.Lock()
_scenes = weakref.WeakKeyDictionary()
_mi = None


def _mitsuba():
    """Mitsuba with :data:`VARIANT` set and Dr.Jit on one thread (imported on first use)."""
    global _mi
    with _lock:
        if _mi is None:
            import drjit as dr
            import mitsuba as mi

            mi.set_variant(VARIANT)
            dr.set_thread_count(1)
            _mi = mi
        return _mi


def _scene(bvh):
    """One Mitsuba scene per raysort BVH: a mesh of the BVH's vertices and faces."""
    mi = _mitsuba()
    with _lock:
        scene = _scenes.get(bvh)
        if scene is None:
            v = np.ascontiguousarray(bvh.vertices, np.float32)
            f = np.ascontiguousarray(bvh.faces, np.uint32)
            mesh = mi.Mesh("raysort", vertex_count=len(v), face_count=len(f),
                           has_vertex_normals=False, has_vertex_texcoords=False)
            params = mi.traverse(mesh)
            params["vertex_positions"] = mi.Float(v.ravel())
            params["faces"] = mi.UInt32(f.ravel())
            params.update()
            scene = mi.load_dict({"type": "scene", "mesh": mesh})
            _scenes[bvh] = scene
        return scene


def _query(scene, o, d, far, any_hit, coherent=False):
    """(t, prim, u, v) of rays from ``o`` (t relative to it; inf and -1 on a miss)."""
    mi = _mitsuba()
    import drjit as dr

    ray = mi.Ray3f(mi.Point3f(*(mi.Float(o[:, k]) for k in range(3))),
                   mi.Vector3f(*(mi.Float(d[:, k]) for k in range(3))))
    ray.maxt = mi.Float(far)
    if any_hit:
        hit = np.asarray(scene.ray_test(ray), bool)
        return np.where(hit, np.float32(np.nan), np.float32(np.inf)), \
            np.where(hit, 0, -1).astype(np.int32), None, None
    pi = scene.ray_intersect_preliminary(ray, coherent=coherent)
    # one kernel for all three outputs: each conversion of an unevaluated Dr.Jit
    # array would otherwise run the whole ray query again
    dr.eval(pi.t, pi.prim_index, pi.prim_uv)
    t = np.asarray(pi.t, np.float32)
    hit = np.isfinite(t)
    prim = np.where(hit, np.asarray(pi.prim_index, np.int64), -1).astype(np.int32)
    uv = np.asarray(pi.prim_uv, np.float32).reshape(2, -1)
    return np.where(hit, t, np.float32(np.inf)), prim, uv[0], uv[1]


class MitsubaTraversal(LibraryTraversal):
    """Mitsuba 3's ``ray_intersect_preliminary`` / ``ray_test`` over its own BVH, one thread.

    The first call on a BVH builds a Mitsuba scene from its vertices and faces
    (shared by later calls).  A ray with ``tmin > 0`` is started at
    ``o + tmin * d``; a closest hit at the start (a ray starting in a
    triangle's plane) is traced again from a little further along, as raysort's
    contract counts only hits with ``t > tmin``.  Hits agree with brute force up
    to Mitsuba's own rounding; counters are not available.

    ==========  ======  =======  ==========================================
    parameter   type    default  meaning
    ==========  ======  =======  ==========================================
    coherent    bool    false    tell Mitsuba the rays are coherent (as its
                                 integrators do for camera rays: Embree's
                                 coherent query mode, about twice as fast
                                 on them); closest-hit queries only
    ==========  ======  =======  ==========================================
    """

    def __init__(self, *, coherent=False):
        self.coherent = boolean("coherent", coherent)

    def scene(self, bvh):
        return _scene(bvh)

    def query(self, scene, origins, directions, far, any_hit):
        return _query(scene, origins, directions, far, any_hit, self.coherent)
