"""pytest-benchmark: env.step on a real corridor (ingolstadt7, the route frame) against a raw
libsumo step of the same network, in one run (``ecodrive perf``: ``real_env_step_over_raw_step``,
target <= 1.5). Each round replays the corridor's first fixed case, so the traffic is identical."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.bench.cases import real

STEPS = 150  # simulated seconds after the ego's insertion
ROUNDS = 10
KEEP = (1, np.zeros(3, dtype=np.float32))  # stay in lane, request 0 m/s^2


@pytest.fixture(scope="module")
def real_env():
    e = gym.make("EcoDrive-v0", network="ingolstadt7", action="parameterized").unwrapped
    yield e, real.variants(["ingolstadt7"])[0].cases[0]
    e.close()


def _reset(env, case):
    def setup():
        env.reset(options=case.options())
        return (), {}
    return setup


def test_real_raw_sumo_step(benchmark, real_env):
    """STEPS raw ``simulationStep`` calls on ingolstadt7 with the ego in the network (no queries)."""
    env, case = real_env

    def run():
        for _ in range(STEPS):
            env.session.step()
    benchmark.pedantic(run, setup=_reset(env, case), rounds=ROUNDS, iterations=1)


def test_real_env_step(benchmark, real_env):
    """STEPS ``env.step`` calls on ingolstadt7 (route-frame observation, masks, reward)."""
    env, case = real_env

    def run():
        for _ in range(STEPS):
            _, _, terminated, truncated, _ = env.step(KEEP)
            assert not (terminated or truncated)  # the ratio is over steps in traffic, not after the end
    benchmark.pedantic(run, setup=_reset(env, case), rounds=ROUNDS, iterations=1)
