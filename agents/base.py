"""The ``Agent`` protocol shared by the baselines and the learning agents.

Agents see gymnasium spaces and numpy arrays only, never SUMO.
"""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from ecodrive_bench.envs.validation import ConfigError, validate


@runtime_checkable
class Agent(Protocol):
    name: str
    action_interface: str  # the env's ``action=`` this agent drives: parameterized | discrete27 | longitudinal | sumo
    env_overrides: dict[str, Any]  # scenario config overrides the agent needs (e.g. {"glosa": True})

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any], explore: bool = False) -> Any:
        """Action for ``obs``; ``info["action_mask"]`` masks the lateral choice."""

    def observe(self, obs, action, reward: float, next_obs, terminated: bool, truncated: bool,
                info: dict[str, Any]) -> dict[str, float]:
        """Take one transition (learners store and update); returns training metrics."""

    def state_dict(self) -> dict[str, Any]:
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        ...


class _NoLearning:
    """Shared no-op learning half of the rule-based agents."""

    def observe(self, obs, action, reward, next_obs, terminated, truncated, info) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {"name": self.name}  # type: ignore[attr-defined]

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("name") != self.name:  # type: ignore[attr-defined]
            raise ValueError(f"state is for agent {state.get('name')!r}, not {self.name!r}")  # type: ignore[attr-defined]


def check_config(cfg: Any) -> None:
    """Validate a learning agent's config dataclass (called from its ``__post_init__``): every
    field against its declaration (``envs.validation.param``), then the relations between fields.
    A bad value is a ``ConfigError`` (a ValueError) naming the config, the field and the range."""
    name = type(cfg).__name__
    try:
        validate(cfg)
    except ConfigError as e:
        raise ConfigError(f"{name}.{e}") from None
    if cfg.eps_end > cfg.eps_init if hasattr(cfg, "eps_end") else False:
        raise ConfigError(f"{name}.eps_end={cfg.eps_end} exceeds eps_init={cfg.eps_init}; accepted: eps_end <= eps_init")
    if cfg.replay_size < cfg.batch_size:
        raise ConfigError(f"{name}.replay_size={cfg.replay_size} is smaller than batch_size={cfg.batch_size}; "
                          f"accepted: replay_size >= batch_size")
