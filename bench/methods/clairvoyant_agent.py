"""The ``clairvoyant`` method: the top of the benchmark's scale, a planner that knows the case's future.

It knows what no causal method can: the signal plans, and the future of every other vehicle of
the case (the traffic is deterministic given the case's SUMO seed). Before its episode the harness
calls ``prepare(env, case)``, which drives the case on the worker's own env to record that future
(``bench.oracle.clairvoyant.Recording``, every eastbound vehicle at every step).

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
layer; the episode replays the one that cost least (E + phi T): its actions, one by one, which
drive that very episode again, since a case is deterministic.

For the fixed cases the chosen drives are shipped (``bench.cases.clairvoyant_drives``): ``prepare``
reads the case's actions instead of planning, where they answer its problem.

It drives the ``parameterized`` action: the lane decision (the LC2013 mask may refuse it) and the
acceleration that brings its speed to the plan's next one, through the same safety layer as
every method.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.cases import clairvoyant_drives as drives
from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.hosts import ENERGY_RTOL, close
from ecodrive_bench.bench.methods.not_learning import NotLearning
from ecodrive_bench.bench.methods.planners import CLAIRVOYANT as NAME
from ecodrive_bench.bench.oracle import mpc as planner
from ecodrive_bench.bench.oracle.clairvoyant import MARGIN, Recording, Tracks, ahead_future, gap_caps
from ecodrive_bench.bench.oracle.dp import Corridor
from ecodrive_bench.bench.oracle.mpc import HEADWAY, MIN_GAP
from ecodrive_bench.envs.config import ScenarioConfig

LOOKAHEAD = 40  # [steps] of known traffic in each re-plan
LANE_EVERY = 5  # [steps] between looks at the lanes beside the ego's
LANE_GAIN = 1.0  # [Wh] a lane beside is taken when its plan costs this much less
ROUNDS = 3  # [-] planned drives per case (the first without a recording), before the cruises
CRUISE_SPEEDS = (1.0, 0.95, 0.9, 0.85, 0.8, 0.75, 0.7)  # [-] target speeds of the cruise drives, shares of the limit
CRUISE_ACCELS = (None, 1.5, 0.75)  # [m/s^2] their acceleration caps (None: a_max, full throttle)
TOL_V = 0.05  # [m/s] speed drift that leaves the first plan for re-plans (as mpc)
TOL_X = 0.6  # [m] position drift that does the same (beyond about a row of the global lattice)


class ClairvoyantAgent(NotLearning):
    """Drives each case knowing its future traffic (``prepare`` records it); never learns."""

    name = NAME
    action_interface = "parameterized"
    env_overrides: dict[str, Any] = {}

    def __init__(self, cfg: ScenarioConfig, shipped: Path | None = drives.FILE) -> None:
        self.cfg = cfg
        self.shipped = shipped  # the shipped drives of the fixed cases (bench.cases.clairvoyant_drives); None: plan
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

    # ------------------------------------------------------------------ planning
    def prepare(self, env: Any, case: Case) -> None:
        """Record ``case`` and pick the drive the episode repeats (module docstring)."""
        started = time.perf_counter()
        self.env, self.lane_y = env, env.files.lane_y
        self.tracks, self.rounds, self.actions = None, [], None
        if self.shipped is not None:
            self.actions = drives.lookup(env.cfg, case, self.shipped)
            if self.actions is not None:
                self.rounds = [{"shipped": str(self.shipped.name)}]
                return
        tried = []  # (cost, actions) of each drive
        for r in range(ROUNDS):  # the planned drives, each but the first on the previous one's recording
            rec, cost = self._drive(env, case, record=r + 1 < ROUNDS)
            self.rounds.append({"round": r, "cost": round(cost, 4), "recorded": self.tracks is not None})
            tried.append((cost, self.taken))
            self.tracks = Tracks.of(rec) if rec is not None else None
        for share in CRUISE_SPEEDS:
            for cap in CRUISE_ACCELS:
                self.cruise = (share * self.cfg.speed_limit, self.cfg.a_max if cap is None else min(cap, self.cfg.a_max))
                try:
                    _, cost = self._drive(env, case, record=False)
                finally:
                    self.cruise = None
                self.rounds.append({"round": len(self.rounds), "cost": round(cost, 4), "recorded": False,
                                    "cruise": [share, cap if cap is not None else "a_max"]})
                tried.append((cost, self.taken))
        best = min(tried, key=lambda d: d[0])  # the first of equal costs
        self.actions = best[1]
        self.rounds.append({"chosen_cost": round(best[0], 4), "wall_s": round(time.perf_counter() - started, 3)})

    def _drive(self, env: Any, case: Case, record: bool = True) -> tuple[Recording | None, float]:
        """One drive of ``case``: its recording (None without ``record``: no drive follows it) and its cost."""
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
        return (Recording(env.t_depart, np.array(xs), tuple(traffic)) if record else None), cost

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
            lateral, accel = self.actions[min(self.step, len(self.actions) - 1)]
            self.step += 1
            return lateral, np.full(3, accel, dtype=np.float32)
        out = self._cruise(obs) if self.cruise is not None else self._closed_loop(obs, info)
        self.taken.append((int(out[0]), float(out[1][0])))
        return out

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
            table = shipped_bounds.table() if self.shipped is not None else None
            first = table.mpc_plan(cfg, self.t0) if table is not None else None
            self.first, self.table = planner.start(self.cor, cfg, self.t0, first_plan=first)
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
        if self.want is None and k % LANE_EVERY == 0 and here is not None and here.leader == "kept":
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

    @property
    def plan_trace(self) -> dict[str, Any] | None:
        """What planning the case found (step log metadata)."""
        return {"rounds": self.rounds} if self.rounds else None


def solve(task: tuple[str, Case]) -> dict[str, Any]:
    """One fixed case planned from scratch (in a worker)."""
    from ecodrive_bench.bench.cases.setting import setting
    from ecodrive_bench.bench.methods.env import make_env

    signals, case = task
    cfg = setting(signals, None)
    agent = ClairvoyantAgent(cfg, shipped=None)
    env = make_env(agent, signals, None)
    try:
        agent.prepare(env, case)
    finally:
        env.close()
    return drives.entry(signals, case, cfg, agent)


def check(path: Path = drives.FILE, per_setting: int = drives.CHECK_PER_SETTING) -> list[str]:
    """One line per drift ([]: none) on a sample of the shipped cases, planned again."""
    from ecodrive_bench.bench.cases.case import load

    try:
        frame = drives.read(path)
    except drives.DrivesError as e:
        return [str(e)]
    cases = {c.index: c for c in load()}
    lines = []
    for s in sorted(set(frame.signals)):
        rows = frame[frame.signals == s].sort_values("case")
        pick = np.random.default_rng(20261127).choice(len(rows), size=min(per_setting, len(rows)), replace=False)
        for r in rows.iloc[np.sort(pick)].itertuples(index=False):
            got = solve((s, cases[int(r.case)]))
            at = f"{path}: {s} case {int(r.case)}"
            if list(got["lateral"]) != [int(a) for a in r.lateral]:
                lines.append(f"{at}: the lane decisions differ from a new plan's; rebuild: {drives.REBUILD}")
            elif not np.allclose(got["accel"], list(r.accel), rtol=drives.ACCEL_RTOL, atol=1e-9):
                lines.append(f"{at}: the accelerations differ beyond a relative {drives.ACCEL_RTOL:g}; rebuild: {drives.REBUILD}")
            elif not close(got["cost"], float(r.cost), ENERGY_RTOL):
                lines.append(f"{at}: cost {float(r.cost)!r} stored, {got['cost']!r} planned; rebuild: {drives.REBUILD}")
    return lines
