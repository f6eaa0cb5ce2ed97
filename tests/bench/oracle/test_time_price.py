"""The price of time that makes a case set of clairvoyant drives no slower than a limit: the least
one, against a brute-force scan; each case's pick at a price; the edge cases."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.bench.oracle.time_price import breakpoints, mean_time, pick, time_price


def _set(seed: int, cases: int = 12, drives: int = 6):
    rng = np.random.default_rng(seed)
    times = [np.round(rng.uniform(150.0, 250.0, drives)) for _ in range(cases)]
    costs = [300.0 - 0.8 * t + rng.normal(0.0, 15.0, drives) for t in times]  # faster drives cost more, with noise
    return costs, times


def test_pick_minimises_the_priced_cost_faster_then_first_of_ties():
    costs, times = np.array([10.0, 8.0, 12.0, 8.0]), np.array([100.0, 104.0, 90.0, 102.0])
    assert pick(costs, times, 0.0) == 3  # 8 = 8: the faster of the two
    assert pick(costs, times, 0.25) == 3  # 35, 34, 34.5, 33.5
    assert pick(costs, times, 1.0) == 2  # 110, 112, 102, 110
    assert pick(np.array([5.0, 5.0]), np.array([7.0, 7.0]), 3.0) == 0  # all equal: the first


@pytest.mark.parametrize("seed", range(6))
def test_the_price_is_the_least_that_meets_the_limit(seed):
    costs, times = _set(seed)
    cheapest = mean_time(costs, times, 0.0)
    fastest = float(np.mean([t.min() for t in times]))
    limit = fastest + 0.4 * (cheapest - fastest)  # between the two: a positive price is needed
    price = time_price(costs, times, limit)
    assert price > 0.0 and mean_time(costs, times, price) <= limit
    cuts = breakpoints(costs, times)
    assert not np.any(np.isclose(cuts, price, rtol=1e-9))  # inside an interval, not on a tie
    below = cuts[cuts < price]  # every interval below the price's: each misses the limit
    mids = np.concatenate([[below[0] / 2.0], (below[:-1] + below[1:]) / 2.0])
    assert len(mids) == len(below) and all(mean_time(costs, times, float(p)) > limit for p in mids)


def test_a_limit_met_exactly_is_met():
    costs, times = _set(3)
    at = [mean_time(costs, times, float(p)) for p in breakpoints(costs, times) * 1.000001]
    limit = sorted(set(at))[len(set(at)) // 2]  # the mean time of some price's choice, exactly
    price = time_price(costs, times, limit)
    assert mean_time(costs, times, price) <= limit


def test_no_breakpoint_no_price():
    costs, times = [np.array([5.0, 7.0]), np.array([3.0])], [np.array([100.0, 110.0]), np.array([90.0])]  # cheaper is faster
    assert len(breakpoints(costs, times)) == 0
    assert time_price(costs, times, 10.0) == 0.0  # no price makes a choice faster


def test_breakpoints_a_last_digit_apart_are_one():
    tie = 0.3  # [Wh/s] two cases whose faster drive overtakes at the same price, computed two ways
    costs = [np.array([10.0, 10.0 + 0.1 + 0.2]), np.array([20.0, 20.0 + 0.3])]
    times = [np.array([101.0, 100.0]), np.array([51.0, 50.0])]
    cuts = breakpoints(costs, times)
    assert len(cuts) == 1 and cuts[0] == pytest.approx(tie)


def test_mean_time_never_rises_with_the_price():
    costs, times = _set(42)
    seen = [mean_time(costs, times, float(p)) for p in np.linspace(0.0, 5.0, 500)]
    assert all(b <= a for a, b in zip(seen, seen[1:]))


def test_zero_where_the_cheapest_meet_it_and_the_fastest_where_nothing_does():
    costs, times = _set(7)
    assert time_price(costs, times, mean_time(costs, times, 0.0)) == 0.0
    price = time_price(costs, times, 0.0)  # no choice is this fast
    assert all(t[pick(c, t, price)] == t.min() for c, t in zip(costs, times))
    with pytest.raises(ValueError, match="at least one case"):
        time_price([], [], 100.0)

