from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import ecodrive_bench.bench.training.train as train_module
from ecodrive_bench.bench.experiments import store, sweep
from ecodrive_bench.bench.logs.mcaplog import is_complete
from ecodrive_bench.envs.config import ConfigError
from ecodrive_bench.reports.build import build
from ecodrive_bench.reports.metrics import reward_curves, smooth


@pytest.fixture(autouse=True)
def _store(tmp_path, monkeypatch):
    """Every sweep here keeps its finished jobs under tmp_path, never in the repository's store."""
    monkeypatch.setattr(store, "STORE", tmp_path / "store")


def test_heatmap_job_trains_evaluates_and_resumes(tmp_path, monkeypatch):
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    argv = ["heatmap", "--values", "20", "--episodes", "2", "--cases", "2", "--validation-cases", "1", "--max-episode-time", "60",
            "--workers", "1", "--logs", str(tmp_path / "logs"), "--run-id", "t"]
    assert sweep.main(argv) == 0
    root = tmp_path / "logs" / "t" / "heatmap"
    df = pd.read_parquet(root / "sweep.parquet")
    assert df.config.tolist() == ["s20-j20"] and df.cases.iloc[0] == 2
    assert df.reward_speed_penalty.iloc[0] == 20 and df.reward_lane_change_penalty.iloc[0] == 50
    logs = sorted((root / "s20-j20-s0").glob("case-*.mcap"))
    assert [p.name for p in logs] == ["case-000.mcap", "case-001.mcap"] and all(is_complete(p) for p in logs)
    assert (root / "s20-j20-s0" / "train.mcap").is_file()
    stamps = [p.stat().st_mtime_ns for p in logs]
    assert sweep.main(argv) == 0  # rerun: nothing is trained or evaluated again
    assert [p.stat().st_mtime_ns for p in logs] == stamps
    assert pd.read_parquet(root / "sweep.parquet").energy.iloc[0] == df.energy.iloc[0]
    reward_argv = ["reward", "--forms", "r", "--phi", "1", "--seeds", "0"] + argv[3:]
    assert sweep.main(reward_argv) == 0
    index, _ = build(tmp_path / "logs" / "t", tmp_path / "report")  # no results.parquet: experiments only
    text = index.read_text()
    assert "## Reward study" in text and "## Sensitivity heatmap" in text
    assert "Lowest energy at |r_p^s| = 20, |r_p^j| = 20" in text
    # both sections name the recipe and the short schedule
    assert text.count("2 training episodes by PRL's recipe (n_step 5 beside Table 2) (shorter than the paper's 1000") == 2
    assert (tmp_path / "report" / "figures" / "heatmap.png").is_file()
    assert (tmp_path / "report" / "figures" / "reward-study.pdf").is_file()


def test_jobs_follow_prls_recipe_unless_paper():
    """By default a job trains as the shipped PRL seeds were (the recipe's episodes and departures
    from Table 2); ``--paper`` gives the paper's 1000 episodes and Table 2, a different job with its
    own run folder and identity; ``--episodes`` shortens either."""
    from ecodrive_bench.bench.training.recipes import recipe

    rec = recipe("prl", "uncoordinated")
    (job,) = sweep.jobs("reward", sweep.parse(["reward", "--forms", "r", "--phi", "1", "--seeds", "0"]))
    assert job.episodes == rec.episodes and job.agent_config == rec.overrides and rec.overrides
    (paper,) = sweep.jobs("reward", sweep.parse(["reward", "--forms", "r", "--phi", "1", "--seeds", "0", "--paper"]))
    assert paper.episodes == 1000 and paper.agent_config == {} and "agent_config" not in sweep._identity(paper)
    (short,) = sweep.jobs("reward", sweep.parse(["reward", "--forms", "r", "--phi", "1", "--seeds", "0",
                                                 "--paper", "--episodes", str(rec.episodes)]))
    assert short.episodes == job.episodes and short.run_dir != job.run_dir
    assert sweep._identity(short) != sweep._identity(job) and short.log_dir == job.log_dir


