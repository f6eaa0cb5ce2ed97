from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run

COMPARE = ["method", "signals", "case", "seed", "energy", "travel_time", "steps", "stops", "clips", "collisions"]


def _opts(logs: Path, *extra: str) -> dict:
    return parse(["--profile", "smoke", "--logs", str(logs), "--methods", "baseline", *extra])


@pytest.fixture(scope="module")
def local_results(tmp_path_factory):
    logs = tmp_path_factory.mktemp("local")
    return run(_opts(logs, "--workers", "2"), progress=False), logs


def test_layout_and_results(local_results):
    df, logs = local_results
    assert len(df) == 2 * 3 and set(df.signals) == {"coordinated", "uncoordinated"}
    for p in df.mcap:  # relative to the run folder
        assert not Path(p).is_absolute() and (logs / "smoke" / p).is_file() and Path(p).parent.name == "baseline"
    assert (logs / "smoke" / "results.parquet").is_file() and (logs / "smoke" / "manifest.json").is_file()
    assert (df.collisions == 0).all()


def test_ray_matches_local(local_results, tmp_path):
    pytest.importorskip("ray")
    import ray

    df_local, _ = local_results
    try:
        df_ray = run(_opts(tmp_path, "--executor", "ray", "--workers", "2"), progress=False)
    finally:
        ray.shutdown()
    pd.testing.assert_frame_equal(df_local[COMPARE], df_ray[COMPARE])


