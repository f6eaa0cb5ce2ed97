"""The ``Agent`` protocol shared by the baselines and the learning agents.

Agents see gymnasium spaces and numpy arrays only, never SUMO.
"""
from __future__ import annotations

from dataclasses import fields
from typing import Any, Protocol, runtime_checkable

import numpy as np


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


# Accepted ranges of the learning agents' config fields, by field name (lo, hi, lo_open): the
# configs share these names. A value outside is a ValueError naming it and the range.
FIELD_RANGES: dict[str, tuple[float | None, float | None, bool]] = {
    "gamma": (0.0, 1.0, False), "tau": (0.0, 1.0, True), "tau_q": (0.0, 1.0, True),
    "tau_param": (0.0, 1.0, True), "tau_critic": (0.0, 1.0, True), "tau_actor": (0.0, 1.0, True),
    "lr": (0.0, 1.0, True), "lr_q": (0.0, 1.0, True), "lr_param": (0.0, 1.0, True),
    "lr_critic": (0.0, 1.0, True), "lr_actor": (0.0, 1.0, True),
    "batch_size": (1, None, False), "replay_size": (1, None, False),
    "eps_init": (0.0, 1.0, False), "eps_end": (0.0, 1.0, False), "eps_decay_episodes": (1, None, False),
    "ou_theta": (0.0, 1.0, False), "ou_sigma": (0.0, None, False), "learning_starts": (0, None, False),
    "reward_scale": (0.0, None, True), "n_step": (1, 100, False), "grad_clip": (0.0, None, True), "seed": (0, None, False),
}


def check_config(cfg: Any) -> None:
    """Range-check a learning agent's config dataclass (called from its ``__post_init__``)."""
    name = type(cfg).__name__
    for f in fields(cfg):
        v = getattr(cfg, f.name)
        if f.name not in FIELD_RANGES or isinstance(v, bool):
            continue
        lo, hi, lo_open = FIELD_RANGES[f.name]
        ok = isinstance(v, (int, float)) and v == v and (lo is None or (v > lo if lo_open else v >= lo)) \
            and (hi is None or v <= hi)
        if not ok:
            rng = f"{lo} {'<' if lo_open else '<='} {f.name}" + (f" <= {hi}" if hi is not None else "")
            raise ValueError(f"{name}.{f.name} = {v!r} is out of range; accepted: {rng}")
    if getattr(cfg, "eps_end", 0.0) > getattr(cfg, "eps_init", 1.0):
        raise ValueError(f"{name}.eps_end = {cfg.eps_end} exceeds eps_init = {cfg.eps_init}; accepted: eps_end <= eps_init")
    if cfg.replay_size < cfg.batch_size:
        raise ValueError(f"{name}.replay_size = {cfg.replay_size} is smaller than batch_size = {cfg.batch_size}; "
                         f"accepted: replay_size >= batch_size")
