"""The report meets damaged or odd input honestly: a partial step log is never counted as an
episode, the working directory does not matter, and bad input is one line with nothing left."""
from __future__ import annotations

import shutil

import pandas as pd
import pytest

from bench.harness.run import parse, run
from reports.build import build, main


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    logs = tmp_path_factory.mktemp("logs")
    run(parse(["--profile", "smoke", "--logs", str(logs), "--methods", "baseline", "glosa", "--signals",
               "coordinated", "--workers", "2"]), progress=False)
    return logs / "smoke"


def copy(smoke, tmp_path):
    shutil.copytree(smoke, tmp_path / "smoke")
    return tmp_path / "smoke"


def test_a_partial_log_is_left_out_and_said_on_stderr(smoke, tmp_path, capsys):
    run_dir = copy(smoke, tmp_path)
    log = run_dir / "coordinated" / "baseline" / "case-001.mcap"
    data = log.read_bytes()
    log.write_bytes(data[: len(data) // 2])
    assert main([str(run_dir), "--out", str(tmp_path / "report")]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and "case-001.mcap" in err
    parts = pd.read_csv(tmp_path / "report" / "return_parts.csv").set_index("method")
    assert parts.loc["baseline", "episodes"] == 2 and parts.loc["glosa", "episodes"] == 3
    assert "1 step log(s) are partial" in (tmp_path / "report" / "index.md").read_text()


def test_the_report_is_the_same_from_any_working_directory(smoke, tmp_path, monkeypatch):
    run_dir = copy(smoke, tmp_path)
    assert not any(pd.read_parquet(run_dir / "results.parquet").mcap.str.startswith("/"))
    monkeypatch.chdir(tmp_path)
    a, warn_a = build(run_dir, tmp_path / "a")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    b, warn_b = build(run_dir.resolve(), tmp_path / "b")
    assert warn_a == warn_b == []
    assert sorted(p.name for p in (tmp_path / "a" / "figures").iterdir()) == \
        sorted(p.name for p in (tmp_path / "b" / "figures").iterdir())
    assert (tmp_path / "a" / "return_parts.csv").read_text() == (tmp_path / "b" / "return_parts.csv").read_text()


@pytest.mark.parametrize("damage, words", [
    ("mcap_file", "not a run folder"),
    ("manifest_list", "expected an object"),
    ("manifest_text", "not valid JSON"),
    ("results_truncated", "not a readable results table"),
    ("results_no_energy", "no 'energy' column"),
])
def test_bad_input_is_one_line_and_leaves_nothing(damage, words, smoke, tmp_path, capsys):
    run_dir = copy(smoke, tmp_path)
    target = run_dir
    if damage == "mcap_file":
        target = run_dir / "coordinated" / "baseline" / "case-000.mcap"
    elif damage == "manifest_list":
        (run_dir / "manifest.json").write_text("[1, 2, 3]")
    elif damage == "manifest_text":
        (run_dir / "manifest.json").write_text("{not json")
    elif damage == "results_no_energy":
        pd.read_parquet(run_dir / "results.parquet").drop(columns=["energy"]).to_parquet(run_dir / "results.parquet")
    else:
        data = (run_dir / "results.parquet").read_bytes()
        (run_dir / "results.parquet").write_bytes(data[: len(data) // 2])
    out = tmp_path / "report"
    assert main([str(target), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]
    assert not out.exists()


def test_readme_headline_is_rewritten_from_the_run(smoke, tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text("# x\n<!-- headline:start -->\ntyped by hand\n<!-- headline:end -->\nrest\n")
    assert main([str(smoke), "--out", str(tmp_path / "rep"), "--readme", str(readme)]) == 0
    text = readme.read_text()
    assert "typed by hand" not in text and "| baseline (SUMO's driver) |" in text and text.endswith("rest\n")
    bare = tmp_path / "BARE.md"
    bare.write_text("no block\n")
    assert main([str(smoke), "--out", str(tmp_path / "rep2"), "--readme", str(bare)]) == 2
    assert bare.read_text() == "no block\n" and not (tmp_path / "rep2").exists()  # refused before building
    assert "no '<!-- headline:start -->'" in capsys.readouterr().err.splitlines()[-1]
    assert main([str(smoke), "--out", str(tmp_path / "rep3"), "--readme", str(tmp_path / "missing.md")]) == 2
    assert not (tmp_path / "rep3").exists()
