"""SUMO's default driving of the ego (Krauss car following + LC2013 lane changing)."""
from __future__ import annotations

from typing import Any

from .base import _NoLearning


class BaselineAgent(_NoLearning):
    name = "baseline"
    action_interface = "sumo"
    env_overrides: dict[str, Any] = {}

    def act(self, obs, info, explore: bool = False) -> int:
        return 0  # the single no-op action: SUMO drives


class SteadyBaselineAgent(BaselineAgent):
    """SUMO's default driving with the ego's driver imperfection off (Krauss sigma = 0): a
    diagnostic beyond the paper that separates 'drives steadily' from 'anticipates signals'."""

    name = "baseline0"
    env_overrides: dict[str, Any] = {"ego_sigma": 0.0}
