from __future__ import annotations

import pandas as pd

from bench.mcaplog import read_log
from bench.mixed import Cell, _done, run_cell
from bench.train import train
from reports.build import build
from reports.metrics import mixed_cells, mpr_effect


def test_mixed_cell_with_a_policy_and_resume(tmp_path):
    train("prl", "uncoordinated", 1, seed=0, out=tmp_path / "run", models=tmp_path / "models",
          agent_config={"learning_starts": 64, "batch_size": 16}, progress=False, validation_cases=1)
    cell = Cell("uncoordinated", 0.5, 300, 0, 400.0, str(tmp_path / "cell.mcap"),
                str(tmp_path / "models" / "prl-uncoordinated"))
    assert _done(cell) is None
    row = run_cell(cell)
    assert row["hdv_vehicles"] > 0 and row["collisions"] == 0
    data = read_log(cell.path)
    kinds = [v.kind for v in data.fleet_vehicles]
    assert data.fleet_cell.mpr == 0.5 and 0.3 < kinds.count("cv") / len(kinds) < 0.7  # CVs ran under PRL
    assert len(data.fleet_vehicles) >= row["all_vehicles"]
    assert _done(cell) == row  # a finished cell is read back, not rerun
    # the report's mixed-traffic section, from the cells' rows as bench.mixed collects them
    plain = Cell("uncoordinated", 0.0, 300, 0, 400.0, str(tmp_path / "cell0.mcap"), "")
    run = tmp_path / "logs" / "m"
    (run / "mixed").mkdir(parents=True)
    pd.DataFrame([run_cell(plain), row]).to_parquet(run / "mixed" / "mixed.parquet")
    index = build(run, tmp_path / "report")
    text = index.read_text()
    assert "## Mixed traffic" in text and (tmp_path / "report" / "figures" / "mixed-traffic.png").is_file()
    effect = mpr_effect(mixed_cells(pd.read_parquet(run / "mixed" / "mixed.parquet")))
    assert effect.all_energy_change.iloc[0] == 0 and effect.all_energy_change.notna().all()
