"""pytest-benchmark: one greedy ``act`` (batch 1, ``explore=False``) of each learned method on a
real observation, one thread, against a raw SUMO step (``test_raw_sumo_step``, same run).

``test_greedy_act[method]`` is the path the harness drives (agents/inference.py: compiled
kernels over numpy copies of the weights); ``test_greedy_act_torch[method]`` the same act through
torch's forward, for reference.
Each agent is seed 0 of the method's shipped policy (uncoordinated), a fresh agent where none
ships; the observation is the one it sees ``OBS_STEP`` steps into the first fixed case.

A tight loop keeps the weights in cache; in an episode SUMO evicts them between acts, so each
benchmark also records extra_info["episode_act_s"] and ["episode_step_s"]: the median act and
``env.step`` of one greedy episode of that case on its path, timed in the same calls.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from ecodrive_bench.agents.registry import LEARNING, make_agent
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.policies import load_policy, policy_agent, policy_dir, policy_spaces

OBS_STEP = 60  # [steps] into the case: other vehicles in the grid
ROUNDS = 200
ITERATIONS = 10  # acts per round (one act is tens of microseconds)


def _agent(method: str):
    folder = policy_dir(method, "uncoordinated")
    if not (folder / "manifest.json").is_file():
        env = make_env(method, "uncoordinated")
        spaces = env.observation_space, env.action_space
        env.close()
        return make_agent(method, *spaces, seed=0, replay_size=1, batch_size=1)
    state, manifest = load_policy(folder, method)
    return policy_agent(folder, method, policy_spaces(folder, manifest), manifest, state, batch_size=1, replay_size=1)


def _episode(agent, env, case) -> tuple[tuple[dict, dict], dict[str, float]]:
    """One greedy episode of ``case``: (the observation and info at ``OBS_STEP``, {median act,
    median env.step [s]})."""
    obs, info = env.reset(seed=case.sumo_seed, options=case.options())
    kept, acts, steps = None, [], []
    while True:
        t0 = time.perf_counter()
        action = agent.act(obs, info, explore=False)
        t1 = time.perf_counter()
        if len(acts) == OBS_STEP:
            kept = (obs, info)
        obs, _, terminated, truncated, info = env.step(action)
        acts.append(t1 - t0)
        steps.append(time.perf_counter() - t1)
        if terminated or truncated:
            return kept or (obs, info), {"episode_act_s": float(np.median(acts)),
                                         "episode_step_s": float(np.median(steps))}


@pytest.fixture(scope="module")
def acting(cases):
    """method -> (agent, observation, info, {path: episode timings}), path "compiled" or "torch"."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    out = {}
    for method in LEARNING:
        agent = _agent(method)
        env = make_env(agent, "uncoordinated")
        try:
            agent.numpy_greedy = False
            _, torch_episode = _episode(agent, env, cases[0])
            agent.numpy_greedy = True
            (obs, info), compiled_episode = _episode(agent, env, cases[0])
        finally:
            env.close()
        out[method] = (agent, obs, info, {"compiled": compiled_episode, "torch": torch_episode})
    yield out
    torch.set_num_threads(threads)


@pytest.mark.parametrize("method", LEARNING)
def test_greedy_act(benchmark, acting, method):
    agent, obs, info, episode = acting[method]
    assert agent.numpy_greedy
    benchmark.pedantic(agent.act, args=(obs, info), rounds=ROUNDS, iterations=ITERATIONS, warmup_rounds=5)
    benchmark.extra_info.update(episode["compiled"])


@pytest.mark.parametrize("method", LEARNING)
def test_greedy_act_torch(benchmark, acting, method):
    agent, obs, info, episode = acting[method]
    agent.numpy_greedy = False
    try:
        benchmark.pedantic(agent.act, args=(obs, info), rounds=ROUNDS, iterations=ITERATIONS, warmup_rounds=5)
    finally:
        agent.numpy_greedy = True
    benchmark.extra_info.update(episode["torch"])
