"""Progress bars of the long phases outside ``ecodrive run``: on stderr, with a total (so tqdm
shows an ETA), where stderr is a terminal; absent where it is not (a CI log stays clean).

A terminal is stood in for by a text buffer that says it is one: tqdm's ``disable=None`` asks
its stream ``isatty()`` when the bar is made."""
from __future__ import annotations

import io
import re
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


def stderr(monkeypatch: pytest.MonkeyPatch, tty: bool) -> io.StringIO:
    """sys.stderr replaced by a buffer, a terminal or a file (a CI log). Called in the test's body:
    pytest's capture puts its own stream back between a fixture's setup and the test."""
    out = Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", out)
    return out


def _fake_cells(monkeypatch: pytest.MonkeyPatch, finished: dict[str, dict]) -> list[str]:
    """``bench.regression.mixed`` with an executor that returns rows at once and ``finished`` as the
    cell files already in the log folder; returns the paths of the cells it ran."""
    from ecodrive_bench.bench.regression import mixed as regression_mixed

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
    from ecodrive_bench.bench.regression.mixed import run_cells

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


def test_regression_mixed_cells_write_no_bar_to_a_log(tmp_path, monkeypatch):
    log = stderr(monkeypatch, tty=False)
    from ecodrive_bench.bench.regression.mixed import run_cells

    _fake_cells(monkeypatch, {})
    assert len(run_cells(logs=tmp_path)) == 6
    assert log.getvalue() == ""


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


def test_mixed_command_writes_no_bar_to_a_log(tmp_path, monkeypatch):
    log = stderr(monkeypatch, tty=False)
    from ecodrive_bench.bench.experiments.mixed import main

    _fake_mixed(monkeypatch)
    argv = ["--logs", str(tmp_path), "--run-id", "m", "--signals", "coordinated", "--mpr", "0", "--demand", "200",
            "--reps", "1", "--duration", "10"]
    assert main(argv) == 0
    assert "cells:" not in log.getvalue()


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


def test_training_writes_no_bar_to_a_log(tmp_path, monkeypatch):
    log = stderr(monkeypatch, tty=False)
    _train(tmp_path)
    assert log.getvalue() == ""


def test_training_without_progress_draws_nothing_on_a_terminal(tmp_path, monkeypatch):
    terminal = stderr(monkeypatch, tty=True)
    _train(tmp_path, progress=False)
    assert terminal.getvalue() == ""
