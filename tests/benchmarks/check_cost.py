"""What the contract checks cost in a frame: each check of raysort.contract timed by thread CPU.

    python tests/benchmarks/check_cost.py [scene] [--size 256] [--spp 16]

Renders ``scene`` once with the default pipeline (``check_plugins=True``), one thread, with
every check function of :mod:`raysort.contract` wrapped in a thread-CPU timer, and prints each
check's seconds and share of the frame's CPU.  (The wrappers add a few microseconds per call.)
"""
import argparse
import collections
import time

from raysort import contract
from raysort.pipeline import Pipeline
from raysort.scene import load_scene

# What the pipeline calls on every frame (check_sort, check_hits and check_rays run only to
# name a fault: the sort result, the hits and the rays are checked inside the gather and
# the scatter, whose share of this cost tests/benchmarks/fused_check_cost.py measures).
CHECKS = ("check_ray_batch", "check_packets", "sort_arrays", "packet_arrays",
          "check_packet_arrays", "check_counters", "check_generated", "check_bounce")


def timed_checks():
    """Wrap every check in place; return the Counter their CPU seconds add up in."""
    spent = collections.Counter()
    for name in CHECKS:
        def wrapper(*args, _check=getattr(contract, name), _name=name, **kwargs):
            start = time.thread_time()
            try:
                return _check(*args, **kwargs)
            finally:
                spent[_name] += time.thread_time() - start
        setattr(contract, name, wrapper)
    return spent


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="sibenik")
    parser.add_argument("--size", type=int, default=256, help="image edge in pixels (256)")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel (16)")
    args = parser.parse_args()
    pipe = Pipeline(load_scene(args.scene), threads=1)
    spent = timed_checks()
    pipe.render(32, 32, 1)                      # warm-up: the lazy wide BVHs
    spent.clear()
    start = time.thread_time()
    result = pipe.render(args.size, args.size, args.spp)
    frame = time.thread_time() - start
    print(f"{args.scene} {args.size}x{args.size} {args.spp} spp, "
          f"{pipe.sorter.name} + {pipe.traversal.name}: frame {frame:.3f} CPU s")
    for name, seconds in spent.most_common():
        print(f"  {name:18s} {seconds:.4f} s  {100 * seconds / frame:5.2f} %")
    print(f"  {'all checks':18s} {sum(spent.values()):.4f} s  "
          f"{100 * sum(spent.values()) / frame:5.2f} %")
    print(result.stats)


if __name__ == "__main__":
    main()
