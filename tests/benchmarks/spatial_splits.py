"""What spatial splits (SBVH) buy: build time, SAH cost, references and speed.

    python tests/benchmarks/spatial_splits.py [scene ...] [--budgets 0,0.1,0.3,1]
                                              [--alpha A] [--traversals wide8,wide]
                                              [--kinds diffuse,camera,frame]
                                              [--sorter nah] [--spp 4] [--rounds 7]
                                              [--size 256] [--json out.json]

For each scene (default: sibenik, sponza, forest) and each ``spatial_splits`` reference
budget (0: no spatial splits, the baseline), with ``split_alpha`` ``--alpha`` (default:
the BVH's), the BVH is built ``--build-rounds`` times in interleaved rounds (the thread's
CPU time, median [min, max]) and its SAH cost (binary, ``BVH.stats``; wide8,
``Wide8.sah_cost``) and reference count are reported. Then, for every budget x traversal
(sorter ``--sorter``, default ``nah``; one thread, checks off), ``diffuse`` traces the
first-bounce diffuse rays of a ``--size`` square render at 1 spp
(:func:`raysort.workloads.workload`) through ``Pipeline.trace``, ``camera`` its primary
rays (:func:`raysort.workloads.camera_rays`, 32x32 tiles), and ``frame`` renders a
``--size`` square frame at ``--spp`` (4) spp (lambert, depth 2) with ``Pipeline.render``
(with the framework's share of its CPU, every stage but ``traverse``); each in
interleaved rounds shuffled per round after an untimed warm-up round
(:func:`raysort.bench.rounds.run_rounds`), timed by the thread's CPU clock. Reported:
Mrays/s (Mpixels/s) median [min, max] and the median [min, max] of the per-round speed
ratios over the first budget with the same traversal. Every configuration's hits (t bit
for bit, prim) or image must equal the first one's, or the run fails. The header names the
CPU, the ISA and the load average.
"""
import argparse
import json
import sys
import time


import raysort
from raysort import isa
from raysort.bench.report import load_average, machine_info
from raysort.bench.rounds import ratios, run_rounds, summary
from raysort.bvh import BVH
from raysort.scene import load_scene
from raysort.workloads import camera_rays, workload


KIND_LABELS = {"diffuse": "first-bounce diffuse rays", "camera": "primary rays",
               "frame": "pixels"}


def _floats(text):
    return [float(x) for x in text.split(",")]


def _names(text):
    return [x for x in text.split(",") if x]


def timed(fn):
    """``fn``'s thread CPU time, in seconds."""
    start = time.thread_time()
    fn()
    return time.thread_time() - start


def measure_builds(scene, budgets, alpha, rounds):
    """Build time (interleaved rounds), SAH and references per budget."""
    def build(b):
        return BVH(scene.vertices, scene.faces, spatial_splits=b, split_alpha=alpha)

    seconds, _ = run_rounds([lambda b=b: timed(lambda: build(b)) for b in budgets], rounds)
    rows = []
    for k, b in enumerate(budgets):
        bvh = build(b)
        wide8 = bvh.wide8
        stats = bvh.stats()
        rows.append({"budget": b, "build_s": summary([r[k] for r in seconds]),
                     "wide8_collapse_s": wide8.build_seconds, "references": stats["references"],
                     "triangles": stats["triangles"], "sah_binary": stats["sah_cost"],
                     "sah_wide8": wide8.sah_cost, "depth": stats["depth"]})
    return rows


