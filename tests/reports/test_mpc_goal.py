"""reports.mpc_goal: mpc against its goal per setting, and the case-level evidence where it misses
(the costs of the cases where it broke, and the event that first broke each plan, from real step
logs)."""
from __future__ import annotations

import pandas as pd
import pytest

from ecodrive_bench.bench.logs.mcaplog import EpisodeLog, read_plan
from ecodrive_bench.reports import mpc_goal


def _rows(method: str, seed: int, times: list[float], energy: float = 100.0, signals: str = "uncoordinated",
          mcap: str = "") -> list[dict]:
    return [{"method": method, "signals": signals, "train_seed": seed, "case": c, "energy": energy,
             "travel_time": t, "mcap": mcap.format(case=c)} for c, t in enumerate(times)]


def _table() -> pd.DataFrame:
    rows = _rows("baseline", -1, [200.0, 200.0, 200.0, 200.0])
    rows += _rows("prl", 0, [190.0, 190.0, 190.0, 190.0]) + _rows("prl", 1, [194.0, 194.0, 194.0, 194.0])
    rows += _rows("dqn", 0, [250.0] * 4)
    rows += _rows("mpc", -1, [160.0, 170.0, 260.0, 280.0], energy=90.0, mcap="mpc/case-{case:03d}.mcap")
    return pd.DataFrame(rows)


def test_goal_names_the_best_learned_method_and_each_half():
    g = mpc_goal.goal(_table(), phi=1.0, learned=("prl", "dqn")).iloc[0]
    assert g.best_learned == "prl" and g.best_cost == pytest.approx(292.0)  # seed means 290 and 294
    assert g.mpc_cost == pytest.approx(90.0 + 217.5) and not g.cost_met  # 307.5 > 292
    assert g.time_rel == pytest.approx(217.5 / 200.0 - 1.0) and not g.time_met  # +8.75% > 5%
    faster = _table()
    faster.loc[faster.method == "mpc", "travel_time"] = 180.0
    g = mpc_goal.goal(faster, phi=1.0, learned=("prl", "dqn")).iloc[0]
    assert g.cost_met and g.time_met
    assert mpc_goal.goal(faster[faster.method != "mpc"], 1.0, ("prl",)).empty


def test_case_split_marks_the_cases_where_mpc_is_much_slower():
    split = mpc_goal.case_split(_table(), 1.0, "uncoordinated", "prl").set_index("case")
    assert list(split.broke) == [False, False, True, True]  # 260 and 280 against 192: > 30 s slower
    assert split.loc[2, "cost_mpc"] == pytest.approx(350.0) and split.loc[2, "cost_other"] == pytest.approx(292.0)


def test_the_report_lines_read_the_first_event_from_the_step_logs(tmp_path):
    table = _table()
    events = {0: [], 1: [{"time": 230.0, "event": "drift"}], 2: [{"time": 270.0, "event": "leader"}],
              3: [{"time": 250.0, "event": "leader"}, {"time": 260.0, "event": "step"}]}
    for case, replans in events.items():
        log = EpisodeLog(tmp_path / f"mpc/case-{case:03d}.mcap", {"method": "mpc"})
        log.add_plan({"time": [200.0, 201.0], "x": [0.0, 10.0], "speed": [10.0, 10.0], "travel_time": 165.0,
                      "replans": replans})
        log.finish({})
    assert read_plan(tmp_path / "mpc/case-002.mcap")["replans"][0]["event"] == "leader"
    first = mpc_goal.first_events(table, tmp_path, "uncoordinated").set_index("case")
    assert list(first.event) == ["none", "drift", "leader", "leader"]
    assert first.loc[3, "after_s"] == 50.0 and first.loc[3, "delay_s"] == 280.0 - 165.0
    text = "\n".join(mpc_goal.lines(table, {"uncoordinated": 1.0}, tmp_path, ("prl", "dqn")))
    assert "**missed**" in text and "prl" in text
    assert "on the 2 cases where mpc is more than 30 s slower" in text
    assert "leader 2" in text and "drift 1" in text and "none 1" in text
    assert "cost no more than mpc: prl 292.0 Wh" in text and "dqn" not in text.split("cost no more than mpc")[1].split("\n")[0]
    assert mpc_goal.lines(table[table.method != "mpc"], {"uncoordinated": 1.0}, tmp_path, ("prl",)) == []


def test_a_miss_on_travel_time_alone_names_that_half_and_prints_no_nan(tmp_path):
    rows = _rows("baseline", -1, [200.0, 200.0]) + _rows("prl", 0, [215.0, 215.0])
    rows += _rows("mpc", -1, [220.0, 220.0], energy=50.0, mcap="mpc/case-{case:03d}.mcap")
    text = "\n".join(mpc_goal.lines(pd.DataFrame(rows), {"uncoordinated": 1.0}, tmp_path, ("prl",)))
    assert "**missed**" in text and "missed on travel time +10.0% against the baseline" in text
    assert "cost +" not in text.split("Why")[1]  # the cost half is met: not named as missed
    assert "nan" not in text and "where it is not, mpc costs 270.0 Wh against 315.0" in text
    assert "no step log of mpc carries its re-plans" in text


def test_the_report_checks_the_goal_and_leaves_out_headroom_without_clairvoyant(tmp_path):
    from ecodrive_bench.reports import section_bounds
    from ecodrive_bench.reports.inputs import Run

    def section(results: pd.DataFrame) -> str | None:
        data = section_bounds.compute(Run(tmp_path, {}, results), [])
        return None if data is None else section_bounds.markdown(data)

    lines = section(_table())
    assert "## Headroom" not in lines  # no clairvoyant in the run: no headroom section
    assert "### mpc against its goal" in lines and "**missed**" in lines
    assert section(_table()[lambda d: d.method != "mpc"]) is None