def test_killed_run_resumes_to_the_same_results(local_results, tmp_path):
    df_local, _ = local_results
    cmd = [sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", "--profile", "smoke", "--logs", str(tmp_path), "--methods", "baseline",
           "--workers", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and len(list(tmp_path.rglob("*.mcap"))) < 2:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the pool's workers too
    proc.wait()
    finished = list(tmp_path.rglob("*.mcap"))
    assert 2 <= len(finished) < 6
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    df = pd.read_parquet(tmp_path / "smoke" / "results.parquet")
    pd.testing.assert_frame_equal(df_local[COMPARE], df[COMPARE])


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in state  # a zombie has exited


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal is Linux-only")
def test_killing_the_parent_stops_its_workers(tmp_path):
    """A sweep killed by its PID alone (not its process group) leaves no worker computing on."""
    cmd = [sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", "--profile", "smoke", "--logs", str(tmp_path), "--methods", "baseline",
           "--workers", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        workers: list[int] = []
        deadline = time.time() + 120
        while time.time() < deadline and not (workers and list(tmp_path.rglob("*.mcap*"))):
            kids = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
            workers = [int(k) for k in kids if b"spawn_main" in Path(f"/proc/{k}/cmdline").read_bytes()]
            time.sleep(0.05)
        assert workers, "no pool worker started"
        proc.kill()
        proc.wait()
        deadline = time.time() + 20
        while time.time() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.1)
        assert not any(_alive(w) for w in workers)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.mark.parametrize("args, words", [
    (["--methods", "teleporter"], ["teleporter", "baseline", "glosa", "baseline0", "prl"]),
    (["--profile", "huge"], ["huge", "smoke", "paper", "full"]),
    (["--executor", "slurm"], ["slurm", "local", "ray"]),
    (["--methods", "prl"], ["no trained policy for prl", "none there"]),
    (["--methods", "prl", "--signals", "coordinated", "--train-seeds", "7", "--models",
      str(Path(__file__).resolve().parents[3] / "models")],
     ["no trained policy for prl / coordinated with training seed 7", "seeds there: 0 1 2 3 4"]),
    (["--workers", "0"], ["--workers", "'0'", "1.."]),
    (["--frobnicate"], ["unrecognized arguments: --frobnicate"]),
    (["--run-id", "../../etc"], ["--run-id", "'../../etc'", "no path separator"]),
    (["--run-id", "/abs"], ["--run-id", "'/abs'"]),
])
def test_bad_input_is_one_line_and_touches_nothing(args, words, tmp_path):
    keep = tmp_path / "smoke" / "coordinated" / "baseline" / "case-000.mcap"
    keep.parent.mkdir(parents=True)
    keep.write_bytes(b"existing")
    (tmp_path / "no-models").mkdir()  # a policies folder with no policy in it
    cmd = [sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", "--logs", str(tmp_path), "--models", str(tmp_path / "no-models"), *args]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    err = [line for line in out.stderr.splitlines() if "pyarrow" not in line and "Try to uninstall" not in line]
    assert out.returncode == 2 and len(err) == 1 and "Traceback" not in out.stderr
    for w in words:
        assert w in err[0]
    assert keep.read_bytes() == b"existing"


def test_unwritable_log_folder(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    cmd = [sys.executable, "-m", "ecodrive_bench.bench.harness.run_command", "--profile", "smoke", "--methods", "baseline", "--logs", str(blocker)]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "not writable" in out.stderr and "Traceback" not in out.stderr
    assert blocker.read_text() == "not a folder"


def test_the_manifest_keeps_the_provenance_of_rows_kept_from_earlier_commands(tmp_path):
    """A folder built by two commands (PRL coordinated, then the baseline uncoordinated) records
    both: the PRL policy's sha256, both settings' scenarios and both commands, oldest first."""
    common = ["--profile", "smoke", "--logs", str(tmp_path), "--workers", "2"]
    run(parse([*common, "--methods", "prl", "--signals", "coordinated", "--train-seeds", "0"]), progress=False)
    first = json.loads((tmp_path / "smoke" / "manifest.json").read_text())
    run(parse([*common, "--methods", "baseline", "--signals", "uncoordinated"]), progress=False)
    man = json.loads((tmp_path / "smoke" / "manifest.json").read_text())
    assert man["methods"] == ["baseline"] and man["episodes_kept_from_earlier_commands"] == 3
    assert man["checkpoint_sha256"] == first["checkpoint_sha256"] and list(man["checkpoint_sha256"]) == ["prl-coordinated/s0"]
    assert sorted(man["scenario"]) == ["coordinated", "uncoordinated"]
    assert [c["methods"] for c in man["commands"]] == [["prl"], ["baseline"]]
    assert man["commands"][0]["command"] == first["command"]


def test_rows_of_a_replaced_policy_are_not_kept_beside_the_new_ones(tmp_path):
    """PRL seed 0 on three cases; its policy file is then replaced and one case rerun: the two
    other rows (the old policy's) leave the table, so the manifest's sha256 covers every row."""
    import shutil

    from ecodrive_bench.bench.cases.case import load as load_cases
    from ecodrive_bench.bench.methods.policies import policy_dir

    models = tmp_path / "models"
    shutil.copytree(policy_dir("prl", "coordinated"), policy_dir("prl", "coordinated", models))
    common = ["--profile", "smoke", "--logs", str(tmp_path), "--workers", "2", "--methods", "prl",
              "--signals", "coordinated", "--train-seeds", "0", "--models", str(models)]
    assert len(run(parse(common), progress=False)) == 3
    shutil.rmtree(policy_dir("prl", "coordinated", models))
    shutil.copytree(policy_dir("prl", "coordinated", seed=1), policy_dir("prl", "coordinated", models))
    man_path = policy_dir("prl", "coordinated", models) / "manifest.json"  # seed 0 trained again: a new policy
    man_path.write_text(json.dumps({**json.loads(man_path.read_text()), "seed": 0}))
    again = run(dataclasses.replace(parse(common), cases=load_cases()[:1]), progress=False)
    man = json.loads((tmp_path / "smoke" / "manifest.json").read_text())
    assert len(again) == 1 and man["episodes_kept_from_earlier_commands"] == 0
    assert man["checkpoint_sha256"]["prl-coordinated/s0"] == json.loads(
        (policy_dir("prl", "coordinated", seed=1) / "manifest.json").read_text())["sha256"]


def test_a_rerun_with_fewer_methods_keeps_the_finished_rows(tmp_path):
    common = ["--profile", "smoke", "--logs", str(tmp_path), "--signals", "coordinated", "--workers", "2"]
    first = run(parse([*common, "--methods", "baseline", "glosa"]), progress=False)
    again = run(parse([*common, "--methods", "baseline"]), progress=False)
    table = pd.read_parquet(tmp_path / "smoke" / "results.parquet")
    assert len(first) == len(table) == 6 and sorted(set(table.method)) == ["baseline", "glosa"]
    assert len(again) == 6
    man = json.loads((tmp_path / "smoke" / "manifest.json").read_text())
    assert man["episodes_kept_from_earlier_commands"] == 3 and man["episodes_reused"] == 3
    # a log that is no longer complete is not kept
    log = tmp_path / "smoke" / "coordinated" / "glosa" / "case-000.mcap"
    log.write_bytes(log.read_bytes()[:100])
    run(parse([*common, "--methods", "baseline"]), progress=False)
    assert len(pd.read_parquet(tmp_path / "smoke" / "results.parquet")) == 5


def test_without_an_address_ray_starts_its_own_beside_a_running_cluster(local_results, two_ray_nodes, tmp_path):
    """A cluster already running on this machine (as `ray start` leaves one) is not joined
    without --address: the run starts a Ray of its own with its --workers CPUs."""
    pytest.importorskip("ray")
    import ray

    df_local, _ = local_results
    try:
        df_ray = run(_opts(tmp_path, "--executor", "ray", "--workers", "2"), progress=False)
        assert ray.cluster_resources().get("CPU") == 2 and two_ray_nodes.address not in str(ray.get_runtime_context().gcs_address)
    finally:
        ray.shutdown()
    pd.testing.assert_frame_equal(df_local[COMPARE], df_ray[COMPARE])


@pytest.mark.parametrize("action", [
    0, 26, 1.5, np.int64(3), np.float32(0.1), True, np.array([0.1], dtype=np.float32), np.array([-4.0, 2.5]),
    np.array([[1, 2]]), (1, np.array([0.1, -3.9, 2.9], dtype=np.float32)), (np.int64(2), np.zeros(3)),
    (0, [0.5, 1.5, 2.5]), [1, 2.5],
])
def test_the_logged_raw_action_is_every_number_of_the_action_as_a_float(action):
    """``raw_action``: the action's numbers in order, as floats, whatever form the agent returns
    (the fast forms for the built-in agents' actions give what the general rule gives)."""
    from ecodrive_bench.bench.harness.episode import _flatten

    parts = action if isinstance(action, tuple) else (action,)
    want = [float(v) for part in parts for v in np.ravel(part)]
    got = _flatten(action)
    assert got == want and all(type(v) is float for v in got)


def test_a_clairvoyant_log_of_other_drives_runs_again(tmp_path, monkeypatch):
    """A clairvoyant step log records its drives' version (``planners.identity``): once the drives
    change (another ``VERSION``), a rerun plans the case again instead of reusing the log."""
    from ecodrive_bench.bench.cases.case import load as load_cases
    from ecodrive_bench.bench.harness import run as run_module
    from ecodrive_bench.bench.methods import planners

    opts = dataclasses.replace(parse(["--profile", "smoke", "--logs", str(tmp_path), "--workers", "1", "--methods",
                                      "clairvoyant", "--signals", "coordinated"]), cases=load_cases()[:1])
    assert len(run(opts, progress=False)) == 1
    todo = run_module.plan(opts, run_module.preflight(opts))
    assert len(todo.reused) == 1 and not todo.tasks
    assert todo.shas["clairvoyant-coordinated"] == planners.identity("clairvoyant") != ""
    assert len({planners.identity(p) for p in planners.PLANNERS} - {""}) == len(planners.PLANNERS)  # one each
    monkeypatch.setattr(run_module, "identity", lambda m: "0" * 64)  # drives of another version
    todo = run_module.plan(opts, run_module.preflight(opts))
    assert not todo.reused and len(todo.tasks) == 1
