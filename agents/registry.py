"""Method name -> agent construction, for the harness and the training command."""
from __future__ import annotations

from typing import Any

from .baseline import BaselineAgent, SteadyBaselineAgent
from .ddpg import DDPGAgent, DDPGConfig
from .dqn import DQNAgent, DQNConfig
from .glosa import GlosaAgent
from .pdqn import PDQNAgent, PDQNConfig

LEARNING = ("prl", "mpdqn", "dqn", "ddpg")
RULE_BASED = ("baseline", "glosa", "baseline0")
METHODS = RULE_BASED + LEARNING
ACTION_INTERFACE = {"baseline": "sumo", "glosa": "sumo", "baseline0": "sumo", "prl": "parameterized", "mpdqn": "parameterized",
                    "dqn": "discrete27", "ddpg": "longitudinal"}
ENV_OVERRIDES: dict[str, dict[str, Any]] = {"glosa": GlosaAgent.env_overrides, "ddpg": DDPGAgent.env_overrides,
                                             "baseline0": SteadyBaselineAgent.env_overrides}


def make_agent(method: str, observation_space, action_space, seed: int = 0, **config: Any):
    """A fresh agent for ``method``; ``config`` overrides fields of its config dataclass."""
    if method == "baseline":
        return BaselineAgent()
    if method == "glosa":
        return GlosaAgent()
    if method == "baseline0":
        return SteadyBaselineAgent()
    if method in ("prl", "mpdqn"):
        return PDQNAgent(observation_space, action_space, PDQNConfig(seed=seed, multipass=method == "mpdqn", **config))
    if method == "dqn":
        return DQNAgent(observation_space, action_space, DQNConfig(seed=seed, **config))
    if method == "ddpg":
        return DDPGAgent(observation_space, action_space, DDPGConfig(seed=seed, **config))
    raise ValueError(f"unknown method {method!r}; accepted: {', '.join(METHODS)}")
