"""What ``raysort bench`` reports: the JSON record, the text tables and the charts.

A report is a dict (written as JSON as it is) with ``machine``, ``load``,
``settings`` and ``groups``: one group per scene (frames) or per scene and
workload (kernels), each with the orders its rounds ran in and one row per
configuration holding every round's seconds, their median and spread, the
per-round speedups over the configuration's baseline and their median and
spread, the image or hit check, the Table I counters and the stage times.
"""
from __future__ import annotations

import io
import os
import platform
import sys

import numpy as np

from raysort.bench.rounds import ratios, summary
from raysort.bvh import BVH
from raysort.errors import ConfigError
from raysort.output import shown
from raysort.stats import COUNTER_LABELS

__all__ = ["SCHEMA", "bvh_settings", "chart_format", "draw_chart", "failures", "format_report",
           "group_report", "load_average", "machine_info", "numpy_simd", "write_chart"]

#: the JSON layout's name and version, written into every report
SCHEMA = "raysort-bench/2"
#: the paper's Table I (Sibenik) and Fig. 2 speedup, by the paper's column name
PAPER_SIBENIK = {
    "Ranged w/o sorting [2]": {"ia": 7.72, "box1": 3.48, "box4": 2.22, "tri1": 30.28,
                               "tri4": 60.75},
    "Partition w/o sorting [7]": {"ia": 5.96, "box1": 0.00, "box4": 6.95, "tri1": 0.00,
                                  "tri4": 38.04},
    "Ranged w/ sorting (ours)": {"ia": 3.63, "box1": 2.69, "box4": 3.60, "tri1": 23.60,
                                 "tri4": 20.22},
}
SORT_STAGES = ("sort", "gather")


def numpy_simd(features=None):
    """The widest x86 SIMD level NumPy's own kernels (its sorts, which the key sorters
    call, among them) run here: ``"avx512"``, ``"avx2"`` or ``"baseline"``, as the CPU
    and ``NPY_DISABLE_CPU_FEATURES`` leave them (NumPy's run-time ``features``; None
    where NumPy does not say).  It can differ from raysort's ISA: ``RAYSORT_ISA=avx2``
    on an AVX-512 CPU leaves NumPy's AVX-512 sort in place."""
    if features is None:
        try:
            from numpy._core._multiarray_umath import __cpu_features__ as features
        except ImportError:         # NumPy 1.x
            try:
                from numpy.core._multiarray_umath import __cpu_features__ as features
            except ImportError:
                return None
    # NumPy 2.4 groups the x86 levels (X86_V3, X86_V4); earlier releases name them
    levels = (("avx512", "X86_V4"), ("avx2", "X86_V3")) if "X86_V4" in features else \
        (("avx512", "AVX512_SKX"), ("avx2", "AVX2"))
    if not any(name in features for _, name in levels):
        return None                 # not an x86 build of NumPy
    return next((level for level, name in levels if features.get(name)), "baseline")


def machine_info():
    """CPU, cores, ISA and versions, for the report's header."""
    import raysort
    from raysort import isa

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next((line.split(":", 1)[1].strip() for line in fh
                        if line.startswith("model name")), cpu)
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "machine": platform.machine(),
            "python": platform.python_version(), "numpy": np.__version__,
            "raysort": raysort.__version__, "isa": isa.active(), "numpy_simd": numpy_simd(),
            "isas_compiled": list(isa.compiled()), "platform": platform.platform()}


