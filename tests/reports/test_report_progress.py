"""The report's progress: the return split (one step log per episode) and the figures show bars
with a total on a terminal's stderr, none in a CI log. A terminal is a buffer that says it is one
(tqdm's ``disable=None`` asks ``isatty()``); see tests/bench/test_progress.py for the rest."""
from __future__ import annotations

import io
import re
import sys

import pytest

from ecodrive_bench.reports.build import build
from ecodrive_bench.reports.section_figures import TRAJECTORY_CASES


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _totals(err: str, desc: str) -> set[tuple[int, int]]:
    return {(int(a), int(b)) for a, b in re.findall(rf"{re.escape(desc)}:[^\r\n]*?(\d+)/(\d+)", err)}


@pytest.mark.parametrize("tty", [True, False])
def test_report_progress_only_on_a_terminal(smoke_report, tmp_path, monkeypatch, tty):
    err = Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    index, _ = build(smoke_report["run"], tmp_path / "report")
    assert index.read_text() == smoke_report["md"]  # the bars change nothing written
    if not tty:
        assert err.getvalue() == ""
        return
    results = smoke_report["results"]
    logs, settings = len(results), results.signals.nunique()
    assert (logs, logs) in _totals(err.getvalue(), "return split")
    figures = settings + settings * TRAJECTORY_CASES  # violins, then the trajectories
    assert (figures, figures) in _totals(err.getvalue(), "figures")


def test_report_progress_off_on_a_terminal(smoke_report, tmp_path, monkeypatch):
    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    build(smoke_report["run"], tmp_path / "report", progress=False)
    assert err.getvalue() == ""
