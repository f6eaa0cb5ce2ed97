"""Each case's energy-optimal bound lands in results.parquet, below what SUMO's driver achieves."""
from __future__ import annotations

import json

import pandas as pd

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run


def test_bounds_join_every_row_and_lie_below_the_baseline(tmp_path):
    opts = parse(["--profile", "smoke", "--logs", str(tmp_path), "--methods", "baseline", "baseline0",
                  "--signals", "uncoordinated", "--workers", "2", "--bounds"])
    df = run(opts, progress=False)
    assert df.cost_bound.notna().all() and df.energy_bound.notna().all()
    base = df[df.method == "baseline"].set_index("case")
    phi = 1.0  # the default reward's phi
    assert (base.cost_bound < base.energy + phi * base.travel_time).all()
    assert (base.energy_bound <= base.energy).all()  # the least energy in no more time than the baseline took
    b = pd.read_parquet(tmp_path / "smoke" / "bounds.parquet")
    assert len(b) == 3 and (b.bound_travel_time > 0).all() and (b.energy_bound_travel_time <= b.time_limit + 1e-9).all()
    assert json.loads((tmp_path / "smoke" / "manifest.json").read_text())["bound_wall_s_median"] > 0
    # a rerun solves nothing again
    mtime = (tmp_path / "smoke" / "bounds.parquet").stat().st_mtime_ns
    again = run(opts, progress=False)
    assert (tmp_path / "smoke" / "bounds.parquet").stat().st_mtime_ns == mtime
    pd.testing.assert_series_equal(again.cost_bound, df.cost_bound)


def test_the_report_shows_the_gaps(tmp_path):
    from ecodrive_bench.reports.build import build

    run(parse(["--profile", "smoke", "--logs", str(tmp_path), "--methods", "baseline", "baseline0",
               "--signals", "coordinated", "--workers", "2", "--bounds"]), progress=False)
    index, _ = build(tmp_path / "smoke", tmp_path / "report")
    assert "## Distance to the energy-optimal bound" in index.read_text()
    gaps = pd.read_csv(tmp_path / "report" / "optimality_gaps.csv").set_index("method")
    assert gaps.loc["baseline", "share_closed"] == 0.0 and (gaps.cost_gap > 0).all()
    assert "Distance to the energy-optimal bound" in (tmp_path / "report" / "index.html").read_text()
