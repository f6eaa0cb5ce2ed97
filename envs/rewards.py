"""The paper's reward forms (eq. 9, 10 and 11); pure functions of one step's measurements."""
from __future__ import annotations

from .config import RewardConfig

COMPONENTS = ("speed", "jerk", "lane_change", "distance", "energy", "terminal")


def reward(
    rc: RewardConfig,
    *,
    speed: float,  # [m/s] after the step
    jerk: float,  # [m/s^3]
    lane_changed: bool,
    distance: float,  # [m] travelled this step
    energy: float,  # [Wh] used this step (negative when recuperating)
    terminated: bool,
    total_energy: float,  # E_f [Wh] so far
    travel_time: float,  # T_f [s] so far
) -> tuple[float, dict[str, float]]:
    """Return (reward, components). Components not used by ``rc.form`` are reported as 0."""
    c = dict.fromkeys(COMPONENTS, 0.0)
    c["lane_change"] = -rc.lane_change_penalty if lane_changed else 0.0
    terminal = -(total_energy + rc.phi * travel_time) if terminated else 0.0
    if rc.form == "r1":
        c["terminal"] = terminal
    elif rc.form == "r2":
        c["distance"] = distance
        c["energy"] = -rc.phi * energy
    else:
        c["speed"] = -rc.speed_penalty if speed < rc.speed_threshold else 0.0
        c["jerk"] = -rc.jerk_penalty if abs(jerk) > rc.jerk_threshold else 0.0
        c["terminal"] = terminal
    return sum(c.values()), c
