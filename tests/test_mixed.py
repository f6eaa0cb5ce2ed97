from __future__ import annotations

from bench.mcaplog import read_log
from bench.mixed import Cell, _done, run_cell
from bench.train import train


def test_mixed_cell_with_a_policy_and_resume(tmp_path):
    train("prl", "uncoordinated", 1, seed=0, out=tmp_path / "run", models=tmp_path / "models",
          agent_config={"learning_starts": 64, "batch_size": 16}, progress=False)
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
