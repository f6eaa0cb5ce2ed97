"""The paper's networks (section 4.2) and the observation scaling the agents share.

Conv block: Conv(8, k3) -> MaxPool(2) -> Conv(16, k3, pad 1) -> MaxPool(2, pad 1) -> flatten.
One deviation, stated: the first pool uses ``ceil_mode=True``. On the 60 x 5 grid the first conv
leaves 3 lane columns and a floor-mode 2-wide pool drops the third, so the leftmost lane would
never reach the features; ceil mode keeps it.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn


class ObsScaler:
    """Scales the raw logic vector to about [-1, 1] by the observation space's bounds."""

    def __init__(self, logic_low: np.ndarray, logic_high: np.ndarray) -> None:
        self.scale = (1.0 / np.maximum(np.abs(logic_low), np.abs(logic_high)).clip(min=1e-6)).astype(np.float32)

    def logic(self, logic: np.ndarray) -> np.ndarray:
        return logic * self.scale


class ConvBlock(nn.Module):
    """One network's conv weights. Networks that see the same grid run their blocks together in
    ``trunks`` (one grouped pass), which is what makes an update affordable on one CPU core."""

    def __init__(self) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(1, 8, 3)
        self.conv2 = nn.Conv2d(8, 16, 3, padding=1)


def trunks(grid: torch.Tensor, blocks: list[ConvBlock]) -> list[torch.Tensor]:
    """Flattened conv features of ``grid`` (B, 60, 5) for each block, in one grouped pass.

    The grid is laid out lanes-first (B, 1, 5, 60) for speed; with square 3x3 kernels and 2x2
    pools this is the paper's block on the transposed grid (a relabelling of weights).
    """
    n = len(blocks)
    x = grid.transpose(1, 2).unsqueeze(1)
    w1 = torch.cat([b.conv1.weight for b in blocks]) if n > 1 else blocks[0].conv1.weight
    b1 = torch.cat([b.conv1.bias for b in blocks]) if n > 1 else blocks[0].conv1.bias
    cl = torch.channels_last  # CPU max-pooling is ~7x faster in this layout
    x = F.max_pool2d(F.relu(F.conv2d(x, w1, b1)).contiguous(memory_format=cl), 2, ceil_mode=True)
    w2 = torch.cat([b.conv2.weight for b in blocks]) if n > 1 else blocks[0].conv2.weight
    b2 = torch.cat([b.conv2.bias for b in blocks]) if n > 1 else blocks[0].conv2.bias
    if n > 1:  # each block's conv2 sees only its own conv1 channels
        x = F.conv2d(x, w2, b2, padding=1, groups=n)
    else:
        x = F.conv2d(x, w2, b2, padding=1)
    x = F.max_pool2d(F.relu(x).contiguous(memory_format=cl), 2, padding=1)
    return [c.flatten(1) for c in x.chunk(n, dim=1)]


def trunk_dim(grid_shape: tuple[int, int]) -> int:
    with torch.no_grad():
        return trunks(torch.zeros(1, *grid_shape), [ConvBlock()])[0].shape[1]


