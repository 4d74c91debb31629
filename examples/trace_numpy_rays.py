"""Trace your own NumPy rays against a trimesh mesh and get the hits back.

    python examples/trace_numpy_rays.py                  # a torus, 100,000 rays
    python examples/trace_numpy_rays.py my_mesh.ply --rays 1000000

raysort needs only the triangles (vertices and faces) of a mesh; any mesh trimesh makes or
loads will do.  ``Pipeline.trace`` sorts, traverses and returns the closest hit of every
ray, in the order you gave them: ``t`` (inf on a miss), the triangle index ``prim`` (-1 on
a miss) and the barycentric coordinates ``u``, ``v`` of the hit in that triangle.

The same in one call, with the BVH cached by the mesh's content:
``raysort.trace(vertices, faces, origins, directions)``; and for code written against
trimesh's ``mesh.ray``: ``mesh.ray = raysort.trimesh.RayMeshIntersector(mesh)``.
A Pipeline, as here, lets you choose and compare the sorter and traversal.
"""
import argparse

import numpy as np
import trimesh

import raysort


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mesh", nargs="?", help="a mesh file trimesh reads (default: a torus)")
    parser.add_argument("--rays", type=int, default=100_000, help="how many rays (100000)")
    args = parser.parse_args(argv)

    mesh = (trimesh.load(args.mesh, force="mesh") if args.mesh
            else trimesh.creation.torus(major_radius=1.0, minor_radius=0.3))
    scene = raysort.Scene.from_mesh(mesh.vertices, mesh.faces)
    pipe = raysort.Pipeline(scene)                # default sorter and traversal

    # rays from random points on a sphere around the mesh toward random points near it
    rng = np.random.default_rng(1)
    centre, radius = mesh.bounds.mean(axis=0), np.ptp(mesh.bounds, axis=0).max()
    origins = centre + rng.normal(size=(args.rays, 3))
    origins = centre + 2 * radius * (origins - centre) / np.linalg.norm(origins - centre,
                                                                        axis=1, keepdims=True)
    targets = centre + 0.5 * radius * rng.uniform(-1, 1, size=(args.rays, 3))
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)

    rays = raysort.RayBatch.from_arrays(origins, directions)      # (n, 3) arrays in
    hits, counters = pipe.trace(rays)                                # closest hits out
    hit = hits.prim >= 0
    print(f"{hit.sum():,} of {args.rays:,} rays hit the mesh "
          f"({len(mesh.faces):,} triangles); {counters.per_ray()['box4']:.1f} SIMD box "
          f"tests per ray")

    # what the hits give you: the points, and the same points from the barycentrics
    points = origins[hit] + hits.t[hit, None] * directions[hit]
    tri = mesh.vertices[mesh.faces[hits.prim[hit]]]               # (k, 3 corners, 3)
    u, v = hits.u[hit, None], hits.v[hit, None]
    from_uv = (1 - u - v) * tri[:, 0] + u * tri[:, 1] + v * tri[:, 2]
    error = np.abs(points - from_uv).max() if hit.any() else 0.0
    print(f"hit points from t and from (u, v) agree to {error:.1e}")
    assert error < 1e-4 * radius

    # an occlusion query on the same rays: True where anything is in the way
    occluded, _ = pipe.trace(rays, any_hit=True)
    assert np.array_equal(occluded, hit)
    normals = mesh.face_normals[hits.prim[hit]]                    # trimesh's per-face data
    facing = (normals * directions[hit]).sum(axis=1) < 0
    print(f"{facing.mean():.1%} of the hits are on the outside of the surface")


if __name__ == "__main__":
    main()
