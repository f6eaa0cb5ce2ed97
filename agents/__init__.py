"""Agents: rule-based baselines and the learning methods, behind one protocol."""
from __future__ import annotations

from .base import Agent
from .baseline import BaselineAgent, SteadyBaselineAgent
from .glosa import GlosaAgent

RULE_BASED = {"baseline": BaselineAgent, "glosa": GlosaAgent, "baseline0": SteadyBaselineAgent}  # no learning

__all__ = ["Agent", "BaselineAgent", "GlosaAgent", "RULE_BASED", "SteadyBaselineAgent"]
