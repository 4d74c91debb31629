"""A trimesh ray backend: existing trimesh code traces its rays with raysort.

trimesh meshes answer ray queries through ``mesh.ray``, an intersector backed
by Embree (``embreex``) or by a slow pure-NumPy one.  This module's
:class:`RayMeshIntersector` has the same methods, arguments and return
conventions, so one line switches a mesh over::

    import trimesh
    from raysort.trimesh import RayMeshIntersector

    mesh = trimesh.load("bunny.ply")
    mesh.ray = RayMeshIntersector(mesh)      # or RayMeshIntersector(mesh, threads=2)
    index_tri = mesh.ray.intersects_first(origins, directions)
    inside = mesh.contains(points)           # trimesh's own code, now on raysort

Underneath it is :func:`raysort.meshtrace.mesh_pipeline`: the sorter + traversal
pipeline (configurable with :class:`raysort.Pipeline`'s keywords) over a BVH
cached by mesh content, so a mesh edited in place gets a new BVH.

What differs from trimesh's backends, on purpose:

* The first hit is exact: the hit of brute force on the float32 mesh and rays
  (the lower face index on equal distances), as for every raysort traversal.
* ``multiple_hits`` re-traces each ray from its last hit distance
  (``tmin = t``, exclusive), vectorised over the rays, instead of nudging the
  origin by an epsilon; it returns each ray's hits ordered by ray, then by
  distance.  Hits at exactly the same distance along a ray (where it crosses
  a shared edge) count once, on the lower face index.
* Locations are ``v0 + u (v1 - v0) + v (v2 - v0)`` of the face hit, in float64:
  always on the face.
"""
from __future__ import annotations

import numpy as np
import trimesh  # the real package: this module is raysort.trimesh

from raysort.meshtrace import mesh_pipeline
from raysort.rays import RayBatch

__all__ = ["RayMeshIntersector"]


class RayMeshIntersector:
    """Ray queries on a trimesh mesh, traced by raysort.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The mesh; its current vertices and faces are read at every query.
    **pipeline
        Keyword arguments of :class:`raysort.Pipeline` (``sorter``,
        ``traversal``, ``threads``, ``tile``, ``bvh``, ...).  Every choice
        gives the same hits; only speed differs.
    """

    def __init__(self, mesh, **pipeline):
        self.mesh = mesh
        self.pipeline = pipeline

    def __repr__(self):
        return f"RayMeshIntersector({self.mesh!r}, **{self.pipeline!r})"

    # ------------------------------------------------------------------
    def _prepare(self, ray_origins, ray_directions):
        """(pipeline, RayBatch) for a query; trimesh's message for mismatched arrays."""
        origins = np.asarray(ray_origins, dtype=np.float64)
        directions = np.asarray(ray_directions, dtype=np.float64)
        if origins.shape != directions.shape:
            raise ValueError("Ray origin and direction don't match!")
        pipe = mesh_pipeline(self.mesh.vertices, self.mesh.faces, **self.pipeline)
        return pipe, RayBatch.from_arrays(origins.reshape(-1, 3), directions.reshape(-1, 3))

    def intersects_first(self, ray_origins, ray_directions, **kwargs):
        """Index of the first face each ray hits.

        Returns
        -------
        (n,) int64
            Face index, or -1 where the ray hits nothing.
        """
        pipe, rays = self._prepare(ray_origins, ray_directions)
        hits, _ = pipe.trace(rays)
        return hits.prim.astype(np.int64)

    def intersects_any(self, ray_origins, ray_directions, **kwargs):
        """Whether each ray hits the mesh at all (an any-hit query).

        Returns
        -------
        (n,) bool
        """
        pipe, rays = self._prepare(ray_origins, ray_directions)
        occluded, _ = pipe.trace(rays, any_hit=True)
        return occluded

    def intersects_id(self, ray_origins, ray_directions, multiple_hits=True, max_hits=100,
                      return_locations=False, **kwargs):
        """The faces hit by each ray: the first one, or all of them along the ray.

        Parameters
        ----------
        ray_origins, ray_directions : (n, 3) float
        multiple_hits : bool
            Every hit along each ray (True) or the first only.
        max_hits : int
            At most this many hits per ray.
        return_locations : bool
            Also return the hit points.

        Returns
        -------
        index_tri : (h,) int64
            Faces hit.
        index_ray : (h,) int64
            The ray of each hit; hits are ordered by ray, then by distance.
        locations : (h, 3) float64
            Hit points (only with `return_locations`).
        """
        pipe, rays = self._prepare(ray_origins, ray_directions)
        index_ray, index_tri, u, v = _hits_along(pipe, rays, max_hits if multiple_hits else 1)
        if not return_locations:
            return index_tri, index_ray
        return index_tri, index_ray, self._locations(index_tri, u, v)

    def intersects_location(self, ray_origins, ray_directions, multiple_hits=True, **kwargs):
        """Where the rays hit the mesh.

        Returns
        -------
        locations : (h, 3) float64
            Hit points, ordered by ray, then by distance.
        index_ray : (h,) int64
        index_tri : (h,) int64
        """
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins, ray_directions, multiple_hits=multiple_hits, return_locations=True,
            **kwargs)
        return locations, index_ray, index_tri

    def contains_points(self, points):
        """Whether each point is inside the (watertight) mesh, by trimesh's ray-parity test."""
        return trimesh.ray.ray_util.contains_points(self, points)

    # ------------------------------------------------------------------
    def _locations(self, index_tri, u, v):
        corners = np.asarray(self.mesh.vertices, dtype=np.float64)[
            np.asarray(self.mesh.faces)[index_tri]]
        u = u.astype(np.float64)[:, None]
        v = v.astype(np.float64)[:, None]
        return corners[:, 0] + u * (corners[:, 1] - corners[:, 0]) \
            + v * (corners[:, 2] - corners[:, 0])


def _hits_along(pipe, rays, max_hits):
    """Up to `max_hits` hits of every ray, nearest first: each round re-traces the rays
    that hit, from their last hit distance on (tmin is exclusive).

    Returns int64 ray and face indices and float32 u, v, ordered by (ray, distance).
    """
    parts = []
    live = np.arange(len(rays), dtype=np.int64)
    batch = rays
    for _ in range(max(int(max_hits), 0)):
        hits, _ = pipe.trace(batch)
        hit = hits.prim >= 0
        live = live[hit]
        if not len(live):
            break
        parts.append((live, hits.prim[hit], hits.t[hit], hits.u[hit], hits.v[hit]))
        batch = rays.take(live)
        batch.tmin[:] = hits.t[hit]
    if not parts:
        empty = np.zeros(0, np.int64)
        return empty, empty, np.zeros(0, np.float32), np.zeros(0, np.float32)
    ray, tri, t, u, v = (np.concatenate(column) for column in zip(*parts))
    order = np.lexsort((t, ray))
    return ray[order], tri[order].astype(np.int64), u[order], v[order]
