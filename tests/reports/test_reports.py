from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run
from ecodrive_bench.reports import metrics, stats
from ecodrive_bench.reports.build import build


def test_metric_functions():
    assert stats.iqm(np.array([0, 1, 2, 3, 4, 5, 6, 100.0])) == pytest.approx(3.5)
    assert stats.probability_of_improvement(np.array([1.0, 2.0]), np.array([3.0, 4.0])) == 1.0
    assert stats.probability_of_improvement(np.array([1.0]), np.array([1.0])) == 0.5
    x = np.random.default_rng(0).normal(10, 1, 200)
    lo, hi = stats.bootstrap_ci(x)
    assert lo < x.mean() < hi and hi - lo < 0.6
    assert metrics.improvement(184.93, 253.79) == pytest.approx(0.2713, abs=1e-4)  # Table 4's 27.13%


def test_table4_against_the_paper():
    res = pd.DataFrame({"method": ["baseline"] * 2 + ["prl"] * 2, "signals": ["uncoordinated"] * 4,
                        "energy": [250.0, 260.0, 180.0, 190.0], "travel_time": [250.0, 270.0, 280.0, 300.0]})
    t4 = metrics.table4(res).set_index("method")
    assert t4.loc["prl", "energy_imp"] == pytest.approx((255 - 185) / 255)
    assert t4.loc["prl", "paper_energy_imp"] == pytest.approx(0.2713, abs=1e-4)
    assert t4.loc["baseline", "energy_vs_paper"] == pytest.approx(255 / 253.79 - 1)
    costs = metrics.paper_costs(t4.reset_index(), {"uncoordinated": 2.0}).set_index("method")
    assert costs.loc["prl", "cost"] == pytest.approx(185 + 2 * 290)
    assert costs.loc["prl", "paper_cost"] == pytest.approx(184.93 + 2 * 289.82)  # Table 4's PRL row
    assert costs.loc["prl", "cost_vs_paper"] == pytest.approx(765 / (184.93 + 2 * 289.82) - 1)
    assert metrics.paper_costs(t4.reset_index(), {"coordinated": 1.0}).empty  # no row of that setting


def test_signal_bands():
    states = [["G", "r"]] * 3 + [["r", "r"]] * 2 + [["G", "G"]] * 2
    steps = pd.DataFrame({"time": np.arange(7.0) + 100, "x": np.arange(7.0) * 10 + 5, "tls_states": states})
    bands = metrics.signal_bands(steps, {"J1": 105.0, "J2": 205.0}, {"J1": 0, "J2": 0})
    j1 = bands[bands.tls == "J1"]
    assert j1.green.tolist() == [True, False, True] and j1.t_start.tolist() == [0.0, 3.0, 5.0]
    assert (bands.x.unique() == [100.0, 200.0]).all()


