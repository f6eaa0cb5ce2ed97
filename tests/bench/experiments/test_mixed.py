from __future__ import annotations

import sys

import pandas as pd
import pytest

from ecodrive_bench.bench.experiments import mixed
from ecodrive_bench.bench.experiments.mixed import Cell, _done, run_cell
from ecodrive_bench.bench.logs.mcaplog import read_log
from ecodrive_bench.bench.training.train import train
from ecodrive_bench.reports.build import build
from ecodrive_bench.reports.metrics import mixed_cells, mpr_effect


def test_mixed_cell_with_a_policy_and_resume(tmp_path, monkeypatch):
    train("prl", "uncoordinated", 1, seed=0, out=tmp_path / "run", models=tmp_path / "models",
          agent_config={"learning_starts": 64, "batch_size": 16}, progress=False, validation_cases=1)
    cell = Cell("uncoordinated", 0.5, 300, 0, 400.0, str(tmp_path / "cell.mcap"),
                str(tmp_path / "models" / "prl-uncoordinated" / "s0"))
    assert _done(cell) is None
    row = run_cell(cell)
    assert row["hdv_vehicles"] > 0 and row["collisions"] == 0
    assert row["wall_s"] > 0  # the cell's cost is logged, for sweep estimates
    data = read_log(cell.path)
    kinds = [v.kind for v in data.fleet_vehicles]
    assert data.fleet_cell.mpr == 0.5 and 0.3 < kinds.count("cv") / len(kinds) < 0.7  # CVs ran under PRL
    assert len(data.fleet_vehicles) >= row["all_vehicles"]
    assert _done(cell) == row  # a finished cell is read back, not rerun
    # the report's mixed-traffic section, from the cells' rows as bench.experiments.mixed collects them
    plain = Cell("uncoordinated", 0.0, 300, 0, 400.0, str(tmp_path / "cell0.mcap"), "")
    run = tmp_path / "logs" / "m"
    (run / "mixed").mkdir(parents=True)
    pd.DataFrame([run_cell(plain), row]).to_parquet(run / "mixed" / "mixed.parquet")
    index, _ = build(run, tmp_path / "report")
    text = index.read_text()
    assert "within each finished repetition" in text  # the one repetition has the whole (2-cell) grid
    assert "## Mixed traffic" in text and (tmp_path / "report" / "figures" / "mixed-traffic.png").is_file()
    effect = mpr_effect(mixed_cells(pd.read_parquet(run / "mixed" / "mixed.parquet")))
    assert effect.all_energy_change.iloc[0] == 0 and effect.all_energy_change.notna().all()
    # a finished cell of another PRL policy is not reused for the one shipped now
    import json

    import pytest

    from ecodrive_bench.bench.experiments.mixed import CellMismatch

    man = tmp_path / "models" / "prl-uncoordinated" / "s0" / "manifest.json"
    shipped = man.read_text()
    man.write_text(json.dumps({**json.loads(shipped), "sha256": "0" * 64}))
    with pytest.raises(CellMismatch, match="PRL policy sha256"):
        _done(cell)
    man.write_text(shipped)
    # nor is one whose CVs ran under another safety layer (SUMO speed mode); a cell without CVs is
    import ecodrive_bench.bench.experiments.mixed as mixed_module
    import ecodrive_bench.envs.sumo as sumo_module

    assert data.meta["speed_mode"] == str(sumo_module.SPEED_MODE_SAFE)
    monkeypatch.setattr(mixed_module, "SPEED_MODE_SAFE", 31)
    with pytest.raises(CellMismatch, match=r"CV speed mode 27 \(asked 31\)"):
        _done(cell)
    assert _done(plain)["mpr"] == 0.0


