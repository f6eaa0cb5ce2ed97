"""SUMO sessions: the only module that talks to SUMO (libsumo in-process, or TraCI).

Every query and command takes a vehicle ID, so the same session serves one ego or hundreds of
controlled vehicles.

libsumo holds one simulation per process. The first session of a process to start takes it (the
fast path: no socket, about 1 ms per step on the corridor); a session that starts while another
one holds libsumo runs its own SUMO process through TraCI with its own label instead, so several
envs in one process (``gymnasium``'s sync vector env, Stable-Baselines3's ``DummyVecEnv``) each
drive their own simulation. The two paths run the same SUMO build on the same inputs and give
the same numbers (``tests/envs/test_sessions.py`` compares every step's energy); TraCI is slower
per call, so for throughput use one process per env (``gym.make_vec(...,
vectorization_mode="async")``).

A session that holds libsumo and is garbage-collected without ``close()`` (an env dropped
mid-episode) gives it up then (``weakref.finalize``), so the next env of the process runs there
rather than through TraCI; not at the interpreter's exit, where the process ends anyway. (A
TraCI-run SUMO ends by itself when its dropped connection's socket closes.)
"""
from __future__ import annotations

import time
import weakref
from dataclasses import dataclass
from typing import Any, NamedTuple

import libsumo as ls
import numpy as np
from libsumo import constants as tc

from .config import ScenarioConfig
from .scenario import EGO_ROUTE, EGO_TYPE, GLOSA_TYPE, HDV_TYPE, ScenarioFiles

_LIBSUMO_OWNER: weakref.ref[SumoSession] | None = None  # the session running in this process's libsumo


def _libsumo_owner() -> SumoSession | None:
    return None if _LIBSUMO_OWNER is None else _LIBSUMO_OWNER()


def _release_libsumo() -> None:
    """libsumo given up by a session that was garbage-collected while it held it (its finalizer;
    also called before a start that finds such a session)."""
    global _LIBSUMO_OWNER
    if _LIBSUMO_OWNER is not None and _LIBSUMO_OWNER() is None:
        _LIBSUMO_OWNER = None
        try:
            ls.close()
        except Exception:  # noqa: BLE001  (nothing to give up: it was not running)
            pass


TRACI_CONNECT_TIMEOUT = 60.0  # [s] for a TraCI-run SUMO to load the scenario and accept the connection


