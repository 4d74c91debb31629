"""The ``raysort`` command: render, bench, plugins, scenes.

Errors a user can cause (bad scene, unknown plugin, unwritable output, ...)
are printed as one line ``raysort: error: ...`` with exit status 2, never as a
traceback; output files are written whole or not at all.
"""
from __future__ import annotations

import argparse
import os
import sys

from raysort.argtypes import SCHEDULER_HELP
from raysort.argtypes import non_negative as _non_negative
from raysort.argtypes import positive as _positive
from raysort.argtypes import seed as _seed
from raysort.argtypes import size as _size
from raysort.errors import ConfigError, RaysortError
from raysort.output import shown

__all__ = ["main"]


MAX_EXPOSURE = 64   # stops: 2**64 brightens the darkest float32 value past 1


def _exposure(text):
    """An argparse type: an exposure in stops, finite and within +-MAX_EXPOSURE."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of stops, got {text!r}") from None
    if not -MAX_EXPOSURE <= value <= MAX_EXPOSURE:     # false for nan too
        raise argparse.ArgumentTypeError(
            f"expected stops in [-{MAX_EXPOSURE}, {MAX_EXPOSURE}], got {text!r}")
    return value


def _aov_names(text):
    """An argparse type: comma-separated AOV layer names."""
    from raysort.aov import parse_names

    try:
        return parse_names(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


# --------------------------------------------------------------------------
# render
# --------------------------------------------------------------------------

# Shader-spec shorthands: a flag sets a shader parameter of this name, for any shader
# that declares it (`--depth 3` is `--shader NAME:max_depth=3`).
SHADER_SHORTHANDS = (("depth", "--depth", "max_depth"),
                     ("shadow_rays", "--shadow-rays", "shadow_rays"))


def _shader_config(args):
    from raysort.registry import load, parse_spec

    config = parse_spec(args.shader)
    given = [(flag, param, getattr(args, attr)) for attr, flag, param in SHADER_SHORTHANDS
             if getattr(args, attr) is not None]
    if given:
        accepted = load("shaders", config["type"]).parameter_names()
    for flag, param, value in given:
        if param not in accepted:
            raise ConfigError(
                f"{flag} sets the shader parameter {param!r}, which shader "
                f"{config['type']!r} does not declare (it takes: "
                f"{', '.join(accepted) or 'no parameters'})")
        config[param] = (value == "on") if param == "shadow_rays" else value
    return config


def _print_summary(result, out, stats_table, stream=None, created=()):
    from raysort.stats import COUNTER_LABELS

    stream = sys.stdout if stream is None else stream
    st, s = result.stats, result.settings
    print(f"rendered {s['scene']} {s['width']}x{s['height']}, {s['spp']} spp with "
          f"{s['sorter']} + {s['traversal']} in {st.wall_seconds:.2f} s "
          f"({st.threads} thread{'s' if st.threads > 1 else ''})", file=stream)
    per_depth = "  ".join(f"depth {d}: {n:,}" for d, n in sorted(st.rays.items()))
    print(f"  rays: {per_depth}  shadow: {st.shadow_rays:,}  total: {st.total_rays:,}",
          file=stream)
    print(f"  throughput: {st.mrays_per_second:.3f} Mrays/s", file=stream)
    stages = "  ".join(f"{k} {v:.2f}" for k, v in st.stage_seconds.items() if v > 0)
    print(f"  stage CPU seconds (summed over threads): {stages}", file=stream)
    if stats_table:
        total = st.closest_hit_counters()
        if not total.available:
            print("  counters: not available for this traversal", file=stream)
        else:
            print("  work per ray (Table I):", file=stream)
            header = "    " + "depth".ljust(8) + "".join(f"{v:>12}" for v in
                                                         COUNTER_LABELS.values())
            print(header, file=stream)
            rows = [(str(d), c) for d, c in sorted(st.counters.items())] + [("all", total)]
            if st.shadow_rays:
                rows.append(("shadow", st.shadow_counters))
            for label, c in rows:
                per = c.per_ray()
                print("    " + label.ljust(8) + "".join(f"{per[k]:12.2f}" for k in
                                                        COUNTER_LABELS), file=stream)
    if out:
        layers = f" (AOV layers: {', '.join(result.aov)})" if result.aov else ""
        made = "".join(f" (created directory {shown(d)})" for d in created)
        png = os.path.splitext(out)[0] + ".png"
        print(f"  wrote {shown(out)}{layers} and {shown(png)}{made}", file=stream)


def cmd_render(args):
    from raysort import output
    from raysort.pipeline import Pipeline
    from raysort.progress import Progress

    out = args.output
    if os.path.splitext(out)[1].lower() != ".exr":
        raise ConfigError(f"the output must be an .exr file (a .png preview is written next "
                          f"to it), got {out!r}")
    png = os.path.splitext(out)[0] + ".png"
    output.check_distinct([("-o", "the image", out), ("-o", "the preview", png),
                           ("--json", "the --json file", args.json)],
                          [("the scene file", args.scene)])
    for path in (out, png, args.json):
        if path is not None:
            output.check_writable(path, parents=True)
    pipe = Pipeline(args.scene, generator=args.generator, sorter=args.sorter,
                    traversal=args.traversal, shader=_shader_config(args), tile=args.tile,
                    threads=args.threads)
    width, height = args.size
    from raysort.distributed import dask_client

    with dask_client(args.scheduler) as client:
        progress = Progress(f"render {pipe.scene.name}", unit="tile", enabled=not args.quiet)
        try:
            result = pipe.render(width, height, args.spp, args.seed, progress=progress,
                                 aov=args.aov, client=client)
        finally:
            progress.close()
    sidecars = {args.json: output.json_text({"settings": result.settings,
                                             "stats": result.stats.as_dict()})} \
        if args.json else None
    made = []                   # (output, the outermost directory created for it)
    try:
        for path in (out, args.json):
            if path:
                made.append((path, output.make_parents(path)))
        result.write(out, exposure=args.exposure, sidecars=sidecars)
    except BaseException:       # nothing written: the directories made for it go too
        for path, top in reversed(made):
            output.remove_parents(path, top)
        raise
    created = [top for _, top in made if top]
    _print_summary(result, out, args.stats, created=created)
    return 0


# --------------------------------------------------------------------------
# plugins, scenes
# --------------------------------------------------------------------------

def cmd_plugins(args):
    from raysort import isa
    from raysort.registry import list_plugins

    infos = list_plugins(load=True)
    rows = [("kind", "name", "distribution", "version", "status")]
    rows += [(i.kind, i.name, i.distribution, i.version, i.status) for i in infos]
    widths = [max(len(r[k]) for r in rows) for k in range(4)]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)) + "  " + r[4])
    info = isa.info()
    print(f"\nISA: active {info['active']}; compiled {', '.join(info['compiled'])}; this CPU "
          f"({info['machine']}) runs {', '.join(info['supported'])} (RAYSORT_ISA forces one)")
    return 0


def cmd_scenes(args):
    """Each packaged scene: name, triangles and its file's one-line description (the
    meshes are read, no BVH is built)."""
    from importlib.resources import files

    from raysort.scene import load_scene, scene_names, tomllib

    rows = [("name", "triangles", "description")]
    for name in scene_names():
        doc = tomllib.loads((files("raysort.scenes") / f"{name}.toml").read_text("utf-8"))
        rows.append((name, f"{load_scene(name).n_triangles:,}", doc.get("description", "")))
    width = max(len(r[0]) for r in rows), max(len(r[1]) for r in rows)
    for name, triangles, description in rows:
        print(f"{name:<{width[0]}}  {triangles:>{width[1]}}  {description}")
    return 0


def _usable_cores():
    """CPU cores this process may run on (its affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


# --------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """argparse whose errors are one line, ``raysort: error: ...``, exit status 2, like
    every other error of the command."""

    def error(self, message):
        self.exit(2, f"raysort: error: {message} (see '{self.prog} --help')\n")


def build_parser():
    parser = _Parser(
        prog="raysort", description="Ray sorting for fast incoherent packet ray tracing.")
    sub = parser.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a scene to OpenEXR (+ PNG preview)",
                       description="Render a scene (a packaged name, a .toml scene file or a "
                                   "mesh file; default: the Sibenik nave).")
    r.add_argument("scene", nargs="?", default=None, help="scene name or file (default sibenik)")
    r.add_argument("--size", type=_size, default=(320, 240), help="WIDTHxHEIGHT (320x240)")
    r.add_argument("--spp", type=_positive, default=4, help="samples per pixel (4)")
    r.add_argument("--depth", type=_non_negative, default=None,
                   help="bounces after the primary hit: sets the shader's max_depth "
                        "(lambert's default: 2)")
    r.add_argument("--seed", type=_seed, default=0, help="random seed, 0..2**32-1 (0)")
    r.add_argument("--sorter", default="none", help="sorter name or name:key=value,... (none)")
    r.add_argument("--traversal", default=None,
                   help="traversal name or spec (stream with AVX2/AVX-512, else wide8)")
    r.add_argument("--generator", default="pinhole", help="generator name or spec (pinhole)")
    r.add_argument("--shader", default="lambert", help="shader name or spec (lambert)")
    r.add_argument("--shadow-rays", choices=("on", "off"), default=None,
                   help="shadow rays to the scene's point lights: sets the shader's shadow_rays "
                        "(lambert's default: on if the scene has lights)")
    r.add_argument("--threads", type=_positive, default=_usable_cores(),
                   help="worker threads (default: the usable cores, %(default)s here)")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS", help=SCHEDULER_HELP)
    r.add_argument("--tile", type=_positive, default=32, help="tile edge in pixels (32)")
    r.add_argument("--exposure", type=_exposure, default=0.0,
                   help="PNG exposure in stops, -64..64 (0)")
    r.add_argument("-o", "--output", default="render.exr",
                   help="output .exr; missing directories are created (render.exr)")
    r.add_argument("--aov", type=_aov_names, default=[], metavar="LAYERS",
                   help="extra EXR layers from each pixel's first primary hit, comma-separated: "
                        "depth, normal, albedo, prim")
    r.add_argument("--stats", action="store_true", help="print the Table I counters")
    r.add_argument("--json", default=None, help="also write settings and stats as JSON")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_render)

    p = sub.add_parser("plugins", help="list every plugin and the SIMD path")
    p.set_defaults(func=cmd_plugins)

    s = sub.add_parser("scenes", help="list the packaged scenes: name, triangles, description")
    s.set_defaults(func=cmd_scenes)

    from raysort.bench import add_parser as add_bench_parser
    add_bench_parser(sub)
    from raysort.sweep import add_parser as add_sweep_parser
    add_sweep_parser(sub)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        from raysort import isa
        isa.active()            # a bad RAYSORT_ISA is reported here, in one line
        return args.func(args)
    except RaysortError as exc:
        print(f"raysort: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("raysort: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. piped into head: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())
