"""bench.experiments.time_price_cost: a set's summary at price 0, at its price and at its fastest
drives; bad set names are one line with exit code 2."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.bench.experiments.time_price_cost import main, summary


def test_the_summary_prices_a_set_that_is_too_slow():
    costs = [np.array([10.0, 14.0, 30.0]), np.array([20.0, 21.0])]
    times = [np.array([100.0, 96.0, 90.0]), np.array([60.0, 58.0])]
    s = summary(costs, times, [90.0, 60.0])  # limit 75: the cheapest take 80 s, the fastest 74 s
    assert (s["cost_0"], s["time_0"]) == (15.0, 80.0)
    assert (s["cost_fastest"], s["time_fastest"]) == (25.5, 74.0)
    assert s["time"] <= s["limit"] == 75.0 and s["cost_0"] < s["cost"] <= s["cost_fastest"]
    assert s["moved"] == 2 and s["price"] > 0 and 0 < s["cut_distance"] < np.inf
    fine = summary(costs, times, [200.0, 200.0])  # met at price 0
    assert fine["price"] == 0.0 and fine["moved"] == 0 and np.isnan(fine["cut_distance"])


def test_a_bad_set_name_is_one_line_and_exit_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--sets", "nowhere/coordinated"])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "nowhere/coordinated" in err[0] and "paper/coordinated" in err[0]
