"""Greedy acting without torch: the acting networks' forward pass for one observation, on numpy
copies of their weights, compiled (``agents/kernels.py``).

At batch 1 the networks are a few hundred thousand multiply-adds; torch spends several times that
in per-op dispatch, module calls and oneDNN's setup of two tiny convolutions. Here an act is two or
three compiled calls: the conv blocks of every net (gathered patches with precomputed indices, 2x2
max pools over gathered windows), then the dense layers and the choice.

The arithmetic is float32, as torch's, but not in torch's order, so outputs agree to float32
rounding, not bit for bit (tests/agents/test_inference.py). Exploration and the learners' updates
keep the torch path.

The copy follows the torch weights: before each forward ``NumpyNets.current`` compares the
parameters' version counters (bumped by in-place ops: ``load_state_dict``, ``copy_`` or ``add_``
under ``no_grad``) with those it copied, and copies again when any moved. Two writes leave the
counters as they were: the fused Adam kernel (``torch._fused_adam_``, the learners' optimizer
step) and writes through ``.data``; so each agent's ``step`` (every update), ``load_state_dict``
and device move (``_views``) also mark the copy stale (``NumpyNets.stale``).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from . import kernels
from .nets import Head, _pairs


def _pool_windows(n: int, pad: int) -> list[tuple[int, int]]:
    """(first, second) position of each 2-wide window of a stride-2 max pool over ``n`` positions
    whose first window starts at ``-pad``; a window that keeps one position names it twice (the
    same windows as ``nets._pool_dim``, i.e. ``max_pool2d``'s with ceil mode or padding 1)."""
    pairs, tail = _pairs(n, pad)
    out = [(0, 0)] if pad else []
    out += [(pad + 2 * i, pad + 2 * i + 1) for i in range(pairs)]
    if tail:
        out.append((n - 1, n - 1))
    return out


def _pool_index(h: int, w: int, pad: int) -> tuple[np.ndarray, tuple[int, int]]:
    """(index (4, H' W') into a flattened (h, w) map of each pooled position's 2x2 window,
    (H', W'))."""
    rows, cols = _pool_windows(h, pad), _pool_windows(w, pad)
    idx = np.array([[r[a] * w + c[b] for r in rows for c in cols] for a in (0, 1) for b in (0, 1)], dtype=np.intp)
    return idx, (len(rows), len(cols))


class ConvPlan:
    """Gather indices of the conv block on a (cells, lanes) grid: the layout of ``nets.trunks``
    (the transposed grid: lanes are the rows, cells the columns), for ``n`` blocks of ``c1``
    first-layer channels."""

    def __init__(self, grid_shape: tuple[int, int], n: int, c1: int) -> None:
        cells, lanes = grid_shape
        h1, w1 = lanes - 2, cells - 2
        # conv1 patches (9, h1 w1): row 3i + j holds grid[w + j, h + i] for output (h, w)
        self.conv1 = np.array([[(w + j) * lanes + (h + i) for h in range(h1) for w in range(w1)]
                               for i in range(3) for j in range(3)], dtype=np.intp)
        self.pool1, (hp, wp) = _pool_index(h1, w1, 0)
        # conv2 patches (N, c1 9, hp wp) into the pooled maps, flattened, with one zero appended for
        # the padding: row 9 c + 3 i + j of block b holds map (b, c) at (h + i - 1, w + j - 1)
        size, zero = hp * wp, n * c1 * hp * wp
        y = np.arange(3)[:, None, None, None] + np.arange(hp)[None, None, :, None] - 1  # (i, 1, h, 1)
        x = np.arange(3)[None, :, None, None] + np.arange(wp)[None, None, None, :] - 1  # (1, j, 1, w)
        inside = (0 <= y) & (y < hp) & (0 <= x) & (x < wp)
        maps = np.arange(n * c1).reshape(n, c1, 1, 1, 1, 1) * size
        idx = np.where(inside, maps + y * wp + x, zero)  # (n, c1, 3, 3, hp, wp)
        self.conv2 = idx.reshape(n, c1 * 9, size).astype(np.intp)
        self.pooled = zero  # pooled first-layer values, before the appended zero
        self.pool2, self.out_hw = _pool_index(hp, wp, 1)


class NumpyNets:
    """Float32 numpy copies of some ``Head``s' weights and their forward pass for one observation.

    ``features`` runs the nets' conv blocks together (as ``nets.features`` does); ``mlp`` runs one
    net's dense layers on a vector or on rows."""

    def __init__(self, nets: Sequence[Head], grid_shape: tuple[int, int]) -> None:
        self.nets = list(nets)
        self.params = [p for net in self.nets for p in net.parameters()]
        c1 = self.nets[0].conv.conv1.out_channels
        self.plan = ConvPlan(grid_shape, len(self.nets), c1)
        self.buf = np.zeros(self.plan.pooled + 1, dtype=np.float32)  # pooled maps, then the padding's zero
        self.nf = self.nets[0].conv.conv2.out_channels * self.plan.pool2.shape[1]  # conv features per net
        self.grid_shape = tuple(grid_shape)
        self.logic_dim = min(net.mlp[0].in_features for net in self.nets) - self.nf  # the net without extra inputs
        self.versions: list[int] | None = None
        self.frozen = False

    def current(self) -> NumpyNets:
        """Self, its copy of the weights made current (copied again when any parameter changed;
        not checked while ``frozen``)."""
        if self.frozen:
            return self
        versions = [p._version for p in self.params]
        if versions != self.versions:
            self._copy()
            self.versions = versions
        return self

    def stale(self) -> None:
        """Copy the weights again before the next forward (for writes the version counters miss);
        ends ``freeze``."""
        self.versions = None
        self.frozen = False

    def freeze(self) -> None:
        """Copy the weights now and act on that copy without comparing the parameters' versions at
        each forward (some twenty tensor attributes read with the caches cold, about 10 us an act in
        an episode), until ``stale``: for an agent that only acts, as the harness's."""
        self.stale()
        self.current()
        self.frozen = True

    def _copy(self) -> None:
        def a(t: torch.Tensor) -> np.ndarray:
            return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32).copy()

        convs = [net.conv for net in self.nets]
        self.w1 = a(torch.cat([c.conv1.weight.flatten(1) for c in convs]))  # (N c1, 9)
        self.b1 = a(torch.cat([c.conv1.bias for c in convs]))  # (N c1,)
        self.w2 = np.stack([a(c.conv2.weight.flatten(1)) for c in convs])  # (N, c2, c1 9)
        self.b2 = np.stack([a(c.conv2.bias) for c in convs])  # (N, c2)
        # the kernels' arguments: each head's dense layers as wt1, b1, wt2, b2, wt3, b3 (wt (in, out): transposed)
        self.weights = [tuple(x for lin in (net.mlp[0], net.mlp[2], net.mlp[4])
                              for x in (np.ascontiguousarray(a(lin.weight).T), a(lin.bias))) for net in self.nets]

    def block(self, grid: np.ndarray, logic: np.ndarray) -> np.ndarray:
        """(N, features) rows: [conv features, logic] of each net for one grid (cells, lanes) and
        scaled logic vector."""
        p = self.plan
        logic = np.asarray(logic, dtype=np.float32)
        if np.shape(grid) != self.grid_shape or logic.shape != (self.logic_dim,):  # the kernels index unchecked
            raise ValueError(f"observation of grid shape {np.shape(grid)} and logic shape {logic.shape}; the networks "
                             f"take a grid of shape {self.grid_shape} and a logic vector of shape ({self.logic_dim},)")
        out = np.empty((len(self.nets), self.nf + logic.shape[0]), dtype=np.float32)
        kernels.conv_block(np.ascontiguousarray(grid, dtype=np.float32).ravel(), p.conv1, self.w1, self.b1, p.pool1,
                           p.conv2, self.w2, self.b2, p.pool2, self.buf, logic, out)
        return out

    def features(self, grid: np.ndarray, logic: np.ndarray) -> list[np.ndarray]:
        """[conv features, logic] of each net for one grid (cells, lanes) and scaled logic vector."""
        return list(self.block(grid, logic))

    def mlp(self, i: int, z: np.ndarray) -> np.ndarray:
        """Net ``i``'s dense layers on ``z``: one input vector, or rows of inputs (R, in)."""
        w = self.weights[i]
        z = np.asarray(z, dtype=np.float32)
        if z.ndim not in (1, 2) or z.shape[-1] != w[0].shape[0]:
            raise ValueError(f"input of shape {z.shape}; net {i} takes vectors of {w[0].shape[0]}")
        if z.ndim == 1:
            return kernels.mlp(np.ascontiguousarray(z), *w)
        return np.stack([kernels.mlp(np.ascontiguousarray(row), *w) for row in z])