def test_a_job_that_is_a_shipped_seeds_training_takes_its_policy(tmp_path, monkeypatch):
    """The reward study's (r, phi = 1) cell by the recipe is how the shipped PRL seeds were trained:
    the job evaluates the shipped policy and keeps its training metrics instead of training again.
    Any other value (here the episode truncation) makes it a job of its own."""
    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.methods.policies import policy_dir

    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    argv = ["reward", "--forms", "r", "--phi", "1", "--seeds", "0", "--cases", "1", "--workers", "1",
            "--logs", str(tmp_path / "logs"), "--run-id", "t"]
    assert sweep.main(argv) == 0
    shipped = policy_dir("prl", "uncoordinated", seed=0)
    manifest = json.loads((shipped / "manifest.json").read_text())
    row = pd.read_parquet(tmp_path / "logs" / "t" / "reward" / "sweep.parquet").iloc[0]
    assert row.policy_from == "models/prl-uncoordinated/s0" and row.selected_episode == manifest["selected_episode"]
    assert not list((tmp_path / "runs").rglob("checkpoint.pt"))  # nothing was trained
    log_dir = tmp_path / "logs" / "t" / "reward" / "r-phi1-s0"
    assert json.loads((log_dir / store.POLICY_MANIFEST).read_text())["sha256"] == manifest["sha256"]
    assert pd.read_parquet(log_dir / "metrics.parquet").equals(pd.read_parquet(shipped / "metrics.parquet"))
    # a job cut short after the copy (its job.json gone) resumes as the shipped policy's, not as a training
    (log_dir / "job.json").unlink()
    assert sweep.main(argv + ["--store", str(tmp_path / "empty-store")]) == 0  # not restored: run again
    assert pd.read_parquet(tmp_path / "logs" / "t" / "reward" / "sweep.parquet").policy_from.tolist() == [
        "models/prl-uncoordinated/s0"]
    for other, scenario in ((["--max-episode-time", "60"], {"max_episode_time": 60.0}), (["--phi", "0.5"], {})):
        (job,) = sweep.jobs("reward", sweep.parse(argv + other))
        env = make_env("prl", job.signals, {"reward": job.reward, **scenario})
        assert sweep.shipped_training(job, env.cfg.to_dict()) is None, other
        env.close()
    (cell,) = sweep.jobs("heatmap", sweep.parse(["heatmap", "--values", "40", "--seeds", "0"]))  # (40, 40): not (40, 30)
    env = make_env("prl", cell.signals, {"reward": cell.reward})
    assert sweep.shipped_training(cell, env.cfg.to_dict()) is None
    env.close()


def test_a_recipe_jobs_folder_is_not_taken_for_a_paper_jobs(tmp_path, capsys):
    """A log folder finished by a recipe job differs from a ``--paper`` job of the same episodes in
    its agent config, which only the recipe job's identity names: it is refused, not reused."""
    argv = ["reward", "--forms", "r", "--phi", "1", "--seeds", "0", "--episodes", "2", "--logs", str(tmp_path)]
    (job,) = sweep.jobs("reward", sweep.parse(argv))
    (paper,) = sweep.jobs("reward", sweep.parse(argv + ["--paper"]))
    Path(job.log_dir).mkdir(parents=True)
    (Path(job.log_dir) / "job.json").write_text(json.dumps({"job": sweep._identity(job), "row": {}}))
    assert sweep.is_finished(job)
    with pytest.raises(ConfigError, match="agent_config"):
        sweep.is_finished(paper)


def test_heatmap_cells_run_coarse_to_fine(tmp_path, monkeypatch):
    """The corners first, then the middle, then the rest: every k^2 first jobs of a seed are a
    complete k x k block, the grid the heatmap claims are judged on."""
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    labels = [j.label for j in sweep.order(sweep.jobs("heatmap", sweep.parse(["heatmap", "--seeds", "0"])))]
    assert labels[:4] == ["s10-j10-s0", "s50-j10-s0", "s10-j50-s0", "s50-j50-s0"] and len(set(labels)) == 25
    cells = sweep.coarse_to_fine_cells([10.0, 20.0, 30.0, 40.0, 50.0])
    for k in range(1, 6):
        first = cells[: k * k]
        assert set(first) == {(s, j) for s in {c[0] for c in first} for j in {c[1] for c in first}}


