"""DDPG + LC2013 (section 5.3): DDPG sets the acceleration, SUMO's LC2013 changes lanes.

Same conv trunk, gamma, step sizes, batch and replay as PRL; OU exploration noise. The reward
is the composite without the lane-change term r_p^c (``lane_change_penalty = 0``).

Bounding the action (not in the paper): the actor's output is the normalised acceleration itself,
clipped to [-1, 1] when acting, and the actor's gradient is inverted at the bounds (Hausknecht &
Stone 2016): dQ/da is scaled by (1 - a)/2 where it pushes a up and by (a + 1)/2 where it pushes
it down, so the output slows down as it nears a bound instead of crossing it. A tanh output
(``bound = "tanh"``) saturates: its pre-tanh output grows on every state until the policy is
"always +3 m/s^2, let Krauss brake", with a vanishing gradient (the run is in docs/notebook.md).
"""
from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces

from .configs import DDPGConfig  # its config lives in agents.configs, read without torch
from .device import CPU, OnDevice, host
from .inference import NumpyNets, ddpg_greedy
from .nets import (
    ConvPass,
    Dense,
    Head,
    LazyAdam,
    ObsScaler,
    OUNoise,
    Workspace,
    clipped_adam_step,
    first_layer_backward,
    load_adam_state,
    mlp_tail,
    mlp_tail_backward,
    set_conv_grads,
    soft_update_,
    trunk_dim,
    zero_grads,
)
from .replay import Replay


