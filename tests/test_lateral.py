"""The scripted lateral scenarios happen as the paper describes (checked with SUMO's driver).

The agent-behaviour assertions (PRL leaves HDV1's lane in A, ends in the shortest-queue lane in
B) need the shipped PRL policy and are added with it.
"""
from __future__ import annotations

import numpy as np

from agents import BaselineAgent
from bench.lateral import run_scenario, summary


def test_scenario_a_hdv1_brakes_three_steps_beside_hdv2():
    df = run_scenario("A", BaselineAgent(), "baseline")
    v1 = df[df.vehicle == "hdv1"].speed.to_numpy()
    dv = np.diff(v1)
    assert np.sum(np.isclose(dv, -2.0)) == 3 and np.all(dv[np.isclose(dv, -2.0)] < 0)
    ego_lane0 = df[df.vehicle == "ego"].lane.iloc[0]
    assert df[df.vehicle == "hdv1"].lane.iloc[0] == ego_lane0
    assert df[df.vehicle == "hdv2"].lane.iloc[0] == ego_lane0 + 1
    assert summary(df, "A")["left_hdv1_lane"] is True  # LC2013 overtakes the braking HDV1 as well


def test_scenario_b_platoon_queues_at_red():
    df = run_scenario("B", BaselineAgent(), "baseline")
    s = summary(df, "B")
    lane0 = df[df.vehicle == "ego"].lane.iloc[0]
    assert s["queues_by_lane"].get(lane0, 0) == 5 and s["queues_by_lane"].get(lane0 + 1, 0) == 2
    assert s["ended_in_shortest_queue_lane"] is False  # SUMO's driver stays behind the platoon
