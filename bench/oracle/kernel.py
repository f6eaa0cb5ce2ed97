"""The DP's inner loop, one backward step over a window of states, compiled with numba.

Why numba: the step is a triple loop (rows x speeds x acceleration choices) whose numpy form
(``backward_step_numpy`` below) builds a padded copy of the next values and one full
temporary per choice; compiled, each state reads its few successors in place and skips the
choices that leave the speed range. numba is made for such array loops, is a well-kept
dependency with wheels for every platform torch has, and keeps the kernel in Python (no build
step). The arithmetic is the numpy form's, in the same order and the same float32 precision,
with the same tie rule (the first choice that is strictly better wins), so both give the same
values and the same plans bit for bit (tests/bench/oracle/test_kernel.py). The row loop works on
slices and is branch-free (the better value and choice are selects, stored to every row), so it
vectorises on every x86-64 target: a conditional store of the one-byte choice has no AVX2 form,
and LLVM would otherwise compile it to a branch per row. ``backward_step_in``, the DP's form, also skips the landings outside the next step's
window, which the DP's buffers hold as infinite.

The first call in a process compiles (about a second). numba's on-disk cache is not used: an
installed package's folder may be read-only, and a cache written under an earlier module name
fails to load after a rename.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True)
def _relax(nxt_jn: np.ndarray, cur_j: np.ndarray, arg_j: np.ndarray, a: int, b: int, lo: int, jn: int,
           cost: np.float32, c: int) -> None:
    """States of rows ``a..b`` (one speed): a landing at speed ``jn`` improves on the best so far
    (``arg_j`` is indexed from row ``lo``; contiguous loads and stores, so the loop vectorises)."""
    n = b - a + 1
    if n <= 0:
        return
    src, dst, best = nxt_jn[a + jn:a + jn + n], cur_j[a:a + n], arg_j[a - lo:a - lo + n]  # slices: contiguous
    code = best.dtype.type(c)
    for i in range(n):  # branch-free: selects, and a store to every row
        cand = src[i] + cost
        old = dst[i]
        dst[i] = min(old, cand)  # select(cand < old, cand, old): the strictly better one
        b = best[i]
        best[i] = b + (code - b) * (cand < old)  # select(cand < old, c, b)


@njit(nogil=True)
def backward_step(nxt: np.ndarray, cur: np.ndarray, arg: np.ndarray, lo: int, hi: int, jlo: int, jhi: int,
                  d_min: int, step_cost: np.ndarray, red_low: np.ndarray, red_top: np.ndarray) -> None:
    """Fill ``cur[jlo:jhi+1, lo:hi+1]`` with the best value over the acceleration choices and
    ``arg`` ([jhi-jlo+1, hi-lo+1]) with the choice, from ``nxt``.

    ``nxt``/``cur``: [speeds, rows] float32 values of the next/this step (rows past the end hold 0):
    speed-major, so that the landings of one next speed ``jn`` from consecutive rows,
    ``nxt[jn, i + jn]``, are consecutive in memory and the row loop vectorises. A choice ``c``
    moves speed ``j`` to ``jn = j + d_min + c`` and row ``i`` to ``i + jn`` at ``step_cost[j, c]``.
    ``red_low[s, jn] <= i <= red_top[s]``: the step crosses stop line ``s`` (ascending), whose
    signal is red in this step, so those landings are forbidden. Choices are tried in ascending
    order for every state and only a strictly better one replaces the best: numpy's tie rule."""
    backward_step_in(nxt, cur, arg, lo, hi, jlo, jhi, d_min, step_cost, red_low, red_top,
                     0, nxt.shape[1] - 1, 0, nxt.shape[0] - 1, nxt.shape[1])  # every landing may be finite


@njit(nogil=True)
def _relax_span(nxt_jn: np.ndarray, cur_j: np.ndarray, arg_j: np.ndarray, a: int, b: int, lo: int, jn: int,
                cost: np.float32, c: int, red_low: np.ndarray, red_top: np.ndarray) -> None:
    """``_relax`` over rows ``a..b`` less the rows whose step crosses a red stop line."""
    start = a
    for s in range(red_top.shape[0]):
        b0, b1 = max(red_low[s, jn], a), min(red_top[s], b)
        if b0 > b1:
            continue
        _relax(nxt_jn, cur_j, arg_j, start, b0 - 1, lo, jn, cost, c)
        start = max(start, b1 + 1)
    _relax(nxt_jn, cur_j, arg_j, start, b, lo, jn, cost, c)


