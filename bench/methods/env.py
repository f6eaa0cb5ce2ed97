"""The env a method drives: the registered ``EcoDrive-v0`` with the method's action interface and
its own scenario overrides (GLOSA's device, say) on top of the caller's."""
from __future__ import annotations

from typing import Any

import gymnasium as gym

from ecodrive_bench.agents.base import Agent
from ecodrive_bench.bench.cases.setting import deep_merge
from ecodrive_bench.envs.env import EcoDriveEnv


def make_env(agent: Agent | str, signals: str, config: dict[str, Any] | None = None,
             family: str | None = None) -> EcoDriveEnv:
    """The raw env for an agent (or a method name), with the agent's scenario overrides; ``family``:
    a split of the corridor families, one corridor drawn per reset (``envs.family``)."""
    from ecodrive_bench.bench import registry

    if isinstance(agent, str):
        entry = registry.method(agent)
        interface, overrides = entry.interface, entry.overrides()
    else:
        interface, overrides = agent.action_interface, agent.env_overrides
    cfg = deep_merge(config or {}, overrides)
    env = gym.make("EcoDrive-v0", signals=signals, action=interface, config=cfg,
                   **({"family": family} if family is not None else {}))
    return env.unwrapped  # the harness steps the raw env: no wrappers in the timed loop
