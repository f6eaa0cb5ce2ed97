"""The DP's inner loop, one backward step over a window of states, compiled with numba.

Why numba: the step is a triple loop (rows x speeds x acceleration choices) whose numpy form
(``backward_step_numpy`` below) builds a padded copy of the next values and one full
temporary per choice; compiled, each state reads its few successors in place and skips the
choices that leave the speed range. numba is made for such array loops, is a well-kept
dependency with wheels for every platform torch has, and keeps the kernel in Python (no build
step). The arithmetic is the numpy form's, in the same order and the same float32 precision,
with the same tie rule (the first choice that is strictly better wins), so both give the same
values and the same plans bit for bit (tests/bench/oracle/test_kernel.py). ``backward_step_in``,
the DP's form, also takes the landings outside the next step's window as infinite and never reads
them, so the DP's buffers need not hold them (``bench.oracle.passes``).

How the step is laid out, so that it compiles to plain vector code on any x86-64 vector unit,
AVX2 as well as AVX-512 (tests/bench/oracle/test_kernel.py builds it for AVX2 and looks for
masked stores):

- ``_landings`` gathers, once per step, each next speed's landing values into rows aligned with
  the states' rows (``src[jn, k]``: the landing from row ``lo + k``), infinite where the step
  skips the landing (outside the next window and not arrived, or across a red stop line). Every
  choice then reads a plain row range, and an infinite landing never replaces the best.
- ``_relax4`` relaxes four choices, in ascending order, in one pass over one speed's rows: the
  best value and choice so far are loaded and stored once per pass and carried in registers
  through the four. It is branch-free (``min`` and selects), and the choice is kept as an int32
  beside the float32 value so that its select is the same 32-bit blend (narrowing the compare to
  one byte per row took a third of an AVX2 loop's instructions).
- Whole vectors: a pass starts and ends on a multiple of ``ALIGN`` rows (the landings beyond a
  group's rows, and the scratch rows past the window, are infinite), so the loop runs no scalar
  remainder, which took about a tenth of a step.
- No masked stores: LLVM turns a store of a select of the value just loaded from the same address
  into a masked store, native with AVX-512 but ``vmaskmovps`` with AVX2, microcoded on AMD Zen 1-3
  (``llvm-mca -mcpu=znver3``: 12 cycles for 8 floats). The value stored here is the last of four
  selects, which it leaves as a blend and a plain store.
- Unsigned indices: numba tests a signed index for wrap-around, which keeps a loop from
  vectorising. And the helpers are inlined by numba (``inline="always"``): each call between
  compiled functions increments and decrements every array argument's reference count with an
  atomic instruction, which took about a third of a step's time.

The first call in a process compiles (about a second). numba's on-disk cache is not used: an
installed package's folder may be read-only, and a cache written under an earlier module name
fails to load after a rename.
"""
from __future__ import annotations

import numpy as np
from numba import njit

U1 = np.uint64(1)  # unsigned loop bounds and indices
GROUP = 4  # choices relaxed in one pass over the rows (``_relax4``)
ALIGN = 16  # [rows] the passes start and end on multiples of this (at least the widest vector): no scalar remainder


@njit(nogil=True, inline="always")
def _copy_row(nxt: np.ndarray, src: np.ndarray, jn: int, q: int, a: int, b: int, lo: int) -> None:
    """``src[q, a - lo:b - lo + 1] = nxt[jn, a + jn:b + jn + 1]`` (unsigned indices)."""
    if a > b:
        return
    ujn, uq, ulo = np.uint64(jn), np.uint64(q), np.uint64(lo)
    for i in range(np.uint64(a), np.uint64(b) + U1):
        src[uq, i - ulo] = nxt[ujn, i + ujn]


@njit(nogil=True, inline="always")
def _landings(nxt: np.ndarray, src: np.ndarray, first: np.ndarray, last: np.ndarray, lo: int, hi: int, jn0: int,
              nlo: int, nhi: int, njlo: int, njhi: int, i_end: int, red_low: np.ndarray, red_top: np.ndarray) -> None:
    """``src[q, k]``: the value of landing at speed ``jn0 + q`` from row ``lo + k``, infinite where
    ``backward_step_in`` skips it (outside the next window and not arrived, or across a red stop
    line); ``first[q]..last[q]``: the rows ``k`` that may be finite (empty: ``first > last``).
    The last row of ``src`` is infinite: the landing of no choice."""
    n, m = hi - lo + 1, src.shape[0] - 1
    for q in range(m + 1):
        jn = jn0 + q
        arrived = max(lo, i_end - jn)  # rows from which the landing has arrived
        a, b = lo, lo - 1
        if q < m and njlo <= jn <= njhi and nlo <= nhi:  # landings in the next window, below the arrived ones
            a, b = max(lo, nlo - jn), min(hi, nhi - jn, arrived - 1)
        f = a - lo if a <= b else n
        t = b - lo if a <= b else -1
        if q < m and arrived <= hi:
            f, t = min(f, arrived - lo), hi - lo
        first[q], last[q] = f, t
        if f > t and q < m:
            continue  # never read
        src[q, :] = np.inf
        if q == m:
            continue
        _copy_row(nxt, src, jn, q, a, b, lo)
        _copy_row(nxt, src, jn, q, arrived, hi, lo)
        for s in range(red_top.shape[0]):
            for i in range(max(red_low[s, jn], lo), min(red_top[s], hi) + 1):
                src[q, i - lo] = np.inf


