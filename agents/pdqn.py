"""PRL: P-DQN over the parameterized action space (section 4, Algorithm 1, Table 2).

Action: (k index in {0,1,2} for k = -1/0/+1, accelerations for every k). The parameter network
x(s; w) outputs the three accelerations, the Q network Q(s, k, x; theta) scores each k. Losses:
eq. 7 (MSE Bellman error against the target networks) and eq. 8 (-sum_k Q(s, k, x_k(s))).
Exploration: eps-greedy over k with the linear schedule of eq. 12, OU noise on the parameters
(eq. 13). The LC2013 mask applies to the greedy argmax, to random choices and, stored with the
next state, to the target max. ``multipass=True`` gives MP-DQN (Bester et al. 2019): Q_k is
evaluated with only x_k non-zero, so the other parameters cannot leak into it.
"""
from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces
from torch.func import functional_call

from .configs import PDQN_NAMES, PDQNConfig  # its config lives in agents.configs, read without torch
from .device import CPU, OnDevice, host
from .inference import NumpyNets, pdqn_greedy
from .nets import (
    ConvPass,
    Dense,
    Head,
    LazyAdam,
    ObsScaler,
    OUNoise,
    Workspace,
    clipped_adam_step,
    features,
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
from .replay import NStepWindow, Replay

K = 3  # lateral choices: k = -1, 0, +1


class PDQNAgent(OnDevice):
    """PRL (``multipass=False``) or MP-DQN (``multipass=True``)."""

    action_interface = "parameterized"
    env_overrides: dict[str, Any] = {}
    NETS = ("q", "param", "q_target", "param_target", "q2", "q2_target")
    OPTS = ("opt_q", "opt_param")
    # built on first use (an acting agent never builds them); the critics' in the order [q, q2]
    opt_q = LazyAdam(lambda a: [p for c in (a.q, a.q2) if c is not None for p in c.parameters()], "lr_q")
    opt_param = LazyAdam(lambda a: a.param.parameters(), "lr_param")
    numpy_greedy = True  # greedy ``act`` on the CPU runs ``inference.NumpyNets``; False: torch's forward

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Tuple, cfg: PDQNConfig | None = None):
        self.cfg = cfg = cfg or PDQNConfig()
        self.name = PDQN_NAMES[cfg.multipass]
        grid_shape = observation_space["grid"].shape
        logic = observation_space["logic"]
        box = action_space[1]
        self.a_low, self.a_high = float(box.low[0]), float(box.high[0])
        self.scaler = ObsScaler(logic.low, logic.high)
        with torch.random.fork_rng():
            torch.manual_seed(cfg.seed)
            self.q = Head(grid_shape, logic.shape[0], K, (256, 64), K)
            self.param = Head(grid_shape, logic.shape[0], 0, (128, 64), K)
            self.q_target = Head(grid_shape, logic.shape[0], K, (256, 64), K)
            self.param_target = Head(grid_shape, logic.shape[0], 0, (128, 64), K)
            # created last, so the other networks start as they do without it
            self.q2 = Head(grid_shape, logic.shape[0], K, (256, 64), K) if cfg.twin_q else None
            self.q2_target = Head(grid_shape, logic.shape[0], K, (256, 64), K) if cfg.twin_q else None
        self.q_target.load_state_dict(self.q.state_dict())
        self.param_target.load_state_dict(self.param.state_dict())
        critics = [self.q] + ([self.q2] if cfg.twin_q else [])
        if cfg.twin_q:
            self.q2_target.load_state_dict(self.q2.state_dict())
        zero_grads(*critics, self.param)
        self._nf, self._nl = trunk_dim(grid_shape), logic.shape[0]
        self._numpy = NumpyNets([self.q, self.param], grid_shape)
        self._views()
        pairs = [(self.q_target, self.q), (self.param_target, self.param)] + (
            [(self.q2_target, self.q2)] if cfg.twin_q else [])
        self._soft = [([*t.parameters()], [*s.parameters()], tau) for (t, s), tau in zip(
            pairs, (cfg.tau_q, cfg.tau_param, cfg.tau_q))]
        self._q_lists = [[*n.parameters()] for n in critics]
        self._p_lists = [[*self.param.parameters()]]
        self.rng = np.random.default_rng(cfg.seed)
        self.noise = OUNoise(K, cfg.ou_theta, cfg.ou_sigma, self.rng)
        self.replay = Replay(cfg.replay_size, grid_shape, logic.shape[0], 1 + K)
        self.window = NStepWindow(cfg.n_step, cfg.gamma)
        self.epsilon = cfg.eps_init
        self.updates = 0

    def _views(self) -> None:
        """What the update derives from the parameters and the device (``OnDevice.to``)."""
        self._eye = torch.eye(K, device=self.device)
        self._ws = Workspace(self.device)  # buffers of the target pass, then of the online pass (done after it)
        nfl = self._nf + self._nl
        self._dense = {name: Dense(getattr(self, name), self._nf, nfl) for name in self.NETS
                       if getattr(self, name) is not None}
        self._numpy.stale()

    # ------------------------------------------------------------------ acting
    def _tensors(self, obs) -> tuple[torch.Tensor, torch.Tensor]:
        return (self.tensor(obs["grid"], dtype=torch.float32)[None],
                self.tensor(self.scaler.logic(obs["logic"]))[None])

    def _params(self, net: Head, feats: torch.Tensor) -> torch.Tensor:
        return torch.tanh(net.from_features(feats))  # normalised accelerations in [-1, 1]

    def q_values(self, net: Head, feats: torch.Tensor, x: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """Q(s, k, x) for every k, shape (B, K); multi-pass when configured. ``frozen`` runs the
        MLP with detached weights, so a loss through it trains only what produced ``x``."""
        def mlp(inp: torch.Tensor) -> torch.Tensor:
            if not frozen:
                return net.mlp(inp)
            return functional_call(net.mlp, {n: p.detach() for n, p in net.mlp.named_parameters()}, (inp,))

        if not self.cfg.multipass:
            return mlp(torch.cat([feats, x], 1))
        b = feats.shape[0]
        eye = torch.eye(K, dtype=x.dtype, device=x.device)
        xs = (x[None] * eye[:, None, :]).reshape(K * b, K)  # pass k keeps only x_k
        out = mlp(torch.cat([feats.repeat(K, 1), xs], 1)).reshape(K, b, K)
        return out[torch.arange(K), :, torch.arange(K)].T  # Q_k from pass k

    def _to_accel(self, x: np.ndarray) -> np.ndarray:
        return (self.a_low + (x + 1.0) * 0.5 * (self.a_high - self.a_low)).astype(np.float32)

    def begin_episode(self, episode: int) -> None:
        c = self.cfg
        self.epsilon = linear_epsilon(episode, c.eps_init, c.eps_end, c.eps_decay_episodes)
        self.noise.reset()
        self.window.reset()  # an n-step transition never spans two episodes

    def freeze(self) -> None:
        """Greedy acts use the weights as they are now, without checking them for edits at each act
        (``NumpyNets.freeze``), until the next update, ``load_state_dict`` or device move: for an
        agent that only acts (``bench.methods.policies.policy_agent``)."""
        self._numpy.freeze()

    def act(self, obs, info, explore: bool = False):
        mask = np.asarray(info["action_mask"], dtype=bool)
        if not explore and self.numpy_greedy and self.device == CPU:
            k, xn, accel = pdqn_greedy(self._numpy.current(), obs["grid"], self.scaler.logic(obs["logic"]), mask,
                                       self.cfg.multipass, (self.a_low, self.a_high))  # accel: _to_accel(xn)
            self._last = (k, xn)
            return k, accel
        with torch.no_grad():
            g, l = self._tensors(obs)
            fq, fp = features(g, l, [self.q, self.param])
            x = self._params(self.param, fp)
            if explore:
                x = (x + self.tensor(self.noise.sample(), dtype=torch.float32)).clamp(-1.0, 1.0)
            if explore and self.rng.random() < self.epsilon:
                k = int(self.rng.choice(np.flatnonzero(mask)))
            else:
                q = host(self.q_values(self.q, fq, x)[0])
                k = int(np.argmax(np.where(mask, q, -np.inf)))
        xn = host(x[0])
        self._last = (k, xn)
        return k, self._to_accel(xn)

    def heads(self, grids: np.ndarray, logics: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q_k, acceleration x_k [m/s^2]) of every head k, each (B, 3), for raw observations."""
        with torch.no_grad():
            g = self.tensor(grids, dtype=torch.float32)
            l = self.tensor(logics * self.scaler.scale)
            fq, fp = features(g, l, [self.q, self.param])
            x = self._params(self.param, fp)
            q = host(self.q_values(self.q, fq, x))
        return q, self._to_accel(host(x))

    def act_batch(self, grids: np.ndarray, logics: np.ndarray, masks: np.ndarray) -> list:
        """Greedy actions for many vehicles in one forward pass (mixed traffic)."""
        q, accel = self.heads(grids, logics)
        k = np.argmax(np.where(np.asarray(masks, dtype=bool), q, -np.inf), axis=1)
        return [(int(ki), a) for ki, a in zip(k, accel)]

    # ------------------------------------------------------------------ learning
    def observe(self, obs, action, reward, next_obs, terminated, truncated, info) -> dict[str, float]:
        k, xn = self._last
        # the env builds fresh arrays every step, so the window may hold them without copying
        step = (obs["grid"], self.scaler.logic(obs["logic"]), np.concatenate([[k], xn]),
                reward * self.cfg.reward_scale, next_obs["grid"], self.scaler.logic(next_obs["logic"]),
                float(terminated), np.asarray(info["action_mask"], dtype=bool))
        for t in self.window.push(step, terminated or truncated):
            self.replay.add(*t)
        if self.replay.size < max(self.cfg.learning_starts, self.cfg.batch_size):
            return {}
        return self.update()

    @torch.no_grad()
    def target(self, b: dict[str, np.ndarray]) -> torch.Tensor:
        """Bellman target y = r + gamma^m (1 - done) max_k Q'(s', k, x'(s')) over the allowed k
        (m = 1 unless ``n_step``, where r sums m discounted rewards and s' is m steps on);
        with ``twin_q``, Q' is the smaller of the two target critics for each k."""
        c = self.cfg
        g2, l2 = torch.as_tensor(b["next_grid"], dtype=torch.float32), torch.as_tensor(b["next_logic"])
        f2 = features(g2, l2, [self.q_target, self.param_target] + ([self.q2_target] if c.twin_q else []))
        x2 = self._params(self.param_target, f2[1])
        q2 = self.q_values(self.q_target, f2[0], x2)
        if c.twin_q:
            q2 = torch.minimum(q2, self.q_values(self.q2_target, f2[2], x2))
        q2 = q2.masked_fill(~torch.as_tensor(b["next_mask"]), -torch.inf)
        # the paper's 1-step target keeps its scalar discount (the shipped policies' runs stay bit-identical)
        discount = c.gamma if c.n_step == 1 else c.gamma ** torch.as_tensor(b["steps"])
        return torch.as_tensor(b["reward"]) + discount * (1.0 - torch.as_tensor(b["done"])) * q2.max(1).values

    def losses(self, b: dict[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
        """(eq. 7 Q loss, eq. 8 parameter loss) on a sampled batch. The parameter loss runs Q's
        layers with detached weights, so each loss has gradients only for its own network."""
        c = self.cfg
        g, l = torch.as_tensor(b["grid"], dtype=torch.float32), torch.as_tensor(b["logic"])
        act = torch.as_tensor(b["action"])
        k, x_b = act[:, 0].long(), act[:, 1:]
        twin = c.twin_q
        y = self.target(b)
        f = features(g, l, [self.q, self.param] + ([self.q2] if twin else []))
        feats, fp = f[0], f[1]
        q_sa = self.q_values(self.q, feats, x_b).gather(1, k[:, None]).squeeze(1)
        loss_q = 0.5 * F.mse_loss(q_sa, y)
        if twin:
            loss_q = loss_q + 0.5 * F.mse_loss(self.q_values(self.q2, f[2], x_b).gather(1, k[:, None]).squeeze(1), y)
        loss_p = -self.q_values(self.q, feats.detach(), self._params(self.param, fp), frozen=True).sum(1).mean()
        return loss_q, loss_p

    def update(self) -> dict[str, float]:
        """One gradient step on ``losses`` (eq. 7 and eq. 8), then the soft target updates.

        The gradients are computed by hand (``_gradients``), not by autograd through ``losses``:
        the same math, in fewer and larger ops (tests/agents/test_update_equivalence.py)."""
        return {k: float(v) for k, v in self.step().items()}

    @torch.no_grad()
    def step(self) -> dict[str, torch.Tensor]:
        """``update``, its losses left as 0-dim tensors on the agent's device (no read-back)."""
        c = self.cfg
        loss_q, loss_p = self._gradients(self.batch(self.replay.sample_torch(self.rng, c.batch_size)))
        clipped_adam_step(self.opt_q, self._q_lists, c.grad_clip)
        clipped_adam_step(self.opt_param, self._p_lists, c.grad_clip)
        for targets, sources, tau in self._soft:
            soft_update_(targets, sources, tau)
        self._numpy.stale()  # the fused Adam step writes the parameters without bumping their versions
        self.updates += 1
        return {"loss_q": loss_q, "loss_param": loss_p}

    def _q_every_k(self, d: Dense, z: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """``q_values`` (B, K) for the Q network ``d`` on inputs ``z`` = [features, logic, room for
        x] (B, nf + nl + K) at parameters ``x``. Multi-pass: the first layer's part without x is
        computed once; pass k adds x_k times x_k's weight column."""
        nfl = self._nf + self._nl
        if not self.cfg.multipass:
            z[:, nfl:] = x
            return mlp_tail(d, torch.addmm(d.b1, z, d.w1t))[2]
        b = z.shape[0]
        h = torch.addmm(d.b1, z[:, :nfl], d.w1t_fl)
        pre = h.new_empty(K, *h.shape)
        torch.addcmul(h, x.t()[:, :, None], d.w1t_x[:, None, :], out=pre)
        return mlp_tail(d, pre.view(K * b, -1))[2].view(K, b, K).diagonal(dim1=0, dim2=2)

    def _critic(self, d: Dense, z: torch.Tensor, k: torch.Tensor, onehot: torch.Tensor, x_q: torch.Tensor,
                y: torch.Tensor, dfeats: torch.Tensor, x: torch.Tensor | None = None):
        """Eq. 7 for the critic ``d`` (inputs ``z``, taken k and parameters ``x_q``, target ``y``):
        its gradients into ``.grad`` and its features' into ``dfeats``. With ``x`` (the parameter
        network's output), eq. 8 too, in the same pass of the critic's layers (rows B: after eq. 7's
        :B; multi-pass K B of them), through the layers as constants: its gradient goes to x only.
        Returns (eq. 7 loss, eq. 8 loss or None, d eq. 8 / dx or None)."""
        nfl, bsz, mp = self._nf + self._nl, k.shape[0], self.cfg.multipass
        z[:, nfl:] = x_q
        h = torch.addmm(d.b1, z[:, :nfl], d.w1t_fl)  # the first layer's part without x: shared
        rows = bsz if x is None else bsz + (K * bsz if mp else bsz)
        pre = self._ws(f"pre{rows}", (rows, h.shape[1]))
        torch.addmm(h, x_q, d.w1t_x, out=pre[:bsz])
        if x is not None and mp:  # pass k adds x_k times x_k's weight column
            torch.addcmul(h, x.t()[:, :, None], d.w1t_x[:, None, :], out=pre[bsz:].view(K, bsz, -1))
        elif x is not None:
            torch.addmm(h, x, d.w1t_x, out=pre[bsz:])
        h1, h2, out = mlp_tail(d, pre)
        q_sa = out[:bsz].gather(1, k[:, None]).squeeze(1)
        loss_q = 0.5 * F.mse_loss(q_sa, y)
        dout = self._ws(f"dout{rows}", (rows, K))
        torch.mul(onehot, ((q_sa - y) / bsz)[:, None], out=dout[:bsz])
        loss_p = None
        if x is not None:  # -sum_k Q(s, k, x(s)), batch mean
            qx = out[bsz:].view(K, bsz, K).diagonal(dim1=0, dim2=2) if mp else out[bsz:]
            loss_p = -qx.sum(1).mean()
            if mp:
                dout[bsz:].zero_()
                dout[bsz:].view(K, bsz, K).diagonal(dim1=0, dim2=2).fill_(-1.0 / bsz)
            else:
                dout[bsz:].fill_(-1.0 / bsz)
        dpre1 = mlp_tail_backward(d, h1, h2, dout, rows=bsz)
        first_layer_backward(d, z, dpre1[:bsz], dfeats)
        if x is None:
            return loss_q, None, None
        if mp:
            return loss_q, loss_p, torch.bmm(dpre1[bsz:].view(K, bsz, -1), d.w1t_x[:, :, None]).view(K, bsz).t()
        return loss_q, loss_p, torch.mm(dpre1[bsz:], d.w1_x)

    def _gradients(self, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The gradients of ``losses`` into the online networks' ``.grad``; returns the losses
        (0-dim tensors on the agent's device)."""
        c = self.cfg
        nf, nl, twin, mp = self._nf, self._nl, c.twin_q, c.multipass
        nfl = nf + nl
        bsz = b["reward"].shape[0]
        nets = [self.q, self.param] + ([self.q2] if twin else [])
        dn = self._dense
        qd = [dn["q"]] + ([dn["q2"]] if twin else [])
        pd = dn["param"]

        # target (as ``target``)
        z2 = self._ws("z", (len(nets), bsz, nfl + K))
        ConvPass(b["next_grid"], [n.conv for n in (self.q_target, self.param_target, self.q2_target)[:len(nets)]],
                 z2, grad=False, ws=self._ws)
        z2[:, :, nf:nfl] = b["next_logic"]
        pt = dn["param_target"]
        x2 = torch.tanh(mlp_tail(pt, torch.addmm(pt.b1, z2[1, :, :nfl], pt.w1t))[2])
        q2 = self._q_every_k(dn["q_target"], z2[0], x2)
        if twin:
            q2 = torch.minimum(q2, self._q_every_k(dn["q2_target"], z2[2], x2))
        q2 = q2.masked_fill(~b["next_mask"], -torch.inf)
        discount = c.gamma if c.n_step == 1 else c.gamma ** b["steps"]
        y = b["reward"] + discount * (1.0 - b["done"]) * q2.max(1).values

        # online features
        z = self._ws("z", (len(nets), bsz, nfl + K))
        conv = ConvPass(b["grid"], [n.conv for n in nets], z, grad=True, ws=self._ws)
        z[:, :, nf:nfl] = b["logic"]
        dfeats = self._ws("dfeats", (len(nets), bsz, nf))
        k, x_b = b["action"][:, 0].long(), b["action"][:, 1:]
        onehot = self._eye[k]
        x_q = x_b * onehot if mp else x_b  # multi-pass: Q_k sees only x_k

        # eq. 8's parameters x(s; w); their gradient from the first critic's pass below
        hp1, hp2, out_p = mlp_tail(pd, torch.addmm(pd.b1, z[1, :, :nfl], pd.w1t))
        x = torch.tanh(out_p)

        # eq. 7 for each critic; eq. 8 in the same pass of the first critic's layers
        loss_q, loss_p, dx = self._critic(qd[0], z[0], k, onehot, x_q, y, dfeats[0], x)
        if twin:
            loss_q = loss_q + self._critic(qd[1], z[2], k, onehot, x_q, y, dfeats[2])[0]
        dpre1 = mlp_tail_backward(pd, hp1, hp2, torch.ops.aten.tanh_backward(dx, x), rows=bsz)
        first_layer_backward(pd, z[1, :, :nfl], dpre1, dfeats[1])

        set_conv_grads([n.conv for n in nets], conv.backward(dfeats))
        return loss_q, loss_p

    # ------------------------------------------------------------------ state
    def state_dict(self, with_training: bool = True) -> dict[str, Any]:
        state = {"name": self.name, "config": asdict(self.cfg), "q": self.q.state_dict(),
                 "param": self.param.state_dict()}
        if with_training:
            state.update({
                "q_target": self.q_target.state_dict(), "param_target": self.param_target.state_dict(),
                "opt_q": self.opt_q.state_dict(), "opt_param": self.opt_param.state_dict(),
                "rng": self.rng.bit_generator.state, "ou": torch.from_numpy(self.noise.state.copy()),
                "epsilon": self.epsilon, "updates": self.updates,
            })
            if self.cfg.twin_q:  # acting needs only q and param
                state.update({"q2": self.q2.state_dict(), "q2_target": self.q2_target.state_dict()})
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("name") != self.name:
            raise ValueError(f"checkpoint is for method {state.get('name')!r}, not {self.name!r}")
        self.q.load_state_dict(state["q"])
        self.param.load_state_dict(state["param"])
        self._numpy.stale()
        if "q_target" in state:
            self.q_target.load_state_dict(state["q_target"])
            self.param_target.load_state_dict(state["param_target"])
            if self.cfg.twin_q != ("q2" in state):
                raise ValueError(f"checkpoint {'has' if 'q2' in state else 'lacks'} a second Q network; "
                                 f"this agent has twin_q={self.cfg.twin_q}")
            if self.cfg.twin_q:
                self.q2.load_state_dict(state["q2"])
                self.q2_target.load_state_dict(state["q2_target"])
            load_adam_state(self.opt_q, state["opt_q"])
            load_adam_state(self.opt_param, state["opt_param"])
            self.rng.bit_generator.state = state["rng"]
            self.noise.state[:] = np.asarray(state["ou"])
            self.epsilon, self.updates = state["epsilon"], state["updates"]
        else:
            self.q_target.load_state_dict(state["q"])
            self.param_target.load_state_dict(state["param"])
