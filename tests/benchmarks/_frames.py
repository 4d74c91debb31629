"""What the whole-frame benchmarks (``frame_profile.py``, ``batch_size.py``) share: their
command line, pipelines that read one BVH, and the header naming the frame and machine.
(They run as scripts, so Python finds this module beside them.)"""
import argparse

import raysort
from raysort.bench.command import add_bvh_argument
from raysort.bench.report import load_average, machine_info


def frame_parser(doc, size):
    """An argument parser (description: the first line of ``doc``) with the frame's
    ``scene``, ``--size`` (default ``size``) and ``--spp``."""
    p = argparse.ArgumentParser(description=doc.split("\n")[0])
    p.add_argument("scene", nargs="?", default="sibenik")
    p.add_argument("--size", type=int, default=size, help=f"image edge in pixels ({size})")
    p.add_argument("--spp", type=int, default=4, help="samples per pixel (4)")
    add_bvh_argument(p)
    return p


def pipelines(scene, configs, bvh=None):
    """``{key: Pipeline(scene, bvh=bvh, **kwargs)}`` for ``configs`` ``{key: kwargs}``, all
    reading the BVH a tiny render of the first one builds (with the trees its traversal
    reads)."""
    pipes = {key: raysort.Pipeline(scene, bvh=bvh or None, **kwargs)
             for key, kwargs in configs.items()}
    first = next(iter(pipes.values()))
    first.render(8, 8, spp=1)
    for pipe in pipes.values():
        pipe._bvh = first.bvh           # built once, read only
    return pipes


def print_header(args, pipe):
    """The frame, the pipeline's plugins, the machine, its ISA and load."""
    machine = machine_info()
    print(f"{args.scene} {args.size}x{args.size}, {args.spp} spp, "
          f"{' + '.join(str(v) for v in pipe.describe().values())}")
    print(f"machine: {machine['cpu']} ({machine['cores']} cores), ISA {machine['isa']} "
          f"(NumPy's SIMD {machine['numpy_simd']}), load average before: {load_average()}")
