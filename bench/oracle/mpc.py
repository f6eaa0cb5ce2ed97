"""Re-planning on the DP: a cost-to-go table, and a leader-aware re-plan onto it.

The signal plans are fixed, so the least cost-to-go ``V(t, x, v)`` of the ``"cost"`` objective
(E + phi T, the ego alone) does not change during an episode, on the global lattice of
``bench.oracle.dp`` (``Grid.n_v`` speed cells). Where every junction runs one cycle it is
periodic in t: ``periodic`` solves one cycle of it for every state of the corridor, once per
process, and every departure reads it at its phase. Otherwise ``start`` solves one departure's
table over its forward-reachable band, ``SLACK`` steps past the bound's certified horizon, so that
a delayed ego still finds its cost-to-go there.

``replan`` is then a small problem: from the ego's state at step ``k``, a backward DP over the
next ``LOOKAHEAD`` steps on the states reachable from it, onto the table's values at step
``k + LOOKAHEAD``, with the vehicle ahead as a constraint; then the table's own choices to the end
of the corridor. The look-ahead uses the same compiled kernel and the same float32 arithmetic as
the table, so with no leader it reproduces the table's values and choices exactly: a re-plan from
a state on a table plan returns the rest of that plan (tests/bench/oracle/test_mpc.py).

Prediction model of the vehicle ahead: constant speed over the look-ahead, ``x_l(t + m dt) =
x_l(t) + v_l m dt`` (its rear bumper). Constraint at every look-ahead step: the ego's front bumper
stays ``MIN_GAP + HEADWAY v`` behind it (SUMO's default minGap and Krauss' tau), so the plan keeps
the gap SUMO's own car-following model keeps. Where no plan keeps it (a vehicle cut in closer),
the re-plan drops the constraint and leaves the vehicle to the safety layer (``Replan.leader``
says which). Beyond the look-ahead the plan is the free-flow optimum.

Snapping: the ego's speed is rounded to the nearest speed cell, its position rounded *up* to the
next row, so the planned position is never behind the real one by less than zero and never more
than one row: a plan that stops before a red stop line or keeps a gap keeps it in SUMO too.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ecodrive_bench.envs.config import ScenarioConfig

from .dp import MS, Corridor, Grid, Plan, _Run, refine, solve
from .kernel import backward_step, backward_step_in, mask_caps, mask_gap
from .lattice import GRID_EPS, Lattice, Window

VERSION = 1  # [-] of the first plans and re-plans: bumped with any change that moves one (the shipped first plans' key)
LOOKAHEAD = 10  # [steps] the leader-constrained part of a re-plan
SLACK = 150  # [steps] the table reaches this far past the bound's certified horizon
MIN_GAP = 2.5  # [m] SUMO's default minGap: bumper-to-bumper gap kept at standstill
HEADWAY = 1.0  # [s] SUMO's default tau (Krauss): time gap kept at speed
LEADER_ACCEL = 1.5  # [m/s^2] the vehicle ahead's predicted acceleration, up to the speed limit
MAX_CYCLES = 40  # [-] value iteration of a periodic table stops here if it has not converged
MAX_STEPS = 7200  # [steps] a plan read from a periodic table ends here at the latest


@dataclass(frozen=True)
class Leader:
    """The vehicle ahead in the ego's lane, as the ego sees it now."""

    gap: float  # [m] from the ego's front bumper to its rear bumper
    speed: float  # [m/s] estimated


