"""Corridor scenario, SUMO session and the EcoDrive-v0 gymnasium environment."""
from __future__ import annotations

from gymnasium.envs.registration import register

from .config import ConfigError, EVParams, RewardConfig, ScenarioConfig

register(id="EcoDrive-v0", entry_point="ecodrive_bench.envs.env:EcoDriveEnv")

__all__ = ["ConfigError", "EVParams", "RewardConfig", "ScenarioConfig"]
