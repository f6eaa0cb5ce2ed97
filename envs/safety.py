"""Safety layer (section 3.2): Krauss clip of the acceleration and LC2013 mask of lane changes.

The pure functions hold the arithmetic; SUMO applies the Krauss bound itself when the vehicle
runs with speed mode ``envs.sumo.SPEED_MODE_SAFE`` (27: every check but the maximum deceleration,
so that the vehicle may brake harder than a_min when Krauss' safe speed asks for it), so the
applied acceleration is min(Krauss safe, requested) by construction, and is read back after the
step.
"""
from __future__ import annotations

import numpy as np

from .action import LATERAL

CLIP_TOLERANCE = 1e-3  # [m/s^2] applied below requested by more than this counts as a clip


def target_speed(speed: float, accel: float, dt: float, v_max: float) -> float:
    """Speed [m/s] to command so the requested ``accel`` holds over ``dt``, within [0, v_max]."""
    return min(v_max, max(0.0, speed + accel * dt))


def applied_acceleration(v_before: float, v_after: float, dt: float) -> float:
    return (v_after - v_before) / dt


def was_clipped(requested: float, applied: float, speed_before: float, dt: float, v_max: float) -> bool:
    """True when the applied acceleration is below what the [0, v_max] bound alone allows."""
    feasible = (target_speed(speed_before, requested, dt, v_max) - speed_before) / dt
    return applied < feasible - CLIP_TOLERANCE


def lane_mask(lane: int, lanes: int, could_left: bool, could_right: bool) -> np.ndarray:
    """Mask over k in (-1 left, 0 stay, +1 right): 1 allowed, 0 masked. Staying is always allowed;
    ``lanes`` is the road's lane count, so no change leaves the road (whatever SUMO says)."""
    left = could_left and lane < lanes - 1
    right = could_right and lane > 0
    return np.array([left, True, right], dtype=np.int8)


def mask_lateral(k: int, mask: np.ndarray) -> int:
    """The paper's k * xi: a masked change becomes 'stay'."""
    return k if mask[LATERAL.index(k)] else 0


def paper_to_sumo(k: int) -> int:
    """Paper k (-1 left) to SUMO's changeLaneRelative direction (+1 left)."""
    return -k
