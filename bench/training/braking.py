"""Braking leaders in training episodes: ``ecodrive train --braking-leaders RATE``.

With probability RATE per training episode, a scripted vehicle enters the ego's lane ahead of it
and brakes, as HDV1 does in the lateral scenario A (section 5.4; ``bench.experiments.lateral``),
with the same placement and braking rules (``envs.scripting``). In the paper's training
traffic a leader that brakes hard beside a lane the mask allows, not at a red light, is rare
(docs/experiments.md, "Scenario A, step by step"); this puts such events into the training
distribution. The MDP is the paper's: observation, action, reward and safety layer are untouched;
the leader is one more vehicle in the traffic.

Per episode, before its reset, the run's braking generator draws (always all five, so its stream
advances by the same amount every episode): whether the episode has an event, the gap
(``GAP``, ego front bumper to leader back bumper after the insertion step), the deceleration
(``DECEL``), the braking steps (``BRAKE_STEPS``) and the trigger, a fraction of the latest spot the
event fits on the arterial's first edge (``A0``, where ``EcoDriveEnv.place`` places
vehicles). From the first step at which the ego's front bumper has passed the trigger, the event
starts at the first step at which:

* the ego drives at ``MIN_EGO_SPEED`` or faster on the first edge, its lane is empty up to
  ``CLEAR_AHEAD`` past where the leader will be (no vehicle in it, none moving into it), and the leader, held at the ego's speed until
  its braking ends, stays ``STOP_MARGIN`` short of J1's stop line (so a red light never brakes it
  and it never runs one); and
* an adjacent lane is free from the grid's back edge to ``FREE_AHEAD`` ahead of the ego's front
  bumper (a lane change is open), unless the next step would be too late for the event to fit,
  when the first condition alone suffices.

The leader enters at the ego's speed in the ego's lane in that step, drives at that speed for
``BRAKE_AFTER - 1`` step(s), brakes at the drawn deceleration for the drawn steps, then drives by
Krauss (no lane changes) along the arterial. Unlike scenario A's HDVs it is held with Krauss's
safety checks on (``SPEED_MODE_SAFE``), so traffic cutting in ahead of it in a full corridor
brakes it rather than meets it. An episode whose ego gives the event no such step
has none (``no_spot``). A vehicle that starts a change into the ego's lane in the insertion step
itself can still take the spot: SUMO then does not insert the leader (``refused``), and it enters
later as an ordinary Krauss vehicle, where SUMO finds room at its spot. The episode's row records what happened (``ROW_KEYS``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ecodrive_bench.bench.methods.policies import CheckpointError
from ecodrive_bench.bench.training.recipes import (
    RATE_RANGE,  # accepted RATE (its home: the recipes, which the command reads too)
)
from ecodrive_bench.envs.observation import HEADING_EAST, occupancy_grid
from ecodrive_bench.envs.vehicle import LATERAL_START

# [m] uniform: ego front bumper to the leader's back bumper after the insertion step. SUMO refuses
# to insert a leader closer than the ego's secure gap plus minGap (about 19 m at the speed limit)
GAP = (20.0, 40.0)
DECEL = (-4.0, -2.0)  # [m/s^2] uniform: the leader's deceleration while it brakes (scenario A: -2)
BRAKE_STEPS = (2, 4)  # [steps] uniform integer, both ends included (scenario A: 3)
BRAKE_AFTER = 2  # [steps] from the insertion step to the first braking step (one step at the ego's speed)
MIN_EGO_SPEED = 5.0  # [m/s] slower egos get no event (a crawling leader's braking is no event)
CLEAR_AHEAD = 10.0  # [m] the ego's lane is empty this far beyond the leader's front bumper
STOP_MARGIN = 10.0  # [m] the held leader stays this far short of J1's stop line
FREE_AHEAD = 30.0  # [m] an adjacent lane counts as free to this distance ahead of the ego's front bumper
LEADER_ID = "braking_leader"
SEED_TAG = 104729  # the braking generator is default_rng([seed, SEED_TAG]): apart from the episode seeds' stream
# per-episode row entries (only in runs with the option on): event ("none", "inserted", "no_spot",
# "refused"), the insertion step (-1: none), the drawn gap [m], deceleration [m/s^2] and braking
# steps (NaN / 0 without an event), the gap measured after the insertion step [m] and whether an
# adjacent lane was free then
ROW_KEYS = ("braking_event", "braking_step", "braking_gap", "braking_decel", "braking_steps",
            "braking_entry_gap", "braking_adjacent_free")


def check_rate(rate: float) -> float:
    """``rate`` if it is a finite number in ``RATE_RANGE``; else a ValueError naming the range."""
    lo, hi = RATE_RANGE
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and lo <= rate <= hi):
        raise ValueError(f"braking leaders rate {rate!r} is not accepted; accepted: a probability per episode in [{lo:g}, {hi:g}]")
    return float(rate)


def spec(rate: float) -> dict[str, Any]:
    """What a run records of the option (checkpoint identity, manifest): the rate and every
    constant that shapes an event."""
    return {"rate": rate, "gap_m": list(GAP), "decel_m_s2": list(DECEL), "brake_steps": list(BRAKE_STEPS),
            "brake_after_steps": BRAKE_AFTER, "min_ego_speed_m_s": MIN_EGO_SPEED, "clear_ahead_m": CLEAR_AHEAD,
            "stop_margin_m": STOP_MARGIN, "free_ahead_m": FREE_AHEAD, "edge": "first (A0)"}


@dataclass(frozen=True)
class Draw:
    """One episode's draws."""

    event: bool
    gap: float  # [m]
    decel: float  # [m/s^2]
    steps: int
    trigger: float  # fraction of the latest spot on the first edge at which the event may start


