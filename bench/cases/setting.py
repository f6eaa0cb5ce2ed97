"""The scenario of one signal setting under a command's overrides: the paper's corridor with
``--scenario``/``--set`` on top (``bench.harness.scenarios`` reads and checks them), the one way
every case set, bound and method builds its ``ScenarioConfig``."""
from __future__ import annotations

from typing import Any

from ecodrive_bench.envs.config import ScenarioConfig


def deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``over`` on top, nested dicts merged key by key."""
    out = dict(base)
    for k, v in over.items():
        out[k] = deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def setting(signals: str, overrides: dict[str, Any] | None) -> ScenarioConfig:
    """The scenario of one signal setting under the command's overrides."""
    return ScenarioConfig.from_dict(deep_merge({"signals": signals}, overrides or {}))
