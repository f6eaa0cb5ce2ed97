"""The scripted lateral scenarios happen as the paper describes (checked with SUMO's driver), and
whether the shipped PRL seeds show the paper's lateral behaviour (section 5.4: in B most do, in A none)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.experiments.lateral import run_scenario, summary


def test_scenario_a_hdv1_brakes_three_steps_beside_hdv2():
    df = run_scenario("A", BaselineAgent(), "baseline")
    v1 = df[df.vehicle == "hdv1"].speed.to_numpy()
    dv = np.diff(v1)
    assert np.sum(np.isclose(dv, -2.0)) == 3 and np.all(dv[np.isclose(dv, -2.0)] < 0)
    ego_lane0 = df[df.vehicle == "ego"].lane.iloc[0]
    assert df[df.vehicle == "hdv1"].lane.iloc[0] == ego_lane0
    assert df[df.vehicle == "hdv2"].lane.iloc[0] == ego_lane0 + 1
    # after the event HDV1 drives by Krauss again and stops at red lights like everyone
    assert df[df.vehicle == "hdv1"].speed.min() < 0.1
    assert summary(df, "A")["left_hdv1_lane"] is False  # SUMO's driver stays behind HDV1


def test_scenario_b_platoon_queues_at_red():
    df = run_scenario("B", BaselineAgent(), "baseline")
    s = summary(df, "B")
    lane0 = df[df.vehicle == "ego"].lane.iloc[0]
    assert s["queues_by_lane"].get(lane0, 0) == 5 and s["queues_by_lane"].get(lane0 + 1, 0) == 2
    assert s["ended_in_shortest_queue_lane"] is False  # SUMO's driver stays behind the platoon


def test_lateral_command_logs_resumes_and_reports(tmp_path, capsys):
    from ecodrive_bench.bench.experiments.lateral import main
    from ecodrive_bench.bench.logs.mcaplog import is_complete
    from ecodrive_bench.reports.build import build

    argv = ["--methods", "baseline", "--logs", str(tmp_path), "--run-id", "t", "--workers", "1"]
    assert main(argv) == 0
    root = tmp_path / "t" / "lateral"
    logs = [root / n / "baseline.mcap" for n in ("A", "B")]
    assert all(is_complete(p) for p in logs) and (root / "lateral.parquet").is_file()
    stamps = [p.stat().st_mtime_ns for p in logs]
    assert main(argv) == 0 and [p.stat().st_mtime_ns for p in logs] == stamps  # finished: not rerun
    text = build(tmp_path / "t", tmp_path / "report")[0].read_text()
    assert "## Lateral scenarios" in text and (tmp_path / "report" / "figures" / "lateral-B.png").is_file()
    assert main(["--methods", "prl2"]) == 2 and "--methods prl2 is not accepted" in capsys.readouterr().err


def _shipped_prl(name: str) -> list[dict]:
    """The scenario's summary for every shipped uncoordinated PRL seed."""
    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.experiments.lateral import scenario_env
    from ecodrive_bench.bench.harness.policies import load_policy, policy_dir, shipped_seeds

    out = []
    for seed in shipped_seeds("prl", "uncoordinated"):
        env = scenario_env("prl")
        agent = make_agent("prl", env.observation_space, env.action_space)
        agent.load_state_dict(load_policy(policy_dir("prl", "uncoordinated", seed=seed), "prl")[0])
        out.append(summary(run_scenario(name, agent, "prl", env=env), name))
    return out


@pytest.mark.xfail(strict=True, reason=(
    "known failure (docs/experiments.md, Why scenario A fails): the scenario's script places HDV1 "
    "behind the ego, so no policy can leave its lane while behind it; fix the script, then re-judge A"))
def test_shipped_prl_leaves_the_braking_vehicles_lane():
    """A (section 5.4): PRL leaves HDV1's lane, judged over the shipped seeds (at least half).
    Strict: when the shipped policies start to behave so, this fails until the mark goes."""
    runs = _shipped_prl("A")
    assert sum(r["left_hdv1_lane"] is True for r in runs) >= len(runs) / 2


def test_shipped_prl_ends_in_the_lane_with_the_shortest_queue():
    """B (section 5.4): PRL ends in a lane with the fewest queued vehicles, judged over the shipped
    seeds (at least half), and does so by changing lanes (it starts behind the platoon)."""
    runs = _shipped_prl("B")
    shown = [r for r in runs if r["ended_in_shortest_queue_lane"] is True]
    assert len(runs) >= 3 and len(shown) >= len(runs) / 2 and all(r["lane_changes"] > 0 for r in shown)


