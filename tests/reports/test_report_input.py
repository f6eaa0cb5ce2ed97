"""The report meets damaged or odd input honestly: a partial step log is never counted as an
episode, the working directory does not matter, and bad input is one line with nothing left."""
from __future__ import annotations

import json
import shutil
from html import unescape

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run
from ecodrive_bench.reports.build import build
from ecodrive_bench.reports.command import main


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
    ("manifest_text", "not a readable JSON file"),
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
    assert "typed by hand" not in text and "| Baseline (SUMO's Krauss driver and LC2013) |" in text and text.endswith("rest\n")
    bare = tmp_path / "BARE.md"
    bare.write_text("no block\n")
    assert main([str(smoke), "--out", str(tmp_path / "rep2"), "--readme", str(bare)]) == 2
    assert bare.read_text() == "no block\n" and not (tmp_path / "rep2").exists()  # refused before building
    assert "no '<!-- headline:start -->'" in capsys.readouterr().err.splitlines()[-1]
    assert main([str(smoke), "--out", str(tmp_path / "rep3"), "--readme", str(tmp_path / "missing.md")]) == 2
    assert not (tmp_path / "rep3").exists()


# ---------------------------------------------------------------- a crafted results table
def craft(smoke, tmp_path, change) -> tuple:
    """A copy of the smoke run whose results table is ``change(table)``, and the original table."""
    run_dir = copy(smoke, tmp_path)
    table = pd.read_parquet(run_dir / "results.parquet")
    change(table.copy()).to_parquet(run_dir / "results.parquet")
    return run_dir, table


def energy_as_words(t):
    t = t.assign(energy=t.energy.astype(str))
    t.loc[2, "energy"] = "abc"
    return t


def case_as_fraction(t):
    return t.assign(case=t.case.astype(float) + 0.5)


def unknown_signals(t):
    t.loc[0, "signals"] = "coord"
    return t


def missing_method(t):
    t.loc[1, "method"] = None
    return t


def terminated_as_words(t):
    return t.assign(terminated="yes")


STRUCTURAL = [
    (energy_as_words, "column 'energy' holds 'abc' in row 2", "a number"),
    (lambda t: t.iloc[:0], "no rows", "one row per episode"),
    (case_as_fraction, "column 'case' holds 0.5", "an integer >= 0"),
    (unknown_signals, "column 'signals' holds 'coord'", "coordinated or uncoordinated"),
    (missing_method, "column 'method' holds a missing value in row 1", "a method name"),
    (terminated_as_words, "column 'terminated' holds 'yes'", "True or False"),
    *[((lambda c: lambda t: t.drop(columns=[c]))(col), f"no {col!r} column", "has method, signals")
      for col in ("method", "signals", "case", "energy", "travel_time", "mcap")],
]


@pytest.mark.parametrize("change, what, expected", STRUCTURAL,
                         ids=["energy-text", "empty", "case-fraction", "signals", "method-none", "terminated-text",
                              *[f"no-{c}" for c in ("method", "signals", "case", "energy", "travel_time", "mcap")]])
