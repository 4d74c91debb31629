"""Rays per second through ``Pipeline.trace`` for several configurations, side by side.

Usage (from any directory, with raysort installed; ``embree`` needs
``pip install ./plugins/raysort-embree``)::

    python docs/bench_trace.py                              # Sibenik, Sponza, forest
    python docs/bench_trace.py --scenes sibenik --rounds 9 --json trace.json
    python docs/bench_trace.py --configs nah+wide8 nah+wide embree --kinds diffuse
    python docs/bench_trace.py --kinds frame --configs nah+wide8 nah+embree --against nah+embree

Each configuration is ``SORTER+TRAVERSAL`` (optionally ``@TILE`` for the tile edge of
camera rays, e.g. ``none+ranged@8``) or a bare traversal (sorter ``none``); a plugin may
carry parameters, e.g. ``mitsuba:coherent=true``.  ``direct:TRAVERSAL`` (a library
yardstick such as ``direct:embree`` or ``direct:mitsuba:coherent=true``) times only the
library's own query (``LibraryTraversal.query``) on the rays' origins, directions and
extents prepared beforehand: no sort, gather, scatter, nor the plugin's own array
handling, the strictest reading of the yardstick.  For each
scene and ray kind (``diffuse``: first-bounce diffuse rays of a 256x256 render at 1
spp, in the render's large packets; ``camera``: its primary rays) every configuration
traces the same rays through ``Pipeline.trace`` (sort + gather + traverse + scatter),
one thread, plugin checks off for trusted plugins; ``frame`` renders a whole frame
instead (``Pipeline.render``, 4 spp, lambert depth 2) and reports Mpixels/s.  Each round runs every
configuration once in an order rotated by one per round (interleaved, round 0 warms
up and is dropped).  Reported: Mrays/s as the median over rounds with [min, max], and
the medians [min, max] of the per-round speed ratios against the reference
configurations (``--against``, default ``direct:embree``, ``embree`` and
``nah+wide8``).  Times are the
measuring thread's CPU time (``--clock cpu``, default; robust to other load on the
machine) or wall time (``--clock wall``).  The header names the CPU and the ISA.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import numpy as np

import raysort
from raysort import isa
from raysort.bench.command import add_bvh_argument
from raysort.bench.report import machine_info
from raysort.workloads import camera_rays, workload

DEFAULT_CONFIGS = ["nah+wide8", "none+wide8", "two_point+wide8", "nah+stream", "none+stream",
                   "nah+ranged", "none+ranged@8", "embree", "direct:embree", "direct:mitsuba",
                   "direct:mitsuba:coherent=true"]
CLOCKS = {"cpu": time.thread_time, "wall": time.perf_counter}
DIRECT = "direct:"      # a library traversal's own query alone (see the module docstring)


def machine():
    """The bench's machine record (CPU, cores, versions, ISA), with the ISA details."""
    return {**machine_info(), "isa_info": isa.info()}


def parse_config(text):
    """``"nah+wide8@8"`` -> (sorter, traversal, tile); ``"direct:mitsuba"`` -> (None,
    "mitsuba", 32)."""
    if text.startswith(DIRECT):
        return None, text[len(DIRECT):], 32
    body, _, tile = text.partition("@")
    sorter, _, traversal = body.rpartition("+")
    return sorter or "none", traversal, int(tile) if tile else 32


def rays_of(scene, kind, size, tile):
    if kind == "diffuse":
        return workload(scene, "diffuse:depth=1", width=size, height=size, spp=1, seed=1,
                        tile=tile)
    return camera_rays(scene, width=size, height=size, spp=1, seed=1, tile=tile)[0]


def direct_query(library, bvh, rays):
    """The arguments of ``library.query`` for ``rays``: (scene, origins, directions, far),
    each ray started at ``tmin`` as :class:`raysort.sdk.LibraryTraversal` does."""
    start = np.maximum(rays.tmin, np.float32(0))
    far = np.where(rays.tmax > rays.tmin, np.minimum(rays.tmax - start, np.float32(1e37)), 0)
    return (library.scene(bvh),
            np.ascontiguousarray((rays.origins + start * rays.directions).T, np.float32),
            np.ascontiguousarray(rays.directions.T, np.float32),
            np.ascontiguousarray(far, np.float32))


