"""The greedy forward pass of the acting networks for one observation, compiled with numba.

Why compiled: at batch 1 the networks are about 0.4 M multiply-adds, a few microseconds of
arithmetic, but a forward in numpy is some twenty calls, each with its dispatch, and in an
episode SUMO's step evicts both the weights and that code from the core's caches between two
acts. One compiled call per act touches only the weights and the few kilobytes of its own code.
numba is already the DP's compiler (``bench/oracle/kernel.py``), is made for such array loops
and keeps the kernel in Python (no build step).

Layout: a dense layer's weight is stored transposed, ``wt`` of shape (in, out), so the product
runs over the inputs and adds one contiguous row of weights per input (a loop numba vectorises
without reordering any sum); inputs that are exactly zero (ReLU outputs, the lane one-hot's zeros) add
nothing and are skipped. Each output is its bias plus the terms in input order, in float32:
another order than BLAS's, so results agree with torch's to float32 rounding, not bit for bit
(``tests/agents/test_inference.py``).

The kernels compile on their first call (about 4 s on one core); the machine code is cached on
disk, so later processes load it in about 0.4 s (``envs/jit.py``).
"""
from __future__ import annotations

import numpy as np

from ecodrive_bench.envs.jit import compiled


@compiled
def conv_block(grid: np.ndarray, conv1: np.ndarray, w1: np.ndarray, b1: np.ndarray, pool1: np.ndarray,
               conv2: np.ndarray, w2: np.ndarray, b2: np.ndarray, pool2: np.ndarray, pooled: np.ndarray,
               logic: np.ndarray, out: np.ndarray) -> None:
    """``out[b]`` = [conv features of block ``b``, ``logic``] for the N blocks run together.

    ``grid``: the observation's (cells, lanes) grid, flattened; ``conv1`` (9, P1) gathers its 3x3
    patches; ``w1`` (N c1, 9) and ``b1`` (N c1,) are every block's first layer; ``pool1`` (4, Q1)
    the 2x2 windows of the first max pool; ``pooled`` (N c1 Q1 + 1,) receives the pooled maps,
    its last entry the padding's zero that ``conv2`` (N, c1 9, P2) gathers from; ``w2`` (N, c2,
    c1 9), ``b2`` (N, c2); ``pool2`` (4, Q2). ReLU follows each pool (the two commute)."""
    nc1, nine = w1.shape
    p1 = conv1.shape[1]
    patches = np.empty((nine, p1), np.float32)
    for r in range(nine):
        for c in range(p1):
            patches[r, c] = grid[conv1[r, c]]
    y1 = np.empty(p1, np.float32)
    q1 = pool1.shape[1]
    for o in range(nc1):
        y1[:] = b1[o]
        for r in range(nine):
            w = w1[o, r]
            for c in range(p1):
                y1[c] += w * patches[r, c]
        for c in range(q1):
            m = max(max(y1[pool1[0, c]], y1[pool1[1, c]]), max(y1[pool1[2, c]], y1[pool1[3, c]]))
            pooled[o * q1 + c] = m if m > 0.0 else np.float32(0.0)
    n, c2, k2 = w2.shape
    p2 = conv2.shape[2]
    q2 = pool2.shape[1]
    cols = np.empty((k2, p2), np.float32)
    y2 = np.empty(p2, np.float32)
    nl = logic.shape[0]
    for b in range(n):
        for r in range(k2):
            for c in range(p2):
                cols[r, c] = pooled[conv2[b, r, c]]
        for o in range(c2):
            y2[:] = b2[b, o]
            for r in range(k2):
                w = w2[b, o, r]
                if w != 0.0:
                    for c in range(p2):
                        y2[c] += w * cols[r, c]
            for c in range(q2):
                m = max(max(y2[pool2[0, c]], y2[pool2[1, c]]), max(y2[pool2[2, c]], y2[pool2[3, c]]))
                out[b, o * q2 + c] = m if m > 0.0 else np.float32(0.0)
        for i in range(nl):
            out[b, c2 * q2 + i] = logic[i]


