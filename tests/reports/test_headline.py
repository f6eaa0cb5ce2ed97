"""The README's headline block is generated from a run's results."""
from __future__ import annotations

import pandas as pd
import pytest

from ecodrive_bench.reports.headline import END, START, rewrite, table


def results() -> pd.DataFrame:
    rows = []
    for s in ("coordinated", "uncoordinated"):
        rows += [{"method": "baseline", "signals": s, "train_seed": -1, "case": c, "energy": 250.0, "travel_time": 200.0}
                 for c in range(2)]
        rows += [{"method": "prl", "signals": s, "train_seed": sd, "case": c, "energy": 200.0 + 10 * sd,
                  "travel_time": 210.0} for sd in (0, 1) for c in range(2)]
    return pd.DataFrame(rows)


def test_table_takes_means_over_seeds_and_improvements_against_the_run_baseline():
    md = table(results())
    prl = next(line for line in md.splitlines() if line.startswith("| PRL |"))
    cells = [c.strip() for c in prl.strip("|").split("|")]
    assert cells[1] == "2"  # training seeds
    assert cells[2] == "205.0" and cells[3] == "+18.0%"  # (250 - 205) / 250
    assert cells[4] == "210.0" and cells[5] == "-5.0%"
    assert "| paper: PRL (Table 4) |  | 221.8 | +4.1% |" in md  # from bench.paper, beside ours


def test_seed_counts_that_differ_by_setting_are_given_per_setting():
    df = results()
    df = df[~((df.signals == "uncoordinated") & (df.train_seed == 1))]  # one seed uncoordinated
    prl = next(line for line in table(df).splitlines() if line.startswith("| PRL |"))
    assert [c.strip() for c in prl.strip("|").split("|")][1] == "2 / 1"  # coordinated / uncoordinated
    only = df[~((df.method == "prl") & (df.signals == "coordinated"))]  # no coordinated run at all
    prl = next(line for line in table(only).splitlines() if line.startswith("| PRL |"))
    assert [c.strip() for c in prl.strip("|").split("|")][1] == "0 / 1"


def test_rewrite_replaces_only_the_block(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"# title\n\nbefore\n{START}\nold\n{END}\nafter\n")
    rewrite(readme, results(), "paper", {"profile": "paper", "git_sha": "abc123"})
    text = readme.read_text()
    assert text.startswith("# title\n\nbefore\n") and text.endswith("after\n") and "old" not in text
    assert "git abc123" in text and "| PRL | 2 |" in text
    bare = tmp_path / "BARE.md"
    bare.write_text("no markers\n")
    with pytest.raises(ValueError, match="no '<!-- headline:start -->'"):
        rewrite(bare, results(), "paper", {})
    assert bare.read_text() == "no markers\n"


def test_the_block_names_the_readme_as_typed_but_no_absolute_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "docs").mkdir()
    for path in (tmp_path / "docs" / "results.md", "docs/results.md"):
        readme = tmp_path / "docs" / "results.md"
        readme.write_text(f"{START}\n{END}\n")
        rewrite(type(readme)(path), results(), "paper", {})
        expected = "results.md`" if str(path).startswith("/") else "docs/results.md`"
        assert f"--readme {expected}" in readme.read_text()


def test_the_physics_sentence_comes_from_the_bound():
    from ecodrive_bench.reports.headline import block, physics_line

    assert physics_line(results(), {}) == ""  # no bound in the run: no sentence
    df = results().assign(cost_bound=300.0, energy_bound=100.0)  # baseline 450, PRL 415 (phi 1)
    line = physics_line(df, {})
    assert line.startswith("How close to physics") and "coordinated, PRL" in line
    assert "closes 23% of the gap" in line and "stays 38% above it" in line  # 35 / 150, 115 / 300
    assert line in block(df, "paper", {})
