"""``ecodrive``: every subcommand has a help that names its options, and bad input on any of them
is one line with exit code 2."""
from __future__ import annotations

import subprocess
import sys

import pytest

from bench.cli import COMMANDS, main


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench.cli", *args], capture_output=True, text=True, timeout=120)


def test_top_level_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for name, (_, desc) in COMMANDS.items():
        assert f"  {name}" in out and desc in out


@pytest.mark.parametrize("command", list(COMMANDS))
def test_each_command_has_help_and_refuses_an_unknown_flag_in_one_line(command, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive"])
    with pytest.raises(SystemExit) as e:
        main([command, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: ecodrive {command}") and "--help" in out
    with pytest.raises(SystemExit) as e:
        main([command, "--no-such-flag", "x"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"ecodrive {command}: error:")


def test_an_unknown_command_is_one_line():
    out = run("frobnicate")
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [out.stderr.strip()] and "'frobnicate'" in out.stderr


@pytest.mark.parametrize("command, args", [
    ("mixed", ["--run-id", "../x"]), ("lateral", ["--run-id", "a/b"]), ("sweep", ["reward", "--run-id", ".."]),
    ("run", ["--run-id", "/tmp/abs"]),
])
def test_a_run_id_that_is_a_path_is_refused(command, args, tmp_path):
    out = run(command, "--logs", str(tmp_path / "logs"), *args)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1 and "--run-id" in out.stderr
    assert not (tmp_path / "logs").exists()