@compiled
def dense(z: np.ndarray, wt: np.ndarray, b: np.ndarray, relu: bool, out: np.ndarray) -> None:
    """``out`` = ``b`` + ``wt``.T ``z`` (``wt`` (in, out)), then ReLU if ``relu``; zero inputs skipped."""
    out[:] = b
    m = out.shape[0]
    for i in range(z.shape[0]):
        zi = z[i]
        if zi != 0.0:
            for j in range(m):
                out[j] += zi * wt[i, j]
    if relu:
        for j in range(m):
            if out[j] < 0.0:
                out[j] = 0.0


@compiled
def mlp(z: np.ndarray, wt1: np.ndarray, b1: np.ndarray, wt2: np.ndarray, b2: np.ndarray, wt3: np.ndarray,
        b3: np.ndarray) -> np.ndarray:
    """A head's three dense layers (ReLU between) on one input vector."""
    h1 = np.empty(b1.shape[0], np.float32)
    dense(z, wt1, b1, True, h1)
    h2 = np.empty(b2.shape[0], np.float32)
    dense(h1, wt2, b2, True, h2)
    out = np.empty(b3.shape[0], np.float32)
    dense(h2, wt3, b3, False, out)
    return out


@compiled
def masked_argmax(q: np.ndarray, mask: np.ndarray) -> int:
    """``np.argmax(np.where(mask, q, -inf))``: the first allowed maximum (a NaN wins, as in numpy)."""
    best, k = -np.inf, 0
    for i in range(q.shape[0]):
        if mask[i]:
            if q[i] != q[i]:
                return i
            if q[i] > best:
                best, k = q[i], i
    return k


@compiled
def _add_input(h: np.ndarray, xk: np.float32, row: np.ndarray) -> None:
    """``h`` += ``xk`` ``row``: one more input's term of a dense layer (none for a zero input)."""
    if xk != 0.0:
        for j in range(h.shape[0]):
            h[j] += xk * row[j]


@compiled
def _rest(h1: np.ndarray, q2: np.ndarray, qb2: np.ndarray, q3: np.ndarray, qb3: np.ndarray, h2: np.ndarray,
          out: np.ndarray) -> None:
    """ReLU of the first layer's sum ``h1`` (in place), then the second and third layers into ``out``."""
    for j in range(h1.shape[0]):
        if h1[j] < 0.0:
            h1[j] = 0.0
    dense(h1, q2, qb2, True, h2)
    dense(h2, q3, qb3, False, out)


@compiled
def pdqn(feats: np.ndarray, q1: np.ndarray, qb1: np.ndarray, q2: np.ndarray, qb2: np.ndarray, q3: np.ndarray,
         qb3: np.ndarray, p1: np.ndarray, pb1: np.ndarray, p2: np.ndarray, pb2: np.ndarray, p3: np.ndarray,
         pb3: np.ndarray, mask: np.ndarray, multipass: bool, x: np.ndarray, low: np.float32, span: np.float32,
         accel: np.ndarray) -> int:
    """P-DQN's greedy choice from ``feats`` (2, F) (the Q network's, the parameter network's):
    ``x`` receives the normalised parameters tanh(param net), ``accel`` the accelerations
    ``low + (x + 1) / 2 span`` (float32 throughout, as ``PDQNAgent._to_accel``), the result is the
    masked argmax of Q(s, k, x). Multi-pass (MP-DQN): Q_k comes from a pass whose input keeps
    only x_k, so the first layer's sum over the features is shared by the passes."""
    out = mlp(feats[1], p1, pb1, p2, pb2, p3, pb3)
    kk = x.shape[0]
    for k in range(kk):
        x[k] = np.tanh(out[k])
        accel[k] = low + (x[k] + np.float32(1.0)) * np.float32(0.5) * span
    nf = feats.shape[1]
    h1 = np.empty(qb1.shape[0], np.float32)
    dense(feats[0], q1[:nf], qb1, False, h1)
    h2 = np.empty(qb2.shape[0], np.float32)
    q = np.empty(kk, np.float32)
    if not multipass:
        for k in range(kk):
            _add_input(h1, x[k], q1[nf + k])
        _rest(h1, q2, qb2, q3, qb3, h2, q)
        return masked_argmax(q, mask)
    hk = np.empty_like(h1)
    o = np.empty(qb3.shape[0], np.float32)
    for k in range(kk):
        hk[:] = h1
        _add_input(hk, x[k], q1[nf + k])
        _rest(hk, q2, qb2, q3, qb3, h2, o)
        q[k] = o[k]
    return masked_argmax(q, mask)
