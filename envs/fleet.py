"""Mixed traffic: every CV of the W->E flow driven by one policy, decentralised, batched.

Each CV observes its own grid and logic vector and passes the same safety layer as the single
ego; one policy call per step acts for all of them. HDVs drive with Krauss + LC2013. The fleet
knows nothing about the agent: ``policy(grids, logics, masks)`` takes stacked arrays and returns
one action per CV, in the action type's format.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .action import make_action
from .config import ScenarioConfig
from .observation import GridLogicObservation
from .scenario import CV_FLOW, build
from .sumo import SumoSession
from .vehicle import ControlledVehicle

Policy = Callable[[np.ndarray, np.ndarray, np.ndarray], list]

STALL_SPEED = 0.5  # [m/s] below this a CV stands
STALL_FREE = 10.0  # [m] of free lane ahead, beyond which standing is not queueing


def stalled(grids: np.ndarray, logics: np.ndarray, cfg: ScenarioConfig) -> np.ndarray:
    """Per CV: standing with more than ``STALL_FREE`` m free ahead in its lane and no red light
    (queueing and waiting at red are not stalls). From the observations alone."""
    lanes = cfg.observed_lanes  # the logic vector's one-hot
    lane = logics[:, :lanes].argmax(1)
    front = int(round(cfg.grid_behind / cfg.cell_length))
    ahead = grids[np.arange(len(grids)), front:front + int(np.ceil(STALL_FREE / cfg.cell_length)) + 1, lane]
    free = (ahead >= 0.5).all(1)
    return (logics[:, lanes + 1] < STALL_SPEED) & free & (logics[:, lanes + 2] != 1.0)


@dataclass
class VehicleRecord:
    kind: str  # "cv" or "hdv"
    depart: float  # [s]
    energy: float = 0.0  # [Wh]
    arrive: float | None = None  # [s]
    distance: float | None = None  # [m] driven by the end of the run, for vehicles still driving then


@dataclass
class FleetStats:
    records: dict[str, VehicleRecord] = field(default_factory=dict)
    collisions: int = 0
    teleports: int = 0
    end_time: float = 0.0  # [s] simulation time when the run was closed
    pending: dict[str, int] = field(default_factory=dict)  # per kind: not yet inserted at the end
    sim_time_s: float = 0.0  # wall time inside simulationStep
    control_time_s: float = 0.0  # wall time observing, deciding and applying
    steps: int = 0
    stall_steps: int = 0  # CV-steps stalled (see ``stalled``)
    longest_stall_s: float = 0.0  # [s] longest run of stalled steps of one CV


class Fleet:
    def __init__(self, cfg: ScenarioConfig, action: str = "parameterized") -> None:
        self.cfg = cfg
        self.files = build(cfg)
        self.session = SumoSession(cfg, self.files)
        self.obs_type = GridLogicObservation(cfg, self.files)
        self.action_type = make_action(action, cfg)
        self.cvs: dict[str, ControlledVehicle] = {}
        self.active: dict[str, VehicleRecord] = {}  # arterial vehicles still in the network
        self.stats = FleetStats()
        self._stall: dict[str, int] = {}  # CV -> current run of stalled steps
        self._arterial_prefixes = (f"{CV_FLOW}.", "art.")

    def start(self, seed: int) -> None:
        self.session.start(seed)
        self.cvs.clear()
        self.active.clear()
        self._stall.clear()
        self.stats = FleetStats()

    def step(self, policy: Policy | None) -> int:
        """One simulation step; returns the number of CVs controlled in it."""
        s, st = self.session, self.stats
        t0 = time.perf_counter()
        n = len(self.cvs)
        if n and policy is not None:
            ids = list(self.cvs)
            obs = [self.cvs[v].observe() for v in ids]
            grids = np.stack([o["grid"] for o in obs])
            logics = np.stack([o["logic"] for o in obs])
            masks = np.stack([self.cvs[v].mask for v in ids])
            self._count_stalls(ids, stalled(grids, logics, self.cfg))
            for vid, action in zip(ids, policy(grids, logics, masks)):
                self.cvs[vid].apply(self.action_type.decode(action))
        t1 = time.perf_counter()
        s.step()
        t2 = time.perf_counter()
        now = s.time()
        st.collisions += len(s.collisions())
        st.teleports += len(s.teleports())
        for vid in s.arrived():
            rec = self.active.pop(vid, None)
            if rec is not None:
                rec.arrive = now
            self.cvs.pop(vid, None)
            self._stall.pop(vid, None)
        for vid in s.departed():
            if vid.startswith(self._arterial_prefixes):
                cv = vid.startswith(f"{CV_FLOW}.")
                st.records[vid] = self.active[vid] = VehicleRecord("cv" if cv else "hdv", now - self.cfg.step_length)
                if cv and policy is not None:
                    s.subscribe(vid)
                    s.take_control(vid)
                    self.cvs[vid] = ControlledVehicle(vid, s, self.obs_type, self.cfg)
        dt = self.cfg.step_length
        for vid, rec in self.active.items():  # only vehicles still driving: the records grow all run
            rec.energy += s.energy_rate(vid) * dt
        for cv in self.cvs.values():
            if cv._pending:
                cv.measure()
        st.sim_time_s += t2 - t1
        st.control_time_s += (t1 - t0) + (time.perf_counter() - t2)
        st.steps += 1
        return n

    def sim_time(self) -> float:
        """[s] the simulation's time."""
        return self.session.time()

    def stall_run(self, vid: str) -> int:
        """Steps CV ``vid`` has been stalled in a row, this step included (0 when it is not)."""
        return self._stall.get(vid, 0)

    def _count_stalls(self, ids: list[str], now_stalled: np.ndarray) -> None:
        st, runs = self.stats, self._stall
        for vid, stall in zip(ids, now_stalled):
            if stall:
                runs[vid] = runs.get(vid, 0) + 1
                st.stall_steps += 1
                st.longest_stall_s = max(st.longest_stall_s, runs[vid] * self.cfg.step_length)
            else:
                runs.pop(vid, None)

    def summary(self, route_length: float) -> dict[str, Any]:
        """Per kind (all, cv, hdv). As the paper: mean energy [Wh/veh], travel time [s] and speed
        [m/s] of the vehicles that finished. Those means favour a congested run (its slow vehicles
        are still inside at the end), so also, over every vehicle inserted: energy per distance
        [Wh/km] and space-mean speed (distance / time in the network) [m/s], with the counts of
        vehicles inserted, still driving at the end (``unfinished``) and never inserted (``pending``).
        Call after ``close``, which records where the unfinished vehicles got to."""
        st = self.stats
        out: dict[str, Any] = {}
        for kind in ("all", "cv", "hdv"):
            recs = [r for r in st.records.values() if kind in ("all", r.kind)]
            done = [r for r in recs if r.arrive is not None]
            tt = np.array([r.arrive - r.depart for r in done])
            dist = sum(route_length if r.arrive is not None else (r.distance or 0.0) for r in recs)
            time_in = sum((r.arrive if r.arrive is not None else st.end_time) - r.depart for r in recs)
            nan = float("nan")
            out[kind] = {"vehicles": len(done),
                         "energy": float(np.mean([r.energy for r in done])) if done else nan,
                         "travel_time": float(tt.mean()) if done else nan,
                         "speed": float(np.mean(route_length / tt)) if done else nan,
                         "inserted": len(recs), "unfinished": len(recs) - len(done),
                         "pending": sum(v for k, v in st.pending.items() if kind in ("all", k)),
                         "energy_per_km": 1000.0 * sum(r.energy for r in recs) / dist if dist > 0 else nan,
                         "space_mean_speed": dist / time_in if time_in > 0 else nan}
        out["collisions"], out["teleports"] = st.collisions, st.teleports
        out["stall_steps"], out["longest_stall_s"] = st.stall_steps, st.longest_stall_s
        return out

    def close(self) -> None:
        """Record where the vehicles still driving got to and who never got in, then stop SUMO."""
        s, st = self.session, self.stats
        if s.running:
            st.end_time = s.time()
            for vid, rec in self.active.items():
                rec.distance = s.odometer(vid)
            pending = [v for v in s.pending() if v.startswith(self._arterial_prefixes)]
            st.pending = {"cv": sum(v.startswith(f"{CV_FLOW}.") for v in pending)}
            st.pending["hdv"] = len(pending) - st.pending["cv"]
        s.close()
