"""The ``raysort bench`` command line (added to ``raysort``'s parser by raysort.cli)."""
from __future__ import annotations

from raysort.argtypes import non_negative, positive, seed, size
from raysort.bench.configs import load_table, select
from raysort.errors import ConfigError, OutputError
from raysort.scene import check_scene

__all__ = ["PAPER_SCENES", "add_parser", "cmd_bench"]

PAPER_SCENES = ("sibenik", "sponza", "forest")

DESCRIPTION = """\
The paper's experiment (Fig. 2 and Table I) on your machine: every configuration
renders the same frame once per round, in a seeded shuffled order, after an
untimed warm-up round; it prints median seconds per frame with their spread,
speedups as the median of per-round ratios, the image check and the Table I
counters.  --kernels times the traversal alone on the rays of a render
(every installed traversal, 8x8, 32x32 and nah packets).  Configurations come
from configs.toml (raysort/bench/), --configs FILE and --add."""


def _names(text):
    return [t.strip() for t in text.split(",") if t.strip()]


def add_parser(sub):
    b = sub.add_parser("bench", help="reproduce the paper's Fig. 2 and Table I",
                       description=DESCRIPTION)
    b.add_argument("scenes", nargs="*", help=f"scenes (default: {' '.join(PAPER_SCENES)})")
    b.add_argument("--size", type=size, default=None,
                   help="WIDTHxHEIGHT (256x256; --kernels: of the render the rays come from)")
    b.add_argument("--spp", type=positive, default=None,
                   help="samples per pixel (4; --kernels: 1)")
    b.add_argument("--depth", type=non_negative, default=2, help="diffuse bounces (2)")
    b.add_argument("--seed", type=seed, default=0, help="the frame's random seed (0)")
    b.add_argument("--threads", type=positive, default=1, help="render threads (1)")
    b.add_argument("--repeat", type=positive, default=3,
                   help="timed rounds, after one untimed warm-up round (3)")
    b.add_argument("--order-seed", type=seed, default=0,
                   help="seed of the per-round shuffled order of configurations (0)")
    b.add_argument("--no-warmup", dest="warmup", action="store_false",
                   help="skip the untimed warm-up round")
    b.add_argument("--paper", action="store_true",
                   help="the paper's settings: 1024x1024, 64 spp (takes long)")
    b.add_argument("--bvh", default=None, metavar="PRESET",
                   help="BVH build preset (default, manta) or parameters "
                        "'preset=manta,max_leaf=16', 'spatial_splits=0' (the plain tree)")
    b.add_argument("--sorters", type=_names, default=[],
                   help="installed sorters, comma separated, or 'all'; with --traversals "
                        "or --kernels: the matrix of sorters x traversals")
    b.add_argument("--traversals", type=_names, default=[],
                   help="installed traversals, comma separated, or 'all'")
    b.add_argument("--configs", action="append", default=[], metavar="FILE",
                   help="a TOML file of more configurations (the tables of configs.toml)")
    b.add_argument("--add", nargs=3, action="append", default=[],
                   metavar=("LABEL", "TRAVERSAL", "SORTER"),
                   help="one more configuration, e.g. --add 'ranged + morton' ranged morton")
    b.add_argument("--only", type=_names, default=[],
                   help="run only these configuration labels, comma separated")
    b.add_argument("--baseline", default=None, metavar="LABEL",
                   help="take every speedup over this configuration")
    b.add_argument("--kernels", action="store_true",
                   help="time the traversal alone on the rays of each --workloads kind")
    b.add_argument("--workloads", type=_names, default=None,
                   help="with --kernels: workload kinds, comma separated "
                        "(primary,diffuse; e.g. diffuse:depth=2, shadow)")
    b.add_argument("--list", action="store_true", help="list the configurations and stop")
    b.add_argument("--json", default=None, help="write the results as JSON (every round)")
    b.add_argument("--chart", default=None,
                   help="write a chart (.png, .pdf, .svg, ...: the extension names the "
                        "format): Fig. 2 style bars, or a heat map of the speedups for "
                        "--kernels and the matrix")
    b.add_argument("-q", "--quiet", action="store_true")
    b.set_defaults(func=cmd_bench)