def draw(rng: np.random.Generator, rate: float) -> Draw:
    """An episode's draws from the run's braking generator (five, whatever the outcome)."""
    u, gap, decel, steps, trigger = (rng.random(), rng.uniform(*GAP), rng.uniform(*DECEL),
                                     rng.integers(BRAKE_STEPS[0], BRAKE_STEPS[1] + 1), rng.random())
    return Draw(bool(u < rate), float(gap), float(decel), int(steps), float(trigger))


class BrakingLeader:
    """One episode's braking leader, driven through ``start(env)``, ``before(env, step)`` and
    ``after(env, step)`` around the steps (``run_episode``'s script protocol); ``row()`` gives the
    episode's ``ROW_KEYS``."""

    def __init__(self, d: Draw) -> None:
        self.d = d
        self.step: int | None = None  # the insertion step
        self.status = "none" if not d.event else "no_spot"
        self.entry_gap = float("nan")
        self.adjacent_free = False
        self.stop_line = self.latest = 0.0

    def start(self, env: Any) -> None:
        cfg = env.cfg
        self.stop_line = env.files.stop_lines[0]
        # the ego's front bumper at the latest spot where the event fits at the speed limit
        self.latest = self.stop_line - STOP_MARGIN - self._reach(cfg.speed_limit, cfg)

    def _reach(self, v: float, cfg: Any) -> float:
        """[m] from the ego's front bumper now to the held leader's front bumper when it is released."""
        return v * cfg.step_length + self.d.gap + cfg.vehicle_length + v * (BRAKE_AFTER + self.d.steps) * cfg.step_length

    def before(self, env: Any, step: int) -> None:
        if self.step is None:
            if self.d.event and self.status == "no_spot" and self._ready(env):
                kin = env.ego.kin
                env.place_ahead(LEADER_ID, kin.lane, self.d.gap, kin.speed)
                env.release(LEADER_ID, pending=True)  # held with Krauss's safety checks on: traffic
                env.hold_speed(LEADER_ID, kin.speed)  # ahead or a red light still brakes it
                self.step, self.status = step, "inserted"
            return
        k = step - self.step - BRAKE_AFTER
        if self.status == "inserted" and 0 <= k < self.d.steps and LEADER_ID in env.vehicle_ids():
            env.brake(LEADER_ID, self.d.decel)
        elif k == self.d.steps:
            env.release(LEADER_ID)

    def after(self, env: Any, step: int) -> None:
        if step != self.step:
            return
        if LEADER_ID not in env.vehicle_ids():  # pending: it will drive as an ordinary vehicle when SUMO inserts it
            env.release(LEADER_ID, pending=True)
            self.status = "refused"
            return
        self.entry_gap = env.kinematics_of(LEADER_ID).x - env.cfg.vehicle_length - env.ego.kin.x

    def _ready(self, env: Any) -> bool:
        """Whether the event starts in the coming step (module docstring)."""
        cfg, kin = env.cfg, env.ego.kin
        if kin.edge != env.files.arterial_edges[0] or kin.speed < MIN_EGO_SPEED or kin.x < self.d.trigger * self.latest:
            return False
        reach = self._reach(kin.speed, cfg)
        if kin.x + reach > self.stop_line - STOP_MARGIN:
            return False
        if env.leader_of(env.ego.vid, reach + CLEAR_AHEAD) is not None or entering(env, reach + CLEAR_AHEAD):
            return False
        self.adjacent_free = free_adjacent(env)
        last = kin.x + kin.speed * cfg.step_length + reach > self.stop_line - STOP_MARGIN
        return self.adjacent_free or last

    def row(self) -> dict[str, Any]:
        inserted = self.status in ("inserted", "refused")
        return {"braking_event": self.status, "braking_step": -1 if self.step is None else self.step,
                "braking_gap": self.d.gap if self.d.event else float("nan"),
                "braking_decel": self.d.decel if self.d.event else float("nan"),
                "braking_steps": self.d.steps if self.d.event else 0,
                "braking_entry_gap": self.entry_gap, "braking_adjacent_free": bool(inserted and self.adjacent_free)}


