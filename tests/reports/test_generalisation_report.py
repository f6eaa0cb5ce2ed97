"""The generalisation section's numbers on a hand-made table, and its bad input."""
from __future__ import annotations

import sys

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.reports import metrics


def rows(variant, method, energies, times, signals="coordinated"):
    return [{"variant": variant, "signals": signals, "method": method, "case": i, "energy": e, "travel_time": t}
            for i, (e, t) in enumerate(zip(energies, times))]


GEN = pd.DataFrame(rows("a", "baseline", [100, 300], [200, 200]) + rows("a", "prl", [80, 240], [220, 200])
                   + rows("b", "baseline", [100, 100], [100, 100]) + rows("b", "prl", [110, 130], [100, 120])
                   + rows("b", "glosa", [90], [100]))


def test_changes_against_the_baseline_per_variant():
    ch = metrics.changes_vs_baseline(GEN, by=("variant", "signals")).set_index(["variant", "method"])
    assert ch.loc[("a", "prl"), "energy_change"] == pytest.approx(160 / 200 - 1)  # -20%
    assert ch.loc[("a", "prl"), "time_change"] == pytest.approx(210 / 200 - 1)
    assert ch.loc[("b", "prl"), "energy_change"] == pytest.approx(0.2)
    assert ch.loc[("b", "baseline"), "energy_change"] == 0
    # glosa ran case 0 only: compared with the baseline's case 0, not its mean over both
    assert ch.loc[("b", "glosa"), "energy_change"] == pytest.approx(-0.1) and ch.loc[("b", "glosa"), "episodes"] == 1


def test_a_group_without_the_baseline_has_no_change():
    ch = metrics.changes_vs_baseline(pd.DataFrame(rows("c", "prl", [1.0], [2.0])), by=("variant", "signals"))
    assert np.isnan(ch.energy_change.iloc[0]) and ch.episodes.iloc[0] == 1


def test_the_family_summary_beside_the_in_distribution_change():
    per = metrics.changes_vs_baseline(GEN, by=("variant", "signals"))
    ind = metrics.changes_vs_baseline(pd.DataFrame(rows(None, "baseline", [100], [100]) + rows(None, "prl", [70], [105])))
    s = metrics.generalisation_summary(per, ind).set_index("method")
    assert s.loc["prl", "variants"] == 2
    assert s.loc["prl", "energy_change"] == pytest.approx((-0.2 + 0.2) / 2)
    assert s.loc["prl", "energy_change_worst"] == pytest.approx(0.2)
    assert s.loc["prl", "time_change_worst"] == pytest.approx(0.1)
    assert s.loc["prl", "in_dist_energy_change"] == pytest.approx(-0.3)
    assert s.loc["prl", "energy_gap"] == pytest.approx(0.3)  # the edge over the baseline shrinks by 30 points
    assert np.isnan(s.loc["glosa", "in_dist_energy_change"])
    assert "in_dist_energy_change" not in metrics.generalisation_summary(per).columns


@pytest.mark.parametrize("make, words", [
    (lambda p: None, "not a run folder"),
    (lambda p: (p.mkdir(), (p / "generalisation.parquet").write_text("junk")), "not a readable results table"),
    (lambda p: (p.mkdir(), pd.DataFrame({"x": [1]}).to_parquet(p / "generalisation.parquet")), "no 'variant' column"),
])
def test_a_bad_generalisation_folder_is_one_line(make, words, tmp_path, monkeypatch, capsys):
    from ecodrive_bench.reports.command import main

    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame({"mcap": []}).to_parquet(run / "results.parquet")
    make(tmp_path / "gen")
    monkeypatch.setattr(sys, "argv", ["ecodrive report"])
    rc = main([str(run), "--out", str(tmp_path / "out"), "--generalisation", str(tmp_path / "gen")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and words in err[0] and not (tmp_path / "out").exists()
