"""``reports.top``: whether clairvoyant stays the top of the scale, on tables whose answers are known."""
from __future__ import annotations

import pandas as pd
import pytest

from ecodrive_bench.reports import top
from ecodrive_bench.reports.generalisation import top_of_scale


def _rows(method: str, costs: list[float], seed: int = -1, time: float = 100.0, variant: str = "v1") -> list[dict]:
    return [{"method": method, "signals": "uncoordinated", "train_seed": seed, "case": c, "energy": e - time,
             "travel_time": time, "variant": variant} for c, e in enumerate(costs)]


def _table(prl_case0: float = 110.0, top_time: float = 100.0, cheap_cases: int = 1) -> pd.DataFrame:
    """PRL's seed 0 costs ``prl_case0`` on its first ``cheap_cases`` cases, 110 elsewhere."""
    return pd.DataFrame(_rows("clairvoyant", [100.0] * 10, time=top_time) + _rows("baseline", [130.0] * 10)
                        + _rows("mpc", [104.0] * 10)
                        + _rows("prl", [prl_case0] * cheap_cases + [110.0] * (10 - cheap_cases), seed=0)
                        + _rows("prl", [110.0] * 10, seed=1))


def test_margins_and_case_shares():
    vs = top.against(_table(prl_case0=80.0), phi=1.0).set_index("method")
    assert vs.loc["prl", "cost"] == pytest.approx((95.0 + 9 * 110.0) / 10)  # case 0's seed mean is 95
    assert vs.loc["prl", "case_share"] == pytest.approx(0.9)  # case 0: 100 > 95
    assert vs.loc["mpc", "margin"] == pytest.approx(1 - 100 / 104)


def test_verdicts_read_each_target():
    t = _table()
    v = top.verdicts(top.against(t, 1.0, by=("variant",)), top.travel_time(t, by=("variant",)), ("prl",),
                     by=("variant",)).iloc[0]
    assert v.cheaper and v.cases_held and v.not_slower and v.cheapest == "mpc"
    t = _table(prl_case0=50.0, top_time=101.0, cheap_cases=2)  # PRL cheaper on 2 of 10; clairvoyant 1% slower
    v = top.verdicts(top.against(t, 1.0, by=("variant",)), top.travel_time(t, by=("variant",)), ("prl",),
                     by=("variant",)).iloc[0]
    assert not v.cases_held and not v.not_slower and v.slower == pytest.approx(0.01)


def test_a_margin_below_five_percent_is_not_cheaper():
    t = pd.concat([_table(), pd.DataFrame(_rows("baseline0", [103.0] * 10))])
    v = top.verdicts(top.against(t, 1.0), top.travel_time(t), ("prl",)).iloc[0]
    assert not v.cheaper and v.min_margin == pytest.approx(1 - 100 / 103)


def test_the_section_counts_the_groups_and_is_empty_without_clairvoyant():
    text = "\n".join(top_of_scale(_table(), {"uncoordinated": 1.0}))
    assert "Cheaper by the margin and below oracle and mpc: 1 of 1" in text and "| uncoordinated | v1 |" in text
    assert top_of_scale(_table().query("method != 'clairvoyant'"), {}) == []