def load_average():
    """The 1, 5 and 15 minute load averages (None where the OS has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        return None


def group_report(configs, seconds, orders, rows, compare=()):
    """One group's JSON: ``seconds[r][k]`` from :func:`raysort.bench.rounds.run_rounds`,
    ``rows[k]`` what configuration ``k`` measured besides time (``rays``, ``counters``
    (a Counters), ``stage_seconds`` (one dict per round), checks).  ``compare``: more
    ``(label, over label)`` pairs whose per-round speedups are reported too."""
    labels = [c.label for c in configs]
    comparisons = []
    for a, b in compare:
        if a in labels and b in labels:
            r = ratios(seconds, labels.index(a), labels.index(b))
            comparisons.append({"label": a, "over": b, "speedup_rounds": r,
                                "speedup": summary(r)})
    out = []
    for k, (c, row) in enumerate(zip(configs, rows)):
        base = labels.index(c.baseline) if c.baseline in labels else 0
        times = [r[k] for r in seconds]
        speedups = ratios(seconds, k, base)
        med = summary(times)
        stages = {name: float(np.median([st.get(name, 0.0) for st in row["stage_seconds"]]))
                  for name in row["stage_seconds"][0]} if row.get("stage_seconds") else {}
        counters = row.get("counters")
        entry = {
            **c.as_dict(), "baseline": labels[base], "row": c.row, "column": c.column,
            "rounds": times, "seconds": med,
            "mrays_per_second": row["rays"] / med["median"] / 1e6 if med["median"] else None,
            "speedup_rounds": speedups, "speedup": summary(speedups),
            "rays": row["rays"],
            "exact_traversal": row["exact_traversal"],
            "identical_image": row.get("identical_image"),
            "identical_hits": row.get("identical_hits"),
            "max_image_difference": row.get("max_image_difference"),
            "counters_available": bool(counters is not None and counters.available),
            "counters_per_ray": counters.per_ray() if counters is not None else None,
            "stage_seconds": stages,
        }
        if "sort_seconds" in row:
            entry["sort_seconds"] = summary(row["sort_seconds"])
        sort = (entry["sort_seconds"]["median"] if "sort_seconds" in entry
                else sum(stages.get(s, 0.0) for s in SORT_STAGES))
        trav = stages.get("traverse") or (med["median"] if "sort_seconds" in entry else 0.0)
        entry["sort_share"] = sort / trav if trav else None
        out.append(entry)
    return {"orders": [[labels[k] for k in order] for order in orders], "configs": out,
            "comparisons": comparisons}


def failures(report):
    """(group, label) of every exact configuration whose image or hits differ."""
    return [(name, r["label"]) for name, g in report["groups"].items() for r in g["configs"]
            if r["exact_traversal"] and (r["identical_image"] is False
                                         or r["identical_hits"] is False)]


# --------------------------------------------------------------------------
# text
# --------------------------------------------------------------------------

def spread(s, fmt="{:.3f}", dash="-"):
    """``median [min-max]`` of a summary (the Markdown tables use an en dash)."""
    return f"{fmt.format(s['median'])} [{fmt.format(s['min'])}{dash}{fmt.format(s['max'])}]"


def check_label(r, differs="DIFFERS", inexact=", max diff {:.2g}"):
    """``same``, ``DIFFERS`` (an exact configuration that did not match) or ``inexact``."""
    same = r["identical_image"] if r["identical_image"] is not None else r["identical_hits"]
    if same:
        return "same"
    if r["exact_traversal"]:
        return differs
    diff = r.get("max_image_difference")
    return "inexact" + (inexact.format(diff) if diff is not None else "")


def bvh_settings(bvh):
    """A report's settings for the BVH: the ``--bvh`` given (``bvh``) and the build
    parameters it resolves to (the defaults included, which change between versions)."""
    return {"bvh": dict(bvh or {}), "bvh_params": BVH.check_parameters(**(bvh or {}))}


def format_report(report, stream=None):
    """Print the report's tables."""
    stream = sys.stdout if stream is None else stream
    s, m = report["settings"], report["machine"]

    def say(text=""):
        print(shown(text), file=stream)

    what = (f"{s['width']}x{s['height']}, {s['spp']} spp, depth {s['depth']}, seed {s['seed']}"
            if report["kind"] == "frame" else
            f"traversal only, rays of a {s['width']}x{s['height']}, {s['spp']} spp render")
    built = s.get("bvh_params")         # (absent from reports of older versions)
    tree = f"BVH {s['bvh'] or 'default'}" + (
        f" ({', '.join(f'{k} {v:g}' for k, v in built.items())})" if built else "")
    say(f"raysort bench: {what}, {s['threads']} thread(s), {tree}; "
        f"{s['repeat']} timed rounds{' after a warm-up round' if s['warmup'] else ''}, "
        f"order shuffled per round (seed {s['order_seed']}); median [min-max]")
    load = report["load"]
    simd = f", NumPy's SIMD {m['numpy_simd']}" if m.get("numpy_simd") else ""
    say(f"machine: {m['cpu']} ({m['cores']} cores), ISA {m['isa']} (compiled "
        f"{', '.join(m['isas_compiled'])}){simd}, Python {m['python']}; load average "
        f"{load.get('before')} before, {load.get('after')} after")
    for name, g in report["groups"].items():
        rows = g["configs"]
        b = g.get("bvh")
        leaves = (f"; BVH {b['leaves']:,} leaves, {b['mean_leaf_size']:.1f} triangles per leaf"
                  if b else "")
        say(f"\n{name} ({g['triangles']:,} triangles{leaves})")
        width = max(22, max(len(r["label"]) for r in rows))
        unit = "s/frame" if report["kind"] == "frame" else "s/trace"
        say(f"  {'configuration':{width}} {unit + ' [min-max]':>23} {'Mrays/s':>8} "
            f"{'speedup [min-max]':>20} {'over':>{min(width, 18)}} {'sort':>6}  check")
        for r in rows:
            share = f"{100 * r['sort_share']:5.1f}%" if r["sort_share"] is not None else "   n/a"
            say(f"  {r['label']:{width}} {spread(r['seconds'], '{:.3f}'):>23} "
                f"{r['mrays_per_second']:8.2f} {spread(r['speedup'], '{:.2f}'):>20} "
                f"{r['baseline'][:18]:>{min(width, 18)}} {share}  {check_label(r)}")
        for c in g.get("comparisons", []):
            say(f"  {c['label']} over {c['over']}: {spread(c['speedup'], '{:.2f}')}x "
                f"(median of per-round ratios)")
        _format_counters(rows, say)
        if any(r["row"] for r in rows):
            _format_pivot(rows, say)
        papered = [r for r in rows if r.get("paper") in PAPER_SIBENIK]
        if g.get("scene") == "sibenik" and papered:
            say("\n  next to the paper's Table I (Sibenik):")
            for r in papered:
                paper = PAPER_SIBENIK[r["paper"]]
                ours = r["counters_per_ray"] or {}
                say(f"    {r['paper']:28}" + "".join(
                    f"{COUNTER_LABELS[k]} {v:5.2f} (ours {ours.get(k) or 0:5.2f})  "
                    for k, v in paper.items()))
    bad = failures(report)
    if bad:
        say(f"\nERROR: exact configurations differ from the reference: {bad}")


