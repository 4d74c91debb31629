"""Where a frame's CPU goes, and what a second thread buys.

Renders one scene with the default pipeline (``Pipeline(scene)``: sorter ``none``, the
traversal of :func:`raysort.pipeline.default_traversal`, ``lambert``) and reports, from
the render's own per-stage thread-CPU timers (``RenderStats.stage_seconds``), each
stage's median over ``--stage-rounds`` frames (after a small warm-up frame, which builds
the trees the traversal reads), its share of the frame's CPU and the framework's share
(every stage but ``traverse``: shade, check, gather, sort, generate, scatter and
``other``, the bookkeeping between them), also with the shader's ``prepare`` counted
(CPU of every frame, but outside the stage timers; timed on its own, the median of
three calls), and how much of the render's thread CPU the stages hold.  Then it
times whole frames with 1 and 2 threads, interleaved in one process (a warm-up round,
the order rotated every round) and prints medians with their spread and the per-round
speed-up.  Images are compared bit for bit.

    python tests/benchmarks/frame_profile.py                  # sibenik 512x512, 4 spp
    python tests/benchmarks/frame_profile.py --size 1024 --spp 4 --rounds 5
    python tests/benchmarks/frame_profile.py --size 1024 --spp 64 --stage-rounds 1 \
        --stage-threads 2 --no-threads        # issue 12's frame, its stages with 2 threads

Run it on an otherwise idle machine: the thread speed-up needs two free cores.
"""
import statistics
import time

import numpy as np

import raysort
from raysort.bench.report import load_average

from _frames import frame_parser, pipelines, print_header


def render(pipe, args):
    start = time.perf_counter()
    result = pipe.render(args.size, args.size, spp=args.spp, seed=1)
    return result, time.perf_counter() - start


def cpu_render(pipe, args):
    """A render with its calling thread's CPU seconds (with one thread: the frame's)."""
    start = time.thread_time()
    result, wall = render(pipe, args)
    return result, wall, time.thread_time() - start


def prepare_seconds(pipe, rounds=3):
    """The median thread-CPU seconds of the shader's ``prepare`` (which ``render`` calls
    once per frame, outside the stage timers)."""
    seconds = []
    for _ in range(rounds):
        start = time.thread_time()
        pipe.shader.prepare(pipe.scene)
        seconds.append(time.thread_time() - start)
    return statistics.median(seconds)


def stage_table(runs, prepare):
    """Each stage's median CPU seconds over the renders ``runs`` (their RenderStats), and
    the framework's share with the shader's ``prepare`` (``prepare`` seconds) counted."""
    seconds = {stage: statistics.median(r.stage_seconds[stage] for r in runs)
               for stage in runs[0].stage_seconds}
    total = sum(seconds.values())
    print(f"  {'stage':<10}{'CPU s':>9}{'share':>8}   (median of {len(runs)} frames)")
    for stage, value in sorted(seconds.items(), key=lambda kv: -kv[1]):
        print(f"  {stage:<10}{value:9.3f}{value / total:8.1%}")
    framework = total - seconds.get("traverse", 0.0)
    print(f"  framework (all but traverse): {framework:.3f} s = {framework / total:.1%} of "
          f"{total:.3f} CPU s")
    print(f"  with the shader's prepare ({prepare:.4f} s, outside the stage timers): "
          f"{framework + prepare:.3f} s = {(framework + prepare) / (total + prepare):.1%}")


def main(argv=None):
    parser = frame_parser(__doc__, 512)
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (5)")
    parser.add_argument("--stage-rounds", type=int, default=3,
                        help="frames (of --stage-threads threads) the stage table is the "
                             "median of (3)")
    parser.add_argument("--no-threads", action="store_true", help="skip the 2-thread part")
    parser.add_argument("--stage-threads", type=int, choices=(1, 2), default=1,
                        help="threads of the stage table's frames (1; with 2, each stage's "
                             "CPU is summed over both threads)")
    args = parser.parse_args(argv)

    pipes = pipelines(raysort.load_scene(args.scene), {n: dict(threads=n) for n in (1, 2)},
                      args.bvh)
    print_header(args, pipes[1])

    threads = args.stage_threads
    runs = [cpu_render(pipes[threads], args) for _ in range(max(1, args.stage_rounds))]
    result = runs[0][0]
    print(f"\n{'one thread' if threads == 1 else f'{threads} threads'}: "
          f"{statistics.median(s for _, s, _ in runs):.2f} s wall (median), "
          f"{result.stats.total_rays:,} rays")
    stage_table([res.stats for res, _, _ in runs], prepare_seconds(pipes[1]))
    if threads == 1:            # (the calling thread's CPU is not the frame's with more)
        covered = [sum(res.stats.stage_seconds.values()) / cpu for res, _, cpu in runs]
        print(f"  the stages hold {statistics.median(covered):.1%} of the render's thread "
              f"CPU (median; the rest: the shader's prepare, the render's set-up)")
    if args.no_threads:
        return

    reference = result.image
    walls = {1: [], 2: []}
    ratios = []
    for r in range(args.rounds + 1):             # round 0 is the warm-up
        order = (1, 2) if r % 2 == 0 else (2, 1)
        got = {}
        for n in order:
            res, got[n] = render(pipes[n], args)
            assert np.array_equal(res.image, reference), f"{n} threads changed the image"
        if r == 0:
            continue
        for n in (1, 2):
            walls[n].append(got[n])
        ratios.append(got[1] / got[2])
    print(f"\nwhole frames, {args.rounds} rounds after a warm-up, order rotated:")
    for n in (1, 2):
        w = walls[n]
        print(f"  {n} thread{'s' if n > 1 else ' '}: median {statistics.median(w):.3f} s "
              f"(min {min(w):.3f}, max {max(w):.3f})")
    print(f"  speed-up 2 threads / 1: median {statistics.median(ratios):.2f}x, per round "
          f"{', '.join(f'{x:.2f}' for x in ratios)}")
    print(f"  load average after: {load_average()}")


if __name__ == "__main__":
    main()
