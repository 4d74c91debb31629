"""A rebuilt kernel module against a saved copy of its old build, in whole frames.

Before changing a kernel, copy the active ISA's build of its module aside; rebuild; then

    cp raysort/_isa/avx2/shaders/lambert.cpython-*.so /tmp/old-lambert.so   # before the edit
    python tests/benchmarks/kernel_ab.py shaders.lambert /tmp/old-lambert.so \\
        --size 1024 --spp 16 --rounds 6 --function _shade

renders the frame (the default pipeline) with each build in turn, in one process, the
order alternated every round (old, new; new, old; ...) after a warm-up frame, and prints
per stage (``RenderStats.stage_seconds``, thread CPU) the median [min, max] of each build
and the median [min, max] of the per-round ratios new / old.  ``--function`` also times
that function of the module (thread CPU of its calls within each frame: the kernel
alone, without its stage's other work).  Every frame's image must be bit-identical to the
first, or the script exits with 1.  The module must be one the pipeline reaches through
:func:`raysort.isa.module` (the per-ISA kernels); the old copy is loaded from its own
file, so both builds live in the process side by side.  Run with ``RAYSORT_ISA`` set to
the ISA whose build was copied.

With ``--rays camera`` (or ``diffuse``, or ``shadow``) it traces, instead of frames, the
primary (or first-bounce diffuse, or the camera hits' any-hit shadow) rays of a ``--size``
x ``--size`` image at 1 spp through
``Pipeline.trace`` (sort, gather, traverse, scatter; plugin checks off unless ``--checks``,
which a change to the contract checks, ``_contract``, needs): ``--calls`` calls
per build and round, the round's median call, and prints each build's Mrays/s and the
per-round speed-up of the new build (the old build's time over the new one's).  The hits
must be bit-identical.

    cp raysort/_isa/avx512/traversals/stream.cpython-*.so /tmp/old-stream.so
    python tests/benchmarks/kernel_ab.py traversals.stream /tmp/old-stream.so sponza \
        --rays camera --size 256 --rounds 9

``--sorter`` and ``--traversal`` choose the pipeline's plugins (for frames and for
``--rays``; default: ``none`` and the default traversal); with ``--rays`` and
``--function`` it also prints that function's median time per call (so a sorter's
kernel is timed where a render calls it: after a trace, with the cache as the trace left it):

    cp raysort/_isa/avx512/sorters/_keysort.cpython-*.so /tmp/old-keysort.so
    python tests/benchmarks/kernel_ab.py sorters._keysort /tmp/old-keysort.so sibenik \
        --rays diffuse --size 256 --rounds 21 --calls 3 --sorter two_point \
        --traversal stream --function sort_rays
"""
import argparse
import importlib.machinery
import importlib.util
import statistics
import sys
import time

import numpy as np

import raysort
from raysort import isa

from _frames import print_header


class TimedModule:
    """A module whose ``function`` adds its calls' thread CPU to ``seconds``."""

    def __init__(self, module, function):
        self.module, self.function, self.seconds = module, function, 0.0
        self._timed = None
        if function:
            inner = getattr(module, function)

            def timed(*args, **kwargs):
                start = time.thread_time()
                try:
                    return inner(*args, **kwargs)
                finally:
                    self.seconds += time.thread_time() - start
            self._timed = timed

    def __getattr__(self, name):
        if name == self.function:
            return self._timed
        return getattr(self.module, name)


def load_copy(name, path):
    """The extension module in ``path`` (a copy of a build of ``name``), under a name of
    its own.  The package's own module of that name is imported first: a Cython module
    puts itself in ``sys.modules`` under its compiled name when that name is free, and
    the copy's Python classes (a sorter's wrapper, which may differ between the builds)
    would then stand in for the package's."""
    importlib.import_module("raysort." + name)
    alias = "raysort_kernel_ab_old." + name.rsplit(".", 1)[-1]
    loader = importlib.machinery.ExtensionFileLoader(alias, path)
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader(alias, loader))
    loader.exec_module(module)
    return module


def spread(values):
    return f"{statistics.median(values):8.4f} [{min(values):.4f}, {max(values):.4f}]"