def _format_counters(rows, say):
    if not any(r["counters_available"] for r in rows):
        return
    say("\n  Table I (per ray)      " + "".join(f"{r['label'][:14]:>15}" for r in rows))
    for key, label in COUNTER_LABELS.items():
        cells = "".join(f"{r['counters_per_ray'][key]:15.2f}" if r["counters_available"]
                        else f"{'n/a':>15}" for r in rows)
        say(f"  {label:22}{cells}")


def pivot(rows, value):
    """``(row names, column names, values[i][j])`` of configurations with a row and a
    column (kernels, matrix); ``value(r)`` picks the number, NaN where none."""
    names = list(dict.fromkeys(r["row"] for r in rows if r["row"]))
    cols = list(dict.fromkeys(r["column"] for r in rows if r["column"]))
    grid = np.full((len(names), len(cols)), np.nan)
    for r in rows:
        if r["row"]:
            grid[names.index(r["row"]), cols.index(r["column"])] = value(r)
    return names, cols, grid


def _format_pivot(rows, say):
    for title, value in (("Mrays/s (median)", lambda r: r["mrays_per_second"]),
                         ("speedup over its baseline (median of per-round ratios)",
                          lambda r: r["speedup"]["median"])):
        names, cols, grid = pivot(rows, value)
        say(f"\n  {title}")
        say(f"  {'':16}" + "".join(f"{c[:12]:>13}" for c in cols))
        for name, line in zip(names, grid):
            say(f"  {name[:16]:16}" + "".join(f"{v:13.2f}" if np.isfinite(v) else f"{'':13}"
                                              for v in line))


# --------------------------------------------------------------------------
# charts
# --------------------------------------------------------------------------

def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise ConfigError("the chart needs matplotlib: pip install 'raysort[bench]'") from None
    return plt


