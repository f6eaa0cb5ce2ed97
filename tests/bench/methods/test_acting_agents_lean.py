"""An agent that only acts builds no optimizer: a harness worker loads a policy and acts without
the optimizers' import of ``torch._dynamo`` (about a second per worker)."""
from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import sys
import numpy as np
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.policies import load_policy, policy_agent, policy_dir, policy_spaces
for m in ("prl", "mpdqn", "dqn", "ddpg"):
    folder = policy_dir(m, "uncoordinated")
    state, man = load_policy(folder, m)
    agent = policy_agent(folder, m, policy_spaces(folder, man), man, state)
    env = make_env(agent, "uncoordinated")
    obs, info = env.reset(options={"sumo_seed": 1, "insert_time": 30.0})
    for _ in range(3):
        obs, *_, info = env.step(agent.act(obs, info, explore=False))
    env.close()
    built = [n for n in agent.OPTS if getattr(type(agent), n).built(agent) is not None]
    print(m, "built:", built)
print("dynamo imported:", "torch._dynamo" in sys.modules)
agent.opt_actor  # a learner's first use builds it
print("after first use:", getattr(type(agent), "opt_actor").built(agent) is not None)
"""


def test_policy_agents_act_without_building_an_optimizer():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert lines[:4] == [f"{m} built: []" for m in ("prl", "mpdqn", "dqn", "ddpg")]
    assert lines[4:] == ["dynamo imported: False", "after first use: True"]


def test_an_optimizer_assigned_in_place_of_the_lazy_one_is_the_one_used():
    import torch

    from ecodrive_bench.agents.ddpg import DDPGAgent
    from ecodrive_bench.bench.methods.env import make_env

    env = make_env("ddpg", "uncoordinated")
    agent = DDPGAgent(env.observation_space, env.action_space)
    assert type(agent).opt_actor.built(agent) is None
    mine = torch.optim.Adam(agent.actor.parameters(), lr=1e-3)
    agent.opt_actor = mine
    assert agent.opt_actor is mine and type(agent).opt_actor.built(agent) is mine
    assert agent.opt_critic is type(agent).opt_critic.built(agent) is not None  # built on first use
    env.close()
