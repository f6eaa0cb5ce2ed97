"""``ecodrive sweep`` and ``ecodrive train-all`` on a two-node Ray cluster (two raylets on this
machine) store what the local executor stores: the same files, byte for byte, but for the wall
times some of them record: ``job_wall_s`` (a job's row in job.json and sweep.parquet),
``training_wall_time_s`` (a policy manifest) and ``sumo_s`` (each evaluation episode's time inside
SUMO, episodes.parquet). Those differ between any two runs, local ones too; every other value is
the same. Each executor writes into the same paths in turn (the first one's output moved away in
between), so the paths the files name are the same too."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

import ecodrive_bench.bench.training.train as train_module
from ecodrive_bench.bench.experiments import sweep
from ecodrive_bench.bench.harness.provenance import git_sha
from ecodrive_bench.bench.training import train_all

WALL_TIMES = {"job_wall_s", "training_wall_time_s", "sumo_s"}  # [s] measured, so never the same twice


@pytest.fixture(scope="module")
def cluster(two_ray_nodes):
    """Two Ray nodes of one CPU each; the commands join it through ``--address``."""
    return two_ray_nodes


def _without_wall_times(value):
    if isinstance(value, dict):
        return {k: _without_wall_times(v) for k, v in value.items() if k not in WALL_TIMES}
    return value


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def compare(local: Path, ray: Path) -> dict[str, list[str]]:
    """Assert that ``local`` and ``ray`` hold the same files with the same content but the wall
    times; {"same": files of the same bytes, "timed": the others}."""
    a, b = _files(local), _files(ray)
    assert sorted(a) == sorted(b)
    out: dict[str, list[str]] = {"same": [], "timed": []}
    for name in a:
        if a[name] == b[name]:
            out["same"].append(name)
            continue
        out["timed"].append(name)
        if name.endswith(".json"):
            assert _without_wall_times(json.loads(a[name])) == _without_wall_times(json.loads(b[name])), name
        else:
            assert name.endswith(".parquet"), name
            x, y = pd.read_parquet(local / name), pd.read_parquet(ray / name)
            assert list(x.columns) == list(y.columns) and (x.dtypes == y.dtypes).all(), name
            keep = [c for c in x.columns if c not in WALL_TIMES]
            pd.testing.assert_frame_equal(x[keep], y[keep], check_exact=True, obj=name)
    return out


def _run_twice(tmp_path: Path, outputs: list[str], command) -> tuple[Path, Path]:
    """``command(executor)`` with the local executor, its ``outputs`` (folders under tmp_path)
    moved to ``local/``, then with Ray; (local/, tmp_path)."""
    before = git_sha.__wrapped__()
    assert command(["--executor", "local"]) == 0
    for out in outputs:
        (tmp_path / "local" / out).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / out).rename(tmp_path / "local" / out)
    assert command(["--executor", "ray"]) == 0
    if git_sha.__wrapped__() != before:  # the manifests and training logs name the commit each run saw
        pytest.skip("the checkout changed (a commit, or an edit of a tracked file) while the test ran")
    return tmp_path / "local", tmp_path


def test_a_sweep_on_the_cluster_stores_what_a_local_sweep_stores(cluster, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(train_module, "RUNS", tmp_path / "runs")  # the local jobs' run folders
    argv = ["reward", "--forms", "r", "--phi", "0.5", "1", "--seeds", "0", "--episodes", "1", "--cases", "1",
            "--validation-cases", "1", "--max-episode-time", "30", "--workers", "2", "--run-id", "t",
            "--logs", str(tmp_path / "logs"), "--store", str(tmp_path / "store")]
    local, ray = _run_twice(tmp_path, ["logs", "store", "runs"],
                            lambda executor: sweep.main(argv + executor + (["--address", cluster.address]
                                                                           if "ray" in executor else [])))
    assert (local / "runs").is_dir() and not (tmp_path / "runs").exists()  # a Ray job's checkpoints stay on its node
    store, logs = compare(local / "store", ray / "store"), compare(local / "logs", ray / "logs")
    # the same bytes but where a file records a wall time (which may also round to the same value)
    assert {Path(n).name for n in store["timed"]} <= {"episodes.parquet", "job.json", "manifest.json"}
    assert {Path(n).name for n in logs["timed"]} <= {"episodes.parquet", "sweep.parquet", "job.json", "policy-manifest.json"}
    assert len(store["same"] + store["timed"]) == 2 * 4  # job.json, episodes, metrics, manifest per job
    assert sorted(Path(n).name for n in logs["same"] + logs["timed"] if n.count("/") == 3) == sorted(
        ["case-000.mcap", "episodes.parquet", "job.json", "metrics.parquet", "policy-manifest.json", "train.mcap"] * 2)
    row = json.loads((ray / "logs" / "t" / "reward" / "r-phi1-s0" / "job.json").read_text())["row"]
    assert row["log_dir"] == str(tmp_path / "logs" / "t" / "reward" / "r-phi1-s0")  # the driver's folder, not a node's


def test_train_all_on_the_cluster_exports_what_a_local_train_all_exports(cluster, tmp_path, monkeypatch):
    """Two DQN runs (one per signal setting) of two episodes: the uncoordinated one stores enough
    transitions for some updates, so the exported networks are trained ones."""
    monkeypatch.setenv("ECODRIVE_RUNS", str(tmp_path / "runs"))  # the local runs' subprocesses
    monkeypatch.setattr(train_all, "RUNS", tmp_path / "runs")
    argv = ["--methods", "dqn", "--seeds", "0", "--episodes", "2", "--models", str(tmp_path / "models")]
    local, ray = _run_twice(tmp_path, ["models", "runs"],
                            lambda executor: train_all.main(argv + executor + (["--address", cluster.address]
                                                                               if "ray" in executor else [])))
    assert (local / "runs").is_dir() and not (tmp_path / "runs").exists()  # a Ray run's checkpoints stay on its node
    models = compare(local / "models", ray / "models")
    assert sorted(models["same"] + models["timed"]) == [
        f"dqn-{s}/s0/{f}" for s in ("coordinated", "uncoordinated") for f in ("manifest.json", "metrics.parquet", "policy.pt")]
    assert {Path(n).name for n in models["timed"]} <= {"manifest.json"}
    manifest = json.loads((ray / "models" / "dqn-coordinated" / "s0" / "manifest.json").read_text())
    assert manifest["command"] == (f"ecodrive train --method dqn --signals coordinated --episodes 2 --seed 0 "
                                   f"--models {tmp_path / 'models'} --device cpu")
    assert pd.read_parquet(ray / "models" / "dqn-uncoordinated" / "s0" / "metrics.parquet").updates.iloc[-1] > 0
