"""An env dropped without ``close()`` gives libsumo up when it is garbage-collected: the next env of
the process runs there, not through TraCI for the rest of the process."""
from __future__ import annotations

import gc

import gymnasium as gym

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)

CASE = {"sumo_seed": 7, "insert_time": 210.0}


def _mid_episode(signals: str = "coordinated"):
    env = gym.make("EcoDrive-v0", signals=signals)
    env.reset(options=CASE)
    return env


def test_an_env_dropped_mid_episode_gives_libsumo_to_the_next_one():
    first = _mid_episode()
    assert first.unwrapped.session.backend == "libsumo"  # no other env of this process holds it
    del first
    gc.collect()
    second = _mid_episode()
    try:
        assert second.unwrapped.session.backend == "libsumo"
    finally:
        second.close()
