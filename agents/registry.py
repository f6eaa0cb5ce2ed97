"""Method name -> agent construction, for the harness and the training command. The learning
agents (torch) are imported when one is built, so the method names cost no torch import (a
command's ``--help`` lists them)."""
from __future__ import annotations

from typing import Any

from . import RULE_BASED as _RULE_CLASSES

LEARNING = ("prl", "mpdqn", "dqn", "ddpg")  # trainable methods (``ecodrive train --method``)
FAMILY_SUFFIX = "-family"  # a learning method trained over the corridor family: its own method name
GENERALISTS = tuple(f"{m}{FAMILY_SUFFIX}" for m in ("prl", "mpdqn"))  # the ones a run looks for
POLICY_METHODS = LEARNING + GENERALISTS  # methods that drive with a trained policy
RULE_BASED = tuple(_RULE_CLASSES)
METHODS = RULE_BASED + POLICY_METHODS
ACTION_INTERFACE = {**{m: c.action_interface for m, c in _RULE_CLASSES.items()},
                    "prl": "parameterized", "mpdqn": "parameterized", "dqn": "discrete27", "ddpg": "longitudinal"}
ACTION_INTERFACE.update({g: ACTION_INTERFACE[g.removesuffix(FAMILY_SUFFIX)] for g in GENERALISTS})


def base_method(method: str) -> str:
    """The algorithm a method runs: ``prl-family`` is PRL trained over the family."""
    return method.removesuffix(FAMILY_SUFFIX) if method in GENERALISTS else method


def __getattr__(name: str) -> Any:
    """``ENV_OVERRIDES``: method -> the scenario overrides its agent needs, read from the agent
    classes on first use (DDPG's imports torch)."""
    if name != "ENV_OVERRIDES":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from .ddpg import DDPGAgent

    value = {m: c.env_overrides for m, c in {**_RULE_CLASSES, "ddpg": DDPGAgent}.items() if c.env_overrides}
    globals()["ENV_OVERRIDES"] = value
    return value


def make_agent(method: str, observation_space, action_space, seed: int = 0, **config: Any):
    """A fresh agent for ``method``; ``config`` overrides fields of its config dataclass."""
    method = base_method(method)
    if method in _RULE_CLASSES:
        return _RULE_CLASSES[method]()
    from .ddpg import DDPGAgent, DDPGConfig
    from .dqn import DQNAgent, DQNConfig
    from .pdqn import PDQNAgent, PDQNConfig

    if method in ("prl", "mpdqn"):
        return PDQNAgent(observation_space, action_space, PDQNConfig(seed=seed, multipass=method == "mpdqn", **config))
    if method == "dqn":
        return DQNAgent(observation_space, action_space, DQNConfig(seed=seed, **config))
    if method == "ddpg":
        return DDPGAgent(observation_space, action_space, DDPGConfig(seed=seed, **config))
    raise ValueError(f"unknown method {method!r}; accepted: {', '.join(METHODS)}")
