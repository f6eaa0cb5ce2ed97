"""pytest-benchmark: the DP's cold solve (``bound``), mpc's periodic table and first plan, and a re-plan.

Run with ``nox -s perf``; ``ecodrive perf`` prints the re-plan's median and p99 against the cold
solve of the same case in the same run. The re-plans are the ones ``mpc`` made while driving a
fixed case in traffic (states, leaders and all), so their spread is the real one.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from ecodrive_bench.bench.harness.mpc import MPCAgent
from ecodrive_bench.bench.oracle import mpc
from ecodrive_bench.bench.oracle.dp import bound

ROUNDS = 3
QUANTILES = {"median": 0.5, "p99": 0.99}


@pytest.fixture(scope="module")
def driven(cases):
    """(agent, the re-plan inputs (k, x, v, leader, keywords) of one episode in traffic)."""
    import gymnasium as gym

    env = gym.make("EcoDrive-v0", signals="uncoordinated", action="longitudinal").unwrapped
    agent = MPCAgent(env.cfg)
    inputs: list[tuple[int, float, float, mpc.Leader | None, dict]] = []
    plan = mpc.replan

    def record(tab, k, x, v, leader=None, **kw):
        inputs.append((k, x, v, leader, kw))
        return plan(tab, k, x, v, leader, **kw)

    mpc.replan = record  # the agent calls it through the module
    try:
        obs, info = env.reset(options=cases[0].options())
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
            done = terminated or truncated
    finally:
        mpc.replan = plan
        env.close()
    assert inputs, "the episode made no re-plan"
    return agent, inputs


def test_dp_cold_solve(benchmark, driven):
    """The bound of the driven case's departure, as the harness solves it (numba kernel)."""
    agent, _ = driven
    benchmark.pedantic(bound, args=(agent.cfg, float(agent.plan.t[0]), "cost"), rounds=ROUNDS, iterations=1)


def test_dp_cold_solve_numpy(benchmark, driven):
    """The same bound with the numpy kernel and no pruning: the solver as it was before the compiled
    kernel and the pruned global pass, the reference the cold solve's speed-up is taken against
    (``ecodrive perf``). The plan is the same."""
    agent, _ = driven
    benchmark.pedantic(bound, args=(agent.cfg, float(agent.plan.t[0]), "cost"), kwargs={"kernel": "numpy", "prune": False},
                       rounds=ROUNDS, iterations=1)


def test_dp_periodic_table(benchmark, driven):
    """What ``mpc`` solves once per process and corridor: the periodic cost-to-go table."""
    agent, _ = driven

    def build():
        mpc._PERIODIC.clear()
        return mpc.periodic(agent.cor, agent.plan_cfg)

    benchmark.pedantic(build, rounds=ROUNDS, iterations=1)


def test_dp_mpc_start(benchmark, driven):
    """What ``mpc`` solves once per episode, the table in hand: its first plan (local passes)."""
    agent, _ = driven
    mpc.periodic(agent.cor, agent.plan_cfg)
    benchmark.pedantic(mpc.start, args=(agent.cor, agent.plan_cfg, float(agent.plan.t[0])), rounds=ROUNDS, iterations=1)


def test_dp_replan(benchmark, driven):
    """Every re-plan of the driven episode, in one round; extra_info: one re-plan's median and p99."""
    agent, inputs = driven
    tab = agent.table
    times: list[float] = []

    def run():
        for k, x, v, leader, kw in inputs:
            t0 = time.perf_counter()
            mpc.replan(tab, k, x, v, leader, **kw)
            times.append(time.perf_counter() - t0)

    benchmark.pedantic(run, rounds=ROUNDS, iterations=1)
    benchmark.extra_info["replans"] = len(inputs)
    for name, q in QUANTILES.items():
        benchmark.extra_info[f"{name}_s"] = float(np.quantile(times, q))
