"""reports.metrics.headroom: the share of the baseline0-to-clairvoyant cost gap a method closes, its CI over
cases and seeds, the cases where the reference is beaten, and the figure's axis."""
from __future__ import annotations

import pandas as pd
import pytest

from ecodrive_bench.reports.metrics import headroom


def _rows(method: str, seed: int, costs: list[float]) -> list[dict]:
    return [{"method": method, "signals": "coordinated", "train_seed": seed, "case": c, "energy": cost - 200.0,
             "travel_time": 200.0} for c, cost in enumerate(costs)]


def test_share_of_the_gap_with_its_seed_ci():
    rows = _rows("baseline0", -1, [100.0, 110.0]) + _rows("clairvoyant", -1, [60.0, 70.0])
    rows += _rows("prl", 0, [78.0, 88.0]) + _rows("prl", 1, [82.0, 92.0])  # mean 85 = halfway
    out = headroom(pd.DataFrame(rows), phi=1.0).set_index("method")
    assert out.loc["prl", "share_closed"] == pytest.approx(0.5)
    assert out.loc["prl", "ci_low"] < 0.5 < out.loc["prl", "ci_high"] and out.loc["prl", "seeds"] == 2
    assert out.loc["clairvoyant", "share_closed"] == pytest.approx(1.0) and out.loc["baseline0", "share_closed"] == 0.0
    assert out.loc["prl", "beaten"] == 0 and out.loc["clairvoyant", "beaten"] == 0


def test_only_cases_every_reference_ran_count():
    rows = _rows("baseline0", -1, [100.0, 110.0, 500.0]) + _rows("clairvoyant", -1, [60.0, 70.0])
    rows += _rows("prl", 0, [80.0, 90.0, 0.0])
    out = headroom(pd.DataFrame(rows), phi=1.0).set_index("method")
    assert out.loc["prl", "cases"] == 2 and out.loc["prl", "share_closed"] == pytest.approx(0.5)


def test_no_row_without_the_references():
    assert headroom(pd.DataFrame(_rows("prl", 0, [80.0])), phi=1.0).empty


def test_the_readme_line_names_the_best_learned_method():
    from ecodrive_bench.reports.headline import headroom_line

    rows = _rows("baseline0", -1, [100.0, 110.0]) + _rows("clairvoyant", -1, [60.0, 70.0])
    rows += _rows("prl", 0, [78.0, 88.0]) + _rows("prl", 1, [82.0, 92.0]) + _rows("dqn", 0, [95.0, 105.0])
    line = headroom_line(pd.DataFrame(rows), {})
    assert "closes 50% [" in line and "coordinated (PRL)" in line and "DQN" not in line
    assert headroom_line(pd.DataFrame(_rows("prl", 0, [80.0])), {}) == ""


def test_the_report_states_the_whole_jobs_ratio_to_its_floor():
    from ecodrive_bench.reports.html_provenance import _floor_all

    man = {"wall_time_all_commands_s": 600.0, "sumo_time_all_commands_s": 800.0, "workers": 2}
    assert "= 1.50" in _floor_all(man) and "whole commands" not in _floor_all(man)
    assert "= 1.50, 1.60 over the whole commands" in _floor_all({**man, "command_wall_all_commands_s": 640.0})
    assert _floor_all({"workers": 2}) == ""


def test_the_report_warns_of_methods_on_different_cases():
    import pandas as pd

    from ecodrive_bench.reports.load import case_set_warnings

    rows = [("baseline", -1, c) for c in range(5)] + [("prl", 0, c) for c in range(3)] + [("prl", 1, c) for c in range(5)]
    df = pd.DataFrame(rows, columns=["method", "train_seed", "case"]).assign(signals="coordinated")
    (warning,) = case_set_warnings(df)
    assert warning.startswith("coordinated: the methods drove different cases") and "prl s0: 3 cases, 0-2" in warning
    assert case_set_warnings(df[df.case < 3]) == []
    both = pd.concat([df[df.case < 3], df[df.case < 3].assign(signals="uncoordinated", case=df.case[df.case < 3] + 10)])
    assert case_set_warnings(both) == []  # each setting its own cases


def test_the_ci_resamples_cases_too():
    """Two seeds that agree on every case: a seeds-only bootstrap has no spread, the case-paired
    one carries the case-to-case spread of the share."""
    rows = _rows("baseline0", -1, [100.0, 110.0, 120.0, 130.0]) + _rows("clairvoyant", -1, [60.0, 70.0, 100.0, 60.0])
    rows += _rows("prl", 0, [90.0, 80.0, 110.0, 70.0]) + _rows("prl", 1, [90.0, 80.0, 110.0, 70.0])
    row = headroom(pd.DataFrame(rows), phi=1.0).set_index("method").loc["prl"]
    assert row.ci_low < row.share_closed < row.ci_high and row.ci_high - row.ci_low > 0.1


def test_cases_that_beat_the_reference_are_counted_and_named():
    rows = _rows("baseline0", -1, [100.0, 110.0, 120.0]) + _rows("clairvoyant", -1, [60.0, 70.0, 80.0])
    rows += _rows("prl", 0, [50.0, 90.0, 75.0]) + _rows("prl", 1, [58.0, 90.0, 95.0])  # case 0: 54 < 60
    row = headroom(pd.DataFrame(rows), phi=1.0).set_index("method").loc["prl"]
    assert row.beaten == 1 and row.beaten_cases == "0"


def test_the_figure_keeps_a_readable_axis(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from ecodrive_bench.reports import figures

    shares = pd.DataFrame({"method": ["prl", "dqn"], "signals": ["coordinated"] * 2, "share_closed": [0.6, -4.0],
                           "ci_low": [0.5, -5.0], "ci_high": [0.7, -3.0]})
    seen = []
    real = plt.Figure.savefig

    def keep(fig, *a, **k):
        seen.append(fig.axes[0].get_xlim())
        return real(fig, *a, **k)

    plt.Figure.savefig = keep
    try:
        figures.headroom(shares, tmp_path)
    finally:
        plt.Figure.savefig = real
    assert seen and seen[0][0] >= -100 and seen[0][1] <= 200
