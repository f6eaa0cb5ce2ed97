"""The paper's reward forms (eq. 9, 10 and 11); pure functions of one step's measurements."""
from __future__ import annotations

from .config import RewardConfig

COMPONENTS = ("speed", "jerk", "lane_change", "distance", "energy", "time", "terminal")


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
    step_time: float = 0.0,  # [s] simulated this step
) -> tuple[float, dict[str, float]]:
    """Return (reward, components). Components not used by ``rc.form`` are reported as 0.

    Form r with ``cost_timing="step"`` pays eq. 11's -(E_f + phi T_f) as -(e_t + phi dt) every
    step (components "energy" and "time"), so an episode's undiscounted return is unchanged; r1
    keeps it at the end, since being terminal-only is what r1 is about."""
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
        if rc.cost_timing == "end":
            c["terminal"] = terminal
        else:
            c["energy"] = -energy
            c["time"] = -rc.phi * step_time
    return sum(c.values()), c