def bvh_params(text):
    """``--bvh``: a preset name or ``key=value`` pairs, as a Pipeline ``bvh`` dict."""
    if text is None:
        return None
    if not text.strip():
        raise ConfigError("--bvh is empty: give a preset name or key=value pairs")
    from raysort.registry import parse_spec

    if "=" not in text:
        return {"preset": text}
    return {k: v for k, v in parse_spec("bvh:" + text).items() if k != "type"}


def add_bvh_argument(parser):
    """A benchmark script's ``--bvh``, as ``raysort bench``'s: parsed by :func:`bvh_params`
    into the BVH's build parameters (``{}`` by default: the BVH's defaults)."""
    parser.add_argument("--bvh", type=bvh_params, default={}, metavar="PRESET",
                        help="the BVH's build parameters, as raysort bench's --bvh (e.g. "
                             "spatial_splits=0 for the plain tree); default: the BVH's defaults")


def check_outputs(args):
    """The chart's format; ConfigError or OutputError now, before anything runs, for an
    output path that is empty, not writable, the other output or an input file."""
    from raysort import output

    outputs = [(f"--{k}", p) for k, p in (("json", args.json), ("chart", args.chart))
               if p is not None]
    for flag, path in outputs:
        try:
            output.check_writable(path)
        except OutputError as exc:
            raise OutputError(f"{flag}: {exc}") from None
    output.check_distinct([(flag, f"the {flag} file", path) for flag, path in outputs],
                          [("the --configs file", p) for p in args.configs]
                          + [("the scene file", p) for p in args.scenes])
    if args.chart is not None:
        from raysort.bench.report import chart_format

        return chart_format(args.chart)
    return None


def cmd_bench(args):
    from raysort import output
    from raysort.progress import Progress

    chart_fmt = check_outputs(args)
    table = load_table(args.configs, [tuple(a) for a in args.add])
    if args.kernels and not args.sorters:
        configs = table.kernel_configs(args.traversals)
    elif args.kernels:                   # the matrix of sorters x traversals, traversal only
        configs = table.frame_configs(args.sorters, args.traversals or ["all"])
    else:
        configs = table.frame_configs(args.sorters, args.traversals)
    if args.only:
        configs = select(configs, args.only)
    if args.baseline is not None:
        select(configs, [args.baseline])
        for c in configs:
            c.baseline = args.baseline
    if args.list:
        for c in configs:
            print(f"{c.label:28} traversal {c.traversal!s:28} sorter {c.sorter!s:36} "
                  f"over {c.baseline}")
        return 0
    bvh = bvh_params(args.bvh)
    if bvh:
        from raysort.bvh import BVH

        BVH.check_parameters(**bvh)          # a bad preset or parameter: an error now
    scenes = args.scenes or PAPER_SCENES
    for spec in scenes:         # every scene's name, before anything is read or timed
        check_scene(spec)
    progress = Progress("bench", enabled=not args.quiet)
    if args.kernels:
        from raysort.bench.kernels import run_kernels
        from raysort.workloads import check_kind

        width, height = args.size or (256, 256)
        kinds = args.workloads or table.kernels.get("workloads", ["primary"])
        for kind in kinds:      # every kind's name before any is timed
            check_kind(kind)
        report = run_kernels(scenes, configs, kinds,
                             width=width, height=height, spp=args.spp or 1, seed=args.seed,
                             repeat=args.repeat, order_seed=args.order_seed, bvh=bvh,
                             warmup=args.warmup, progress=progress)
    else:
        from raysort.bench.frame import run_frames

        if args.workloads:
            raise ConfigError("--workloads needs --kernels")
        width, height = (1024, 1024) if args.paper else (args.size or (256, 256))
        spp = 64 if args.paper else (args.spp or 4)
        report = run_frames(scenes, configs, table, width=width, height=height, spp=spp,
                            depth=args.depth, seed=args.seed, threads=args.threads,
                            repeat=args.repeat, order_seed=args.order_seed, bvh=bvh,
                            warmup=args.warmup, progress=progress)
    from raysort.bench.report import (
        SCHEMA,
        draw_chart,
        failures,
        format_report,
        write_chart,
    )

    report = {"schema": SCHEMA, **report}
    format_report(report)
    # the chart is drawn before anything is written: if it fails, no file is left
    chart = draw_chart(report, chart_fmt) if chart_fmt else None
    if args.json is not None:
        output.write_json(args.json, report)
        print(f"\nwrote {args.json}")
    if chart is not None:
        write_chart(report, args.chart, chart)
        print(f"wrote {args.chart}")
    return 1 if failures(report) else 0
