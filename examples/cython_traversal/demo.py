"""Use the ``stack`` traversal by name and check it against raysort's ``single``.

    pip install --no-build-isolation ./examples/cython_traversal
    python examples/cython_traversal/demo.py --size 64
"""
import argparse

import numpy as np

import raysort
from raysort.workloads import workload


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scene", nargs="?", default="sibenik")
    parser.add_argument("--size", type=int, default=64, help="image edge in pixels (64)")
    args = parser.parse_args(argv)

    scene = raysort.load_scene(args.scene)
    mine = raysort.Pipeline(scene, traversal="stack")        # found through its entry point
    theirs = raysort.Pipeline(scene, traversal="single")
    for kind in ("primary", "diffuse", "shadow"):
        work = workload(scene, kind, width=args.size, height=args.size)
        got, counters = mine.trace(work.rays, work.packets, any_hit=work.any_hit)
        want, _ = theirs.trace(work.rays, work.packets, any_hit=work.any_hit)
        if work.any_hit:
            same = np.array_equal(got, want)
        else:
            same = (np.array_equal(got.prim, want.prim)
                    and np.array_equal(got.t.view(np.uint32), want.t.view(np.uint32)))
        per = counters.per_ray()
        print(f"{work.label:<28} {len(work):>8,} rays  boxes/ray {per['box1']:6.1f}  "
              f"triangles/ray {per['tri1']:6.1f}  same as single: {same}")
        assert same, f"stack differs from single on {work.label}"
    image = raysort.Pipeline(scene, traversal="stack").render(args.size, args.size, 1).image
    assert np.array_equal(image, theirs.render(args.size, args.size, 1).image)
    print("renders are bit-identical")


if __name__ == "__main__":
    main()