def entering(env: Any, ahead: float) -> bool:
    """Whether a vehicle beside the ego's lane, up to ``ahead`` m ahead of its front bumper, has
    started moving into it (by ``LATERAL_START`` or more; SUMO's ``getLeader`` sees it only once its
    lane index flips, and its cut-in would block the leader's insertion)."""
    ego, lane_y = env.ego, env.files.lane_y
    if len(lane_y) < 2:
        return False
    pitch, y0, x0 = lane_y[1] - lane_y[0], lane_y[ego.kin.lane], ego.kin.x
    return any(x0 < x and x - length - x0 <= ahead and abs(y - y0) < pitch - LATERAL_START
               and abs((angle - HEADING_EAST + 180.0) % 360.0 - 180.0) < 45.0 for x, y, angle, length in ego.others)


def free_adjacent(env: Any) -> bool:
    """Whether a lane beside the ego's (one the road has) is free from the occupancy grid's back
    edge to ``FREE_AHEAD`` ahead of the ego's front bumper, as the ego's observation grid shows it."""
    cfg, ego = env.cfg, env.ego
    grid = occupancy_grid(ego.kin.x, ego.others, env.files.lane_y, cfg)
    rows = int(round((cfg.grid_behind + min(FREE_AHEAD, cfg.grid_ahead)) / cfg.cell_length))
    lane = ego.kin.lane
    return any(0 <= c < cfg.lanes and bool(grid[:rows, c].all()) for c in (lane - 1, lane + 1))


class BrakingLeaders:
    """The run's option: ``episode()`` draws the next episode's ``BrakingLeader`` from the run's
    braking generator, whose ``state`` the checkpoint keeps."""

    def __init__(self, rate: float, seed: int) -> None:
        self.rate = check_rate(rate)
        self.rng = np.random.default_rng([seed, SEED_TAG])

    def episode(self) -> BrakingLeader:
        return BrakingLeader(draw(self.rng, self.rate))

    @property
    def state(self) -> dict[str, Any]:
        return self.rng.bit_generator.state

    def restore(self, checkpoint: dict[str, Any], path: Any) -> None:
        """Continue the generator where ``checkpoint`` (read from ``path``) left it; a missing or
        malformed state is a ``CheckpointError`` naming ``path``."""
        try:
            self.rng.bit_generator.state = checkpoint["braking_rng"]
        except (ValueError, TypeError, KeyError) as e:
            raise CheckpointError(f"{path}: its braking_rng state is not a PCG64 state ({e})") from None


class NoScript:
    """The episode script of a run without the option: does nothing, adds nothing to the row."""

    def start(self, env: Any) -> None:
        pass

    def before(self, env: Any, step: int) -> None:
        pass

    def after(self, env: Any, step: int) -> None:
        pass

    def row(self) -> dict[str, Any]:
        return {}


NO_SCRIPT = NoScript()
