"""What the DP needs of a corridor: the ego's start, the corridor's end, the stop lines, SUMO's
signal timing and the speed limits, read from the network SUMO runs in the ego's route frame
(``envs.route``: positions along the route, the green windows of the route's links, the limits of
its edges and junctions). The generated arterial is one such corridor: its frame is its x axis,
one green window per cycle and one speed limit."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ecodrive_bench.envs.config import ConfigError, ScenarioConfig
from ecodrive_bench.envs.network import corridor_files

POSITION_EPS = 0.1  # [m] SUMO's POSITION_EPS: departPos "base" = vehicle length + this
MS = 1000  # [ms/s] SUMO's time unit
STOP_EPS = 1e-3  # [m] a stop line at the ego's start (a first edge shorter than the ego) lies this far ahead
LIMIT_TOL = 0.05  # [m/s] a network's limit this close to speed_limit is taken as it (13.89 for 50 km/h)
NET_PRECISION = 2  # decimals of a SUMO network file's lengths and coordinates ([m], 0.01 m)


def _net(x: float) -> float:
    """``x`` [m] (a sum of a network's lengths along a route) to the network's precision."""
    return round(x, NET_PRECISION)


@dataclass(frozen=True)
class Corridor:
    """What the DP needs of the built scenario: start, end, stop lines and signal timing."""

    x0: float  # [m] the ego's front bumper at insertion
    v0: float  # [m/s] its insertion speed
    x_end: float  # [m] start of the exit edge: reaching it ends the episode
    stop_lines: tuple[float, ...]  # [m] W->E stop lines
    offsets_ms: tuple[int, ...]  # [ms] signal offsets as SUMO reads them, one per stop line
    cycles_ms: tuple[int, ...]  # [ms] one per stop line
    greens_ms: tuple[int, ...]  # [ms] arterial green at the start of each cycle, one per stop line
    # a network corridor's: per stop line its green windows (a, b] [ms] of cycle position (greens_ms
    # is then their total); () : the one window (0, green] of each
    windows_ms: tuple[tuple[tuple[int, int], ...], ...] = ()
    limits: tuple[tuple[float, float, float], ...] = ()  # (start, end [m], speed [m/s]) below the speed limit
    # the fields a network corridor fills and the generated arterial leaves empty (digests omit them when empty)
    NETWORK_FIELDS: ClassVar[tuple[str, ...]] = ("windows_ms", "limits")

    @classmethod
    def from_config(cls, cfg: ScenarioConfig) -> Corridor:
        """The corridor of ``cfg`` in its route frame (``envs.route``; on the generated arterial the
        frame is its x axis). Positions are the network's, to its precision (``NET_PRECISION``:
        float summation along the route is rounded away). A corridor whose every signal is green in
        one window from its cycle's start and whose limits are all the speed limit is stored in that
        one-window form (``windows_ms`` and ``limits`` empty), as the generated arterial is. A
        ``PlanError`` where a signal on the route is not fixed-time or a limit on it is above
        ``cfg.speed_limit`` (the lattice's top speed)."""
        route = corridor_files(cfg).route
        moving = [c.tls for c in route.crossings if not c.static]
        if moving:
            raise PlanError(f"signal {moving[0]!r:.60} on the route is not fixed-time; accepted for the planners: "
                            f"static programs only (an actuated signal's future is not known)")
        top = max(v for _, _, v in route.limits)
        if top > cfg.speed_limit + LIMIT_TOL:
            raise PlanError(f"the route's speed limit {top:g} m/s is above speed_limit={cfg.speed_limit:g}; "
                            f"accepted for the planners: limits up to speed_limit")
        below = tuple((_net(a), _net(b), v) for a, b, v in route.limits if v < cfg.speed_limit - LIMIT_TOL)
        c = route.crossings
        x0 = min(_net(route.lengths[0]), cfg.vehicle_length + POSITION_EPS)  # SUMO puts a longer vehicle at the lane's end
        windows = tuple(x.windows_ms for x in c)
        one_window = not below and all(len(w) == 1 and w[0][0] == 0 for w in windows)
        return cls(
            x0=x0, v0=min(cfg.speed_limit, route.limits[0][2]), x_end=_net(route.offsets[-1]),
            stop_lines=tuple(max(_net(x.stop_line), x0 + STOP_EPS) for x in c), offsets_ms=tuple(x.offset_ms for x in c),
            cycles_ms=tuple(x.cycle_ms for x in c), greens_ms=tuple(sum(b - a for a, b in w) for w in windows),
            windows_ms=() if one_window else windows, limits=below)

    def starting(self, speed: float, dv: float) -> Corridor:
        """The corridor from a start at ``speed`` [m/s] (the ego's at its insertion, which traffic
        may slow), rounded down to a multiple of ``dv`` [m/s], at most ``v0``: a network corridor's
        planners start from the speed the ego has, on the lattice of speed cell ``dv``."""
        return replace(self, v0=math.floor(min(speed, self.v0) / dv + 1e-6) * dv)

    def first(self, k: int) -> Corridor:
        """The corridor with only its first ``k`` signals (tests: none, or a single red)."""
        return replace(self, stop_lines=self.stop_lines[:k], offsets_ms=self.offsets_ms[:k],
                       cycles_ms=self.cycles_ms[:k], greens_ms=self.greens_ms[:k], windows_ms=self.windows_ms[:k])

    def green(self, t_start: np.ndarray, dt: float) -> np.ndarray:
        """(len(t_start), n stop lines) bool: the arterial is green in the step from ``t``."""
        t_ms = np.rint(np.asarray(t_start, dtype=float) * MS).astype(np.int64)
        end = t_ms[:, None] + int(round(dt * MS)) - np.asarray(self.offsets_ms, dtype=np.int64)[None, :]
        pos = np.mod(end, np.asarray(self.cycles_ms, dtype=np.int64)[None, :])
        if not self.windows_ms:
            return (pos > 0) & (pos <= np.asarray(self.greens_ms, dtype=np.int64)[None, :])
        out = np.zeros(pos.shape, dtype=bool)
        for m, windows in enumerate(self.windows_ms):
            for a, b in windows:
                out[:, m] |= (pos[:, m] > a) & (pos[:, m] <= b)
        return out


class PlanError(ConfigError):
    """A corridor the planners cannot plan on; one line naming why and what is accepted."""
