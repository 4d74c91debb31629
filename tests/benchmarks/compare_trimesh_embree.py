"""raysort's trimesh backend against trimesh's Embree backend, side by side.

    python tests/benchmarks/compare_trimesh_embree.py [--scene sibenik] [--rays 1000000]
        [--rounds 5] [--threads 1]

Random rays (origins uniform in 1.5 times the scene's box, directions uniform on
the sphere) are traced with ``trimesh.ray.ray_pyembree.RayMeshIntersector`` and
with ``raysort.trimesh.RayMeshIntersector`` in a few pipeline configurations;
the runs are interleaved round by round, and the script prints each query's
median seconds and Mrays/s and the median of the per-round ratios to Embree.
BVH/scene builds happen before the first round and are not timed.  It also
checks that the first hits agree (as a fraction of rays).
"""
import argparse
import os
import platform
import statistics
import time

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector as EmbreeIntersector

import raysort
from raysort import isa
from raysort.trimesh import RayMeshIntersector

QUERIES = {
    "intersects_first": lambda ray, o, d: ray.intersects_first(o, d),
    "intersects_any": lambda ray, o, d: ray.intersects_any(o, d),
    "intersects_location (all hits)": lambda ray, o, d: ray.intersects_location(o, d),
}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="sibenik")
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1, help="raysort worker threads")
    parser.add_argument("--queries", default=",".join(QUERIES),
                        help="comma-separated subset of: " + ", ".join(QUERIES))
    args = parser.parse_args()

    scene = raysort.load_scene(args.scene)
    mesh = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
    rng = np.random.default_rng(1)
    lo, hi = scene.bounds.astype(np.float64)
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.5
    origins = centre + (rng.random((args.rays, 3)) * 2 - 1) * half
    directions = rng.normal(size=(args.rays, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)

    backends = {"embree": EmbreeIntersector(mesh),
                "raysort nah+wide": RayMeshIntersector(mesh, threads=args.threads),
                "raysort none+wide": RayMeshIntersector(mesh, sorter="none",
                                                        threads=args.threads)}
    first = {name: ray.intersects_first(origins[:1000], directions[:1000])   # warm-up, builds
             for name, ray in backends.items()}
    for name in backends:
        agree = np.mean(first[name] == first["embree"])
        print(f"{name}: first hits agree with embree on {agree:.2%} of 1000 rays")
    print(f"scene {args.scene} ({len(scene.faces):,} triangles), {args.rays:,} rays, "
          f"{args.rounds} rounds, raysort threads {args.threads}; CPU "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, raysort "
          f"ISA {isa.active()}")
    for query in args.queries.split(","):
        call = QUERIES[query]
        seconds = {name: [] for name in backends}
        for _ in range(args.rounds):
            for name, ray in backends.items():
                start = time.perf_counter()
                call(ray, origins, directions)
                seconds[name].append(time.perf_counter() - start)
        print(f"\n{query}")
        for name, times in seconds.items():
            ratio = statistics.median(e / t for e, t in zip(seconds["embree"], times))
            median = statistics.median(times)
            print(f"  {name:<20} median {median:7.3f} s  {args.rays / median / 1e6:6.2f} "
                  f"Mrays/s  speed vs embree (median of per-round ratios) {ratio:5.2f}x")


if __name__ == "__main__":
    main()