def test_jobs_run_started_first_then_lowest_seed_first(tmp_path, monkeypatch):
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    todo = sweep.jobs("reward", sweep.parse(["reward", "--forms", "r", "r2", "--phi", "1", "--seeds", "0", "1"]))
    assert [j.label for j in sweep.order(todo)] == ["r-phi1-s0", "r2-phi1-s0", "r-phi1-s1", "r2-phi1-s1"]
    started = next(j for j in todo if j.label == "r2-phi1-s1")
    Path(started.run_dir).mkdir(parents=True)
    (Path(started.run_dir) / "checkpoint.pt").write_bytes(b"")
    assert [j.label for j in sweep.order(todo)] == ["r2-phi1-s1", "r-phi1-s0", "r2-phi1-s0", "r-phi1-s1"]


def test_two_sweeps_side_by_side_keep_each_others_jobs_in_the_table(tmp_path, monkeypatch):
    """A job that another sweep (another process, on another part of the grid) finishes while this
    one runs stays in the study's table when this sweep rewrites it."""
    argv = ["reward", "--forms", "r", "--phi", "0.5", "--seeds", "0", "--logs", str(tmp_path), "--run-id", "t"]
    root = tmp_path / "t" / "reward"

    def job_json(log_dir: Path, config: str) -> dict:
        row = {"config": config, "seed": 0, "selected_episode": 1, "energy": 1.0, "travel_time": 1.0,
               "collisions": 0, "log_dir": str(log_dir)}
        log_dir.mkdir(parents=True)
        (log_dir / "job.json").write_text(json.dumps({"job": {}, "row": row}))
        return row

    def run_job(job):  # meanwhile, the other sweep finishes r1-phi1
        job_json(root / "r1-phi1-s0", "r1-phi1")
        return job_json(Path(job.log_dir), job.name)

    monkeypatch.setattr(sweep, "run_job", run_job)
    monkeypatch.setattr(sweep, "run_local", lambda todo, workers, fn: (fn(t) for t in todo))
    assert sweep.main(argv) == 0
    assert pd.read_parquet(root / "sweep.parquet").config.tolist() == ["r-phi0.5", "r1-phi1"]


def test_a_sweep_without_a_finished_job_is_reported_as_such(tmp_path):
    """A sweep writes its (empty) tables before its first job finishes; the report says so."""
    for study in sweep.STUDIES:
        (tmp_path / "run" / study).mkdir(parents=True)
        assert sweep.write_tables(tmp_path / "run" / study, {}).empty
    index, _ = build(tmp_path / "run", tmp_path / "report")
    text = index.read_text()
    assert "No job of the reward study has finished yet." in text and "No cell of the heatmap has finished yet." in text


def test_the_report_names_the_training_of_a_mixed_sweep():
    from ecodrive_bench.reports.experiments import _budget

    both = pd.DataFrame({"episodes": [300, 300], "agent_n_step": [5.0, None]})  # a recipe job and a --paper one
    assert "(1 of 2 jobs by PRL's recipe, n_step 5; the others by Table 2)" in _budget(both)
    assert "by PRL's recipe (n_step 5 beside Table 2)" in _budget(both.iloc[:1])
    assert "recipe" not in _budget(pd.DataFrame({"episodes": [1000]}))


def test_smoothing_is_the_papers():
    x = np.array([10.0, 0.0, 0.0])
    assert smooth(x).tolist() == pytest.approx([10.0, 9.8, 9.604])
    curves = reward_curves(pd.DataFrame({"config": ["a"] * 4, "seed": [0, 0, 1, 1], "episode": [0, 1, 0, 1],
                                         "energy": [1.0, 3.0, 3.0, 5.0], "travel_time": [1.0] * 4}))
    assert curves.energy.tolist() == pytest.approx([2.0, 2.04]) and curves.energy_hi.iloc[1] == pytest.approx(3.04)


