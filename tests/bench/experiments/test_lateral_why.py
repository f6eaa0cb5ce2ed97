"""The scenario-A analysis (bench/experiments/lateral_why.py): its grid reading, its corrected
placement of the scripted vehicles, and its per-step table with the critic's values."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ecodrive_bench.bench.experiments.lateral_why import (
    column,
    free_ahead,
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


def test_ahead_script_puts_hdv1_ahead_of_a_fast_ego_and_the_table_scores_every_step(tmp_path):
    from ecodrive_bench.bench.experiments.lateral import scenario_env
    from ecodrive_bench.bench.experiments.lateral_why import policy_agent

    log = tmp_path / "a.mcap"
    traj = run_a("prl", 0, log, "ahead")  # seed 0 enters at the speed limit
    first = traj[traj.vehicle == "hdv1"].time.min()
    assert first == traj.time.min(), "HDV1 appears at the first step"
    env = scenario_env("prl")
    try:
        t = step_table(log, traj, policy_agent("prl", 0, env), env.cfg)
    finally:
        env.close()
    assert np.isfinite(t[["q_left", "q_stay", "q_right"]].to_numpy()).all()
    s = run_summary(t, traj)
    assert s["hdv1_ahead_steps"] > 0 and s["event_steps"] > 0 and s["event_min_free_own"] < 50


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
