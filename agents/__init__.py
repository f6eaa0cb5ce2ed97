"""Agents: rule-based baselines and (later) the learning methods, behind one protocol."""
from __future__ import annotations

from .base import Agent
from .baseline import BaselineAgent
from .glosa import GlosaAgent

RULE_BASED = {"baseline": BaselineAgent, "glosa": GlosaAgent}  # name -> class, no learning

__all__ = ["Agent", "BaselineAgent", "GlosaAgent", "RULE_BASED"]
