"""``ecodrive report`` on a run folder whose step logs are crafted (``conftest.py``): each refused
log is left out with a warning naming the file and the field, and the rest of the report is
written (before, a signal link past the signal states was an IndexError in ``signal_bands``, an
oracle plan without ``x`` a KeyError, and a bomb 2.5 GB of memory)."""
from __future__ import annotations

import json

import pandas as pd

from ecodrive_bench.reports.command import main


def test_the_report_leaves_out_each_crafted_log_with_a_warning(craft, bomb, tmp_path, capsys):
    run = tmp_path / "run"
    logs = {  # (method, case): the log written
        ("baseline", 0): craft.write_log(run / "coordinated/baseline/case-000.mcap",
                                         steps=[craft.step(i) for i in range(20)]),
        ("baseline", 1): craft.write_log(run / "coordinated/baseline/case-001.mcap"),
        ("prl", 0): craft.write_log(run / "coordinated/prl/case-000.mcap", steps=[
            craft.step(i) for i in range(29)] + [craft.step(29, tls_states=["GGG"] * 5)]),  # link 3 past "GGG"
        ("prl", 1): run / "coordinated/prl/case-001.mcap",
        ("oracle", 0): craft.write_log(run / "coordinated/oracle/case-000.mcap", plan_json=json.dumps(
            {k: v for k, v in craft.plan().items() if k != "x"})),
        ("oracle", 1): craft.write_log(run / "coordinated/oracle/case-001.mcap", plan_json=json.dumps(craft.plan())),
    }
    logs[("prl", 1)].write_bytes(bomb.read_bytes())
    rows = [{"method": m, "signals": "coordinated", "case": c, "train_seed": 0 if m == "prl" else -1,
             "energy": 30.0 + c, "travel_time": 100.0 + c, "collisions": 0, "terminated": True, "truncated": False,
             "mcap": str(p.relative_to(run))} for (m, c), p in logs.items()]
    pd.DataFrame(rows).to_parquet(run / "results.parquet")
    assert main([str(run), "--out", str(tmp_path / "report")]) == 0
    err = capsys.readouterr().err
    index = (tmp_path / "report" / "index.md").read_text()
    for path, field in ((logs[("prl", 0)], "step 29 tls_states: a state string of 3 links for 'J1'"),
                        (logs[("oracle", 0)], "plan: has time, speed but no x"),
                        (logs[("prl", 1)], "claims 1073741824 bytes")):
        said = [line for line in err.splitlines() if str(path) in line]
        assert said and all(field in line for line in said), (field, err)
        assert field in index
    assert "Traceback" not in err
    assert (tmp_path / "report" / "index.html").is_file()
    figures = {p.name for p in (tmp_path / "report" / "figures").iterdir()}
    assert any(name.startswith("compare-coordinated-case001") for name in figures)  # the readable case is drawn