def pdqn_greedy(nets: NumpyNets, grid: np.ndarray, logic: np.ndarray, mask: np.ndarray, multipass: bool,
                bounds: tuple[float, float] = (-1.0, 1.0)) -> tuple[int, np.ndarray, np.ndarray]:
    """(k, normalised parameters x, accelerations) of ``PDQNAgent``'s greedy choice; ``nets`` are
    [Q, parameter network], ``logic`` is scaled; the accelerations map x in [-1, 1] onto
    ``bounds`` (low, high), in float32 as ``PDQNAgent._to_accel``. Multi-pass: Q_k from the pass
    whose input keeps only x_k."""
    feats = nets.block(grid, logic)
    x = np.empty(nets.weights[1][-1].shape[0], dtype=np.float32)
    accel = np.empty_like(x)
    low, high = bounds  # numpy's float32 arithmetic on x casts low and the span (a Python float) to float32
    k = kernels.pdqn(feats, *nets.weights[0], *nets.weights[1], _mask(mask, x.shape[0]), multipass, x,
                     np.float32(low), np.float32(high - low), accel)
    return k, x, accel


def _mask(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` as n booleans (a ValueError otherwise: the kernels index it unchecked)."""
    out = np.asarray(mask, dtype=np.bool_)
    if out.shape != (n,):
        raise ValueError(f"action mask of shape {out.shape}; the network chooses among {n} actions")
    return out


def dqn_greedy(nets: NumpyNets, grid: np.ndarray, logic: np.ndarray, mask: np.ndarray) -> int:
    """``DQNAgent``'s greedy action index over the allowed actions ``mask``; ``logic`` is scaled."""
    q = kernels.mlp(nets.block(grid, logic)[0], *nets.weights[0])
    return kernels.masked_argmax(q, _mask(mask, q.shape[0]))


def ddpg_greedy(nets: NumpyNets, grid: np.ndarray, logic: np.ndarray, bound: str) -> np.ndarray:
    """``DDPGAgent``'s normalised acceleration in [-1, 1], shape (1,); ``logic`` is scaled."""
    out = kernels.mlp(nets.block(grid, logic)[0], *nets.weights[0])
    return np.tanh(out) if bound == "tanh" else np.clip(out, -1.0, 1.0)


def compile_kernels() -> None:
    """Compile every greedy kernel in this process (or load it from numba's disk cache), on small
    nets of the same array types as the agents': a parent calls it before it starts workers, so
    they load the cache instead of all compiling it at once."""
    grid_shape = (12, 6)
    logic = np.zeros(9, dtype=np.float32)
    grid = np.ones(grid_shape, dtype=np.float32)
    q, param = Head(grid_shape, 9, 3, (8, 8), 3), Head(grid_shape, 9, 0, (8, 8), 3)
    pair = NumpyNets([q, param], grid_shape).current()
    for multipass in (False, True):
        pdqn_greedy(pair, grid, logic, np.ones(3, dtype=np.int8), multipass, (-4.0, 3.0))
    one = NumpyNets([param], grid_shape).current()
    dqn_greedy(one, grid, logic, np.ones(3, dtype=np.int8))
    ddpg_greedy(one, grid, logic, "tanh")
