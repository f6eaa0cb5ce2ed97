"""Bad input files are refused in one line naming the file, the entry, the value and the accepted
range, before anything is read without bounds or written: a case list (``bench.cases.case.load``,
the generalisation family's cases), a ``--scenario`` file and a ``--set`` value."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from ecodrive_bench.bench.args import MAX_JSON_BYTES, InputError, UsageError
from ecodrive_bench.bench.cases import case as cases_mod
from ecodrive_bench.bench.cases import heldout
from ecodrive_bench.bench.cases.case import CaseError, check_cases, load
from ecodrive_bench.bench.cases.heldout import FamilyError
from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.scenarios import parse_overrides

SIGNALS = ["coordinated", "uncoordinated"]


def _write_cases(tmp_path, edit) -> os.PathLike:
    data = cases_mod.generate()
    edit(data["cases"])
    path = tmp_path / "cases.json"
    path.write_text(json.dumps(data, indent=1))
    return path


def _set(key, value):
    def edit(cases):
        cases[5][key] = value
    return edit


def _drop(key):
    def edit(cases):
        del cases[5][key]
    return edit


def _duplicate(cases):
    cases[7]["index"] = 3


@pytest.mark.parametrize("edit, words", [
    (_duplicate, ["case #7 (index 3)", "index=3 is also case #3's", "unique non-negative integers"]),
    (_set("insert_time", -5.0), ["case #5 (index 5)", "insert_time=-5.0", "[150.0, 300.0]"]),
    (_set("insert_time", 400), ["insert_time=400", "[150.0, 300.0]"]),
    (_set("insert_time", "210"), ["insert_time='210'", "[150.0, 300.0]"]),
    (_set("sumo_seed", "7"), ["case #5", "sumo_seed='7'", "an integer in [0, 2**31-1)"]),
    (_set("sumo_seed", 2**70), ["sumo_seed=1180591620717411303424", "[0, 2**31-1)"]),
    (_set("sumo_seed", 2**31 - 1), ["sumo_seed=2147483647", "[0, 2**31-1)"]),
    (_set("sumo_seed", True), ["sumo_seed=True", "[0, 2**31-1)"]),
    (_set("index", -1), ["case #5 (index -1)", "index=-1", "[0, inf)"]),
    (_set("group", 10), ["group=10", "[0, 10)"]),
    (_set("seed", 1), ["unknown key(s) 'seed'", "exactly index, sumo_seed, insert_time, group"]),
    (_drop("insert_time"), ["missing key(s) 'insert_time'", "exactly index, sumo_seed, insert_time, group"]),
])
def test_a_bad_case_is_one_line_naming_the_file_the_case_and_the_range(edit, words, tmp_path):
    path = _write_cases(tmp_path, edit)
    with pytest.raises(CaseError) as e:
        load(path)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg
    for w in words:
        assert w in msg
    assert isinstance(e.value, InputError) and isinstance(e.value, ValueError)  # the commands' exit 2


@pytest.mark.parametrize("key, value, words", [
    ("groups", 3, ["groups=3", "accepted: 10 (the violin figure groups the cases by index mod 10)"]),
    ("groups", -1, ["groups=-1", "accepted: 10"]),
    ("groups", None, ["groups=None", "accepted: 10"]),
    ("groups", 10.5, ["groups=10.5", "accepted: 10"]),
    ("groups", "ten", ["groups='ten'", "accepted: 10"]),
    ("insert_range_s", [0, 1], ["insert_range_s=[0, 1]", "accepted: [150.0, 300.0]"]),
    ("insert_range_s", None, ["insert_range_s=None", "accepted: [150.0, 300.0]"]),
    ("master_seed", "abc", ["master_seed='abc'", "a non-negative integer"]),
])
def test_a_bad_case_list_header_is_one_line(key, value, words, tmp_path):
    data = cases_mod.generate()
    data[key] = value
    path = tmp_path / "cases.json"
    path.write_text(json.dumps(data))
    with pytest.raises(CaseError) as e:
        load(path)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg and all(w in msg for w in words), msg


def test_a_case_list_without_cases_says_so(tmp_path):
    data = cases_mod.generate()
    del data["cases"]
    path = tmp_path / "cases.json"
    path.write_text(json.dumps(data))
    with pytest.raises(CaseError, match="no 'cases' list \\(missing or null\\)"):
        load(path)


def test_a_case_whose_group_is_not_its_index_mod_10_is_refused(tmp_path):
    path = _write_cases(tmp_path, _set("group", 7))  # case 5's group is 5
    with pytest.raises(CaseError, match=r"case #5 \(index 5\): group=7; accepted: the index mod 10, 5"):
        load(path)


def test_the_stored_cases_load_and_check_cleanly(tmp_path):
    got = load()
    assert [c.index for c in got] == list(range(100)) and got == check_cases(cases_mod.generate()["cases"], "x", 10)


@pytest.mark.parametrize("kind", ["device", "folder", "large", "deep", "binary", "list", "version"])
def test_a_case_list_that_is_not_one_is_refused_before_it_is_read(kind, tmp_path):
    path = {"device": "/dev/zero", "folder": str(tmp_path)}.get(kind, tmp_path / "cases.json")
    if kind == "large":
        path.write_text(" " * (MAX_JSON_BYTES + 1))
    elif kind == "deep":
        path.write_text("[" * 100_000)
    elif kind == "binary":
        path.write_bytes(b"\xff\xfe{}")
    elif kind == "list":
        path.write_text("[]")
    elif kind == "version":
        path.write_text('{"version": 2, "cases": []}')
    with pytest.raises(CaseError) as e:
        load(path)
    assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_a_bad_case_in_the_family_file_is_named(tmp_path):
    data = json.loads(heldout.text())
    data["variants"][1]["cases"][3]["sumo_seed"] = "7"
    bad = tmp_path / "generalisation.json"
    bad.write_text(json.dumps(data, indent=1) + "\n")
    with pytest.raises(FamilyError) as e:
        heldout.load(bad)
    name = data["variants"][1]["name"]
    assert f"variant {name}: case #3 (index 3): sumo_seed='7'" in str(e.value) and "[0, 2**31-1)" in str(e.value)
    data["variants"][0]["cases"][2]["index"] = 1
    bad.write_text(json.dumps(data, indent=1) + "\n")
    with pytest.raises(FamilyError, match=r"case #2 \(index 1\): index=1 is also case #1's"):
        heldout.load(bad)


def _scenario_file(kind, tmp_path):
    if kind == "device":
        return "/dev/zero"
    if kind == "folder":
        return str(tmp_path)
    path = tmp_path / "s.json"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "large":
        path.write_text('{"lanes": 3' + " " * MAX_JSON_BYTES + "}")
    elif kind == "deep":
        path.write_text("[" * 100_000)
    elif kind == "deep-valid":  # parses, but deeper than any scenario
        path.write_text('{"ev": ' + "[" * 200 + "]" * 200 + "}")
    elif kind == "digits":
        path.write_text('{"lanes": ' + "9" * 5000 + "}")
    return str(path)


@pytest.mark.parametrize("kind, words", [
    ("device", ["/dev/zero: not a regular file", "at most 1048576 bytes (1 MiB)"]),
    ("folder", ["not a regular file"]),
    ("fifo", ["not a regular file"]),
    ("large", ["bytes is too large", "at most 1048576 bytes"]),
    ("deep", ["not a readable JSON file", "nested more than 32 deep"]),
    ("deep-valid", ["nested more than 32 deep"]),
    ("digits", ["not a readable JSON file"]),
])
def test_a_scenario_file_is_refused_in_one_line_before_it_is_read(kind, words, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    with pytest.raises(SystemExit) as e:
        parse(["--logs", str(tmp_path / "logs"), "--scenario", _scenario_file(kind, tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "--scenario" in err[0]
    for w in words:
        assert w in err[0]
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize("item, words", [
    ("yellow=0", ["--set yellow=0", "yellow=0 is out of range; accepted: [1.0, 10.0]"]),
    ("main_green=87", ["main_green=87", "side green of >= 1.0 s"]),
    ("spacings=" + "[" * 100_000, ["--set spacings=[[[", "VALUE is not readable"]),
    ("spacings=" + "[" * 100 + "]" * 100, ["nested more than 32 deep"]),
    ("lanes=" + "9" * 5000, ["VALUE is not readable"]),
    ("a" + ".a" * 50_000 + "=1", ["FIELD has 50001 parts"]),
])
def test_a_bad_set_value_is_one_line_exit_2(item, words, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    with pytest.raises(SystemExit) as e:
        parse(["--logs", str(tmp_path / "logs"), "--set", item])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and len(err[0]) < 600
    for w in words:
        assert w in err[0]
    assert not (tmp_path / "logs").exists()


def test_a_scenario_netconvert_cannot_build_is_refused_at_parse_time(tmp_path, monkeypatch):
    import ecodrive_bench.envs.scenario as scenario

    fake = tmp_path / "netconvert"
    fake.write_text("#!/bin/sh\necho 'Error: cannot do that' >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setattr(scenario, "_netconvert", lambda: str(fake))
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "cache"))
    with pytest.raises(InputError) as e:
        parse_overrides(None, ["lanes=3"], ["coordinated"])
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("--scenario/--set: scenario ") and "Error: cannot do that" in msg
    assert parse_overrides(None, ["lanes=3"], ["coordinated"], build=False) == {"lanes": 3}


def test_ecodrive_run_with_a_bad_case_list_is_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys):
    """A duplicate index (one MCAP would overwrite the other) is refused before the run folder is
    made: the case list is read in the run's checks (``bench.harness.run.preflight``)."""
    from ecodrive_bench.bench.harness import run as run_mod
    from ecodrive_bench.bench.harness.run_command import main

    bad = _write_cases(tmp_path, _duplicate)
    monkeypatch.setattr(run_mod, "load", lambda: load(bad))
    logs = tmp_path / "logs"
    assert main(["--profile", "smoke", "--methods", "baseline", "--signals", "coordinated", "--logs", str(logs)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is also case" in err[0] and str(bad) in err[0]
    assert not logs.exists()


def test_planners_join_the_default_methods_or_the_named_ones_in_one_command(tmp_path):
    """``--planners`` adds oracle, mpc and clairvoyant, once, to the methods with a shipped policy or
    to those named; without it they run only when named (``--profile generalisation`` always has them)."""
    from ecodrive_bench.bench.harness.options import parse
    from ecodrive_bench.bench.harness.run import resolve_methods

    def methods(*argv: str) -> list[str]:
        runs, _ = resolve_methods(parse([*argv, "--logs", str(tmp_path)]))
        return list(dict.fromkeys(m for m, _, _ in runs))

    plain, with_planners = methods(), methods("--planners")
    assert not {"oracle", "mpc", "clairvoyant"} & set(plain) and {"prl", "baseline"} <= set(plain)
    assert with_planners == [*plain, "oracle", "mpc", "clairvoyant"]
    assert methods("--methods", "baseline", "--planners") == ["baseline", "oracle", "mpc", "clairvoyant"]
    assert methods("--methods", "mpc", "baseline", "--planners") == ["mpc", "baseline", "oracle", "clairvoyant"]


def test_the_benchmark_session_adds_the_planners_unless_methods_are_named():
    """``nox -s benchmark`` runs the planners in its one ``ecodrive run`` unless ``--methods`` is
    given (abbreviated too); options it cannot read are left to ``ecodrive run`` to refuse."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("noxfile", Path(__file__).parents[3] / "noxfile.py")
    noxfile = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(noxfile)
    assert noxfile._given([]).methods is None
    assert noxfile._given(["--profile", "smoke", "--workers", "2"]).methods is None
    for given in (["--methods", "prl"], ["--meth", "prl"], ["--methods=prl"]):
        assert noxfile._given(given).methods == ["prl"], given
    assert noxfile._given(["--methods"]) is None  # ecodrive run refuses it


def test_a_run_folder_keeps_one_case_set(tmp_path, capsys):
    """A command after which a run folder's methods would drive different cases (another profile
    into the same --run-id; a method added on fewer cases) is refused in one line naming both sets,
    before anything is written; rerunning some cases of a method the folder has is allowed, and a
    table the harness would not keep (no train_seed column: written before it) is no reason."""
    import pandas as pd

    from ecodrive_bench.bench.harness.run import KEEP, SCENARIO_COLUMNS, one_case_set
    from ecodrive_bench.bench.harness.run_command import main

    run_dir = tmp_path / "mine"
    run_dir.mkdir()
    rows = [("coordinated", c) for c in (0, 1, 2)] + [("uncoordinated", 7)]
    table = pd.DataFrame([{**{k: 0 for k in KEEP if k not in SCENARIO_COLUMNS}, "method": "glosa", "train_seed": -1,
                           "signals": s, "case": c} for s, c in rows])  # the default scenario, as a table before
                                                                       # its scenario columns
    table.to_parquet(run_dir / "results.parquet")
    before = sorted(p.name for p in run_dir.iterdir())

    def refused(*argv: str) -> str:
        rc = main([*argv, "--run-id", "mine", "--logs", str(tmp_path), "--workers", "1"])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and sorted(p.name for p in run_dir.iterdir()) == before
        return err[0]

    err = refused("--profile", "paper", "--methods", "baseline", "--signals", "coordinated")
    assert "holds coordinated episodes on cases 0-2; this command runs cases 0-99 (glosa would keep only those)" in err
    err = refused("--profile", "smoke", "--methods", "baseline", "--signals", "uncoordinated")
    assert "on cases 7; this command runs cases 0-2 (neither set holds the other)" in err
    with pytest.raises(UsageError, match=r"runs cases 1 \(baseline would drive only these\)"):
        one_case_set(run_dir, [("baseline", "coordinated", -1)], {1})
    one_case_set(run_dir, [("glosa", "coordinated", -1)], {1})  # some cases of a method it has: allowed
    one_case_set(run_dir, [("glosa", "coordinated", -1), ("baseline", "coordinated", -1)], set(range(100)))
    table.drop(columns="train_seed").to_parquet(run_dir / "results.parquet")
    one_case_set(run_dir, [("baseline", "coordinated", -1)], set(range(100)))


def test_a_models_folder_that_is_not_there_is_refused(tmp_path, capsys):
    """A typo in --models would silently drop every learning method: one line, exit 2."""
    from ecodrive_bench.bench.harness.run_command import main

    (tmp_path / "a-file").write_text("")
    for path, why in ((tmp_path / "nope", "no such folder"), (tmp_path / "a-file", "not a folder")):
        with pytest.raises(SystemExit) as e:
            main(["--profile", "smoke", "--models", str(path), "--logs", str(tmp_path / "logs")])
        err = capsys.readouterr().err.strip().splitlines()
        assert e.value.code == 2 and len(err) == 1 and f"--models {path}: {why}" in err[0]
    assert not (tmp_path / "logs").exists()
