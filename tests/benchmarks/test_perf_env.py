"""pytest-benchmark: env step against a raw libsumo step, reset cost, and MCAP logging overhead.

Run with ``nox -s perf`` (saves JSON and prints the ratios via ``ecodrive perf``).
Each benchmark replays the same fixed case, so the simulated traffic is identical.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.harness.episode import make_env, run_episode

STEPS = 150  # simulated seconds after the ego's insertion
ROUNDS = 15
KEEP = (1, np.zeros(3, dtype=np.float32))  # stay in lane, request 0 m/s^2


@pytest.fixture(scope="module")
def env():
    import gymnasium as gym

    e = gym.make("EcoDrive-v0", signals="uncoordinated", action="parameterized").unwrapped
    yield e
    e.close()


def _setup(env, case):
    def setup():
        env.reset(options=case.options())
        return (), {}
    return setup


def test_raw_sumo_step(benchmark, env, cases):
    """STEPS raw ``simulationStep`` calls with the ego in the network (no queries)."""
    def run():
        for _ in range(STEPS):
            env.session.step()
    benchmark.pedantic(run, setup=_setup(env, cases[0]), rounds=ROUNDS, iterations=1)
    benchmark.extra_info["steps"] = STEPS  # a round's simulationStep calls (bench.perf: one step's time)


def test_env_step(benchmark, env, cases):
    """STEPS ``env.step`` calls (observation, safety layer, reward) with a constant action.

    extra_info["sim_share"]: the share of env.step time spent inside libsumo's simulationStep,
    timed in the same calls (robust to machine noise)."""
    sim = [0.0]
    raw_step = env.session.step

    def timed_step(until: float = 0.0) -> None:
        t = time.perf_counter()
        raw_step(until)
        sim[0] += time.perf_counter() - t

    def run():
        for _ in range(STEPS):
            env.step(KEEP)

    def setup():
        env.session.step = raw_step
        env.reset(options=cases[0].options())
        env.session.step = timed_step
        return (), {}

    t0 = time.perf_counter()
    benchmark.pedantic(run, setup=setup, rounds=ROUNDS, iterations=1)
    env.session.step = raw_step
    total = benchmark.stats.stats.total
    benchmark.extra_info["step_over_sim"] = total / sim[0]
    del t0


def test_env_reset(benchmark, env, cases):
    it = iter(range(10**6))
    benchmark.pedantic(lambda: env.reset(options=cases[next(it) % len(cases)].options()), rounds=20, iterations=1)


@pytest.fixture(scope="module")
def baseline_env():
    agent = BaselineAgent()
    e = make_env(agent, "uncoordinated")
    yield agent, e
    e.close()


def test_episode_unlogged(benchmark, baseline_env, cases):
    agent, env = baseline_env
    benchmark.pedantic(lambda: run_episode(env, agent, cases[0], "baseline"), rounds=10, iterations=1)


def test_episode_logged(benchmark, baseline_env, cases, tmp_path, monkeypatch):
    """extra_info["log_share"]: time inside the logger (record + finish) over episode time
    without it, measured in the same episodes."""
    from ecodrive_bench.bench.logs import mcaplog

    agent, env = baseline_env
    spent = [0.0]
    for name in ("record", "finish", "__init__"):
        orig = getattr(mcaplog.EpisodeLog, name)

        def timed(self, *a, _orig=orig, **k):
            t = time.perf_counter()
            try:
                return _orig(self, *a, **k)
            finally:
                spent[0] += time.perf_counter() - t
        monkeypatch.setattr(mcaplog.EpisodeLog, name, timed)
    it = iter(range(10**6))
    benchmark.pedantic(
        lambda: run_episode(env, agent, cases[0], "baseline", log_path=tmp_path / f"case-{next(it)}.mcap"),
        rounds=10, iterations=1,
    )
    total = benchmark.stats.stats.total
    benchmark.extra_info["log_overhead"] = spent[0] / (total - spent[0])
