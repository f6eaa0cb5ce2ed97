"""The DP's lattice: the (position, speed) grid of one resolution, its index arithmetic, its
per-step energy table and which landings cross a stop line, plus the types a pass over it
returns (``Window``, ``Solution``). ``bench.oracle.passes`` runs value iteration over it and
``bench.oracle.dp`` chooses the lattices and the passes."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ecodrive_bench.envs.config import ScenarioConfig

from .corridor import Corridor
from .energy import energy_wh

GRID_EPS = 1e-9  # [-] slack for float rounding in grid index arithmetic
KRAUSS_TAU = 1.0  # [s] SUMO's default tau: the ego's reaction time in Krauss' safe speed
Window = tuple[int, int, int, int]  # rows lo..hi, speeds jlo..jhi evaluated at one step


@dataclass
class Solution:
    value: float  # [Wh] optimal value of the start state (float32 sums)
    policy: list[tuple[int, int, np.ndarray] | None]  # per step: first row, first speed, best choice
    states: int  # states evaluated
    values: list[np.ndarray | None] | None = None  # per step: [speed, row] values of its window (``keep``)


class Lattice:
    """Index arithmetic of one (position, speed) grid and its per-step energy table."""

    def __init__(self, cor: Corridor, cfg: ScenarioConfig, n_v: int, krauss: bool = False) -> None:
        dt = cfg.step_length
        self.nv, self.krauss = n_v, krauss
        self.dv = cfg.speed_limit / n_v  # [m/s]
        self.dx = self.dv * dt  # [m]
        self.d_min = math.ceil(cfg.a_min * dt / self.dv - GRID_EPS)  # [speed cells per step]
        self.d_max = math.floor(cfg.a_max * dt / self.dv + GRID_EPS)
        self.n_d = self.d_max - self.d_min + 1
        self.i_end = math.ceil((cor.x_end - cor.x0) / self.dx - GRID_EPS)  # first row that has arrived
        # the start speed's cell: the speed limit's on the generated arterial; on a network corridor
        # the first lane's limit, rounded down to a cell where it is not one (``on_grid`` False)
        q0 = cor.v0 / self.dv
        self.j0 = min(n_v, int(round(q0)) if abs(q0 - round(q0)) < 1e-6 else math.floor(q0))
        self.on_grid = abs(q0 - self.j0) < 1e-6
        self.over = self._limits(cor, n_v)  # [speed, row] states above a speed limit, or None
        j = np.arange(n_v + 1)
        j_next = j[:, None] + np.arange(self.d_min, self.d_max + 1)[None, :]
        ok = (j_next >= 0) & (j_next <= n_v)
        step = energy_wh(j[:, None] * self.dv, np.clip(j_next, 0, n_v) * self.dv, dt, cfg.ev)
        self.energy = np.where(ok, step, np.inf)  # [Wh] (speed, acceleration choice)
        # the step from row i to next speed j' crosses stop line m (x_i < s <= x_i + j' dx) iff
        # cross_low[m, j'] <= i <= cross_top[m]
        q = (np.asarray(cor.stop_lines, dtype=float) - cor.x0) / self.dx
        self.cross_top = (np.ceil(q - GRID_EPS) - 1).astype(np.int64)
        self.cross_low = np.ceil(q[:, None] - j[None, :] - GRID_EPS).astype(np.int64).reshape(len(q), n_v + 1)
        if krauss:  # while red, SUMO lets the ego take speed v' only if it can still stop at the line:
            # gap >= v'^2 / (2 b) + tau v' (b = -a_min); so landings at v' closer than that are forbidden too
            v = j * self.dv
            gap = v ** 2 / (2.0 * -cfg.a_min) + KRAUSS_TAU * v  # [m]
            first = np.floor(q[:, None] - gap[None, :] / self.dx + GRID_EPS).astype(np.int64) + 1
            self.cross_low = np.minimum(self.cross_low, first.reshape(len(q), n_v + 1))

    def _limits(self, cor: Corridor, n_v: int) -> np.ndarray | None:
        """[speed, row] (rows 0 .. i_end + n_v) True where the state breaks a speed limit: its speed
        is above the limit of a stretch that the step which landed it covered, (x - v dt, x]."""
        if not cor.limits:
            return None
        over = np.zeros((n_v + 1, self.i_end + n_v + 1), dtype=bool)
        for a, b, limit in cor.limits:
            lo = math.floor((a - cor.x0) / self.dx + GRID_EPS) + 1  # first row past a
            for j in range(math.floor(limit / self.dv + GRID_EPS) + 1, n_v + 1):
                hi = math.ceil((b - cor.x0) / self.dx - GRID_EPS) + j  # rows whose last step began before b
                over[j, max(lo, 0):max(min(hi, over.shape[1]), 0)] = True
        return over

    def cap(self, buf: np.ndarray, lo: int, hi: int, jlo: int, jhi: int) -> None:
        """Set the states of the window (rows lo..hi, speeds jlo..jhi) of a [speed, row] value
        buffer that break a speed limit to infinity."""
        if self.over is not None and lo <= hi and jlo <= jhi:
            sub = buf[jlo:jhi + 1, lo:hi + 1]
            sub[self.over[jlo:jhi + 1, lo:hi + 1]] = np.inf

    def arrived(self, buf: np.ndarray) -> None:
        """Fill a value buffer's arrived rows (from ``i_end``): 0, infinite where a speed limit is broken."""
        buf[:, self.i_end:] = 0.0
        if self.over is not None:
            sub = buf[:, self.i_end:]
            sub[self.over[:, self.i_end:self.i_end + sub.shape[1]]] = np.inf

    def windows(self, horizon: int, tube: tuple[np.ndarray, np.ndarray, int, int] | None = None) -> list[Window]:
        """States worth evaluating at each step: rows forward-reachable from the start (full
        speed ahead / full braking), not arrived, able to arrive by ``horizon``; within
        ``tube = (rows, speeds, half-width rows, half-width speeds)`` of a plan if given."""
        out, lo, j = [], 0, self.j0
        for k in range(horizon):
            w = [max(lo, self.i_end - (horizon - k) * self.nv), min(k * self.nv, self.i_end - 1), 0, self.nv]
            if tube is not None:
                rows, speeds, wr, wv = tube
                c = min(k, len(rows) - 1)
                r = min(int(rows[c]), self.i_end - 1)
                js = int(speeds[c])
                w = [max(w[0], r - wr), min(w[1], r + wr), max(0, js - wv), min(self.nv, js + wv)]
            out.append((w[0], w[1], w[2], w[3]))
            j = max(0, j + self.d_min)
            lo += j
        return out

    def extract(self, sol: Solution) -> tuple[np.ndarray, np.ndarray]:
        """Row and speed indices of the optimal plan, forwards from the start."""
        i, j, rows, speeds = 0, self.j0, [0], [self.j0]
        for entry in sol.policy:
            assert entry is not None, "the optimal plan left the evaluated states"
            lo, jlo, arg = entry
            j += int(arg[j - jlo, i - lo]) + self.d_min
            i += j
            rows.append(i)
            speeds.append(j)
            if i >= self.i_end:
                break
        return np.array(rows), np.array(speeds)
