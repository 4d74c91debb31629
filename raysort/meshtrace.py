"""Tracing rays against a triangle mesh in one call, for scripts.

:func:`trace` takes plain NumPy arrays, a mesh and rays, and returns the closest
hits, running the same sort -> gather -> traverse -> scatter pipeline as
:meth:`raysort.Pipeline.trace`.  The BVH of each mesh is built once and kept:
meshes are recognised by their content (a hash of the float32 vertices and
int32 faces) together with the BVH parameters, the cache holds the last
:data:`CACHE_SIZE` of them, and concurrent calls from several threads build a
mesh's BVH only once.
"""
from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from typing import NamedTuple

import numpy as np

from raysort.errors import ConfigError
from raysort.pipeline import Pipeline
from raysort.rays import RayBatch
from raysort.scene import Scene

__all__ = ["trace", "mesh_pipeline", "clear_cache", "TraceHits", "CACHE_SIZE"]

#: meshes (with their BVHs) kept between calls, least recently used dropped first
CACHE_SIZE = 8

_cache = OrderedDict()          # key -> _Entry
_cache_lock = threading.Lock()  # guards _cache; each entry has its own build lock


class TraceHits(NamedTuple):
    """Closest hits in ray order: ``t`` (float32, +inf on a miss), ``prim`` (int32 face
    index, -1 on a miss) and the barycentric ``u``, ``v`` (float32) of the hit, so that
    the hit point is ``(1 - u - v) * v0 + u * v1 + v * v2`` of face ``prim``."""

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray


class _Entry:
    __slots__ = ("scene", "lock")

    def __init__(self, scene):
        self.scene, self.lock = scene, threading.Lock()


def _key(vertices, faces, bvh):
    digest = hashlib.blake2b(digest_size=16)
    for array in (vertices, faces):
        digest.update(repr(array.shape).encode())
        digest.update(array.tobytes())
    return digest.hexdigest(), tuple(sorted(dict(bvh or {}).items()))


def _entry(vertices, faces, bvh):
    """The cached scene of this mesh content and BVH parameters (made if new)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    key = _key(vertices, faces, bvh)
    with _cache_lock:
        entry = _cache.get(key)
        if entry is not None:
            _cache.move_to_end(key)
            return entry
    entry = _Entry(Scene.from_mesh(vertices, faces))   # checks the mesh
    with _cache_lock:
        entry = _cache.setdefault(key, entry)
        _cache.move_to_end(key)
        while len(_cache) > CACHE_SIZE:
            _cache.popitem(last=False)
    return entry


def mesh_pipeline(vertices, faces, **pipeline):
    """A :class:`raysort.Pipeline` over a mesh given as arrays, with its BVH built.

    The mesh's scene and BVH come from the cache (see the module's docstring);
    the pipeline itself is new, so its plugins are not shared between threads.

    Parameters
    ----------
    vertices : array (n, 3)
        Converted to float32.
    faces : integer array (m, 3)
        Indices into `vertices`.
    **pipeline
        Keyword arguments of :class:`raysort.Pipeline` (``sorter``,
        ``traversal``, ``threads``, ``tile``, ``bvh``, ...).  ``check_plugins``
        defaults to False here: built-in sorters are trusted and skip the
        contract check (about 6% of a trace of random rays), while sorters
        from other packages are always checked.

    Raises
    ------
    SceneError
        If the mesh has no faces, bad indices or non-finite vertices.
    ConfigError
        If a pipeline argument is not accepted.
    """
    entry = _entry(vertices, faces, pipeline.get("bvh"))
    pipe = Pipeline(entry.scene, **{"check_plugins": False, **pipeline})
    with entry.lock:   # one build per mesh, however many threads ask at once
        pipe.bvh  # noqa: B018 (the property builds it)
    return pipe


def trace(vertices, faces, origins, directions, *, tmin=0.0, tmax=np.inf, any_hit=False,
          **pipeline):
    """Closest hits of rays on a triangle mesh, in one call.

    Parameters
    ----------
    vertices : array (n, 3)
        Mesh vertices (converted to float32, as raysort traces in float32).
    faces : integer array (m, 3)
        Triangles as indices into `vertices`.
    origins, directions : array (k, 3)
        The rays (float32); directions need not be unit length, and ``t`` is
        measured in units of each direction's length.
    tmin, tmax : float or array (k,)
        A hit counts when ``tmin < t < tmax``.
    any_hit : bool
        Occlusion query: return a bool array (True where the ray hits anything
        in the interval) instead of the closest hits.
    **pipeline
        Keyword arguments of :class:`raysort.Pipeline` (``sorter``,
        ``traversal``, ``threads``, ``tile``, ``bvh``, ...); the hits are the
        same for every choice.

    Returns
    -------
    TraceHits or numpy.ndarray
        ``(t, prim, u, v)`` arrays of length k, or with `any_hit` a bool array.

    Raises
    ------
    SceneError, ConfigError
        For a bad mesh, bad ray arrays or bounds, or pipeline arguments.

    Examples
    --------
    >>> t, prim, u, v = raysort.trace(vertices, faces, origins, directions)
    """
    pipe = mesh_pipeline(vertices, faces, **pipeline)
    rays = RayBatch.from_arrays(origins, directions)
    for name, value in (("tmin", tmin), ("tmax", tmax)):
        value = np.asarray(value, dtype=np.float32)
        if value.shape not in ((), (len(rays),)):
            raise ConfigError(f"{name} must be a number or an array of {len(rays)} (one per "
                              f"ray), got shape {value.shape}")
        getattr(rays, name)[:] = value
    hits, _ = pipe.trace(rays, any_hit=any_hit)
    if any_hit:
        return hits
    return TraceHits(hits.t, hits.prim, hits.u, hits.v)


def clear_cache():
    """Forget every cached mesh and BVH."""
    with _cache_lock:
        _cache.clear()
