"""The generalisation family and profile: the stored family is the generator's, every variant is a
corridor the shipped policies never saw but can observe, ``ecodrive run --profile
generalisation`` writes one resumable sub-run per variant with --transfer implied, and every bad
input is one line with exit 2."""
from __future__ import annotations

import dataclasses
import json
import sys

import pandas as pd
import pytest

from ecodrive_bench.bench.args import UsageError
from ecodrive_bench.bench.cases import heldout
from ecodrive_bench.bench.cases.case import load as load_cases
from ecodrive_bench.bench.cases.heldout import FamilyError, load, select
from ecodrive_bench.bench.harness.generalisation_run import run_family
from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import resolve_methods
from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.envs.config import SIGNALS, ScenarioConfig

PAPER = ScenarioConfig()


def test_the_stored_family_is_the_generators_and_every_variant_is_a_valid_unseen_corridor():
    assert heldout.main(write=False) == 0
    assert heldout.FAMILY_FILE.read_text() == heldout.text()
    family = load()
    assert len(family) == heldout.N_VARIANTS and len({v.name for v in family}) == len(family)
    fixed = {(c.sumo_seed, c.insert_time) for c in load_cases()}
    for v in family:
        assert len(v.cases) == heldout.CASES_PER_VARIANT and not {(c.sumo_seed, c.insert_time) for c in v.cases} & fixed
        for s in SIGNALS:
            cfg = v.config(s)
            assert cfg.digest() != ScenarioConfig(signals=s).digest()
            assert cfg.n_intersections in heldout.JUNCTIONS and cfg.grid_shape[0] == PAPER.grid_shape[0]
            assert cfg.step_length == PAPER.step_length and 3 <= cfg.lanes <= 5
            assert 600 <= cfg.arterial_flow <= 1400 and len(set(cfg.spacings)) > 1
    assert {v.scenario["lanes"] for v in family} == {3, 4, 5}
    assert sum("junction_offsets" in v.scenario for v in family) == len(family) // 2


def test_a_tampered_or_stale_family_file_is_refused(tmp_path):
    data = json.loads(heldout.text())
    data["variants"][0]["scenario"]["arterial_flow"] = 1500.0
    bad = tmp_path / "generalisation.json"
    bad.write_text(json.dumps(data, indent=1) + "\n")
    with pytest.raises(FamilyError, match="differs from the generator"):
        load(bad)
    assert heldout.main(write=False, path=bad) == 1
    bad.write_text(json.dumps({**data, "version": 99}))
    with pytest.raises(FamilyError, match="version 99"):
        load(bad)
    bad.write_text("{not json")
    with pytest.raises(FamilyError, match="not a readable"):
        load(bad)


def test_variants_are_chosen_by_full_or_short_name():
    family = load()
    assert select(family, None) == family
    assert [v.name for v in select(family, ["g3", family[0].name])] == [family[0].name, family[2].name]
    with pytest.raises(FamilyError, match="unknown variant 'g99'"):
        select(family, ["g99"])


