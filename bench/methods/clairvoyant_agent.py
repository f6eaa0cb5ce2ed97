"""The ``clairvoyant`` method: the top of the benchmark's scale, a planner that knows the case's future.

It knows what no causal method can: the signal plans, and the future of every other vehicle of
the case (the traffic is deterministic given the case's SUMO seed). Before its episode the harness
calls ``prepare(env, case)``, which drives the case on the worker's own env to record that future
(``bench.oracle.clairvoyant.Recording``, every vehicle on the ego's route at every step).

Then it drives in closed loop, as ``mpc`` does, but with the future known instead of guessed. It
follows the departure's first plan (the DP's free-flow optimum with Krauss' red cap, on the fine
lattice) while the ego stays on it and no recorded vehicle ahead comes into its way over the
look-ahead; from then on, at every step, it re-plans on the DP's cost-to-go table (``bench.oracle.mpc.replan``) over a
``LOOKAHEAD``-step look-ahead in which the vehicles ahead of it in its lane move as the recording
says (``ahead_future``: each one's recorded path from now, shifted to where it is now), kept
behind at SUMO's minGap plus Krauss' safe distance (``gap_caps``). Every ``LANE_EVERY`` steps it
plans the same way in the lanes beside its own, and changes to one whose plan costs
``LANE_GAIN`` less. Because the ego's own presence changes the traffic a little (a vehicle that
changes lanes in front of it, one that it holds up), ``prepare`` records again from its own drive
and drives once more, up to ``ROUNDS`` drives. Last it cruises the case, once per target speed of
``CRUISE_SPEEDS`` and acceleration cap of ``CRUISE_ACCELS``: in its lane, up to that speed at
most at that acceleration, the safety layer's Krauss clip following the traffic (steady driving
at full throttle is one of them). The planner's departure plan, the free-flow optimum, sometimes
loses a cycle where a queue stands in its way, and a cruise at the right speed catches the greens
that the queue leaves. Each drive is a real closed-loop drive of the case through the safety
layer, and before them ``prepare`` lets SUMO's driver (the ``baseline`` method) drive the case on an
env of its own, for its travel time.

The episode replays the chosen drive: its actions, one by one, which drive that very episode
again, since a case is deterministic. Which drive is chosen couples the cases of a set (a corridor
and signal setting): the reference is the least mean cost E + phi T whose mean travel time is no
more than SUMO's driver's, and a set's price of time lambda (``bench.oracle.time_price``) makes
each case take the drive of least E + (phi + lambda) T; lambda is 0 where the cheapest drives
already meet SUMO's driver's mean time. The fixed cases', the held-out corridors' and the real
corridors' sets are planned whole and their chosen drives shipped
(``bench.cases.clairvoyant_drives``; planned by ``bench.shipped.drives``): ``prepare`` reads the
case's actions instead of planning, where they answer its problem. A case planned on its own,
with no set, takes its cheapest drive (lambda 0).

On a network corridor (``envs.route``) the same, in the route frame: positions along the route,
the recorded vehicles those on the route's lanes, a lane their index on the edge they are on
(``envs.env.EcoDriveEnv.traffic``); its plans start from the speed traffic let the ego insert at.
There it drives the ``longitudinal`` action, as ``mpc`` and ``oracle`` do: SUMO's LC2013 keeps the
ego on lanes that continue its route (a network's lanes end and turn, which the route frame's lane
index does not follow). The drives of ``mpc`` and ``oracle`` on the case, planned for the cost
E + (phi + p) T at each extra price of time p of ``TIME_PRICES`` and driven on the same env
exactly as their own episodes, are candidates beside its own. At p = 0 they are those methods'
episodes, so that a case's cheapest drive never costs more than the cheaper of them; the dearer
prices give faster drives at little more energy (a real network's queues make the free-flow plan
of least cost lose a green that a slightly quicker one catches), from which a set's price of time
chooses where its mean time must come down to SUMO's driver's. The real case set's drives are
shipped like the others (``bench.shipped.drives.case_sets``); both signal settings of a
network are one problem (``bench.cases.shipped_bounds.problem_digest``), so one set is planned
per real corridor.

It drives the ``parameterized`` action: the lane decision (the LC2013 mask may refuse it) and the
acceleration that brings its speed to the plan's next one, through the same safety layer as
every method.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.agents.baseline import BaselineAgent
from ecodrive_bench.bench.cases import clairvoyant_drives as drives
from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.hosts import ENERGY_RTOL, close
from ecodrive_bench.bench.methods.errors import ShippedMismatch
from ecodrive_bench.bench.methods.not_learning import NotLearning
from ecodrive_bench.bench.methods.planners import CLAIRVOYANT as NAME
from ecodrive_bench.bench.oracle import mpc as planner
from ecodrive_bench.bench.oracle.clairvoyant import MARGIN, Recording, Tracks, ahead_future, gap_caps
from ecodrive_bench.bench.oracle.dp import Corridor, Grid
from ecodrive_bench.bench.oracle.mpc import HEADWAY, MIN_GAP
from ecodrive_bench.bench.oracle.time_price import pick
from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.route import LANE_PITCH

BASELINE = BaselineAgent.name  # SUMO's driver, whose travel time on the case bounds the drive's
LOOKAHEAD = 40  # [steps] of known traffic in each re-plan
LANE_EVERY = 5  # [steps] between looks at the lanes beside the ego's
LANE_GAIN = 1.0  # [Wh] a lane beside is taken when its plan costs this much less
ROUNDS = 3  # [-] planned drives per case (the first without a recording), before the cruises
CRUISE_SPEEDS = (1.0, 0.95, 0.9, 0.85, 0.8, 0.75, 0.7)  # [-] target speeds of the cruise drives, shares of the limit
CRUISE_ACCELS = (None, 1.5, 0.75)  # [m/s^2] their acceleration caps (None: a_max, full throttle)
TOL_V = 0.05  # [m/s] speed drift that leaves the first plan for re-plans (as mpc)
TOL_X = 0.6  # [m] position drift that does the same (beyond about a row of the global lattice)
TIME_PRICES = (0.0, 0.5, 1.0, 2.0, 4.0)  # [Wh/s] extra prices of time of the causal planners' candidate drives (networks)


class ClairvoyantAgent(NotLearning):
    """Drives each case knowing its future traffic (``prepare`` records it); never learns."""

    name = NAME
    action_interface = "parameterized"
    env_overrides: dict[str, Any] = {}

    def __init__(self, cfg: ScenarioConfig, shipped: Path | None = drives.FILE) -> None:
        self.cfg = cfg
        if cfg.network is not None:  # a network corridor: SUMO keeps the ego on its route's lanes (module docstring)
            self.action_interface = "longitudinal"
        self.shipped = shipped  # the shipped drives of the case sets (bench.cases.clairvoyant_drives); None: plan
        self.cor = Corridor.from_config(cfg)
        self.env: Any = None
        self.tracks: Tracks | None = None  # the recorded future the next drive uses
        self.table: planner.Table | None = None
        self.t0 = 0.0
        self.want: int | None = None  # the lane the ego is changing to
        self.first: Any = None  # the departure's first plan (fine lattice), followed while it holds
        self.rounds: list[dict[str, Any]] = []
        self.lane_y: tuple[float, ...] = ()
        self.taken: list[tuple[int, float]] = []  # the drive's actions so far: (k index, acceleration)
        self.actions: list[tuple[int, float]] | None = None  # the chosen drive's, which the episode repeats
        self.step = 0  # actions taken in this episode
        self.cruise: tuple[float, float] | None = None  # a cruise drive's (target speed [m/s], acceleration cap [m/s^2])
        self.other: Any = None  # a causal planner whose drive is a candidate (a network corridor's)
        self.expected: dict[str, Any] = {}  # the shipped row the episode replays: its travel time and cost (``verify``)
        self.case_label = ""

    # ------------------------------------------------------------------ planning
    def prepare(self, env: Any, case: Case) -> None:
        """Pick the drive the episode repeats: the shipped one, else the cheapest of ``plan``'s."""
        started = time.perf_counter()
        self.env, self.lane_y = env, traffic_lanes(env)
        self.tracks, self.rounds, self.actions, self.expected = None, [], None, {}
        self.case_label = f"case {case.index}"
        if self.shipped is not None:
            self.actions = drives.lookup(env.cfg, case, self.shipped)
            if self.actions is not None:
                self.expected = drives.about(env.cfg, case, self.shipped)
                self.rounds = [{"shipped": str(self.shipped.name), **self.expected}]
                return
        tried = self.plan(env, case)
        best = tried[pick(np.array([d[0] for d in tried]), np.array([d[1] for d in tried]), 0.0)]
        self.actions = best[2]
        self.rounds.append({"chosen_cost": round(best[0], 4), "chosen_time": best[1], "time_price": 0.0,
                            "wall_s": round(time.perf_counter() - started, 3)})

    def plan(self, env: Any, case: Case) -> list[tuple[float, float, list[tuple[int, float]]]]:
        """Every drive of ``case`` (module docstring): (cost, travel time [s], actions) each, in the
        order driven; ``rounds`` gets SUMO's driver's time and each drive's cost and time."""
        self.env, self.lane_y = env, traffic_lanes(env)
        self.tracks, self.rounds, self.actions = None, [{"sumo_driver_time": sumo_driver_time(env, case)}], None
        tried = []
        for r in range(ROUNDS):  # the planned drives, each but the first on the previous one's recording
            rec, cost, took = self._drive(env, case, record=r + 1 < ROUNDS)
            self.rounds.append({"round": r, "cost": round(cost, 4), "time": took, "recorded": self.tracks is not None})
            tried.append((cost, took, self.taken))
            self.tracks = Tracks.of(rec) if rec is not None else None
        for share in CRUISE_SPEEDS:
            for cap in CRUISE_ACCELS:
                self.cruise = (share * self.cfg.speed_limit, self.cfg.a_max if cap is None else min(cap, self.cfg.a_max))
                try:
                    _, cost, took = self._drive(env, case, record=False)
                finally:
                    self.cruise = None
                self.rounds.append({"round": len(self.rounds) - 1, "cost": round(cost, 4), "time": took,
                                    "recorded": False, "cruise": [share, cap if cap is not None else "a_max"]})
                tried.append((cost, took, self.taken))
        if self.cfg.network is not None:  # the causal planners' drives are candidates too, at each price of time
            from ecodrive_bench.bench.methods.mpc_agent import MPCAgent
            from ecodrive_bench.bench.methods.oracle_agent import OracleAgent

            for price in TIME_PRICES:
                priced = replace(self.cfg, reward=replace(self.cfg.reward, phi=self.cfg.reward.phi + price))
                for other in (MPCAgent(priced), OracleAgent(priced)):
                    self.other = other
                    try:
                        _, cost, took = self._drive(env, case, record=False)
                    finally:
                        self.other = None
                    self.rounds.append({"round": len(self.rounds) - 1, "cost": round(cost, 4), "time": took,
                                        "recorded": False, "planner": other.name, "time_price": price})
                    tried.append((cost, took, self.taken))
        return tried

    def _drive(self, env: Any, case: Case, record: bool = True) -> tuple[Recording | None, float, float]:
        """One drive of ``case``: its recording (None without ``record``: no drive follows it), its
        cost (E + phi T) and its travel time [s]."""
        obs, info = env.reset(seed=case.sumo_seed, options=case.options())
        xs, traffic = [info["position"]], [env.traffic()] if record else []
        while True:
            obs, _, terminated, truncated, info = env.step(self.act(obs, info))
            xs.append(info["position"])
            if record:
                traffic.append(env.traffic())
            if terminated or truncated:
                break
        cost = float(info["energy"] + env.cfg.reward.phi * info["travel_time"])
        return (Recording(env.t_depart, np.array(xs), tuple(traffic)) if record else None), cost, float(info["travel_time"])

    # ------------------------------------------------------------------ acting
    def _plan(self, k: int, x: float, v: float, lane: int, ids: tuple[str, ...], rows: np.ndarray):
        assert self.table is not None
        rear, speed = ahead_future(self.tracks, k, LOOKAHEAD, ids, rows, x, self.lane_y[lane])
        caps = gap_caps(rear, speed, -self.cfg.a_min, self.cor.x0)
        return planner.replan(self.table, k, x, v, lookahead=LOOKAHEAD, length=2, caps=caps)

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any], explore: bool = False):
        if info["travel_time"] == 0.0:  # the reset: a new episode
            self.step, self.taken = 0, []
        if self.actions is not None:  # the chosen drive, action for action
            if self.step >= len(self.actions):
                raise ShippedMismatch(f"clairvoyant, {self.case_label}: its drive has {len(self.actions)} actions and "
                                      f"the episode goes on past them; the drive is not this case's (rebuild: "
                                      f"{drives.REBUILD})")
            lateral, accel = self.actions[self.step]
            self.step += 1
            return self._action(lateral, accel)
        if self.other is not None:  # a causal planner's drive (a network corridor's candidates)
            out = (1, np.full(3, float(self.other.act(obs, info)[0]), dtype=np.float32))
        else:
            out = self._cruise(obs) if self.cruise is not None else self._closed_loop(obs, info)
        self.taken.append((int(out[0]), float(out[1][0])))
        return self._action(int(out[0]), float(out[1][0]))

    def _action(self, lateral: int, accel: float) -> Any:
        """The env's action: (lane decision, the acceleration's three copies), or on a network
        corridor (the ``longitudinal`` interface) the acceleration alone."""
        if self.action_interface == "longitudinal":
            return np.array([accel], dtype=np.float32)
        return lateral, np.full(3, accel, dtype=np.float32)

    def _cruise(self, obs: dict[str, np.ndarray]) -> tuple[int, np.ndarray]:
        """A cruise drive's action: stay in lane, towards the target speed at most at the cap."""
        assert self.cruise is not None
        target, cap = self.cruise
        return 1, self._towards(target, float(obs["logic"][self.cfg.observed_lanes + 1]), cap)

    def _towards(self, target: float, v: float, cap: float | None = None) -> np.ndarray:
        """The acceleration [m/s^2] that brings speed ``v`` to ``target`` in a step, within
        [a_min, ``cap``] (default a_max), as the action's three copies."""
        cfg = self.cfg
        accel = min(max((target - v) / cfg.step_length, cfg.a_min), cfg.a_max if cap is None else cap)
        return np.full(3, accel, dtype=np.float32)

    def _follows(self, k: int, x: float, v: float, lane: int, ids: tuple[str, ...], rows: np.ndarray) -> bool:
        """Whether the first plan still holds: the ego on it, and no vehicle ahead in its way over
        the look-ahead (the recorded future, the same gap as ``gap_caps``)."""
        p = self.first
        if p is None or k + 1 >= len(p.v) or abs(v - p.v[k]) > TOL_V or abs(x - p.x[k]) > TOL_X:
            return False
        rear, speed = ahead_future(self.tracks, k, LOOKAHEAD, ids, rows, x, self.lane_y[lane])
        m = np.arange(1, min(LOOKAHEAD, len(p.v) - 1 - k) + 1)
        pv = p.v[k + m]
        gap = np.maximum(0.0, HEADWAY * pv + (pv * pv - speed[m] * speed[m]) / (2.0 * -self.cfg.a_min))
        return not np.any(p.x[k + m] > rear[m] - MIN_GAP - MARGIN - gap)

    def _closed_loop(self, obs: dict[str, np.ndarray], info: dict[str, Any]):
        cfg, dt = self.cfg, self.cfg.step_length
        if info["travel_time"] == 0.0 or self.table is None:  # the reset: a new departure
            if self.env is None:
                raise RuntimeError("clairvoyant: prepare(env, case) records each case before its episode")
            self.t0 = float(info["time"])
            cor, first = self.cor, None
            if cfg.network is not None:  # a network corridor: from the speed traffic let the ego insert at
                cor = cor.starting(float(obs["logic"][cfg.observed_lanes + 1]), Grid().spacing(cfg, fine=False)[0])
            else:
                table = shipped_bounds.table() if self.shipped is not None else None
                first = table.mpc_plan(cfg, self.t0) if table is not None else None
            self.first, self.table = planner.start(cor, cfg, self.t0, first_plan=first)
            self.want = None
        k = int(round((float(info["time"]) - self.t0) / dt))
        x, v = float(info["position"]), float(obs["logic"][cfg.observed_lanes + 1])
        lane = int(np.argmax(obs["logic"][:cfg.observed_lanes]))
        ids, rows = self.env.traffic()
        if self.first is not None and self.want is None and self._follows(k, x, v, lane, ids, rows):
            if k % LANE_EVERY != 0:  # on the first plan, between looks at the lanes beside
                return 1, self._towards(float(self.first.v[k + 1]), v)
        else:
            self.first = None  # from here on every step re-plans on the global lattice
        here = self._plan(k, x, v, lane, ids, rows)
        if self.want == lane:
            self.want = None
        if (self.want is None and k % LANE_EVERY == 0 and here is not None and here.leader == "kept"
                and self.action_interface != "longitudinal"):
            mask = info["action_mask"]  # k index: 0 left (a higher lane), 1 stay, 2 right
            for index, other in ((0, lane + 1), (2, lane - 1)):
                if mask[index] and 0 <= other < cfg.lanes:
                    there = self._plan(k, x, v, other, ids, rows)
                    if there is not None and there.leader == "kept" and there.value < here.value - LANE_GAIN:
                        self.want = other
        k_index = 1 if self.want is None else (0 if self.want > lane else 2)
        if self.want is not None:
            self.first = None
        if self.first is not None:
            target = float(self.first.v[k + 1])
        else:
            target = float(here.v[1]) if here is not None and len(here.v) > 1 else cfg.speed_limit
        return k_index, self._towards(target, v)

    def verify(self, summary: dict[str, Any]) -> None:
        """Called with the episode's summary before its log is published: a replayed shipped drive
        must give its row's travel time exactly and its energy (the row's cost less phi times the
        time) within ``ENERGY_RTOL``, and use every action; else ``ShippedMismatch``, one line."""
        if not self.expected:
            return
        want_t = float(self.expected["travel_time"])
        want_e = float(self.expected["cost"]) - self.cfg.reward.phi * want_t
        got_t, got_e = float(summary["travel_time"]), float(summary["energy"])
        at = f"clairvoyant, {self.case_label}: its shipped drive ({drives.FILE.name})"
        if got_t != want_t:
            raise ShippedMismatch(f"{at} says {want_t:g} s, the replay took {got_t:g} s; rebuild: {drives.REBUILD}")
        if not close(got_e, want_e, ENERGY_RTOL):
            raise ShippedMismatch(f"{at} says {want_e:.6g} Wh, the replay used {got_e:.6g} Wh (beyond a relative "
                                  f"{ENERGY_RTOL:g}); rebuild: {drives.REBUILD}")
        if self.actions is not None and self.step != len(self.actions):
            raise ShippedMismatch(f"{at} has {len(self.actions)} actions, the episode ended after {self.step}; "
                                  f"rebuild: {drives.REBUILD}")

    @property
    def plan_trace(self) -> dict[str, Any] | None:
        """What planning the case found (step log metadata)."""
        return {"rounds": self.rounds} if self.rounds else None


def traffic_lanes(env: Any) -> tuple[float, ...]:
    """The lateral coordinate of each lane as ``env.traffic()`` gives it: its index times
    ``envs.route.LANE_PITCH``."""
    return tuple(i * LANE_PITCH for i in range(env.cfg.observed_lanes))


def sumo_driver_time(env: Any, case: Case) -> float:
    """SUMO's driver's travel time [s] on ``case`` on ``env``'s corridor: the ``baseline`` method's
    episode of it (the same case and scenario give the same episode), on an env of its own."""
    from ecodrive_bench.bench.methods.env import make_env

    other = make_env(BASELINE, env.cfg.signals, env.cfg.to_dict())
    try:
        _, info = other.reset(seed=case.sumo_seed, options=case.options())
        while True:
            _, _, terminated, truncated, info = other.step(0)
            if terminated or truncated:
                return float(info["travel_time"])
    finally:
        other.close()
