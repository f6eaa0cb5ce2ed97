"""What a script may do beside the ego, through the env: place a vehicle, hold or brake its speed,
release it, and read the road. The lateral scenarios (``bench.experiments.lateral``), training's
braking leaders (``bench.training.braking``) and the harness's episode totals use these, so that
one module still talks to SUMO (``envs.sumo``) and nothing reaches round the env.

A scripted vehicle is of the human-driven type, placed on the arterial's first edge (x = 0 at its
start) and held at its commanded speed with its own safety checks off, until ``release`` hands it
to Krauss; it keeps driving its route, without lane changes.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .config import ScenarioConfig
    from .sumo import Kinematics, SumoSession


class Scripting:
    """The scripting API of ``EcoDriveEnv`` (a base class of it)."""

    session: SumoSession
    cfg: ScenarioConfig
    ego: Any

    # ------------------------------------------------------------------ reading the road
    def vehicle_ids(self) -> tuple[str, ...]:
        """Every vehicle in the simulation now."""
        return self.session.vehicle_ids()

    def sim_time(self) -> float:
        """[s] the simulation's time."""
        return self.session.time()

    def kinematics_of(self, vid: str) -> Kinematics:
        """A vehicle's kinematics now (x, y, angle, speed, accel, lane, edge)."""
        return self.session.kinematics(vid)

    def leader_of(self, vid: str, dist: float) -> tuple[str, float] | None:
        """(id, gap [m]) of the vehicle ahead of ``vid`` within ``dist`` m (SUMO may look further), or None."""
        return self.session.leader(vid, dist)

    # ------------------------------------------------------------------ scripting vehicles
    def place(self, vid: str, lane: int, pos: float, speed: float) -> None:
        """Add ``vid`` at lane position ``pos`` [m] of lane ``lane`` of the first edge, held at ``speed`` [m/s]."""
        self.session.add_scripted(vid, lane=lane, pos=pos, speed=speed)

    def place_ahead(self, vid: str, lane: int, gap: float, speed: float) -> float:
        """Add ``vid`` in lane ``lane`` so that it is ``gap`` m ahead of the ego after the coming step
        (from the ego's front bumper to ``vid``'s back bumper), held at ``speed`` [m/s]; returns its
        front bumper's lane position [m].

        SUMO inserts it in the next step, after it has moved the ego: it goes ``gap`` m ahead of
        where the ego's front bumper is then at its present speed (an ego that changes speed in that
        step shifts the gap by that change x one step). The arterial's first edge starts at x = 0,
        so x is also the lane position. A spot SUMO refuses (another vehicle too close) leaves
        ``vid`` pending; the caller checks ``vehicle_ids`` after the step."""
        cfg, kin = self.cfg, self.ego.kin
        pos = kin.x + kin.speed * cfg.step_length + gap + cfg.vehicle_length
        self.place(vid, lane, pos, speed)
        return pos

    def hold_speed(self, vid: str, speed: float) -> None:
        """Command ``vid``'s speed [m/s] from now on."""
        self.session.set_speed(vid, speed)

    def brake(self, vid: str, decel: float) -> None:
        """Command ``vid``'s speed for the coming step: its present speed changed by ``decel``
        [m/s^2, negative] over one step, never below standstill."""
        v = self.session.kinematics(vid).speed
        self.session.set_speed(vid, max(0.0, v + decel * self.cfg.step_length))

    def release(self, *vids: str, pending: bool = False) -> None:
        """Hand those of ``vids`` that are in the simulation back to Krauss (their own safety checks
        on, no commanded speed); ``pending``: also those SUMO has not inserted yet (they drive as
        ordinary vehicles when it does)."""
        present = set(self.session.vehicle_ids())
        for vid in vids:
            if pending or vid in present:
                self.session.release_speed(vid)

    # ------------------------------------------------------------------ an episode's totals
    def battery_totals(self) -> tuple[float, float]:
        """(consumed, regenerated) [Wh] of the ego's battery device so far."""
        return self.session.battery_totals(self.ego.vid)

    @property
    def sumo_seconds(self) -> float:
        """[s] wall time inside SUMO since the simulation started: loading and stepping (a run's floor)."""
        return self.session.sumo_seconds