def trace_rounds(args, builds):
    """--rays: the rays of the workload traced by each build in turn; returns 0 if every
    call's hits are bit-identical to the first's."""
    from raysort.workloads import camera_rays, workload
    scene = raysort.load_scene(args.scene)
    if args.rays == "camera":
        work = camera_rays(scene, width=args.size, height=args.size, spp=1, seed=1)[0]
    else:
        kind = "shadow" if args.rays == "shadow" else "diffuse:depth=1"
        work = workload(scene, kind, width=args.size, height=args.size, spp=1, seed=1)
    pipe = raysort.Pipeline(scene, threads=1, check_plugins=args.checks, sorter=args.sorter,
                            traversal=args.traversal)
    args.spp = 1
    print_header(args, pipe)
    print(f"module {args.module}: old {args.old}, new {builds['new'].module.__file__}")
    print(f"{len(work.rays)} {args.rays} rays through Pipeline.trace, {args.calls} calls per "
          f"build and round (median), {args.rounds} rounds after a warm-up")
    times, first, same = {"old": [], "new": []}, None, True
    function = {"old": [], "new": []}
    for r in range(args.rounds + 1):
        for key in (("old", "new") if r % 2 == 0 else ("new", "old")):
            build = builds[key]
            isa._modules[args.module] = build
            calls, inner = [], []
            for _ in range(args.calls):
                before = build.seconds
                start = time.thread_time()
                hits, _ = pipe.trace(work.rays, work.packets, any_hit=work.any_hit)
                calls.append(time.thread_time() - start)
                inner.append(build.seconds - before)
            if r:
                times[key].append(statistics.median(calls))
                function[key].append(statistics.median(inner))
            found = (hits.copy(),) if work.any_hit else (hits.t.copy(), hits.prim.copy())
            first = found if first is None else first
            same = same and all(np.array_equal(a, b) for a, b in zip(found, first))
    del isa._modules[args.module]
    n = len(work.rays)
    print(f"every call's hits bit-identical: {same}")
    for key in ("old", "new"):
        rates = [n / t / 1e6 for t in times[key]]
        print(f"  {key}: {spread(rates)} Mrays/s")
    print(f"  speed-up new / old per round: "
          f"{spread([o / w for o, w in zip(times['old'], times['new'])])}")
    if args.function:
        for key in ("old", "new"):
            print(f"  {key} {args.function}: {spread([t * 1e3 for t in function[key]])} ms "
                  f"per call")
        print(f"  {args.function} new / old per round: "
              f"{spread([w / o for o, w in zip(function['old'], function['new'])])}")
    return 0 if same else 1


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("module", help="kernel module, as raysort.isa.module names it")
    parser.add_argument("old", help="a copy of that module's old build (.so)")
    parser.add_argument("scene", nargs="?", default="sibenik")
    parser.add_argument("--size", type=int, default=512, help="image edge in pixels (512)")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel (16)")
    parser.add_argument("--rounds", type=int, default=6, help="frames per build (6)")
    parser.add_argument("--checks", action="store_true",
                        help="with --rays: check every plugin's results, as the default "
                             "pipeline does (time _contract's sort_result with --function)")
    parser.add_argument("--function", default="",
                        help="also time this function of the module (e.g. _shade)")
    parser.add_argument("--threads", type=int, default=1, help="render threads (1)")
    parser.add_argument("--rays", choices=["camera", "diffuse", "shadow"],
                        help="trace these rays of the image instead of rendering frames")
    parser.add_argument("--calls", type=int, default=10,
                        help="with --rays: calls per build and round (10)")
    parser.add_argument("--sorter", default="none", help="the pipeline's sorter (none)")
    parser.add_argument("--traversal", default=None,
                        help="the pipeline's traversal (its default)")
    args = parser.parse_args(argv)
    new = isa.module(args.module)
    builds = {"old": TimedModule(load_copy(args.module, args.old), args.function),
              "new": TimedModule(new, args.function)}
    if args.rays:
        return trace_rounds(args, builds)
    pipe = raysort.Pipeline(args.scene, threads=args.threads, sorter=args.sorter,
                            traversal=args.traversal)
    print_header(args, pipe)
    print(f"module {args.module}: old {args.old}, new {builds['new'].module.__file__}")
    pipe.render(64, 64, spp=1, seed=1)                  # builds the trees
    runs, first, same = {"old": [], "new": []}, None, True
    for r in range(args.rounds):
        for key in (("old", "new") if r % 2 == 0 else ("new", "old")):
            build = builds[key]
            isa._modules[args.module] = build
            before = build.seconds
            result = pipe.render(args.size, args.size, spp=args.spp, seed=1)
            seconds = dict(result.stats.stage_seconds)
            seconds["frame"] = sum(result.stats.stage_seconds.values())
            if args.function:
                seconds[args.function] = build.seconds - before
            runs[key].append(seconds)
            if first is None:
                first = np.asarray(result.image)
            same = same and np.array_equal(np.asarray(result.image), first)
    del isa._modules[args.module]
    print(f"{args.rounds} rounds; every image bit-identical: {same}")
    print(f"  {'CPU s':<10}{'old':>26}{'new':>26}   new / old per round")
    for stage in runs["old"][0]:
        old = [run[stage] for run in runs["old"]]
        new = [run[stage] for run in runs["new"]]
        if min(old) == 0:            # a stage this pipeline does not run
            continue
        ratios = [n / o for n, o in zip(new, old)]
        print(f"  {stage:<10}{spread(old):>26}{spread(new):>26}   {spread(ratios)}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