def test_bad_sweep_input_is_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        sweep.parse(["heatmaps"])
    assert e.value.code == 2 and "choose one of reward, heatmap" in capsys.readouterr().err
    rc = sweep.main(["reward", "--forms", "r9", "--logs", str(tmp_path)])
    assert rc == 2 and "r9" in capsys.readouterr().err and not tmp_path.joinpath("paper").exists()


def test_sweep_table_keeps_earlier_jobs_and_refuses_a_mismatch(tmp_path, monkeypatch, capsys):
    """Two commands over different heatmap cells add up in one table; asking a finished cell again
    with another episode count is refused and its folder is left as it was."""
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    common = ["--episodes", "1", "--cases", "1", "--validation-cases", "1", "--max-episode-time", "30",
              "--workers", "1", "--logs", str(tmp_path / "logs"), "--run-id", "t"]
    assert sweep.main(["heatmap", "--values", "10"] + common) == 0
    assert sweep.main(["heatmap", "--values", "50"] + common) == 0
    root = tmp_path / "logs" / "t" / "heatmap"
    assert pd.read_parquet(root / "sweep.parquet").config.tolist() == ["s10-j10", "s50-j50"]
    assert len(pd.read_parquet(root / "episodes.parquet")) == 2
    before = {p.name: p.read_bytes() for p in (root / "s10-j10-s0").iterdir()}
    common[1] = "2"
    assert sweep.main(["heatmap", "--values", "10"] + common) == 2
    assert "episodes 1 (asked 2)" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in (root / "s10-j10-s0").iterdir()} == before


