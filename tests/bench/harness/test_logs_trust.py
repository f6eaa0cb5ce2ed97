"""Agents and logs that lie do not get into `ecodrive run`'s results (real SUMO episodes,
smoke-sized): an agent that forks inside act leaves whole logs and one result per case; a log
written over while the episode ran is never published; a published log damaged afterwards, or
written by another version of the agent's code, is not reused."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
import pytest
from plugin_agent import install, source

from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.bench.harness.steplogs import check, written_by
from ecodrive_bench.bench.logs.mcaplog import read_log

AGENT = source('''
    if self.mode == "forker" and self.step == 50:
        os.fork()  # both processes return from act
    if self.mode == "liar" and self.step == 150:  # overwrite the middle of its own step log
        part = max((HERE / "logs").rglob("liar/*.mcap.part"), key=lambda p: p.stat().st_mtime_ns)
        with open(part, "r+b") as f:
            f.seek(part.stat().st_size // 2)
            f.write(b"\\xff" * 64)
''', ['forker', 'liar', 'cruise'])


@pytest.fixture
def agents(tmp_path, monkeypatch):
    return install(tmp_path, 'lying_agents', AGENT, monkeypatch)


def _run(folder: Path, capsys, *extra: str) -> tuple[int, list[str], list[str]]:
    rc = main(["--profile", "smoke", "--logs", str(folder / "logs"), "--methods", "baseline", "--signals",
               "uncoordinated", "--workers", "1", *extra])
    lines = capsys.readouterr().err.splitlines()
    return rc, [ln for ln in lines if ln.startswith("error")], [ln for ln in lines if ln.startswith("note")]


def test_an_agent_that_forks_in_act_leaves_whole_logs_and_one_result_per_case(agents, capsys):
    rc, err, _ = _run(agents, capsys, "--agent", "lying_agents:forker")
    assert rc == 0 and not err, err
    table = pd.read_parquet(agents / "logs" / "smoke" / "results.parquet")
    rows = table[table.method == "forker"]
    assert sorted(rows.case) == [0, 1, 2]
    for case, steps in zip(rows.case, rows.steps):
        log = read_log(agents / "logs" / "smoke" / "uncoordinated" / "forker" / f"case-{case:03d}.mcap")
        assert log.complete and not log.warning and len(log.steps) == steps + 1


def test_a_log_written_over_during_its_episode_is_not_published(agents, capsys):
    rc, err, _ = _run(agents, capsys, "--agent", "lying_agents:liar")
    assert rc == 3 and len(err) == 3, err
    assert all("its step log did not check out" in line and "liar/uncoordinated case" in line for line in err)
    folder = agents / "logs" / "smoke" / "uncoordinated" / "liar"
    assert not list(folder.glob("*.mcap")) and len(list(folder.glob("*.mcap.part"))) == 3
    table = pd.read_parquet(agents / "logs" / "smoke" / "results.parquet")
    assert set(table.method) == {"baseline"}


def _damage(path: Path) -> None:
    """Bytes in the middle of the file flipped: its index, summary and footer are untouched."""
    data = bytearray(path.read_bytes())
    mid = len(data) // 3
    data[mid:mid + 32] = bytes(b ^ 0xFF for b in data[mid:mid + 32])
    path.write_bytes(bytes(data))


def test_a_published_log_damaged_afterwards_is_run_again(agents, capsys):
    rc, err, _ = _run(agents, capsys)
    assert rc == 0 and not err
    run_dir = agents / "logs" / "smoke"
    log = run_dir / "uncoordinated" / "baseline" / "case-001.mcap"
    _damage(log)
    assert check(log)
    rc, err, _ = _run(agents, capsys)
    assert rc == 0 and not err
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["episodes_run"] == 1 and manifest["episodes_reused"] == 2
    assert check(log) == ""


def test_a_changed_agent_does_not_reuse_the_earlier_logs(agents, capsys):
    run_dir = agents / "logs" / "smoke"
    rc, err, _ = _run(agents, capsys, "--agent", "lying_agents:cruise")
    assert rc == 0 and not err
    log = run_dir / "uncoordinated" / "cruise" / "case-000.mcap"
    first = written_by(log)
    assert first and json.loads((run_dir / "manifest.json").read_text())["checkpoint_sha256"][
        "cruise-uncoordinated"] == first
    rc, err, notes = _run(agents, capsys, "--agent", "lying_agents:cruise")  # the same code: reused
    assert rc == 0 and json.loads((run_dir / "manifest.json").read_text())["episodes_run"] == 0 and not notes
    module = agents / "lying_agents.py"
    module.write_text(module.read_text().replace("VERSION = 1", "VERSION = 2"))
    sys.modules.pop("lying_agents", None)
    rc, err, notes = _run(agents, capsys, "--agent", "lying_agents:cruise")
    assert rc == 0 and not err
    assert len(notes) == 1 and "'cruise' (lying_agents:cruise) is not the one that wrote 3 of its step logs" in notes[0]
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["episodes_run"] == 3 and manifest["episodes_reused"] == 3  # the baseline's
    assert written_by(log) not in (None, first) and manifest["checkpoint_sha256"]["cruise-uncoordinated"] == written_by(log)
