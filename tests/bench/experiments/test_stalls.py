"""``ecodrive stalls``'s bad input: one line naming the flag, its value and its range, exit 2."""
from __future__ import annotations

import sys

import pytest

from ecodrive_bench.bench.experiments import stalls
from ecodrive_bench.bench.methods.policies import CheckpointError


@pytest.fixture(autouse=True)
def _no_cell(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["ecodrive stalls"])
    monkeypatch.setattr(stalls, "trace", lambda *a, **k: pytest.fail("a cell was run"))


@pytest.mark.parametrize("flag, value, accepted", [
    ("--rep", "nan", "0.."), ("--rep", "-1", "0.."),
    ("--duration", "5", "[10, 7200]"), ("--duration", "nan", "[10, 7200]"),
    ("--mpr", "0", "(0, 1]"), ("--mpr", "1.5", "(0, 1]"),
    ("--demand", "0", "(0, 1000]"), ("--demand", "inf", "(0, 1000]"),
    ("--at", "0", "1.."),
])
def test_a_bad_flag_names_just_itself(flag, value, accepted, capsys):
    with pytest.raises(SystemExit) as e:
        stalls.main([flag, value])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2
    why = "is not an integer" if ".." in accepted and not value.lstrip("-").isdigit() else "is out of range"
    assert err == [f"ecodrive stalls: error: argument {flag}: {value!r} {why}; accepted: {accepted}"]


def test_a_policy_error_has_the_command_prefix(monkeypatch, capsys):
    def refuse(*a, **k):
        raise CheckpointError("models/prl-coordinated/s0/policy.pt: sha256 does not match")

    monkeypatch.setattr(stalls, "trace", refuse)
    assert stalls.main([]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ecodrive stalls: error: models/prl-coordinated/s0/policy.pt: sha256 does not match"]
