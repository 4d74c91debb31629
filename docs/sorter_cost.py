"""Sort + gather cost and traversal time of every installed sorter, per traversal.

Usage (from any directory, with raysort installed)::

    python docs/sorter_cost.py                                # all sorters, ranged + wide
    python docs/sorter_cost.py --scenes sibenik --rounds 11 --json cost.json
    python docs/sorter_cost.py --sorters two_point two_point:octant=False garanzha:split=True
    python docs/sorter_cost.py --report docs/sorter-cost.json     # print saved results

For each scene, the first-bounce diffuse rays of a render (``workload(scene,
"diffuse:depth=1")``, 256x256 at 1 spp by default, in the large packets the render
makes) are sorted by every sorter, gathered and traced by every traversal, one
thread.  Each round runs every sorter once, in an order rotated by one per round
(interleaved, so that load on the machine is shared out), and times

* ``sort``: ``sorter.sort(rays, packets, bounds)``;
* ``gather``: ``raysort.rays.gather`` of the sorted rays into sub-packets;
* ``trace``: ``traversal.intersect`` of those sub-packets.

Times are the measuring thread's CPU time by default (``--clock cpu``), which
leaves out the time the thread waits for a core on a loaded machine;
``--clock wall`` uses wall-clock time.

Reported per scene, traversal and sorter: medians over rounds with [min, max],
the cost share ``(sort + gather) / trace`` (median of the per-round ratios; issue
13's goal is at most 10 %), the speed-up of the traversal and of sort + gather +
trace over ``none`` and over ``nah`` (medians of per-round ratios), and the Table
I counters per ray of one traversal (``N_IA``, box tests ``N_B`` = scalar + SIMD,
triangle tests ``N_T`` = scalar + SIMD).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import raysort
from raysort import isa
from raysort.bench.report import machine_info
from raysort.rays import gather
from raysort.workloads import workload


def machine():
    """The bench's machine record (CPU, cores, versions, ISA), with the ISA details."""
    return {**machine_info(), "isa_info": isa.info()}


def measure(scene_name, sorters, traversals, rounds, size, depth, clock=time.thread_time):
    """Per (traversal, sorter): lists of per-round seconds and one round's counters."""
    scene = raysort.load_scene(scene_name)
    bvh = scene.bvh()
    work = workload(scene, f"diffuse:depth={depth}", width=size, height=size, spp=1, seed=1)
    plugins = {name: raysort.create("sorters", name) for name in sorters}
    travs = {name: raysort.create("traversals", name) for name in traversals}
    times = {(t, s): {"sort": [], "gather": [], "trace": []} for t in traversals for s in sorters}
    counters = {}
    for r in range(rounds + 1):                 # round 0 warms up and is not kept
        for k in range(len(sorters)):
            s = sorters[(k + r) % len(sorters)]
            t0 = clock()
            order, offsets = plugins[s].sort(work.rays, work.packets, bvh.bounds)
            sort_s = clock() - t0
            for t in traversals:
                t1 = clock()
                packets = gather(work.rays, order, offsets)
                t2 = clock()
                c = travs[t].intersect(bvh, packets, any_hit=False)
                t3 = clock()
                if r == 0:
                    counters[t, s] = c.per_ray()
                    continue
                rec = times[t, s]
                rec["sort"].append(sort_s)
                rec["gather"].append(t2 - t1)
                rec["trace"].append(t3 - t2)
    return work, times, counters


CLOCKS = {"cpu": time.thread_time, "wall": time.perf_counter}


def ratio(num, den):
    """Median, min and max of the per-round ratios num[i] / den[i]."""
    rs = [a / b for a, b in zip(num, den)]
    return statistics.median(rs), min(rs), max(rs)


def summarise(times, counters, sorters, traversals):
    rows = []
    for t in traversals:
        base = times[t, "none"] if "none" in sorters else None
        nah = times[t, "nah"] if "nah" in sorters else None
        for s in sorters:
            rec = times[t, s]
            cost = [a + b for a, b in zip(rec["sort"], rec["gather"])]
            total = [a + b for a, b in zip(cost, rec["trace"])]
            row = {"traversal": t, "sorter": s,
                   "sort_ms": 1e3 * statistics.median(rec["sort"]),
                   "gather_ms": 1e3 * statistics.median(rec["gather"]),
                   "trace_ms": 1e3 * statistics.median(rec["trace"]),
                   "trace_ms_range": [1e3 * min(rec["trace"]), 1e3 * max(rec["trace"])],
                   "cost_share": ratio(cost, rec["trace"]),
                   "counters": counters[t, s]}
            for label, ref in (("none", base), ("nah", nah)):
                if ref is not None:
                    ref_total = [a + b + c for a, b, c in zip(ref["sort"], ref["gather"],
                                                              ref["trace"])]
                    row[f"trace_speedup_vs_{label}"] = ratio(ref["trace"], rec["trace"])
                    row[f"total_speedup_vs_{label}"] = ratio(ref_total, total)
            rows.append(row)
    return rows


