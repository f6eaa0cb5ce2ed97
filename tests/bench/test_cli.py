"""``ecodrive``: every subcommand has a help that names its options, and bad input on any of them
is one line with exit code 2."""
from __future__ import annotations

import subprocess
import sys

import pytest

from ecodrive_bench.bench.cli import COMMANDS, main


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.cli", *args], capture_output=True, text=True, timeout=120)


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
    out = run("--frobnicate")  # an option before any command is named as such
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [out.stderr.strip()] and "--frobnicate" in out.stderr


@pytest.mark.parametrize("command, args", [
    ("mixed", ["--run-id", "../x"]), ("lateral", ["--run-id", "a/b"]), ("sweep", ["reward", "--run-id", ".."]),
    ("run", ["--run-id", "/tmp/abs"]),
])
def test_a_run_id_that_is_a_path_is_refused(command, args, tmp_path):
    out = run(command, "--logs", str(tmp_path / "logs"), *args)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1 and "--run-id" in out.stderr
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize("command, args", [
    ("mixed", ["--logs", "{blk}", "--mpr", "0", "--demand", "200", "--reps", "1"]),
    ("lateral", ["--logs", "{blk}", "--methods", "baseline"]),
    ("train", ["--method", "prl", "--signals", "coordinated", "--episodes", "1", "--out", "{blk}/run"]),
    ("run", ["--logs", "{blk}", "--methods", "baseline", "--profile", "smoke"]),
    ("regress", ["--logs", "{blk}", "--no-mixed"]),
    ("stalls", ["--out", "{blk}/x.parquet"]),
    ("sweep", ["reward", "--logs", "{blk}", "--seeds", "0", "--episodes", "1"]),
    ("view", ["{blk}"]),
    ("report", ["{blk}"]),
])
def test_an_unwritable_or_wrong_folder_is_one_line(command, args, tmp_path, monkeypatch, capsys):
    blocker = tmp_path / "blocker"  # a file where a folder is expected
    blocker.write_bytes(b"keep")
    monkeypatch.setattr(sys, "argv", ["ecodrive"])
    rc = main([command, *[a.format(blk=blocker) for a in args]])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "error" in err[0] and str(blocker) in err[0]
    assert blocker.read_bytes() == b"keep"


@pytest.mark.parametrize("command, args", [
    ("run", ["--profile", "smoke", "--logs", ""]), ("report", ["somewhere", "--out", ""]), ("report", [""]),
    ("sweep", ["reward", "--store", ""]), ("mixed", ["--logs", " "]), ("train", ["--out", ""]),
    ("stalls", ["--out", ""]), ("regress", ["--logs", ""]),
])
def test_an_empty_path_is_refused_not_taken_for_the_current_folder(command, args, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["ecodrive"])
    try:
        rc = main([command, *args])
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "is not accepted; give a file or folder name" in err[0], err
    assert not any(tmp_path.iterdir())


def test_a_module_run_with_python_m_names_itself_so():
    """``python -m MODULE`` help and errors name the module, not its file (``run_command.py``)."""
    out = subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", "--frobnicate"],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.startswith("python -m ecodrive_bench.bench.harness.run_command: error: ")


HEAVY_HELP: tuple[str, ...] = ()  # commands whose --help may import torch: none
# what a help must not import: torch for every other command; for `ecodrive` and `ecodrive run`
# also the runners' stack (SUMO, the compiled kernels, the tables)
NOT_FOR_HELP = {"": ("torch", "numpy", "pandas", "libsumo", "numba", "scipy", "mcap"),
                "run": ("torch", "pandas", "libsumo", "numba", "scipy", "mcap", "matplotlib"),
                "report": ("torch", "pandas", "libsumo", "numba", "scipy", "matplotlib"),
                "train-all": ("torch", "libsumo", "numba", "matplotlib"),
                "lateral": ("torch", "libsumo", "numba", "matplotlib")}
HELP_IMPORTS = """
import contextlib, io, json, sys
from ecodrive_bench.bench.cli import main
sys.argv = ["ecodrive"]
seen = {}
for command in json.loads(sys.argv_commands):
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            main([command, "--help"] if command else ["--help"])
        except SystemExit as e:
            assert e.code == 0, (command, e.code)
    seen[command] = sorted(name for name in sys.modules if "." not in name)
print(json.dumps(seen))
"""


def test_help_answers_without_importing_torch_or_the_runners():
    """``ecodrive --help`` and ``ecodrive COMMAND --help`` build the parser only: the commands
    import their runners after parsing. One interpreter asks each command in turn (``ecodrive``
    and ``run`` first), so a module seen after a command was imported by it or by one before."""
    import json

    commands = ["", "run", *(c for c in COMMANDS if c not in (*HEAVY_HELP, "run"))]
    code = HELP_IMPORTS.replace("sys.argv_commands", repr(json.dumps(commands)))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    seen = json.loads(out.stdout)
    for command in commands:
        banned = NOT_FOR_HELP.get(command, ("torch",))
        assert not set(seen[command]) & set(banned), f"`ecodrive {command} --help` imported " \
                                                     f"{sorted(set(seen[command]) & set(banned))}"


def test_train_help_imports_neither_torch_nor_the_env():
    """``ecodrive train --help`` lists the agents' config fields from ``agents.configs`` (no torch)
    and builds its parser in ``train_command``: no torch, SUMO, numba or pandas, in a fresh process."""
    code = ("import sys\nfrom ecodrive_bench.bench.cli import main\ntry:\n    main(['train', '--help'])\n"
            "except SystemExit:\n    pass\nprint(sorted(m for m in ('torch', 'libsumo', 'numba', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
