"""Agents: rule-based baselines and the learning methods, behind one protocol."""
from __future__ import annotations

from .base import Agent
from .baseline import BaselineAgent, SteadyBaselineAgent
from .glosa import GlosaAgent

RULE_BASED = {c.name: c for c in (BaselineAgent, GlosaAgent, SteadyBaselineAgent)}  # no learning, by their names

__all__ = ["Agent", "BaselineAgent", "GlosaAgent", "RULE_BASED", "SteadyBaselineAgent"]
