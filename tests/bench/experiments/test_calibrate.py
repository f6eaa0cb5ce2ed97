"""``ecodrive calibrate``'s bad input: one line, exit 2, before any episode runs or any output."""
from __future__ import annotations

import sys

import pytest

from ecodrive_bench.bench.experiments import calibrate


@pytest.fixture(autouse=True)
def _no_episodes(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["ecodrive calibrate"])
    monkeypatch.setattr(calibrate, "make_env", lambda *a, **k: pytest.fail("an env was built"))


@pytest.mark.parametrize("item, words", [
    ("frob=1", "--set frob=1: unknown config key(s) frob; accepted:"),
    ("lanes=0", "--set lanes=0: lanes=0 is out of range; accepted: [1, 6]"),
    ("ev.mass=NaN", "--set ev.mass=NaN: ev.mass=nan is out of range; accepted: [500, 3500]"),
    ("ev.mass=heavy", "--set ev.mass=heavy: ev.mass='heavy'"),
    ("lanes.x=3", "--set lanes.x=3: lanes={'x': 3}"),
    ("lanes", "--set 'lanes': expected FIELD=VALUE"),
])
def test_a_bad_override_is_one_line_before_anything_runs(item, words, capsys):
    with pytest.raises(SystemExit) as e:
        calibrate.main(["--cases", "1", "--set", item])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert e.value.code == 2 and len(lines) == 1
    assert lines[0].startswith("ecodrive calibrate: error: ") and words in lines[0]
    assert out == ""  # not even the table's header


def test_a_later_bad_override_is_caught_too(capsys):
    with pytest.raises(SystemExit) as e:
        calibrate.main(["--set", "ev.mass=1450", "spacing=-1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "--set spacing=-1: spacing=-1" in err[0]


@pytest.mark.parametrize("value", ["nan", "0", "101"])
def test_bad_cases_names_the_flag_value_and_range(value, capsys):
    with pytest.raises(SystemExit) as e:
        calibrate.main(["--cases", value])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2
    assert err == [f"ecodrive calibrate: error: argument --cases: {value!r} is {'not an integer' if value == 'nan' else 'out of range'}; accepted: 1..100"]
