"""The energy-optimal bound: backward dynamic programming for the ego alone on the corridor.

Problem (what ``bound`` solves). The ego drives the arterial in free flow, from where the env
inserts it (front bumper at ``vehicle_length + POSITION_EPS`` on the first edge, SUMO's
``departPos="base"``, at ``departSpeed="max"`` = the speed limit) at ``depart_time`` (the env's
``t_depart``) until its front bumper reaches the exit edge, i.e. leaves the last junction (where
``EcoDriveEnv`` terminates). Steps of ``dt = cfg.step_length`` with SUMO's Euler update
``v' = v + a dt``, ``x' = x + v' dt``; ``a`` in [a_min, a_max], ``0 <= v <= speed_limit``; a
stop line may only be crossed in a step during which its arterial signal is green (yellow
counts as red: SUMO's licence to run a yellow it cannot stop for is not used). Energy per step
is SUMO's model (``bench.oracle.energy``, straight road). Objective ``"cost"``: min E + phi T
(phi = ``cfg.reward.phi``); ``"energy"``: min E subject to T <= ``time_limit``. The end speed is
free, as in the env: the optimum recuperates its kinetic energy in the last metres.

Signal timing is SUMO's: a program with offset ``o`` is at cycle position ``(t - o) mod C``, and
a switch due at ``s`` rules the whole step ``[t, t + dt)`` containing ``s`` (SUMO runs the events
due before ``t + dt`` at the start of that step). So the step from ``t`` is green iff
``0 < (t + dt - o) mod C <= G``, each junction with its own ``o``, ``C``, ``G`` (``ScenarioConfig.timing``).
Positions are SUMO x coordinates read from the network (uneven spacing included).

Method. Speeds live on ``v = j dv``, ``dv = speed_limit / n`` (the start speed is a grid point),
positions on ``x = x0 + i dx``, ``dx = dv dt``: the Euler update maps grid states onto grid
states exactly, so a plan is exactly feasible in SUMO's kinematics and its energy is exact; the
grid only restricts accelerations to multiples of ``da = dv / dt``. Value iteration runs
backwards over the time steps, vectorised: for all states at once, the value after each next
speed is one strided view of the next value array. The inner loop, one backward step over a
window of states, is compiled with numba (``bench.oracle.kernel``; the numpy form stays as its
reference, ``kernel="numpy"``, with the same plans bit for bit). (1) A global pass on ``n = Grid.n_v`` evaluates every state in the forward-reachable
and backward-feasible band: it picks the green windows. Its horizon (the band's time extent) comes
from the cost of the optimal plan on the lattice with twice the speed cell, solved the same way
down to ``COARSEST`` cells: that plan is one of this lattice's, so no plan slower than the last
step count whose lower bound (``bench.oracle.horizon``) is within its cost can be optimal. The band shrinks
by about a third and the plan is the unpruned pass's bit for bit (``prune=False`` runs the
guess-and-certify loop alone). (2) Local passes on the ``Grid.fine``
times finer lattice evaluate only a tube (``tube_x``, ``tube_v``) around the current plan,
re-centred until the cost stops falling. The coarse plan lies on the fine lattice, so a local
pass never does worse. It matters: coasting (drag alone, about -0.14 m/s^2 at 50 km/h) is the
cheap way to slow down, and at da = 0.5 m/s^2 a plan must mix braking (recuperated at 70 %)
with driving (drawn at 1/0.9) instead. ``"cost"`` certifies the global horizon ``K``: every plan
has a cost of at least ``rate T + eta_rec W(T)/3600`` (``bench.oracle.horizon``: the auxiliaries,
and eta_rec times the least mechanical work of T steps over the corridor), so no plan slower than
``K`` steps beats the one found when its cost is within that bound's least value over T > K;
otherwise ``K`` grows and it re-solves.

Resolution (default ``Grid()``, 50 km/h, dt = 1 s): global dv = dx = da = 0.496 (m/s, m,
m/s^2), final 0.124. A plan is feasible, so its cost bounds the continuous-control optimum of
the problem from above; refining lowers it. ``Grid().refine()`` (final 0.062) lowered the cost
by 0.013-0.026 % on the 5-intersection corridor (departures 200, 231, 260 s) and by 0.15-0.17 %
on the 450 m one-intersection corridor, where the end manoeuvre weighs more; the tests assert
< 0.2 %. The local passes matched a global pass on their final lattice to 0.01 % (one-
intersection corridor); where the cost is flat in the cruise speed they may stop a coarse cell
from the best one (phi = 0.3: 12.3 instead of 11.9 m/s, about 0.08 % of cost). A ``"cost"`` case takes
0.2-0.6 s on one core of the 2-core machine beside other jobs, 0.03-0.06x the reference solver's
time with numba compiling for AVX2 or AVX-512 (``Plan.grid["wall_s"]``; ``python -m
ecodrive_bench.bench.oracle.dp --reference`` times both, ``nox -s perf`` records the ratio, see
docs/performance.md); dt = 0.5 s takes about 4 times as long. Not timed in tests.

Not a constraint here, but one in SUMO: while a light is red, SUMO caps the speed so that the
car can still stop at the line (Krauss). A plan that reaches the line at speed just as green
starts is therefore not drivable in the env: the bound is optimistic there. Plans that never
lean on a red (e.g. departure 260 s) replay in SUMO step for step (tests/bench/oracle).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ecodrive_bench.envs.config import ScenarioConfig

from .corridor import MS, Corridor
from .energy import energy_wh
from .horizon import LeastCost
from .lattice import GRID_EPS, Lattice, Solution, Window
from .passes import KERNELS, Buffers, backward

OBJECTIVES = ("cost", "energy")
HORIZON_MARGIN = 10  # [steps] added to the first guess of the "cost" horizon
LATE_STEPS = 5  # [steps] a local pass may arrive this much later than the plan it refines
STALL = 1e-4  # [-] local passes stop when the cost falls by less than this fraction
MAX_HORIZON = 86400.0  # [s] the "cost" horizon stops growing here
VERSION = 1  # [-] of the plans and values ``bound`` returns: bump it with any change that alters one, so
# the bounds shipped with the fixed cases (bench.cases.shipped_bounds) miss and are solved again

COARSEST = 7  # [-] speed cells: ``_Run._upper`` halves the lattice down to this, no further


@dataclass(frozen=True)
class Grid:
    """Resolution of the DP. Work grows ~ n_v^3 (global) and ~ fine^3 (local passes)."""

    n_v: int = 28  # [-] speed cells of the global pass between 0 and the speed limit
    # local levels: (cells per global cell, tube half-width [m] in position, [m/s] in speed);
    # each level's factor must divide the next one's
    levels: tuple[tuple[int, float, float], ...] = ((4, 25.0, 3.0),)
    passes: int = 8  # [-] at most this many local passes per level

    def __post_init__(self) -> None:
        factors = [1] + [lv[0] for lv in self.levels]
        if not (isinstance(self.n_v, int) and self.n_v >= 2 and all(isinstance(f, int) for f in factors)
                and all(b % a == 0 and b >= a for a, b in zip(factors, factors[1:]))):
            raise ValueError(f"n_v={self.n_v!r} must be an integer >= 2 and the level factors "
                             f"{factors[1:]} integers, each dividing the next")

    @property
    def fine(self) -> int:
        """Cells of the final lattice per global cell."""
        return self.levels[-1][0] if self.levels else 1

    def refine(self, factor: int = 2) -> Grid:
        """A grid ``factor`` times finer: one more local level at ``factor`` times the final
        resolution, in a tube half as wide, seeded with the plan of this grid, so the refined
        plan never costs more."""
        f, tube_x, tube_v = self.levels[-1] if self.levels else (1, 25.0, 3.0)
        return replace(self, levels=self.levels + ((f * int(factor), tube_x / 2, tube_v / 2),))

    def spacing(self, cfg: ScenarioConfig, fine: bool = True) -> tuple[float, float, float]:
        """(dv [m/s], dx [m], da [m/s^2]) of the final (or, ``fine=False``, the global) lattice."""
        dv = cfg.speed_limit / (self.n_v * (self.fine if fine else 1))
        return dv, dv * cfg.step_length, dv / cfg.step_length


@dataclass
class Plan:
    """An optimal trajectory. ``t, x, v`` have one entry per time step from the departure to
    the arrival (N + 1 entries); ``a[k]`` is the acceleration of the step from ``t[k]`` (N)."""

    t: np.ndarray  # [s] simulation time
    x: np.ndarray  # [m] front bumper x
    v: np.ndarray  # [m/s]
    a: np.ndarray  # [m/s^2]
    energy: float  # [Wh]
    travel_time: float  # [s]
    cost: float  # [Wh] energy + phi * travel_time
    objective: str
    crossings: np.ndarray  # [s] start of the step in which each stop line is crossed
    grid: dict[str, Any] = field(default_factory=dict)  # resolution, horizon, states, wall_s, ...
    table: tuple[Any, Any, int] | None = field(default=None, repr=False)  # (lattice, global pass, horizon): solve(slack=)


def bound(cfg: ScenarioConfig, depart_time: float, objective: str = "cost",
          time_limit: float | None = None, grid: Grid | None = None, kernel: str = "numba",
          krauss: bool = False, prune: bool = True) -> Plan:
    """The optimal plan for ``cfg``'s corridor and signals, departing at ``depart_time`` [s]
    (the env's ``t_depart``). ``objective="energy"`` needs ``time_limit`` [s]. ``kernel``: the
    inner loop, ``"numba"`` or the numpy reference ``"numpy"`` (``KERNELS``; the same plan).
    ``krauss``: Krauss' stop-for-red cap is a constraint too (the best plan SUMO's driver model
    lets the ego drive alone, for a controller; not the bound). ``prune`` (``"cost"``): the global
    pass's horizon comes from a plan on coarser lattices (the same plan, less work); False runs the
    guess-and-certify loop alone, the reference ``nox -s perf`` takes the speed-up against."""
    return solve(Corridor.from_config(cfg), cfg, depart_time, objective, time_limit, grid, kernel, krauss, prune=prune)


def solve(cor: Corridor, cfg: ScenarioConfig, depart_time: float, objective: str = "cost",
          time_limit: float | None = None, grid: Grid | None = None, kernel: str = "numba",
          krauss: bool = False, slack: int = 0, prune: bool = True) -> Plan:
    """``bound`` on a given ``Corridor`` (tests drop or move its signals). ``slack`` > 0 (``"cost"``
    only): the global pass runs ``slack`` steps past the horizon it needs and the plan keeps it
    (``Plan.table``: the cost-to-go a re-planning controller reads, ``bench.oracle.mpc``)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective={objective!r} is not accepted; choose one of {', '.join(OBJECTIVES)}")
    if kernel not in KERNELS:
        raise ValueError(f"kernel={kernel!r} is not accepted; choose one of {', '.join(KERNELS)}")
    if objective == "energy" and time_limit is None:
        raise ValueError("objective='energy' needs a time_limit [s]")
    grid = grid or Grid()
    started = time.perf_counter()
    run = _Run(cor, cfg, depart_time, cfg.reward.phi if objective == "cost" else 0.0, kernel)
    lat = Lattice(cor, cfg, grid.n_v, krauss)
    if objective == "energy":
        horizon = int(math.floor(float(time_limit) / cfg.step_length + GRID_EPS))
        sol = run.backward(lat, lat.windows(horizon))
    else:
        horizon, sol = run.certified(lat, slack, prune)
    if not np.isfinite(sol.value):
        raise ValueError(f"no plan arrives within {horizon * cfg.step_length:g} s (time_limit={time_limit})")
    rows, speeds = lat.extract(sol)
    table = (lat, sol, horizon) if slack > 0 and objective == "cost" else None
    return refine(run, lat, rows, speeds, horizon, grid, krauss, objective, started, table)


