"""``raysort bench``: the paper's experiment (Fig. 2 and Table I) on your machine.

For each scene it renders the same frame (path tracer, Lambertian surfaces,
jittered samples, depth 2, no shadow rays, one seed) with several
(traversal, sorter) configurations:

========================  ==========  ==========================  =============
configuration             traversal   sorter                      paper column
========================  ==========  ==========================  =============
ranged (8x8)              ranged      none, 64-ray packets        Ranged w/o [2]
partition (32x32)         partition   none, 1024-ray packets      Partition w/o
ranged + nah              ranged      nah (32x32 large packets)   Ranged w/ (ours)
masked (8x8)              masked      none, 64-ray packets
masked + nah              masked      nah
partition + nah           partition   nah
single                    single      none
wide (+ nah)              wide        none / nah                  (beyond the paper)
========================  ==========  ==========================  =============

plus every other installed sorter or traversal named with ``--sorters`` /
``--traversals`` (e.g. ``morton``, or ``embree`` from raysort-embree, which is
added automatically when installed).  Every configuration must produce a
bit-identical image; timings are the best of ``--repeat`` interleaved runs.
It prints seconds per frame, Mrays/s, the speedup over the baseline and the
Table I counters per ray, and can write JSON and a Fig. 2 style bar chart.
"""
from __future__ import annotations

import os
import platform
import sys
from dataclasses import dataclass, field

import numpy as np

from raysort import registry
from raysort.errors import ConfigError
from raysort.pipeline import Pipeline
from raysort.scene import load_scene
from raysort.stats import COUNTER_LABELS

__all__ = ["Config", "default_configs", "run_bench", "add_parser"]

PAPER_SCENES = ("sibenik", "sponza", "forest")
#: the paper's Table I for Sibenik and its Fig. 2 speedup, for side-by-side reports
PAPER_SIBENIK = {
    "ranged (8x8)": {"ia": 7.72, "box1": 3.48, "box4": 2.22, "tri1": 30.28, "tri4": 60.75},
    "partition (32x32)": {"ia": 5.96, "box1": 0.00, "box4": 6.95, "tri1": 0.00, "tri4": 38.04},
    "ranged + nah": {"ia": 3.63, "box1": 2.69, "box4": 3.60, "tri1": 23.60, "tri4": 20.22},
}
PAPER_SPEEDUP = {"sibenik": 1.46}


@dataclass
class Config:
    """One (traversal, sorter) configuration of the experiment."""

    label: str
    traversal: object
    sorter: object

    def pipeline_args(self):
        return {"traversal": self.traversal, "sorter": self.sorter}


@dataclass
class Result:
    config: Config
    seconds: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    identical: bool = True
    exact: bool = True
    max_difference: float = 0.0

    @property
    def best(self):
        return min(self.seconds)


def default_configs(extra_sorters=(), extra_traversals=()):
    """The paper's three configurations first (the baseline is the first), then the rest."""
    configs = [
        Config("ranged (8x8)", "ranged", {"type": "none", "packet_size": 64}),
        Config("partition (32x32)", "partition", {"type": "none", "packet_size": 1024}),
        Config("ranged + nah", "ranged", "nah"),
        Config("masked (8x8)", "masked", {"type": "none", "packet_size": 64}),
        Config("masked + nah", "masked", "nah"),
        Config("partition + nah", "partition", "nah"),
        Config("single", "single", "none"),
        Config("wide", "wide", "none"),
        Config("wide + nah", "wide", "nah"),
        Config("wide8", "wide8", "none"),
        Config("wide8 + nah", "wide8", "nah"),
    ]
    known = {"none", "nah", "nah_numpy"}
    for sorter in extra_sorters:
        if sorter not in known:
            configs.append(Config(f"ranged + {sorter}", "ranged", sorter))
    for trav in extra_traversals:
        if trav not in {"single", "masked", "ranged", "partition", "wide", "wide8"}:
            configs.append(Config(trav, trav, "none"))
            configs.append(Config(f"{trav} + nah", trav, "nah"))
    return configs


def machine_info():
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    from raysort import isa
    import raysort

    return {"cpu": cpu, "cores": os.cpu_count(), "machine": platform.machine(),
            "python": platform.python_version(), "numpy": np.__version__,
            "raysort": raysort.__version__, "isa": isa.active(),
            "isas_compiled": isa.compiled(),
            "platform": platform.platform()}