def fmt_ratio(r, pct=False):
    if pct:
        return f"{100 * r[0]:5.1f}% [{100 * r[1]:.1f}, {100 * r[2]:.1f}]"
    return f"{r[0]:.3f} [{r[1]:.3f}, {r[2]:.3f}]"


def print_header(info, args, out=sys.stdout):
    print(f"CPU: {info['cpu']}; raysort ISA: {info['isa']}; one thread; "
          f"{args['rounds']} interleaved rounds; {args.get('clock', 'cpu')} time; "
          f"medians [min, max]", file=out)


def print_table(scene, rays, packets, rows, out=sys.stdout):
    print(f"\n### {scene}: {rays} first-bounce diffuse rays, {packets} large packets\n",
          file=out)
    print("| traversal | sorter | sort ms | gather ms | trace ms [min, max] | "
          "(sort+gather)/trace | trace speed-up vs none | vs nah | total speed-up vs nah | "
          "N_IA | N_B scalar + SIMD | N_T scalar + SIMD |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    for r in rows:
        c = r["counters"]
        if c["box1"] is None:                     # a traversal that cannot count
            ia = nb = nt = "n/a"
        else:
            ia = f"{c['ia']:.2f}"
            nb = f"{c['box1']:.1f} + {c['box4']:.1f}"
            nt = f"{c['tri1']:.1f} + {c['tri4']:.1f}"
        print(f"| {r['traversal']} | {r['sorter']} | {r['sort_ms']:.2f} | {r['gather_ms']:.2f} | "
              f"{r['trace_ms']:.1f} [{r['trace_ms_range'][0]:.1f}, "
              f"{r['trace_ms_range'][1]:.1f}] | {fmt_ratio(r['cost_share'], pct=True)} | "
              f"{fmt_ratio(r.get('trace_speedup_vs_none', (float('nan'),) * 3))} | "
              f"{fmt_ratio(r.get('trace_speedup_vs_nah', (float('nan'),) * 3))} | "
              f"{fmt_ratio(r.get('total_speedup_vs_nah', (float('nan'),) * 3))} | "
              f"{ia} | {nb} | {nt} |", file=out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="sibenik,sponza,forest")
    ap.add_argument("--sorters", nargs="+", default=["all"],
                    help="sorter names or specs ('two_point:octant=False'), or 'all' "
                         "installed; none and nah are always measured (the baselines)")
    ap.add_argument("--traversals", default="ranged,wide")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--size", type=int, default=256, help="image width and height")
    ap.add_argument("--depth", type=int, default=1, help="diffuse bounce (1: first)")
    ap.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                    help="cpu: this thread's CPU time (robust on a loaded machine, the "
                         "default); wall: perf_counter")
    ap.add_argument("--json", help="also write the results here")
    ap.add_argument("--report", metavar="JSON", help="print the tables of a saved --json "
                    "file instead of measuring")
    args = ap.parse_args(argv)
    if args.report:
        with open(args.report, encoding="utf-8") as fh:
            report = json.load(fh)
        print_header(report["machine"], report["args"])
        for scene, res in report["scenes"].items():
            print_table(scene, res["rays"], res["packets"], res["rows"])
        return
    sorters = []
    for spec in ["none", "nah"] + args.sorters:
        for name in raysort.available("sorters") if spec == "all" else [spec]:
            if name not in sorters:
                sorters.append(name)
    traversals = args.traversals.split(",")
    info = machine()
    print_header(info, vars(args))
    report = {"machine": info, "args": vars(args), "scenes": {}}
    for scene in args.scenes.split(","):
        work, times, counters = measure(scene, sorters, traversals, args.rounds, args.size,
                                        args.depth, CLOCKS[args.clock])
        rows = summarise(times, counters, sorters, traversals)
        print_table(scene, len(work.rays), len(work.packets) - 1, rows)
        sys.stdout.flush()
        report["scenes"][scene] = {"rays": len(work.rays), "packets": len(work.packets) - 1,
                                   "rows": rows, "times": {
            f"{t}/{s}": v for (t, s), v in times.items()}}
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, separators=(",", ":"))


if __name__ == "__main__":
    main()
