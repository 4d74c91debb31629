"""raysort.bench.rounds: the timing method, on injected timings (nothing is timed here)."""
import numpy as np
import pytest

from raysort.bench.rounds import ratios, run_rounds, summary


class Canned:
    """A 'configuration' that returns the next of its canned seconds and logs each call."""

    def __init__(self, name, values, log):
        self.name, self.values, self.log = name, list(values), log

    def __call__(self):
        self.log.append(self.name)
        return self.values.pop(0)


def test_warmup_runs_each_once_untimed_then_every_round_runs_each_once():
    log = []
    runs = [Canned(k, [99.0] + [float(k + 1)] * 4, log) for k in range(3)]
    seconds, orders = run_rounds(runs, 4, seed=5)
    assert log[:3] == [0, 1, 2]                       # warm-up, in list order
    assert len(seconds) == 4 and len(orders) == 4
    for r in range(4):
        assert sorted(orders[r]) == [0, 1, 2]
        assert log[3 + 3 * r: 6 + 3 * r] == orders[r]  # each round in its own order
        assert seconds[r] == [1.0, 2.0, 3.0]          # times land under their run, not slot
    assert 99.0 not in sum(seconds, [])


def test_order_is_shuffled_per_round_and_reproducible_from_the_seed():
    def orders(seed):
        runs = [lambda: 1.0 for _ in range(6)]
        return run_rounds(runs, 8, seed=seed, warmup=False)[1]

    assert orders(3) == orders(3)
    assert orders(3) != orders(4)
    assert len({tuple(o) for o in orders(3)}) > 1     # not the same order every round


def test_progress_counts_every_run_warmup_included():
    seen = []
    run_rounds([lambda: 1.0] * 2, 3, progress=lambda d, t: seen.append((d, t)))
    assert seen == [(k, 8) for k in range(1, 9)]


def test_speedup_is_the_median_of_per_round_ratios_not_a_ratio_of_bests():
    # baseline and candidate drift together: round 2 is slow for both
    seconds = [[1.0, 0.5], [4.0, 2.0], [1.2, 1.0]]
    r = ratios(seconds, 1, 0)
    assert r == pytest.approx([2.0, 2.0, 1.2])
    assert summary(r)["median"] == pytest.approx(2.0)
    best = min(row[0] for row in seconds) / min(row[1] for row in seconds)
    assert best == pytest.approx(2.0) and summary(r)["min"] == pytest.approx(1.2)
    medians = (summary([s[0] for s in seconds])["median"]
               / summary([s[1] for s in seconds])["median"])
    assert medians == pytest.approx(1.2)      # a ratio of medians would say 1.2x


def test_summary_median_spread_and_iqr():
    s = summary([5.0, 1.0, 3.0, 2.0, 4.0])
    assert s == {"median": 3.0, "min": 1.0, "max": 5.0, "iqr": 2.0}
    assert summary([7.0])["iqr"] == 0.0


def test_a_zero_time_gives_an_infinite_ratio_not_an_error():
    assert np.isinf(ratios([[1.0, 0.0]], 1, 0)[0])