def run_bench(scene_specs, *, width=256, height=256, spp=4, depth=2, seed=0, threads=1,
              repeat=1, configs=None, progress=None):
    """Run every configuration on every scene; returns a JSON-ready dict."""
    configs = configs or default_configs()
    shader = {"type": "lambert", "max_depth": depth, "shadow_rays": False}
    scenes = [load_scene(spec) for spec in scene_specs]
    total = len(scenes) * len(configs) * repeat
    done = 0
    report = {"machine": machine_info(), "settings": {
        "width": width, "height": height, "spp": spp, "depth": depth, "seed": seed,
        "threads": threads, "repeat": repeat, "shadow_rays": False}, "scenes": {}}
    for scene in scenes:
        scene.bvh()  # build once, outside the timings
        pipes = [Pipeline(scene, shader=shader, threads=threads, **c.pipeline_args())
                 for c in configs]
        results = [Result(c, exact=type(p.traversal).exact) for c, p in zip(configs, pipes)]
        reference = None
        for _ in range(repeat):                 # interleave configurations against drift
            for pipe, res in zip(pipes, results):
                out = pipe.render(width, height, spp, seed)
                if not res.seconds or out.stats.wall_seconds < res.best:
                    res.stats = out.stats       # report the stages of the fastest run
                res.seconds.append(out.stats.wall_seconds)
                if reference is None:
                    reference = out.image
                same = np.array_equal(out.image.view(np.uint32), reference.view(np.uint32))
                res.identical = res.identical and same
                res.max_difference = float(np.abs(out.image - reference).max())
                done += 1
                if progress:
                    progress(done, total)
        report["scenes"][scene.name] = _scene_report(scene, results)
    return report


def _scene_report(scene, results):
    base = results[0].best
    rows = []
    for res in results:
        st = res.stats
        counters = st.closest_hit_counters()
        rows.append({
            "label": res.config.label,
            "traversal": str(res.config.traversal), "sorter": str(res.config.sorter),
            "seconds": res.best, "all_seconds": res.seconds,
            "mrays_per_second": st.total_rays / res.best / 1e6,
            "speedup": base / res.best,
            "rays": st.total_rays,
            "identical_image": res.identical,
            "exact_traversal": res.exact,
            "max_image_difference": res.max_difference,
            "counters_available": counters.available,
            "counters_per_ray": counters.per_ray(),
            "stage_seconds": st.stage_seconds,
        })
    return {"triangles": scene.n_triangles, "configs": rows}


# --------------------------------------------------------------------------
# reporting
# --------------------------------------------------------------------------

def format_report(report, stream=None):
    stream = sys.stdout if stream is None else stream
    s = report["settings"]
    m = report["machine"]
    print(f"raysort bench: {s['width']}x{s['height']}, {s['spp']} spp, depth {s['depth']}, "
          f"no shadow rays, seed {s['seed']}, {s['threads']} thread(s), best of "
          f"{s['repeat']}", file=stream)
    print(f"machine: {m['cpu']} ({m['cores']} cores), ISA {m['isa']} (compiled "
          f"{', '.join(m['isas_compiled'])}), Python {m['python']}", file=stream)
    for name, scene in report["scenes"].items():
        rows = scene["configs"]
        print(f"\n{name} ({scene['triangles']:,} triangles)", file=stream)
        print(f"  {'configuration':22} {'s/frame':>9} {'Mrays/s':>9} {'speedup':>8}  image",
              file=stream)
        for r in rows:
            image = ("same" if r["identical_image"] else
                     "DIFFERS" if r["exact_traversal"] else
                     f"inexact traversal, max difference {r['max_image_difference']:.2g}")
            print(f"  {r['label']:22} {r['seconds']:9.3f} {r['mrays_per_second']:9.3f} "
                  f"{r['speedup']:7.2f}x  {image}", file=stream)
        print("\n  Table I (per ray)       " + "".join(f"{r['label'][:14]:>15}" for r in rows),
              file=stream)
        for key, label in COUNTER_LABELS.items():
            cells = "".join(f"{r['counters_per_ray'][key]:15.2f}" if r["counters_available"]
                            else f"{'n/a':>15}" for r in rows)
            print(f"  {label:22}{cells}", file=stream)
        if name == "sibenik":
            print("\n  paper (Sibenik, Table I):", file=stream)
            for label, vals in PAPER_SIBENIK.items():
                print(f"    {label:20}" + "".join(f"{COUNTER_LABELS[k]} {v:.2f}  "
                                               for k, v in vals.items()), file=stream)
            print(f"    paper speedup of ranged + sorting over ranged: "
                  f"{PAPER_SPEEDUP['sibenik']}x", file=stream)
    bad = [(n, r["label"]) for n, sc in report["scenes"].items() for r in sc["configs"]
           if r["exact_traversal"] and not r["identical_image"]]
    if bad:
        print(f"\nERROR: images differ from the baseline for {bad}", file=stream)


