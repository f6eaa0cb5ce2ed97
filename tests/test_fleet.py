from __future__ import annotations

import numpy as np

from envs.config import ScenarioConfig
from envs.fleet import Fleet


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