@dataclass
class Table:
    """The cost-to-go of one departure on the global lattice: ``values[at(k)]`` and
    ``choices[at(k)]`` cover the window ``windows[at(k)]`` of step ``k`` after the departure (rows
    ``lo..hi``, speeds ``jlo..jhi``). A periodic table (``period`` steps, every junction on one
    cycle) holds one cycle of the infinite-horizon cost-to-go and serves every departure: step
    ``k`` is its phase ``(offset + k) mod period``."""

    cor: Corridor
    cfg: ScenarioConfig
    depart_time: float  # [s]
    lat: Lattice
    windows: list[Window]
    values: list[np.ndarray | None]  # [speed, row] float32 [Wh]
    choices: list[np.ndarray | None]  # [speed, row] acceleration choice index
    green: np.ndarray  # (steps, stop lines) bool: the arterial is green in the step from step k
    step_cost: np.ndarray  # [speed, choice] float32 [Wh]: energy + phi dt
    wall_s: float  # [s] to build, with the first plan
    period: int = 0  # [steps] of a periodic table, 0 for one departure's
    cycles: int = 0  # [-] value-iteration cycles a periodic table took to repeat
    offset: int = 0  # [steps] phase of the departure in a periodic table
    scratch: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)  # ``_solve``'s buffers

    def at(self, k: int) -> int:
        """Index of step ``k`` after the departure in the table's lists."""
        return (self.offset + k) % self.period if self.period else k

    @property
    def horizon(self) -> int:
        return MAX_STEPS if self.period else len(self.windows)


@dataclass
class Replan:
    """A plan from step ``k``: ``x``, ``v`` have one entry per step from ``k`` to the arrival."""

    k: int  # [steps] after the departure
    x: np.ndarray  # [m] front bumper on the lattice
    v: np.ndarray  # [m/s]
    value: float  # [Wh] its cost-to-go (float32 sums)
    leader: str  # "none" (no vehicle ahead), "kept" (the gap constraint holds) or "relaxed"
    wall_s: float  # [s]
    states: int = 0  # [-] states the look-ahead evaluated (the rest is read from the table)


