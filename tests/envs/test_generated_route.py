"""The generated arterial is one kind of network corridor (envs.route): the env drives it through
the same route frame as a real network, whose frame on the arterial is its x axis, and the lane
rules are the route's (no change inside a junction, a change counted on one edge)."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.envs.scenario import build

X_TOL = 1e-6  # [m] route-frame position against SUMO's x: float summation along the route


@pytest.mark.parametrize("signals", ["coordinated", "uncoordinated"])
def test_the_arterial_route_frame_is_its_x_axis_and_no_change_happens_inside_a_junction(signals):
    env = gym.make("EcoDrive-v0", signals=signals, action="parameterized").unwrapped
    files = build(env.cfg)
    assert files.route.edges == files.arterial_edges and files.check_junctions
    rng = np.random.default_rng(3)
    try:
        _, info = env.reset(options={"sumo_seed": 11, "insert_time": 200.0})
        junction_steps, changes, prev = 0, 0, (env.ego.kin.edge, env.ego.kin.lane)
        done = False
        while not done:
            edge = env.ego.kin.edge
            assert abs(info["position"] - env.ego.kin.x) < X_TOL, (edge, info["position"], env.ego.kin.x)
            if edge.startswith(":"):
                junction_steps += 1
                assert info["action_mask"].tolist() == [0, 1, 0]  # only "stay" inside a junction
            k = int(rng.integers(3))  # lane requests often: many are masked, some are made
            action = (k, rng.uniform(-1.0, 2.0, size=3).astype(np.float32))
            _, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            now = (env.ego.kin.edge, env.ego.kin.lane)
            changes += now[0] == prev[0] and now[1] != prev[1] and not now[0].startswith(":")
            prev = now
        assert terminated and junction_steps > 0
        assert info["lane_changes"] == changes > 0  # counted where the index changed on one edge
        assert info["collisions"] == 0
    finally:
        env.close()
