"""Observation type: the paper's occupancy grid plus logic vector (section 3.2).

``occupancy_grid`` and ``logic_vector`` are pure functions of arrays; ``GridLogicObservation``
gathers those arrays from the SUMO session for any vehicle ID.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from .config import ScenarioConfig
from .jit import compiled
from .scenario import LANE_WIDTH, ScenarioFiles
from .sumo import VAR_ANGLE, VAR_LENGTH, VAR_POSITION, Kinematics, SumoSession

NO_V2I = -1.0  # red flag and time to green outside V2I range (paper)
HEADING_EAST = 90.0  # [deg] SUMO angle of W->E travel
CROSS_HALF_LENGTH = 1.0  # [m] footprint half-length of a crossing vehicle along the arterial
_RED = frozenset("rRyYu")


def occupancy_grid(
    ego_x: float, others: Sequence[Sequence[float]], lane_y: Sequence[float], cfg: ScenarioConfig
) -> np.ndarray:
    """Grid of shape (rows, observed lanes); row 0 is ``grid_behind`` m behind the ego's front
    bumper, the last row ``grid_ahead`` m ahead; lane 0 is the rightmost. 1 = free, 0 = occupied.
    Columns beyond the road's lanes (``cfg.obs_lanes`` > ``len(lane_y)``) read as occupied.

    ``others``: rows of [x, y, angle (deg), length (m)] of the other vehicles (front bumper
    positions, as SUMO reports them; a sequence or an (N, 4) array; a non-finite value is a
    ``ValueError``). A vehicle is in the lane whose centre is nearest (within
    half a lane width); heading along the arterial (within 45 deg) it covers [x - length, x],
    crossing a junction [x - 1, x + 1] m; it marks every cell it overlaps.
    """
    rows, lanes = cfg.grid_shape
    vehicles = np.array(others, dtype=np.float64).reshape(-1, 4) if len(others) else _NONE
    return _grid(vehicles, np.asarray(lane_y, dtype=np.float64), rows, lanes, ego_x - cfg.grid_behind,
                 1.0 / cfg.cell_length)


_NONE = np.zeros((0, 4))  # no other vehicle


def _grid(vehicles: np.ndarray, lane_y: np.ndarray, rows: int, lanes: int, origin: float, inv: float) -> np.ndarray:
    """``occupancy_grid`` of (N, 4) float64 rows: one compiled call, or the ``ValueError`` that
    names the first non-finite rows."""
    grid = _fill(vehicles, lane_y, rows, lanes, origin, inv, LANE_WIDTH / 2)
    if grid.shape[0] != rows:  # _fill's signal: a vehicle row is not finite
        bad = vehicles[~np.isfinite(vehicles).all(axis=1)][:3].tolist()
        raise ValueError(f"neighbour rows must be finite [x, y, angle, length]; got {bad}")
    return grid


@compiled
def _fill(others: np.ndarray, lane_y: np.ndarray, rows: int, lanes: int, origin: float, inv: float,
          half: float) -> np.ndarray:
    """A new (rows, lanes) float32 grid of ones, the lanes past ``lane_y``'s zeroed and the cells of
    ``others`` marked (``_mark``); an empty grid when a value of ``others`` is not finite. One
    compiled call a step: numpy's per-call overhead, paid with cold caches after every SUMO step,
    cost several times the work."""
    for i in range(others.shape[0]):
        for j in range(4):
            if not math.isfinite(others[i, j]):
                return np.empty((0, lanes), dtype=np.float32)
    grid = np.ones((rows, lanes), dtype=np.float32)
    n = lane_y.shape[0]
    grid[:, n:] = 0.0  # lanes the road does not have
    if others.shape[0]:
        pitch = (lane_y[n - 1] - lane_y[0]) / (n - 1) if n > 1 else 1.0
        _mark(grid, others, lane_y, origin, inv, half, pitch)
    return grid


@compiled
def _mark(grid: np.ndarray, others: np.ndarray, lane_y: np.ndarray, origin: float, inv: float, half: float,
          pitch: float) -> None:
    """Mark the cells ``others`` (N, 4) occupy in ``grid`` (compiled: a loop over tens of vehicles
    a step, where numpy's per-call overhead would dominate). Lanes are rounded half to even, as
    Python's ``round``."""
    rows, n = grid.shape[0], lane_y.shape[0]
    for i in range(others.shape[0]):
        x, y, angle, length = others[i, 0], others[i, 1], others[i, 2], others[i, 3]
        lane = 0
        if n > 1:
            v = (y - lane_y[0]) / pitch
            r = math.floor(v)
            if v - r > 0.5 or (v - r == 0.5 and r % 2 != 0):
                r += 1
            lane = int(r)
        if not 0 <= lane < n or abs(y - lane_y[lane]) > half:
            continue
        if abs((angle - HEADING_EAST + 180.0) % 360.0 - 180.0) < 45.0:
            back, front = x - length, x
        else:  # crossing traffic inside a junction
            back, front = x - CROSS_HALF_LENGTH, x + CROSS_HALF_LENGTH
        lo = max(0, math.floor((back - origin) * inv))
        hi = min(rows, math.ceil((front - origin) * inv))
        for c in range(lo, hi):
            grid[c, lane] = 0.0


def logic_vector(
    lane: int, lanes: int, distance: float, speed: float, red: float, time_to_green: float
) -> np.ndarray:
    """[lane one-hot (lanes), distance to next stop line [m], speed [m/s], red flag, time to green [s]]."""
    vec = np.zeros(lanes + 4, dtype=np.float32)
    if 0 <= lane < lanes:
        vec[lane] = 1.0
    vec[lanes:] = (distance, speed, red, time_to_green)
    return vec


@dataclass
class SignalView:
    """What V2I tells the vehicle about its next signal (None fields outside the network)."""

    tls: str
    link: int
    distance: float  # [m] to the stop line
    state: str  # SUMO state char of the vehicle's link
    in_range: bool
    red: float  # 1 red / 0 green / -1 unknown (out of V2I range)
    time_to_green: float  # [s]; -1 out of V2I range


def observation_space(cfg: ScenarioConfig) -> spaces.Dict:
    """The observation space of ``cfg``: a function of the config alone, so a policy's space can
    be rebuilt from the scenario it was trained on (its logic bounds are its input scaling)."""
    rows, lanes = cfg.grid_shape
    d_max = cfg.max_spacing * 2 + cfg.side_length  # generous bound on distance to the next stop line
    low = np.array([0.0] * lanes + [0.0, 0.0, -1.0, -1.0], dtype=np.float32)
    high = np.array([1.0] * lanes + [d_max, cfg.speed_limit * 1.5, 1.0, cfg.max_cycle], dtype=np.float32)
    return spaces.Dict({
        "grid": spaces.Box(0.0, 1.0, shape=(rows, lanes), dtype=np.float32),
        "logic": spaces.Box(low, high, dtype=np.float32),
    })


class GridLogicObservation:
    """Dict observation {"grid": (rows, observed lanes) in {0,1}, "logic": (observed lanes + 4,)}."""

    def __init__(self, cfg: ScenarioConfig, files: ScenarioFiles) -> None:
        self.cfg = cfg
        self.lane_y = tuple(files.lane_y)
        self._lane_y = np.asarray(self.lane_y, dtype=np.float64)
        self._rows, self._lanes = cfg.grid_shape
        self.space = observation_space(cfg)
        self._high = self.space["logic"].high

    def signal(self, session: SumoSession, vid: str) -> SignalView | None:
        nxt = session.next_signal(vid)
        if nxt is None:
            return None
        tls, link, dist, state = nxt
        if dist > self.cfg.v2i_range:
            return SignalView(tls, link, dist, state, False, NO_V2I, NO_V2I)
        red = 1.0 if state in _RED else 0.0
        ttg = session.time_to_green(tls, link) if red else 0.0
        return SignalView(tls, link, dist, state, True, red, ttg)

    def observe(
        self, session: SumoSession, vid: str, kin: Kinematics, neighbours: dict
    ) -> tuple[dict[str, np.ndarray], SignalView | None, list[tuple[float, float, float, float]]]:
        """Observation of ``vid``; also returns its signal view and the others' [x, y, angle, length]."""
        x, _, _, speed, _, lane, _ = kin
        others = [(*v[VAR_POSITION], v[VAR_ANGLE], v[VAR_LENGTH]) for k, v in neighbours.items() if k != vid]
        cfg = self.cfg  # occupancy_grid, with its constants kept
        grid = _grid(np.array(others, dtype=np.float64).reshape(-1, 4) if others else _NONE, self._lane_y, self._rows,
                     self._lanes, x - cfg.grid_behind, 1.0 / cfg.cell_length)
        sig = self.signal(session, vid)
        if sig is None:
            logic = logic_vector(lane, self.cfg.observed_lanes, 0.0, speed, NO_V2I, NO_V2I)
        else:
            logic = logic_vector(lane, self.cfg.observed_lanes, min(sig.distance, self._high[-4]), speed, sig.red,
                                 min(sig.time_to_green, self._high[-1]))
        return {"grid": grid, "logic": logic}, sig, others
