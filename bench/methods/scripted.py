"""Scripted vehicles placed relative to the ego and driven by commanded speeds: the placement and
braking rules shared by the lateral scenarios (``bench.experiments.lateral``) and training's
braking leaders (``bench.training.braking``).

Both are used through ``run_episode(..., script=)``'s protocol (``start(env)`` after the reset,
``before(env, step)`` / ``after(env, step)`` around every step), or the same calls in training's
loop. ``envs.sumo.SumoSession.add_scripted`` places a vehicle on the arterial's first edge
(``A0``, x = 0 at its start), held at its speed with its own safety checks off, until
``release`` hands it to Krauss.
"""
from __future__ import annotations

from typing import Any


def place_ahead(env: Any, vid: str, lane: int, gap: float, speed: float) -> float:
    """Add ``vid`` in lane ``lane`` so that it is ``gap`` m ahead of the ego after the coming step
    (from the ego's front bumper to ``vid``'s back bumper), held at ``speed`` [m/s]; returns its
    front bumper's lane position [m].

    SUMO inserts it in the next step, after it has moved the ego: it goes ``gap`` m ahead of
    where the ego's front bumper is then at its present speed (an ego that changes speed in that
    step shifts the gap by that change x one step). ``x`` is the front bumper, and the arterial's
    first edge starts at x = 0, so it is also the lane position. A spot SUMO refuses (another
    vehicle too close) leaves ``vid`` pending; the caller checks ``vehicle_ids`` after the step."""
    cfg, kin = env.cfg, env.ego.kin
    front = kin.x + kin.speed * cfg.step_length
    pos = front + gap + cfg.vehicle_length
    env.session.add_scripted(vid, lane=lane, pos=pos, speed=speed)
    return pos


def brake(env: Any, vid: str, decel: float) -> None:
    """Command ``vid``'s speed for the coming step: its present speed changed by ``decel``
    [m/s^2, negative] over one step, never below standstill."""
    s = env.session
    v = s.kinematics(vid).speed
    s.set_speed(vid, max(0.0, v + decel * env.cfg.step_length))


def release(env: Any, vids: list[str]) -> None:
    """Hand the scripted vehicles among ``vids`` that are in the simulation back to Krauss (their
    own safety checks on, no commanded speed); they keep driving their route, without lane changes."""
    s = env.session
    present = set(s.vehicle_ids())
    for vid in vids:
        if vid in present:
            s.release_speed(vid)
