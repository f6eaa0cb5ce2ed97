"""The real-corridors section's pure parts (reports.real): means with CIs, the changes against
SUMO's driver and steady driving, the zero-shot edges; and a bad table refused in one line."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.reports import real
from ecodrive_bench.reports.load import RunError


def _table() -> pd.DataFrame:
    rows = []
    for variant, scale in (("a", 1.0), ("b", 2.0)):
        for case in range(6):
            for method, seed, e, t in (("baseline", -1, 100, 50), ("baseline0", -1, 80, 50),
                                       ("prl", 0, 70, 50), ("prl", 1, 90, 50)):
                rows.append({"variant": variant, "method": method, "signals": "coordinated", "case": case,
                             "train_seed": seed, "energy": scale * (e + case), "travel_time": float(t)})
    return pd.DataFrame(rows)


def test_summary_means_and_changes():
    s = real.summary(_table(), {"coordinated": 1.0}).set_index(["variant", "method"])
    a = s.loc[("a", "prl")]
    assert a.energy == pytest.approx(80 + 2.5) and a.travel_time == 50 and a.seeds == 2
    assert a.energy_ci_low <= a.energy <= a.energy_ci_high
    assert a.cost_vs_baseline0 == pytest.approx(0.0)  # seeds' mean 82.5 + 50 against 82.5 + 50
    assert s.loc[("a", "baseline0")].cost_vs_driver == pytest.approx((82.5 + 50) / (102.5 + 50) - 1)
    assert s.loc[("a", "baseline")].cost_vs_driver == 0.0


def test_edges_over_steady_driving_per_corridor_and_worst():
    t = _table()
    t.loc[(t.variant == "b") & (t.method == "prl"), "energy"] -= 20  # better on b only
    e = real.edge_rows(t, {"coordinated": 1.0}, None, None).iloc[0]
    assert e.method == "prl" and e.seeds == 2
    assert e.real_cost > 0 and e.real_cost_worst == pytest.approx(0.0)
    assert np.isnan(e.paper_cost) and np.isnan(e.heldout_cost)  # no such runs given


def _with_mcap(t: pd.DataFrame) -> pd.DataFrame:
    return t.assign(mcap=[f"{v}/{s}/{m}/case-{c:03d}.mcap" for v, s, m, c in zip(t.variant, t.signals, t.method, t.case)])


@pytest.mark.parametrize("spoil, words", [
    (lambda t: t.assign(energy="many"), "column 'energy'"),
    (lambda t: t.assign(travel_time=np.inf), "no row is left"),
    (lambda t: t.iloc[:0], "has no rows"),
    (lambda t: t.drop(columns=["variant"]), "no 'variant' column"),
    (lambda t: t.assign(signals="sideways"), "column 'signals'"),
])
def test_a_bad_table_is_one_line(spoil, words, tmp_path):
    spoil(_with_mcap(_table())).to_parquet(tmp_path / "real.parquet")
    with pytest.raises(RunError) as e:
        real.load(tmp_path)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_bad_rows_are_dropped_with_a_note(tmp_path):
    t = _with_mcap(_table())
    t.loc[0, "energy"] = np.nan
    t.to_parquet(tmp_path / "real.parquet")
    table, _, notes = real.load(tmp_path)
    assert len(table) == len(t) - 1 and len(notes) == 1 and "NaN" in notes[0]


@pytest.mark.parametrize("manifest, words", [
    ("fifo", "not a regular file"),
    ("zero", "not a regular file"),
    ('{"family": [1, 2], "variants": {}}', "'family' is a JSON list, expected an object"),
    ('{"variants": "g1"}', "'variants' is a JSON str, expected an object"),
])
def test_the_generalisation_folder_is_read_as_carefully_as_a_run(manifest, words, tmp_path):
    """``report --generalisation`` reads its folder through the one reader of family tables."""
    import os

    from ecodrive_bench.reports import generalisation

    _with_mcap(_table()).to_parquet(tmp_path / "generalisation.parquet")
    path = tmp_path / "manifest.json"
    if manifest == "fifo":
        os.mkfifo(path)
    elif manifest == "zero":
        path.symlink_to("/dev/zero")
    else:
        path.write_text(manifest)
    with pytest.raises(RunError) as e:
        generalisation.load(tmp_path)
    assert words in str(e.value) and "\n" not in str(e.value)


def _with_planners(top: float, mpc: float) -> pd.DataFrame:
    """``_table`` with clairvoyant (energy ``top``) and mpc (``mpc``) on every case of both corridors."""
    t = _table()
    extra = [{"variant": v, "method": m, "signals": "coordinated", "case": c, "train_seed": -1,
              "energy": (1.0 if v == "a" else 2.0) * (e + c), "travel_time": 50.0}
             for v in ("a", "b") for c in range(6) for m, e in (("clairvoyant", top), ("mpc", mpc))]
    return pd.concat([t, pd.DataFrame(extra)], ignore_index=True)


def test_headroom_shares_per_corridor():
    s = real.scale_rows(_with_planners(40, 60), {"coordinated": 1.0}).set_index(["variant", "method"])
    assert s.loc[("a", "baseline0")].share == pytest.approx(0.0)
    assert s.loc[("a", "clairvoyant")].share == pytest.approx(1.0)
    assert s.loc[("a", "mpc")].share == pytest.approx(0.5)  # baseline0 80, mpc 60, clairvoyant 40 (+ case)
    assert s.loc[("b", "mpc")].headroom == pytest.approx(2 * 40)
    a = s.loc[("a", "prl")]
    assert a.share_ci_low <= a.share <= a.share_ci_high and a.seeds == 2


def test_the_top_of_the_scale_is_judged_per_corridor():
    holds = real.scale_checks(real.summary(_with_planners(40, 60), {"coordinated": 1.0}))
    assert len(holds) == 2 and all(line.endswith("holds") for line in holds)
    misses = real.scale_checks(real.summary(_with_planners(79, 60), {"coordinated": 1.0}))
    assert all("does not hold" in line and "MPC" in line for line in misses)  # dearer than mpc
    assert all("Baseline0" in line for line in misses)  # 79 + 50 is not 5% below 80 + 50


def test_no_clairvoyant_no_headroom():
    assert real.scale_rows(_table(), {"coordinated": 1.0}).empty
    assert real.scale_checks(real.summary(_table(), {"coordinated": 1.0})) == []