@njit(nogil=True)
def backward_step_in(nxt: np.ndarray, cur: np.ndarray, arg: np.ndarray, lo: int, hi: int, jlo: int, jhi: int,
                     d_min: int, step_cost: np.ndarray, red_low: np.ndarray, red_top: np.ndarray,
                     nlo: int, nhi: int, njlo: int, njhi: int, i_end: int) -> None:
    """``backward_step`` when ``nxt`` is finite only in the next step's window (rows
    ``nlo..nhi``, speeds ``njlo..njhi``; empty if ``nlo > nhi``) and on arrived rows (``>= i_end``,
    every speed), as the DP's buffers are: landings elsewhere are infinite, never strictly better,
    so they are skipped. The same values and choices as ``backward_step``, with less work where
    the windows are narrow (the local passes' tubes)."""
    nv = nxt.shape[0] - 1
    n_d = step_cost.shape[1]
    for j in range(jlo, jhi + 1):
        cur[j, lo:hi + 1] = np.inf
        arg[j - jlo, :] = 0
        arg_j = arg[j - jlo, :]
        for c in range(n_d):
            jn = j + d_min + c
            if jn < 0:
                continue
            if jn > nv:
                break
            cost = step_cost[j, c]
            arrived = max(lo, i_end - jn)  # rows from which the landing has arrived
            if njlo <= jn <= njhi and nlo <= nhi:  # landings in the next window, below the arrived ones
                a, b = max(lo, nlo - jn), min(hi, nhi - jn, arrived - 1)
                if a <= b:
                    _relax_span(nxt[jn], cur[j], arg_j, a, b, lo, jn, cost, c, red_low, red_top)
            if arrived <= hi:
                _relax_span(nxt[jn], cur[j], arg_j, arrived, hi, lo, jn, cost, c, red_low, red_top)


@njit(nogil=True)
def mask_gap(buf: np.ndarray, lo: int, hi: int, jlo: int, jhi: int, base: float, headway: float,
             speeds: np.ndarray, x0: float, dx: float, eps: float) -> None:
    """The states (rows ``lo..hi``, speeds ``jlo..jhi``) of ``buf`` [speed, row] whose front
    bumper passes the vehicle ahead's limit ``base - headway speeds[j]`` [m] become infinite: the
    rows above ``floor((limit - x0) / dx + eps)`` (``bench.oracle.mpc``'s gap constraint; the
    numpy form's arithmetic, element by element, in the same order)."""
    for j in range(jlo, jhi + 1):
        top = np.floor((base - headway * speeds[j] - x0) / dx + eps)
        for i in range(lo, hi + 1):
            if i > top:
                buf[j, i] = np.inf


@njit(nogil=True)
def mask_caps(buf: np.ndarray, lo: int, hi: int, jlo: int, jhi: int, caps: np.ndarray) -> None:
    """The states (rows ``lo..hi``, speeds ``jlo..jhi``) of ``buf`` [speed, row] above their
    speed's row cap ``caps[j]`` become infinite (moving obstacles, ``bench.oracle.clairvoyant``)."""
    for j in range(jlo, jhi + 1):
        for i in range(max(lo, caps[j] + 1), hi + 1):
            buf[j, i] = np.inf


def backward_step_numpy(nxt: np.ndarray, cur: np.ndarray, arg: np.ndarray, lo: int, hi: int, jlo: int, jhi: int,
                        d_min: int, step_cost: np.ndarray, red_low: np.ndarray, red_top: np.ndarray,
                        *next_window: int) -> None:
    """``backward_step`` in numpy, one array operation per choice: the reference the compiled
    kernel is tested against (and the DP's form before it; ``Grid(kernel="numpy")``).
    ``next_window``: ``backward_step_in``'s last five arguments, accepted so that both kernels take
    the same call, and unused: this form reads every landing."""
    nxt, cur, arg = nxt.T, cur.T, arg.T  # [rows, speeds] views
    nv, n_d = nxt.shape[1] - 1, step_cost.shape[1]
    n, m = hi - lo + 1, jhi - jlo + 1
    base = nxt[lo:]
    # after[r, j'] = value of landing at row lo + r + j' with speed j' (x' = x + v' dt)
    after = np.lib.stride_tricks.as_strided(base, shape=(n, nv + 1),
                                            strides=(base.strides[0], base.strides[0] + base.strides[1]))
    first = jlo + d_min  # next speed of padded column 0
    a, b = max(0, first), min(nv, jhi + d_min + n_d - 1)
    padded = np.full((n, m - 1 + n_d), np.inf, dtype=np.float32)
    padded[:, a - first:b - first + 1] = after[:, a:b + 1]
    for s in range(len(red_top)):  # red / yellow: no crossing in this step
        for jn in range(a, b + 1):
            r0, r1 = max(lo, red_low[s, jn]), min(hi, red_top[s])
            if r0 <= r1:
                padded[r0 - lo:r1 - lo + 1, jn - first] = np.inf
    best = np.full((n, m), np.inf, dtype=np.float32)
    arg[:] = 0
    cand = np.empty_like(best)
    better = np.empty(best.shape, dtype=bool)
    for c in range(n_d):  # next speed j + d_min + c
        np.add(padded[:, c:c + m], step_cost[jlo:jhi + 1, c], out=cand)
        np.less(cand, best, out=better)
        np.copyto(best, cand, where=better)
        np.copyto(arg, c, where=better)
    cur[lo:hi + 1, jlo:jhi + 1] = best