class Head(nn.Module):
    """A network: conv block, then [features, logic (, extra inputs)] -> hidden -> outputs."""

    def __init__(self, grid_shape: tuple[int, int], logic_dim: int, extra_dim: int, hidden: tuple[int, int],
                 out_dim: int) -> None:
        super().__init__()
        self.conv = ConvBlock()
        h1, h2 = hidden
        self.mlp = nn.Sequential(
            nn.Linear(trunk_dim(grid_shape) + logic_dim + extra_dim, h1), nn.ReLU(),
            nn.Linear(h1, h2), nn.ReLU(), nn.Linear(h2, out_dim),
        )

    def from_features(self, feats: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        return self.mlp(feats if extra is None else torch.cat([feats, extra], dim=1))

    def forward(self, grid: torch.Tensor, logic: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        return self.from_features(torch.cat([trunks(grid, [self.conv])[0], logic], 1), extra)


def features(grid: torch.Tensor, logic: torch.Tensor, nets: list[Head]) -> list[torch.Tensor]:
    """[conv features, logic] of each net, computed in one grouped pass."""
    return [torch.cat([f, logic], 1) for f in trunks(grid, [n.conv for n in nets])]


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for t, s in zip(target.parameters(), source.parameters()):
            t.lerp_(s, tau)


class OUNoise:
    """Ornstein-Uhlenbeck noise (eq. 13) drawn from a seeded numpy Generator."""

    def __init__(self, dim: int, theta: float, sigma: float, rng: np.random.Generator) -> None:
        self.theta, self.sigma, self.rng = theta, sigma, rng
        self.state = np.zeros(dim)

    def reset(self) -> None:
        self.state[:] = 0.0

    def sample(self) -> np.ndarray:
        self.state += -self.theta * self.state + self.sigma * self.rng.standard_normal(self.state.shape)
        return self.state.copy()


def linear_epsilon(episode: int, eps_init: float, eps_end: float, decay_episodes: int) -> float:
    """Eq. 12: eps = (eps_init - eps_end) * max((N - n) / N, 0) + eps_end."""
    return (eps_init - eps_end) * max((decay_episodes - episode) / decay_episodes, 0.0) + eps_end


# ---------------------------------------------------------------------------------------------
# The learners' update path. An update runs its forward and backward passes by hand, as explicit
# matmuls and a few elementwise ops, without autograd: at batch 128 the networks are small enough
# that per-op overhead, the 1-channel first convolution (~20x slower in oneDNN than its FLOPs) and
# layout conversions, not arithmetic, decided an update's time. The math is the one the agents'
# autograd formulation states (tests/agents/test_update_equivalence.py holds each update against
# it); exploring acts keep ``trunks`` and ``Head.forward`` (greedy ones on the CPU run the same
# networks in numpy, agents/inference.py).
# ---------------------------------------------------------------------------------------------

def _pairs(n: int, pad: int) -> tuple[int, int]:
    """(full windows, lone last position) of a 2-wide, stride-2 max pool over ``n`` positions whose
    first window starts at ``-pad`` (0 or 1); a window that overhangs the end keeps its one position
    (ceil mode for the first pool, the padded last window for the second)."""
    return (n - pad) // 2, (n - pad) % 2


class Workspace:
    """Buffers an update reuses from one call to the next: the same memory every time, instead of
    a fresh allocation whose first touch costs more than the op that fills it."""

    def __init__(self, device: torch.device | str = "cpu") -> None:
        self.bufs: dict[str, torch.Tensor] = {}
        self.device = torch.device(device)

    def __call__(self, key: str, shape) -> torch.Tensor:
        t = self.bufs.get(key)
        if t is None or t.shape != tuple(shape):
            t = self.bufs[key] = torch.empty(shape, device=self.device)
        return t

    def typed(self, key: str, shape, dtype: torch.dtype) -> torch.Tensor:
        t = self.bufs.get(key)
        if t is None or t.shape != tuple(shape) or t.dtype != dtype:
            t = self.bufs[key] = torch.empty(shape, dtype=dtype, device=self.device)
        return t


def _empty(ws: Workspace | None, key: str, shape, like: torch.Tensor) -> torch.Tensor:
    return torch.empty(shape, device=like.device) if ws is None else ws(key, shape)


def _pool_dim(x: torch.Tensor, dim: int, pad: int, masks: list | None, ws: Workspace | None = None,
              key: str = "", out: torch.Tensor | None = None) -> torch.Tensor:
    """Max over 2-wide windows along ``dim``; with ``masks``, records 1.0 where the first of a pair
    won (also on a tie, as ``max_pool2d`` scans), else 0.0. Pooling along the cells, then along the
    lanes, picks ``max_pool2d``'s element: the first maximum of the window in row-major order."""
    n = x.shape[dim]
    p, tail = _pairs(n, pad)
    if p == 0:  # every window holds one position: nothing to pool
        if masks is not None:
            masks.append(None)
        return x if out is None else out.copy_(x)
    shape = list(x.shape)
    shape[dim] = pad + p + tail
    out = _empty(ws, "pool" + key, shape, x) if out is None else out
    pairs = x.narrow(dim, pad, 2 * p).unflatten(dim, (p, 2))
    a, b = pairs.select(dim + 1, 0), pairs.select(dim + 1, 1)
    torch.maximum(a, b, out=out.narrow(dim, pad, p))
    if masks is not None:  # float, not bool: CPU kernels on bool tensors are several times slower
        masks.append(torch.ge(a, b, out=_empty(ws, "mask" + key, a.shape, x)))
    if pad:
        out.narrow(dim, 0, 1).copy_(x.narrow(dim, 0, 1))
    if tail:
        out.narrow(dim, pad + p, 1).copy_(x.narrow(dim, n - 1, 1))
    return out


def _unpool_dim(d: torch.Tensor, mask: torch.Tensor | None, dim: int, pad: int, n: int, ws: Workspace | None = None,
                key: str = "") -> torch.Tensor:
    """The gradient of ``_pool_dim``: each window's gradient goes to the position that won it."""
    if mask is None:
        return d
    p, tail = _pairs(n, pad)
    shape = list(d.shape)
    shape[dim] = n
    dx = _empty(ws, "unpool" + key, shape, d)
    pairs = dx.narrow(dim, pad, 2 * p).unflatten(dim, (p, 2))
    dp = d.narrow(dim, pad, p)
    first = pairs.select(dim + 1, 0)
    torch.mul(dp, mask, out=first)
    torch.sub(dp, first, out=pairs.select(dim + 1, 1))  # exact: g - g = 0 and g - 0 = g
    if pad:
        dx.narrow(dim, 0, 1).copy_(d.narrow(dim, 0, 1))
    if tail:
        dx.narrow(dim, n - 1, 1).copy_(d.narrow(dim, pad + p, 1))
    return dx


class ConvPass:
    """Conv features of several blocks for one batch of grids, written into a buffer, with what
    ``backward`` needs.

    ``grid`` (B, cells, lanes), float or uint8; ``out`` (N, B, D) receives block n's features in ``out[n, :, :F]``
    (F = ``trunk_dim``) in the order ``Head`` flattens them (channel, lane, cell). The layout is
    the transposed grid of ``trunks`` in channels-last memory: conv1 (one input channel, which
    oneDNN runs far below its FLOP rate) is a matmul of the 3x3 patches (for 16 or more output
    channels; for one block, oneDNN's channels-last conv1 beats MKL's 8-column matmul), conv2 is
    oneDNN's grouped channels-last convolution (fast), and the pools (ReLU after the pool: the two
    commute) are pairwise maxima that keep their winners for the backward pass.
    """

    @torch.no_grad()
    def __init__(self, grid: torch.Tensor, blocks: list[ConvBlock], out: torch.Tensor, grad: bool,
                 ws: Workspace | None = None) -> None:
        n = len(blocks)
        bsz, cells, lanes = grid.shape
        h1, w1 = lanes - 2, cells - 2
        c1, c2 = (blocks[0].conv1.out_channels, blocks[0].conv2.out_channels)
        self.blocks, self.n, self.grad, self.ws = blocks, n, grad, ws
        self.shapes = (bsz, h1, w1, c1, c2)
        gt = (torch.empty(bsz, lanes, cells, dtype=grid.dtype, device=grid.device) if ws is None
              else ws.typed("grid", (bsz, lanes, cells), grid.dtype))
        gt.copy_(grid.transpose(1, 2))  # (B, lanes, cells), in the replay's dtype (uint8: 4x less to move)
        self.matmul1 = n * c1 >= 16  # MKL's matmul is slow below 16 output columns; oneDNN's conv is not
        if self.matmul1:
            # patches, K-major: row 3i + j holds grid[b, w + j, h + i] for every output (b, h, w);
            # row 9 holds ones, so the matmul adds the bias and its transpose sums the bias gradient
            self.cols = _empty(ws, "cols", (10, bsz * h1 * w1), grid)
            self.cols[:9].view(3, 3, bsz, h1, w1).copy_(gt.as_strided((3, 3, bsz, h1, w1),
                                                                      (cells, 1, lanes * cells, cells, 1)))
            self.cols[9].fill_(1.0)
            k1 = torch.cat([torch.cat([b.conv1.weight.view(c1, 9), b.conv1.bias[:, None]], 1) for b in blocks])
            y = torch.mm(self.cols.t(), k1.t(), out=_empty(ws, "y1", (bsz * h1 * w1, n * c1), grid))
            y = y.view(bsz, h1, w1, n * c1)
        else:  # one input channel is one memory layout: flagged channels-last, oneDNN takes its fast path
            self.x1 = _empty(ws, "x1", (bsz, lanes, cells), grid).copy_(gt).unsqueeze(1).as_strided(
                (bsz, 1, lanes, cells), (lanes * cells, 1, cells, 1))
            self.w1 = torch.cat([b.conv1.weight for b in blocks]) if n > 1 else blocks[0].conv1.weight
            b1c = torch.cat([b.conv1.bias for b in blocks]) if n > 1 else blocks[0].conv1.bias
            y = F.conv2d(self.x1, self.w1, b1c).permute(0, 2, 3, 1)
        self.masks: list | None = [] if grad else None
        self.p1 = _pool_dim(_pool_dim(y, 2, 0, self.masks, ws, "w1"), 1, 0, self.masks, ws, "h1").relu_()
        self.w2 = torch.cat([b.conv2.weight for b in blocks]) if n > 1 else blocks[0].conv2.weight
        b2c = torch.cat([b.conv2.bias for b in blocks]) if n > 1 else blocks[0].conv2.bias
        z = F.conv2d(self.p1.permute(0, 3, 1, 2), self.w2, b2c, padding=1, groups=n).permute(0, 2, 3, 1)
        self.z_hw = z.shape[1:3]
        zh, zw = self.z_hw
        h2, w2 = 1 + sum(_pairs(zh, 1)), 1 + sum(_pairs(zw, 1))
        self.f_shape = (c2, h2, w2)
        nf = c2 * h2 * w2
        # the last pool runs in the conv layout (B, h2, w2, N, c2), contiguous; one copy then puts
        # each block's features into ``out`` in (channel, lane, cell) order (a pool or ReLU written
        # straight through that strided view costs several times the copy)
        z = z.view(bsz, zh, zw, n, c2)
        p2 = _pool_dim(z, 2, 1, self.masks, ws, "w2")
        if _pairs(zh, 1)[0]:
            p2 = _pool_dim(p2, 1, 1, self.masks, ws, "h2")
        elif self.masks is not None:  # no lane pairs (the 5-lane grid): pooling along the lanes keeps every row
            self.masks.append(None)
        self.p2 = p2.relu_()  # (the convolution's own output where nothing was pooled; backward does not read it)
        out[:, :, :nf].unflatten(2, (c2, h2, w2)).permute(1, 3, 4, 0, 2).copy_(p2)

    @torch.no_grad()
    def backward(self, dfeats: torch.Tensor) -> list[list[torch.Tensor]]:
        """Gradients [conv1.weight, conv1.bias, conv2.weight, conv2.bias] of each block from the
        gradients ``dfeats`` (N, B, F) of the features."""
        bsz, h1, w1, c1, c2 = self.shapes
        n = self.n
        ch, h2, w2 = self.f_shape
        m_w1, m_h1, m_w2, m_h2 = self.masks
        ws = self.ws
        dp2 = _empty(ws, "dp2", (bsz, h2, w2, n, ch), dfeats)
        dp2.copy_(dfeats.unflatten(2, (ch, h2, w2)).permute(1, 3, 4, 0, 2))
        torch.ops.aten.threshold_backward.grad_input(dp2, self.p2, 0.0, grad_input=dp2)  # the last ReLU
        zh, zw = self.z_hw
        dz = _unpool_dim(_unpool_dim(dp2, m_h2, 1, 1, zh, ws, "h2"), m_w2, 2, 1, zw, ws, "w2").view(bsz, zh, zw, -1)
        x2 = self.p1.permute(0, 3, 1, 2)
        dx2, dw2, db2 = torch.ops.aten.convolution_backward(
            dz.permute(0, 3, 1, 2), x2, self.w2, [n * c2], [1, 1], [1, 1], [1, 1], False, [0, 0], n,
            [True, True, True])
        dp1 = torch.ops.aten.threshold_backward(dx2.permute(0, 2, 3, 1), self.p1, 0.0)
        dy = _unpool_dim(_unpool_dim(dp1, m_h1, 1, 0, h1, ws, "h1"), m_w1, 2, 0, w1, ws, "w1").view(-1, n * c1)
        if self.matmul1:
            dk1 = torch.mm(self.cols, dy).t().contiguous()  # (N c1, 10): weights, bias
            dw1, db1 = dk1[:, :9], dk1[:, 9]
        else:
            _, dw1, db1 = torch.ops.aten.convolution_backward(
                dy.view(bsz, h1, w1, n * c1).permute(0, 3, 1, 2), self.x1, self.w1, [n * c1], [1, 1], [0, 0], [1, 1],
                False, [0, 0], 1, [False, True, True])
        return [[dw1[i * c1:(i + 1) * c1].reshape(c1, 1, 3, 3), db1[i * c1:(i + 1) * c1],
                 dw2[i * c2:(i + 1) * c2], db2[i * c2:(i + 1) * c2]] for i in range(n)]


class Dense:
    """A ``Head``'s dense parameters and the views of them the update uses, made once (parameters
    are updated in place, so the views stay current). ``nf``: conv features, ``nfl``: features and
    logic; the first layer's remaining inputs are the extra ones (Q's x, the critic's action)."""

    @torch.no_grad()
    def __init__(self, net: Head, nf: int, nfl: int) -> None:
        l1, l2, l3 = net.mlp[0], net.mlp[2], net.mlp[4]
        self.w1, self.b1, self.w2, self.b2, self.w3, self.b3 = (l1.weight, l1.bias, l2.weight, l2.bias, l3.weight,
                                                                l3.bias)
        self.w1t, self.w2t, self.w3t = self.w1.t(), self.w2.t(), self.w3.t()
        self.w1t_fl, self.w1t_x = self.w1[:, :nfl].t(), self.w1[:, nfl:].t()  # features+logic, extra inputs
        self.w1_f, self.w1_x = self.w1[:, :nf], self.w1[:, nfl:]


def mlp_tail(d: Dense, pre1: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(h1, h2, out) of the dense layers after the first layer's pre-activation ``pre1`` (reused
    for h1 in place)."""
    h1 = pre1.relu_()
    h2 = torch.addmm(d.b2, h1, d.w2t).relu_()
    return h1, h2, torch.addmm(d.b3, h2, d.w3t)


def mlp_tail_backward(d: Dense, h1: torch.Tensor, h2: torch.Tensor, dout: torch.Tensor, rows: int = 0) -> torch.Tensor:
    """The gradient of the first layer's pre-activation from the output's gradient ``dout``. The
    first ``rows`` rows are a loss on this network's weights: their gradients of layers 2 and 3 go
    into the parameters' ``.grad``; the others (a loss that sees the weights as constants) only
    pass their gradient on to the input."""
    if rows:
        torch.mm(dout[:rows].t(), h2[:rows], out=d.w3.grad)
        torch.sum(dout[:rows], 0, out=d.b3.grad)
    dpre2 = torch.ops.aten.threshold_backward(torch.mm(dout, d.w3), h2, 0.0)
    if rows:
        torch.mm(dpre2[:rows].t(), h1[:rows], out=d.w2.grad)
        torch.sum(dpre2[:rows], 0, out=d.b2.grad)
    return torch.ops.aten.threshold_backward(torch.mm(dpre2, d.w2), h1, 0.0)


def first_layer_backward(d: Dense, z: torch.Tensor, dpre1: torch.Tensor, dfeats: torch.Tensor) -> None:
    """Gradients of the first layer (input ``z``) into ``.grad``, and of the conv features into
    ``dfeats``."""
    torch.mm(dpre1.t(), z, out=d.w1.grad)
    torch.sum(dpre1, 0, out=d.b1.grad)
    torch.mm(dpre1, d.w1_f, out=dfeats)


def set_conv_grads(blocks: list[ConvBlock], grads: list[list[torch.Tensor]]) -> None:
    for blk, gs in zip(blocks, grads):
        for p, g in zip((blk.conv1.weight, blk.conv1.bias, blk.conv2.weight, blk.conv2.bias), gs):
            p.grad.copy_(g)


def zero_grads(*modules: nn.Module) -> None:
    """Give every parameter a ``.grad`` that the hand-written backward passes overwrite in place."""
    for m in modules:
        for p in m.parameters():
            if p.grad is None:
                p.grad = torch.zeros_like(p)


def clip_coef(params: list[torch.Tensor], max_norm: float) -> torch.Tensor:
    """The factor ``clip_grad_norm_(params, max_norm)`` scales the gradients by (its foreach
    path's ops), as a 0-dim tensor."""
    total = torch.linalg.vector_norm(torch.stack(torch._foreach_norm([p.grad for p in params], 2.0)), 2.0)
    return torch.clamp(max_norm / (total + 1e-6), max=1.0)


def soft_update_(targets: list[torch.Tensor], sources: list[torch.Tensor], tau: float) -> None:
    """``soft_update`` over parameter lists in one call (the same lerp per element)."""
    torch._foreach_lerp_(targets, sources, tau)


def adam(params, lr: float) -> torch.optim.Adam:
    """Adam with the fused CPU kernel (one pass over each tensor instead of ~10 ops)."""
    return torch.optim.Adam(params, lr=lr, fused=True)


class LazyAdam:
    """An agent's ``adam`` optimizer, as a class attribute built on first use for each agent, over
    ``params(agent)`` at the config's learning rate ``lr`` (a field name): an agent that only acts
    (the harness's, a worker's) never builds one. The first optimizer of a process imports
    ``torch._dynamo``, about 1.2 s on these machines, which every worker of a run paid once for
    nothing. Adam starts with empty state and draws nothing, so building it later changes no number.
    The built optimizer is kept under ``_<name>``; ``built`` reads it without building."""

    def __init__(self, params: Callable[[Any], Iterable[torch.Tensor]], lr: str) -> None:
        self.params, self.lr, self.slot = params, lr, ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = f"_{name}"

    def __get__(self, agent: Any, owner: type | None = None) -> Any:
        if agent is None:
            return self
        opt = agent.__dict__.get(self.slot)
        if opt is None:
            opt = agent.__dict__[self.slot] = adam(self.params(agent), lr=getattr(agent.cfg, self.lr))
        return opt

    def __set__(self, agent: Any, opt: torch.optim.Optimizer) -> None:
        """An optimizer assigned in its place (a test's plain Adam, say) is the one used and moved."""
        agent.__dict__[self.slot] = opt

    def built(self, agent: Any) -> torch.optim.Optimizer | None:
        return agent.__dict__.get(self.slot)


def load_adam_state(opt: torch.optim.Adam, state: dict) -> None:
    """``opt.load_state_dict``, keeping the fused kernel for checkpoints written without it."""
    opt.load_state_dict(state)
    for g in opt.param_groups:
        g["fused"], g["foreach"] = True, None


def clipped_adam_step(opt: torch.optim.Optimizer, nets: list[list[torch.Tensor]], max_norm: float) -> None:
    """``clip_grad_norm_(params, max_norm)`` for each parameter list in ``nets`` (together the
    optimizer's parameters), then ``opt.step()``.

    For a fused Adam whose state exists (every step after the first) this makes the two calls of
    its step (torch.optim.adam._fused_adam) without the bookkeeping around them, and hands each
    clip factor to the fused kernel as its gradient scale (grad / (1 / factor)): no pass of its
    own over the gradients."""
    coefs = [clip_coef(ps, max_norm) for ps in nets]
    groups = opt.param_groups
    g = groups[0]
    if (type(opt) is not torch.optim.Adam or len(groups) != 1 or not g["fused"] or g["amsgrad"] or g["maximize"]
            or g["decoupled_weight_decay"] or g["differentiable"] or isinstance(g["lr"], torch.Tensor)
            or opt._optimizer_step_pre_hooks or opt._optimizer_step_post_hooks
            or len(opt.state) != len(g["params"]) or sum(map(len, nets)) != len(g["params"])):
        for ps, coef in zip(nets, coefs):
            torch._foreach_mul_([p.grad for p in ps], coef)
        opt.step()
        return
    beta1, beta2 = g["betas"]
    for ps, coef in zip(nets, coefs):
        states = [opt.state[p] for p in ps]
        steps = [s["step"] for s in states]
        torch._foreach_add_(steps, 1)
        torch._fused_adam_(ps, [p.grad for p in ps], [s["exp_avg"] for s in states], [s["exp_avg_sq"] for s in states],
                           [], steps, amsgrad=False, lr=g["lr"], beta1=beta1, beta2=beta2,
                           weight_decay=g["weight_decay"], eps=g["eps"], maximize=False,
                           grad_scale=torch.reciprocal(coef), found_inf=None)
