"""The ``mpc`` method: a closed-loop controller that knows the signal plans (``bench.oracle.mpc``).

At the first step of an episode it takes the cost-to-go table (``bench.oracle.mpc.start``: the
corridor's periodic one, solved once per process) and the departure's least-cost plan on the
fine lattice with Krauss' stop-for-red cap obeyed (the plan SUMO drives step for step when the
ego is alone); for the fixed cases that plan is read from the shipped bounds
(``bench.cases.shipped_bounds``, the same plan bit for bit) instead of being solved again. At
every step it reads
the ego's state (speed from the observation, position from ``info["position"]``) and the vehicle
ahead from the occupancy grid. It keeps the first plan until the first event that says it no
longer holds:

- ``drift``: the ego left the plan's cell (speed off by more than ``TOL_V``, or the position out
  of ``[x_plan - one global row - TOL_X, x_plan + TOL_X]``); between re-plans the state therefore
  stays within these bounds of the plan in force, which is what the trigger guarantees;
- ``leader``: over the look-ahead, the plan in force comes closer to the predicted vehicle ahead
  than ``MIN_GAP + HEADWAY v``;
- ``end``: the plan in force has ended before the corridor.

From then on it re-plans at every step on the global lattice (``bench.oracle.mpc.replan``, about a
millisecond: ``nox -s perf``). With no vehicle ahead such a re-plan from a state on the plan in
force returns the rest of that plan (tests/bench/oracle/test_mpc.py), so re-planning every step is
event triggering that also notices when a leader's constraint has gone slack. Between re-plans
of the first plan, the state stays within the drift bounds above of the plan, by construction.

The vehicle ahead: the first occupied cell ahead of the front bumper in the ego's lane column of
the grid (its rear bumper, to the cell: the gap is rounded down). Its speed is the ego's speed
plus the gap's change over the last two steps (SUMO's update ``x' = x + v' dt``), at least 0; a
vehicle first seen this step is taken at the ego's speed. This is what the observation tells.

It drives the ``longitudinal`` action type through the same safety layer as ``oracle`` and
DDPG+LC2013: Krauss clips the request, LC2013 changes lanes. It requests ``a = (v_plan[k+1] -
v) / dt`` within [a_min, a_max]. The plans in force are kept (``plan_trace``: the first, and each
re-plan with its time, event, wall time and its first ``LOGGED_STEPS`` steps) for the step log,
where the viewer draws them.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.methods.not_learning import NotLearning
from ecodrive_bench.bench.methods.planners import MPC as NAME
from ecodrive_bench.bench.oracle import mpc as planner
from ecodrive_bench.bench.oracle.dp import MS, Corridor, Grid, Plan
from ecodrive_bench.envs.config import ScenarioConfig

GREEN_MARGINS = (0.0, 0.0)  # [s] planned crossings keep off the first / last seconds of each green (variant)
PLAN_HEADWAY = 0.0  # [s] time gap the plan keeps to the vehicle ahead, beyond MIN_GAP (validation: docs/mpc.md)
TOL_V = 0.05  # [m/s] speed drift that triggers a re-plan
TOL_X = 0.05  # [m] position drift (beyond the one-row rounding) that triggers a re-plan
LOGGED_STEPS = planner.LOOKAHEAD  # [steps] of each re-plan kept in the step log (its look-ahead)
LOG_DECIMALS = 3  # [-] rounding of the logged plans ([m], [m/s])


class MPCAgent(NotLearning):
    """Re-plans on the DP's cost-to-go table when the ego drifts or the vehicle ahead is in the way.

    The keywords are the variants compared on validation cases (docs/mpc.md): ``margins`` [s] keep
    planned crossings off the start / end of each green, ``time_weight`` [Wh/s] plans with another
    phi, ``follow=False`` leaves the vehicle ahead to the safety layer, ``headway`` [s] and
    ``leader_accel`` [m/s^2] set the gap kept and the leader's prediction. The defaults are the
    shipped method. ``shipped``: the shipped bounds' file, whose first plans the agent takes where
    they answer its problem (its corridor and time weight the scenario's own); None: always
    solve."""

    name = NAME
    action_interface = "longitudinal"
    env_overrides: dict[str, Any] = {}

    def __init__(self, cfg: ScenarioConfig, margins: tuple[float, float] = GREEN_MARGINS,
                 time_weight: float | None = None, follow: bool = True, headway: float = PLAN_HEADWAY,
                 leader_accel: float = planner.LEADER_ACCEL, shipped: Path | None = shipped_bounds.FILE) -> None:
        self.headway, self.leader_accel = headway, leader_accel
        self.cfg = cfg
        self.follow = follow  # keep the gap to the vehicle ahead in the plan (else: the safety layer alone)
        self.plan_cfg = cfg if time_weight is None else replace(cfg, reward=replace(cfg.reward, phi=time_weight))
        start, end = (int(round(m * MS)) for m in margins)
        cor = Corridor.from_config(cfg)
        self.cor = replace(cor, offsets_ms=tuple(o + start for o in cor.offsets_ms),
                           greens_ms=tuple(g - start - end for g in cor.greens_ms))
        # the shipped first plans are the scenario's own problem: no green margins, its own phi
        self.shipped = shipped if self.cor == cor and self.plan_cfg is cfg else None
        self.plan: Plan | None = None
        self.table: planner.Table | None = None
        self.k0 = 0  # [steps] the step the plan in force starts at
        self.x = np.zeros(0)  # [m] plan in force from step k0
        self.v = np.zeros(0)  # [m/s]
        self.gaps: list[float | None] = []  # last two gaps to the vehicle ahead [m]
        self.events: list[dict[str, Any]] = []
        self.first = True  # the plan in force is the departure's first plan (fine lattice)
        self.counts: dict[str, int] = {}

    def start(self, depart_time: float, speed: float | None = None) -> None:
        """A new episode departing at ``depart_time`` [s] at ``speed`` [m/s]: on the generated
        arterial always the speed limit; on a network corridor what traffic let the ego insert at
        (None: the first lane's limit)."""
        cor, first = self.cor, None
        if self.cfg.network is not None:
            cor = cor.starting(cor.v0 if speed is None else speed, Grid().spacing(self.cfg, fine=False)[0])
        else:
            table = shipped_bounds.table(self.shipped) if self.shipped is not None else None
            first = table.mpc_plan(self.plan_cfg, depart_time) if table is not None else None
        self.plan, self.table = planner.start(cor, self.plan_cfg, depart_time, first_plan=first)
        self.k0, self.x, self.v = 0, self.plan.x, self.plan.v
        self.gaps, self.events, self.first = [], [], True
        self.counts = {"drift": 0, "leader": 0, "end": 0, "step": 0, "relaxed": 0, "lost": 0}

    def leader(self, obs: dict[str, np.ndarray], speed: float) -> planner.Leader | None:
        """The vehicle ahead in the ego's lane, from the grid; updates the gap history."""
        cfg = self.cfg
        lanes = cfg.observed_lanes
        lane = int(np.argmax(obs["logic"][:lanes]))
        ahead = int(round(cfg.grid_behind / cfg.cell_length))  # first row ahead of the front bumper
        column = obs["grid"][ahead:, lane]
        occupied = np.nonzero(column < 0.5)[0]
        gap = float(occupied[0]) * cfg.cell_length if len(occupied) else None
        self.gaps = (self.gaps + [gap])[-3:]
        if gap is None:
            return None
        est = speed
        dt = cfg.step_length
        if len(self.gaps) == 3 and self.gaps[0] is not None and self.gaps[1] is not None:
            est = speed + (gap - self.gaps[0]) / (2 * dt)
        elif len(self.gaps) >= 2 and self.gaps[-2] is not None:
            est = speed + (gap - self.gaps[-2]) / dt
        return planner.Leader(gap=gap, speed=max(0.0, est))

    def _event(self, k: int, x: float, v: float, lead: planner.Leader | None) -> str | None:
        idx = k - self.k0
        if idx + 1 >= len(self.v):
            return "end"
        dx = self.table.lat.dx if self.table is not None else 0.0
        if abs(v - self.v[idx]) > TOL_V or x > self.x[idx] + TOL_X or x < self.x[idx] - dx - TOL_X:
            return "drift"
        if lead is not None:
            m = np.arange(1, min(planner.LOOKAHEAD, len(self.v) - 1 - idx) + 1)
            travel = np.array([planner.leader_travel(lead.speed, int(q), self.cfg, self.leader_accel) for q in m])
            limit = x + lead.gap + travel - planner.MIN_GAP
            if np.any(self.x[idx + m] > limit - self.headway * self.v[idx + m]):
                return "leader"
        return None

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any], explore: bool = False) -> np.ndarray:
        cfg, dt = self.cfg, self.cfg.step_length
        speed = float(obs["logic"][cfg.observed_lanes + 1])
        if info["travel_time"] == 0.0 or self.plan is None:  # the reset's info: a new departure
            self.start(float(info["time"]), speed)
        assert self.plan is not None and self.table is not None
        k = int(round((float(info["time"]) - self.plan.t[0]) / dt))
        x = float(info["position"])
        lead = self.leader(obs, speed) if self.follow else None
        event = self._event(k, x, speed, lead) if self.first else "step"
        if event is not None:
            self.first = False
            self.counts[event] += 1
            started = time.perf_counter()
            # from here on every step re-plans: the plan in force is read one step ahead and logged
            # LOGGED_STEPS ahead, so the table's choices are not followed further
            new = planner.replan(self.table, k, x, speed, lead, headway=self.headway, leader_accel=self.leader_accel,
                                 length=LOGGED_STEPS + 1)
            if new is None:  # no plan arrives within the table: hold the speed limit (Krauss governs)
                self.counts["lost"] += 1
                self.k0, self.x, self.v = k, np.array([x, x]), np.array([speed, cfg.speed_limit])
            else:
                self.counts["relaxed"] += new.leader == "relaxed"
                self.k0, self.x, self.v = k, new.x, new.v
            head = slice(0, LOGGED_STEPS + 1)
            self.events.append({"time": float(info["time"]), "event": event,
                                "leader": "lost" if new is None else new.leader,
                                "wall_ms": round((time.perf_counter() - started) * 1e3, LOG_DECIMALS),
                                "x": np.round(self.x[head], LOG_DECIMALS).tolist(),
                                "speed": np.round(self.v[head], LOG_DECIMALS).tolist()})
        idx = k - self.k0
        target = float(self.v[idx + 1]) if idx + 1 < len(self.v) else cfg.speed_limit
        accel = min(max((target - speed) / dt, cfg.a_min), cfg.a_max)
        return np.array([accel], dtype=np.float32)

    @property
    def plan_trace(self) -> dict[str, Any] | None:
        """The first plan as plain lists, the re-plans and the event counts (step log metadata)."""
        if self.plan is None:
            return None
        p = self.plan
        return {"time": p.t.tolist(), "x": p.x.tolist(), "speed": p.v.tolist(), "energy": p.energy,
                "travel_time": p.travel_time, "cost": p.cost, "objective": p.objective,
                "replans": self.events, "events": dict(self.counts),
                "table_wall_s": self.table.wall_s if self.table is not None else 0.0}