def test_lateral_command_drives_every_shipped_seed(tmp_path):
    import shutil

    from ecodrive_bench.bench.experiments.lateral import main
    from ecodrive_bench.bench.harness.policies import policy_dir
    from ecodrive_bench.reports.build import build

    models = tmp_path / "models"
    for seed in (0, 1):
        shutil.copytree(policy_dir("prl", "uncoordinated", seed=seed), policy_dir("prl", "uncoordinated", models, seed))
    assert main(["--methods", "prl", "baseline", "--models", str(models), "--logs", str(tmp_path), "--run-id", "t",
                 "--workers", "1"]) == 0
    root = tmp_path / "t" / "lateral"
    df = pd.read_parquet(root / "lateral.parquet")
    prl = df[df.method == "prl"]
    assert sorted(zip(prl.scenario, prl.train_seed)) == [("A", 0), ("A", 1), ("B", 0), ("B", 1)]
    assert df[df.method == "baseline"].train_seed.isna().all()
    assert sorted(p.name for p in (root / "B").glob("*.mcap")) == ["baseline.mcap", "prl-s0.mcap", "prl-s1.mcap"]
    text = build(tmp_path / "t", tmp_path / "report")[0].read_text()
    assert "- prl, scenario B: " in text and " of 2 runs show the paper's behaviour" in text


# ---------------------------------------------------------------- bad input: one line, exit 2, nothing written
def _lateral_copy(tmp_path):
    """A models root with a copy of the shipped uncoordinated PRL seed 0, and that seed's folder."""
    import shutil

    from ecodrive_bench.bench.harness.policies import policy_dir

    models = tmp_path / "models"
    folder = policy_dir("prl", "uncoordinated", models)
    shutil.copytree(policy_dir("prl", "uncoordinated"), folder)
    return models, folder


def _match_manifest(folder):
    """The manifest's sha256 made to match the (replaced) policy.pt, as whoever replaced it could."""
    import json

    from ecodrive_bench.bench.io import sha256

    man = json.loads((folder / "manifest.json").read_text())
    man["sha256"] = sha256(folder / "policy.pt")
    (folder / "manifest.json").write_text(json.dumps(man))


def _truncated(folder, tmp_path):
    path = folder / "policy.pt"
    path.write_bytes(path.read_bytes()[:1000])
    _match_manifest(folder)
    return path


def _wrong_structure(folder, tmp_path):
    import torch

    path = folder / "policy.pt"
    state = torch.load(path, weights_only=True)
    torch.save({**state, "name": "x"}, path)
    _match_manifest(folder)
    return path


def _payload(folder, tmp_path):
    import os

    import torch

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {tmp_path / 'ran'}",))

    path = folder / "policy.pt"
    state = torch.load(path, weights_only=True)
    torch.save({**state, "extra": Payload()}, path)
    _match_manifest(folder)
    return path


def _bad_manifest(folder, tmp_path):
    path = folder / "manifest.json"
    path.write_text("{oops")
    return path


@pytest.mark.parametrize("corrupt", [_truncated, _wrong_structure, _payload, _bad_manifest],
                         ids=["truncated", "wrong-structure", "payload", "bad-manifest"])
def test_lateral_refuses_a_bad_policy_as_one_line_before_anything_runs(corrupt, tmp_path, capsys):
    from ecodrive_bench.bench.experiments.lateral import main

    models, folder = _lateral_copy(tmp_path)
    path = corrupt(folder, tmp_path)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    logs = tmp_path / "logs"
    rc = main(["--methods", "prl", "--models", str(models), "--logs", str(logs), "--workers", "1"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and str(path) in err
    assert not logs.exists() and not (tmp_path / "ran").exists()
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_lateral_refuses_a_named_learning_method_without_a_shipped_policy(tmp_path, capsys):
    from ecodrive_bench.bench.experiments.lateral import main

    models, logs = tmp_path / "nonexistent", tmp_path / "logs"
    rc = main(["--methods", "baseline", "prl", "--models", str(models), "--logs", str(logs)])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "--methods prl" in err and str(models / "prl-uncoordinated") in err
    assert not logs.exists()


def test_lateral_skips_a_default_learning_method_without_a_shipped_policy(tmp_path):
    from ecodrive_bench.bench.experiments.lateral import LATERAL_METHODS, lateral_seeds

    seeds, skipped = lateral_seeds(list(LATERAL_METHODS), tmp_path / "nonexistent", explicit=False)
    assert seeds == {"baseline": [None]} and skipped == ["prl", "ddpg"]


def test_lateral_with_default_methods_and_a_bad_policy_prints_the_error_only(tmp_path, capsys):
    """ddpg is skipped (no shipped policy) and prl refused: the refusal is the only line."""
    from ecodrive_bench.bench.experiments.lateral import main

    models, folder = _lateral_copy(tmp_path)
    path = _wrong_structure(folder, tmp_path)
    rc = main(["--models", str(models), "--logs", str(tmp_path / "logs")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and str(path) in err


def test_the_lateral_worker_refuses_a_wrong_structure_as_a_checkpoint_error(tmp_path):
    """The worker's own load (a file replaced after the parent's check) names the file."""
    from types import SimpleNamespace

    from ecodrive_bench.bench.experiments.lateral import LateralTask, task_agent
    from ecodrive_bench.bench.harness.policies import CheckpointError, policy_spaces, read_manifest

    _, folder = _lateral_copy(tmp_path)
    path = _wrong_structure(folder, tmp_path)
    obs, act = policy_spaces(folder, read_manifest(folder))
    task = LateralTask("A", "prl", str(folder), str(tmp_path / "prl-s0.mcap"), 0)
    with pytest.raises(CheckpointError) as e:
        task_agent(task, SimpleNamespace(observation_space=obs, action_space=act))
    assert str(path) in str(e.value) and "\n" not in str(e.value)
