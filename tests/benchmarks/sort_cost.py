"""What sorting costs next to the fast traversals: sort, gather and trace of the same rays.

    python tests/benchmarks/sort_cost.py [scene ...] [--sorters a,b] [--traversals wide8,stream]
                                         [--rounds 7] [--size 256] [--rays diffuse]
                                         [--json out.json] [--markdown]
    python tests/benchmarks/sort_cost.py --medians run1.json run2.json ...

For each scene (default: sibenik, sponza, forest) the first-bounce diffuse rays of a
``--size`` square render at 1 spp (:func:`raysort.workloads.workload`, the rays ``raysort
bench --kernels`` measures; ``--rays`` names another workload kind, e.g. ``primary``,
``diffuse:depth=2`` or ``shadow``, whose any-hit rays are traced as any-hit queries) are,
for every sorter (default: every installed one) and every
traversal, sorted, gathered and traced, and each of the three is timed by the thread's CPU
clock (``time.thread_time``: one thread, so other jobs on the machine count less than in wall
time).  The gather is the pipeline's gather stage (:func:`raysort.rays.gather_checked`, which
checks the sorter's order against the large packets on the way, as a render does by default).
The configurations (sorter x traversal) run in interleaved rounds, in an order shuffled per
round, after one untimed warm-up round (:func:`raysort.bench.rounds.run_rounds`).
Per configuration it prints the medians of sort, gather and trace [min-max], and the median of
the per-round shares (sort + gather) / trace [min-max]: the budget of issue 13 is 10 %.  Every
configuration's hits must equal the first one's (t bit for bit, prim), or the run fails.
``--markdown`` also prints each scene as a Markdown table (sorters by rows, one sort + gather
share column per traversal), as BENCHMARKS.md shows it.  ``--medians`` runs nothing: it prints,
per scene, sorter and traversal, the median over the given ``--json`` files of each run's median
sort time and share (for runs of two builds alternated on a shared machine).
"""
import argparse
import json
import sys
import time

import numpy as np

from raysort import isa, registry
from raysort.bench.report import load_average, machine_info
from raysort.bench.rounds import run_rounds, summary
from raysort.rays import MAX_PACKET, Hits, gather_checked, scatter, scatter_occluded
from raysort.scene import load_scene
from raysort.workloads import workload

BUDGET = 0.10


def reads_batch(traversal):
    """Whether the pipeline lets this traversal read the batch itself (no gather)."""
    return hasattr(traversal, "_intersect_batch")


class Config:
    """One sorter and one traversal on one workload: each call sorts, gathers and traces once,
    keeps the three thread-CPU times and returns the trace's.

    A traversal that reads the batch itself (``stream``) takes the pipeline's path unless
    ``packets``: the "gather" is then the check of the sorter's result that the pipeline runs
    instead (the traversal copies each ray into its records itself, in the trace)."""

    def __init__(self, sorter, traversal, bvh, work, packets=False):
        self.sorter = registry.create("sorters", sorter)
        self.traversal = registry.create("traversals", traversal)
        self.batch = reads_batch(self.traversal) and not packets
        self.sorter_name = sorter
        self.traversal_name = traversal + (" (batch)" if self.batch else "")
        self.bvh, self.work = bvh, work
        self.sort, self.gather, self.trace = [], [], []
        self.hits = None

    def __call__(self):
        w = self.work
        packets_in, bounds = w.packets.copy(), self.bvh.bounds.copy()
        out = np.empty(len(w), np.uint8) if w.any_hit else np.empty((4, len(w)), np.float32)
        t0 = time.thread_time()
        order, offsets = self.sorter.sort(w.rays, packets_in, bounds)
        t1 = time.thread_time()
        if self.batch:
            assert isa.module("_contract").sort_result(order, offsets, w.packets, len(w),
                                                       MAX_PACKET)[0] == 0
            t2 = time.thread_time()
            self.traversal._intersect_batch(self.bvh, w.rays.data, order, offsets, 0,
                                            len(offsets) - 1, w.any_hit, out)
            t3 = time.thread_time()
            self.hits = out.view(bool) if w.any_hit else Hits._of_block(out)
        else:
            packets = gather_checked(w.rays, order, offsets, w.packets)[0]
            t2 = time.thread_time()
            self.traversal.intersect(self.bvh, packets, any_hit=w.any_hit)
            t3 = time.thread_time()
            self.hits = (scatter_occluded if w.any_hit else scatter)(packets, len(w))
        self.sort.append(t1 - t0)
        self.gather.append(t2 - t1)
        self.trace.append(t3 - t2)
        return t3 - t2

    def row(self, rounds):
        """Medians and spreads of the timed rounds (the warm-up is dropped)."""
        sort, gath, trace = (np.asarray(x[-rounds:]) for x in (self.sort, self.gather, self.trace))
        return {"sorter": self.sorter_name, "traversal": self.traversal_name,
                "sort": summary(sort), "gather": summary(gath), "trace": summary(trace),
                "share": summary((sort + gath) / trace)}


def same_hits(a, b):
    if isinstance(a, np.ndarray):       # any-hit: occluded or not
        return bool(np.array_equal(a, b))
    return bool(np.array_equal(a.t.view(np.uint32), b.t.view(np.uint32))
                and np.array_equal(a.prim, b.prim))


def spread_ms(s):
    return f"{1e3 * s['median']:7.2f} [{1e3 * s['min']:.2f}-{1e3 * s['max']:.2f}]"


def spread_pct(s):
    return f"{100 * s['median']:5.1f} % [{100 * s['min']:.1f}-{100 * s['max']:.1f}]"


