"""What the contract checks cost in a frame: the same frame with checks on and off.

    python tests/benchmarks/check_cost.py [scene] [--size 256] [--spp 16] [--rounds 7]

Renders ``scene`` with the default pipeline (raysort's own trusted plugins) twice per
round, one thread: ``check_plugins=True`` (every plugin result checked, as for a plugin
from outside raysort) and ``check_plugins=False`` (the trusted built-ins skip their
checks).  A warm-up round first, the order alternating per round; per round the extra
frame CPU of the checked frame over the unchecked one, and their median with its
spread.  The images are compared bit for bit.

The checks of a sorter's order, of the rays and of a traversal's hits run inside the
gather and the scatter, so the pipeline's own ``check`` stage timer sees only the rest
(shown too); the on/off difference is the whole cost.  It is a per cent or two of a
frame, less than the noise of a shared machine, so the script also replays every
gather and scatter call of a checked frame with and without its checks, several times
each, the settings alternating, keeps the fastest replay of each call and setting, and
reports the difference of their sums as a share of the fastest checked frame's CPU
(warm caches: the checks read what the gather and scatter read anyway, so the extra is
mostly arithmetic); one such frame per round.  Run it on an otherwise idle machine and
read the spreads.

For a count of instructions instead (stable on a noisy machine), render under
callgrind with the checks on or off, once and twice; the frame is the difference:

    OPENBLAS_NUM_THREADS=1 valgrind --tool=callgrind \
        python tests/benchmarks/check_cost.py sibenik --size 128 --only on --renders 1
"""
import argparse
import functools
import statistics
import time

from raysort import contract
from raysort import pipeline as pipeline_module
from raysort import rays as rays_module
from raysort.bench.report import machine_info
from raysort.pipeline import Pipeline
from raysort.scene import load_scene


STAND_ALONE = ("sort_arrays", "check_generated", "check_bounce")   # the 'check' stage


def captured_frame(pipe, size, spp):
    """Render one frame, recording the arguments of every gather and scatter call and of
    every stand-alone check (:data:`STAND_ALONE`); returns (frame CPU seconds,
    [(gather args, scatter args)], [(check function, args, keyword args)])."""
    calls, checks, gathered = [], [], {}

    def gather(rays, order, offsets, packets, **options):
        gathered["last"] = (rays, order, offsets, packets)
        return rays_module.gather_checked(rays, order, offsets, packets, **options)

    def scatter(batch, order, offsets, tmax, n_prim, any_hit, **options):
        calls.append((gathered["last"], (batch, tmax, n_prim, any_hit)))
        return rays_module.scatter_checked(batch, order, offsets, tmax, n_prim, any_hit,
                                           **options)

    def recorded(check):
        def call(*args, **kwargs):
            checks.append((check, args, kwargs))
            return check(*args, **kwargs)
        return call

    real = pipeline_module.gather_checked, pipeline_module.scatter_checked
    real_checks = {name: getattr(contract, name) for name in STAND_ALONE}
    pipeline_module.gather_checked, pipeline_module.scatter_checked = gather, scatter
    for name, check in real_checks.items():
        setattr(contract, name, recorded(check))
    try:
        start = time.thread_time()
        pipe.render(size, size, spp)
        return time.thread_time() - start, calls, checks
    finally:
        pipeline_module.gather_checked, pipeline_module.scatter_checked = real
        for name, check in real_checks.items():
            setattr(contract, name, check)


def fastest(call, reps):
    """The least thread-CPU seconds of ``reps`` runs of ``call()``."""
    best = float("inf")
    for _ in range(reps):
        start = time.thread_time()
        call()
        best = min(best, time.thread_time() - start)
    return best


def replay(calls, checks, reps):
    """Thread-CPU seconds the frame's checks take, replayed: each gather and scatter
    call ``reps`` times with and without its checks, the settings alternating call by
    call, and each stand-alone check ``reps`` times; the fastest run of each call and
    setting is kept (a shared machine's noise only ever adds time, so the minimum is
    the stable estimate).  Returns (fused checks' extra seconds, stand-alone seconds)."""
    spent = {True: 0.0, False: 0.0}
    for (rays, order, offsets, packets), (batch, tmax, n_prim, any_hit) in calls:
        best = {True: float("inf"), False: float("inf")}
        for rep in range(reps):
            for checked in ((True, False) if rep % 2 else (False, True)):
                start = time.thread_time()
                rays_module.gather_checked(rays, order, offsets, packets,
                                           keep_tmax=checked and not any_hit,
                                           check_order=checked)
                rays_module.scatter_checked(batch, order, offsets, tmax, n_prim, any_hit,
                                            check_hits=checked, check_order=checked)
                best[checked] = min(best[checked], time.thread_time() - start)
        for checked in best:
            spent[checked] += best[checked]
    alone = sum(fastest(functools.partial(check, *args, **kwargs), reps)
                for check, args, kwargs in checks)
    return spent[True] - spent[False], alone


