"""Each case's energy-optimal bound lands in results.parquet, below what SUMO's driver achieves."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.provenance import process_age
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
    median = json.loads((tmp_path / "smoke" / "manifest.json").read_text())["bound_wall_s_median"]
    assert median is None if (b.bound_source == "shipped").all() else median > 0  # only what this run solved
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
    assert "## Distance to the cost-optimal bound" in index.read_text()
    gaps = pd.read_csv(tmp_path / "report" / "optimality_gaps.csv").set_index("method")
    assert gaps.loc["baseline", "share_closed"] == 0.0 and (gaps.cost_gap > 0).all()
    assert "Distance to the cost-optimal bound" in (tmp_path / "report" / "index.html").read_text()


def test_bounds_are_written_case_by_case_so_a_kill_keeps_the_finished_ones(tmp_path):
    """The bounds phase rewrites bounds.parquet as each case finishes: interrupted after two of
    three cases, the two are kept, and the rerun solves only the third."""
    import pytest

    from ecodrive_bench.bench.cases.bounds import COLUMNS, BoundTask, attach

    results = pd.DataFrame({"method": ["baseline"] * 3, "signals": ["coordinated"] * 3, "case": [0, 1, 2],
                            "depart_time": [200.0, 210.0, 220.0], "travel_time": [190.0, 191.0, 192.0],
                            "terminated": [True] * 3})
    solved: list[int] = []

    def fake(task: BoundTask) -> dict:
        solved.append(task.case)
        return {c: 0.0 for c in COLUMNS} | {"signals": task.signals, "case": task.case,
                                            "depart_time": task.depart_time, "time_limit": task.time_limit}

    def interrupted(tasks, workers, fn):
        for t in tasks[:2]:
            yield fake(t)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        attach(tmp_path, results, 1, interrupted, progress=False)
    assert sorted(pd.read_parquet(tmp_path / "bounds.parquet").case) == [0, 1]
    solved.clear()
    out = attach(tmp_path, results, 1, lambda tasks, workers, fn: map(fake, tasks), progress=False)
    assert solved == [2] and out.cost_bound.notna().all()


def test_the_manifest_measures_the_floor_and_every_commands_wall_time(tmp_path, monkeypatch):
    """Every episode run records its seconds inside SUMO; the manifest has the phase times, SUMO's
    time, their ratio, and the wall time summed over every command that wrote the folder, of the
    episodes' and bounds' phases and of the whole commands (this process's start-up charged to its
    first run only)."""
    from ecodrive_bench.bench.harness import run as run_module

    monkeypatch.setattr(run_module, "_STARTED", [])  # as in a fresh process: no run before these
    age = process_age()  # [s] this process's start-up so far
    common = ["--profile", "smoke", "--logs", str(tmp_path), "--methods", "baseline", "--workers", "2"]
    first = run(parse([*common, "--signals", "coordinated"]), progress=False)
    df = run(parse([*common, "--signals", "uncoordinated"]), progress=False)
    kept = df[df.signals == "coordinated"].drop(columns="sumo_s").reset_index(drop=True)
    pd.testing.assert_frame_equal(kept, first.drop(columns="sumo_s").reset_index(drop=True), check_dtype=False)
    assert kept["return"].notna().all()  # every column kept, "return" (no Python identifier) too
    man = json.loads((tmp_path / "smoke" / "manifest.json").read_text())
    new = df[df.signals == "uncoordinated"]
    assert (new.sumo_s > 0).all() and (new.sumo_s < 60).all()
    assert df[df.signals == "coordinated"].sumo_s.isna().all()  # kept from the first command: not run now
    assert man["sumo_time_s"] == pytest.approx(new.sumo_s.sum(), abs=0.01)
    assert man["floor_ratio"] > 1 and set(man["phases_s"]) == {"before", "episodes", "bounds", "after"}
    assert man["wall_time_all_commands_s"] == pytest.approx(sum(c["wall_time_s"] for c in man["commands"]), abs=0.02)
    assert len(man["commands"]) == 2 and man["wall_time_all_commands_s"] > man["wall_time_s"]
    first, second = man["commands"]
    for c in (first, second):  # the whole command is its phases
        assert c["command_wall_s"] == pytest.approx(sum(c["phases_s"].values()), abs=0.05)
        assert c["command_wall_s"] > c["wall_time_s"] and min(c["phases_s"].values()) >= 0
    # the process started before the first run (pytest, the imports): charged to the first only
    assert first["phases_s"]["before"] >= age > second["phases_s"]["before"]
    assert man["command_wall_all_commands_s"] == pytest.approx(first["command_wall_s"] + second["command_wall_s"],
                                                               abs=0.02)


@pytest.mark.parametrize("scenario, solved", [({"network": "cologne3"}, 2), (None, 4)])
def test_a_networks_bound_is_solved_once_for_both_settings(tmp_path, scenario, solved):
    """On a network both settings pose one problem: a case whose departure and baseline time agree in
    both is solved once and its row written for each; on the generated arterial each setting's."""
    from ecodrive_bench.bench.cases import bounds

    results = pd.DataFrame([{"method": "baseline", "signals": s, "case": c, "depart_time": 500.0 + c,
                             "travel_time": 100.0 + c, "terminated": True, "seed": 7 + c, "insert_time": 490.0 + c}
                            for s in ("coordinated", "uncoordinated") for c in (0, 1)])
    asked = []

    def runner(tasks, workers, fn):
        asked.extend(tasks)
        for t in tasks:  # a stand-in for the DP: the task's own numbers
            yield {"signals": t.signals, "case": t.case, "depart_time": t.depart_time, "time_limit": t.time_limit,
                   "cost_bound": 1.0 + t.case, "bound_energy": 0.5, "bound_travel_time": 90.0, "energy_bound": 0.4,
                   "energy_bound_travel_time": 95.0, "bound_wall_s": 0.0, "bound_source": bounds.SOLVED}

    out = bounds.attach(tmp_path, results, 1, runner, scenario=scenario, progress=False,
                        shipped=tmp_path / "none.parquet")
    assert len(asked) == solved
    assert out.cost_bound.tolist() == [1.0 + c for c in out.case]  # every row of both settings has its case's bound
    written = pd.read_parquet(tmp_path / "bounds.parquet")
    assert sorted(zip(written.signals, written.case)) == sorted(zip(results.signals, results.case))
    assert written.bound_wall_s.isna().sum() == len(written) - solved  # the twins' rows took no DP time