def write_chart(report, path):
    """A Fig. 2 style bar chart: seconds per frame per scene and configuration."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise ConfigError("the chart needs matplotlib: pip install 'raysort[bench]'") from None
    from raysort.output import atomic_target

    scenes = list(report["scenes"])
    labels = [r["label"] for r in report["scenes"][scenes[0]]["configs"]]
    width = 0.8 / len(labels)
    fig, ax = plt.subplots(figsize=(max(6, 2.2 * len(scenes) + 2), 4))
    for k, label in enumerate(labels):
        values = [next(r["seconds"] for r in report["scenes"][s]["configs"]
                       if r["label"] == label) for s in scenes]
        ax.bar(np.arange(len(scenes)) + k * width - 0.4 + width / 2, values, width,
               label=label)
    ax.set_xticks(np.arange(len(scenes)), scenes)
    ax.set_ylabel("seconds per frame (lower is better)")
    s = report["settings"]
    ax.set_title(f"raysort bench: {s['width']}x{s['height']}, {s['spp']} spp, depth "
                 f"{s['depth']}, {s['threads']} thread(s)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    plt.close(fig)


# --------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------

def add_parser(sub):
    from raysort.cli import _non_negative, _positive, _size

    b = sub.add_parser("bench", help="reproduce the paper's Fig. 2 and Table I",
                       description=__doc__.split("\n\n")[0].replace("``", ""))
    b.add_argument("scenes", nargs="*", help=f"scenes (default: {' '.join(PAPER_SCENES)})")
    b.add_argument("--size", type=_size, default=(256, 256), help="WIDTHxHEIGHT (256x256)")
    b.add_argument("--spp", type=_positive, default=4, help="samples per pixel (4)")
    b.add_argument("--depth", type=_non_negative, default=2, help="diffuse bounces (2)")
    b.add_argument("--seed", type=_non_negative, default=0)
    b.add_argument("--threads", type=_positive, default=1)
    b.add_argument("--repeat", type=_positive, default=1, help="best of N runs (1)")
    b.add_argument("--paper", action="store_true",
                   help="the paper's settings: 1024x1024, 64 spp (takes long)")
    b.add_argument("--sorters", default="", help="extra installed sorters, comma separated")
    b.add_argument("--traversals", default="", help="extra installed traversals, comma separated")
    b.add_argument("--only", default="", help="run only these configuration labels, "
                                              "comma separated (the first is the baseline)")
    b.add_argument("--json", default=None, help="write the results as JSON")
    b.add_argument("--chart", default=None, help="write a Fig. 2 style bar chart (PNG)")
    b.add_argument("-q", "--quiet", action="store_true")
    b.set_defaults(func=cmd_bench)


def cmd_bench(args):
    from raysort import output
    from raysort.progress import Progress

    for path in (args.json, args.chart):
        if path:
            output.check_writable(path)
    width, height = (1024, 1024) if args.paper else args.size
    spp = 64 if args.paper else args.spp
    extra_s = [s for s in args.sorters.split(",") if s]
    extra_t = [t for t in args.traversals.split(",") if t]
    if "embree" in registry.available("traversals") and "embree" not in extra_t:
        extra_t.append("embree")
    for kind, names in (("sorters", extra_s), ("traversals", extra_t)):
        for name in names:
            registry.load(kind, name)      # unknown or broken: a clear error now
    configs = default_configs(extra_s, extra_t)
    if args.only:
        wanted = [w.strip() for w in args.only.split(",")]
        by_label = {c.label: c for c in configs}
        missing = [w for w in wanted if w not in by_label]
        if missing:
            raise ConfigError(f"unknown configuration {missing[0]!r}; known: "
                              f"{', '.join(by_label)}")
        configs = [by_label[w] for w in wanted]
    report = run_bench(args.scenes or PAPER_SCENES, width=width, height=height, spp=spp,
                       depth=args.depth, seed=args.seed, threads=args.threads,
                       repeat=args.repeat, configs=configs,
                       progress=Progress("bench", enabled=not args.quiet))
    format_report(report)
    if args.json:
        output.write_json(args.json, report)
        print(f"\nwrote {args.json}")
    if args.chart:
        write_chart(report, args.chart)
        print(f"wrote {args.chart}")
    return 0 if all(r["identical_image"] or not r["exact_traversal"]
                    for sc in report["scenes"].values() for r in sc["configs"]) else 1