def measure(scene_name, kind, configs, rounds, size, clock, bvh_params=None):
    scene = raysort.load_scene(scene_name)
    start = time.perf_counter()
    bvh = scene.bvh(**(bvh_params or {}))
    build = {"binary_s": time.perf_counter() - start}
    wide8 = bvh.wide8
    build.update(wide8_s=wide8.build_seconds, wide8_sah=wide8.sah_cost,
                 binary_sah=bvh.stats()["sah_cost"], wide8_nodes=len(wide8.nodes),
                 wide8_groups=len(wide8.groups), wide8_depth=wide8.depth)
    pipes, works = {}, {}
    for c in configs:
        sorter, traversal, tile = parse_config(c)
        if sorter is None:
            pipes[c] = raysort.create("traversals", traversal)
        else:
            pipes[c] = raysort.Pipeline(scene, sorter=sorter, traversal=traversal, tile=tile,
                                        threads=1, check_plugins=False)
            pipes[c]._bvh = bvh                  # one BVH for all (built above)
        if tile not in works:
            works[tile] = None if kind == "frame" else \
                rays_of(scene, kind, size, tile if kind == "camera" else 32)
    direct = {c: direct_query(pipes[c], bvh, works[32].rays) for c in configs
              if parse_config(c)[0] is None}
    times = {c: [] for c in configs}
    for r in range(rounds + 1):                  # round 0 warms up and is not kept
        for k in range(len(configs)):
            c = configs[(k + r) % len(configs)]
            work = works[parse_config(c)[2]]
            t0 = clock()
            if kind == "frame":
                pipes[c].render(size, size, spp=4, seed=0)
            elif parse_config(c)[0] is None:
                pipes[c].query(*direct[c], False)
            else:
                pipes[c].trace(work.rays, work.packets)
            dt = clock() - t0
            if r:
                times[c].append(dt)
    n = size * size if kind == "frame" else len(next(iter(works.values())).rays)
    return n, times, build


def ratios(num, den):
    rs = [b / a for a, b in zip(num, den)]        # speed ratio: time of den / time of num
    return [statistics.median(rs), min(rs), max(rs)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["sibenik", "sponza", "forest"])
    ap.add_argument("--kinds", nargs="+", default=["diffuse", "camera"],
                    choices=["diffuse", "camera", "frame"])
    ap.add_argument("--configs", nargs="+", default=DEFAULT_CONFIGS)
    ap.add_argument("--against", nargs="+", default=["direct:embree", "embree", "nah+wide8"])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--clock", choices=sorted(CLOCKS), default="cpu")
    add_bvh_argument(ap)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    installed = set(raysort.available("traversals"))
    configs = [c for c in args.configs if parse_config(c)[1].partition(":")[0] in installed
               and not (args.kinds == ["frame"] and parse_config(c)[0] is None)]
    for c in sorted(set(args.configs) - set(configs)):
        print(f"skipping {c}: traversal not installed", file=sys.stderr)
    info = machine()
    print(f"CPU: {info['cpu']}; raysort ISA: {info['isa']} (compiled: "
          f"{', '.join(info['isa_info']['compiled'])}); one thread; {args.rounds} interleaved "
          f"rounds; {args.clock} time; BVH {args.bvh or 'defaults'}; Mrays/s median "
          f"[min, max]")
    results = []
    for scene in args.scenes:
        for kind in args.kinds:
            n, times, build = measure(scene, kind, configs, args.rounds, args.size,
                                      CLOCKS[args.clock], args.bvh)
            print(f"\n### {scene}, {kind} ({n} {'pixels' if kind == 'frame' else 'rays'}); "
                  f"BVH {build['binary_s']:.2f} s, wide8 "
                  f"collapse {build['wide8_s'] * 1e3:.0f} ms, SAH binary "
                  f"{build['binary_sah']:.1f} / wide8 {build['wide8_sah']:.2f}\n")
            refs = [a for a in args.against if a in times]
            unit = "Mpixels/s" if kind == "frame" else "Mrays/s"
            print(f"| configuration | {unit} [min, max] |" +
                  "".join(f" speed vs {a} [min, max] |" for a in refs))
            print("|---|---|" + "---|" * len(refs))
            rows = []
            for c in configs:
                speeds = [n / t / 1e6 for t in times[c]]
                row = {"scene": scene, "kind": kind, "config": c, "rays": n,
                       "mrays_s": [statistics.median(speeds), min(speeds), max(speeds)],
                       "vs": {a: ratios(times[c], times[a]) for a in refs}, "build": build}
                rows.append(row)
                m = row["mrays_s"]
                print(f"| {c} | {m[0]:.2f} [{m[1]:.2f}, {m[2]:.2f}] |" +
                      "".join(" {:.2f}x [{:.2f}, {:.2f}] |".format(*row["vs"][a]) for a in refs))
            results += rows
            sys.stdout.flush()
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"machine": info, "args": vars(args), "results": results}, fh, indent=1)


if __name__ == "__main__":
    main()
