"""The DP's inner loop, one backward step over a window of states, compiled with numba.

Why numba: the step is a triple loop (rows x speeds x acceleration choices) whose numpy form
(``backward_step_numpy`` below) builds a padded copy of the next values and one full
temporary per choice; compiled, each state reads its few successors in place and skips the
choices that leave the speed range. numba is made for such array loops, is a well-kept
dependency with wheels for every platform torch has, and keeps the kernel in Python (no build
step). The arithmetic is the numpy form's, in the same order and the same float32 precision,
with the same tie rule (the first choice that is strictly better wins), so both give the same
values and the same plans bit for bit (tests/bench/oracle/test_kernel.py). ``backward_step_in``,
the DP's form, also skips the landings outside the next step's window, which the DP's buffers
hold as infinite.

The row loop (one speed, one choice, consecutive rows) compiles to plain vector loads, compares,
blends and stores on any x86-64 vector unit, AVX2 as well as AVX-512:

- it is branch-free: the better value is ``min`` (a select) and the choice an integer select,
  stored to every row. A conditional store of the one-byte choice has no AVX2 instruction and
  compiles to a branch per row there.
- one speed's best values so far alternate between two rows of a scratch buffer: each choice
  reads one row and writes the other (copying the rows it does not relax), then ``cur`` takes
  the last. Storing a select of a value just loaded from the same address is what LLVM turns
  into a masked store, native with AVX-512 but ``vmaskmovps`` on AVX2, microcoded on AMD Zen
  1-3 (``llvm-mca -mcpu=znver3``: 12 cycles for 8 floats) and slower than a plain store on Intel.
- indices are unsigned: numba tests a signed index for wrap-around, which keeps the loop from
  vectorising; and the helpers are inlined by numba (``inline="always"``), because every call
  between compiled functions increments and decrements each array argument's reference count
  with an atomic instruction, which took about a third of a step's time.

The first call in a process compiles (about a second). numba's on-disk cache is not used: an
installed package's folder may be read-only, and a cache written under an earlier module name
fails to load after a rename.
"""
from __future__ import annotations

import numpy as np
from numba import njit

U1 = np.uint64(1)  # unsigned loop bounds and indices


@njit(nogil=True, inline="always")
def _relax(nxt: np.ndarray, vals: np.ndarray, arg: np.ndarray, jn: np.uint64, old: np.uint64, new: np.uint64,
           jj: np.uint64, a: np.uint64, b: np.uint64, lo: np.uint64, cost: np.float32, code: int) -> None:
    """Rows ``a..b`` of one speed (``jj``: its row of ``arg``), one choice landing at speed ``jn``:
    ``vals[new] = min(vals[old], landing + cost)`` row by row, and the choice becomes ``code``
    where the landing is strictly better (``vals``, ``arg`` indexed from row ``lo``)."""
    for i in range(a, b + U1):  # unsigned indices: no wrap-around test, so the loop vectorises
        cand = nxt[jn, i + jn] + cost
        k = i - lo
        o = vals[old, k]
        vals[new, k] = min(o, cand)  # select(cand < o, cand, o): the strictly better one
        x = arg[jj, k]
        arg[jj, k] = x + (code - x) * (cand < o)  # select(cand < o, code, x)


@njit(nogil=True, inline="always")
def _copy(vals: np.ndarray, old: np.uint64, new: np.uint64, a: np.uint64, b: np.uint64) -> None:
    """``vals[new, a:b] = vals[old, a:b]``."""
    for k in range(a, b):
        vals[new, k] = vals[old, k]


@njit(nogil=True, inline="always")
def _advance(nxt: np.ndarray, vals: np.ndarray, arg: np.ndarray, jn: int, p: int, jj: int, pos: int, a: int, b: int,
             lo: int, cost: np.float32, c: int) -> int:
    """Rows ``pos..a-1`` copied from ``vals[p]`` to ``vals[1 - p]``, rows ``a..b`` relaxed by the
    landing at speed ``jn``; the next row to fill."""
    a = max(a, pos)
    if a > b:
        return pos
    old, new = np.uint64(p), np.uint64(1 - p)
    _copy(vals, old, new, np.uint64(pos - lo), np.uint64(a - lo))
    _relax(nxt, vals, arg, np.uint64(jn), old, new, np.uint64(jj), np.uint64(a), np.uint64(b), np.uint64(lo), cost,
           arg.dtype.type(c))
    return b + 1


@njit(nogil=True, inline="always")
def _relax_span(nxt: np.ndarray, vals: np.ndarray, arg: np.ndarray, jn: int, p: int, jj: int, pos: int, a: int, b: int,
                lo: int, cost: np.float32, c: int, red_low: np.ndarray, red_top: np.ndarray) -> int:
    """``_advance`` over rows ``a..b`` less the rows whose step crosses a red stop line (copied)."""
    start = a
    for s in range(red_top.shape[0]):
        b0, b1 = max(red_low[s, jn], a), min(red_top[s], b)
        if b0 > b1:
            continue
        pos = _advance(nxt, vals, arg, jn, p, jj, pos, start, b0 - 1, lo, cost, c)
        start = max(start, b1 + 1)
    return _advance(nxt, vals, arg, jn, p, jj, pos, start, b, lo, cost, c)


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
    if lo > hi:
        return
    n = hi - lo + 1
    vals = np.empty((2, n), dtype=cur.dtype)  # one speed's best values so far (row p) and the next (1 - p)
    for j in range(jlo, jhi + 1):
        jj = j - jlo
        vals[0, :] = np.inf
        arg[jj, :] = 0
        p = 0
        for c in range(n_d):
            jn = j + d_min + c
            if jn < 0:
                continue
            if jn > nv:
                break
            cost = step_cost[j, c]
            arrived = max(lo, i_end - jn)  # rows from which the landing has arrived
            a, b = lo, lo - 1
            if njlo <= jn <= njhi and nlo <= nhi:  # landings in the next window, below the arrived ones
                a, b = max(lo, nlo - jn), min(hi, nhi - jn, arrived - 1)
            if a > b and arrived > hi:
                continue
            pos = lo
            if a <= b:
                pos = _relax_span(nxt, vals, arg, jn, p, jj, pos, a, b, lo, cost, c, red_low, red_top)
            if arrived <= hi:
                pos = _relax_span(nxt, vals, arg, jn, p, jj, pos, arrived, hi, lo, cost, c, red_low, red_top)
            _copy(vals, np.uint64(p), np.uint64(1 - p), np.uint64(pos - lo), np.uint64(n))
            p = 1 - p
        cur[j, lo:hi + 1] = vals[p]


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
