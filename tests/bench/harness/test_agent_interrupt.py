"""A KeyboardInterrupt raised inside an agent's ``act`` in a pool worker is that episode's failure,
one line like any exception the agent raises (before: the worker died with a traceback, three
times per case, and every case was tried); a Ctrl-C to the command still stops it at once."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from plugin_agent import install, source

from ecodrive_bench.bench.harness.executors import run_local
from ecodrive_bench.bench.harness.pool import Failure, TaskExit


def interrupting(task: tuple[str, str]) -> dict:
    """A pool task: ``interrupt-*`` raises KeyboardInterrupt as an agent's act would (marked as
    the agent's, at step 7, as ``run_episode`` marks it); counts its attempts in a marker file."""
    folder, name = task
    with open(Path(folder) / name, "a") as f:
        f.write(f"{os.getpid()}\n")
    if name.startswith("interrupt"):
        e = KeyboardInterrupt("the agent's own")
        e.ecodrive_step, e.ecodrive_agent = 7, True
        raise e
    return {"name": name}


def test_a_keyboard_interrupt_inside_a_task_is_its_failure_not_a_dead_worker(tmp_path, capfd):
    failed: list[Failure] = []
    names = ["ok-a", "interrupt-b", "ok-c", "interrupt-d"]
    rows = list(run_local([(str(tmp_path), n) for n in names], 2, interrupting, on_failure=failed.append))
    assert sorted(r["name"] for r in rows) == ["ok-a", "ok-c"]
    assert sorted(f.task[1] for f in failed) == ["interrupt-b", "interrupt-d"]
    for f in failed:
        assert isinstance(f.error, TaskExit) and f.attempts == 1 and f.agent and f.step == 7
        assert f.reason == "KeyboardInterrupt: the agent's own (raised inside the task, not a Ctrl-C)"
        assert "raise e" in f.traceback
        assert len((tmp_path / f.task[1]).read_text().split()) == 1  # not retried as a dead worker
    assert "Traceback" not in capfd.readouterr().err  # no worker printed one


def test_a_ctrl_c_to_the_parent_still_stops_the_pool(tmp_path):
    script = textwrap.dedent(f"""
        import time
        from pathlib import Path
        from ecodrive_bench.bench.harness.executors import run_local

        def slow(i):
            Path({str(tmp_path)!r}, f"started-{{i}}").touch()
            time.sleep(60)
            return i

        if __name__ == "__main__":
            list(run_local(range(4), 2, slow))
    """)
    (tmp_path / "pool_script.py").write_text(script)
    proc = subprocess.Popen([sys.executable, str(tmp_path / "pool_script.py")], cwd=tmp_path, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(tmp_path)})
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob("started-*")) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert list(tmp_path.glob("started-*")), "no task started"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)  # at once, not after the tasks' 60 s
    assert proc.returncode != 0 and "KeyboardInterrupt" in err
    assert len(list(tmp_path.glob("started-*"))) <= 2  # no further task was started


AGENT = source('''
    if info["travel_time"] >= 3:
        raise KeyboardInterrupt("pressed inside act")
''', ["interrupting"])


def test_an_agent_that_raises_keyboard_interrupt_is_one_line_per_failed_episode(tmp_path, monkeypatch, capfd):
    from ecodrive_bench.bench.harness.run_command import main

    install(tmp_path, "interrupting_agent", AGENT, monkeypatch)
    rc = main(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--methods", "baseline", "--signals",
               "uncoordinated", "--agent", "interrupting_agent:interrupting", "--workers", "2"])
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    manifest = json.loads((tmp_path / "logs" / "smoke" / "manifest.json").read_text())
    failed = manifest["episodes_failed"]  # the cases in flight when the first failed (2 workers): 1 or 2
    assert rc == 3 and 1 <= len(failed) <= 2 and len(lines) == len(failed), err
    assert [f["attempts"] for f in failed] == [1] * len(failed)  # not retried as a dead worker
    assert manifest["episodes_not_run"] == 3 - len(failed)  # its other cases in the setting
    for f, line in zip(sorted(failed, key=lambda f: f["case"]), sorted(lines)):
        assert ("agent 'interrupting_agent:interrupting' (interrupting) raised KeyboardInterrupt: pressed inside act "
                f"(raised inside the task, not a Ctrl-C) at step 3 of interrupting/uncoordinated case "
                f"{f['case']:03d}") in line
    assert "Traceback" not in err
