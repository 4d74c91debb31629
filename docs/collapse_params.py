"""The 8-wide tree's collapse parameters against trace speed: is the default the best
for camera rays (issue 12's camera target) as well as for diffuse rays?

Usage (from any directory, with raysort installed)::

    python docs/collapse_params.py sponza                    # camera and diffuse rays
    python docs/collapse_params.py sibenik --kinds primary --rounds 9
    python docs/collapse_params.py sponza --variants 0.3:32,0.5:32,0.4:24 --bvh spatial_splits=0

One binary BVH per scene (the default build, or ``--bvh`` as raysort bench's) is
collapsed to 8-wide trees (:meth:`raysort.BVH.collapse8`) with several (group cost,
largest merged leaf) pairs (``--variants``), the default (``BVH.WIDE8_GROUP_COST``,
``BVH.WIDE8_MAX_LEAF``) first.  The default pipeline's
``none`` + ``stream`` traces the same rays (:func:`raysort.workloads.workload`, 256x256
at 1 spp) through each tree in interleaved rounds (the order rotated per round, one
untimed warm-up round, each timing the thread CPU of 5 traces).  Per tree: Mrays/s
(median), the median [min, max] of the per-round speed-ups over the default, the tree's
SAH cost and the Table I counters per ray.  Every tree must give the default's hits
bit for bit (the script stops otherwise).
"""
import argparse
import statistics
import time

import numpy as np

import raysort
from raysort.bench.command import add_bvh_argument
from raysort.bvh import BVH
from raysort.workloads import workload

DEFAULT = (BVH.WIDE8_GROUP_COST, BVH.WIDE8_MAX_LEAF)
VARIANTS = [(0.8, 32), (0.6, 16), (0.4, 16), (0.4, 8), (1.0, 8), (0.2, 32)]


def variants(text):
    """``"0.3:32,0.5:16"`` -> [(0.3, 32), (0.5, 16)]."""
    pairs = [item.split(":") for item in text.split(",") if item]
    return [(float(g), int(leaf)) for g, leaf in pairs]


def timed(pipe, work, calls=5):
    """Thread-CPU seconds of one trace (the mean of ``calls``) and the last hits and
    counters."""
    start = time.thread_time()
    for _ in range(calls):
        hits, counters = pipe.trace(work.rays, any_hit=work.any_hit)
    return (time.thread_time() - start) / calls, hits, counters


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--kinds", default="primary,diffuse")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--variants", type=variants, default=VARIANTS, metavar="G:LEAF,...",
                    help="the (group cost, largest leaf) pairs to compare with the default")
    add_bvh_argument(ap)
    args = ap.parse_args()
    scene = raysort.load_scene(args.scene)
    bvh = scene.bvh(**args.bvh)
    shapes = [DEFAULT] + [v for v in args.variants if v != DEFAULT]
    trees = {v: bvh.collapse8(group_cost=v[0], max_leaf=v[1]) for v in shapes}
    pipe = raysort.Pipeline(scene, sorter="none", traversal="stream")
    pipe._bvh = bvh                         # one binary tree; its wide8 is swapped below
    print(f"CPU ISA {raysort.isa.info()['active']}; {args.rounds} interleaved rounds")
    for kind in args.kinds.split(","):
        work = workload(scene, kind, width=256, height=256)
        seconds, counters, ref = {v: [] for v in shapes}, {}, None
        for r in range(args.rounds + 1):
            for v in shapes[r % len(shapes):] + shapes[:r % len(shapes)]:
                bvh._wide8 = trees[v]
                dt, hits, counters[v] = timed(pipe, work)
                if ref is None:
                    ref = hits.t.view(np.int32).copy(), hits.prim.copy()
                if not (np.array_equal(hits.t.view(np.int32), ref[0])
                        and np.array_equal(hits.prim, ref[1])):
                    raise SystemExit(f"tree {v}: hits differ from the default tree's")
                if r:                       # round 0 warms up
                    seconds[v].append(dt)
        n = len(work.rays)
        print(f"\n{args.scene} {kind} ({n} rays)\n")
        print("| group cost | largest leaf | Mrays/s | speed vs default [min, max] | SAH "
              "| ia | box4 | tri4 |\n| ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |")
        for v in shapes:
            ratios = [b / t for b, t in zip(seconds[shapes[0]], seconds[v])]
            c = counters[v]
            print(f"| {v[0]:.1f} | {v[1]} | {n / statistics.median(seconds[v]) / 1e6:.2f} | "
                  f"{statistics.median(ratios):.3f} [{min(ratios):.3f}, {max(ratios):.3f}] | "
                  f"{trees[v].sah_cost:.2f} | {c.ia / n:.3f} | {c.box4 / n:.3f} | "
                  f"{c.tri4 / n:.3f} |")
    bvh._wide8 = None


if __name__ == "__main__":
    main()
