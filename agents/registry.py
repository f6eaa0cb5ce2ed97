"""Algorithm name -> agent construction, for the harness and the training command. The learning
agents (torch) are imported when one is built, so the names cost no torch import. Which methods
exist, their kinds, interfaces and names are the method registry's (``bench.registry``), which
names these algorithms; this module builds them."""
from __future__ import annotations

from typing import Any

from . import RULE_BASED as _RULE_CLASSES
from .configs import PDQN_NAMES

LEARNING = (*PDQN_NAMES.values(), "dqn", "ddpg")  # the algorithms ``ecodrive train --method`` trains


def config_class(algorithm: str) -> type:
    """The config dataclass of a learning algorithm (``agents.configs``: no torch)."""
    from .configs import DDPGConfig, DQNConfig, PDQNConfig

    if algorithm not in LEARNING:
        raise ValueError(f"unknown algorithm {algorithm!r}; accepted: {', '.join(LEARNING)}")
    return {"ddpg": DDPGConfig, "dqn": DQNConfig}.get(algorithm, PDQNConfig)


def make_agent(algorithm: str, observation_space, action_space, seed: int = 0, **config: Any):
    """A fresh agent of ``algorithm`` (a learning one, or a rule-based method's name); ``config``
    overrides fields of its config dataclass."""
    if algorithm in _RULE_CLASSES:
        return _RULE_CLASSES[algorithm]()
    from .ddpg import DDPGAgent, DDPGConfig
    from .dqn import DQNAgent, DQNConfig
    from .pdqn import PDQNAgent, PDQNConfig

    if algorithm in PDQN_NAMES.values():
        multipass = algorithm == PDQN_NAMES[True]
        return PDQNAgent(observation_space, action_space, PDQNConfig(seed=seed, multipass=multipass, **config))
    if algorithm == "dqn":
        return DQNAgent(observation_space, action_space, DQNConfig(seed=seed, **config))
    if algorithm == "ddpg":
        return DDPGAgent(observation_space, action_space, DDPGConfig(seed=seed, **config))
    raise ValueError(f"unknown algorithm {algorithm!r}; accepted: {', '.join([*_RULE_CLASSES, *LEARNING])}")
