"""The edge over steady driving (``reports.edge``) and the specialists-against-generalists lines,
on tables whose answers are known."""
from __future__ import annotations

import math

import pandas as pd
import pytest

from ecodrive_bench.reports.edge import edges
from ecodrive_bench.reports.generalisation import specialists_against_generalists


def _rows(method: str, energies: dict[int, list[float]], travel: float = 0.0, **extra) -> list[dict]:
    """One row per (seed, case): ``energies[seed][case]``; ``train_seed`` -1 for a method with
    no policy (pass a single key -1)."""
    return [{"method": method, "signals": "uncoordinated", "train_seed": seed, "case": case, "energy": e,
             "travel_time": travel, **extra} for seed, es in energies.items() for case, e in enumerate(es)]


def test_the_edge_is_the_share_below_the_reference_with_a_ci_over_seeds():
    df = pd.DataFrame(_rows("baseline0", {-1: [100.0] * 4}) + _rows("prl", {0: [90.0] * 4, 1: [80.0] * 4}))
    row = edges(df, phi=1.0).set_index("method").loc["prl"]
    assert row.cost == pytest.approx(0.15) and row.energy == pytest.approx(0.15) and row.seeds == 2
    assert 0.10 <= row.cost_ci_low <= 0.15 <= row.cost_ci_high <= 0.20 and row.cost_ci_low < row.cost_ci_high


def test_one_seed_has_no_ci_and_time_counts_through_phi():
    df = pd.DataFrame(_rows("baseline0", {-1: [100.0, 100.0]}, travel=100.0) + _rows("prl", {0: [100.0, 100.0]}, travel=50.0))
    row = edges(df, phi=2.0).set_index("method").loc["prl"]
    assert row.cost == pytest.approx(1 - 200.0 / 300.0) and row.energy == pytest.approx(0.0)
    assert math.isnan(row.cost_ci_low) and math.isnan(row.cost_ci_high)


def test_a_family_edge_weighs_each_variant_equally_and_names_the_worst():
    df = pd.DataFrame(_rows("baseline0", {-1: [100.0] * 2}, variant="a") + _rows("prl", {0: [90.0] * 2}, variant="a")
                      + _rows("baseline0", {-1: [50.0] * 6}, variant="b") + _rows("prl", {0: [35.0] * 6}, variant="b"))
    row = edges(df, phi=1.0, by=("variant",)).set_index("method").loc["prl"]
    assert row.cost == pytest.approx((0.1 + 0.3) / 2) and row.cost_worst == pytest.approx(0.1)


def test_a_seed_that_misses_a_case_gives_no_edge():
    rows = _rows("baseline0", {-1: [100.0] * 3}) + _rows("prl", {0: [90.0] * 3, 1: [80.0] * 2})
    assert math.isnan(edges(pd.DataFrame(rows), phi=1.0).set_index("method").loc["prl"].cost)


def test_the_targets_read_met_and_missed_with_their_margins():
    family = pd.DataFrame(
        _rows("baseline0", {-1: [100.0] * 2}, variant="a") + _rows("prl-family", {0: [95.0] * 2}, variant="a")
        + _rows("baseline0", {-1: [100.0] * 2}, variant="b") + _rows("prl-family", {0: [101.0] * 2}, variant="b")
        + _rows("prl", {0: [99.0] * 2}, variant="a") + _rows("prl", {0: [99.0] * 2}, variant="b"))
    paper = pd.DataFrame(_rows("baseline0", {-1: [100.0] * 3}) + _rows("prl", {0: [90.0] * 3})
                         + _rows("prl-family", {0: [93.0] * 3}))
    text = "\n".join(specialists_against_generalists(family, paper, {"uncoordinated": 1.0}))
    assert "### Specialists against generalists" in text
    # family mean edge (5% - 1%) / 2 = 2% against PRL's 10% in distribution: missed by 8 points
    assert "PRL-family's cost edge +2.0% against PRL's +10.0% on its own corridor: missed by 8.0 points" in text
    assert "PRL-family's worst edge -1.0%: missed (worst variant -1.0%)" in text
    assert "PRL-family costs 93.0 against PRL's 90.0 (+3.3%; within 2%): missed by 1.3 points" in text


def test_no_generalist_no_section():
    family = pd.DataFrame(_rows("baseline0", {-1: [100.0]}, variant="a") + _rows("prl", {0: [90.0]}, variant="a"))
    assert specialists_against_generalists(family, None, {}) == []
