"""SUMO's EV energy model in numpy (bench.oracle.energy): hand numbers, then SUMO itself."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.agents.baseline import BaselineAgent
from ecodrive_bench.bench.oracle.energy import energy_wh
from ecodrive_bench.envs.config import EVParams
from ecodrive_bench.envs.env import EcoDriveEnv

EPISODE_TOL = 0.01  # [-] model summed over an episode vs SUMO's episode energy, relative
STEP_TOL = 1e-9  # [Wh] one step without a heading change vs SUMO's energy of that step
EV = EVParams()


def test_cruise_step_by_hand():
    # 10 m/s steady, 1 s: air 0.5*1.2041*2.2*0.28*10^3 + roll 0.01*9.80665*1450*10 [W]
    mech = 0.5 * 1.2041 * 2.2 * 0.28 * 1000 + 0.01 * 9.80665 * 1450 * 10
    want = (mech / 0.9 + 300.0) / 3600.0  # propulsion efficiency, then the auxiliaries
    assert want == pytest.approx(0.636675, abs=1e-6)  # 2292.03 W
    assert float(energy_wh(10.0, 10.0, 1.0, EV)) == pytest.approx(want, rel=1e-12)


def test_braking_step_by_hand():
    # 10 -> 6 m/s in 0.5 s: kinetic of mass + rotating mass, drag at the speed after the step
    mech = 0.5 * (1450 + 40) * (36 - 100) / 0.5 + 0.5 * 1.2041 * 2.2 * 0.28 * 216 + 0.01 * 9.80665 * 1450 * 6
    want = (mech * 0.7 + 300.0) * 0.5 / 3600.0  # recuperation efficiency; auxiliaries not discounted
    assert want < 0
    assert float(energy_wh(10.0, 6.0, 0.5, EV)) == pytest.approx(want, rel=1e-12)


def test_broadcasts_and_radial_term():
    e = energy_wh(np.array([[0.0], [5.0]]), np.array([1.0, 2.0, 3.0]), 1.0, EV)
    assert e.shape == (2, 3)
    # a heading change adds c_rad m v^2 / r with r = v dt / |dtheta|, clipped to [1e-4, 1e4] m
    dth = 0.08  # [rad]
    extra = (energy_wh(12.0, 12.0, 1.0, EV, dth) - energy_wh(12.0, 12.0, 1.0, EV)) * 3600 * 0.9
    assert float(extra) == pytest.approx(0.1 * 1450 * 12.0 * dth, rel=1e-9)
    tiny = (energy_wh(12.0, 12.0, 1.0, EV, 1e-5) - energy_wh(12.0, 12.0, 1.0, EV)) * 3600 * 0.9
    assert float(tiny) == pytest.approx(0.1 * 1450 * 144.0 / 1e4, rel=1e-9)  # radius clipped at 1e4 m


def _sumo_episode(sumo_seed: int, insert_time: float, step_length: float) -> dict[str, np.ndarray | float]:
    """One episode of the rule-based baseline (SUMO drives) in mixed traffic: speeds and
    headings after every step, SUMO's energy per step and its episode total."""
    agent = BaselineAgent()
    env = EcoDriveEnv(action=agent.action_interface, step_length=step_length, max_episode_time=150.0,
                      **agent.env_overrides)
    try:
        obs, info = env.reset(options={"sumo_seed": sumo_seed, "insert_time": insert_time})
        speed, heading, step_energy = [env.ego.kin[3]], [np.radians(env.ego.kin[2])], []
        while True:
            obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
            if info["ego_left_simulation"]:
                break
            speed.append(env.ego.kin[3])
            heading.append(np.radians(env.ego.kin[2]))
            step_energy.append(info["energy_step"])
            if terminated or truncated:
                break
        return {"v": np.array(speed), "heading": np.array(heading), "e": np.array(step_energy),
                "total": info["energy"], "lane_changes": info["lane_changes"]}
    finally:
        env.close()


@pytest.mark.parametrize("sumo_seed, insert_time, step_length", [
    (1, 160.0, 1.0), (2, 200.0, 1.0), (3, 250.0, 1.0), (5, 170.0, 0.5),
])
def test_model_matches_sumo_episode(sumo_seed, insert_time, step_length):
    ep = _sumo_episode(sumo_seed, insert_time, step_length)
    v, dth = ep["v"], (np.diff(ep["heading"]) + np.pi) % (2 * np.pi) - np.pi
    model = energy_wh(v[:-1], v[1:], step_length, EV, dth)
    assert len(model) > 60 and ep["total"] > 50.0  # a real episode, not a stub
    rel = (model.sum() - ep["total"]) / ep["total"]
    print(f"seed {sumo_seed} dt {step_length}: SUMO {ep['total']:.4f} Wh, model {model.sum():.4f} Wh, "
          f"error {100 * rel:+.4f} %, {ep['lane_changes']} lane changes")
    assert abs(rel) < EPISODE_TOL
    straight = dth == 0
    assert straight.sum() > 0.8 * len(dth)
    assert np.abs(model[straight] - ep["e"][straight]).max() < STEP_TOL
