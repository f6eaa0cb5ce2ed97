"""The progress of the long phases (``bench.progress``): on stderr, with a total (so an ETA); a
tqdm bar where stderr is a terminal, plain lines where it is not (a redirected run, a CI log): one
when the phase starts, one at most every ``LOG_INTERVAL_S`` as work finishes, one at the end.

A terminal is stood in for by a text buffer that says it is one: ``bench.progress.bar`` asks its
stream ``isatty()`` when the bar is made."""
from __future__ import annotations

import io
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from ecodrive_bench.bench.experiments.mixed import CI_DEMAND


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def bar(err: str, desc: str) -> list[tuple[int, int]]:
    """Every (done, total) the bar named ``desc`` drew."""
    return [(int(a), int(b)) for a, b in re.findall(rf"{re.escape(desc)}:[^\r\n]*?(\d+)/(\d+)", err)]


LINE = re.compile(r"^(?P<desc>[^:]+): (?P<n>\d+)/(?P<total>\d+) \(\d+%\), (?P<rest>.*)$")


def lines(err: str, desc: str) -> list[tuple[int, int, str]]:
    """(done, total, the rest) of every plain progress line of ``desc``; a redrawn bar (``\\r``)
    fails."""
    assert "\r" not in err and "\x1b" not in err, repr(err)
    found = [LINE.match(line) for line in err.splitlines()]
    return [(int(m["n"]), int(m["total"]), m["rest"]) for m in found if m and m["desc"] == desc]


def stderr(monkeypatch: pytest.MonkeyPatch, tty: bool) -> io.StringIO:
    """sys.stderr replaced by a buffer, a terminal or a file (a CI log). Called in the test's body:
    pytest's capture puts its own stream back between a fixture's setup and the test."""
    out = Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", out)
    return out


def _fake_cells(monkeypatch: pytest.MonkeyPatch, finished: dict[str, dict]) -> list[str]:
    """``bench.regression.mixed_cells`` with an executor that returns rows at once and ``finished`` as the
    cell files already in the log folder; returns the paths of the cells it ran."""
    from ecodrive_bench.bench.regression import mixed_cells as regression_mixed

    ran: list[str] = []

    def run_local(cells, workers, fn):
        for c in cells:
            ran.append(c.path)
            yield {"mcap": c.path, "signals": c.signals, "mpr": c.mpr, "demand": c.demand}

    monkeypatch.setattr(regression_mixed, "run_local", run_local)
    monkeypatch.setattr(regression_mixed, "_done", lambda c: finished.get(c.path))
    return ran


def test_regression_mixed_cells_show_a_bar_and_keep_the_finished_cells(tmp_path, monkeypatch):
    terminal = stderr(monkeypatch, tty=True)
    from ecodrive_bench.bench.regression.mixed_cells import run_cells

    finished: dict[str, dict] = {}
    ran = _fake_cells(monkeypatch, finished)
    first = run_cells(logs=tmp_path)
    assert len(ran) == 6 and bar(terminal.getvalue(), "mixed cells")[-1] == (6, 6)
    # a killed check rerun on the same folder: two cells finished, one of them at another demand
    kept, stale = first.mcap.iloc[0], first.mcap.iloc[1]
    finished.update({kept: {**first.iloc[0].to_dict(), "mpr": -1.0},
                     stale: {**first.iloc[1].to_dict(), "demand": CI_DEMAND + 1}})
    ran.clear()
    terminal.seek(0)
    terminal.truncate()
    again = run_cells(logs=tmp_path)
    assert kept not in ran and stale in ran and len(ran) == 5
    assert again.mcap.tolist() == first.mcap.tolist() and again.mpr.iloc[0] == -1.0  # read back, in cell order
    assert bar(terminal.getvalue(), "mixed cells")[0] == (1, 6)  # the bar counts the kept cell


