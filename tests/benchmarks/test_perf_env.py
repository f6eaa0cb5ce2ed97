"""pytest-benchmark: env step against a raw libsumo step, reset cost, and MCAP logging overhead.

Run with ``nox -s perf`` (saves JSON and prints the ratios via ``ecodrive perf``).
Each benchmark replays the same fixed case, so the simulated traffic is identical.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.methods.env import make_env

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


FAMILY_RESETS = 10  # reset(seed=i), i = 0..9, per env and round


def test_family_reset(benchmark):
    """``reset(seed=i)`` of a warm ``family="train"`` env (each reset draws a corridor; its scenario
    files were built and cached by a first pass over the same seeds) against the same calls of a
    plain env, alternating within each round. extra_info["over_plain"]: the median of the rounds'
    ratios, taken in the same rounds (robust to machine noise; ``bench.perf``)."""
    import gymnasium as gym

    family = gym.make("EcoDrive-v0", signals="uncoordinated", family="train").unwrapped
    plain = gym.make("EcoDrive-v0", signals="uncoordinated").unwrapped
    ratios, family_s, plain_s = [], [], []
    try:
        for i in range(FAMILY_RESETS):  # warm: every corridor these seeds draw is built once
            family.reset(seed=i)
        plain.reset(seed=0)

        def run():
            t = time.perf_counter()
            for i in range(FAMILY_RESETS):
                family.reset(seed=i)
            t_family = time.perf_counter() - t
            t = time.perf_counter()
            for i in range(FAMILY_RESETS):
                plain.reset(seed=i)
            t_plain = time.perf_counter() - t
            ratios.append(t_family / t_plain)
            family_s.append(t_family / FAMILY_RESETS)
            plain_s.append(t_plain / FAMILY_RESETS)

        benchmark.pedantic(run, rounds=3, iterations=1)
    finally:
        family.close()
        plain.close()
    benchmark.extra_info.update(over_plain=float(np.median(ratios)), family_reset_s=float(np.median(family_s)),
                                plain_reset_s=float(np.median(plain_s)), resets=FAMILY_RESETS)


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
