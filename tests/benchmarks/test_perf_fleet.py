"""pytest-benchmark: a mixed-traffic step with ~200 controlled CVs (batched PRL inference).

extra_info["control_over_sim"]: wall time of observing + deciding + applying for all CVs over
the time inside ``simulationStep``, measured in the same steps (target <= 3).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from ecodrive_bench.agents.registry import make_agent
from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.fleet import Fleet


@pytest.fixture(scope="module")
def fleet():
    torch.set_num_threads(1)
    cfg = ScenarioConfig(signals="coordinated", arterial_flow=5000.0, mpr=1.0)
    f = Fleet(cfg)
    agent = make_agent("prl", f.obs_type.space, f.action_type.space, seed=0)
    policy = lambda g, l, m: [(1, np.array([3.0, 3.0, 3.0], np.float32))] * len(g)  # noqa: E731  (keeps traffic moving)
    f.start(1)
    while len(f.cvs) < 200 and f.stats.steps < 1000:
        f.step(policy)
    yield f, agent
    f.close()


def test_fleet_step_200_cvs(benchmark, fleet):
    f, agent = fleet
    f.stats.sim_time_s = f.stats.control_time_s = 0.0
    counts = []
    benchmark.pedantic(lambda: counts.append(f.step(agent.act_batch)), rounds=30, iterations=1)
    benchmark.extra_info["cvs_mean"] = float(np.mean(counts))
    benchmark.extra_info["control_over_sim"] = f.stats.control_time_s / f.stats.sim_time_s