def test_a_stored_job_is_restored_not_trained(tmp_path, monkeypatch, capsys):
    """A finished job's small results go to the store; a sweep on a machine without the run folder
    or the logs (a new session) restores them instead of training, and the report is built from them.
    A job asked with other values is not taken from the store; a broken stored job is one line, exit 2."""
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    common = ["--forms", "r", "--phi", "1", "--seeds", "0", "--episodes", "2", "--cases", "1",
              "--validation-cases", "1", "--max-episode-time", "30", "--workers", "1", "--store", str(tmp_path / "kept")]
    assert sweep.main(["reward", *common, "--logs", str(tmp_path / "a"), "--run-id", "t"]) == 0
    (kept,) = (tmp_path / "kept" / "reward").iterdir()
    assert kept.name.startswith("uncoordinated-r-phi1-s0-e2-")
    assert sorted(p.name for p in kept.iterdir()) == ["episodes.parquet", "job.json", "manifest.json", "metrics.parquet"]
    # trained by PRL's uncoordinated recipe (n-step 5), which the job's identity names
    assert json.loads((kept / "job.json").read_text())["job"]["agent_config"] == {"n_step": 5}
    assert json.loads((kept / "manifest.json").read_text())["agent_config"]["n_step"] == 5
    first = pd.read_parquet(tmp_path / "a" / "t" / "reward" / "sweep.parquet")
    stored = {p.name: p.read_bytes() for p in kept.iterdir()}

    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs-elsewhere")
    assert sweep.main(["reward", *common, "--logs", str(tmp_path / "b"), "--run-id", "t"]) == 0
    assert "1 finished job(s) restored" in capsys.readouterr().out
    root = tmp_path / "b" / "t" / "reward"
    again = pd.read_parquet(root / "sweep.parquet")
    cols = ["config", "seed", "episodes", "selected_episode", "energy", "travel_time", "collisions"]
    assert again[cols].equals(first[cols])
    assert not (tmp_path / "runs-elsewhere").exists() and not list(root.glob("*/*.mcap"))
    assert {p.name: p.read_bytes() for p in kept.iterdir()} == stored  # restoring writes nothing to the store
    index, warnings = build(tmp_path / "b" / "t", tmp_path / "report")
    assert "## Reward study" in index.read_text() and (tmp_path / "report" / "figures" / "reward-study.pdf").is_file()

    # other values (one more test case): a different job, trained (a run folder appears), not restored
    other = [("2" if i == common.index("--cases") + 1 else c) for i, c in enumerate(common)]
    assert sweep.main(["reward", *other, "--logs", str(tmp_path / "c"), "--run-id", "t"]) == 0
    assert (tmp_path / "runs-elsewhere").is_dir() and len(list((tmp_path / "kept" / "reward").iterdir())) == 2
    assert "restored_from" not in json.loads((tmp_path / "c" / "t" / "reward" / "r-phi1-s0" / "job.json").read_text())["row"]

    capsys.readouterr()
    (kept / "job.json").write_text("{not json")
    assert sweep.main(["reward", *common, "--logs", str(tmp_path / "d"), "--run-id", "t"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(kept) in err and "cannot be read" in err
    assert not (tmp_path / "d" / "t" / "reward" / "r-phi1-s0" / "job.json").exists()


@pytest.mark.parametrize("flag, value, accepted", [
    ("--seeds", "nan", "0.."), ("--seeds", "-1", "0.."),
    ("--episodes", "0", "1..100000"), ("--episodes", "nan", "1..100000"),
    ("--cases", "101", "1..100"), ("--validation-cases", "0", "1..100"),
    # the reward and scenario configs' own ranges
    ("--phi", "abc", "[0.0, 100.0]"), ("--phi", "-1", "[0.0, 100.0]"), ("--values", "2000", "[0.0, 1000.0]"),
    ("--max-episode-time", "nan", "[10.0, 7200.0]"),
])
def test_a_bad_value_names_just_its_flag_value_and_range(flag, value, accepted, monkeypatch, capsys):
    import sys

    monkeypatch.setattr(sys, "argv", ["ecodrive sweep"])
    with pytest.raises(SystemExit) as e:
        sweep.parse(["reward", flag, value])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2
    why = "is out of range"
    if value == "abc":
        why = "is not a number"
    elif ".." in accepted and not value.lstrip("-").isdigit():
        why = "is not an integer"
    assert err == [f"ecodrive sweep: error: argument {flag}: {value!r} {why}; accepted: {accepted}"]


def test_errors_after_parsing_start_with_the_command(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setattr(sys, "argv", ["ecodrive sweep"])
    assert sweep.main(["reward", "--forms", "r9", "--logs", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ecodrive sweep: error: ") and "r9" in err[0]
    blocker = tmp_path / "blocker"
    blocker.write_text("keep")
    assert sweep.main(["heatmap", "--values", "10", "--logs", str(blocker)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ecodrive sweep: error: cannot write")


@pytest.mark.parametrize("name", ["episodes.parquet", "metrics.parquet"])
def test_a_truncated_stored_parquet_is_one_line_and_nothing_is_restored(name, tmp_path, monkeypatch, capsys):
    """A stored job whose parquet file was cut short: one line naming it, exit 2, no job trained,
    the log folder and the store as they were."""
    import sys

    monkeypatch.setattr(sys, "argv", ["ecodrive sweep"])
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")
    monkeypatch.setattr(sweep, "run_local", lambda *a, **k: pytest.fail("a job was run"))
    argv = ["reward", "--forms", "r", "--phi", "1", "--seeds", "0", "--episodes", "2", "--cases", "1",
            "--validation-cases", "1", "--max-episode-time", "30", "--workers", "1", "--store", str(tmp_path / "kept"),
            "--logs", str(tmp_path / "logs"), "--run-id", "t"]
    (job,) = sweep.jobs("reward", sweep.parse(argv))
    src = store.folder(tmp_path / "kept", job.study, job.label, sweep._identity(job))
    src.mkdir(parents=True)
    identity = json.loads(json.dumps(sweep._identity(job), default=float))
    (src / "job.json").write_text(json.dumps({"job": identity, "row": {"config": job.name, "seed": 0}}))
    pd.DataFrame({"energy": [1.0]}).to_parquet(src / "episodes.parquet")
    pd.DataFrame({"episode": [0, 1]}).to_parquet(src / "metrics.parquet")
    (src / "manifest.json").write_text("{}")
    (src / name).write_bytes((src / name).read_bytes()[:30])
    before = {p.name: p.read_bytes() for p in src.iterdir()}
    assert sweep.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"ecodrive sweep: error: {src / name}: not a readable parquet table")
    assert {p.name: p.read_bytes() for p in src.iterdir()} == before
    assert not (tmp_path / "logs" / "t" / "reward" / job.label).exists() and not (tmp_path / "runs").exists()


def test_a_truncated_finished_episodes_table_is_one_line(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setattr(sys, "argv", ["ecodrive sweep"])
    root = tmp_path / "logs" / "t" / "heatmap"
    (root / "old-s0").mkdir(parents=True)
    (root / "old-s0" / "job.json").write_text(json.dumps({"job": {}, "row": {"config": "old", "seed": 0}}))
    (root / "old-s0" / "episodes.parquet").write_bytes(b"PAR1")
    with pytest.raises(ConfigError, match="old-s0/episodes.parquet: not a readable parquet table"):
        sweep.write_tables(root, sweep.finished(root))


def test_the_table_gives_older_jobs_their_share_of_finished_trips(tmp_path):
    """A job row written before rows recorded ``finished`` gets it from its episodes."""
    old, new = tmp_path / "r1-phi1-s0", tmp_path / "r-phi1-s0"
    for d, terminated in ((old, [True, False, False, False]), (new, [True, True])):
        d.mkdir()
        pd.DataFrame({"terminated": terminated, "energy": 1.0}).to_parquet(d / "episodes.parquet")
    rows = {str(old): {"config": "r1-phi1", "seed": 0, "energy": 5.0},
            str(new): {"config": "r-phi1", "seed": 0, "energy": 5.0, "finished": 1.0}}
    table = sweep.write_tables(tmp_path, rows).set_index("config")
    assert table.loc["r1-phi1", "finished"] == 0.25 and table.loc["r-phi1", "finished"] == 1.0
    assert "finished" not in rows[str(old)]  # the job's own row is left as it was


def test_bad_cases_or_store_are_one_line_before_any_training(tmp_path, monkeypatch, capsys):
    """``--cases 0`` (a job with nothing to evaluate) and a ``--store`` that is a file are refused
    in one line, exit 2, before a job trains or a run folder is made."""
    monkeypatch.setattr(sweep, "run_job", lambda job: pytest.fail("a job ran"))
    argv = ["reward", "--forms", "r", "--phi", "1", "--seeds", "0", "--logs", str(tmp_path / "logs"), "--run-id", "t"]
    with pytest.raises(SystemExit) as e:
        sweep.main([*argv, "--cases", "0"])
    assert e.value.code == 2 and "--cases: '0' is out of range; accepted: 1..100" in capsys.readouterr().err
    afile = tmp_path / "afile"
    afile.write_text("precious\n")
    assert sweep.main([*argv, "--store", str(afile)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--store: {afile} is a file, not a folder" in err[0]
    assert afile.read_text() == "precious\n" and not (tmp_path / "logs").exists()


def test_a_sweep_writes_plain_progress_lines_to_a_log(tmp_path, monkeypatch, capsys):
    argv = ["reward", "--forms", "r", "--phi", "1", "--seeds", "0", "--logs", str(tmp_path), "--run-id", "t"]

    def run_job(job):
        row = {"config": job.name, "seed": 0, "selected_episode": 1, "energy": 1.0, "travel_time": 1.0,
               "collisions": 0, "log_dir": job.log_dir}
        Path(job.log_dir).mkdir(parents=True)
        (Path(job.log_dir) / "job.json").write_text(json.dumps({"job": {}, "row": row}))
        return row

    monkeypatch.setattr(sweep, "run_job", run_job)
    monkeypatch.setattr(sweep, "run_local", lambda todo, workers, fn: (fn(t) for t in todo))
    assert sweep.main(argv) == 0
    err = capsys.readouterr().err  # pytest's captured stderr is no terminal: lines, not a bar (bench.progress)
    jobs = [line for line in err.splitlines() if line.startswith("reward jobs: ")]
    assert "\r" not in err and jobs[0] == "reward jobs: 0/1 (0%), starting" and jobs[-1].startswith("reward jobs: 1/1 (100%)")
    assert jobs[-1].endswith(", done") and len(jobs) == 2
