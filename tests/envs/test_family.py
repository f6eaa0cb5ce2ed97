"""Corridor families in the env (``family=``): each reset draws a corridor of the split from the
env's own generator, deterministically per seed, with the same spaces on every corridor; the
training family is its generator's, and shares no corridor with the held-out family."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.envs import family
from ecodrive_bench.envs.config import ConfigError

STAY = (1, np.array([0.0, 1.0, 0.0], np.float32))


def _episode_starts(split: str, seeds: list[int]) -> list[tuple[str, float, bytes]]:
    env = gym.make("EcoDrive-v0", signals="uncoordinated", family=split).unwrapped
    try:
        out = []
        for s in seeds:
            obs, info = env.reset(seed=s)
            assert env.observation_space.contains(obs)
            obs, *_ , info = env.step(STAY)
            out.append((info["corridor"], info["position"], obs["grid"].tobytes()))
        return out
    finally:
        env.close()


@pytest.mark.slow
def test_family_resets_are_deterministic_per_seed_and_cover_the_split():
    names = [c.name for c in family.corridors("validation")]
    seeds = list(range(40))
    first = _episode_starts("validation", seeds)
    assert first == _episode_starts("validation", seeds)  # the corridor, the case and the traffic
    assert {c for c, _, _ in first} == set(names)  # 40 draws over 8 corridors cover them all


def test_the_spaces_are_the_same_on_every_corridor_and_a_corridor_can_be_named():
    env = gym.make("EcoDrive-v0", signals="coordinated", family="test").unwrapped
    try:
        spaces = (env.observation_space, env.action_space)
        for c in family.corridors("test")[:2]:
            obs, info = env.reset(seed=1, options={"corridor": c.name, "sumo_seed": 3, "insert_time": 200.0})
            assert info["corridor"] == c.name and env.cfg.n_intersections == c.scenario["n_intersections"]
            assert (env.observation_space, env.action_space) == spaces and env.observation_space.contains(obs)
        with pytest.raises(ValueError, match="corridor='nowhere' is not accepted"):
            env.reset(options={"corridor": "nowhere"})
    finally:
        env.close()


def test_a_bad_split_is_one_line():
    with pytest.raises(ConfigError, match="family='training' is not accepted; accepted: train, validation, test"):
        gym.make("EcoDrive-v0", family="training")


def test_an_env_without_a_family_takes_no_corridor_option():
    env = gym.make("EcoDrive-v0").unwrapped
    try:
        with pytest.raises(ValueError, match="'corridor'"):
            env.reset(options={"corridor": "t01"})
    finally:
        env.close()


def test_family_of_the_wrong_type_is_a_config_error():
    import gymnasium as gym

    from ecodrive_bench.envs.config import ConfigError

    with pytest.raises(ConfigError, match=r"family=\['train'\] is not accepted; accepted: train, validation, test"):
        gym.make("EcoDrive-v0", family=["train"])


@pytest.mark.parametrize("given, named", [({"lanes": 2}, "lanes"), ({"obs_lanes": 3}, "obs_lanes"),
                                          ({"config": {"spacings": [300.0] * 4}}, "spacings")])
def test_fields_the_family_sets_are_refused_not_replaced(given, named):
    import gymnasium as gym

    from ecodrive_bench.envs.config import ConfigError

    with pytest.raises(ConfigError, match=rf"family='train' sets {named} per corridor; they are not accepted"):
        gym.make("EcoDrive-v0", family="train", **given)
    gym.make("EcoDrive-v0", family="train", lanes=5).close()  # the default itself is no clash


def test_the_test_split_warns_once_per_process(monkeypatch):
    import warnings

    import gymnasium as gym

    from ecodrive_bench.envs import family

    monkeypatch.setattr(family, "_WARNED_TEST", False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym.make("EcoDrive-v0", family="test").close()
        gym.make("EcoDrive-v0", family="test").close()
    said = [w for w in caught if "held-out corridors" in str(w.message)]
    assert len(said) == 1 and issubclass(said[0].category, UserWarning)
