"""Traversal-only timing: several traversals (and parameter settings) on the same gathered rays.

Usage (from any directory, with raysort installed)::

    python docs/bench_traverse.py                                   # wide8 vs stream, 3 scenes
    python docs/bench_traverse.py --configs stream stream:min_stream=16 stream:tree=4 wide8
    python docs/bench_traverse.py --scenes sibenik --sorter none --rounds 11

The first-bounce diffuse rays of a 256x256 render at 1 spp (``workload(scene,
"diffuse:depth=1")``) are sorted once with ``--sorter`` and gathered once into the
sorter's sub-packets; then every configuration (``TRAVERSAL`` or
``TRAVERSAL:key=value,...``) traces all of them in one ``intersect`` call per round,
from the same starting state, in an order rotated by one per round (round 0 warms up
and is dropped).  No sort, gather or scatter is timed: this isolates the kernels,
where ``docs/bench_trace.py`` measures what ``Pipeline.trace`` costs.  Reported per
configuration: thread CPU time, median [min, max] over rounds, the median [min, max]
of the per-round speed ratios against the first configuration, whether its hits are
bit-identical to the first's, and its counters per ray.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import raysort
from raysort import isa
from raysort.bench.report import machine_info
from raysort.rays import PacketRow, gather_checked
from raysort.workloads import workload


def traversal(spec):
    """``"stream:min_stream=16,order=direction"`` -> a traversal plugin."""
    name, _, rest = spec.partition(":")
    params = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        params[key] = int(value) if value.lstrip("-").isdigit() else value
    return raysort.create("traversals", {"type": name, **params})


def measure(scene_name, sorter, configs, rounds):
    scene = raysort.load_scene(scene_name)
    bvh = scene.bvh()
    work = workload(scene, "diffuse:depth=1", width=256, height=256, spp=1, seed=1)
    order, offsets = raysort.create("sorters", sorter).sort(work.rays, work.packets.copy(),
                                                            bvh.bounds.copy())
    batch = gather_checked(work.rays, np.asarray(order, np.int32),
                           np.asarray(offsets, np.int32), work.packets, check_order=False)[0]
    t_row = int(PacketRow.t)
    start_t = batch.rows[t_row].copy()
    plugins = {c: traversal(c) for c in configs}
    times = {c: [] for c in configs}
    results = {}
    for r in range(rounds + 1):
        for k in range(len(configs)):
            c = configs[(k + r) % len(configs)]
            batch.rows[t_row] = start_t
            batch.prim.fill(-1)
            t0 = time.thread_time()
            counters = plugins[c].intersect(bvh, batch)
            dt = time.thread_time() - t0
            if r:
                times[c].append(dt)
            results[c] = (batch.prim.copy(), batch.rows[t_row].view(np.int32).copy(), counters)
    return len(work.rays), times, results


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["sibenik", "sponza", "forest"])
    ap.add_argument("--sorter", default="nah")
    ap.add_argument("--configs", nargs="+", default=["wide8", "stream"])
    ap.add_argument("--rounds", type=int, default=9)
    args = ap.parse_args(argv)
    info = machine_info()
    print(f"CPU: {info['cpu']}; raysort ISA: {isa.active()}; one thread; {args.rounds} "
          f"interleaved rounds; thread CPU time; sorter {args.sorter}")
    ref = args.configs[0]
    for scene_name in args.scenes:
        n, times, results = measure(scene_name, args.sorter, args.configs, args.rounds)
        print(f"\n### {scene_name}: {n} first-bounce diffuse rays, one call\n")
        print(f"| configuration | ms [min, max] | speed vs {ref} [min, max] | same hits | "
              "N_B/ray | N_T/ray | rays/stream |")
        print("|---|---|---|---|---|---|---|")
        for c in args.configs:
            t = times[c]
            ratios = [a / b for a, b in zip(times[ref], t)]
            same = all(np.array_equal(x, y) for x, y in zip(results[c][:2], results[ref][:2]))
            cnt = results[c][2]
            per = cnt.per_ray()
            nb = (per["box1"] or 0) + (per["box4"] or 0)
            nt = (per["tri1"] or 0) + (per["tri4"] or 0)
            stream = f"{cnt.stream_rays / cnt.stream_tasks:.1f}" if cnt.stream_tasks else "-"
            print(f"| {c} | {statistics.median(t) * 1e3:.2f} [{min(t) * 1e3:.2f}, "
                  f"{max(t) * 1e3:.2f}] | {statistics.median(ratios):.2f}x [{min(ratios):.2f}, "
                  f"{max(ratios):.2f}] | {'yes' if same else 'NO'} | {nb:.1f} | {nt:.1f} | "
                  f"{stream} |")


if __name__ == "__main__":
    main()
