"""Failed episodes do not take `ecodrive run` down (real SUMO episodes, smoke-sized): a worker
SIGKILLed mid-episode is replaced and its case rerun; a case whose worker dies every time, or
whose agent raises, is one line on stderr (the traceback in <run>/errors/), the other rows are
written, the exit code is 3, and the rerun retries it. Two commands on one run folder: the second
is refused."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from plugin_agent import install, source

from ecodrive_bench.bench.harness.run_command import main

AGENT = source('''
    if (HERE / f"{self.mode}.on").exists():
        if self.mode == "boom" and self.step == 31:
            raise ValueError("the agent's bug")
        if self.mode == "kill" and self.step == 5:
            if info["time"] < 225:  # case 002 (inserted at 206.4 s): dies every time
                os.kill(os.getpid(), signal.SIGKILL)
            try:  # another case: once
                os.close(os.open(HERE / "killed-once", os.O_CREAT | os.O_EXCL))
                os.kill(os.getpid(), signal.SIGKILL)
            except FileExistsError:
                pass
''', ['boom', 'kill'])


@pytest.fixture
def agents(tmp_path, monkeypatch):
    return install(tmp_path, 'failing_agents', AGENT, monkeypatch)


def _run(logs: Path, agent: str, workers: str, capsys) -> tuple[int, list[str]]:
    rc = main(["--profile", "smoke", "--logs", str(logs), "--methods", "baseline", "--signals", "uncoordinated",
               "--agent", f"failing_agents:{agent}", "--workers", workers])
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if ln.startswith("error")]
    return rc, err


def test_a_killed_worker_is_replaced_and_a_case_that_always_dies_is_recorded_as_failed(agents, capsys):
    logs, run_dir = agents / "logs", agents / "logs" / "smoke"
    (agents / "kill.on").touch()
    rc, err = _run(logs, "kill", "2", capsys)
    assert rc == 3 and len(err) == 1, err
    assert "kill/uncoordinated case 002" in err[0] and "SIGKILL" in err[0] and "3 times" in err[0]
    assert (agents / "killed-once").exists()  # another case's worker was killed once, and that case finished
    table = pd.read_parquet(run_dir / "results.parquet")
    assert sorted(zip(table.method, table.case)) == [("baseline", 0), ("baseline", 1), ("baseline", 2),
                                                     ("kill", 0), ("kill", 1)]
    folder = run_dir / "uncoordinated" / "kill"
    assert not (folder / "case-002.mcap").exists() and (folder / "case-002.mcap.part").exists()
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert [(f["case"], f["attempts"]) for f in manifest["episodes_failed"]] == [(2, 3)]
    assert (run_dir / "errors" / "uncoordinated-kill-case-002.txt").is_file()
    (agents / "kill.on").unlink()
    rc, err = _run(logs, "kill", "2", capsys)  # the rerun retries the failed case only
    assert rc == 0 and not err
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["episodes_run"] == 1 and manifest["episodes_failed"] == []
    assert len(pd.read_parquet(run_dir / "results.parquet")) == 6 and (folder / "case-002.mcap").is_file()
    assert not (run_dir / "errors" / "uncoordinated-kill-case-002.txt").exists()


def test_an_agent_that_raises_is_one_line_and_the_other_rows_are_kept(agents, capsys):
    logs, run_dir = agents / "logs", agents / "logs" / "smoke"
    (agents / "boom.on").touch()
    rc, err = _run(logs, "boom", "1", capsys)
    assert rc == 3 and len(err) == 1, err
    trace = run_dir / "errors" / "uncoordinated-boom-case-000.txt"
    for words in ("agent 'failing_agents:boom' (boom)", "ValueError: the agent's bug", "step 31",
                  "uncoordinated case 000", str(trace)):
        assert words in err[0]
    assert 'raise ValueError("the agent\'s bug")' in trace.read_text()
    table = pd.read_parquet(run_dir / "results.parquet")
    assert set(table.method) == {"baseline"} and len(table) == 3  # the baseline's episodes are kept
    assert not list((run_dir / "uncoordinated" / "boom").glob("*.mcap"))
    (agents / "boom.on").unlink()
    rc, err = _run(logs, "boom", "1", capsys)  # fixed: the rerun runs the agent's cases
    assert rc == 0 and not err and not trace.exists()
    assert len(pd.read_parquet(run_dir / "results.parquet")) == 6


def test_a_second_command_on_the_same_run_folder_is_refused(tmp_path):
    cmd = [sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", "--profile", "smoke", "--logs", str(tmp_path), "--methods",
           "baseline", "--signals", "uncoordinated", "--workers", "1"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[3])}
    procs = [subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
             for _ in range(2)]
    outs = [(p.wait(timeout=600), p.stderr.read(), p.pid) for p in procs]
    (rc_a, err_a, pid_a), (rc_b, err_b, pid_b) = sorted(outs)
    assert (rc_a, rc_b) == (0, 2), (err_a, err_b)
    lines = [ln for ln in err_b.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and f"is in use by another ecodrive command (pid {pid_a})" in lines[0]
    assert len(pd.read_parquet(tmp_path / "smoke" / "results.parquet")) == 3
