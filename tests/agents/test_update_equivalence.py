"""The learners' hand-written updates against the straightforward autograd formulation.

``update`` of P-DQN / MP-DQN, DQN and DDPG computes its gradients by hand (agents/nets.py: the
conv trunk as matmuls, pairwise max pools, explicit backward passes, fused Adam with the clip
factor as its gradient scale). The references below are the straightforward autograd updates
(autograd through the losses, ``clip_grad_norm_``, the default Adam, one ``lerp_`` per
tensor); P-DQN's losses are the agent's own ``losses``, DQN's and DDPG's are written out here.
From the same initial state and the same replay draws, a few updates must leave every online and
target parameter equal up to float reassociation.
No SUMO: the spaces are the env's, the replay is filled with synthetic transitions whose grids
have vehicles several cells long, so pool windows tie as they do on real grids.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from gymnasium import spaces
from torch.func import functional_call

from ecodrive_bench.agents.nets import (
    ConvBlock,
    ConvPass,
    Workspace,
    clipped_adam_step,
    features,
    soft_update,
    trunk_dim,
    trunks,
)
from ecodrive_bench.agents.registry import make_agent

K = 3
LOGIC = spaces.Box(np.array([0, 0, 0, 0, 0, 0, 0, -1, -1], np.float32),
                   np.array([1, 1, 1, 1, 1, 1080, 20.833334, 1, 90], np.float32))
ACTIONS = {"prl": spaces.Tuple((spaces.Discrete(3), spaces.Box(-4.0, 3.0, (3,), np.float32))),
           "dqn": spaces.Discrete(27), "ddpg": spaces.Box(-4.0, 3.0, (1,), np.float32)}
ACTIONS["mpdqn"] = ACTIONS["prl"]


def _grid(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    g = np.zeros(shape, np.float32)
    for lane in range(shape[1]):
        for _ in range(rng.integers(0, 5)):
            start, length = rng.integers(0, shape[0]), rng.integers(1, 4)
            g[start:start + length, lane] = 1.0
    return g


def _agent(method: str, grid_shape=(60, 5), n: int = 600, **config):
    obs = spaces.Dict({"grid": spaces.Box(0.0, 1.0, grid_shape, np.float32), "logic": LOGIC})
    agent = make_agent(method, obs, ACTIONS[method], seed=3, replay_size=1000, batch_size=64, **config)
    rng = np.random.default_rng(7)
    for _ in range(n):
        if method == "dqn":
            action = [rng.integers(0, 27)]
        elif method == "ddpg":
            action = rng.uniform(-1.2, 1.2, 1)  # a little beyond the bounds, as exploration noise puts it
        else:
            action = np.r_[rng.integers(0, 3), rng.uniform(-1, 1, 3)]
        mask = np.r_[True, rng.random(2) < 0.7][rng.permutation(3)]
        agent.replay.add(_grid(rng, grid_shape), rng.uniform(-1, 1, 9), action, rng.normal(), _grid(rng, grid_shape),
                         rng.uniform(-1, 1, 9), float(rng.random() < 0.05), mask, steps=int(rng.integers(1, 4)))
    return agent


# ---------------------------------------------------------------------------------------- references
# P-DQN's autograd formulation is the agent's own ``losses`` (eq. 7 and 8 through ``q_values``),
# which ``update`` does not call; DQN's and DDPG's are written out below.


class RefPDQN:
    def __init__(self, agent):
        self.a = a = agent
        critics = [a.q] + ([a.q2] if a.cfg.twin_q else [])
        self.opt_q = torch.optim.Adam([p for c in critics for p in c.parameters()], lr=a.cfg.lr_q)
        self.opt_param = torch.optim.Adam(a.param.parameters(), lr=a.cfg.lr_param)

    def update(self):
        a, c = self.a, self.a.cfg
        loss_q, loss_p = a.losses(a.replay.sample(a.rng, c.batch_size))
        self.opt_q.zero_grad(set_to_none=True)
        self.opt_param.zero_grad(set_to_none=True)
        (loss_q + loss_p).backward()
        torch.nn.utils.clip_grad_norm_(a.q.parameters(), c.grad_clip)
        torch.nn.utils.clip_grad_norm_(a.param.parameters(), c.grad_clip)
        if c.twin_q:
            torch.nn.utils.clip_grad_norm_(a.q2.parameters(), c.grad_clip)
        self.opt_q.step()
        self.opt_param.step()
        soft_update(a.q_target, a.q, c.tau_q)
        soft_update(a.param_target, a.param, c.tau_param)
        if c.twin_q:
            soft_update(a.q2_target, a.q2, c.tau_q)
        return {"loss_q": loss_q.item(), "loss_param": loss_p.item()}


class RefDQN:
    def __init__(self, agent):
        self.a = agent
        self.opt = torch.optim.Adam(agent.q.parameters(), lr=agent.cfg.lr)

    def update(self):
        a, c = self.a, self.a.cfg
        b = a.replay.sample(a.rng, c.batch_size)
        act = torch.as_tensor(b["action"][:, 0]).long()
        with torch.no_grad():
            (f2,) = features(torch.as_tensor(b["next_grid"], dtype=torch.float32), torch.as_tensor(b["next_logic"]),
                             [a.q_target])
            mask2 = torch.as_tensor(b["next_mask"]).repeat(1, a.n // 3)
            q2 = a.q_target.from_features(f2).masked_fill(~mask2, -torch.inf).max(1).values
            y = torch.as_tensor(b["reward"]) + c.gamma * (1.0 - torch.as_tensor(b["done"])) * q2
        (f,) = features(torch.as_tensor(b["grid"], dtype=torch.float32), torch.as_tensor(b["logic"]), [a.q])
        q = a.q.from_features(f).gather(1, act[:, None]).squeeze(1)
        loss = 0.5 * F.mse_loss(q, y)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(a.q.parameters(), c.grad_clip)
        self.opt.step()
        soft_update(a.q_target, a.q, c.tau)
        return {"loss_q": loss.item()}


class RefDDPG:
    def __init__(self, agent):
        self.a = agent
        self.opt_actor = torch.optim.Adam(agent.actor.parameters(), lr=agent.cfg.lr_actor)
        self.opt_critic = torch.optim.Adam(agent.critic.parameters(), lr=agent.cfg.lr_critic)

    def update(self):
        a, c = self.a, self.a.cfg
        b = a.replay.sample(a.rng, c.batch_size)
        g, l = torch.as_tensor(b["grid"], dtype=torch.float32), torch.as_tensor(b["logic"])
        with torch.no_grad():
            fc2, fa2 = features(torch.as_tensor(b["next_grid"], dtype=torch.float32),
                                torch.as_tensor(b["next_logic"]), [a.critic_target, a.actor_target])
            a2 = a._bounded(a.actor_target.from_features(fa2))
            y = torch.as_tensor(b["reward"]) + c.gamma * (1.0 - torch.as_tensor(b["done"])) * \
                a.critic_target.from_features(fc2, a2).squeeze(1)
        fc, fa = features(g, l, [a.critic, a.actor])
        loss_c = 0.5 * F.mse_loss(a.critic.from_features(fc, torch.as_tensor(b["action"])).squeeze(1), y)
        frozen = {n: p.detach() for n, p in a.critic.mlp.named_parameters()}
        out = a.actor.from_features(fa)
        if c.bound == "tanh":
            q = functional_call(a.critic.mlp, frozen, (torch.cat([fc.detach(), torch.tanh(out)], 1),))
            loss_a = -q.mean()
        else:
            act = out.detach().requires_grad_(True)
            q = functional_call(a.critic.mlp, frozen, (torch.cat([fc.detach(), act], 1),))
            dq = torch.autograd.grad(q.sum(), act)[0]
            x = out.detach()
            dq = torch.where(dq > 0, dq * (1.0 - x) / 2.0, dq * (x + 1.0) / 2.0)
            loss_a = -(out * dq).sum() / out.shape[0]
        self.opt_critic.zero_grad(set_to_none=True)
        self.opt_actor.zero_grad(set_to_none=True)
        (loss_c + loss_a).backward()
        torch.nn.utils.clip_grad_norm_(a.critic.parameters(), c.grad_clip)
        torch.nn.utils.clip_grad_norm_(a.actor.parameters(), c.grad_clip)
        self.opt_critic.step()
        self.opt_actor.step()
        soft_update(a.critic_target, a.critic, c.tau_critic)
        soft_update(a.actor_target, a.actor, c.tau_actor)
        return {"loss_q": loss_c.item(), "loss_param": -q.detach().mean().item()}


REFERENCE = {"prl": RefPDQN, "mpdqn": RefPDQN, "dqn": RefDQN, "ddpg": RefDDPG}
NETS = {"prl": ("q", "param", "q_target", "param_target", "q2", "q2_target"),
        "dqn": ("q", "q_target"), "ddpg": ("actor", "critic", "actor_target", "critic_target")}
NETS["mpdqn"] = NETS["prl"]

CASES = [
    ("prl", {}), ("mpdqn", {}), ("prl", {"twin_q": True}), ("prl", {"n_step": 3}),
    ("mpdqn", {"twin_q": True, "grad_clip": 0.05}),  # a clip factor below 1 on every step
    ("prl", {"grad_clip": 0.05}),
    ("dqn", {}), ("dqn", {"grad_clip": 0.05}),
    ("ddpg", {}), ("ddpg", {"bound": "tanh"}), ("ddpg", {"grad_clip": 0.05}),
]


@pytest.mark.parametrize(("method", "config"), CASES, ids=[f"{m}-{c}" for m, c in CASES])
def test_update_equals_the_autograd_reference(method, config):
    fast, slow = _agent(method, **config), _agent(method, **config)
    ref = REFERENCE[method](slow)
    for _ in range(6):
        got, want = fast.update(), ref.update()
        for key in want:
            assert got[key] == pytest.approx(want[key], rel=1e-5, abs=1e-7), key
    compared = 0
    for name in NETS[method]:
        a, b = getattr(fast, name, None), getattr(slow, name)
        if b is None:
            continue
        for (pn, p), (_, q) in zip(a.named_parameters(), b.named_parameters()):
            torch.testing.assert_close(p, q, rtol=1e-5, atol=1e-6, msg=f"{name}.{pn}")
            compared += 1
    assert compared >= 20
    assert fast.rng.bit_generator.state == slow.rng.bit_generator.state  # the same replay draws


@pytest.mark.parametrize(("grid_shape", "n_blocks"), [((60, 5), 1), ((60, 5), 2), ((61, 4), 3), ((40, 3), 2),
                                                     ((59, 6), 3), ((60, 7), 2)])
@pytest.mark.parametrize("shared", [False, True])
def test_conv_pass_is_the_trunk_with_its_gradients(grid_shape, n_blocks, shared):
    """Features of ``ConvPass`` equal ``trunks`` (the acting path); its backward equals autograd
    through ``trunks``, with the pools' winners as max_pool2d's (ties included: binary grids).
    One block takes oneDNN's first convolution, more the patch matmul. ``shared``: as in an
    update, a target pass (other blocks, other grids) runs first in the same ``Workspace``."""
    torch.manual_seed(0)
    rng = np.random.default_rng(1)
    blocks = [ConvBlock() for _ in range(n_blocks)]
    grid = torch.as_tensor(np.stack([_grid(rng, grid_shape) for _ in range(32)]))
    ref = trunks(grid, blocks)
    nf = trunk_dim(grid_shape)
    out = torch.zeros(len(blocks), 32, nf + 4)
    ws = Workspace() if shared else None
    if shared:
        other = torch.as_tensor(np.stack([_grid(rng, grid_shape) for _ in range(32)]))
        ConvPass(other.to(torch.uint8), [ConvBlock() for _ in range(n_blocks)], torch.zeros_like(out), grad=False,
                 ws=ws)
    cp = ConvPass(grid.to(torch.uint8), blocks, out, grad=True, ws=ws)
    for i, r in enumerate(ref):
        torch.testing.assert_close(out[i, :, :nf], r, rtol=1e-6, atol=1e-6)
    dfeats = torch.randn(len(blocks), 32, nf)
    params = [p for b in blocks for p in b.parameters()]
    want = torch.autograd.grad(sum((r * dfeats[i]).sum() for i, r in enumerate(ref)), params)
    got = [g for block in cp.backward(dfeats) for g in block]
    for g, w in zip(got, want):  # sums of thousands of terms: relative to each gradient's scale
        torch.testing.assert_close(g, w, rtol=1e-5, atol=1e-5 * float(w.abs().max()))


def test_fused_clipped_step_equals_clip_then_adam():
    """``clipped_adam_step``'s lean path (the clip factor as the fused kernel's gradient scale)
    against ``clip_grad_norm_`` then the optimizer's own step."""
    torch.manual_seed(0)
    nets = [[torch.nn.Parameter(torch.randn(5, 7)), torch.nn.Parameter(torch.randn(7))] for _ in range(2)]
    copies = [[torch.nn.Parameter(p.detach().clone()) for p in ps] for ps in nets]
    fast = torch.optim.Adam([p for ps in nets for p in ps], lr=1e-2, fused=True)
    slow = torch.optim.Adam([p for ps in copies for p in ps], lr=1e-2)
    for step in range(4):
        grads = [torch.randn(p.shape) * (1 + 10 * (step % 2)) for ps in nets for p in ps]
        for p, q, g in zip([p for ps in nets for p in ps], [p for ps in copies for p in ps], grads):
            p.grad, q.grad = g.clone(), g.clone()
        with torch.no_grad():
            clipped_adam_step(fast, nets, 3.0)
        for ps in copies:
            torch.nn.utils.clip_grad_norm_(ps, 3.0)
        slow.step()
        for p, q in zip([p for ps in nets for p in ps], [p for ps in copies for p in ps]):
            torch.testing.assert_close(p, q, rtol=1e-6, atol=1e-7)


def test_update_is_deterministic():
    a, b = _agent("mpdqn", twin_q=True), _agent("mpdqn", twin_q=True)
    for _ in range(3):
        assert a.update() == b.update()
    for p, q in zip(a.q.parameters(), b.q.parameters()):
        assert torch.equal(p, q)