def chart_format(path):
    """The file format a chart at ``path`` is written in, by its extension (png, pdf,
    svg, ...); ConfigError now if matplotlib is missing or does not write that format."""
    _pyplot()
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    formats = set(FigureCanvasAgg.get_supported_filetypes()) - {"pgf"}   # pgf needs LaTeX
    fmt = os.path.splitext(os.fspath(path))[1][1:].lower()
    if fmt not in formats:
        raise ConfigError(f"--chart {os.fspath(path)!r}: the extension names the format, one "
                          f"of .{', .'.join(sorted(formats))} (e.g. .png, .pdf or .svg)")
    return fmt


def draw_chart(report, fmt="png"):
    """The chart as the bytes of a ``fmt`` file: a Fig. 2 style bar chart (median
    seconds, min-max whiskers) per group; for a matrix or kernels report, a heat map
    of the speedups per group instead.  Text is drawn as it is (no math mode)."""
    plt = _pyplot()
    groups = list(report["groups"])
    out = io.BytesIO()
    with plt.rc_context({"text.parse_math": False, "text.usetex": False}):
        if any(r["row"] for g in report["groups"].values() for r in g["configs"]):
            fig = _heat_maps(plt, report, groups)
        else:
            fig = _bars(plt, report, groups)
        try:
            fig.savefig(out, format=fmt, dpi=120)
        finally:
            plt.close(fig)
    return out.getvalue()


def write_chart(report, path, data=None):
    """Write the chart to ``path`` in the format its extension names, whole or not at
    all; ``data``: the chart already drawn (:func:`draw_chart`)."""
    from raysort.output import atomic_target

    if data is None:
        data = draw_chart(report, chart_format(path))
    with atomic_target(path) as tmp, open(tmp, "wb") as fh:
        fh.write(data)


def _bars(plt, report, groups):
    labels = [r["label"] for r in report["groups"][groups[0]]["configs"]]
    width = 0.8 / len(labels)
    fig, ax = plt.subplots(figsize=(max(6, 2.2 * len(groups) + 2), 4))
    for k, label in enumerate(labels):
        rows = [next(r for r in report["groups"][g]["configs"] if r["label"] == label)
                for g in groups]
        med = np.array([r["seconds"]["median"] for r in rows])
        err = np.array([[m - r["seconds"]["min"], r["seconds"]["max"] - m]
                        for m, r in zip(med, rows)]).T
        ax.bar(np.arange(len(groups)) + k * width - 0.4 + width / 2, med, width,
               yerr=err, capsize=2, label=shown(label), color=plt.cm.tab20(k % 20))
    ax.set_xticks(np.arange(len(groups)), [shown(g) for g in groups])
    ax.set_ylabel("seconds per frame, median (lower is better)")
    s = report["settings"]
    ax.set_title(f"raysort bench: {s['width']}x{s['height']}, {s['spp']} spp, depth "
                 f"{s['depth']}, {s['threads']} thread(s), {s['repeat']} rounds", fontsize=9)
    ax.legend(fontsize=6)
    fig.tight_layout()
    return fig


def _heat_maps(plt, report, groups):
    fig, axes = plt.subplots(len(groups), 1, squeeze=False,
                             figsize=(8, 2.2 + 2.4 * len(groups)))
    for ax, name in zip(axes[:, 0], groups):
        names, cols, grid = pivot(report["groups"][name]["configs"],
                                  lambda r: r["speedup"]["median"])
        im = ax.imshow(grid, cmap="RdYlGn", vmin=min(0.5, np.nanmin(grid)),
                       vmax=max(1.5, np.nanmax(grid)))
        ax.set_xticks(range(len(cols)), [shown(c) for c in cols], rotation=30, fontsize=7)
        ax.set_yticks(range(len(names)), [shown(n) for n in names], fontsize=7)
        for i in range(len(names)):
            for j in range(len(cols)):
                if np.isfinite(grid[i, j]):
                    ax.text(j, i, f"{grid[i, j]:.2f}", ha="center", va="center", fontsize=6)
        ax.set_title(f"{shown(name)}: speedup over baseline (median of rounds)", fontsize=8)
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    return fig