def _traci_start(args: list[str]) -> Any:
    """A SUMO process of its own on a free local port, and the TraCI connection to it (polled every
    10 ms: ``traci.start`` waits whole seconds between tries and prints each)."""
    import subprocess
    import time

    import sumolib  # noqa: PLC0415  (pure Python: finds the SUMO binary of the installed wheel)
    from traci.connection import Connection  # noqa: PLC0415

    port = sumolib.miscutils.getFreeSocketPort()
    proc = subprocess.Popen([sumolib.checkBinary("sumo"), *args, "--remote-port", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + TRACI_CONNECT_TIMEOUT
    while True:
        try:
            return Connection("localhost", port, proc, None, False)
        except OSError as e:
            if proc.poll() is not None:
                err = (proc.stderr.read() if proc.stderr else b"").decode(errors="replace").strip()
                raise RuntimeError(f"SUMO (TraCI, port {port}) exited with code {proc.returncode}: "
                                   f"{err.splitlines()[-1] if err else 'no message'}") from None
            if time.monotonic() > deadline:
                proc.kill()
                raise RuntimeError(f"SUMO (TraCI) did not accept a connection on port {port} within "
                                   f"{TRACI_CONNECT_TIMEOUT:g} s ({e})") from None
            time.sleep(0.01)
# context-subscription variables, as keys of ``neighbours()`` results
VAR_POSITION, VAR_ANGLE, VAR_LENGTH = tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LENGTH
_GREEN = frozenset("gG")

# speed mode 27 = 31 without bit 2 ("regard maximum deceleration"): SUMO's Krauss safe speed clips
# any commanded speed, and when it asks for more braking than the vType's decel (4 m/s^2 = -a_min)
# the vehicle brakes harder, up to its emergencyDecel, as SUMO's own drivers do. With bit 2 on, an
# HDV stopping at a yellow light at its decel of 4.5 m/s^2 in front of a CV (mixed traffic) ended
# in a collision. Commanded speeds never need more than the action bound a_min.
SPEED_MODE_SAFE = 27
# lane-change mode 513: TraCI requests respect the others' gaps, and SUMO makes only the strategic
# changes a route needs (a lane that does not continue it, before a turn) where no TraCI request
# conflicts; the agent decides every other change
LC_MODE_EXTERNAL = 513
LC_MODE_DEFAULT = 1621  # SUMO's default (LC2013 decides)


def sumo_version() -> str:
    """SUMO's version number, e.g. '1.28.0'."""
    return str(ls.getVersion()[1]).removeprefix("SUMO ").strip()


class Kinematics(NamedTuple):
    """One vehicle's state after a step, as SUMO reports it."""

    x: float  # [m] front bumper
    y: float  # [m]
    angle: float  # [deg] SUMO heading
    speed: float  # [m/s]
    accel: float  # [m/s^2]
    lane: int  # lane index, 0 = rightmost
    edge: str  # road id (":..." inside a junction)


@dataclass
class TlsPlan:
    """Phase durations [s] and states of one signal, for time-to-green look-ups."""

    durations: list[float]
    states: list[str]


class SumoSession:
    """Owns the running simulation. Created by the environment; agents never see it."""

    def __init__(self, cfg: ScenarioConfig, files: ScenarioFiles) -> None:
        self.cfg = cfg
        self.files = files
        self.running = False
        self.backend = ""  # "libsumo" or "traci" while running
        self._api: Any = _Closed()  # the libsumo module, or this session's TraCI connection
        self.busy = False  # in the middle of an episode: its libsumo is not handed to another session
        self.sumo_seconds = 0.0  # [s] wall time inside SUMO since start(): loading and stepping (the floor)
        self._plans: dict[str, TlsPlan] = {}
        self._lanes: dict[str, tuple[tuple[tuple[float, float], ...], float]] = {}  # lane id -> (shape, width)
        self._edge_lanes: dict[str, int] = {}
        self._finalizer: weakref.finalize | None = None  # gives libsumo up if this is dropped holding it
        self._context_range = max(cfg.grid_ahead, cfg.grid_behind) + 2 * cfg.vehicle_length

    # ------------------------------------------------------------------ lifecycle
    def command(self, seed: int) -> list[str]:
        f = self.files
        begin = ["--begin", f"{f.begin:g}"] if f.begin else []
        return [
            "sumo", "-n", str(f.net), "-r", ",".join(map(str, (f.routes, *f.demand))), "-a", str(f.additional), *begin,
            "--step-length", f"{self.cfg.step_length:g}", "--seed", str(int(seed)),
            "--lanechange.duration", f"{self.cfg.lane_change_duration:g}",
            "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
            "--collision.check-junctions", "true" if f.check_junctions else "false", "--xml-validation", "never",
        ]

    def start(self, seed: int) -> None:
        """(Re)start this session's simulation: in libsumo if no other session of the process
        is in the middle of an episode there (one whose episode is over gives libsumo up and is
        closed), else in a SUMO process of its own through TraCI."""
        global _LIBSUMO_OWNER
        self.close()
        t0 = time.perf_counter()
        _release_libsumo()  # a collected owner's, if its finalizer has not run
        owner = _libsumo_owner()
        if owner is not None and not owner.busy:
            owner.close()
        if _libsumo_owner() is None:
            ls.start(self.command(seed))
            _LIBSUMO_OWNER, self._api, self.backend = weakref.ref(self), ls, "libsumo"
            self._finalizer = weakref.finalize(self, _release_libsumo)
            self._finalizer.atexit = False  # at the interpreter's exit the process ends anyway
        else:
            self._api, self.backend = _traci_start(self.command(seed)[1:]), "traci"
        self.busy = True
        self.running = True
        self.sumo_seconds = time.perf_counter() - t0  # loading counts, as the warm-up's steps will
        if not self._plans:
            api = self._api
            for tls in self.files.tls_ids:
                logic = api.trafficlight.getAllProgramLogics(tls)
                prog = api.trafficlight.getProgram(tls)
                lg = next(lo for lo in logic if lo.programID == prog)
                self._plans[tls] = TlsPlan([p.duration for p in lg.phases], [p.state for p in lg.phases])

    def close(self) -> None:
        global _LIBSUMO_OWNER
        if self._finalizer is not None:
            self._finalizer.detach()
            self._finalizer = None
        if self.running:
            self._api.close()
            self.running = False
        self.busy = False
        if _libsumo_owner() is self:
            _LIBSUMO_OWNER = None
        self._api, self.backend = _Closed(), ""

    # ------------------------------------------------------------------ simulation
    def time(self) -> float:
        return self._api.simulation.getTime()

    def step(self, until: float = 0.0) -> None:
        t0 = time.perf_counter()
        self._api.simulationStep(until)
        self.sumo_seconds += time.perf_counter() - t0

    def departed(self) -> tuple[str, ...]:
        return self._api.simulation.getDepartedIDList()

    def arrived(self) -> tuple[str, ...]:
        return self._api.simulation.getArrivedIDList()

    def collisions(self) -> list[tuple[str, str]]:
        return [(c.collider, c.victim) for c in self._api.simulation.getCollisions()]

    def teleports(self) -> tuple[str, ...]:
        return self._api.simulation.getStartingTeleportIDList()

    def pending(self) -> tuple[str, ...]:
        """Vehicles due to depart that SUMO could not insert yet (the entry is blocked)."""
        return self._api.simulation.getPendingVehicles()

    def vehicle_ids(self) -> tuple[str, ...]:
        return self._api.vehicle.getIDList()

    def present(self, vid: str) -> bool:
        """Whether ``vid`` is in ``vehicle_ids()`` (on a road, parking or placed by TraCI), asked of
        the one vehicle instead of fetching the whole list: SUMO names the road of such a vehicle,
        gives "" for any other it knows (not yet inserted, teleporting), and does not know one that
        has arrived or was removed."""
        try:
            return self._api.vehicle.getRoadID(vid) != ""
        except Exception as e:  # libsumo's and traci's TraCIException: distinct classes, one name
            if type(e).__name__ == "TraCIException":
                return False
            raise

    def on_route(self, exclude: str, lanes: dict[str, tuple[float, int]], pitch: float) -> tuple[tuple[str, ...], np.ndarray]:
        """Every vehicle but ``exclude`` on a lane of the route
        (``lanes``: lane id -> its start along the route frame [m], its lane index), one row each of
        front bumper position along the route [m], lane index times ``pitch`` [m], length [m], speed [m/s]."""
        v = self._api.vehicle
        ids, rows = [], []
        for vid in v.getIDList():
            place = lanes.get(v.getLaneID(vid)) if vid != exclude else None
            if place is None:
                continue
            ids.append(vid)
            rows.append((place[0] + v.getLanePosition(vid), place[1] * pitch, v.getLength(vid), v.getSpeed(vid)))
        return tuple(ids), np.array(rows, dtype=float).reshape(-1, 4)

    # ------------------------------------------------------------------ vehicles
    def add_vehicle(self, vid: str, controlled: bool, glosa: bool = False) -> None:
        """Insert a vehicle of the EV type at the arterial's start, now."""
        vtype = GLOSA_TYPE if glosa else EGO_TYPE
        self._api.vehicle.add(vid, EGO_ROUTE, typeID=vtype, depart="now", departLane="best", departSpeed="max")
        self.subscribe(vid)
        if controlled:
            self.take_control(vid)

    def subscribe(self, vid: str) -> None:
        """Context subscription of the vehicles around ``vid`` (read by ``neighbours``)."""
        self._api.vehicle.subscribeContext(vid, tc.CMD_GET_VEHICLE_VARIABLE, self._context_range,
                                    [VAR_POSITION, VAR_ANGLE, VAR_LENGTH])

    def add_scripted(self, vid: str, lane: int, pos: float, speed: float) -> None:
        """Insert a human-driven vehicle at an exact spot of the arterial's first edge, held at
        ``speed`` with its own safety checks off and no lane changes (scripted scenarios, tests)."""
        self._api.vehicle.add(vid, EGO_ROUTE, typeID=HDV_TYPE, depart="now", departLane=str(lane),
                       departPos=f"{pos:.2f}", departSpeed=f"{speed:.3f}")
        self._api.vehicle.setSpeedMode(vid, 0)
        self._api.vehicle.setLaneChangeMode(vid, 0)
        self._api.vehicle.setSpeed(vid, speed)

    def release_speed(self, vid: str) -> None:
        """Hand a scripted vehicle back to Krauss (safety checks on, no commanded speed)."""
        self._api.vehicle.setSpeedMode(vid, SPEED_MODE_SAFE)
        self._api.vehicle.setSpeed(vid, -1)

    def take_control(self, vid: str) -> None:
        self._api.vehicle.setSpeedMode(vid, SPEED_MODE_SAFE)
        self._api.vehicle.setLaneChangeMode(vid, LC_MODE_EXTERNAL)

    def lateral_to_sumo(self, vid: str, lc2013: bool) -> None:
        self._api.vehicle.setLaneChangeMode(vid, LC_MODE_DEFAULT if lc2013 else LC_MODE_EXTERNAL)

    def kinematics(self, vid: str) -> Kinematics:
        v = self._api.vehicle
        x, y = v.getPosition(vid)
        return Kinematics(x, y, v.getAngle(vid), v.getSpeed(vid), v.getAcceleration(vid), v.getLaneIndex(vid),
                          v.getRoadID(vid))

    def neighbours(self, vid: str) -> dict[str, dict[int, object]]:
        """Vehicles within the context range: id -> {var: value} (the vehicle itself included)."""
        return self._api.vehicle.getContextSubscriptionResults(vid)

    def position(self, vid: str) -> tuple[float, float]:
        """(x, y) [m] of the vehicle's front bumper."""
        x, y = self._api.vehicle.getPosition(vid)
        return x, y

    def lane_place(self, vid: str) -> tuple[str, float]:
        """(lane id, position along it [m]) of the vehicle's front bumper."""
        v = self._api.vehicle
        return v.getLaneID(vid), v.getLanePosition(vid)

    def lane_geometry(self, lane: str) -> tuple[tuple[tuple[float, float], ...], float]:
        """(shape, width [m]) of ``lane``: static, so read once per lane and kept."""
        geo = self._lanes.get(lane)
        if geo is None:
            geo = self._lanes[lane] = (tuple(self._api.lane.getShape(lane)), self._api.lane.getWidth(lane))
        return geo

    def edge_lanes(self, edge: str) -> int:
        """Number of lanes of ``edge`` (static, kept)."""
        n = self._edge_lanes.get(edge)
        if n is None:
            n = self._edge_lanes[edge] = self._api.edge.getLaneNumber(edge)
        return n

    def route_lanes(self, vid: str) -> dict[int, bool]:
        """Lane index -> whether that lane of the vehicle's edge continues its route (SUMO's best lanes)."""
        return {int(lane.rsplit("_", 1)[1]): bool(cont) for lane, _, _, _, cont, _ in self._api.vehicle.getBestLanes(vid)}

    def odometer(self, vid: str) -> float:
        """Distance [m] driven since insertion."""
        return self._api.vehicle.getDistance(vid)

    def energy_rate(self, vid: str) -> float:
        """Electric power drawn now [Wh/s]; negative while recuperating."""
        return self._api.vehicle.getElectricityConsumption(vid)

    def battery_totals(self, vid: str) -> tuple[float, float]:
        """(consumed, regenerated) [Wh] from the battery device."""
        g = self._api.vehicle.getParameter
        return (float(g(vid, "device.battery.totalEnergyConsumed")),
                float(g(vid, "device.battery.totalEnergyRegenerated")))

    def set_speed(self, vid: str, speed: float) -> None:
        self._api.vehicle.setSpeed(vid, speed)

    def change_lane(self, vid: str, direction: int) -> None:
        """Request a change by ``direction`` lanes (SUMO sign: +1 left, -1 right)."""
        self._api.vehicle.changeLaneRelative(vid, direction, self.cfg.step_length)

    def could_change(self, vid: str, direction: int) -> bool:
        """LC2013's safety verdict for a change in ``direction`` (SUMO sign: +1 left)."""
        return self._api.vehicle.couldChangeLane(vid, direction)

    def leader(self, vid: str, dist: float) -> tuple[str, float] | None:
        res = self._api.vehicle.getLeader(vid, dist)
        return None if res is None or res[0] == "" else (res[0], res[1])

    def follow_speed(self, vid: str, speed: float, gap: float, leader_speed: float, leader_decel: float) -> float:
        """Krauss safe following speed [m/s] of ``vid`` for the given situation."""
        return self._api.vehicle.getFollowSpeed(vid, speed, gap, leader_speed, leader_decel)

    # ------------------------------------------------------------------ signals
    def next_signal(self, vid: str) -> tuple[str, int, float, str] | None:
        """(tls id, link index, distance to stop line [m], state char) of the next signal."""
        nxt = self._api.vehicle.getNextTLS(vid)
        return nxt[0] if nxt else None

    def time_to_green(self, tls: str, link: int) -> float:
        """Seconds until ``link`` of ``tls`` turns green (0 when green now)."""
        plan = self._plans[tls]
        phase = self._api.trafficlight.getPhase(tls)
        if plan.states[phase][link] in _GREEN:
            return 0.0
        t = self._api.trafficlight.getNextSwitch(tls) - self._api.simulation.getTime()
        n = len(plan.states)
        for i in range(1, n):
            j = (phase + i) % n
            if plan.states[j][link] in _GREEN:
                return t
            t += plan.durations[j]
        return t

    def signal_states(self, tls_ids: tuple[str, ...]) -> list[str]:
        return [self._api.trafficlight.getRedYellowGreenState(t) for t in tls_ids]


class _Closed:
    """Stands for the simulation of a session that is not running: any call is one clear error."""

    def __getattr__(self, name: str) -> Any:
        raise RuntimeError("the SUMO session is not running: call reset() first (or it was closed)")
