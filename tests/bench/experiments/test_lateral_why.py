"""The scenario-A analysis (bench/experiments/lateral_why.py): its grid reading, its controls, and
its per-step table with the critic's values."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.bench.experiments.lateral_why import (
    column,
    free_ahead,
    free_beside,
    run_a,
    run_summary,
    step_table,
    traffic_summary,
)


def test_free_ahead_reads_the_column_from_the_front_bumper():
    g = np.ones((60, 3), dtype=np.uint8)
    g[25:31, 1] = 0  # a vehicle 15-21 m ahead (row 10 is the front bumper)
    g[2:5, 0] = 0  # behind: not counted
    assert free_ahead(g, 1, 10.0, 1.0) == 15.0 and free_ahead(g, 0, 10.0, 1.0) == 50.0
    assert free_ahead(g, 3, 10.0, 1.0) == -1.0 and free_ahead(g, -1, 10.0, 1.0) == -1.0
    assert column(g, 1, 10.0, 1.0) == "1" * 15 + "0" * 6 + "1" * 29 and column(g, 5, 10.0, 1.0) == "-"
    assert free_beside(g, 1, 10.0, 1.0) and not free_beside(g, 0, 10.0, 1.0) and not free_beside(g, 3, 10.0, 1.0)


@pytest.mark.parametrize("method", ["prl", "dqn"])
def test_the_table_scores_every_step_and_sees_hdv1_and_hdv2(method, tmp_path):
    """Seed 0 of each keeps its lane through the event: HDV1 ahead in the grid's own column, HDV2
    ahead in the left one, a finite Q for every lateral choice at every step."""
    from ecodrive_bench.bench.experiments.lateral import scenario_env
    from ecodrive_bench.bench.experiments.lateral_why import policy_agent

    log = tmp_path / "a.mcap"
    traj = run_a(method, 0, log, "scripted")
    env = scenario_env(method)
    try:
        t = step_table(log, traj, policy_agent(method, 0, env), env.cfg)
    finally:
        env.close()
    assert np.isfinite(t[["q_left", "q_stay", "q_right"]].to_numpy()).all()
    s = run_summary(t, traj)
    assert s["event_steps"] > 5 and s["event_max_free_left"] < 30 and s["event_left_allowed_free30"] == 0
    assert t[t.hdv1_gap > 0].time.min() == traj.time.min(), "HDV1 is ahead from the first step after the reset"


def test_free_control_has_no_hdv2():
    traj = run_a("prl", 0, None, "free")
    assert set(traj.vehicle) == {"ego", "hdv1"}


def test_traffic_summary_counts_hard_braking_leaders_beside_a_free_allowed_lane():
    df = pd.DataFrame([
        {"episode": 0, "step": 1, "gap": 10.0, "leader_accel": -3.0, "free_left": 50.0, "free_right": -1.0,
         "mask_left": 1, "mask_right": 0, "red": 0.0, "dq_free_allowed": 0.2},
        {"episode": 0, "step": 2, "gap": 10.0, "leader_accel": -3.0, "free_left": 10.0, "free_right": -1.0,
         "mask_left": 1, "mask_right": 0, "red": 1.0, "dq_free_allowed": np.nan},
        {"episode": 0, "step": 3, "gap": 10.0, "leader_accel": -0.5, "free_left": 50.0, "free_right": -1.0,
         "mask_left": 1, "mask_right": 0, "red": 0.0, "dq_free_allowed": -0.1},
        {"episode": 0, "step": 100, "gap": np.nan},
    ])
    s = traffic_summary(df)
    assert (s["steps"], s["leader_steps"], s["hard_brake"], s["hard_brake_not_red"], s["hard_brake_free"],
            s["hard_brake_free_allowed"], s["hard_brake_free_allowed_not_red"]) == (100, 3, 2, 1, 1, 1, 1)
    assert s["max_dq_at_events"] == 0.2
