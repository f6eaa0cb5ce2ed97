"""Small refusals of ``ecodrive run``, each one line and exit 2: JSON that names a key twice (a
``--scenario`` file, a case list, a ``--set`` value); a run id or method name too long for a file
name; a run folder's ``.lock`` that is not a regular file; an ``--sb3`` path that is no regular file
or too large."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from ecodrive_bench.bench import runlock
from ecodrive_bench.bench.args import MAX_NAME
from ecodrive_bench.bench.cases import case as cases_mod
from ecodrive_bench.bench.cases.case import CaseError, load
from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.methods.sb3_zip import ZipError, read


def _refused(argv: list[str], tmp_path: Path, monkeypatch, capsys) -> str:
    """The one error line of ``ecodrive run`` options that are refused with exit 2."""
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    with pytest.raises(SystemExit) as e:
        parse(["--logs", str(tmp_path / "logs"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1, err
    assert not (tmp_path / "logs").exists()
    return err[0]


def test_a_scenario_file_that_names_a_key_twice_is_refused(tmp_path, monkeypatch, capsys):
    path = tmp_path / "s.json"
    path.write_text('{"lanes": 3, "ev": {"mass": 1500, "mass": 1800}}')
    err = _refused(["--scenario", str(path)], tmp_path, monkeypatch, capsys)
    assert f"--scenario {path}: key 'mass' appears twice in one object" in err


def test_a_set_value_that_names_a_key_twice_is_refused(tmp_path, monkeypatch, capsys):
    err = _refused(["--set", 'ev={"mass": 1500, "mass": 1800}'], tmp_path, monkeypatch, capsys)
    assert "--set ev=" in err and "key 'mass' appears twice" in err


def test_a_case_list_that_names_a_key_twice_is_refused(tmp_path):
    data = cases_mod.generate()
    text = json.dumps(data, indent=1)
    first = json.dumps(data["cases"][5], indent=1).replace("\n", "\n  ")
    assert first in text
    path = tmp_path / "cases.json"
    path.write_text(text.replace(first, first[:-1].rstrip() + ', "sumo_seed": 9\n  }', 1))
    with pytest.raises(CaseError) as e:
        load(path)
    assert "\n" not in str(e.value) and f"case list {path}: key 'sumo_seed' appears twice" in str(e.value)


@pytest.mark.parametrize("option", ["--run-id", "--name"])
def test_a_name_too_long_for_a_file_name_is_refused_up_front(option, tmp_path, monkeypatch, capsys):
    extra = ["--agent", "some_module:factory"] if option == "--name" else []
    err = _refused([option, "a" * 256, *extra], tmp_path, monkeypatch, capsys)
    assert f"argument {option}: 'aaaa" in err and "(256 characters)" in err and f"at most {MAX_NAME} characters" in err
    assert parse(["--logs", str(tmp_path / "logs"), option, "a" * MAX_NAME, *extra]) is not None


def test_an_agent_factory_whose_name_is_too_long_needs_a_name(tmp_path, monkeypatch, capsys):
    err = _refused(["--agent", "some_module:" + "f" * 300], tmp_path, monkeypatch, capsys)
    assert "the factory's name 'fff" in err and "(300 characters) is too long" in err and "give --name" in err


def test_a_lock_file_that_is_a_fifo_is_refused_in_one_line(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    os.mkfifo(run_dir / runlock.LOCK)
    with pytest.raises(runlock.InUse) as e:
        with runlock.hold(run_dir):
            pass
    assert str(e.value) == (f"run folder {run_dir}: its lock file .lock is a FIFO, not a regular file; remove it, "
                            "or use another --run-id")


def test_ecodrive_run_on_a_folder_whose_lock_is_a_fifo_exits_2(tmp_path, capsys):
    from ecodrive_bench.bench.harness.run_command import main

    os.makedirs(tmp_path / "logs" / "smoke")
    os.mkfifo(tmp_path / "logs" / "smoke" / ".lock")
    rc = main(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--methods", "baseline", "--signals",
               "coordinated"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "is a FIFO, not a regular file" in err[0], err


@pytest.mark.parametrize("kind", ["device", "fifo", "large"])
def test_an_sb3_path_that_is_no_regular_file_or_too_large_is_refused_before_it_is_read(kind, tmp_path, monkeypatch):
    from ecodrive_bench.bench.methods import sb3_zip

    path = tmp_path / "model.zip"
    if kind == "device":
        path = Path("/dev/zero")
    elif kind == "fifo":
        os.mkfifo(path)  # opening it to read would wait for a writer
    else:
        monkeypatch.setattr(sb3_zip, "MAX_ZIP_BYTES", 1000)
        path.write_bytes(bytes(1001))
    with pytest.raises(ZipError) as e:
        read(path)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"--sb3 {str(path)!r}: ")
    assert ("not a regular file" in msg) if kind != "large" else ("1001 bytes is too large" in msg)
    with pytest.raises(ZipError, match="model.zip': cannot read it"):  # as before
        read(tmp_path / "gone" / "model.zip")


def test_the_cli_refuses_sb3_dev_zero_in_one_line(tmp_path, monkeypatch, capsys):
    pytest.importorskip("stable_baselines3")
    err = _refused(["--sb3", "/dev/zero", "--sb3-algo", "PPO"], tmp_path, monkeypatch, capsys)
    assert "--sb3 '/dev/zero': not a regular file; accepted: a regular zip file of at most" in err
