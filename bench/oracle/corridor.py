"""What the DP needs of a built scenario: the ego's start, the corridor's end, the stop lines,
SUMO's signal timing and the speed limits, read from the network SUMO runs: the generated
arterial's (``envs.scenario.build``, x coordinates, one green window per cycle, one speed limit)
or a network corridor's route frame (``envs.route``: positions along the route, the green windows
of the route's links, the limits of its edges and junctions)."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ecodrive_bench.envs.config import ConfigError, ScenarioConfig
from ecodrive_bench.envs.scenario import build

POSITION_EPS = 0.1  # [m] SUMO's POSITION_EPS: departPos "base" = vehicle length + this
MS = 1000  # [ms/s] SUMO's time unit
STOP_EPS = 1e-3  # [m] a stop line at the ego's start (a first edge shorter than the ego) lies this far ahead
LIMIT_TOL = 0.05  # [m/s] a network's limit this close to speed_limit is taken as it (13.89 for 50 km/h)


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
        if cfg.network is not None:
            return cls.from_route(cfg)
        files = build(cfg)
        net = ET.parse(files.net).getroot()

        def lane_start(edge: str) -> float:
            lane = net.find(f"./edge[@id='{edge}']/lane")
            if lane is None:
                raise RuntimeError(f"edge {edge} not found in {files.net}")
            return float(lane.get("shape").split()[0].split(",")[0])

        def sumo_ms(seconds: float) -> int:  # the .add.xml writes "%g"; SUMO keeps milliseconds
            return int(round(float(f"{seconds:g}") * MS))

        timing, y = cfg.timing, cfg.yellow  # a cycle is the sum of the phases SUMO read
        return cls(
            x0=lane_start(files.arterial_edges[0]) + cfg.vehicle_length + POSITION_EPS,
            v0=cfg.speed_limit, x_end=lane_start(files.exit_edge), stop_lines=tuple(files.stop_lines),
            offsets_ms=tuple(sumo_ms(t.offset) for t in timing), greens_ms=tuple(sumo_ms(t.green) for t in timing),
            cycles_ms=tuple(sumo_ms(t.green) + 2 * sumo_ms(y) + sumo_ms(t.cycle - t.green - 2 * y) for t in timing),
        )

    @classmethod
    def from_route(cls, cfg: ScenarioConfig) -> Corridor:
        """A network corridor's, in its route frame; a ``PlanError`` where a signal on the route is
        not fixed-time or a limit on it is above ``cfg.speed_limit`` (the lattice's top speed)."""
        from ecodrive_bench.envs.network import corridor_files  # noqa: PLC0415

        route = corridor_files(cfg).route
        assert route is not None
        moving = [c.tls for c in route.crossings if not c.static]
        if moving:
            raise PlanError(f"signal {moving[0]!r:.60} on the route is not fixed-time; accepted for the planners: "
                            f"static programs only (an actuated signal's future is not known)")
        top = max(v for _, _, v in route.limits)
        if top > cfg.speed_limit + LIMIT_TOL:
            raise PlanError(f"the route's speed limit {top:g} m/s is above speed_limit={cfg.speed_limit:g}; "
                            f"accepted for the planners: limits up to speed_limit")
        below = tuple((a, b, v) for a, b, v in route.limits if v < cfg.speed_limit - LIMIT_TOL)
        c = route.crossings
        x0 = min(route.lengths[0], cfg.vehicle_length + POSITION_EPS)  # SUMO puts a longer vehicle at the lane's end
        return cls(
            x0=x0, v0=min(cfg.speed_limit, route.limits[0][2]), x_end=route.offsets[-1],
            stop_lines=tuple(max(x.stop_line, x0 + STOP_EPS) for x in c), offsets_ms=tuple(x.offset_ms for x in c),
            cycles_ms=tuple(x.cycle_ms for x in c), greens_ms=tuple(sum(b - a for a, b in x.windows_ms) for x in c),
            windows_ms=tuple(x.windows_ms for x in c), limits=below)

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
