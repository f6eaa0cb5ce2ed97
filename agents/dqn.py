"""DQN over the paper's 27 discrete actions (section 5.3): 9 accelerations x 3 lateral choices.

Same conv trunk, hyperparameters and eps schedule as PRL (Table 2, eq. 12); the LC2013 mask
removes the actions whose lateral part is unsafe, when acting and in the target max.
"""
from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces

from .configs import DQNConfig  # its config lives in agents.configs, read without torch
from .device import CPU, OnDevice, host
from .inference import NumpyNets, dqn_greedy
from .nets import (
    ConvPass,
    Dense,
    Head,
    LazyAdam,
    ObsScaler,
    Workspace,
    clipped_adam_step,
    first_layer_backward,
    linear_epsilon,
    load_adam_state,
    mlp_tail,
    mlp_tail_backward,
    set_conv_grads,
    soft_update_,
    trunk_dim,
    zero_grads,
)
from .replay import Replay

N_LAT = 3  # action index = lon * 3 + lat, lat index i is k = (-1, 0, +1)[i]


class DQNAgent(OnDevice):
    name = "dqn"
    action_interface = "discrete27"
    env_overrides: dict[str, Any] = {}
    NETS = ("q", "q_target")
    OPTS = ("opt",)
    opt = LazyAdam(lambda a: a.q.parameters(), "lr")  # built on first use (an acting agent never builds it)
    numpy_greedy = True  # greedy ``act`` on the CPU runs ``inference.NumpyNets``; False: torch's forward

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Discrete, cfg: DQNConfig | None = None):
        self.cfg = cfg = cfg or DQNConfig()
        self.n = int(action_space.n)
        grid_shape, logic = observation_space["grid"].shape, observation_space["logic"]
        self.scaler = ObsScaler(logic.low, logic.high)
        with torch.random.fork_rng():
            torch.manual_seed(cfg.seed)
            self.q = Head(grid_shape, logic.shape[0], 0, (256, 64), self.n)
            self.q_target = Head(grid_shape, logic.shape[0], 0, (256, 64), self.n)
        self.q_target.load_state_dict(self.q.state_dict())
        zero_grads(self.q)
        self._nf, self._nl = trunk_dim(grid_shape), logic.shape[0]
        self._params, self._target_params = [*self.q.parameters()], [*self.q_target.parameters()]
        self._numpy = NumpyNets([self.q], grid_shape)
        self._views()
        self.rng = np.random.default_rng(cfg.seed)
        self.replay = Replay(cfg.replay_size, grid_shape, logic.shape[0], 1)
        self.epsilon = cfg.eps_init
        self.updates = 0

    def _views(self) -> None:
        """What the update derives from the parameters and the device (``OnDevice.to``)."""
        self._dense = Dense(self.q, self._nf, self._nf + self._nl)
        self._dense_target = Dense(self.q_target, self._nf, self._nf + self._nl)
        self._ws = Workspace(self.device)  # buffers of the target pass, then of the online pass (done after it)
        self._numpy.stale()

    def action_mask(self, lateral_mask: np.ndarray) -> np.ndarray:
        """The 27-action mask from the mask over k."""
        return np.tile(np.asarray(lateral_mask, dtype=bool), self.n // N_LAT)

    def begin_episode(self, episode: int) -> None:
        c = self.cfg
        self.epsilon = linear_epsilon(episode, c.eps_init, c.eps_end, c.eps_decay_episodes)

    def freeze(self) -> None:
        """Greedy acts use the weights as they are now, without checking them for edits at each act
        (``NumpyNets.freeze``), until the next update, ``load_state_dict`` or device move: for an
        agent that only acts (``bench.methods.policies.policy_agent``)."""
        self._numpy.freeze()

    def act(self, obs, info, explore: bool = False) -> int:
        mask = self.action_mask(info["action_mask"])
        if explore and self.rng.random() < self.epsilon:
            return int(self.rng.choice(np.flatnonzero(mask)))
        if not explore and self.numpy_greedy and self.device == CPU:
            return dqn_greedy(self._numpy.current(), obs["grid"], self.scaler.logic(obs["logic"]), mask)
        with torch.no_grad():
            g = self.tensor(obs["grid"], dtype=torch.float32)[None]
            l = self.tensor(self.scaler.logic(obs["logic"]))[None]
            q = host(self.q(g, l)[0])
        return int(np.argmax(np.where(mask, q, -np.inf)))

    def observe(self, obs, action, reward, next_obs, terminated, truncated, info) -> dict[str, float]:
        self.replay.add(obs["grid"], self.scaler.logic(obs["logic"]), [action], reward * self.cfg.reward_scale,
                        next_obs["grid"], self.scaler.logic(next_obs["logic"]), float(terminated),
                        np.asarray(info["action_mask"], dtype=bool))
        if self.replay.size < max(self.cfg.learning_starts, self.cfg.batch_size):
            return {}
        return self.update()

    def update(self) -> dict[str, float]:
        """One step on 0.5 MSE of Q(s, a) against r + gamma (1 - done) max_a' Q'(s', a') over the
        allowed a', then the soft target update. The gradients are computed by hand, as in
        ``PDQNAgent.update`` (tests/agents/test_update_equivalence.py holds them to autograd's)."""
        return {k: float(v) for k, v in self.step().items()}

    @torch.no_grad()
    def step(self) -> dict[str, torch.Tensor]:
        """``update``, its losses left as 0-dim tensors on the agent's device (no read-back)."""
        c = self.cfg
        loss = self._gradients(self.batch(self.replay.sample_torch(self.rng, c.batch_size)))
        clipped_adam_step(self.opt, [self._params], c.grad_clip)
        soft_update_(self._target_params, self._params, c.tau)
        self._numpy.stale()  # the fused Adam step writes the parameters without bumping their versions
        self.updates += 1
        return {"loss_q": loss}

    def _gradients(self, b: dict[str, torch.Tensor]) -> torch.Tensor:
        """The loss's gradient into ``self.q``'s ``.grad``; returns the loss (0-dim, on the agent's device)."""
        c = self.cfg
        nf, nfl = self._nf, self._nf + self._nl
        bsz = b["reward"].shape[0]
        z2 = self._ws("z", (1, bsz, nfl))
        ConvPass(b["next_grid"], [self.q_target.conv], z2, grad=False, ws=self._ws)
        z2[:, :, nf:] = b["next_logic"]
        dt = self._dense_target
        q2 = mlp_tail(dt, torch.addmm(dt.b1, z2[0], dt.w1t))[2]
        mask2 = b["next_mask"].repeat(1, self.n // N_LAT)
        q2 = q2.masked_fill(~mask2, -torch.inf).max(1).values
        y = b["reward"] + c.gamma * (1.0 - b["done"]) * q2

        z = self._ws("z", (1, bsz, nfl))
        conv = ConvPass(b["grid"], [self.q.conv], z, grad=True, ws=self._ws)
        z[:, :, nf:] = b["logic"]
        d = self._dense
        h1, h2, out = mlp_tail(d, torch.addmm(d.b1, z[0], d.w1t))
        a = b["action"][:, 0].long()[:, None]
        q = out.gather(1, a).squeeze(1)
        loss = 0.5 * F.mse_loss(q, y)
        dpre1 = mlp_tail_backward(d, h1, h2, torch.zeros_like(out).scatter_(1, a, ((q - y) / bsz)[:, None]), rows=bsz)
        dfeats = self._ws("dfeats", (1, bsz, nf))
        first_layer_backward(d, z[0], dpre1, dfeats[0])
        set_conv_grads([self.q.conv], conv.backward(dfeats))
        return loss

    def state_dict(self, with_training: bool = True) -> dict[str, Any]:
        state = {"name": self.name, "config": asdict(self.cfg), "q": self.q.state_dict()}
        if with_training:
            state.update({"q_target": self.q_target.state_dict(), "opt": self.opt.state_dict(),
                          "rng": self.rng.bit_generator.state, "epsilon": self.epsilon, "updates": self.updates})
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("name") != self.name:
            raise ValueError(f"checkpoint is for method {state.get('name')!r}, not {self.name!r}")
        self.q.load_state_dict(state["q"])
        self._numpy.stale()
        self.q_target.load_state_dict(state.get("q_target", state["q"]))
        if "opt" in state:
            load_adam_state(self.opt, state["opt"])
            self.rng.bit_generator.state = state["rng"]
            self.epsilon, self.updates = state["epsilon"], state["updates"]