def test_mixed_claims_pass_fail_and_not_checked():
    from ecodrive_bench.bench.regression.mixed_cells import claims

    def cells(e1: float, hdv_v: float) -> pd.DataFrame:
        rows = []
        for s in ("coordinated", "uncoordinated"):
            for mpr, e, v, he, hv in ((0.0, 150.0, 8.0, 150.0, 8.0), (0.5, 140.0, 7.9, 149.0, hdv_v),
                                      (1.0, e1, 7.8, float("nan"), float("nan"))):
                rows.append({"signals": s, "mpr": mpr, "all_energy_per_km": e, "all_space_mean_speed": v,
                             "hdv_energy_per_km": he, "hdv_space_mean_speed": hv, "all_energy": 2.2 * e,
                             "all_speed": v + 1.0, "all_vehicles": 200, "collisions": 0})
        return pd.DataFrame(rows)

    assert {st for _, st, _ in claims(cells(130.0, 7.9))} == {"PASS"}
    failed = [n for n, st, _ in claims(cells(155.0, 7.0)) if st == "FAIL"]
    assert len(failed) == 4 and all("energy per km falls" in n or "space_mean_speed" in n for n in failed)
    assert claims(None)[0][1] == "NOT CHECKED"


def test_lane_gaps_reads_the_grid():
    import numpy as np

    from ecodrive_bench.bench.experiments.stalls import lane_gaps

    grid = np.ones((60, 3), np.float32)  # 10 rows behind the front bumper, 50 ahead
    grid[10 + 12, 0] = 0.0  # 12 m free ahead in lane 0
    grid[10 - 3, 1] = 0.0  # something 3 m behind in lane 1
    ahead, behind = lane_gaps(grid, front=10, cell=1.0)
    assert ahead[0] == 12.0 and np.isnan(ahead[1]) and np.isnan(ahead[2])
    assert behind[1] == 3.0 and np.isnan(behind[0])


def test_stall_trace_records_what_the_policy_did(tmp_path):
    """A PRL network whose 'stay' head always brakes (so that CVs stall whatever the shipped policy
    does) in the regression's MPR-1 cell, 200 s: every record is a standing CV with free road and
    no red, and the action applied is the greedy allowed head's."""
    import pytest

    from ecodrive_bench.bench.experiments.stalls import HEADS, main, trace
    from ecodrive_bench.bench.methods.policies import load_policy, policy_dir, save_policy
    from ecodrive_bench.envs.action import LATERAL

    models = tmp_path / "models"
    train("prl", "coordinated", 1, seed=0, out=tmp_path / "run", models=models,
          agent_config={"learning_starts": 64, "batch_size": 16}, progress=False, validation_cases=1)
    state, manifest = load_policy(policy_dir("prl", "coordinated", models), "prl")
    last = max(k for k in state["param"] if k.endswith(".bias"))  # the output layer: tanh(-5) -> a_min
    state["param"][last][LATERAL.index(0)] = -5.0
    save_policy(policy_dir("prl", "coordinated", models), state, manifest)
    rows, summary = trace("coordinated", 1.0, 300, 200, (1,), models=models)
    assert rows and summary["stall_steps"] >= len(rows)
    for r in rows:
        assert r["speed"] < 0.5 and r["red"] != 1.0 and not r[f"ahead_{r['lane']}"] <= 10.0
        j = LATERAL.index(r["k"])
        assert r["mask"][j] == "1" and r["accel"] == r[f"a_{HEADS[j]}"]
        allowed = [i for i in range(3) if r["mask"][i] == "1"]
        assert max(allowed, key=lambda i: r[f"q_{HEADS[i]}"]) == j
    out = tmp_path / "s.parquet"
    out.write_bytes(b"keep")
    with pytest.raises(SystemExit):
        main(["--out", str(out), "--duration", "10"])
    assert out.read_bytes() == b"keep"  # not overwritten
    with pytest.raises(SystemExit):
        main(["--mpr", "0"])


def test_stay_ablation_masks_both_lane_changes():
    import numpy as np

    from ecodrive_bench.bench.experiments.mixed import _stay

    seen = []
    policy = _stay(lambda g, l, m: seen.append(m) or [(1, np.zeros(3))] * len(m))
    masks = np.ones((4, 3), np.int8)
    policy(None, None, masks)
    assert seen[0].tolist() == [[False, True, False]] * 4 and masks.all()  # the caller's masks untouched