class DDPGAgent(OnDevice):
    name = "ddpg"
    action_interface = "longitudinal"
    env_overrides: dict[str, Any] = {"reward": {"lane_change_penalty": 0.0}}
    NETS = ("actor", "critic", "actor_target", "critic_target")
    OPTS = ("opt_actor", "opt_critic")
    # built on first use (an acting agent never builds them)
    opt_actor = LazyAdam(lambda a: a.actor.parameters(), "lr_actor")
    opt_critic = LazyAdam(lambda a: a.critic.parameters(), "lr_critic")
    numpy_greedy = True  # greedy ``act`` on the CPU runs ``inference.NumpyNets``; False: torch's forward

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
        zero_grads(self.actor, self.critic)
        self._nf, self._nl = trunk_dim(grid_shape), logic.shape[0]
        self._numpy = NumpyNets([self.actor], grid_shape)
        self._views()
        self._soft = [([*t.parameters()], [*s.parameters()], tau) for t, s, tau in (
            (self.critic_target, self.critic, cfg.tau_critic), (self.actor_target, self.actor, cfg.tau_actor))]
        self._critic_params, self._actor_params = [[*self.critic.parameters()]], [[*self.actor.parameters()]]
        self.rng = np.random.default_rng(cfg.seed)
        self.noise = OUNoise(1, cfg.ou_theta, cfg.ou_sigma, self.rng)
        self.replay = Replay(cfg.replay_size, grid_shape, logic.shape[0], 1)
        self.updates = 0

    def _views(self) -> None:
        """What the update derives from the parameters and the device (``OnDevice.to``)."""
        nfl = self._nf + self._nl
        self._dense = {name: Dense(getattr(self, name), self._nf, nfl) for name in self.NETS}
        self._ws = Workspace(self.device)  # buffers of the target pass, then of the online pass (done after it)
        self._numpy.stale()

    def begin_episode(self, episode: int) -> None:
        self.noise.reset()

    def _bounded(self, out: torch.Tensor) -> torch.Tensor:
        """The normalised acceleration in [-1, 1] from the actor's raw output."""
        return torch.tanh(out) if self.cfg.bound == "tanh" else out.clamp(-1.0, 1.0)

    def freeze(self) -> None:
        """Greedy acts use the weights as they are now, without checking them for edits at each act
        (``NumpyNets.freeze``), until the next update, ``load_state_dict`` or device move: for an
        agent that only acts (``bench.methods.policies.policy_agent``)."""
        self._numpy.freeze()

    def act(self, obs, info, explore: bool = False) -> np.ndarray:
        if not explore and self.numpy_greedy and self.device == CPU:
            x = ddpg_greedy(self._numpy.current(), obs["grid"], self.scaler.logic(obs["logic"]), self.cfg.bound)
        else:
            with torch.no_grad():
                g = self.tensor(obs["grid"], dtype=torch.float32)[None]
                l = self.tensor(self.scaler.logic(obs["logic"]))[None]
                x = host(self._bounded(self.actor(g, l))[0])
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
        """One step for critic (0.5 MSE of Q(s, a) against r + gamma (1 - done) Q'(s', actor'(s')))
        and actor (-Q(s, actor(s)) through the critic's layers as constants; with ``bound =
        "invert"``, the inverted gradient of the module docstring), then the soft target updates.
        The gradients are computed by hand, as in ``PDQNAgent.update``
        (tests/agents/test_update_equivalence.py holds them to autograd's)."""
        return {k: float(v) for k, v in self.step().items()}

    @torch.no_grad()
    def step(self) -> dict[str, torch.Tensor]:
        """``update``, its losses left as 0-dim tensors on the agent's device (no read-back)."""
        c = self.cfg
        loss_c, q_mean = self._gradients(self.batch(self.replay.sample_torch(self.rng, c.batch_size)))
        clipped_adam_step(self.opt_critic, self._critic_params, c.grad_clip)
        clipped_adam_step(self.opt_actor, self._actor_params, c.grad_clip)
        for targets, sources, tau in self._soft:
            soft_update_(targets, sources, tau)
        self._numpy.stale()  # the fused Adam step writes the parameters without bumping their versions
        self.updates += 1
        return {"loss_q": loss_c, "loss_param": -q_mean}  # -Q(s, actor(s)), as eq. 8

    def _gradients(self, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The gradients into critic's and actor's ``.grad``; returns (critic loss, mean Q(s,
        actor(s))), 0-dim tensors on the agent's device."""
        c = self.cfg
        nf, nfl = self._nf, self._nf + self._nl
        bsz = b["reward"].shape[0]
        dn = self._dense
        z2 = self._ws("z", (2, bsz, nfl + 1))
        ConvPass(b["next_grid"], [self.critic_target.conv, self.actor_target.conv], z2, grad=False, ws=self._ws)
        z2[:, :, nf:nfl] = b["next_logic"]
        at, ct = dn["actor_target"], dn["critic_target"]
        z2[0, :, nfl:] = self._bounded(mlp_tail(at, torch.addmm(at.b1, z2[1, :, :nfl], at.w1t))[2])
        y = b["reward"] + c.gamma * (1.0 - b["done"]) * mlp_tail(ct, torch.addmm(ct.b1, z2[0], ct.w1t))[2].squeeze(1)

        z = self._ws("z", (2, bsz, nfl + 1))
        conv = ConvPass(b["grid"], [self.critic.conv, self.actor.conv], z, grad=True, ws=self._ws)
        z[:, :, nf:nfl] = b["logic"]
        dfeats = self._ws("dfeats", (2, bsz, nf))
        cd, ad = dn["critic"], dn["actor"]
        # the actor's action, then one pass of the critic's layers over Q(s, a_b) (rows :B, the
        # critic's loss) and Q(s, actor(s)) (rows B:, the actor's, through the layers as constants);
        # the first layer's part without the action is shared
        hp1, hp2, out = mlp_tail(ad, torch.addmm(ad.b1, z[1, :, :nfl], ad.w1t))
        a = torch.tanh(out) if c.bound == "tanh" else out
        z[0, :, nfl:] = b["action"]
        hc = torch.addmm(cd.b1, z[0, :, :nfl], cd.w1t_fl)
        pre = self._ws("pre", (2 * bsz, hc.shape[1]))
        torch.addmm(hc, b["action"], cd.w1t_x, out=pre[:bsz])
        torch.addmm(hc, a, cd.w1t_x, out=pre[bsz:])
        h1, h2, qs = mlp_tail(cd, pre)
        q_b, q = qs[:bsz].squeeze(1), qs[bsz:]
        loss_c = 0.5 * F.mse_loss(q_b, y)
        dout = self._ws("dout", (2 * bsz, 1))
        torch.div(q_b - y, bsz, out=dout[:bsz, 0])
        dout[bsz:].fill_(-1.0 / bsz if c.bound == "tanh" else 1.0)  # d(-mean Q)/dQ, or dQ/dQ for dQ/da
        dpre1 = mlp_tail_backward(cd, h1, h2, dout, rows=bsz)
        first_layer_backward(cd, z[0], dpre1[:bsz], dfeats[0])
        dq = torch.mm(dpre1[bsz:], cd.w1_x)
        if c.bound == "tanh":
            dout = torch.ops.aten.tanh_backward(dq, a)
        else:  # dQ/da, inverted at the bounds, batch mean
            dq = torch.where(dq > 0, dq * (1.0 - out) / 2.0, dq * (out + 1.0) / 2.0)
            dout = -dq / bsz
        dpre1 = mlp_tail_backward(ad, hp1, hp2, dout, rows=bsz)
        first_layer_backward(ad, z[1, :, :nfl], dpre1, dfeats[1])
        set_conv_grads([self.critic.conv, self.actor.conv], conv.backward(dfeats))
        return loss_c, q.mean()

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
        self._numpy.stale()
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state.get("actor_target", state["actor"]))
        self.critic_target.load_state_dict(state.get("critic_target", state["critic"]))
        if "opt_actor" in state:
            load_adam_state(self.opt_actor, state["opt_actor"])
            load_adam_state(self.opt_critic, state["opt_critic"])
            self.rng.bit_generator.state = state["rng"]
            self.noise.state[:] = np.asarray(state["ou"])
            self.updates = state["updates"]
