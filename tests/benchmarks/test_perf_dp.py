"""pytest-benchmark: the DP's cold solve (``bound``), mpc's periodic table and first plan, and a re-plan.

Run with ``nox -s perf``; ``ecodrive perf`` prints the cold solve against the reference solver,
both timed in the same rounds, and the re-plan's median and p99 against the cold solve of the same
case. The re-plans are the ones ``mpc`` made while driving a fixed case in traffic (states, leaders
and all), so their spread is the real one.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from ecodrive_bench.bench.methods.mpc_agent import MPCAgent
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
    """The bound of the driven case's departure as the harness solves it (numba kernel) and, in each
    round right after it, the same bound by the reference solver: the numpy kernel and no pruning,
    the solver as it was before the compiled kernel and the pruned global pass (the same plan,
    checked). extra_info: the cold solve's median (``time_s``), the reference's (``reference_s``)
    and the median of the rounds' ratios (``over_reference``, which ``ecodrive perf`` prints): a
    ratio from the same rounds, so a busy machine slows both sides of it."""
    agent, _ = driven
    cfg, depart = agent.cfg, float(agent.plan.t[0])
    solve_s: list[float] = []
    reference_s: list[float] = []

    def pair():
        t0 = time.perf_counter()
        plan = bound(cfg, depart, "cost")
        t1 = time.perf_counter()
        ref = bound(cfg, depart, "cost", kernel="numpy", prune=False)
        reference_s.append(time.perf_counter() - t1)
        solve_s.append(t1 - t0)
        assert np.array_equal(plan.x, ref.x) and np.array_equal(plan.v, ref.v) and plan.cost == ref.cost

    benchmark.pedantic(pair, rounds=ROUNDS, iterations=1)
    benchmark.extra_info["depart_s"] = depart
    benchmark.extra_info["time_s"] = float(np.median(solve_s))
    benchmark.extra_info["reference_s"] = float(np.median(reference_s))
    benchmark.extra_info["over_reference"] = float(np.median(np.array(solve_s) / np.array(reference_s)))


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


def test_clairvoyant_plan(benchmark, cases):
    """Planning a case that is not shipped (``ClairvoyantAgent(shipped=None).prepare``: its
    record-and-drive rounds, each drive re-planning every step on the DP), against a baseline episode
    of the same case, timed in the same rounds. extra_info["over_episode"]: the median of the
    rounds' ratios, the plan's cost in episodes (``bench.perf``); a shipped case costs one episode."""
    from ecodrive_bench.agents import BaselineAgent
    from ecodrive_bench.bench.harness.episode import run_episode
    from ecodrive_bench.bench.methods.clairvoyant_agent import ClairvoyantAgent
    from ecodrive_bench.bench.methods.env import make_env

    case = cases[0]
    planner = ClairvoyantAgent(make_env("baseline", "uncoordinated").cfg, shipped=None)
    env = make_env(planner, "uncoordinated")
    base, base_env = BaselineAgent(), make_env("baseline", "uncoordinated")
    ratios, plan_s, episode_s = [], [], []
    try:
        def run():
            t = time.perf_counter()
            planner.prepare(env, case)
            t_plan = time.perf_counter() - t
            t = time.perf_counter()
            run_episode(base_env, base, case, "baseline")
            t_episode = time.perf_counter() - t
            ratios.append(t_plan / t_episode)
            plan_s.append(t_plan)
            episode_s.append(t_episode)

        benchmark.pedantic(run, rounds=ROUNDS, iterations=1)
    finally:
        env.close()
        base_env.close()
    benchmark.extra_info.update(over_episode=float(np.median(ratios)), plan_s=float(np.median(plan_s)),
                                episode_s=float(np.median(episode_s)))