def test_sweep_table_collects_every_finished_cell_and_refuses_a_mismatch(tmp_path, capsys):
    """MPR-0 cells (SUMO alone, 20 s): a second sweep over another demand keeps the first sweep's
    cell in the table; a rerun asking another duration for a finished cell is refused and the cell
    file is left as it was."""
    from ecodrive_bench.bench.experiments.mixed import main

    args = ["--signals", "coordinated", "--mpr", "0", "--reps", "1", "--workers", "1", "--logs", str(tmp_path),
            "--run-id", "m"]
    assert main(args + ["--demand", "200", "--duration", "20"]) == 0
    assert main(args + ["--demand", "300", "--duration", "20"]) == 0
    table = pd.read_parquet(tmp_path / "m" / "mixed" / "mixed.parquet")
    assert sorted(table.demand) == [200.0, 300.0] and (table.duration == 20.0).all()
    cell = tmp_path / "m" / "mixed" / "coordinated" / "mpr0.0-d200-r0.mcap"
    before = cell.read_bytes()
    assert main(args + ["--demand", "200", "--duration", "30"]) == 2
    assert "duration 20.0 (asked 30.0)" in capsys.readouterr().err
    assert cell.read_bytes() == before


def test_mixed_coverage_and_like_for_like_effect():
    from ecodrive_bench.reports.metrics import mixed_coverage

    rows = pd.DataFrame([{"signals": "coordinated", "mpr": m, "demand": d, "rep": 0, "all_energy_per_km": e,
                          "all_pending": 0.0 if m == 0 else 4.0}
                         for m, d, e in ((0.0, 200, 100.0), (0.0, 700, 300.0), (1.0, 200, 90.0))])
    cover = mixed_coverage(rows).set_index("mpr")
    assert cover.loc[0.0, "missing"] == 0 and cover.loc[1.0, "missing"] == 1 and cover.loc[1.0, "demands"] == "200"
    effect = mpr_effect(mixed_cells(rows)).set_index("mpr")
    # MPR 1 has only 200 veh/h/lane: both levels are compared there (90 / 100), not against the 200-700 mean
    assert abs(effect.loc[1.0, "all_energy_per_km_change"] - (-0.1)) < 1e-12
    assert pd.isna(effect.loc[1.0, "all_pending_change"])  # 4 against 0 has no relative change


def test_cells_run_repetition_by_repetition(tmp_path):
    from ecodrive_bench.bench.experiments.mixed import parse, plan

    cells = plan(parse(["--reps", "3", "--mpr", "0", "1", "--demand", "200", "700"]), tmp_path)
    per_rep = 2 * 2 * 2  # settings x MPR x demand
    assert len(cells) == 3 * per_rep
    assert [c.rep for c in cells] == [r for r in range(3) for _ in range(per_rep)]
    assert len({c.path for c in cells}) == len(cells)


def test_mpr_effect_spread_pairs_each_repetition_and_skips_unfinished_ones():
    from ecodrive_bench.reports.metrics import mpr_effect_spread

    # rep 0: -10% at MPR 1; rep 1: -30%; rep 2 lacks a cell (not counted)
    rows = pd.DataFrame([{"signals": "uncoordinated", "mpr": m, "demand": d, "rep": r,
                          "all_energy_per_km": base * (1 - cut * m)}
                         for r, base, cut in ((0, 100.0, 0.1), (1, 200.0, 0.3), (2, 50.0, 0.9))
                         for m in (0.0, 1.0) for d in (200, 700) if not (r == 2 and m == 1.0 and d == 700)])
    s = mpr_effect_spread(rows).set_index("mpr")
    assert s.loc[1.0, "reps"] == 2
    assert abs(s.loc[1.0, "all_energy_per_km_change_mean"] - (-0.2)) < 1e-12  # not the pooled -23.3%
    assert abs(s.loc[1.0, "all_energy_per_km_change_min"] - (-0.3)) < 1e-12
    assert abs(s.loc[1.0, "all_energy_per_km_change_max"] - (-0.1)) < 1e-12
    assert mpr_effect_spread(rows[rows.rep == 2]).empty
    # the pooled effect over the runs every MPR level has drops rep 2's MPR-0 cell at 700 as well
    from ecodrive_bench.reports.metrics import common_runs

    kept = common_runs(rows)
    assert len(kept) == 10 and not ((kept.rep == 2) & (kept.demand == 700)).any()
    effect = mpr_effect(mixed_cells(kept)).set_index("mpr")
    # MPR 0: d200 (100+200+50)/3, d700 (100+200)/2 -> 133.33; MPR 1: (90+140+5)/3, (90+140)/2 -> 96.67
    assert abs(effect.loc[1.0, "all_energy_per_km_change"] - (96.666667 / 133.333333 - 1)) < 1e-6


