"""What the built-in planners (``oracle``, ``mpc``) share as agents: they never learn, and their
state is their name."""
from __future__ import annotations

from typing import Any


class NotLearning:
    """``observe``, ``state_dict`` and ``load_state_dict`` of an agent that does not learn."""

    name = ""

    def observe(self, obs, action, reward, next_obs, terminated, truncated, info) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {"name": self.name}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("name") != self.name:
            raise ValueError(f"state is for agent {state.get('name')!r}, not {self.name!r}")
