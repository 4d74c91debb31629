"""What the pipeline's ``batch_rays`` buys: one-thread frame CPU, the framework's share and
the 2-thread speed-up per batch size, side by side in one process.

    python tests/benchmarks/batch_size.py sibenik --size 1024 --spp 4 \
        --batch-rays 32768,131072,262144 --rounds 4

For every ``--batch-rays`` value a default pipeline (``Pipeline(scene, batch_rays=b)``:
sorter ``none``, the default traversal, ``lambert``) renders the same frame with one thread
and with two; the configurations run in interleaved rounds (the order rotated every round)
after a warm-up render each.  Per batch size it prints the medians [min-max] of the
one-thread frame's CPU (``time.thread_time``), of the framework's share (every stage timer
but ``traverse``, of their sum: what ``frame_profile.py`` reports), of the two-thread
frame's wall time, and of the per-round ratios against the first value: frame CPU,
framework share in points, and the speed-up of two threads over one (wall times of the same
round).  Every frame's image must equal the first one's bit for bit (the batches change the
counters, never the image).  Run it on an otherwise idle machine: the speed-up needs two
free cores.
"""
import statistics
import time

import numpy as np

import raysort

from _frames import frame_parser, pipelines, print_header


def spread(values, fmt="{:.3f}"):
    return (f"{fmt.format(statistics.median(values))} "
            f"[{fmt.format(min(values))}-{fmt.format(max(values))}]")


def main(argv=None):
    parser = frame_parser(__doc__, 1024)
    parser.add_argument("--batch-rays", default="32768,131072",
                        help="comma-separated batch sizes; the first is the reference")
    parser.add_argument("--rounds", type=int, default=4, help="timed rounds (4)")
    args = parser.parse_args(argv)
    sizes = [int(b) for b in args.batch_rays.split(",")]

    configs = [(b, threads) for b in sizes for threads in (1, 2)]
    pipes = pipelines(raysort.load_scene(args.scene),
                      {c: dict(batch_rays=c[0], threads=c[1]) for c in configs}, args.bvh)
    print_header(args, pipes[configs[0]])

    reference = None
    cpu, share, wall = ({c: [] for c in configs} for _ in range(3))
    for r in range(args.rounds + 1):            # round 0 is the warm-up
        k = r % len(configs)
        for c in configs[k:] + configs[:k]:
            start, start_cpu = time.perf_counter(), time.thread_time()
            result = pipes[c].render(args.size, args.size, spp=args.spp, seed=1)
            seconds, seconds_cpu = time.perf_counter() - start, time.thread_time() - start_cpu
            if reference is None:
                reference = result.image
            assert np.array_equal(result.image, reference), f"batch_rays, threads {c}: image"
            if r == 0:
                continue
            wall[c].append(seconds)
            if c[1] == 1:
                stages = result.stats.stage_seconds
                cpu[c].append(seconds_cpu)
                share[c].append(1 - stages["traverse"] / sum(stages.values()))
    base = sizes[0]
    print(f"\n{args.rounds} rounds after a warm-up; median [min-max]; ratios per round "
          f"against batch_rays={base}:")
    for b in sizes:
        one, two = (b, 1), (b, 2)
        cpu_ratio = [x / y for x, y in zip(cpu[one], cpu[base, 1])]
        points = [100 * (x - y) for x, y in zip(share[one], share[base, 1])]
        speedup = [x / y for x, y in zip(wall[one], wall[two])]
        print(f"  batch_rays {b:>7}: 1 thread {spread(cpu[one])} CPU s, framework "
              f"{spread([100 * x for x in share[one]], '{:.1f}')} %, 2 threads "
              f"{spread(wall[two])} s wall | frame CPU / base {spread(cpu_ratio)}, framework "
              f"{spread(points, '{:+.1f}')} points, 2 / 1 threads {spread(speedup, '{:.2f}')}x")


if __name__ == "__main__":
    main()