def check_shares(pipe, size, spp, rounds, reps):
    """Per round, the fused and the stand-alone checks' CPU as shares of a frame
    (replayed), the frame being the fastest of the ``rounds`` checked renders."""
    frames, spent = [], []
    for _ in range(rounds):
        frame, calls, checks = captured_frame(pipe, size, spp)
        frames.append(frame)
        spent.append(replay(calls, checks, reps))
    return [(100 * fused / min(frames), 100 * alone / min(frames)) for fused, alone in spent]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="sibenik")
    parser.add_argument("--size", type=int, default=256, help="image edge in pixels (256)")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel (16)")
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds (7)")
    parser.add_argument("--reps", type=int, default=5,
                        help="replays of each gather and scatter call per setting (5)")
    parser.add_argument("--only", choices=("on", "off"),
                        help="just render with the checks on or off (for callgrind)")
    parser.add_argument("--renders", type=int, default=1, help="frames to render with --only")
    args = parser.parse_args()
    scene = load_scene(args.scene)
    if args.only:
        pipe = Pipeline(scene, threads=1, check_plugins=args.only == "on")
        pipe.render(32, 32, 1)                  # the lazy wide BVHs, as in a timed run
        for _ in range(args.renders):
            pipe.render(args.size, args.size, args.spp)
        return
    pipes = {"on": Pipeline(scene, threads=1, check_plugins=True),
             "off": Pipeline(scene, threads=1, check_plugins=False)}
    seconds = {name: [] for name in pipes}
    check_stage, images = [], {}
    for r in range(args.rounds + 1):
        for name in (("on", "off") if r % 2 else ("off", "on")):
            start = time.thread_time()
            result = pipes[name].render(args.size, args.size, args.spp)
            spent = time.thread_time() - start
            images[name] = result.image
            if r:                               # round 0 warms up (lazy wide BVHs)
                seconds[name].append(spent)
                if name == "on":
                    check_stage.append(result.stats.stage_seconds.get("check", 0.0) / spent)
    assert images["on"].tobytes() == images["off"].tobytes(), "checks changed the image"
    extra = [100 * (on / off - 1) for on, off in zip(seconds["on"], seconds["off"])]
    info = machine_info()
    print(f"{args.scene} {args.size}x{args.size} {args.spp} spp, {pipes['on'].sorter.name} + "
          f"{pipes['on'].traversal.name}, one thread; {info['cpu']}, ISA {info['isa']}")
    for name in pipes:
        print(f"  checks {name:3s}: frame {statistics.median(seconds[name]):.3f} CPU s "
              f"[{min(seconds[name]):.3f}-{max(seconds[name]):.3f}]")
    print(f"  extra CPU with checks: median {statistics.median(extra):+.2f} % "
          f"[{min(extra):+.2f} .. {max(extra):+.2f}] (per round: "
          f"{', '.join(f'{x:+.1f}' for x in extra)})")
    print(f"  'check' stage timer: {100 * statistics.median(check_stage):.2f} % of the frame "
          f"(with the first Python after a kernel, cold in cache, that would run anyway)")
    shares = check_shares(pipes["on"], args.size, args.spp, args.rounds, args.reps)
    fused, alone = ([share[k] for share in shares] for k in (0, 1))
    total = [f + a for f, a in shares]
    print(f"  replayed, each call {args.reps}x per setting, fastest kept, per round:")
    for label, values in (("inside gather and scatter", fused), ("stand-alone", alone),
                          ("=> checks in all", total)):
        print(f"    {label:26s} median {statistics.median(values):.2f} % of the frame "
              f"[{min(values):.2f} .. {max(values):.2f}]")

if __name__ == "__main__":
    main()