def test_regression_mixed_cells_write_lines_to_a_log(tmp_path, monkeypatch):
    log = stderr(monkeypatch, tty=False)
    from ecodrive_bench.bench.regression.mixed_cells import run_cells

    _fake_cells(monkeypatch, {})
    assert len(run_cells(logs=tmp_path)) == 6
    got = lines(log.getvalue(), "mixed cells")
    assert got[0] == (0, 6, "starting") and got[-1][:2] == (6, 6) and got[-1][2].endswith("done")
    assert len(got) == 2  # the cells took less than LOG_INTERVAL_S: the first line and the last
    log.seek(0)
    log.truncate()
    assert len(run_cells(logs=tmp_path / "again", progress=False)) == 6
    assert log.getvalue() == ""  # progress=False: nothing


def _fake_mixed(monkeypatch: pytest.MonkeyPatch) -> None:
    from ecodrive_bench.bench.experiments import mixed

    def run_local(cells, workers, fn):
        for c in cells:
            yield {"mcap": c.path, "signals": c.signals, "mpr": c.mpr, "demand": c.demand, "rep": c.rep,
                   "all_energy": 1.0}

    monkeypatch.setattr(mixed, "run_local", run_local)


def test_mixed_command_shows_its_cells_with_a_total(tmp_path, monkeypatch):
    terminal = stderr(monkeypatch, tty=True)
    from ecodrive_bench.bench.experiments.mixed import main

    _fake_mixed(monkeypatch)
    argv = ["--logs", str(tmp_path), "--run-id", "m", "--signals", "coordinated", "--mpr", "0", "--demand", "200",
            "300", "--reps", "1", "--duration", "10"]
    assert main(argv) == 0
    assert bar(terminal.getvalue(), "cells")[-1] == (2, 2)


def test_mixed_command_writes_lines_to_a_log(tmp_path, monkeypatch):
    log = stderr(monkeypatch, tty=False)
    from ecodrive_bench.bench.experiments.mixed import main

    _fake_mixed(monkeypatch)
    argv = ["--logs", str(tmp_path), "--run-id", "m", "--signals", "coordinated", "--mpr", "0", "--demand", "200",
            "--reps", "1", "--duration", "10"]
    assert main(argv) == 0
    got = lines(log.getvalue(), "cells")
    assert [g[:2] for g in got] == [(0, 1), (1, 1)] and got[-1][2].endswith("done")


def _train(tmp_path: Path, progress: bool = True) -> None:
    from ecodrive_bench.bench.training.train import train

    train("dqn", "coordinated", 1, seed=0, out=tmp_path / "run", models=None, progress=progress,
          agent_config={"learning_starts": 64, "batch_size": 16}, scenario={"max_episode_time": 30.0},
          validation_cases=2)


def test_training_shows_its_validation_with_a_total(tmp_path, monkeypatch):
    terminal = stderr(monkeypatch, tty=True)
    _train(tmp_path)
    err = terminal.getvalue()
    assert bar(err, "dqn/coordinated")[-1] == (1, 1)
    assert bar(err, "validation") and {t for _, t in bar(err, "validation")} == {2}


def test_training_writes_lines_to_a_log(tmp_path, monkeypatch):
    log = stderr(monkeypatch, tty=False)
    _train(tmp_path)
    err = log.getvalue()
    train = lines(err, "dqn/coordinated")
    assert train[0] == (0, 1, "starting") and train[-1][:2] == (1, 1) and "done, E=" in train[-1][2]
    validation = lines(err, "validation")
    assert validation[0] == (0, 2, "starting") and validation[-1][:2] == (2, 2)
    log.seek(0)
    log.truncate()
    _train(tmp_path / "again", progress=False)
    assert log.getvalue() == ""  # progress=False: nothing


def test_training_without_progress_draws_nothing_on_a_terminal(tmp_path, monkeypatch):
    terminal = stderr(monkeypatch, tty=True)
    _train(tmp_path, progress=False)
    assert terminal.getvalue() == ""


