"""The single libsumo session of a process: the only module that imports libsumo.

Every query and command takes a vehicle ID, so the same session serves one ego or hundreds of
controlled vehicles. libsumo allows one simulation per process; a second ``start`` closes the
first.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import libsumo as ls
from libsumo import constants as tc

from .config import ScenarioConfig
from .scenario import EGO_ROUTE, EGO_TYPE, GLOSA_TYPE, HDV_TYPE, ScenarioFiles

_ACTIVE: SumoSession | None = None
# context-subscription variables, as keys of ``neighbours()`` results
VAR_POSITION, VAR_ANGLE, VAR_LENGTH, VAR_SPEED = tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LENGTH, tc.VAR_SPEED
_GREEN = frozenset("gG")

# speed mode 27 = 31 without bit 2 ("regard maximum deceleration"): SUMO's Krauss safe speed clips
# any commanded speed, and when it asks for more braking than the vType's decel (4 m/s^2 = -a_min)
# the vehicle brakes harder, up to its emergencyDecel, as SUMO's own drivers do. With bit 2 on, an
# HDV stopping at a yellow light at its decel of 4.5 m/s^2 in front of a CV (mixed traffic) ended
# in a collision. Commanded speeds never need more than the action bound a_min.
SPEED_MODE_SAFE = 27
# lane-change mode 512: no autonomous changes; TraCI requests respect the others' gaps
LC_MODE_EXTERNAL = 512
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
        self._plans: dict[str, TlsPlan] = {}
        self._context_range = max(cfg.grid_ahead, cfg.grid_behind) + 2 * cfg.vehicle_length

    # ------------------------------------------------------------------ lifecycle
    def command(self, seed: int) -> list[str]:
        f = self.files
        return [
            "sumo", "-n", str(f.net), "-r", str(f.routes), "-a", str(f.additional),
            "--step-length", f"{self.cfg.step_length:g}", "--seed", str(int(seed)),
            "--lanechange.duration", f"{self.cfg.lane_change_duration:g}",
            "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
            "--collision.check-junctions", "true", "--xml-validation", "never",
        ]

    def start(self, seed: int) -> None:
        global _ACTIVE
        if _ACTIVE is not None and _ACTIVE.running:
            _ACTIVE.close()
        ls.start(self.command(seed))
        _ACTIVE = self
        self.running = True
        if not self._plans:
            for tls in self.files.tls_ids:
                logic = ls.trafficlight.getAllProgramLogics(tls)
                prog = ls.trafficlight.getProgram(tls)
                lg = next(lo for lo in logic if lo.programID == prog)
                self._plans[tls] = TlsPlan([p.duration for p in lg.phases], [p.state for p in lg.phases])

    def close(self) -> None:
        global _ACTIVE
        if self.running:
            ls.close()
            self.running = False
        if _ACTIVE is self:
            _ACTIVE = None

    # ------------------------------------------------------------------ simulation
    @staticmethod
    def time() -> float:
        return ls.simulation.getTime()

    @staticmethod
    def step(until: float = 0.0) -> None:
        ls.simulationStep(until)

    @staticmethod
    def departed() -> tuple[str, ...]:
        return ls.simulation.getDepartedIDList()

    @staticmethod
    def arrived() -> tuple[str, ...]:
        return ls.simulation.getArrivedIDList()

    @staticmethod
    def collisions() -> list[tuple[str, str]]:
        return [(c.collider, c.victim) for c in ls.simulation.getCollisions()]

    @staticmethod
    def teleports() -> tuple[str, ...]:
        return ls.simulation.getStartingTeleportIDList()

    @staticmethod
    def pending() -> tuple[str, ...]:
        """Vehicles due to depart that SUMO could not insert yet (the entry is blocked)."""
        return ls.simulation.getPendingVehicles()

    @staticmethod
    def vehicle_ids() -> tuple[str, ...]:
        return ls.vehicle.getIDList()

    # ------------------------------------------------------------------ vehicles
    def add_vehicle(self, vid: str, controlled: bool, glosa: bool = False) -> None:
        """Insert a vehicle of the EV type at the arterial's start, now."""
        vtype = GLOSA_TYPE if glosa else EGO_TYPE
        ls.vehicle.add(vid, EGO_ROUTE, typeID=vtype, depart="now", departLane="best", departSpeed="max")
        self.subscribe(vid)
        if controlled:
            self.take_control(vid)

    def subscribe(self, vid: str) -> None:
        """Context subscription of the vehicles around ``vid`` (read by ``neighbours``)."""
        ls.vehicle.subscribeContext(vid, tc.CMD_GET_VEHICLE_VARIABLE, self._context_range,
                                    [VAR_POSITION, VAR_ANGLE, VAR_LENGTH, VAR_SPEED])

    @staticmethod
    def add_scripted(vid: str, lane: int, pos: float, speed: float) -> None:
        """Insert a human-driven vehicle at an exact spot of the arterial's first edge, held at
        ``speed`` with its own safety checks off and no lane changes (scripted scenarios, tests)."""
        ls.vehicle.add(vid, EGO_ROUTE, typeID=HDV_TYPE, depart="now", departLane=str(lane),
                       departPos=f"{pos:.2f}", departSpeed=f"{speed:.3f}")
        ls.vehicle.setSpeedMode(vid, 0)
        ls.vehicle.setLaneChangeMode(vid, 0)
        ls.vehicle.setSpeed(vid, speed)

    @staticmethod
    def release_speed(vid: str) -> None:
        """Hand a scripted vehicle back to Krauss (safety checks on, no commanded speed)."""
        ls.vehicle.setSpeedMode(vid, SPEED_MODE_SAFE)
        ls.vehicle.setSpeed(vid, -1)

    @staticmethod
    def take_control(vid: str) -> None:
        ls.vehicle.setSpeedMode(vid, SPEED_MODE_SAFE)
        ls.vehicle.setLaneChangeMode(vid, LC_MODE_EXTERNAL)

    @staticmethod
    def lateral_to_sumo(vid: str, lc2013: bool) -> None:
        ls.vehicle.setLaneChangeMode(vid, LC_MODE_DEFAULT if lc2013 else LC_MODE_EXTERNAL)

    @staticmethod
    def kinematics(vid: str) -> Kinematics:
        v = ls.vehicle
        x, y = v.getPosition(vid)
        return Kinematics(x, y, v.getAngle(vid), v.getSpeed(vid), v.getAcceleration(vid), v.getLaneIndex(vid),
                          v.getRoadID(vid))

    @staticmethod
    def neighbours(vid: str) -> dict[str, dict[int, object]]:
        """Vehicles within the context range: id -> {var: value} (the vehicle itself included)."""
        return ls.vehicle.getContextSubscriptionResults(vid)

    @staticmethod
    def odometer(vid: str) -> float:
        """Distance [m] driven since insertion."""
        return ls.vehicle.getDistance(vid)

    @staticmethod
    def energy_rate(vid: str) -> float:
        """Electric power drawn now [Wh/s]; negative while recuperating."""
        return ls.vehicle.getElectricityConsumption(vid)

    @staticmethod
    def battery_totals(vid: str) -> tuple[float, float]:
        """(consumed, regenerated) [Wh] from the battery device."""
        g = ls.vehicle.getParameter
        return (float(g(vid, "device.battery.totalEnergyConsumed")),
                float(g(vid, "device.battery.totalEnergyRegenerated")))

    @staticmethod
    def set_speed(vid: str, speed: float) -> None:
        ls.vehicle.setSpeed(vid, speed)

    def change_lane(self, vid: str, direction: int) -> None:
        """Request a change by ``direction`` lanes (SUMO sign: +1 left, -1 right)."""
        ls.vehicle.changeLaneRelative(vid, direction, self.cfg.step_length)

    @staticmethod
    def could_change(vid: str, direction: int) -> bool:
        """LC2013's safety verdict for a change in ``direction`` (SUMO sign: +1 left)."""
        return ls.vehicle.couldChangeLane(vid, direction)

    @staticmethod
    def leader(vid: str, dist: float) -> tuple[str, float] | None:
        res = ls.vehicle.getLeader(vid, dist)
        return None if res is None or res[0] == "" else (res[0], res[1])

    @staticmethod
    def follow_speed(vid: str, speed: float, gap: float, leader_speed: float, leader_decel: float) -> float:
        """Krauss safe following speed [m/s] of ``vid`` for the given situation."""
        return ls.vehicle.getFollowSpeed(vid, speed, gap, leader_speed, leader_decel)

    # ------------------------------------------------------------------ signals
    def next_signal(self, vid: str) -> tuple[str, int, float, str] | None:
        """(tls id, link index, distance to stop line [m], state char) of the next signal."""
        nxt = ls.vehicle.getNextTLS(vid)
        return nxt[0] if nxt else None

    def time_to_green(self, tls: str, link: int) -> float:
        """Seconds until ``link`` of ``tls`` turns green (0 when green now)."""
        plan = self._plans[tls]
        phase = ls.trafficlight.getPhase(tls)
        if plan.states[phase][link] in _GREEN:
            return 0.0
        t = ls.trafficlight.getNextSwitch(tls) - ls.simulation.getTime()
        n = len(plan.states)
        for i in range(1, n):
            j = (phase + i) % n
            if plan.states[j][link] in _GREEN:
                return t
            t += plan.durations[j]
        return t

    @staticmethod
    def signal_states(tls_ids: tuple[str, ...]) -> list[str]:
        return [ls.trafficlight.getRedYellowGreenState(t) for t in tls_ids]
