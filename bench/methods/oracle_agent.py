"""The ``oracle`` method: the cost-optimal plan (``bench.oracle.dp``) replayed in SUMO.

At the first step of an episode the agent solves the case's bound with the ``"cost"`` objective
(least E + phi T through the known fixed-time signals, the ego alone on the corridor) for the
departure it sees (``info["time"]`` at the reset is the env's ``t_depart``), or reads that very
plan from the bounds shipped with the fixed cases where they hold its problem
(``bench.cases.shipped_bounds``: same scenario, DP version and grid, departure). Then it drives open
loop in time: at step k it asks for the acceleration that brings its speed to the plan's speed at
step k + 1, ``a = (v_plan[k+1] - v) / dt``, within [a_min, a_max]. It drives the ``longitudinal``
action type, so the safety layer clips the request to Krauss' safe speed when traffic or a red
light is in the way, and SUMO's LC2013 changes lanes, as for DDPG+LC2013. After the plan ends (a
delayed ego) it holds the speed limit. In free flow the replay follows the plan step for step;
where traffic delays the ego, the gap between the replayed cost and the bound is what traffic
costs. (Where the plan reaches a stop line at speed just as green starts, SUMO's Krauss model
slows the ego before the line, so the replay is a little slower than the bound even alone:
``bench.oracle.dp``'s docstring.)

On a network corridor (``envs.route``) the plan starts from the ego's speed at its insertion
(traffic may slow it; rounded down to a speed cell), in the route frame, and is solved for each
departure: nothing is shipped for those.

The plan is kept as ``plan_trace`` (time, x, speed arrays) for the step log, where the viewer
and the report draw it beside the driven trajectory.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.methods.not_learning import NotLearning
from ecodrive_bench.bench.methods.planners import ORACLE as NAME
from ecodrive_bench.bench.oracle.dp import Corridor, Grid, Plan, bound, solve
from ecodrive_bench.envs.config import ScenarioConfig

OBJECTIVE = "cost"  # the bound the oracle replays: least E + phi T


class OracleAgent(NotLearning):
    """Replays the cost-optimal plan of each episode's departure; never learns."""

    name = NAME
    action_interface = "longitudinal"
    env_overrides: dict[str, Any] = {}

    def __init__(self, cfg: ScenarioConfig, shipped: Path | None = shipped_bounds.FILE) -> None:
        self.cfg = cfg
        self.plan: Plan | None = None
        self.shipped = shipped  # the shipped bounds' file; None: always solve
        # a network corridor's route frame (a PlanError names a signal that is not fixed-time)
        self.cor = Corridor.from_config(cfg) if cfg.network is not None else None

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any], explore: bool = False) -> np.ndarray:
        cfg, dt = self.cfg, self.cfg.step_length
        speed = float(obs["logic"][cfg.observed_lanes + 1])
        if info["travel_time"] == 0.0 or self.plan is None:  # the reset's info: a new departure
            if self.cor is not None:  # a network corridor: from the speed traffic let the ego insert at
                cor = self.cor.starting(speed, Grid().spacing(cfg, fine=False)[0])
                self.plan = solve(cor, cfg, float(info["time"]), OBJECTIVE)
            else:
                table = shipped_bounds.table(self.shipped) if self.shipped is not None else None
                plan = table.plan(cfg, float(info["time"])) if table is not None else None
                self.plan = plan if plan is not None else bound(cfg, float(info["time"]), OBJECTIVE)
        plan = self.plan
        k = int(round((float(info["time"]) - plan.t[0]) / dt))
        target = float(plan.v[k + 1]) if k + 1 < len(plan.v) else cfg.speed_limit
        accel = min(max((target - speed) / dt, cfg.a_min), cfg.a_max)
        return np.array([accel], dtype=np.float32)

    @property
    def plan_trace(self) -> dict[str, list[float]] | None:
        """The current episode's plan as plain lists (for the step log's metadata)."""
        if self.plan is None:
            return None
        p = self.plan
        return {"time": p.t.tolist(), "x": p.x.tolist(), "speed": p.v.tolist(), "energy": p.energy,
                "travel_time": p.travel_time, "cost": p.cost, "objective": p.objective}