def test_mixed_claims_on_a_grid():
    from ecodrive_bench.reports.claims import mixed_claims

    effect = pd.DataFrame({"signals": ["coordinated"] * 3 + ["uncoordinated"] * 2, "mpr": [0.0, 0.5, 1.0, 0.0, 0.5],
                           "all_energy_per_km_change": [0.0, -0.1, -0.2, 0.0, 0.01],
                           "all_space_mean_speed_change": [0.0, -0.02, -0.3, 0.0, 0.0],
                           "hdv_energy_per_km_change": [0.0, 0.04, None, 0.0, 0.06],
                           "hdv_space_mean_speed_change": [0.0, -0.08, None, 0.0, 0.01]})
    c = mixed_claims(effect, speed_loss_tol=0.1, hdv_tol=0.05, paper_saving=0.138).set_index(["signals", "claim"]).status
    assert c["coordinated", "fleet energy per km falls from MPR 0 to 1"] == "PASS"
    assert c["coordinated", "space-mean speed loss at MPR 1 < 10%"] == "FAIL"  # -30%
    assert c["coordinated", "HDV energy per km not worse by > 5% at any MPR in (0, 1)"] == "PASS"
    assert c["coordinated", "HDV space-mean speed not worse by > 5% at any MPR in (0, 1)"] == "FAIL"  # -8%
    assert c["coordinated", "fleet energy per km below MPR 0 at every MPR > 0"] == "PASS"
    assert c["uncoordinated", "fleet energy per km below MPR 0 at every MPR > 0"] == "FAIL"  # +1% at 0.5
    assert c["uncoordinated", "fleet energy and speed at MPR 1 against 0"] == "NOT CHECKED"
    assert c["uncoordinated", "HDV energy per km not worse by > 5% at any MPR in (0, 1)"] == "FAIL"  # +6%


def test_cv_brakes_for_an_hdv_stopping_at_yellow(tmp_path):
    """Uncoordinated, MPR 0.6, 200 veh/h/lane, the shipped PRL policy: at t = 493 s an HDV stops
    at a yellow light at its decel of 4.5 m/s^2, 13 m ahead of a CV whose decel (the action bound)
    is 4 m/s^2. The safety layer (speed mode 27) lets SUMO brake it as hard as its safe speed asks,
    so it stops short (with speed mode 31 it could brake no harder than 4 m/s^2 and would hit it)."""
    from ecodrive_bench.bench.methods.policies import policy_dir

    cell = Cell("uncoordinated", 0.6, 200, 0, 520.0, str(tmp_path / "cell.mcap"),
                str(policy_dir("prl", "uncoordinated")))
    row = run_cell(cell)
    assert row["cv_vehicles"] > 0 and row["collisions"] == 0 and row["teleports"] == 0

@pytest.mark.parametrize("argv, flag, value, accepted", [
    (["--reps", "0"], "--reps", "'0'", "1.."),
    (["--reps", "nan"], "--reps", "'nan'", "1.."),
    (["--duration", "5"], "--duration", "'5'", "[10, 7200]"),
    (["--mpr", "nan"], "--mpr", "'nan'", "[0, 1]"),
    (["--mpr", "0.2", "2"], "--mpr", "'2'", "[0, 1]"),
    (["--demand", "0"], "--demand", "'0'", "(0, 1000]"),
])
def test_a_bad_mixed_flag_names_just_itself(argv, flag, value, accepted, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive mixed"])
    with pytest.raises(SystemExit) as e:
        mixed.parse(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2
    why = "is not an integer" if ".." in accepted and not value.strip("'").lstrip("-").isdigit() else "is out of range"
    assert err == [f"ecodrive mixed: error: argument {flag}: {value} {why}; accepted: {accepted}"]


def test_mixed_errors_after_parsing_start_with_the_command(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive mixed"])
    monkeypatch.setattr(mixed, "policy_dir", lambda method, signals: tmp_path / "none" / f"{method}-{signals}")
    assert mixed.main(["--signals", "coordinated", "--mpr", "0.5", "--logs", str(tmp_path / "logs")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ecodrive mixed: error: no trained PRL policy for coordinated")
    assert not (tmp_path / "logs").exists()