@pytest.mark.parametrize("args, words", [
    (["--profile", "generalisation", "--variants", "nope"], "unknown variant 'nope'"),
    (["--variants", "g1"], "give --profile generalisation or real too"),
    (["--profile", "generalisation", "--set", "lanes=3"], "--scenario, --set and --network are for the other profiles"),
])
def test_bad_input_is_one_line_exit_2(args, words, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    with pytest.raises(SystemExit) as e:
        main([*args, "--logs", str(tmp_path / "logs")])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and words in err[0] and not (tmp_path / "logs").exists()


def test_a_tampered_family_file_stops_the_profile_in_one_line(tmp_path, monkeypatch, capsys):
    bad = tmp_path / "generalisation.json"
    bad.write_text(heldout.text().replace("\"lanes\": 5", "\"lanes\": 6", 1))
    monkeypatch.setattr(heldout, "FAMILY_FILE", bad)
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    with pytest.raises(SystemExit) as e:
        main(["--profile", "generalisation", "--logs", str(tmp_path / "logs")])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "differs from the generator" in err[0]


def test_a_later_variant_that_is_refused_stops_the_profile_before_the_first_runs(tmp_path, monkeypatch, capsys):
    """g2's folder holds another scenario's episodes: the command is refused before g1's folder is
    made, and each policy is loaded once for both variants."""
    import ecodrive_bench.bench.harness.run as harness_run

    loads = []
    real = harness_run.check_policy
    monkeypatch.setattr(harness_run, "check_policy", lambda folder, method: loads.append(folder) or real(folder, method))
    g1, g2 = load()[:2]
    (tmp_path / "generalisation" / g2.name).mkdir(parents=True)
    pd.DataFrame({"signals": ["coordinated"], "eval_scenario_hash": ["another"]}).to_parquet(
        tmp_path / "generalisation" / g2.name / "results.parquet")
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    rc = main(["--profile", "generalisation", "--variants", "g1", "g2", "--methods", "prl", "--signals", "coordinated",
               "--train-seeds", "0", "--logs", str(tmp_path), "--workers", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "another scenario" in err[0] and g2.name in err[0]
    assert not (tmp_path / "generalisation" / g1.name).exists() and len(loads) == 1


def test_the_profile_plans_every_method_with_the_oracle_and_transfer(tmp_path):
    opts = parse(["--profile", "generalisation", "--logs", str(tmp_path)])
    assert opts.transfer is True and opts.run_id == "generalisation" and len(opts.family) == 6
    runs, _ = resolve_methods(opts)
    methods = {m for m, _, _ in runs}
    assert {"baseline", "baseline0", "oracle", "mpc", "prl"} <= methods
    (tmp_path / "generalisation").mkdir()
    (tmp_path / "generalisation" / "results.parquet").write_bytes(b"")
    with pytest.raises(UsageError, match="single-scenario run"):
        run_family(opts, progress=False)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """One variant (3 lanes, random offsets) x one case: a shipped 5-lane policy, the baseline,
    the oracle and mpc on it, for real."""
    logs = tmp_path_factory.mktemp("gen")
    argv = ["--profile", "generalisation", "--variants", "g3", "--methods", "prl", "baseline", "oracle", "mpc",
            "--signals", "coordinated", "--train-seeds", "0", "--workers", "2", "--logs", str(logs)]
    opts = parse(argv)
    opts.family = [dataclasses.replace(v, cases=v.cases[:1]) for v in opts.family]
    return run_family(opts, progress=False), logs / "generalisation", opts


def test_a_shipped_policy_drives_a_held_out_variant_with_transfer(tiny):
    df, root, opts = tiny
    variant = opts.family[0]
    assert len(df) == 4 and set(df.variant) == {variant.name} and df.terminated.all() and (df.collisions == 0).all()
    assert set(df.eval_scenario_hash) == {variant.config("coordinated").digest()}
    assert set(df.train_scenario_hash[df.method == "prl"]) == {ScenarioConfig(signals="coordinated").digest()}
    sub = root / variant.name
    assert (sub / "results.parquet").is_file() and json.loads((sub / "manifest.json").read_text())["transfer"] is True
    assert all((root / m).is_file() for m in df.mcap)  # paths relative to the family folder
    man = json.loads((root / "manifest.json").read_text())
    assert man["profile"] == "generalisation" and man["family"]["version"] == heldout.VERSION
    assert man["variants"] == {variant.name: variant.scenario}
    again = run_family(opts, progress=False)  # a rerun reuses every finished episode
    pd.testing.assert_frame_equal(df.drop(columns="sumo_s"), again.drop(columns="sumo_s"))
    assert again.sumo_s.isna().all() and (df.sumo_s > 0).all()  # SUMO's time of episodes run, not reused


def test_the_report_of_a_generalisation_run(tiny, tmp_path):
    from ecodrive_bench.reports.command import main as report

    _, root, opts = tiny
    assert report([str(root), "--out", str(tmp_path / "r")]) == 0
    md = (tmp_path / "r" / "index.md").read_text()
    assert "## Generalisation: held-out corridors" in md and opts.family[0].name in md
    assert (tmp_path / "r" / "generalisation.csv").is_file() and (tmp_path / "r" / "figures" / "generalisation-coordinated.png").is_file()
    page = (tmp_path / "r" / "index.html").read_text()
    assert "Generalisation" in page
    # a change is shown once as a percent, in the markdown and on the page (not scaled twice)
    per = pd.read_csv(tmp_path / "r" / "generalisation.csv")
    change = per.loc[per.method == "prl", "energy_change"].iloc[0]
    text = f"{100 * change:+.1f}%"
    assert f"| {text} |" in md and text.replace("-", "\u2212") in page
    assert f"{10000 * change:+.0f}%".replace("-", "\u2212") not in page


def test_the_docs_list_the_family():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[3] / "docs" / "generalisation.md").read_text()
    assert f"version {heldout.VERSION}" in doc and str(heldout.MASTER_SEED) in doc
    for v in load():
        spacings = ', '.join(f'{x:g}' for x in v.scenario['spacings'])
        assert f"| {v.name} | {v.scenario['n_intersections']} | {spacings} |" in doc
