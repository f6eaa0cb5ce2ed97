"""DDPG + LC2013 (section 5.3): DDPG sets the acceleration, SUMO's LC2013 changes lanes.

Same conv trunk, gamma, step sizes, batch and replay as PRL; OU exploration noise. The reward
is the composite without the lane-change term r_p^c (``lane_change_penalty = 0``).

Bounding the action (not in the paper): the actor's output is the normalised acceleration itself,
clipped to [-1, 1] when acting, and the actor's gradient is inverted at the bounds (Hausknecht &
Stone 2016): dQ/da is scaled by (1 - a)/2 where it pushes a up and by (a + 1)/2 where it pushes
it down, so the output slows down as it nears a bound instead of crossing it. With a tanh output
instead (``bound = "tanh"``) the first run saturated: by episode 25 the pre-tanh output was about
4 on every state and by episode 1000 about 10, i.e. "always +3 m/s^2, let Krauss brake", with a
vanishing gradient and the same greedy validation score at every checkpoint from 25 to 1000.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces
from torch.func import functional_call

from .base import check_config
from .nets import Head, ObsScaler, OUNoise, features, soft_update
from .replay import Replay


@dataclass
class DDPGConfig:
    gamma: float = 0.99  # discount factor (Table 2)
    tau_critic: float = 0.01  # soft-update rate of the target critic, tau_1 (Table 2)
    tau_actor: float = 0.001  # soft-update rate of the target actor, tau_2 (Table 2)
    lr_critic: float = 1e-4  # Adam step size of the critic, alpha (Table 2)
    lr_actor: float = 1e-5  # Adam step size of the actor, beta (Table 2)
    batch_size: int = 128  # minibatch size (Table 2)
    replay_size: int = 500_000  # replay capacity (Table 2)
    ou_theta: float = 0.15  # OU mean reversion per step (not in the paper)
    ou_sigma: float = 0.2  # OU noise scale in units of the half action range (not in the paper)
    learning_starts: int = 1000  # transitions stored before the first update (not in the paper)
    reward_scale: float = 0.01  # rewards are multiplied by this for learning
    grad_clip: float = 10.0  # max gradient norm per network (not in the paper)
    bound: str = "invert"  # "invert": inverting gradients at [-1, 1]; "tanh": squash (saturates, see above)
    seed: int = 0  # seeds network initialisation and the agent's numpy Generator

    def __post_init__(self) -> None:
        check_config(self)
        if self.bound not in ("invert", "tanh"):
            raise ValueError(f"DDPGConfig.bound={self.bound!r}; accepted: 'invert', 'tanh'")


class DDPGAgent:
    name = "ddpg"
    action_interface = "longitudinal"
    env_overrides: dict[str, Any] = {"reward": {"lane_change_penalty": 0.0}}

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, cfg: DDPGConfig | None = None):
        self.cfg = cfg = cfg or DDPGConfig()
        grid_shape, logic = observation_space["grid"].shape, observation_space["logic"]
        self.a_low, self.a_high = float(action_space.low[0]), float(action_space.high[0])
        self.scaler = ObsScaler(logic.low, logic.high)
        with torch.random.fork_rng():
            torch.manual_seed(cfg.seed)
            self.actor = Head(grid_shape, logic.shape[0], 0, (128, 64), 1)
            self.critic = Head(grid_shape, logic.shape[0], 1, (256, 64), 1)
            self.actor_target = Head(grid_shape, logic.shape[0], 0, (128, 64), 1)
            self.critic_target = Head(grid_shape, logic.shape[0], 1, (256, 64), 1)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr_actor)
        self.opt_critic = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr_critic)
        self.rng = np.random.default_rng(cfg.seed)
        self.noise = OUNoise(1, cfg.ou_theta, cfg.ou_sigma, self.rng)
        self.replay = Replay(cfg.replay_size, grid_shape, logic.shape[0], 1)
        self.updates = 0

    def begin_episode(self, episode: int) -> None:
        self.noise.reset()

    def _bounded(self, out: torch.Tensor) -> torch.Tensor:
        """The normalised acceleration in [-1, 1] from the actor's raw output."""
        return torch.tanh(out) if self.cfg.bound == "tanh" else out.clamp(-1.0, 1.0)

    def act(self, obs, info, explore: bool = False) -> np.ndarray:
        with torch.no_grad():
            g = torch.as_tensor(obs["grid"], dtype=torch.float32)[None]
            l = torch.as_tensor(self.scaler.logic(obs["logic"]))[None]
            x = self._bounded(self.actor(g, l))[0].numpy()
        if explore:
            x = np.clip(x + self.noise.sample(), -1.0, 1.0)
        self._last = x.astype(np.float32)
        return (self.a_low + (self._last + 1.0) * 0.5 * (self.a_high - self.a_low)).astype(np.float32)

    def observe(self, obs, action, reward, next_obs, terminated, truncated, info) -> dict[str, float]:
        self.replay.add(obs["grid"], self.scaler.logic(obs["logic"]), self._last, reward * self.cfg.reward_scale,
                        next_obs["grid"], self.scaler.logic(next_obs["logic"]), float(terminated),
                        np.ones(3, dtype=bool))
        if self.replay.size < max(self.cfg.learning_starts, self.cfg.batch_size):
            return {}
        return self.update()

    def update(self) -> dict[str, float]:
        c = self.cfg
        b = self.replay.sample(self.rng, c.batch_size)
        g, l = torch.as_tensor(b["grid"], dtype=torch.float32), torch.as_tensor(b["logic"])
        with torch.no_grad():
            fc2, fa2 = features(torch.as_tensor(b["next_grid"], dtype=torch.float32),
                                torch.as_tensor(b["next_logic"]), [self.critic_target, self.actor_target])
            a2 = self._bounded(self.actor_target.from_features(fa2))
            y = torch.as_tensor(b["reward"]) + c.gamma * (1.0 - torch.as_tensor(b["done"])) * \
                self.critic_target.from_features(fc2, a2).squeeze(1)
        fc, fa = features(g, l, [self.critic, self.actor])
        loss_c = 0.5 * F.mse_loss(self.critic.from_features(fc, torch.as_tensor(b["action"])).squeeze(1), y)
        frozen = {n: p.detach() for n, p in self.critic.mlp.named_parameters()}
        out = self.actor.from_features(fa)
        if c.bound == "tanh":
            q = functional_call(self.critic.mlp, frozen, (torch.cat([fc.detach(), torch.tanh(out)], 1),))
            loss_a = -q.mean()
        else:
            a = out.detach().requires_grad_(True)
            q = functional_call(self.critic.mlp, frozen, (torch.cat([fc.detach(), a], 1),))
            dq = torch.autograd.grad(q.sum(), a)[0]
            x = out.detach()
            dq = torch.where(dq > 0, dq * (1.0 - x) / 2.0, dq * (x + 1.0) / 2.0)
            loss_a = -(out * dq).sum() / out.shape[0]  # its gradient is the inverted -dQ/da, batch mean
        self.opt_critic.zero_grad(set_to_none=True)
        self.opt_actor.zero_grad(set_to_none=True)
        (loss_c + loss_a).backward()  # each loss reaches only its own network
        torch.nn.utils.clip_grad_norm_(self.critic.parameters(), c.grad_clip)
        torch.nn.utils.clip_grad_norm_(self.actor.parameters(), c.grad_clip)
        self.opt_critic.step()
        self.opt_actor.step()
        soft_update(self.critic_target, self.critic, c.tau_critic)
        soft_update(self.actor_target, self.actor, c.tau_actor)
        self.updates += 1
        return {"loss_q": loss_c.item(), "loss_param": -q.detach().mean().item()}  # -Q(s, actor(s)), as eq. 8

    def state_dict(self, with_training: bool = True) -> dict[str, Any]:
        state = {"name": self.name, "config": asdict(self.cfg), "actor": self.actor.state_dict(),
                 "critic": self.critic.state_dict()}
        if with_training:
            state.update({
                "actor_target": self.actor_target.state_dict(), "critic_target": self.critic_target.state_dict(),
                "opt_actor": self.opt_actor.state_dict(), "opt_critic": self.opt_critic.state_dict(),
                "rng": self.rng.bit_generator.state, "ou": torch.from_numpy(self.noise.state.copy()), "updates": self.updates,
            })
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("name") != self.name:
            raise ValueError(f"checkpoint is for method {state.get('name')!r}, not {self.name!r}")
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state.get("actor_target", state["actor"]))
        self.critic_target.load_state_dict(state.get("critic_target", state["critic"]))
        if "opt_actor" in state:
            self.opt_actor.load_state_dict(state["opt_actor"])
            self.opt_critic.load_state_dict(state["opt_critic"])
            self.rng.bit_generator.state = state["rng"]
            self.noise.state[:] = np.asarray(state["ou"])
            self.updates = state["updates"]
