"""Per-vehicle control core: observe, apply a command through the safety layer, measure.

It works for any vehicle ID, so the single-agent env drives one of these and a mixed-traffic
run drives hundreds with one policy.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import safety
from .action import Command
from .config import ScenarioConfig
from .observation import GridLogicObservation, RoutePlace, SignalView
from .sumo import SumoSession


@dataclass
class StepMeasure:
    """What happened to one vehicle over one simulation step."""

    requested_accel: float  # [m/s^2]; nan under SUMO control
    requested_lateral: int  # paper k; 0 under SUMO control
    applied_accel: float  # [m/s^2]
    applied_lateral: int  # k after the mask (SUMO's own change under LC2013)
    clipped: bool
    lane_changed: bool
    distance: float  # [m]
    energy: float  # [Wh]
    jerk: float  # [m/s^3]
    speed: float  # [m/s] after the step
    lane_change_charged: bool = False  # r_p^c falls on this step (RewardConfig.lane_change_charge)


LATERAL_START = 0.1  # [m] sideways move in the requested direction that shows a change has started


@dataclass
class ControlledVehicle:
    vid: str
    session: SumoSession
    obs_type: GridLogicObservation
    cfg: ScenarioConfig
    mask: np.ndarray = field(default_factory=lambda: np.ones(3, dtype=np.int8))
    kin: tuple = ()
    signal: SignalView | None = None
    others: list = field(default_factory=list)  # [(x, y, angle, length)] of the neighbours
    along: float = 0.0  # [m] position along the corridor (``obs_type.along``)
    energy: float = 0.0  # [Wh] cumulative
    lane_changes: int = 0
    clips: int = 0
    _prev_accel: float = 0.0
    _pending: tuple = ()
    _manoeuvre: int = 0  # SUMO direction of a change charged at its start whose lane index has not flipped yet
    place: RoutePlace | None = None  # where it is on its route (``obs_type.place()`` at the start)

    def __post_init__(self) -> None:
        if self.place is None:
            self.place = self.obs_type.place()

    def observe(self, measured: bool = False) -> dict[str, np.ndarray]:
        """The vehicle's observation now, its signal view, neighbours and lateral mask updated.
        ``measured``: ``measure`` has just read the state after the last step, so it is not read again."""
        s = self.session
        if not measured:
            self.kin = s.kinematics(self.vid)
            self.along = self.obs_type.along(s, self.vid, self.kin, self.place)
        obs, self.signal, self.others = self.obs_type.observe(s, self.vid, self.kin, s.neighbours(self.vid), self.place)
        # the road's lanes, not the observation's: a change into a padded lane is masked
        self.mask = self.obs_type.mask(s, self.vid, self.kin.lane, self.place)
        return obs

    def apply(self, cmd: Command) -> None:
        """Send ``cmd`` to SUMO for the coming step (call ``observe`` first)."""
        s, cfg = self.session, self.cfg
        speed = self.kin.speed
        lateral = 0
        if cmd.lateral is not None:
            lateral = safety.mask_lateral(cmd.lateral, self.mask)
            if lateral:
                s.change_lane(self.vid, safety.paper_to_sumo(lateral))
        if cmd.accel is not None:
            s.set_speed(self.vid, safety.target_speed(speed, cmd.accel, cfg.step_length, cfg.speed_limit))
        self._pending = (cmd, lateral, speed, self.kin.lane, self.kin.x, self.kin.y, self.kin.edge)

    def measure(self) -> StepMeasure:
        """Read back the step just simulated (call after ``session.step``)."""
        s, cfg = self.session, self.cfg
        cmd, sent, v0, lane0, x0, y0, edge0 = self._pending
        kin = s.kinematics(self.vid)
        along = self.obs_type.along(s, self.vid, kin, self.place)
        distance, self.along = max(0.0, along - self.along), along
        dt = cfg.step_length
        applied = safety.applied_acceleration(v0, kin.speed, dt)
        clipped = cmd.accel is not None and safety.was_clipped(cmd.accel, applied, v0, dt, cfg.speed_limit)
        lane_changed = (kin.lane != lane0 and kin.edge[:1] != ":" and kin.edge != ""
                        and self.obs_type.same_road(edge0, kin.edge))
        # what happened, not what was asked: SUMO re-checks safety when it executes a change
        lateral = (kin.lane < lane0) - (kin.lane > lane0) if lane_changed else 0  # SUMO index grows to the left
        if cfg.reward.lane_change_charge == "request":
            charged = self._charge(safety.paper_to_sumo(sent) if sent else 0, -lateral, kin.y - y0)
        else:
            charged = lane_changed
        energy = s.energy_rate(self.vid) * dt
        self.energy += energy
        self.lane_changes += lane_changed
        self.clips += clipped
        jerk = (applied - self._prev_accel) / dt
        self._prev_accel = applied
        self.kin = kin
        return StepMeasure(
            requested_accel=float("nan") if cmd.accel is None else cmd.accel,
            requested_lateral=0 if cmd.lateral is None else cmd.lateral,
            applied_accel=applied, applied_lateral=lateral, clipped=bool(clipped),
            lane_changed=lane_changed, distance=distance,
            energy=energy, jerk=jerk, speed=kin.speed, lane_change_charged=charged,
        )

    def _charge(self, sent: int, direction: int, dy: float) -> bool:
        """Whether r_p^c falls on this step under "request" charging. ``sent``: SUMO direction of the
        change requested (0 none); ``direction``: of the lane index change this step (0 none);
        ``dy``: sideways move [m] (SUMO y grows to the left, as the direction)."""
        started = sent != 0 and (direction == sent or dy * sent > LATERAL_START)
        finishing = direction != 0 and direction == self._manoeuvre
        if started and direction != sent:
            self._manoeuvre = sent  # charged now; its lane flip comes in a later step
        elif direction or dy * self._manoeuvre <= LATERAL_START:
            self._manoeuvre = 0  # flipped, or no longer moving sideways (SUMO gave it up)
        return started or (direction != 0 and not finishing)
