"""What the DP needs of a built scenario: the ego's start, the corridor's end, the stop lines and
SUMO's signal timing, read from the network SUMO runs (``envs.scenario.build``)."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

import numpy as np

from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.scenario import build

POSITION_EPS = 0.1  # [m] SUMO's POSITION_EPS: departPos "base" = vehicle length + this
MS = 1000  # [ms/s] SUMO's time unit


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

    @classmethod
    def from_config(cls, cfg: ScenarioConfig) -> Corridor:
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

    def first(self, k: int) -> Corridor:
        """The corridor with only its first ``k`` signals (tests: none, or a single red)."""
        return replace(self, stop_lines=self.stop_lines[:k], offsets_ms=self.offsets_ms[:k],
                       cycles_ms=self.cycles_ms[:k], greens_ms=self.greens_ms[:k])

    def green(self, t_start: np.ndarray, dt: float) -> np.ndarray:
        """(len(t_start), n stop lines) bool: the arterial is green in the step from ``t``."""
        t_ms = np.rint(np.asarray(t_start, dtype=float) * MS).astype(np.int64)
        end = t_ms[:, None] + int(round(dt * MS)) - np.asarray(self.offsets_ms, dtype=np.int64)[None, :]
        pos = np.mod(end, np.asarray(self.cycles_ms, dtype=np.int64)[None, :])
        return (pos > 0) & (pos <= np.asarray(self.greens_ms, dtype=np.int64)[None, :])