def refine(run: _Run, lat: Lattice, rows: np.ndarray, speeds: np.ndarray, horizon: int, grid: Grid, krauss: bool,
           objective: str, started: float, table: tuple[Any, Any, int] | None = None) -> Plan:
    """The local passes of ``grid.levels`` from a global-lattice plan (row and speed indices on
    ``lat``, arriving within ``horizon`` steps), as a ``Plan``."""
    cor, cfg, depart_time = run.cor, run.cfg, run.depart_time
    value = coarse = run.objective(speeds, lat)
    passes = 0
    for factor, tube_x, tube_v in grid.levels:  # local passes, each seeded with the plan in hand
        fine = Lattice(cor, cfg, grid.n_v * factor, krauss)
        rows, speeds = rows * (fine.nv // lat.nv), speeds * (fine.nv // lat.nv)
        tube = (math.ceil(tube_x / fine.dx), math.ceil(tube_v / fine.dv))
        for _ in range(grid.passes):
            late = min(len(rows) - 1 + LATE_STEPS, horizon)
            f_rows, f_speeds = fine.extract(run.backward(fine, fine.windows(late, (rows, speeds) + tube)))
            f_value = run.objective(f_speeds, fine)
            passes += 1
            if f_value > value:  # float32 ties: keep the plan in hand
                break
            gain, rows, speeds, value = value - f_value, f_rows, f_speeds, f_value
            if gain <= STALL * abs(value):
                break
        lat = fine
    dt = cfg.step_length
    x, v = cor.x0 + rows * lat.dx, speeds * lat.dv
    n = len(rows) - 1
    t = depart_time + np.arange(n + 1) * dt
    energy = float(energy_wh(v[:-1], v[1:], dt, cfg.ev).sum())
    crossings = np.array([t[np.nonzero((x[:-1] < s) & (x[1:] >= s))[0][0]] for s in cor.stop_lines])
    return Plan(
        t=t, x=x, v=v, a=np.diff(v) / dt, energy=energy, travel_time=n * dt,
        cost=energy + cfg.reward.phi * n * dt, objective=objective, crossings=crossings,
        grid={"n_v": grid.n_v, "fine": grid.fine, "dv": lat.dv, "dx": lat.dx, "da": lat.dv / dt,
              "horizon": horizon, "krauss": krauss, "passes": passes, "states": run.states, "coarse_objective": coarse,
              "objective": value, "wall_s": time.perf_counter() - started},
        table=table,
    )


class _Run:
    """One solve: the signals seen from ``depart_time`` and the time weight ``phi`` [Wh/s]."""

    def __init__(self, cor: Corridor, cfg: ScenarioConfig, depart_time: float, phi: float, kernel: str) -> None:
        self.cor, self.cfg, self.depart_time, self.phi, self.kernel = cor, cfg, depart_time, phi, kernel
        self.states = 0  # evaluated, all passes
        self.buffers: Buffers = {}  # the compiled kernel's value buffers, reused by the passes on one lattice

    def backward(self, lat: Lattice, windows: list[Window], keep: bool = False) -> Solution:
        dt = self.cfg.step_length
        green = self.cor.green(self.depart_time + np.arange(len(windows)) * dt, dt) if self.cor.stop_lines else None
        out = backward(lat, green, windows, self.phi * dt, self.kernel, keep, self.buffers)
        self.states += out.states
        return out

    def certified(self, lat: Lattice, slack: int = 0, prune: bool = True,
                  patient: bool = True) -> tuple[int, Solution]:
        """Global pass of the "cost" objective on a horizon that provably does not bind; ``slack``
        > 0: ``slack`` steps longer, keeping every step's values (``solve``). ``prune`` (``slack``
        0 only): the horizon comes from the cost of a plan solved on the lattice half as fine
        (``_upper``), which shrinks the band without changing the optimum or its plan.
        ``patient=False``: ValueError at once where the first horizon has no plan, instead of
        doubling it (a coarse lattice's pass is worth nothing then)."""
        cor, dt, least = self.cor, self.cfg.step_length, LeastCost(self.cor, self.cfg, self.phi)
        if least.rate <= 0:
            raise ValueError("phi = 0 and no constant power intake: no horizon; use objective='energy'")
        if prune and slack == 0:
            upper = self._upper(lat)
            if upper is not None:
                horizon = least.last_steps(upper + _margin(upper))
                sol = self.backward(lat, lat.windows(horizon))
                if sol.value <= upper + _margin(upper):  # every plan costing <= upper arrives within it
                    return horizon, sol
        n_red = sum(math.ceil((c - g) / (dt * MS)) for c, g in zip(cor.cycles_ms, cor.greens_ms))
        cruise = max(cor.v0, 0.5 * self.cfg.speed_limit)  # [m/s] the first guess's speed (an ego may start at rest)
        horizon = math.ceil((cor.x_end - cor.x0) / (cruise * dt)) + n_red + HORIZON_MARGIN + slack
        while horizon * dt <= MAX_HORIZON:
            sol = self.backward(lat, lat.windows(horizon), keep=slack > 0)
            if not np.isfinite(sol.value):
                if not patient:
                    raise ValueError(f"no plan within {horizon} steps")
                horizon *= 2
            elif sol.value <= least.after(horizon):
                return horizon, sol  # no plan slower than the horizon can cost less (module docstring)
            else:
                horizon = max(horizon + 1, least.last_steps(float(sol.value)))
        raise ValueError(f"no plan certified within {MAX_HORIZON:g} s")

    def _upper(self, lat: Lattice) -> float | None:
        """E + phi T [Wh] of the optimal plan on the lattice with twice the speed cell (its
        states lie on ``lat``, so the plan is one of ``lat``'s), solved the same way in turn;
        None where ``lat`` has no such coarser lattice, the coarser one cannot both speed up and
        slow down within a step or does not hold the start speed, or it has no plan within its first
        horizon."""
        if lat.nv % 2 or lat.nv // 2 < COARSEST:
            return None
        coarse = Lattice(self.cor, self.cfg, lat.nv // 2, lat.krauss)
        if coarse.d_max < 1 or coarse.d_min > -1 or not coarse.on_grid:
            return None
        try:
            _, sol = self.certified(coarse, patient=False)
        except ValueError:
            return None
        return self.objective(coarse.extract(sol)[1], coarse)

    def objective(self, speeds: np.ndarray, lat: Lattice) -> float:
        """E + phi T [Wh] of a path of speed indices, in float64."""
        v = speeds * lat.dv
        dt = self.cfg.step_length
        return float(energy_wh(v[:-1], v[1:], dt, self.cfg.ev).sum()) + self.phi * (len(v) - 1) * dt


def _margin(cost: float) -> float:
    """[Wh] more than the float32 error of a DP value near ``cost`` (sums of at most a few
    thousand float32 terms)."""
    return 1e-3 * abs(cost) + 0.1


if __name__ == "__main__":  # timing: python -m ecodrive_bench.bench.oracle.dp [--signals S] [--reference] [depart_time ...]
    import argparse
    import statistics

    ap = argparse.ArgumentParser(description="The bound of each departure and its wall time (Plan.grid's wall_s, after "
                                             "one solve that compiles the kernel); --reference: beside the reference "
                                             "solver's (numpy kernel, unpruned), alternating, medians of --rounds.")
    ap.add_argument("depart", type=float, nargs="*", default=[200.0, 231.0, 260.0], help="departure times [s]")
    ap.add_argument("--signals", choices=("coordinated", "uncoordinated"), default="coordinated")
    ap.add_argument("--reference", action="store_true", help="time the reference solver too")
    ap.add_argument("--rounds", type=int, default=1)
    opts = ap.parse_args()
    cfg = ScenarioConfig(signals=opts.signals)
    bound(cfg, opts.depart[0])
    for depart in opts.depart:
        walls, refs = [], []
        for _ in range(opts.rounds):
            p = bound(cfg, depart)
            walls.append(p.grid["wall_s"])
            if opts.reference:
                refs.append(bound(cfg, depart, kernel="numpy", prune=False).grid["wall_s"])
        wall = statistics.median(walls)
        ref = f", reference {statistics.median(refs):.2f} s = {wall / statistics.median(refs):.3f}x" if refs else ""
        print(f"depart {depart:g} s: cost {p.cost:.3f} Wh = E {p.energy:.3f} Wh + T {p.travel_time:g} s, "
              f"{p.grid['states']:.3g} states, {p.grid['passes']} local passes, {wall:.3f} s{ref}", flush=True)