def start(cor: Corridor, cfg: ScenarioConfig, depart_time: float, grid: Grid | None = None,
          first_plan: Plan | None = None) -> tuple[Plan, Table]:
    """The first plan of a departure and its cost-to-go table. Where every junction runs one
    cycle, the table is the process's periodic one (``periodic``, solved once per corridor and
    config) and the plan its optimum from the insertion state, on the global lattice, refined on
    the fine lattice; ``first_plan``, that plan as solved before (the one ``start`` returned for
    the same corridor, config, departure and grid: the shipped bounds keep it for the fixed
    cases), is taken instead of solving it again. Otherwise one global pass, ``SLACK`` steps past
    the certified horizon, gives both (``first_plan`` is not used). Krauss' red cap is obeyed in
    both."""
    started = time.perf_counter()
    tab = periodic(cor, cfg, grid)
    dt_ms = int(round(cfg.step_length * MS))
    depart_ms = int(round(depart_time * MS))
    if tab is not None and depart_ms % dt_ms == 0:
        view = replace(tab, offset=(depart_ms // dt_ms) % tab.period, depart_time=depart_time)
        if first_plan is not None:
            view.wall_s = time.perf_counter() - started
            return first_plan, view
        first = _solve(view, 0, 0, Lattice(cor, cfg, view.lat.nv).j0, 0, None, 0.0, 0.0, 0.0)  # the global-lattice optimum
        if first is not None:
            run = _Run(cor, cfg, depart_time, cfg.reward.phi, "numba")
            plan = refine(run, view.lat, first[0], first[1], MAX_STEPS, grid or Grid(), True, "cost", started)
            view.wall_s = time.perf_counter() - started
            return plan, view
    plan = solve(cor, cfg, depart_time, "cost", grid=grid, krauss=True, slack=SLACK)
    assert plan.table is not None
    lat, sol, horizon = plan.table
    plan.table = None  # the plan's other holders (logs, agents) need not keep 200 MB alive
    windows = lat.windows(horizon)
    dt = cfg.step_length
    steps = len(windows) + LOOKAHEAD
    green = (cor.green(depart_time + np.arange(steps) * dt, dt) if cor.stop_lines
             else np.ones((steps, 0), dtype=bool))
    cost = np.ascontiguousarray((lat.energy + cfg.reward.phi * dt).astype(np.float32))
    tab = Table(cor=cor, cfg=cfg, depart_time=depart_time, lat=lat, windows=windows, values=sol.values,
                choices=[p[2] if p is not None else None for p in sol.policy], green=green, step_cost=cost,
                wall_s=time.perf_counter() - started)
    return plan, tab


def shippable_first(cor: Corridor, cfg: ScenarioConfig, depart_time: float, grid: Grid | None = None) -> Plan | None:
    """``start``'s first plan where the periodic table serves the departure (the plan
    ``first_plan`` may stand for), else None."""
    plan, tab = start(cor, cfg, depart_time, grid)
    return plan if tab.period else None


_PERIODIC: dict[tuple[Corridor, ScenarioConfig, Grid], Table | None] = {}  # per process


def periodic(cor: Corridor, cfg: ScenarioConfig, grid: Grid | None = None) -> Table | None:
    """The infinite-horizon cost-to-go over one signal cycle, on the global lattice with Krauss'
    red cap, for every state of the corridor; None where the junctions' cycles differ or the step
    does not divide the cycle. Value iteration runs backwards cycle by cycle until the values of
    a whole cycle repeat bit for bit (or ``MAX_CYCLES``): from then on no later arrival is cheaper.
    Cached per process (some 60 MB per corridor and config)."""
    grid = grid or Grid()
    cor = replace(cor, v0=cfg.speed_limit)  # one table serves every start speed (``start`` picks its row)
    key = (cor, cfg, grid)
    if key in _PERIODIC:
        return _PERIODIC[key]
    dt_ms = int(round(cfg.step_length * MS))
    cycles = set(cor.cycles_ms)
    if len(cycles) != 1 or next(iter(cycles)) % dt_ms:
        _PERIODIC[key] = None
        return None
    started = time.perf_counter()
    period = next(iter(cycles)) // dt_ms
    lat = Lattice(cor, cfg, grid.n_v, krauss=True)
    nv, i_end, dt = lat.nv, lat.i_end, cfg.step_length
    green = (cor.green(np.arange(period) * dt, dt) if cor.stop_lines else np.ones((period, 0), dtype=bool))
    cost = np.ascontiguousarray((lat.energy + cfg.reward.phi * dt).astype(np.float32))
    no_red = (np.zeros((0, nv + 1), dtype=np.int64), np.zeros(0, dtype=np.int64))
    nxt = np.full((nv + 1, i_end + nv + 1), np.inf, dtype=np.float32)
    lat.arrived(nxt)
    cur = nxt.copy()
    values: list[np.ndarray | None] = [None] * period
    choices: list[np.ndarray | None] = [None] * period
    last, cycles = None, 0
    while cycles < MAX_CYCLES:
        cycles += 1
        for p in range(period - 1, -1, -1):
            red = no_red
            if not green[p].all():
                r = np.nonzero(~green[p])[0]
                red = (lat.cross_low[r], lat.cross_top[r])
            arg = np.empty((nv + 1, i_end), dtype=np.int8 if lat.n_d < 127 else np.int16)
            backward_step(nxt, cur, arg, 0, i_end - 1, 0, nv, lat.d_min, cost, *red)
            lat.cap(cur, 0, i_end - 1, 0, nv)
            values[p], choices[p] = cur[:, :i_end].copy(), arg
            nxt, cur = cur, nxt
        if last is not None and np.array_equal(values[0], last):
            break
        last = values[0]
    tab = Table(cor=cor, cfg=cfg, depart_time=0.0, lat=lat, windows=[(0, i_end - 1, 0, nv)] * period,
                values=values, choices=choices, green=green, step_cost=cost, wall_s=time.perf_counter() - started,
                period=period, cycles=cycles)
    _PERIODIC[key] = tab
    return tab


def _buffers(tab: Table) -> tuple[np.ndarray, np.ndarray]:
    """Two [speed, row] value buffers for ``_solve``, kept with the table and reused: rows from
    ``i_end`` on (arrived) hold 0 and are never written."""
    if tab.scratch is None:
        lat = tab.lat
        buf = np.full((lat.nv + 1, lat.i_end + lat.nv + 1), np.inf, dtype=np.float32)
        lat.arrived(buf)
        tab.scratch = (buf, buf.copy())
    return tab.scratch


def _leader_speeds(speed: float, m: int, cfg: ScenarioConfig, accel: float | None) -> np.ndarray:
    """[m/s] the vehicle ahead's predicted speed after each of the next ``m`` steps."""
    a = LEADER_ACCEL if accel is None else accel
    return np.minimum(speed + a * cfg.step_length * np.arange(1, m + 1), cfg.speed_limit)


def leader_travel(speed: float, m: int, cfg: ScenarioConfig, accel: float | None = None) -> float:
    """[m] the vehicle ahead covers in ``m`` steps by the prediction model: from ``speed`` [m/s]
    at ``accel`` (``LEADER_ACCEL``) up to the speed limit, SUMO's Euler update ``x' = x + v' dt``."""
    return float(_leader_speeds(speed, m, cfg, accel).sum() * cfg.step_length)


def _travels(speed: float, steps: int, cfg: ScenarioConfig, accel: float) -> list[float]:
    """``leader_travel(speed, m, cfg, accel)`` for m = 0..``steps`` (0 for m = 0): the speeds once,
    each sum over its prefix (the same numbers, summed as ``leader_travel`` sums them)."""
    v = _leader_speeds(speed, steps, cfg, accel)
    return [0.0] + [float(v[:m].sum() * cfg.step_length) for m in range(1, steps + 1)]


def snap(tab: Table, x: float, v: float) -> tuple[int, int]:
    """(row, speed cell) of a real state: position rounded up, speed to the nearest cell, and
    down to the first cell within the speed limits there (a network corridor's)."""
    lat = tab.lat
    i = max(0, math.ceil((x - tab.cor.x0) / lat.dx - GRID_EPS))
    j = min(lat.nv, max(0, int(round(v / lat.dv))))
    if lat.over is not None and i < lat.over.shape[1]:
        while j > 0 and lat.over[j, i]:
            j -= 1
    return i, j


def replan(tab: Table, k: int, x: float, v: float, leader: Leader | None = None,
           lookahead: int = LOOKAHEAD, headway: float = HEADWAY, leader_accel: float = LEADER_ACCEL,
           length: int | None = None, caps: Callable[[Lattice, int], np.ndarray] | None = None) -> Replan | None:
    """The least-cost plan from the ego's state (``x`` [m], ``v`` [m/s]) at step ``k`` after the
    departure, keeping the gap to ``leader`` over the look-ahead; None when no plan arrives within
    the table's horizon. ``length``: only the plan's first ``length`` entries (at least 2; its
    value is the whole plan's), without following the table's choices further; None: to the
    arrival. ``caps`` (instead of ``leader``): a known future of the vehicles ahead, as
    ``caps(lat, m)`` = the highest row of each speed at look-ahead step ``m``
    (``bench.oracle.clairvoyant``)."""
    started = time.perf_counter()
    i0, j0 = snap(tab, x, v)
    mode = "none"
    plan = None
    if caps is not None:
        plan = _solve(tab, k, i0, j0, lookahead, None, 0.0, headway, leader_accel, length, caps)
        mode = "kept" if plan is not None else "relaxed"
    elif leader is not None:
        plan = _solve(tab, k, i0, j0, lookahead, x + leader.gap, leader.speed, headway, leader_accel, length)
        mode = "kept"
        if plan is None:
            mode = "relaxed"
    if plan is None:
        plan = _solve(tab, k, i0, j0, lookahead, None, 0.0, headway, leader_accel, length)
    if plan is None:
        return None
    rows, speeds, value, states = plan
    lat = tab.lat
    return Replan(k=k, x=tab.cor.x0 + rows * lat.dx, v=speeds * lat.dv, value=value, leader=mode, states=states,
                  wall_s=time.perf_counter() - started)


def _solve(tab: Table, k: int, i0: int, j0: int, lookahead: int, leader_rear: float | None,
           leader_speed: float, headway: float, leader_accel: float, length: int | None = None,
           caps: Callable[[Lattice, int], np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, float, int] | None:
    lat, nv = tab.lat, tab.lat.nv
    if i0 >= lat.i_end:
        return np.array([i0]), np.array([j0]), 0.0, 0
    horizon = tab.horizon
    if k >= horizon:
        return None
    steps = min(lookahead, horizon - k)
    wins: list[Window] = []
    lo = hi = i0
    jl = jh = j0
    for _ in range(steps):  # the states reachable from (i0, j0)
        wins.append((lo, min(hi, lat.i_end - 1), jl, jh))
        jl, jh = max(0, jl + lat.d_min), min(nv, jh + lat.d_max)
        lo, hi = lo + jl, hi + jh
    wins.append((lo, min(hi, lat.i_end - 1), jl, jh))  # reachable after the look-ahead
    nxt, cur = _buffers(tab)  # values outside each step's window are stale: the kernel never reads them
    nwin: Window = (1, 0, 1, 0)  # the window of nxt's values (empty: only the arrived rows, 0)
    if k + steps < horizon:  # the table's cost-to-go after the look-ahead, where reachable
        tlo, thi, tjlo, tjhi = tab.windows[tab.at(k + steps)]
        rlo, rhi, rjlo, rjhi = wins[steps]
        nwin = (max(tlo, rlo), min(thi, rhi), max(tjlo, rjlo), min(tjhi, rjhi))
        if nwin[0] <= nwin[1] and nwin[2] <= nwin[3]:
            src = tab.values[tab.at(k + steps)]
            nxt[nwin[2]:nwin[3] + 1, nwin[0]:nwin[1] + 1] = src[nwin[2] - tjlo:nwin[3] - tjlo + 1,
                                                                nwin[0] - tlo:nwin[1] - tlo + 1]
        else:
            nwin = (1, 0, 1, 0)
    speeds_ms = np.arange(nv + 1) * lat.dv
    travel = _travels(leader_speed, steps, tab.cfg, leader_accel) if leader_rear is not None else []

    def keep_gap(buf: np.ndarray, m: int, win: Window) -> None:  # states at look-ahead step m that come too close
        lo, hi, jlo, jhi = win
        lat.cap(buf, lo, hi, jlo, jhi)
        if caps is not None and lo <= hi and jlo <= jhi:
            mask_caps(buf, lo, hi, jlo, jhi, caps(lat, m))
        if leader_rear is None or lo > hi or jlo > jhi:
            return
        mask_gap(buf, lo, hi, jlo, jhi, leader_rear + travel[m] - MIN_GAP, headway, speeds_ms, tab.cor.x0, lat.dx,
                 GRID_EPS)

    if steps == 0 and nwin[0] > nwin[1]:  # no look-ahead and a start outside the table's window
        return None
    keep_gap(nxt, steps, nwin)
    args: list[np.ndarray | None] = [None] * steps
    no_red = (np.zeros((0, nv + 1), dtype=np.int64), np.zeros(0, dtype=np.int64))
    for m in range(steps - 1, -1, -1):
        lo, hi, jlo, jhi = wins[m]
        if lo <= hi:
            green = tab.green[tab.at(k + m)]
            red = no_red
            if not green.all():
                r = np.nonzero(~green)[0]
                red = (lat.cross_low[r], lat.cross_top[r])
            arg = np.empty((jhi - jlo + 1, hi - lo + 1), dtype=np.int8 if lat.n_d < 127 else np.int16)
            backward_step_in(nxt, cur, arg, lo, hi, jlo, jhi, lat.d_min, tab.step_cost, *red, *nwin, lat.i_end)
            args[m] = arg
            if m > 0:
                keep_gap(cur, m, wins[m])
            nwin = (lo, hi, jlo, jhi)
        else:
            nwin = (1, 0, 1, 0)
        nxt, cur = cur, nxt
    value = float(nxt[j0, i0])
    if not np.isfinite(value):
        return None
    states = sum((hi - lo + 1) * (jhi - jlo + 1) for lo, hi, jlo, jhi in wins[:steps] if lo <= hi)
    rows, speeds = [i0], [j0]
    i, j = i0, j0
    for m in range(steps):
        lo, _, jlo, _ = wins[m]
        j += int(args[m][j - jlo, i - lo]) + lat.d_min  # type: ignore[index]
        i += j
        rows.append(i)
        speeds.append(j)
        if i >= lat.i_end or len(rows) == length:
            return np.array(rows), np.array(speeds), value, states
    for kk in range(k + steps, horizon):  # the table's own choices to the end
        lo, _, jlo, _ = tab.windows[tab.at(kk)]
        j += int(tab.choices[tab.at(kk)][j - jlo, i - lo]) + lat.d_min  # type: ignore[index]
        i += j
        rows.append(i)
        speeds.append(j)
        if i >= lat.i_end or len(rows) == length:
            break
    return np.array(rows), np.array(speeds), value, states
