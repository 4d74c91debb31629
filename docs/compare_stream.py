"""The ``stream`` traversal against single-ray ``wide8`` / ``wide`` and Embree (Pipeline.trace).

Usage (from any directory, with raysort installed; Embree rows need
``pip install ./plugins/raysort-embree``)::

    python docs/compare_stream.py                          # Sibenik, Sponza, forest
    python docs/compare_stream.py --scenes sibenik --rounds 9 --size 256
    python docs/compare_stream.py --configs stream+nah wide8+nah embree+none
    python docs/compare_stream.py --configs stream+nah stream:tree=4+nah wide8+nah

Workload: the first-bounce diffuse rays of a render (``workload(scene,
"diffuse:depth=1")``, ``--size`` squared pixels at 1 spp, in the tile-sized large
packets the render makes), traced through ``Pipeline(scene, sorter, traversal,
threads=1).trace`` in batches of ``--batch`` rays (the pipeline's ``batch_rays``: a
render at 16 spp or more hands each trace call that many rays of one tile).  A
configuration is ``traversal+sorter`` (``traversal:key=value`` for parameters).

Each round runs every configuration once over the whole workload, in an order
rotated by one per round; round 0 warms up and is not kept.  Per configuration:
the median over rounds (with [min, max]) of the traverse stage and of sort +
gather + traverse (the pipeline's own stage clock, wall time), and the median of
the per-round ratios against the reference configurations (``--versus``); the
best single-ray wide configuration (``wide8`` or ``wide``) is the one with the lowest
median traverse time.
Counters per ray (box and triangle tests, mean stream size) come from one round.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys

import raysort
from raysort import isa
from raysort.bench.report import machine_info
from raysort.workloads import workload


def machine():
    """The bench's machine record (CPU, cores, versions, ISA), with the ISA details."""
    return {**machine_info(), "isa_info": isa.info()}


def parse_config(text):
    """``traversal[:k=v,...]+sorter`` -> (traversal spec, sorter name)."""
    traversal, _, sorter = text.partition("+")
    return traversal, sorter or "none"


def batches(work, size):
    """(rays, large packets) of consecutive runs of whole large packets, about ``size`` rays."""
    packets = work.packets
    start = 0
    for k in range(1, len(packets)):
        if packets[k] - packets[start] >= size or k == len(packets) - 1:
            a, b = int(packets[start]), int(packets[k])
            idx = list(range(a, b))
            yield work.rays.take(idx), (packets[start:k + 1] - a).astype("int32")
            start = k


def measure(scene_name, configs, rounds, size, batch):
    scene = raysort.load_scene(scene_name)
    work = workload(scene, "diffuse:depth=1", width=size, height=size, spp=1, seed=1)
    chunks = list(batches(work, batch))
    pipes = {}
    for c in configs:
        traversal, sorter = parse_config(c)
        pipes[c] = raysort.Pipeline(scene, sorter=sorter, traversal=traversal, threads=1,
                                    check_plugins=False, batch_rays=batch)
    times = {c: {"traverse": [], "total": []} for c in configs}
    counters = {}
    for r in range(rounds + 1):
        for k in range(len(configs)):
            c = configs[(k + r) % len(configs)]
            timings = {}
            total = raysort.Counters()
            for rays, packets in chunks:
                _, counts = pipes[c].trace(rays, packets, timings=timings)
                total = total + counts
            if r == 0:
                counters[c] = total
                continue
            times[c]["traverse"].append(timings["traverse"])
            times[c]["total"].append(sum(timings.get(s, 0.0)
                                         for s in ("sort", "gather", "traverse")))
    return len(work.rays), len(chunks), times, counters


def median_ratio(num, den):
    return statistics.median(a / b for a, b in zip(num, den))


def report(scene_name, n_rays, n_chunks, times, counters, versus, out=sys.stdout):
    configs = list(times)
    wide = [c for c in configs if parse_config(c)[0].split(":")[0] in ("wide", "wide8")]
    best_wide = min(wide, key=lambda c: statistics.median(times[c]["traverse"])) if wide else None
    refs = [v for v in versus if v in times] + ([f"best wide ({best_wide})"] if best_wide else [])
    ref_times = {v: times[v]["traverse"] for v in versus if v in times}
    if best_wide:
        ref_times[refs[-1]] = times[best_wide]["traverse"]
    print(f"\n## {scene_name}: {n_rays} first-bounce diffuse rays in {n_chunks} trace calls",
          file=out)
    head = ["config", "traverse s [min, max]", "sort+gather+traverse s"] + \
           [f"x vs {v}" for v in refs] + ["N_B/ray", "N_T/ray", "rays/stream"]
    print("| " + " | ".join(head) + " |", file=out)
    print("|" + "---|" * len(head), file=out)
    rows = []
    for c in sorted(configs, key=lambda c: statistics.median(times[c]["traverse"])):
        t = times[c]["traverse"]
        tot = times[c]["total"]
        cnt = counters[c]
        per = cnt.per_ray()
        nb = None if per["box1"] is None else per["box1"] + per["box4"]
        nt = None if per["tri1"] is None else per["tri1"] + per["tri4"]
        mean_stream = cnt.stream_rays / cnt.stream_tasks if cnt.stream_tasks else None
        ratios = {v: median_ratio(ref_times[v], t) for v in refs}
        row = [c, f"{statistics.median(t):.4f} [{min(t):.4f}, {max(t):.4f}]",
               f"{statistics.median(tot):.4f}"] + [f"{ratios[v]:.2f}" for v in refs] + \
              ["-" if nb is None else f"{nb:.1f}", "-" if nt is None else f"{nt:.1f}",
               "-" if mean_stream is None else f"{mean_stream:.1f}"]
        print("| " + " | ".join(row) + " |", file=out)
        rows.append({"config": c, "traverse": t, "total": tot, "ratios": ratios,
                     "counters": cnt.as_dict()})
    return rows


DEFAULT_CONFIGS = (["stream+" + s for s in ("none", "nah", "origin_direction", "two_point",
                                            "termination", "garanzha")]
                   + ["wide8+none", "wide8+nah", "embree+none"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["sibenik", "sponza", "forest"])
    ap.add_argument("--configs", nargs="+", default=DEFAULT_CONFIGS)
    ap.add_argument("--versus", nargs="+", default=["wide8+nah", "embree+none"])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--size", type=int, default=256, help="image width and height (pixels)")
    ap.add_argument("--batch", type=int, default=16384, help="rays per Pipeline.trace call")
    ap.add_argument("--json", help="also write the results here")
    args = ap.parse_args(argv)
    installed = set(raysort.available("traversals"))
    configs = [c for c in args.configs if parse_config(c)[0].split(":")[0] in installed]
    skipped = sorted(set(args.configs) - set(configs))
    info = machine()
    print(f"# stream vs wide vs Embree — {info['cpu']}, ISA {info['isa']}, one thread, "
          f"{args.rounds} rounds (+1 warm-up), {args.size}x{args.size} px, batches of "
          f"{args.batch} rays")
    if skipped:
        print(f"(not installed, skipped: {', '.join(skipped)})")
    results = {"machine": info, "args": vars(args), "scenes": {}}
    for scene_name in args.scenes:
        n, chunks, times, counters = measure(scene_name, configs, args.rounds, args.size,
                                             args.batch)
        results["scenes"][scene_name] = report(scene_name, n, chunks, times, counters,
                                               args.versus)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
