"""One pass of the DP: value iteration over a list of windows, backwards from the last step, one
``bench.oracle.kernel`` step per time step (``bench.oracle.dp`` runs the passes).

Buffers: two [speed, row] float32 arrays, this step's values and the next step's, swapped after
each step; the rows from ``i_end`` on have arrived and hold 0. The numpy reference reads every
landing, so its buffers hold infinity outside the window just written (each step resets the
window written two steps before). The compiled kernel reads only the next step's window and the
arrived rows, so its buffers need neither the infinities nor the resets: they are allocated once
per lattice in a solve (``Buffers``) and reused by its later passes, which saves filling and
first touching 8 MB per local pass (about a tenth of a solve).
"""
from __future__ import annotations

import math

import numpy as np

from .kernel import backward_step_in, backward_step_numpy
from .lattice import Lattice, Solution, Window

# the inner loop, compiled (it skips landings outside the next step's window) or the numpy reference
KERNELS = {"numba": backward_step_in, "numpy": backward_step_numpy}
WINDOWED = ("numba",)  # the kernels that read only the next step's window and the arrived rows
Buffers = dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]  # (speeds, rows): a windowed kernel's pair


def _pair(lat: Lattice, windowed: bool, buffers: Buffers | None) -> tuple[np.ndarray, np.ndarray]:
    """The two value buffers: reused from ``buffers`` for a windowed kernel, else new and infinite."""
    shape = (lat.nv + 1, lat.i_end + lat.nv + 1)  # [speed, row]: the kernel's layout
    if windowed and buffers is not None and shape in buffers:
        return buffers[shape]
    pair = []
    for _ in range(2):
        buf = np.empty(shape, dtype=np.float32) if windowed else np.full(shape, np.inf, dtype=np.float32)
        lat.arrived(buf)
        pair.append(buf)
    if windowed and buffers is not None:
        buffers[shape] = (pair[0], pair[1])
    return pair[0], pair[1]


def backward(lat: Lattice, green: np.ndarray | None, windows: list[Window], time_cost: float,
             kernel: str = "numba", keep: bool = False, buffers: Buffers | None = None) -> Solution:
    """Value iteration from step ``len(windows)`` (not arrived = infeasible) back to the start;
    ``keep``: also return every step's values (the cost-to-go table a re-planning controller
    reads, ``bench.oracle.mpc``); ``buffers``: the solve's buffers, for a windowed kernel."""
    step, windowed = KERNELS[kernel], kernel in WINDOWED
    nv, n_d, i_end = lat.nv, lat.n_d, lat.i_end
    nxt, cur = _pair(lat, windowed, buffers)
    reg_nxt: Window | None = None  # region of each buffer written by the last step stored there
    reg_cur: Window | None = None
    step_cost = np.ascontiguousarray((lat.energy + time_cost).astype(np.float32))
    arg_type = np.int8 if n_d < 127 else np.int16
    policy: list[tuple[int, int, np.ndarray] | None] = [None] * len(windows)
    values: list[np.ndarray | None] | None = [None] * len(windows) if keep else None
    no_red = (np.zeros((0, nv + 1), dtype=np.int64), np.zeros(0, dtype=np.int64))
    states = 0
    for k in range(len(windows) - 1, -1, -1):
        if reg_cur is not None and not windowed:
            cur[reg_cur[2]:reg_cur[3] + 1, reg_cur[0]:reg_cur[1] + 1] = np.inf
        reg_cur = None
        lo, hi, jlo, jhi = windows[k]
        if lo <= hi and jlo <= jhi:
            states += (hi - lo + 1) * (jhi - jlo + 1)
            red = no_red
            if green is not None and not green[k].all():  # red / yellow: no crossing in this step
                r = np.nonzero(~green[k])[0]
                red = (lat.cross_low[r], lat.cross_top[r])
            arg = np.empty((jhi - jlo + 1, hi - lo + 1), dtype=arg_type)  # [speed, row]
            step(nxt, cur, arg, lo, hi, jlo, jhi, lat.d_min, step_cost, *red,
                 *(reg_nxt if reg_nxt is not None else (1, 0, 1, 0)), i_end)  # nxt's finite window, empty at the end
            lat.cap(cur, lo, hi, jlo, jhi)
            reg_cur = (lo, hi, jlo, jhi)
            policy[k] = (lo, jlo, arg)
            if values is not None:
                values[k] = cur[jlo:jhi + 1, lo:hi + 1].copy()
        nxt, cur, reg_nxt, reg_cur = cur, nxt, reg_cur, reg_nxt
    # the start state (row 0, speed j0): a windowed kernel's buffer holds its value only if the first window does
    j0 = lat.j0
    start = reg_nxt is not None and reg_nxt[0] <= 0 <= reg_nxt[1] and reg_nxt[2] <= j0 <= reg_nxt[3]
    value = 0.0 if i_end <= 0 else float(nxt[j0, 0]) if start or not windowed else math.inf
    return Solution(value=value, policy=policy, states=states, values=values)