def measure_speeds(scene, kind, budgets, alpha, traversals, rounds, size, sorter="nah", spp=4):
    """Speed per (budget, traversal), and its ratios over budget 0 per round: ``diffuse``
    (``camera``) traces the same first-bounce diffuse (primary) rays (Mrays/s; every
    configuration's hits must agree), ``frame`` renders a frame, ``spp`` spp, lambert depth
    2 (Mpixels/s, and the framework's share of the frame's CPU: every stage but
    ``traverse``; every image must agree)."""
    configs = [(b, t) for t in traversals for b in budgets]
    pipes = [raysort.Pipeline(scene, sorter=sorter, traversal=t, threads=1, check_plugins=False,
                              bvh={"spatial_splits": b, "split_alpha": alpha})
             for b, t in configs]
    results = [None] * len(configs)
    shares = [[] for _ in configs]
    if kind == "frame":
        n = size * size

        def result(k):
            frame = pipes[k].render(size, size, spp=spp, seed=0)
            cpu = frame.stats.stage_seconds
            shares[k].append(1 - cpu["traverse"] / sum(cpu.values()))
            return frame.image.tobytes()
    else:
        work = camera_rays(scene, width=size, height=size, spp=1, seed=1, tile=32)[0] \
            if kind == "camera" else \
            workload(scene, "diffuse:depth=1", width=size, height=size, spp=1, seed=1, tile=32)
        n = len(work.rays)

        def result(k):
            hits = pipes[k].trace(work.rays, work.packets)[0]
            return hits.prim.tobytes() + hits.t.tobytes()

    def run(k):
        def go():
            results[k] = result(k)
        return timed(go)

    seconds, _ = run_rounds([lambda k=k: run(k) for k in range(len(configs))], rounds)
    for (b, t), r in zip(configs, results):
        if r != results[0]:
            sys.exit(f"spatial_splits={b} with {t}: the {'image' if kind == 'frame' else 'hits'}"
                     f" differ from the first configuration's")
    rows = []
    for k, (b, t) in enumerate(configs):
        base = configs.index((budgets[0], t))
        speeds = [n / r[k] / 1e6 for r in seconds]
        rows.append({"kind": kind, "budget": b, "traversal": t, "rays": n,
                     "mrays_s": summary(speeds),
                     "vs_first_budget": summary(ratios(seconds, k, base))})
        if kind == "frame":
            rows[-1]["framework_share"] = summary(shares[k][-rounds:])
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=["sibenik", "sponza", "forest"])
    ap.add_argument("--budgets", type=_floats, default=[0.0, 0.1, 0.3, 1.0])
    ap.add_argument("--alpha", type=float, default=None,
                    help="split_alpha (default: the BVH default)")
    ap.add_argument("--traversals", type=_names, default=["wide8", "wide"])
    ap.add_argument("--kinds", type=_names, default=["diffuse"],
                    help="diffuse (first-bounce rays, Mrays/s), camera (primary rays, "
                         "Mrays/s), frame (Mpixels/s)")
    ap.add_argument("--sorter", default="nah", help="the pipelines' sorter (nah)")
    ap.add_argument("--spp", type=int, default=4, help="samples per pixel of frames (4)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--build-rounds", type=int, default=3)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    args.alpha = BVH.check_parameters(split_alpha=args.alpha)["split_alpha"]
    info = machine_info()
    print(f"CPU: {info['cpu']}; ISA: {isa.active()}; load average {load_average()}; one "
          f"thread; sorter {args.sorter}; split_alpha {args.alpha}; {args.rounds} interleaved "
          f"rounds after a warm-up; thread CPU time; median [min, max]")
    results = []
    for name in args.scenes:
        scene = load_scene(name)
        builds = measure_builds(scene, args.budgets, args.alpha, args.build_rounds)
        speeds = [row for kind in args.kinds
                  for row in measure_speeds(scene, kind, args.budgets, args.alpha,
                                            args.traversals, args.rounds, args.size,
                                            args.sorter, args.spp)]
        columns = [(kind, t) for kind in args.kinds for t in args.traversals]
        print(f"\n### {name} ({len(scene.faces)} triangles; " + "; ".join(
            f"{kind}: {next(r['rays'] for r in speeds if r['kind'] == kind)} "
            f"{KIND_LABELS[kind]}"
            for kind in args.kinds) + ")\n")
        print("| spatial_splits | build s | references | SAH binary | SAH wide8 |" + "".join(
            f" {t} {kind} {'Mpixels/s' if kind == 'frame' else 'Mrays/s'} | vs "
            f"{args.budgets[0]:g} |" for kind, t in columns))
        print("|---|---|---|---|---|" + "---|---|" * len(columns))
        for b_row in builds:
            b = b_row["budget"]
            s = b_row["build_s"]
            cells = [f"{b:g}", f"{s['median']:.3f} [{s['min']:.3f}, {s['max']:.3f}]",
                     f"{b_row['references']} ({b_row['references'] / b_row['triangles']:.3f}x)",
                     f"{b_row['sah_binary']:.2f}", f"{b_row['sah_wide8']:.2f}"]
            for kind, t in columns:
                row = next(r for r in speeds
                           if r["kind"] == kind and r["budget"] == b and r["traversal"] == t)
                m, v = row["mrays_s"], row["vs_first_budget"]
                cells += [f"{m['median']:.3f} [{m['min']:.3f}, {m['max']:.3f}]",
                          f"{v['median']:.3f}x [{v['min']:.3f}, {v['max']:.3f}]"]
            print("| " + " | ".join(cells) + " |")
        for row in speeds:
            if "framework_share" in row:
                f = row["framework_share"]
                print(f"framework share of a frame (all but traverse), {row['traversal']}, "
                      f"spatial_splits {row['budget']:g}: {f['median']:.1%} [{f['min']:.1%}, "
                      f"{f['max']:.1%}]")
        sys.stdout.flush()
        results.append({"scene": name, "builds": builds, "speeds": speeds})
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"machine": info, "isa": isa.active(), "load": load_average(),
                       "args": vars(args), "results": results}, fh, indent=1)


if __name__ == "__main__":
    main()
