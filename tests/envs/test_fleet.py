from __future__ import annotations

import numpy as np

from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.fleet import Fleet


def test_batched_control_of_many_cvs():
    cfg = ScenarioConfig(signals="uncoordinated", arterial_flow=1500.0, mpr=0.5)
    fleet = Fleet(cfg)
    fleet.start(3)
    calls = []

    def policy(grids, logics, masks):
        calls.append(len(grids))
        assert grids.shape[1:] == (60, 5) and logics.shape[1] == 9 and masks.shape[1] == 3
        return [(1, np.array([1.0, 1.0, 1.0], dtype=np.float32))] * len(grids)  # stay, +1 m/s^2

    for _ in range(400):
        fleet.step(policy)
    fleet.close()
    kinds = [r.kind for r in fleet.stats.records.values()]
    assert max(calls) >= 10 and len(calls) > 300  # one call per step for all CVs
    assert 0.3 < kinds.count("cv") / len(kinds) < 0.7
    out = fleet.summary(route_length=5 * cfg.spacing)
    assert out["cv"]["vehicles"] > 0 and out["hdv"]["vehicles"] > 0 and out["collisions"] == 0
    assert 0 < out["all"]["speed"] <= cfg.speed_limit * 1.2 and out["cv"]["energy"] > 0


def test_no_cvs_means_plain_sumo():
    fleet = Fleet(ScenarioConfig(signals="coordinated", mpr=0.0))
    fleet.start(1)
    for _ in range(300):
        assert fleet.step(None) == 0
    fleet.close()
    out = fleet.summary(route_length=2200.0)
    assert out["cv"]["vehicles"] == 0 and out["hdv"]["vehicles"] > 10


def test_summary_counts_the_vehicles_still_driving():
    """CVs that stand still never finish: the finishers' means cannot see them, the space-mean
    speed over every inserted vehicle does."""
    cfg = ScenarioConfig(signals="uncoordinated", arterial_flow=1500.0, mpr=0.5)
    fleet = Fleet(cfg)
    fleet.start(3)

    def stand_still(grids, logics, masks):
        return [(1, np.array([-4.0, -4.0, -4.0], dtype=np.float32))] * len(grids)

    for _ in range(300):
        fleet.step(stand_still)
    fleet.close()
    out = fleet.summary(route_length=5 * cfg.spacing)
    for kind in ("all", "cv", "hdv"):
        assert out[kind]["inserted"] == out[kind]["vehicles"] + out[kind]["unfinished"]
        assert out[kind]["pending"] >= 0
    assert out["cv"]["vehicles"] == 0 and out["cv"]["unfinished"] > 5
    assert out["cv"]["space_mean_speed"] < 1.0
    assert out["hdv"]["vehicles"] > 0 and out["hdv"]["speed"] > 3.0
    assert out["all"]["space_mean_speed"] < out["all"]["speed"]
    assert np.isfinite(out["all"]["energy_per_km"]) and out["all"]["energy_per_km"] > 0
    assert out["stall_steps"] > 0 and out["longest_stall_s"] > 100.0  # standing since insertion


def test_stalls_are_standing_with_free_road_and_no_red():
    from ecodrive_bench.envs.fleet import stalled

    cfg = ScenarioConfig()
    rows, lanes = cfg.grid_shape
    grids = np.ones((4, rows, lanes), dtype=np.float32)
    logic = np.zeros((4, lanes + 4), dtype=np.float32)
    logic[:, 1] = 1.0  # lane 1
    logic[:, lanes + 1] = (0.0, 0.0, 0.0, 8.0)  # speed [m/s]
    logic[:, lanes + 2] = (-1.0, 1.0, 0.0, 0.0)  # red flag: out of range, red, green, green
    grids[2, 15, 1] = 0.0  # a vehicle 5 m ahead: queueing
    grids[0, 15, 2] = 0.0  # one in the next lane does not matter
    assert stalled(grids, logic, cfg).tolist() == [True, False, False, False]