class Clock:
    """A clock a test moves (tqdm's bars read ``tqdm.std.time``)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_log_gets_a_line_at_the_start_at_most_one_per_interval_and_one_at_the_end(monkeypatch):
    from ecodrive_bench.bench import progress

    log = stderr(monkeypatch, tty=False)
    monkeypatch.delenv(progress.INTERVAL_ENV, raising=False)
    clock = Clock()
    monkeypatch.setattr("tqdm.std.time", clock)  # a bar's _time
    with progress.bar(total=20, desc="episodes", unit="ep") as b:
        for _ in range(15):  # one episode every 10 s
            clock.t += 10.0
            b.update(1)
            b.set_postfix(E="1Wh")  # no line of its own
    got = lines(log.getvalue(), "episodes")
    assert progress.LOG_INTERVAL_S == 60.0
    assert [g[:2] for g in got] == [(0, 20), (6, 20), (12, 20), (15, 20)]  # at 0, 60 and 120 s, then the end
    assert got[1][2] == "0.1 ep/s, elapsed 01:00, ETA 02:20, E=1Wh"
    assert got[-1][2] == "0.1 ep/s, elapsed 02:30, stopped, E=1Wh"  # closed before its total


def test_the_interval_is_overridden_by_the_environment(monkeypatch):
    from ecodrive_bench.bench import progress

    log = stderr(monkeypatch, tty=False)
    monkeypatch.setenv(progress.INTERVAL_ENV, "0")
    for _ in progress.bar(range(3), desc="cases", unit="case"):
        pass
    assert [g[:2] for g in lines(log.getvalue(), "cases")] == [(0, 3), (1, 3), (2, 3), (3, 3)]
    monkeypatch.setenv(progress.INTERVAL_ENV, "soon")
    assert progress.log_interval() == progress.LOG_INTERVAL_S


def test_a_terminal_gets_the_bar_and_a_line_written_under_it_stays_one_line(monkeypatch):
    from tqdm import tqdm

    from ecodrive_bench.bench import progress

    log = stderr(monkeypatch, tty=False)
    monkeypatch.setenv(progress.INTERVAL_ENV, "0")
    with progress.bar(total=2, desc="episodes", unit="ep") as b:
        b.update(1)
        tqdm.write("error: one episode failed", file=sys.stderr)
        b.update(1)
    assert log.getvalue().splitlines()[2] == "error: one episode failed"
    terminal = stderr(monkeypatch, tty=True)
    with progress.bar(total=2, desc="episodes", unit="ep") as b:
        b.update(2)
    assert "\r" in terminal.getvalue() and bar(terminal.getvalue(), "episodes")[-1] == (2, 2)


def test_a_redirected_run_logs_its_progress(tmp_path):
    """``ecodrive run`` with stderr to a file (as ``> run.log 2>&1`` or ``| tee``): plain lines."""
    log = tmp_path / "run.log"
    env = {**os.environ, "ECODRIVE_PROGRESS_INTERVAL": "0"}
    with open(log, "w") as f:
        rc = subprocess.run([str(Path(sys.executable).parent / "ecodrive"), "run", "--profile", "smoke", "--methods",
                             "baseline", "--signals", "coordinated", "--workers", "2", "--logs", str(tmp_path / "logs")],
                            stdout=subprocess.DEVNULL, stderr=f, env=env, timeout=600).returncode
    err = log.read_text()
    assert rc == 0, err
    got = lines(err, "episodes")
    assert [g[:2] for g in got] == [(0, 3), (1, 3), (2, 3), (3, 3)], err
    assert got[0][2] == "starting" and re.fullmatch(r"[\d.]+ ep/s, elapsed \d\d:\d\d, done", got[-1][2]), err
    assert re.fullmatch(r"[\d.]+ ep/s, elapsed \d\d:\d\d, ETA \d\d:\d\d", got[1][2]), err
