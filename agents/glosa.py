"""SUMO's own GLOSA device (green light optimal speed advisory) on the ego, range = V2I range.

A rule-based eco-driving baseline beyond the paper: SUMO adapts the ego's speed factor to
arrive on green; the env sets ``device.glosa.range`` to ``v2i_range``.
"""
from __future__ import annotations

from typing import Any

from .base import _NoLearning


class GlosaAgent(_NoLearning):
    name = "glosa"
    action_interface = "sumo"
    env_overrides: dict[str, Any] = {"glosa": True}

    def act(self, obs, info, explore: bool = False) -> int:
        return 0
