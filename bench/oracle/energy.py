"""SUMO 1.28's electric-vehicle energy model (emission class ``Energy``), vectorised in numpy.

This is ``HelpersEnergy::compute`` as the battery device and TraCI's
``vehicle.getElectricityConsumption`` evaluate it once per simulation step, for the parameters
``envs.scenario`` writes into the ego's vType (``envs.config.EVParams``). With ``v1`` the speed
after the step and ``a = (v1 - v0) / dt`` SUMO's acceleration of the step (so the speed before
is ``v1 - a dt = v0``), the mechanical power [W] is

    P_mech = 0.5 (m + m_rot) (v1^2 - v0^2) / dt          kinetic + rotating masses
           + 0.5 rho A c_d v1^3                           air drag (at the speed after the step)
           + c_r g m v1                                   rolling resistance (flat road)
           + c_rad m v1^2 / r,  r = clip(v1 dt / |dtheta|, 1e-4, 1e4)   radial drag (heading change)

and the battery power is ``P_mech / eta_prop`` when ``P_mech > 0``, else ``P_mech * eta_rec``,
plus ``constantPowerIntake`` *after* the efficiencies (SUMO issue #16463, 2025: auxiliaries are
not discounted by the powertrain; older sources add it before). The energy of the step is
``P_bat dt / 3600`` [Wh]. The radial term is the fit to 1.28 (older sources multiply by v once more).

Checked against SUMO itself (tests/bench/oracle/test_energy.py, baseline episodes in traffic):
steps without a heading change agree to 1e-12 Wh, full braking at -4 m/s^2 included (no
recuperation cap); episode sums agree to 0.02 % at dt = 1 s and 0.2 % at dt = 0.5 s. The gap
is the radial term of lane changes: SUMO's battery device registers the first heading change
of a manoeuvre one step late. Not modelled: slope (the corridor is flat),
``recuperationEfficiencyByDeceleration`` (SUMO's default 0 leaves the factor at 1) and
``maximumPower`` (not applied by this model, SUMO issue #11108; at a_max = 3 m/s^2 and 50 km/h
the ego's wheel power stays below its 80 kW anyway). Sources: SUMO's HelpersEnergy.cpp and
EnergyParams.cpp (eclipse-sumo/sumo), issue #16463, and the fit to SUMO 1.28 above, which also
fixed GRAVITY = 9.80665 (9.81 leaves 2e-4 Wh per step).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ecodrive_bench.envs.config import EVParams

GRAVITY = 9.80665  # [m/s^2] SUMO's GRAVITY constant (not 9.81: the roll term shows the difference)
AIR_DENSITY = 1.2041  # [kg/m^3] at 20 degC, hard-coded in SUMO
RADIUS_MIN = 1e-4  # [m] SUMO clips the turning radius to [RADIUS_MIN, RADIUS_MAX]
RADIUS_MAX = 1e4  # [m]
J_PER_WH = 3600.0  # [J/Wh]


def mechanical_power_w(v0: ArrayLike, v1: ArrayLike, dt: float, ev: EVParams,
                       heading_change: ArrayLike = 0.0) -> np.ndarray:
    """Power at the wheels [W] over a step from ``v0`` to ``v1`` [m/s] of ``dt`` [s]; negative
    when braking. ``heading_change`` [rad] is the change of the vehicle's angle in the step."""
    v0 = np.asarray(v0, dtype=float)
    v1 = np.asarray(v1, dtype=float)
    dth = np.abs(np.asarray(heading_change, dtype=float))
    m = ev.mass
    power = 0.5 * (m + ev.rotating_mass) * (v1 * v1 - v0 * v0) / dt
    power = power + 0.5 * AIR_DENSITY * ev.front_surface_area * ev.air_drag_coefficient * (v1 * v1 * v1)
    power = power + ev.roll_drag_coefficient * GRAVITY * m * v1
    if np.any(dth != 0.0):
        with np.errstate(divide="ignore", invalid="ignore"):
            radius = np.clip(v1 * dt / dth, RADIUS_MIN, RADIUS_MAX)
            radial = np.where(dth != 0.0, ev.radial_drag_coefficient * m * v1 * v1 / radius, 0.0)
        power = power + radial
    return power


def battery_power_w(mechanical: ArrayLike, ev: EVParams) -> np.ndarray:
    """Electric power drawn from the battery [W] for a wheel power [W]; negative = charging."""
    p = np.asarray(mechanical, dtype=float)
    p = np.where(p > 0.0, p / ev.propulsion_efficiency, p * ev.recuperation_efficiency)
    return p + ev.constant_power_intake


def energy_wh(v0: ArrayLike, v1: ArrayLike, dt: float, ev: EVParams,
              heading_change: ArrayLike = 0.0) -> np.ndarray:
    """Battery energy [Wh] of one step from speed ``v0`` to ``v1`` [m/s] lasting ``dt`` [s] on a
    flat road, negative when recuperating; broadcasts over its array arguments."""
    mech = mechanical_power_w(v0, v1, dt, ev, heading_change)
    return battery_power_w(mech, ev) * dt / J_PER_WH


def cruise_energy_wh(v: ArrayLike, distance: float, ev: EVParams) -> np.ndarray:
    """Energy [Wh] to cover ``distance`` [m] at constant speed ``v`` [m/s] (continuous time):
    the power of a steady step times distance / v."""
    v = np.asarray(v, dtype=float)
    return battery_power_w(mechanical_power_w(v, v, 1.0, ev), ev) * (distance / v) / J_PER_WH