def markdown(scene, rows):
    """One scene's rows as a Markdown table: a row per sorter, the sort and gather medians
    (of the first traversal's rounds) and the median share [min-max] per traversal."""
    by = {(r["sorter"], r["traversal"]): r for r in rows}
    traversals = list(dict.fromkeys(r["traversal"] for r in rows))
    sorters = list(dict.fromkeys(r["sorter"] for r in rows))
    head = ["sorter", "sort ms", "gather ms"] + [f"{t} ms" for t in traversals] + \
        [f"share vs {t}" for t in traversals]
    lines = [f"{scene}:", "", "| " + " | ".join(head) + " |",
             "| --- |" + " ---: |" * (len(head) - 1)]
    for s in sorters:
        first = by[s, traversals[0]]
        cells = [s, f"{1e3 * first['sort']['median']:.2f}",
                 f"{1e3 * first['gather']['median']:.2f}"]
        cells += [f"{1e3 * by[s, t]['trace']['median']:.1f}" for t in traversals]
        cells += [f"{100 * by[s, t]['share']['median']:.1f} % "
                  f"[{100 * by[s, t]['share']['min']:.1f}–{100 * by[s, t]['share']['max']:.1f}]"
                  for t in traversals]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def medians(paths):
    """Per (scene, sorter, traversal): the median over runs of each run's median sort
    seconds, gather seconds, trace seconds and share."""
    runs = {}
    for path in paths:
        with open(path, encoding="utf-8") as fh:
            report = json.load(fh)
        for scene, data in report["scenes"].items():
            for r in data["rows"]:
                runs.setdefault((scene, r["sorter"], r["traversal"]), []).append(r)
    print(f"median over {len(paths)} runs of each run's median "
          f"(thread-CPU ms; share = (sort + gather) / trace)")
    print(f"{'scene':10s}{'sorter':18s}{'traversal':10s}{'sort':>8s}{'gather':>8s}"
          f"{'trace':>8s}{'share':>9s}")
    for (scene, sorter, traversal), rows in runs.items():
        sort, gath, trace, share = (np.median([r[key]["median"] for r in rows])
                                    for key in ("sort", "gather", "trace", "share"))
        print(f"{scene:10s}{sorter:18s}{traversal:10s}{1e3 * sort:8.2f}{1e3 * gath:8.2f}"
              f"{1e3 * trace:8.1f}{100 * share:7.1f} %")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["sibenik", "sponza", "forest"])
    parser.add_argument("--sorters", default=None,
                        help="comma-separated sorter specs (default: every installed sorter)")
    parser.add_argument("--traversals", default="wide8,stream")
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds (7)")
    parser.add_argument("--size", type=int, default=256, help="image edge in pixels (256)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rays", default="diffuse",
                        help="the workload kind (raysort.workloads: primary, diffuse, shadow, "
                             "ao; default diffuse)")
    parser.add_argument("--json", default=None, help="also write the results here")
    parser.add_argument("--markdown", action="store_true", help="also print Markdown tables")
    parser.add_argument("--packets", action="store_true",
                        help="also run traversals that read the batch (stream) through "
                             "gathered packets, as before they could")
    parser.add_argument("--medians", nargs="+", metavar="JSON",
                        help="only summarise these --json files (see the module docstring)")
    args = parser.parse_args(argv)
    if args.medians:
        medians(args.medians)
        return 0
    sorters = (args.sorters.split(",") if args.sorters
               else [s for s in registry.available("sorters")])
    traversals = args.traversals.split(",")
    machine = machine_info()
    report = {"machine": machine, "load": {"before": load_average()}, "rounds": args.rounds,
              "size": args.size, "seed": args.seed, "rays": args.rays, "scenes": {}}
    print(f"CPU {machine['cpu']}, {machine['cores']} cores, ISA {machine['isa']} (NumPy's "
          f"SIMD {machine['numpy_simd']}), load {report['load']['before']}; thread-CPU ms, "
          f"median [min-max] of "
          f"{args.rounds} interleaved rounds; share = (sort + gather) / trace, per round")
    failed = False
    for j, spec in enumerate(args.scenes):
        scene = load_scene(spec)
        bvh = scene.bvh()
        work = workload(scene, args.rays, width=args.size, height=args.size, seed=args.seed)
        configs = [Config(s, t, bvh, work, packets) for s in sorters for t in traversals
                   for packets in ((False, True) if args.packets else (False,))
                   if not packets or reads_batch(registry.create("traversals", t))]
        run_rounds(configs, args.rounds, seed=j)
        rows = [c.row(args.rounds) for c in configs]
        for c, r in zip(configs, rows):
            r["identical_hits"] = same_hits(c.hits, configs[0].hits)
            failed |= not r["identical_hits"]
        report["scenes"][scene.name] = {"rays": len(work), "triangles": scene.n_triangles,
                                        "rows": rows}
        print(f"\n{scene.name}: {len(work)} {args.rays} rays, "
              f"{scene.n_triangles} triangles")
        print(f"{'sorter':18s}{'traversal':10s}{'sort ms':>22s}{'gather ms':>22s}"
              f"{'trace ms':>24s}   share")
        for r in rows:
            flag = "" if r["identical_hits"] else "  HITS DIFFER"
            over = "  > 10 %" if r["share"]["median"] > BUDGET else ""
            print(f"{r['sorter']:17s} {r['traversal']:10s}{spread_ms(r['sort']):>22s}"
                  f"{spread_ms(r['gather']):>22s}{spread_ms(r['trace']):>24s}   "
                  f"{spread_pct(r['share'])}{over}{flag}")
        sys.stdout.flush()
    report["load"]["after"] = load_average()
    print(f"\nload after: {report['load']['after']}")
    if args.markdown:
        for name, scene in report["scenes"].items():
            print("\n" + markdown(name, scene["rows"]))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=1)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
