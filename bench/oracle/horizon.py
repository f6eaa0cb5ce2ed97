"""A lower bound on the cost E + phi T of any plan that crosses the corridor in T steps.

The DP's ``"cost"`` objective needs a horizon it can prove does not bind: no plan slower than K
steps can beat the one found (``bench.oracle.dp``). Per step a plan pays phi dt and the
auxiliaries' energy (``rate``). The battery draws at least eta_rec times the mechanical work W,
since eta_rec <= 1 <= 1/eta_prop (``bench.oracle.energy``: P/eta_prop when driving, eta_rec P
when braking). Over the corridor's length D, Euler steps telescope the kinetic terms and sum
v dt to at least D, so W >= -KE0 (at most the start's kinetic energy comes back) + c_r g m D
(rolling) + 0.5 rho A c_d D^3 / (T dt)^2 (air drag, which for a given mean speed is least at
constant speed: power means). So

    cost(T) >= rate T + eta_rec W(T) / 3600,

convex in T (a T + b / T^2). tests/bench/oracle/test_kernel.py checks it against solved plans.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

from ecodrive_bench.envs.config import ScenarioConfig

from .energy import AIR_DENSITY, GRAVITY, J_PER_WH

if TYPE_CHECKING:
    from .corridor import Corridor


@dataclass(frozen=True)
class LeastCost:
    """The bound for one corridor (``bench.oracle.dp.Corridor``), config and time weight."""

    cor: Corridor  # x0, x_end [m] and v0 [m/s] are read
    cfg: ScenarioConfig
    phi: float  # [Wh/s]

    @cached_property
    def rate(self) -> float:
        """[Wh/step] what every step costs at least: phi dt and the auxiliaries' energy."""
        return (self.phi + self.cfg.ev.constant_power_intake / J_PER_WH) * self.cfg.step_length

    @cached_property
    def _terms(self) -> tuple[float, float]:
        """(eta_rec times the work that does not depend on T [Wh], the air term's b [Wh step^2])."""
        ev, dt = self.cfg.ev, self.cfg.step_length
        dist = max(self.cor.x_end - self.cor.x0, 0.0)
        fixed = -0.5 * (ev.mass + ev.rotating_mass) * self.cor.v0 ** 2 + ev.roll_drag_coefficient * GRAVITY * ev.mass * dist
        air = 0.5 * AIR_DENSITY * ev.front_surface_area * ev.air_drag_coefficient * dist ** 3 / dt ** 2
        return ev.recuperation_efficiency * fixed / J_PER_WH, ev.recuperation_efficiency * air / J_PER_WH

    def at(self, steps: float) -> float:
        """[Wh] no plan arriving in ``steps`` steps costs less."""
        fixed, air = self._terms
        return self.rate * steps + fixed + air / steps ** 2

    def after(self, horizon: int) -> float:
        """[Wh] no plan slower than ``horizon`` steps costs less (the bound's minimum over T > horizon)."""
        t_min = (2.0 * self._terms[1] / self.rate) ** (1.0 / 3.0)  # [steps] the convex bound's minimiser
        return self.at(max(horizon + 1.0, t_min))

    def last_steps(self, cost: float) -> int:
        """The most steps a plan costing at most ``cost`` [Wh] can take (at least 1)."""
        fixed, _ = self._terms
        steps = math.ceil((cost - min(fixed, 0.0)) / self.rate) + 1  # the bound exceeds ``cost`` from here on
        while steps > 1 and self.at(steps) > cost:
            steps -= 1
        return steps
