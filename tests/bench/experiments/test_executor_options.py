"""``--executor`` and ``--address`` of ``ecodrive sweep`` and ``ecodrive train-all`` (one home:
``bench.harness.executors.add_options``): a bad value is one line naming it and what is accepted,
exit code 2, before anything runs; and the driver's side of a Ray task's files (``land``)."""
from __future__ import annotations

import sys

import pytest

from ecodrive_bench.bench.experiments import sweep
from ecodrive_bench.bench.harness.executors import address, land
from ecodrive_bench.bench.training import train_all

ACCEPTED = "accepted: auto, HOST:PORT or ray://HOST:PORT with PORT 1..65535"


@pytest.mark.parametrize("value", ["auto", "127.0.0.1:6379", "head-node.cluster.local:6379", "ray://10.0.0.5:10001",
                                   "[::1]:6379", "h:65535"])
def test_ray_addresses_are_accepted(value):
    assert address(value) == value


@pytest.mark.parametrize("command, main, prefix", [
    ("ecodrive sweep", sweep.main, ["reward"]), ("ecodrive train-all", train_all.main, []),
])
@pytest.mark.parametrize("args, message", [
    (["--executor", "dask"], "argument --executor: invalid choice: 'dask' (choose from 'local', 'ray')"),
    (["--executor", "ray", "--address", "head"], f"argument --address: 'head' is not accepted; {ACCEPTED}"),
    (["--executor", "ray", "--address", "head:0"], f"argument --address: 'head:0' is not accepted; {ACCEPTED}"),
    (["--executor", "ray", "--address", "h:99999"], f"argument --address: 'h:99999' is not accepted; {ACCEPTED}"),
    (["--executor", "ray", "--address", "http://h:80"], f"argument --address: 'http://h:80' is not accepted; {ACCEPTED}"),
    (["--address", "auto"], "--address auto is for --executor ray (got --executor local); add --executor ray or "
                            "drop --address"),
])
def test_a_bad_executor_or_address_is_one_line(command, main, prefix, args, message, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", [command])
    with pytest.raises(SystemExit) as e:
        main(prefix + args + (["--logs", str(tmp_path)] if prefix else ["--models", str(tmp_path)]))
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [f"{command}: error: {message}"]
    assert not any(tmp_path.iterdir())


def test_train_all_on_ray_trains_on_the_cpu(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive train-all"])
    with pytest.raises(SystemExit) as e:
        train_all.main(["--executor", "ray", "--device", "cuda", "--models", str(tmp_path)])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--device cuda with --executor ray" in err[0] and "accepted: --device cpu" in err[0]


def test_landed_files_come_in_whole_the_marker_last(tmp_path, monkeypatch):
    """Every file is written atomically into the folder, the ``last`` one after all others; a name
    that is not a plain file name is refused before anything is written."""
    import ecodrive_bench.bench.harness.executors as executors

    order: list[str] = []
    real = executors.atomic_bytes
    monkeypatch.setattr(executors, "atomic_bytes", lambda data, path: (order.append(path.name), real(data, path)))
    land({"job.json": b"{}", "a.mcap": b"a", "episodes.parquet": b"p"}, tmp_path / "job", last=("job.json",))
    assert order[-1] == "job.json" and sorted(order) == ["a.mcap", "episodes.parquet", "job.json"]
    assert (tmp_path / "job" / "a.mcap").read_bytes() == b"a"
    for bad in ("../escape", "sub/file", ".."):
        with pytest.raises(ValueError, match="not a plain file name"):
            land({"ok": b"", bad: b""}, tmp_path / "other")
        assert not (tmp_path / "other").exists()


@pytest.mark.parametrize("command, main, argv", [
    ("ecodrive sweep", sweep.main, ["reward", "--logs"]), ("ecodrive train-all", train_all.main, ["--models"]),
    ("ecodrive run", None, ["--profile", "smoke", "--logs"]),
])
def test_ray_missing_is_one_line_before_anything_is_written(command, main, argv, tmp_path, monkeypatch, capsys):
    """Where Ray is not installed, ``--executor ray`` is refused at parsing: exit 2, nothing made."""
    import importlib.util

    from ecodrive_bench.bench.harness import executors
    from ecodrive_bench.bench.harness.run_command import main as run_main

    real = importlib.util.find_spec
    monkeypatch.setattr(executors.importlib.util, "find_spec", lambda name, *a: None if name == "ray" else real(name, *a))
    monkeypatch.setattr(sys, "argv", [command])
    with pytest.raises(SystemExit) as e:
        (main or run_main)([*argv, str(tmp_path / "out"), "--executor", "ray"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"{command}: error: --executor ray needs Ray, which is not installed here: pip install -e "
                   f"\".[distributed]\" in the checkout, or use --executor local"]
    assert not (tmp_path / "out").exists()
