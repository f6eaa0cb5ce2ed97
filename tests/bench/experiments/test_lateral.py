"""The scripted lateral scenarios happen as the paper describes (checked with SUMO's driver), and
whether the shipped PRL seeds show the paper's lateral behaviour (section 5.4: in B most do, in A none)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from agents import BaselineAgent
from bench.experiments.lateral import run_scenario, summary


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
    from bench.experiments.lateral import main
    from bench.logs.mcaplog import is_complete
    from reports.build import build

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
    from agents.registry import make_agent
    from bench.experiments.lateral import scenario_env
    from bench.harness.policies import load_policy, policy_dir, shipped_seeds

    out = []
    for seed in shipped_seeds("prl", "uncoordinated"):
        env = scenario_env("prl")
        agent = make_agent("prl", env.observation_space, env.action_space)
        agent.load_state_dict(load_policy(policy_dir("prl", "uncoordinated", seed=seed), "prl")[0])
        out.append(summary(run_scenario(name, agent, "prl", env=env), name))
    return out


@pytest.mark.xfail(strict=True, reason=(
    "known failure (docs/results.md, lateral scenarios): no shipped uncoordinated PRL seed leaves "
    "HDV1's lane in A; they brake behind it (some change lanes later, away from the event)"))
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

    from bench.experiments.lateral import main
    from bench.harness.policies import policy_dir
    from reports.build import build

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
