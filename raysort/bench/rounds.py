"""The timing method of ``raysort bench``: interleaved rounds, medians and per-round ratios.

A shared machine drifts (other jobs, frequency, caches), so one configuration's
best time against another's best, taken minutes apart, can mislead.  Instead:

* one untimed **warm-up round** runs every configuration once first, so lazy
  structures (the wide BVH, an outside library's scene) are built outside the
  timings;
* each timed **round** runs every configuration once, in an order shuffled
  per round from a seeded generator (the orders are reported);
* a configuration is summarised by the **median** of its rounds and their
  spread (min, max, interquartile range);
* a **speedup** is taken per round (baseline seconds / configuration seconds,
  both from the same round), and summarised by the median of those ratios and
  their spread.

Nothing here knows what is timed: a configuration is any callable returning
its seconds, so the arithmetic is tested on injected timings.
"""
from __future__ import annotations

import numpy as np

__all__ = ["run_rounds", "run_checked", "reference_index", "summary", "ratios"]


def reference_index(configs, runs):
    """The configuration every other is checked against: the baseline if its traversal
    is exact, else the first exact one."""
    base = next((k for k, c in enumerate(configs) if c.label == configs[0].baseline), 0)
    if not runs[base].exact:
        base = next((k for k, r in enumerate(runs) if r.exact), base)
    return base


def run_checked(configs, runs, repeat, *, seed, warmup, progress, group, groups):
    """:func:`run_rounds` of one group (a scene, or a scene and a workload) of
    ``groups``, each run's ``reference`` set first to the result (``run.result()``) of
    the configuration :func:`reference_index` picks; ``progress(done, total)`` counts
    over all groups."""
    reference = runs[reference_index(configs, runs)].result()
    for run in runs:
        run.reference = reference

    def tick(done, total):
        if progress:
            progress(group * total + done, groups * total)

    return run_rounds(runs, repeat, seed=seed, warmup=warmup, progress=tick)


def run_rounds(runs, repeat, *, seed=0, warmup=True, progress=None):
    """Run ``runs`` (a list of callables returning seconds) ``repeat`` times each.

    Returns ``(seconds, orders)``: ``seconds[r][k]`` is run ``k``'s time in round
    ``r``; ``orders[r]`` the order in which round ``r`` ran them (a permutation,
    from ``np.random.default_rng(seed)``).  ``progress(done, total)`` is called
    after every run, warm-up included.
    """
    n = len(runs)
    rng = np.random.default_rng(seed)
    total = n * (repeat + bool(warmup))
    done = 0
    if warmup:
        for run in runs:
            run()
            done += 1
            if progress:
                progress(done, total)
    seconds = [[0.0] * n for _ in range(repeat)]
    orders = []
    for r in range(repeat):
        order = [int(k) for k in rng.permutation(n)]
        orders.append(order)
        for k in order:
            seconds[r][k] = float(runs[k]())
            done += 1
            if progress:
                progress(done, total)
    return seconds, orders


def summary(values):
    """Median, min, max and interquartile range of a list of numbers."""
    v = np.asarray(values, dtype=np.float64)
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return {"median": float(med), "min": float(v.min()), "max": float(v.max()),
            "iqr": float(q3 - q1)}


def ratios(seconds, k, base):
    """Per-round speedups of run ``k`` over run ``base``: ``base / k`` in each round."""
    return [row[base] / row[k] if row[k] > 0 else float("inf") for row in seconds]