def test_a_structurally_bad_results_table_is_one_line_naming_file_and_column(change, what, expected, smoke,
                                                                             tmp_path, capsys):
    run_dir, _ = craft(smoke, tmp_path, change)
    out = tmp_path / "report"
    assert main([str(run_dir), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert str(run_dir / "results.parquet") in err[0] and what in err[0] and expected in err[0]
    assert "Traceback" not in err[0] and not out.exists()


def test_a_refused_table_leaves_an_existing_report_as_it_was(smoke, tmp_path, capsys):
    run_dir, _ = craft(smoke, tmp_path, lambda t: t.iloc[:0])
    out = tmp_path / "report"
    out.mkdir()
    (out / "index.md").write_text("an earlier report")
    (out / ".report-files.json").write_text('["index.md"]\n')
    assert main([str(run_dir), "--out", str(out)]) == 2
    assert "no rows" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == [".report-files.json", "index.md"]
    assert (out / "index.md").read_text() == "an earlier report"


def nan_energy(t):
    t.loc[1, "energy"] = float("nan")
    return t


def inf_time(t):
    t.loc[1, "travel_time"] = float("inf")
    return t


def copied_rows(t):
    return pd.concat([t, t.iloc[[0, 1]]], ignore_index=True)


def clashing_copy(t):
    other = t.iloc[[0]].assign(energy=1.0)
    return pd.concat([t, other], ignore_index=True)


@pytest.mark.parametrize("change, why, dropped, kept", [
    (nan_energy, "1 row(s) dropped with a missing (NaN) energy", [1], [0, 2]),
    (inf_time, "1 row(s) dropped with an infinite travel_time", [1], [0, 2]),
    (copied_rows, "2 row(s) dropped that are exact copies of another row", [], [0, 1, 2]),
    (clashing_copy, "2 row(s) dropped that share their signals, method, train_seed, case", [0], [1, 2]),
], ids=["nan-energy", "inf-time", "duplicates", "conflicting-duplicates"])
def test_bad_rows_are_dropped_and_said_in_the_report_and_on_stderr(change, why, dropped, kept, smoke, tmp_path,
                                                                   capsys):
    """Baseline's rows of the given cases are dropped; Table 4 is the mean of those kept, never
    inf or NaN, every table counts each episode once, and the report says what was dropped."""
    run_dir, table = craft(smoke, tmp_path, change)
    out = tmp_path / "report"
    assert main([str(run_dir), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"warning: {run_dir / 'results.parquet'}: {why}" in err and "baseline/coordinated" in err
    for page in ("index.md", "index.html"):
        text = (out / page).read_text()
        assert why in text and "baseline/coordinated" in text, page
    t4 = pd.read_csv(out / "table4.csv").set_index("method")
    base = table[(table.method == "baseline") & table.case.isin(kept)]
    assert t4.loc["baseline", "energy"] == pytest.approx(base.energy.mean())
    assert t4.loc["baseline", "travel_time"] == pytest.approx(base.travel_time.mean())
    assert "inf" not in (out / "table4.md").read_text() and "nan" not in (out / "table4.md").read_text()
    st = pd.read_csv(out / "statistics.csv").set_index(["method", "metric"])
    assert st.loc[("baseline", "energy"), "n"] == len(kept) and st.loc[("glosa", "energy"), "n"] == 3
    parts = pd.read_csv(out / "return_parts.csv").set_index("method")
    assert parts.loc["baseline", "episodes"] == len(kept)
    assert not set(dropped) & set(kept)


def test_numbers_stored_as_text_are_read_as_numbers(smoke, tmp_path, capsys):
    run_dir, table = craft(smoke, tmp_path, lambda t: t.assign(energy=t.energy.astype(str)))
    out = tmp_path / "report"
    assert main([str(run_dir), "--out", str(out)]) == 0
    assert "column 'energy' is stored as" in capsys.readouterr().err
    t4 = pd.read_csv(out / "table4.csv").set_index("method")
    assert t4.loc["baseline", "energy"] == pytest.approx(table[table.method == "baseline"].energy.mean())


def test_report_files_are_never_written_through_a_planted_link(smoke_report, tmp_path, capsys):
    """``index.html`` and ``table4.csv`` planted as links to a file outside are replaced, not
    written through; a report folder that is a link is refused in one line."""
    from ecodrive_bench.reports.command import main as report_main

    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "report"
    out.mkdir()
    for name in ("index.html", "table4.csv", "figures"):
        (out / name).symlink_to(victim)
    assert report_main([str(smoke_report["run"]), "--out", str(out)]) == 2  # a folder holding links
    assert "symbolic link" in capsys.readouterr().err
    for name in ("index.html", "table4.csv", "figures"):
        (out / name).unlink()
    (out / "index.html").symlink_to(victim)
    linked = tmp_path / "linked-report"
    linked.symlink_to(out, target_is_directory=True)
    assert report_main([str(smoke_report["run"]), "--out", str(linked)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "is a symbolic link" in err
    (out / "index.html").unlink()
    assert report_main([str(smoke_report["run"]), "--out", str(out)]) == 0
    assert victim.read_text() == "precious\n" and not (out / "index.html").is_symlink()


def test_a_planted_link_under_a_reports_file_name_is_replaced(smoke_report, tmp_path):
    from ecodrive_bench.bench.io import atomic_csv

    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    (tmp_path / "table4.csv").symlink_to(victim)
    atomic_csv(pd.DataFrame({"a": [1]}), tmp_path / "table4.csv")
    assert victim.read_text() == "precious\n" and pd.read_csv(tmp_path / "table4.csv").a.tolist() == [1]


def test_a_file_given_as_the_report_folder_is_one_line_and_kept(smoke, tmp_path, capsys):
    """``--out`` naming an existing file: one line saying it is a file, exit 2, the file as it was."""
    target = tmp_path / "a-file"
    target.write_text("precious\n")
    assert main([str(smoke), "--out", str(target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{target} is a file, not a folder" in err[0]
    assert target.read_text() == "precious\n"


def test_a_report_rebuilt_in_its_folder_removes_only_its_earlier_files(smoke_report, tmp_path):
    """A report of fewer signal settings, built over a report of more: the figures and tables of
    the setting no longer in the run go, the user's own file and a file no report listed stay."""
    run_dir = tmp_path / "run"
    shutil.copytree(smoke_report["run"], run_dir)
    out = tmp_path / "report"
    build(run_dir, out, progress=False)
    first = set(json.loads((out / ".report-files.json").read_text()))
    assert {"index.md", "index.html", "table4.csv", "figures/violin-uncoordinated.png"} <= first
    (out / "notes.txt").write_text("mine\n")
    (out / "figures" / "sketch.png").write_bytes(b"mine")
    results = pd.read_parquet(run_dir / "results.parquet")
    results[results.signals == "coordinated"].to_parquet(run_dir / "results.parquet", index=False)
    build(run_dir, out, progress=False)
    second = set(json.loads((out / ".report-files.json").read_text()))
    left = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    assert not any("uncoordinated" in f for f in second | left), sorted(left)
    assert "figures/violin-coordinated.png" in second and left == second | {
        ".report-files.json", "notes.txt", "figures/sketch.png"}
    assert (out / "notes.txt").read_text() == "mine\n"


def test_a_damaged_file_list_removes_nothing(smoke_report, tmp_path):
    out = tmp_path / "report"
    build(smoke_report["run"], out, progress=False)
    (out / "figures" / "old.png").write_bytes(b"an earlier report's")
    (out / ".report-files.json").write_text("[not json")
    build(smoke_report["run"], out, progress=False)
    assert (out / "figures" / "old.png").is_file()
    assert "figures/old.png" not in json.loads((out / ".report-files.json").read_text())


def test_a_run_on_another_scenario_is_not_judged_by_the_papers_claims(smoke_report, tmp_path):
    """A run evaluated with scenario overrides (``--scenario``/``--set``): the report says so at the top
    and under Warnings, and every paper claim is NOT CHECKED, in index.md as in index.html."""
    run_dir = tmp_path / "run"
    shutil.copytree(smoke_report["run"], run_dir)
    manifest = json.loads((run_dir / "manifest.json").read_text())
    manifest["scenario_overrides"] = {"lanes": 3, "ev": {"mass": 1500.0}}
    (run_dir / "manifest.json").write_text(json.dumps(manifest))
    index, warnings = build(run_dir, tmp_path / "report", progress=False)
    md, html = index.read_text(), (tmp_path / "report" / "index.html").read_text()
    assert "Scenario: **not the paper's**: `lanes=3, ev.mass=1500.0`" in md
    assert any("scenario is not the paper's (lanes=3, ev.mass=1500.0)" in w for w in warnings)
    head = unescape(html.split("</header>")[0])
    assert "<span>Scenario</span><b>not the paper's: <code>lanes=3, ev.mass=1500.0</code>" in head
    claims_html = html.split("<section id='claims'>")[1].split("</section>")[0]
    assert "this run's scenario is not the paper's (lanes=3, ev.mass=1500.0)" in unescape(claims_html)
    section = md.split("## Does the paper hold on this run?")[1].split("\n## ")[0]
    rows = [line for line in section.splitlines() if line.startswith("| ") and "claim" not in line]
    assert rows and all("| NOT CHECKED |" in r for r in rows)
    assert "PASS" not in section and "FAIL" not in section
    assert '<tr class="absent">' in claims_html and '<tr class="pass">' not in claims_html
    assert '<tr class="fail">' not in claims_html


def test_the_paper_scenarios_claims_are_in_index_md(smoke_report):
    """index.md carries the claims table that index.html shows, with the same statuses."""
    md = smoke_report["md"]
    assert "Scenario: the paper's." in md
    section = md.split("## Does the paper hold on this run?")[1].split("\n## ")[0]
    assert "| PASS |" in section or "| FAIL |" in section


def test_a_second_report_into_a_folder_being_written_is_one_line(smoke_report, tmp_path, capsys):
    """Two reports into one folder would prune each other's files: the second is refused while the
    first holds the folder, and the first's files stay."""
    from ecodrive_bench.bench.runlock import hold_folder

    out = tmp_path / "report"
    build(smoke_report["run"], out, progress=False)
    before = sorted(p.name for p in out.rglob("*"))
    with hold_folder(out, "report folder", "another --out"):  # the first report, still writing
        assert main([str(smoke_report["run"]), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"report folder {out} is in use by another ecodrive command; wait" in err[0]
    assert "or use another --out" in err[0] and sorted(p.name for p in out.rglob("*")) == before


def test_the_readme_headline_is_refused_for_another_scenario(smoke_report, tmp_path, capsys):
    run_dir = tmp_path / "run"
    shutil.copytree(smoke_report["run"], run_dir)
    manifest = json.loads((run_dir / "manifest.json").read_text())
    (run_dir / "manifest.json").write_text(json.dumps({**manifest, "scenario_overrides": {"lanes": 3}}))
    readme = tmp_path / "README.md"
    readme.write_text("# x\n<!-- headline:start -->\nold\n<!-- headline:end -->\n")
    assert main([str(run_dir), "--out", str(tmp_path / "rep"), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--readme: this run's scenario is not the paper's (lanes=3)" in err[0]
    assert "old" in readme.read_text() and not (tmp_path / "rep").exists()


def test_a_refused_log_is_named_as_refused_not_partial(smoke, tmp_path, capsys):
    """A log the reader refuses (here: garbage) is counted apart from a partial one, with its reason."""
    run_dir = copy(smoke, tmp_path)
    (run_dir / "coordinated" / "baseline" / "case-001.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(100))
    assert main([str(run_dir), "--out", str(tmp_path / "report")]) == 0
    md = (tmp_path / "report" / "index.md").read_text()
    assert "1 step log(s) were refused by the log reader" in md and "are partial" not in md
    assert "refused by the log reader" in (tmp_path / "report" / "index.html").read_text()
    assert "case-001.mcap" in capsys.readouterr().err


@pytest.mark.parametrize("kind", ["fifo", "zero"])
def test_a_readme_that_is_not_a_regular_file_says_so(kind, smoke, tmp_path, capsys):
    import os

    readme = tmp_path / "README.md"
    if kind == "fifo":
        os.mkfifo(readme)
    else:
        readme.symlink_to("/dev/zero")
    assert main([str(smoke), "--out", str(tmp_path / "report"), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a regular file" in err[0] and "no such file" not in err[0]
    assert not (tmp_path / "report").exists()
