"""Pure functions of the observation, safety layer and rewards, with hand-computed numbers."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.envs import safety
from ecodrive_bench.envs.config import RewardConfig, ScenarioConfig
from ecodrive_bench.envs.observation import logic_vector, occupancy_grid
from ecodrive_bench.envs.rewards import reward

CFG = ScenarioConfig()
LANE_Y = np.array([-14.4, -11.2, -8.0, -4.8, -1.6])


def test_grid_marks_a_car_ahead_in_its_lane():
    # a 5 m car whose front bumper is 20 m ahead of the ego's, in lane 2
    g = occupancy_grid(100.0, [(120.0, -8.0, 90.0, 5.0)], LANE_Y, CFG)
    assert g.shape == (60, 5)
    occupied = np.argwhere(g == 0)
    assert set(occupied[:, 1]) == {2}
    # rows are offsets from -10 m: the car spans [15, 20] m ahead -> rows 25..29
    assert occupied[:, 0].min() == 25 and occupied[:, 0].max() == 29
    assert g.sum() == 60 * 5 - 5


def test_grid_clips_at_range_and_ignores_far_vehicles():
    others = [
        (160.0, -1.6, 90.0, 5.0),  # 60 m ahead: out of the 50 m range
        (92.0, -14.4, 90.0, 5.0),  # behind: spans [-13, -8] m -> rows 0..1 only
        (120.0, 30.0, 180.0, 5.0),  # a side-street car far off the arterial
        (120.0, -4.0, 180.0, 5.0),  # crossing inside a junction, lane 3: [19, 21] m
    ]
    g = occupancy_grid(100.0, others, LANE_Y, CFG)
    assert np.argwhere(g == 0).tolist() == [[0, 0], [1, 0], [29, 3], [30, 3]]


def test_logic_vector_layout():
    v = logic_vector(3, 5, 250.0, 12.5, 1.0, 17.0)
    assert v.tolist() == [0, 0, 0, 1, 0, 250.0, 12.5, 1.0, 17.0]


def test_target_speed_bounds():
    assert safety.target_speed(10.0, 3.0, 1.0, 13.89) == pytest.approx(13.0)
    assert safety.target_speed(13.0, 3.0, 1.0, 13.89) == pytest.approx(13.89)
    assert safety.target_speed(2.0, -4.0, 1.0, 13.89) == 0.0


def test_clip_detection():
    # asked +3 at 10 m/s, got -1.5: Krauss clipped it
    assert safety.was_clipped(3.0, -1.5, 10.0, 1.0, 13.89)
    # asked +3 at 13 m/s, got +0.89: only the speed limit, not a safety clip
    assert not safety.was_clipped(3.0, 0.89, 13.0, 1.0, 13.89)


def test_lane_mask_and_apply():
    m = safety.lane_mask(lane=4, lanes=5, could_left=True, could_right=False)
    assert m.tolist() == [0, 1, 0]  # leftmost lane: no left; right blocked by LC2013
    assert safety.mask_lateral(-1, m) == 0 and safety.mask_lateral(1, m) == 0
    m = safety.lane_mask(lane=2, lanes=5, could_left=True, could_right=True)
    assert safety.mask_lateral(-1, m) == -1 and safety.paper_to_sumo(-1) == 1


def test_composite_reward_components():
    rc = RewardConfig(cost_timing="end")  # the paper's eq. 11: E_f + phi T_f paid at t_f
    r, c = reward(rc, speed=1.0, jerk=5.0, lane_changed=True, distance=1.0, energy=0.5,
                  terminated=False, total_energy=10.0, travel_time=10.0)
    assert c["speed"] == -40 and c["jerk"] == -30 and c["lane_change"] == -50 and c["terminal"] == 0
    assert r == -120
    r, c = reward(rc, speed=10.0, jerk=0.0, lane_changed=False, distance=10.0, energy=0.5,
                  terminated=True, total_energy=230.0, travel_time=190.0)
    assert r == c["terminal"] == -(230.0 + 1.0 * 190.0)


def test_composite_reward_per_step_costs():
    rc = RewardConfig(phi=2.0)  # default cost_timing="step"
    r, c = reward(rc, speed=10.0, jerk=0.0, lane_changed=False, distance=10.0, energy=0.75,
                  terminated=False, total_energy=10.0, travel_time=10.0, step_time=1.0)
    assert c["energy"] == -0.75 and c["time"] == -2.0 and c["terminal"] == 0 and r == -2.75
    r, c = reward(rc, speed=10.0, jerk=0.0, lane_changed=False, distance=10.0, energy=-0.25,
                  terminated=True, total_energy=230.0, travel_time=190.0, step_time=1.0)
    assert c["terminal"] == 0 and r == pytest.approx(0.25 - 2.0)  # nothing lumped at the end


def test_r1_and_r2():
    r, c = reward(RewardConfig(form="r2", phi=2.0), speed=10.0, jerk=9.0, lane_changed=False, distance=10.0,
                  energy=-0.5, terminated=False, total_energy=0.0, travel_time=0.0)
    assert r == pytest.approx(10.0 + 1.0)  # recuperation raises r2
    r, c = reward(RewardConfig(form="r1"), speed=0.0, jerk=9.0, lane_changed=False, distance=10.0,
                  energy=1.0, terminated=False, total_energy=5.0, travel_time=5.0)
    assert r == 0.0
