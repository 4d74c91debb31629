"""Markdown tables of saved ``raysort bench --json`` reports, as BENCHMARKS.md quotes them.

    python docs/bench_markdown.py docs/bench/frame.json [more.json ...]

Frame and kernel reports: one table per group (median seconds [min-max],
Mrays/s, speedup median [min-max] over the named baseline, the check, the
Table I counters per ray).  Reports with rows and columns (``--kernels``, the
matrix) also get the Mrays/s and speedup grids.  Nothing is re-measured.
"""
import json
import sys

import numpy as np

from raysort.bench import report
from raysort.bench.report import pivot
from raysort.stats import COUNTER_LABELS


def spread(s, fmt="{:.3f}"):
    return report.spread(s, fmt, dash="–")


def check(r):
    return report.check_label(r, differs="**DIFFERS**", inexact=" (max {:.2g})")


def table(group, kind):
    rows = group["configs"]
    unit = "s/frame" if kind == "frame" else "s/trace"
    counters = any(r["counters_available"] for r in rows)
    head = ["configuration", f"{unit} median [min–max]", "Mrays/s",
            f"speedup [min–max] over {rows[0]['baseline']}", "sort", "check"]
    if counters:
        head += list(COUNTER_LABELS.values())
    align = ["---"] + ["---:"] * 4 + ["---"] + ["---:"] * (len(head) - 6)
    out = ["| " + " | ".join(head) + " |", "| " + " | ".join(align) + " |"]
    for r in rows:
        share = f"{100 * r['sort_share']:.1f}%" if r["sort_share"] is not None else "n/a"
        cells = [r["label"], spread(r["seconds"], "{:.3f}" if kind == "frame" else "{:.4f}"),
                 f"{r['mrays_per_second']:.2f}",
                 spread(r["speedup"], "{:.2f}"), share, check(r)]
        if counters:
            cells += [f"{r['counters_per_ray'][k]:.2f}" if r["counters_available"] else "n/a"
                      for k in COUNTER_LABELS]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def grid(group, title, value, fmt):
    names, cols, values = pivot(group["configs"], value)
    out = [f"{title}:", "", "| | " + " | ".join(cols) + " |",
           "| --- " + "| ---: " * len(cols) + "|"]
    for name, line in zip(names, values):
        out.append(f"| {name} | " + " | ".join(fmt.format(v) if np.isfinite(v) else ""
                                             for v in line) + " |")
    return "\n".join(out)


def main(paths):
    for path in paths:
        with open(path, encoding="utf-8") as fh:
            rep = json.load(fh)
        s, m = rep["settings"], rep["machine"]
        print(f"<!-- {path}: {m['cpu']}, {m['cores']} cores, ISA {m['isa']}; load "
              f"{rep['load']['before']} before, {rep['load']['after']} after; "
              f"{s['repeat']} rounds; BVH {s['bvh'] or 'default'} -->\n")
        for name, g in rep["groups"].items():
            b = g["bvh"]
            print(f"**{name}** ({g['triangles']:,} triangles; {b['leaves']:,} leaves, "
                  f"{b['mean_leaf_size']:.1f} triangles per leaf)\n")
            print(table(g, rep["kind"]) + "\n")
            for c in g.get("comparisons", []):
                print(f"* {c['label']} over {c['over']}: "
                      f"{spread(c['speedup'], '{:.2f}')}x (median of per-round ratios)")
            if g.get("comparisons"):
                print()
            if any(r["row"] for r in g["configs"]):
                print(grid(g, "Mrays/s (median)", lambda r: r["mrays_per_second"], "{:.2f}")
                      + "\n")
                print(grid(g, "speedup over its baseline (median of per-round ratios)",
                           lambda r: r["speedup"]["median"], "{:.2f}") + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