@njit(nogil=True, inline="always")
def _relax4(src: np.ndarray, vals: np.ndarray, args: np.ndarray, rows: np.ndarray, costs: np.ndarray,
            codes: np.ndarray, a: np.uint64, b: np.uint64) -> None:
    """Rows ``a..b-1`` of one speed, four choices in order (landings ``src[rows[g]]`` at
    ``costs[g]``): each that is strictly better than the best so far (``vals``) replaces it and
    its code (``codes[g]``) the choice (``args``). Branch-free: ``min`` and selects."""
    r0, r1, r2, r3 = rows[0], rows[1], rows[2], rows[3]
    w0, w1, w2, w3 = costs[0], costs[1], costs[2], costs[3]
    c0, c1, c2, c3 = codes[0], codes[1], codes[2], codes[3]
    for k in range(a, b):  # unsigned: no wrap-around test on the indices, so the loop vectorises
        o = vals[k]
        x = args[k]
        v = src[r0, k] + w0
        x = c0 if v < o else x
        o = min(o, v)  # select(v < o, v, o)
        v = src[r1, k] + w1
        x = c1 if v < o else x
        o = min(o, v)
        v = src[r2, k] + w2
        x = c2 if v < o else x
        o = min(o, v)
        v = src[r3, k] + w3
        x = c3 if v < o else x
        vals[k] = min(o, v)
        args[k] = x


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
    """``backward_step`` where ``nxt`` is finite only in the next step's window (rows
    ``nlo..nhi``, speeds ``njlo..njhi``; empty if ``nlo > nhi``) and on arrived rows (``>= i_end``,
    every speed): the landings elsewhere are taken as infinite, never strictly better, and not
    read, so ``nxt`` may hold anything there (the DP's and mpc's buffers keep earlier steps'
    values). The same values and choices as ``backward_step`` on such an ``nxt``, with less work
    where the windows are narrow (the local passes' tubes)."""
    nv = nxt.shape[0] - 1
    n_d = step_cost.shape[1]
    if lo > hi or jlo > jhi:
        return
    n = hi - lo + 1
    n_pad = -(-n // ALIGN) * ALIGN  # rows n.. of the scratch: infinite landings, never read back
    jn0 = max(0, jlo + d_min)  # the next speeds reached
    m = max(0, min(nv, jhi + d_min + n_d - 1) - jn0 + 1)  # their count
    src = np.empty((m + 1, n_pad), dtype=nxt.dtype)
    first, last = np.empty(m + 1, dtype=np.int64), np.empty(m + 1, dtype=np.int64)
    _landings(nxt, src, first, last, lo, hi, jn0, nlo, nhi, njlo, njhi, i_end, red_low, red_top)
    vals = np.empty(n_pad, dtype=cur.dtype)  # one speed's best values so far
    args = np.empty(n_pad, dtype=np.int32)  # and choices
    chosen = np.empty(n_d, dtype=np.int64)
    ulo = np.uint64(lo)
    rows = np.empty(GROUP, dtype=np.uint64)
    costs = np.empty(GROUP, dtype=step_cost.dtype)
    codes = np.empty(GROUP, dtype=np.int32)
    for j in range(jlo, jhi + 1):
        vals[:] = np.inf
        args[:] = 0
        count = 0  # the choices with a landing that may be finite, ascending
        for c in range(n_d):
            q = j + d_min + c - jn0
            if 0 <= q < m and first[q] <= last[q]:
                chosen[count] = c
                count += 1
        for g0 in range(0, count, GROUP):
            a, b = n, -1
            for g in range(GROUP):
                rows[g], costs[g], codes[g] = m, 0.0, 0  # no choice: the infinite row
                if g0 + g < count:
                    c = chosen[g0 + g]
                    q = j + d_min + c - jn0
                    rows[g], costs[g], codes[g] = q, step_cost[j, c], c
                    a, b = min(a, first[q]), max(b, last[q])
            a, b = a // ALIGN * ALIGN, min(n_pad, -(-(b + 1) // ALIGN) * ALIGN)  # the landings outside a..b are infinite
            _relax4(src, vals, args, rows, costs, codes, np.uint64(a), np.uint64(b))
        uj, ujj = np.uint64(j), np.uint64(j - jlo)
        for k in range(np.uint64(n)):
            cur[uj, k + ulo] = vals[k]
            arg[ujj, k] = args[k]


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
