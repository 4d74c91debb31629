"""What a sorter's order does to the ``stream`` traversal: the same rays, the same work,
other memory.

Usage (from any directory, with raysort installed)::

    python docs/stream_orders.py                      # Sibenik, Sponza, forest
    python docs/stream_orders.py --scenes sibenik --rounds 15 --json out.json

Workload: the first-bounce diffuse rays of a ``--size`` squared render at 1 spp
(:func:`raysort.workloads.workload`, in the render's 1024-ray large packets: the rays
``tests/benchmarks/sort_cost.py`` measures).  Each is traced by ``stream`` the way the
pipeline does (reading the batch through the order, ``_intersect_batch``), once per
*order*:

* ``none``: the batch order, cut into ``none``'s sub-packets (the baseline);
* ``random``: a random permutation within each large packet, ``none``'s sub-packets;
* each sorter: its own order and sub-packets;
* ``none, cut as S``: the batch order cut into sorter ``S``'s sub-packets (as many
  chunks as ``S`` makes, none of its reordering; one row per distinct cut).

A sorter reorders rays only within a large packet.  Where every stream is made of
whole large packets (Sibenik's 65,536 rays: four streams of 16,384, sixteen 1024-ray
packets each) every order traces the same rays in the same streams, so the Table I
counters are equal for every order and a difference in time is memory and
bookkeeping; where a stream's cut falls inside a large packet (a batch whose packets
lost rays that missed), the rays on either side of the cut depend on the order and
the counters differ a little (the SIMD N_B column: box tests over ``none``'s).  Rounds
are interleaved (the orders shuffled per round, one untimed warm-up round); per order
the median thread-CPU ms of a trace [min, max] and the median [min, max] of the
per-round ratios to ``none``.  The hits must equal ``none``'s bit for bit (the script
exits with 1 otherwise).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from raysort import registry
from raysort.bench.report import load_average, machine_info
from raysort.bench.rounds import run_rounds, summary
from raysort.scene import load_scene
from raysort.workloads import workload

SORTERS = ("nah", "garanzha", "origin_direction", "termination", "two_point")


class Trace:
    """One order of one workload: each call traces it once and keeps the thread CPU."""

    def __init__(self, name, order, offsets, traversal, bvh, work):
        self.name, self.traversal, self.bvh, self.work = name, traversal, bvh, work
        self.order = np.ascontiguousarray(order, dtype=np.int32)
        self.offsets = np.ascontiguousarray(offsets, dtype=np.int32)
        self.out = np.empty((4, len(work)), np.float32)
        self.seconds, self.counters = [], None

    def __call__(self):
        t0 = time.thread_time()
        counters, bad_ray, bad_hit, order_ok = self.traversal._intersect_batch(
            self.bvh, self.work.rays.data, self.order, self.offsets, 0, len(self.offsets) - 1,
            False, self.out)
        self.seconds.append(time.thread_time() - t0)
        assert order_ok and bad_ray == -1 and bad_hit == -1, self.name
        self.counters = counters
        return self.seconds[-1]


def orders_of(work, bvh, rng):
    """``{name: (order, offsets)}`` for the orders of the module docstring."""
    out = {}
    for name in ("none",) + SORTERS:
        out[name] = registry.create("sorters", name).sort(work.rays, work.packets.copy(),
                                                          bvh.bounds.copy())
    order, offsets = out["none"]
    shuffled = np.array(order, dtype=np.int32)
    for a, b in zip(work.packets[:-1], work.packets[1:]):
        shuffled[a:b] = rng.permutation(shuffled[a:b])
    out["random"] = (shuffled, offsets)
    cuts = {}          # sorters with the same sub-packets share a row
    for name in SORTERS:
        if not np.array_equal(out[name][1], offsets):
            key = np.asarray(out[name][1]).tobytes()
            cuts.setdefault(key, (out[name][1], []))[1].append(name)
    for cut, names in cuts.values():
        out[f"none, cut as {'/'.join(names)}"] = (order, cut)
    return out


def same(a, b):
    return bool(np.array_equal(a.view(np.uint32), b.view(np.uint32)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["sibenik", "sponza", "forest"])
    parser.add_argument("--rounds", type=int, default=11, help="timed rounds (11)")
    parser.add_argument("--size", type=int, default=256, help="image edge in pixels (256)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", default=None, help="also write the results here")
    args = parser.parse_args(argv)
    machine = machine_info()
    print(f"CPU {machine['cpu']}, {machine['cores']} cores, ISA {machine['isa']}, load "
          f"{load_average()}; stream through the batch, thread-CPU ms, median [min, max] "
          f"of {args.rounds} interleaved rounds; ratio: per round, to none")
    report, failed = {"machine": machine, "rounds": args.rounds, "scenes": {}}, False
    traversal = registry.create("traversals", "stream")
    for j, spec in enumerate(args.scenes):
        scene = load_scene(spec)
        bvh = scene.bvh()
        work = workload(scene, "diffuse", width=args.size, height=args.size, seed=args.seed)
        traces = [Trace(name, order, offsets, traversal, bvh, work)
                  for name, (order, offsets) in orders_of(work, bvh, np.random.default_rng(j))
                  .items()]
        run_rounds(traces, args.rounds, seed=j)
        base = traces[0]
        rows = []
        print(f"\n{scene.name}: {len(work)} first-bounce diffuse rays")
        print(f"{'order':56s}{'sub-packets':>12s}{'trace ms':>24s}{'ratio to none':>24s}"
              f"{'SIMD N_B':>10s}  same counters")
        for t in traces:
            ms = np.asarray(t.seconds[-args.rounds:]) * 1e3
            ratio = ms / (np.asarray(base.seconds[-args.rounds:]) * 1e3)
            hits_equal = same(t.out, base.out)
            failed |= not hits_equal
            s, r = summary(ms), summary(ratio)
            rows.append({"order": t.name, "sub_packets": len(t.offsets) - 1, "ms": s,
                         "ratio": r, "identical_hits": hits_equal,
                         "same_counters": t.counters == base.counters,
                         "box4": t.counters.box4, "tri4": t.counters.tri4})
            print(f"{t.name:56s}{len(t.offsets) - 1:12d}"
                  f"{s['median']:10.2f} [{s['min']:.2f}, {s['max']:.2f}]"
                  f"{r['median']:10.3f} [{r['min']:.3f}, {r['max']:.3f}]"
                  f"{t.counters.box4 / base.counters.box4:10.4f}  "
                  f"{'yes' if t.counters == base.counters else 'no'}"
                  f"{'' if hits_equal else '  HITS DIFFER'}")
        c = base.counters
        print(f"none's counters: SIMD N_B {c.box4}, SIMD N_T {c.tri4}, "
              f"stream rays {c.stream_rays}")
        report["scenes"][scene.name] = {"rays": len(work), "rows": rows}
        sys.stdout.flush()
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=1)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