def test_report_from_a_run(tmp_path):
    run(parse(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--methods", "baseline", "glosa"]),
        progress=False)
    index, _ = build(tmp_path / "logs" / "smoke", tmp_path / "report")
    text = index.read_text()
    assert "## Table 4" in text and "231.13" in text and "253.79" in text  # published values beside ours
    assert "- baseline, uncoordinated: " in text and f"against {253.79 + 260.21:.1f} (phi = 1 Wh/s; " in text
    for name in ("table4.md", "table4.tex", "statistics.md", "index.html"):
        assert (tmp_path / "report" / name).is_file()
    figs = sorted(p.name for p in (tmp_path / "report" / "figures").iterdir())
    assert "violin-coordinated.png" in figs and "violin-uncoordinated.pdf" in figs
    assert sum(n.startswith("compare-") and n.endswith(".png") for n in figs) == 6  # 3 cases x 2 settings
    assert "<img src='figures/violin-coordinated.png'" in (tmp_path / "report" / "index.html").read_text()
    # the return by reward component: read from the step logs, adding up to the harness's return
    assert "## Return by reward component" in text
    parts = pd.read_csv(tmp_path / "report" / "return_parts.csv")
    results = pd.read_parquet(tmp_path / "logs" / "smoke" / "results.parquet")
    assert len(parts) == 4 and parts.episodes.tolist() == [3, 3, 3, 3]
    comps = [c for c in parts.columns if c not in ("method", "signals", "episodes", "reward")]
    assert {"speed", "energy", "time"} <= set(comps) and "distance" not in comps  # all-zero columns dropped
    np.testing.assert_allclose(parts[comps].sum(axis=1), parts.reward, rtol=1e-9)
    expect = results.groupby(["method", "signals"])["return"].mean()
    for r in parts.itertuples():
        assert r.reward == pytest.approx(expect[(r.method, r.signals)], rel=1e-9)
        assert r.time < 0 and r.energy < 0


def test_stratified_seed_bootstrap_and_across_seeds():
    rng = np.random.default_rng(3)
    # 4 seeds x 30 cases; the CI widens with the spread between seeds, and resampling seeds per
    # case (each case a stratum) makes it narrower than the seed means' range
    offsets = np.array([0.0, 10.0, 20.0, 30.0])
    noise = rng.normal(0, 1, (4, 30))
    scores = 200 + offsets[:, None] + noise
    lo, hi = stats.stratified_seed_bootstrap(scores)
    assert lo < scores.mean() < hi and hi - lo < 30
    lo2, hi2 = stats.stratified_seed_bootstrap(200 + 2 * offsets[:, None] + noise)
    assert hi2 - lo2 > 1.5 * (hi - lo)
    assert np.isnan(stats.stratified_seed_bootstrap(scores[:1])).all()  # one seed: no spread to sample
    rows = [{"method": "prl", "signals": "coordinated", "train_seed": s, "case": c, "energy": scores[s, c],
             "travel_time": 100.0 + s} for s in range(4) for c in range(30)]
    rows.append({"method": "prl", "signals": "coordinated", "train_seed": 0, "case": 99, "energy": 1e6,
                 "travel_time": 1e6})  # a case only one seed ran is left out
    agg = metrics.across_seeds(pd.DataFrame(rows)).set_index("metric")
    assert agg.loc["energy", "seeds"] == 4 and agg.loc["energy", "cases"] == 30
    assert agg.loc["energy", "mean"] == pytest.approx(scores.mean())
    assert agg.loc["travel_time", "seed_min"] == 100.0 and agg.loc["travel_time", "seed_max"] == 103.0


def test_optimality_gaps_by_hand():
    rows = []
    for c, (eb, tb, e0, t0, em, tm) in enumerate([(100.0, 200.0, 250.0, 250.0, 200.0, 240.0),
                                                   (110.0, 190.0, 260.0, 240.0, 210.0, 250.0)]):
        bound = {"cost_bound": eb + tb, "energy_bound": 90.0}
        rows.append({"method": "baseline", "signals": "uncoordinated", "case": c, "energy": e0, "travel_time": t0, **bound})
        rows.append({"method": "prl", "signals": "uncoordinated", "case": c, "energy": em, "travel_time": tm, **bound})
    g = metrics.optimality_gaps(pd.DataFrame(rows), phi=1.0).set_index("method")
    assert g.loc["baseline", "cost_gap"] == pytest.approx(np.mean([500 / 300 - 1, 500 / 300 - 1]))
    assert g.loc["prl", "cost_gap"] == pytest.approx(np.mean([440 / 300 - 1, 460 / 300 - 1]))
    assert g.loc["prl", "share_closed"] == pytest.approx((500 - 450) / (500 - 300))
    assert g.loc["baseline", "share_closed"] == pytest.approx(0.0)
    assert g.loc["prl", "energy_gap_equal_time"] == pytest.approx(np.mean([200 / 90 - 1, 210 / 90 - 1]))


def test_the_sweep_header_counts_jobs_when_seeds_differ_between_configurations():
    from ecodrive_bench.reports.experiments import _jobs_text

    full = pd.DataFrame({"config": ["a", "a", "b", "b"], "seed": [0, 1, 0, 1]})
    assert _jobs_text(full) == "2 configurations x 2 seeds"
    uneven = pd.DataFrame({"config": ["a", "a", "a", "b"], "seed": [0, 1, 2, 0]})
    assert _jobs_text(uneven) == "4 jobs: 2 configurations, 1-3 training seeds each"


def test_a_method_whose_trips_do_not_finish_is_warned_about(smoke_report, tmp_path):
    """A results table where one baseline episode was cut at the truncation: the report says so
    under Warnings instead of letting its energy pass for a saving."""
    import shutil

    from ecodrive_bench.reports.load import unfinished_warnings

    run_dir = tmp_path / "run"
    shutil.copytree(smoke_report["run"], run_dir)
    results = pd.read_parquet(run_dir / "results.parquet")
    assert unfinished_warnings(results) == []
    first = results.index[(results.method == "baseline") & (results.signals == "coordinated")][0]
    results.loc[first, ["terminated", "truncated"]] = [False, True]
    results.to_parquet(run_dir / "results.parquet")
    index, warnings = build(run_dir, tmp_path / "report")
    assert any(w.startswith("baseline, coordinated: 1 of 3 episodes did not reach") for w in warnings)
    assert "did not reach the corridor's end" in index.read_text()


def test_probability_of_improvement_is_paired_by_case():
    """A method that beats the baseline on every case by 1 Wh, where the cases spread over 100 Wh:
    paired by case it is 1.0; pooled over all pairs of episodes it would be about 0.5."""
    rng = np.random.default_rng(0)
    difficulty = rng.uniform(150, 250, 100)
    base = difficulty[None, :]
    method = np.stack([difficulty - 1.0 - 0.1 * s for s in range(3)])  # three training seeds
    assert stats.probability_of_improvement(method, base) == 1.0
    pooled = np.mean(method.reshape(-1)[:, None] < base.reshape(-1)[None, :])
    assert 0.45 < pooled < 0.55  # what the pooled form measured
    assert stats.probability_of_improvement_ci(method, base) == (1.0, 1.0)
    worse = np.vstack([method[:2], difficulty[None, :] + 1.0])  # one seed loses on every case
    lo, hi = stats.probability_of_improvement_ci(worse, base)
    assert stats.probability_of_improvement(worse, base) == pytest.approx(2 / 3)
    assert lo < 2 / 3 < hi <= 1.0
    with pytest.raises(ValueError, match="pair them by case"):
        stats.probability_of_improvement(method[:, :10], base)


def test_the_statistics_table_pairs_by_case_from_results_rows():
    rng = np.random.default_rng(1)
    difficulty = rng.uniform(150, 250, 20)
    rows = [{"method": "baseline", "signals": "coordinated", "train_seed": -1, "case": c, "energy": e,
             "travel_time": 200.0} for c, e in enumerate(difficulty)]
    rows += [{"method": "prl", "signals": "coordinated", "train_seed": s, "case": c, "energy": e - 0.5,
              "travel_time": 210.0} for s in range(2) for c, e in enumerate(difficulty)]
    st = metrics.statistics(pd.DataFrame(rows)).set_index(["method", "metric"])
    assert st.loc[("prl", "energy"), "p_improve_vs_baseline"] == 1.0
    assert st.loc[("prl", "travel_time"), "p_improve_vs_baseline"] == 0.0
    assert np.isnan(st.loc[("baseline", "energy"), "p_improve_vs_baseline"])
