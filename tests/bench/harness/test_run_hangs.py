"""A hung episode cannot hang `ecodrive run` (real SUMO episodes, smoke-sized, real signals): an
agent whose act never returns is a failed episode at its limit; one Ctrl-C or SIGTERM ends the
run in seconds with a stopped worker, no traceback and no process left; workers that die before
they take an episode end the run in one line, exit 3, with the manifest and the record written."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from plugin_agent import install, source

from ecodrive_bench.bench.harness.run_command import main

AGENT = source('''
    if self.step == 5 and self.mode == "sleepy":
        time.sleep(3600)
    if self.step == 5 and self.mode == "stopper" and not (HERE / "stopped").exists():
        (HERE / "stopped").write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGSTOP)
''', ['sleepy', 'stopper'])
ROOT = Path(__file__).parents[3]


@pytest.fixture
def agents(tmp_path, monkeypatch):
    return install(tmp_path, 'hang_agents', AGENT, monkeypatch)


def _command(logs: Path, *extra: str) -> list[str]:
    return ["--profile", "smoke", "--logs", str(logs), "--methods", "baseline", "--signals", "uncoordinated", *extra]


def test_an_agent_whose_act_never_returns_is_a_failed_episode_at_its_limit(agents, capsys):
    run_dir = agents / "logs" / "smoke"
    t0 = time.monotonic()
    rc = main(_command(agents / "logs", "--agent", "hang_agents:sleepy", "--workers", "1", "--episode-limit", "30"))
    assert time.monotonic() - t0 < 240
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error")]
    assert rc == 3 and len(err) == 1, err
    assert "sleepy/uncoordinated case 000 failed: it ran past its time limit of 30 s" in err[0]
    assert "its other cases in this setting are not run" in err[0] and "--episode-limit" in err[0]
    trace = (run_dir / "errors" / "uncoordinated-sleepy-case-000.txt").read_text()
    assert "in act" in trace and "hang_agents.py" in trace  # where it hung
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert [f["case"] for f in manifest["episodes_failed"]] == [0] and manifest["episodes_not_run"] == 2
    assert not list((run_dir / "uncoordinated" / "sleepy").glob("*.mcap"))


def _start(folder: Path, *extra: str) -> subprocess.Popen:
    """``ecodrive run`` in a session of its own (a terminal's Ctrl-C goes to its process group)."""
    cmd = [sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", *_command(folder / "logs", *extra)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(ROOT)])}
    return subprocess.Popen(cmd, cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def _left(procs: list[psutil.Process], wait_s: float = 10.0) -> list[int]:
    """The pids of ``procs`` still there (not zombies) after at most ``wait_s``."""
    end = time.monotonic() + wait_s
    while True:
        left = []
        for p in procs:
            try:
                if p.status() != psutil.STATUS_ZOMBIE:
                    left.append(p.pid)
            except psutil.NoSuchProcess:
                pass
        if not left or time.monotonic() > end:
            return left
        time.sleep(0.1)


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_one_signal_ends_the_run_in_seconds_with_a_stopped_worker(agents, signum, code):
    proc = _start(agents, "--agent", "hang_agents:stopper", "--workers", "2")
    try:
        end = time.monotonic() + 180
        while not (agents / "stopped").exists() and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.1)
        stopped = int((agents / "stopped").read_text())
        while psutil.Process(stopped).status() != psutil.STATUS_STOPPED:
            time.sleep(0.05)
        procs = psutil.Process(proc.pid).children(recursive=True)
        assert stopped in [p.pid for p in procs]
        t0 = time.monotonic()
        if signum == signal.SIGINT:
            os.killpg(proc.pid, signum)  # as a terminal's Ctrl-C: to the whole foreground group
        else:
            os.kill(proc.pid, signum)
        _, err = proc.communicate(timeout=60)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            for p in psutil.Process(proc.pid).children(recursive=True):
                p.kill()
    assert proc.returncode == code, err
    assert took < 15, took
    assert "Traceback" not in err, err
    assert "finished episodes are kept" in err.strip().splitlines()[-1]
    assert _left(procs) == []


def test_workers_that_die_before_they_take_an_episode_end_the_run_in_one_line(tmp_path):
    """Every spawned worker SIGKILLed as soon as it appears (as by the OOM killer during its
    imports): one error line, exit 3, the manifest and errors/pool.txt written."""
    proc = _start(tmp_path, "--workers", "2")
    kills, end = 0, time.monotonic() + 300
    try:
        while proc.poll() is None and time.monotonic() < end:
            try:
                for child in psutil.Process(proc.pid).children():
                    if "spawn_main" in " ".join(child.cmdline()):
                        child.kill()
                        kills += 1
            except psutil.Error:
                pass
            time.sleep(0.02)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert proc.returncode == 3 and len(lines) == 1, err
    assert "Traceback" not in err and kills >= 5
    assert "keep dying before they take a task (SIGKILL" in lines[0] and "3 episode(s) not run" in lines[0]
    run_dir = tmp_path / "logs" / "smoke"
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert "keep dying" in manifest["pool_failure"]["reason"] and manifest["episodes_not_run"] == 3
    record = (run_dir / "errors" / "pool.txt").read_text()
    assert "baseline/uncoordinated case 002" in record
