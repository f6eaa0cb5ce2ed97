"""pytest-benchmark: the main job's episodes against their floor, method by method.

``extra_info["floor_ratio"]``: the wall time of logged greedy episodes run as ``nox -s
benchmark`` runs them (``bench.harness.executors.run_task``: the shipped seed-0 policy, the step
log, the shipped first plans) over SUMO's own time in them (``sumo_s``: its steps and the reset's
loading and warm-up), over every round. ``ecodrive perf`` prints it against the main job's goal
(1.3x); one process, so the pool's own overhead (a few percent) is not in it. Each round runs
the same fixed cases, so the simulated traffic is identical.

``extra_info["floor_ratio_without_act"]``: the same with the time spent in the agent's ``act``
taken out, what the episodes would cost if acting were free (``ecodrive perf`` prints it beside).
"""
from __future__ import annotations

import dataclasses
import time

import pytest

from ecodrive_bench.agents.registry import LEARNING
from ecodrive_bench.bench.harness import executors
from ecodrive_bench.bench.harness.executors import Task, run_task

METHODS = ("baseline", "prl", "mpdqn", "dqn", "ddpg", "oracle", "mpc")
CASES = 3  # [-] fixed cases a round
ROUNDS = 2
SIGNALS = "uncoordinated"


@pytest.mark.parametrize("method", METHODS)
def test_episode_over_floor(benchmark, method, cases, tmp_path, monkeypatch):
    policy = f"models/{method}-{SIGNALS}/s0" if method in LEARNING else ""
    base = Task(method, SIGNALS, cases[0], "", policy, 0 if policy else -1)
    run_task(dataclasses.replace(base, path=str(tmp_path / "warm.mcap")))  # load the policy, compile, read the tables
    spent = {"wall": 0.0, "sumo": 0.0, "act": 0.0, "n": 0}
    agent, _ = executors._AGENTS[(base.method, base.signals, base.policy_dir, base.scenario)]  # the warm-up's
    act = agent.act

    def timed_act(*args, **kwargs):
        t = time.perf_counter()
        try:
            return act(*args, **kwargs)
        finally:
            spent["act"] += time.perf_counter() - t

    monkeypatch.setattr(agent, "act", timed_act, raising=False)  # undone after the test, however it ends

    def one_round() -> None:
        for case in cases[:CASES]:
            spent["n"] += 1
            t0 = time.perf_counter()
            row = run_task(dataclasses.replace(base, case=case, path=str(tmp_path / f"{spent['n']}.mcap")))
            spent["wall"] += time.perf_counter() - t0
            spent["sumo"] += row["sumo_s"]

    benchmark.pedantic(one_round, rounds=ROUNDS, iterations=1)
    benchmark.extra_info["floor_ratio"] = spent["wall"] / spent["sumo"]
    benchmark.extra_info["floor_ratio_without_act"] = (spent["wall"] - spent["act"]) / spent["sumo"]
    benchmark.extra_info["episodes"] = spent["n"]
