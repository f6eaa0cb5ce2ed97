"""The scripted lateral scenarios happen as the paper describes (real SUMO runs, checked with SUMO's
driver), and whether the shipped PRL seeds show the paper's lateral behaviour (section 5.4)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.agents import BaselineAgent, SteadyBaselineAgent
from ecodrive_bench.bench.experiments.lateral import (
    BRAKE_AT,
    HDV1_BRAKE,
    braking_window,
    relative,
    run_scenario,
    summary,
)


def test_scenario_a_hdv1_brakes_ahead_in_the_egos_lane_with_the_left_lane_open_beside():
    """SUMO's driver without imperfection keeps the speed it enters at (13.89 m/s) until the
    braking, so the gaps at the onset are the scenario's: HDV1 25 m ahead in the ego's lane, HDV2
    8 m ahead in the lane to its left; nothing beside the ego there, nothing in the lanes beyond."""
    df = run_scenario("A", SteadyBaselineAgent(), "baseline0")
    assert (df.groupby("vehicle").time.min() == df.time.min()).all(), "every HDV enters in the first step"
    w = braking_window(df)
    assert len(w) == 4 and (w.offset == 0).all() and (w.gap > 10).all(), "HDV1 ahead in the ego's lane throughout"
    assert w.gap.iloc[0] == pytest.approx(25.0, abs=0.1) and w.gap2.iloc[0] == pytest.approx(8.0, abs=0.1)
    assert (w.offset2 == 1).all() and (w.gap2 > 0).all() and not w.beside_left.any()
    lanes = df[df.time.isin(w.index)].groupby("time").lane.agg(["min", "max"])
    assert (lanes["max"] <= w.lane_ego + 1).all(), "the lanes beyond HDV2's are empty"
    dv = np.diff(relative(df, "hdv1").speed_o.to_numpy())
    braking = np.flatnonzero(np.isclose(dv, HDV1_BRAKE))
    assert list(braking) == [BRAKE_AT - 1, BRAKE_AT, BRAKE_AT + 1], "three consecutive steps at -2 m/s^2 from the onset"
    assert df[df.vehicle == "hdv1"].speed.min() < 0.1  # then Krauss again: it stops at red lights like everyone


@pytest.mark.parametrize("agent, method", [(BaselineAgent(), "baseline"), (SteadyBaselineAgent(), "baseline0")])
def test_sumo_driver_leaves_the_braking_vehicles_lane(agent, method):
    """LC2013 falls back behind HDV2 and changes to the left lane within the event window, with
    HDV1 still ahead; it never comes within 10 m of HDV1 before."""
    s = summary(run_scenario("A", agent, method), "A")
    assert s["left_hdv1_lane"] is True and 3.0 <= s["left_at"] <= 8.0
    assert 25.0 <= s["brake_gap"] <= 32.0 and s["event_min_gap"] > 10.0


def test_scenario_b_platoon_queues_at_red_ahead_of_the_ego():
    df = run_scenario("B", BaselineAgent(), "baseline")
    first = df[df.time == df.time.min()].set_index("vehicle")
    ego = first.loc["ego"]
    platoon, left = first.filter(like="platoon", axis=0), first.filter(like="left", axis=0)
    assert len(platoon) == 5 and len(left) == 2, "every HDV enters in the first step"
    assert (platoon.lane == ego.lane).all() and (platoon.x - 5.0 > ego.x + 39.0).all()
    assert (left.lane == ego.lane + 1).all() and (left.x > ego.x).all()
    s = summary(df, "B")
    assert s["queues_by_lane"] == {ego.lane: 5, ego.lane + 1: 2}
    # SUMO's driver overtakes in the empty lane beyond the short queue
    assert s["queue_front_lane"] == ego.lane + 2 and s["at_queue_front_in_shortest_queue_lane"] is True


def test_lateral_command_logs_resumes_and_reports(tmp_path, capsys):
    from ecodrive_bench.bench.experiments import lateral
    from ecodrive_bench.bench.experiments.lateral import main
    from ecodrive_bench.bench.logs.mcaplog import is_complete
    from ecodrive_bench.reports.build import build

    argv = ["--methods", "baseline", "--logs", str(tmp_path), "--run-id", "t", "--workers", "1"]
    assert main(argv) == 0
    root = tmp_path / "t" / "lateral"
    logs = [root / n / "baseline.mcap" for n in ("A", "B")]
    assert all(is_complete(p) for p in logs) and (root / "lateral.parquet").is_file()
    rows = pd.read_parquet(root / "lateral.parquet").set_index("scenario")
    assert rows.collisions.tolist() == [0, 0] and rows.left_hdv1_lane["A"] == True  # noqa: E712 (numpy bool)
    assert rows.at_queue_front_in_shortest_queue_lane["B"] == True  # noqa: E712
    stamps = [p.stat().st_mtime_ns for p in logs]
    assert main(argv) == 0 and [p.stat().st_mtime_ns for p in logs] == stamps  # finished: not rerun
    with pytest.MonkeyPatch.context() as mp:  # a log written by another script is rerun
        mp.setattr(lateral, "script_hash", lambda name: "another script")
        assert main(argv) == 0 and all(a != b for a, b in zip((p.stat().st_mtime_ns for p in logs), stamps))
    assert lateral.script_hash("A") != lateral.script_hash("B")
    text = build(tmp_path / "t", tmp_path / "report")[0].read_text()
    assert "## Lateral scenarios" in text and (tmp_path / "report" / "figures" / "lateral-B.png").is_file()
    assert main(["--methods", "prl2"]) == 2 and "--methods prl2 is not accepted" in capsys.readouterr().err


def _shipped_prl(name: str, script: type | None = None) -> list[dict]:
    """The scenario's summary for every shipped uncoordinated PRL seed (``script``: a variant of
    ``lateral.Script``, e.g. a control of ``lateral_why``)."""
    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.experiments import lateral
    from ecodrive_bench.bench.methods.policies import load_policy, policy_dir, shipped_seeds

    out = []
    for seed in shipped_seeds("prl", "uncoordinated"):
        env = lateral.scenario_env("prl")
        agent = make_agent("prl", env.observation_space, env.action_space)
        agent.load_state_dict(load_policy(policy_dir("prl", "uncoordinated", seed=seed), "prl")[0])
        if script is None:
            out.append(summary(run_scenario(name, agent, "prl", env=env), name))
            continue
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(lateral, "Script", script)
            out.append(summary(run_scenario(name, agent, "prl", env=env), name))
    return out


def test_shipped_prl_leaves_the_braking_vehicles_lane():
    """A (section 5.4): PRL leaves HDV1's lane within the event window, judged over the shipped
    seeds (at least half: seeds 1-3), with HDV1 25 m ahead at the onset and never closer than 10 m."""
    runs = _shipped_prl("A")
    assert all(r["brake_gap"] == pytest.approx(25.0, abs=0.5) and r["event_min_gap"] > 10.0 for r in runs)
    assert len(runs) >= 3 and sum(r["left_hdv1_lane"] is True for r in runs) >= len(runs) / 2


@pytest.mark.xfail(strict=True, reason=(
    "the shipped PRL seeds' lane choice does not follow the braking (docs/experiments.md, Scenario A, "
    "step by step): seeds 2 and 3 prefer 'left' with nothing ahead (Q_left - Q_stay > 0 from the "
    "reset) and leave before HDV1 brakes; seed 0 keeps Q_left - Q_stay < 0 with the left lane free "
    "and allowed at every event step; only seeds 1 and 4 stay until the braking and then leave"))
def test_shipped_prl_with_a_free_left_lane_leaves_when_hdv1_brakes():
    """A without HDV2 (``lateral_why.FreeScript``: the left lane free from the start): PRL keeps
    its lane while HDV1 drives steadily and leaves it within the event window, judged over the
    shipped seeds (at least half). Strict: when the shipped policies behave so, this fails until
    the mark goes."""
    from ecodrive_bench.bench.experiments.lateral_why import FreeScript

    runs = _shipped_prl("A", FreeScript)
    assert sum(r["left_hdv1_lane"] is True for r in runs) >= len(runs) / 2


def test_shipped_prl_meets_the_queues_in_the_lane_with_the_shortest_queue():
    """B (section 5.4): PRL reaches the front of the queues in a lane with the fewest queued
    vehicles, judged over the shipped seeds (at least half: seeds 0 and 2-4), by changing lanes
    (it starts behind the platoon)."""
    runs = _shipped_prl("B")
    shown = [r for r in runs if r["at_queue_front_in_shortest_queue_lane"] is True]
    assert len(runs) >= 3 and len(shown) >= len(runs) / 2 and all(r["lane_changes"] > 0 for r in shown)


def test_lateral_command_drives_every_shipped_seed(tmp_path):
    import shutil

    from ecodrive_bench.bench.experiments.lateral import main
    from ecodrive_bench.bench.methods.policies import policy_dir
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

    from ecodrive_bench.bench.methods.policies import policy_dir

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
    from ecodrive_bench.bench.methods.policies import CheckpointError, policy_spaces, read_manifest

    _, folder = _lateral_copy(tmp_path)
    path = _wrong_structure(folder, tmp_path)
    obs, act = policy_spaces(folder, read_manifest(folder))
    task = LateralTask("A", "prl", str(folder), str(tmp_path / "prl-s0.mcap"), 0)
    with pytest.raises(CheckpointError) as e:
        task_agent(task, SimpleNamespace(observation_space=obs, action_space=act))
    assert str(path) in str(e.value) and "\n" not in str(e.value)
