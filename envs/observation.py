"""Observation type: the paper's occupancy grid plus logic vector (section 3.2).

``occupancy_grid`` and ``logic_vector`` are pure functions of arrays; ``GridLogicObservation``
gathers those arrays from the SUMO session for any vehicle ID.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from gymnasium import spaces

from . import safety
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


def lane_frame(shape: Sequence[tuple[float, float]], pos: float) -> tuple[float, float, float, float]:
    """(x, y) of the point ``pos`` [m] along the polyline ``shape``, and the unit direction (dx, dy)
    of its segment there (the first segment extended before the start, the last past the end)."""
    segs = [(x0, y0, x1, y1, d) for (x0, y0), (x1, y1) in zip(shape, shape[1:]) if (d := math.hypot(x1 - x0, y1 - y0)) > 0]
    if not segs:
        return float(shape[0][0]), float(shape[0][1]), 1.0, 0.0
    i = 0
    while pos > segs[i][4] and i < len(segs) - 1:  # walk to the segment that holds pos
        pos -= segs[i][4]
        i += 1
    x0, y0, x1, y1, d = segs[i]
    dx, dy = (x1 - x0) / d, (y1 - y0) / d
    return x0 + dx * pos, y0 + dy * pos, dx, dy


def to_route_frame(others: np.ndarray, cx: float, cy: float, dx: float, dy: float) -> np.ndarray:
    """Rows [x, y, angle, length] moved into the frame whose origin is (cx, cy) and whose x axis
    runs along (dx, dy), y to its left: [along, left, angle relative to the axis + 90, length], so
    a vehicle heading along the route reads as heading east, as on the generated arterial."""
    if not len(others):
        return _NONE
    axis = math.degrees(math.atan2(dx, dy))  # SUMO angle (clockwise from north) of the axis
    return _to_frame(others, cx, cy, dx, dy, axis)


@compiled
def _to_frame(others: np.ndarray, cx: float, cy: float, dx: float, dy: float, axis: float) -> np.ndarray:
    """``to_route_frame``'s arithmetic, row by row (compiled: numpy's per-call overhead on a few
    tens of rows cost more than the work); the same operations in the same order as numpy's."""
    out = np.empty_like(others)
    for i in range(others.shape[0]):
        rx, ry = others[i, 0] - cx, others[i, 1] - cy
        out[i, 0] = rx * dx + ry * dy
        out[i, 1] = ry * dx - rx * dy
        out[i, 2] = (others[i, 2] - axis + HEADING_EAST) % 360.0
        out[i, 3] = others[i, 3]
    return out


@dataclass
class RoutePlace:
    """Where one vehicle is on its route, kept from step to step (each vehicle has its own)."""

    widths: tuple[float, ...] = ()  # [m] lane widths of the last route edge it was on, rightmost first
    road: str = ""  # that edge (``widths`` are read again only when it changes)
    lane: int = 0  # its lane index there
    edge: str = ""  # the edge it is on (an internal one inside a junction)
    internal: bool = False  # it is on a junction's internal lane
    exit: tuple[int, float] = (0, 0.0)  # (last route edge it was on, the odometer at that edge's end [m])
    lane_place: tuple[str, float] | None = None  # ``along``'s (lane id, position), which the next ``observe`` reuses
    best: dict[str, dict[int, bool]] = field(default_factory=dict)  # edge -> lane index -> it continues the route


class GridLogicObservation:
    """Dict observation {"grid": (rows, observed lanes) in {0,1}, "logic": (observed lanes + 4,)},
    taken in the vehicle's route frame (``envs.route``; the generated arterial is one such route,
    whose frame is its x axis): the grid's x axis runs along the vehicle's lane where the vehicle is,
    its origin on that lane's centre line; its lanes are those of the edge the vehicle is on (on a
    junction's internal lane, the edge it came from), lane 0 rightmost. A lane change is allowed
    only towards a lane that continues the route (SUMO's best lanes), and LC2013's verdict applies.
    Positions (``along``) are the distance driven along the route. What a vehicle's place was is
    its own ``RoutePlace``, so one observation type serves any number of vehicles."""

    def __init__(self, cfg: ScenarioConfig, files: ScenarioFiles) -> None:
        self.cfg = cfg
        self._rows, self._lanes = cfg.grid_shape
        self.space = observation_space(cfg)
        self._high = self.space["logic"].high
        self.route = files.route
        self._index = {e: r for r, e in enumerate(self.route.edges)}  # route edge -> its index
        self._first = (tuple(self.route.lane_widths), 0)  # before a vehicle's first edge is read

    def place(self) -> RoutePlace:
        """A new vehicle's place (``ControlledVehicle`` keeps one)."""
        widths, lane = self._first
        return RoutePlace(widths=widths, lane=lane)

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

    def along(self, session: SumoSession, vid: str, kin: Kinematics, place: RoutePlace) -> float:
        """The front bumper's position in the route frame (``envs.route``): the edge's offset plus
        the lane position on a route edge; on a junction's internal lane, the end of the edge it
        came from plus the distance driven since, at most the next edge's offset."""
        lane_id, pos = place.lane_place = session.lane_place(vid)
        odo = session.odometer(vid)
        route = self.route
        r = self._index.get(lane_id.rsplit("_", 1)[0])
        if r is not None:
            place.exit = (r, odo + route.lengths[r] - pos)
            return route.offsets[r] + pos
        r, odo_end = place.exit
        x = route.offsets[r] + route.lengths[r] + max(0.0, odo - odo_end)
        return min(x, route.offsets[r + 1]) if r + 1 < len(route.offsets) else x

    @staticmethod
    def same_road(edge0: str, edge1: str) -> bool:
        """Whether a lane index read on ``edge0`` and one on ``edge1`` number the same lanes."""
        return edge0 == edge1

    def mask(self, session: SumoSession, vid: str, lane: int, place: RoutePlace) -> np.ndarray:
        """The lateral mask over k: the edge's lanes, those that continue the route, and LC2013's
        verdict (``safety.lane_mask``); no change inside a junction."""
        if place.internal:
            return safety.lane_mask(lane, 1, False, False)
        cont = place.best.get(place.edge)
        if cont is None:  # a vehicle's route is fixed: which lanes of an edge continue it is read once
            cont = place.best[place.edge] = session.route_lanes(vid)
        left = cont.get(lane + 1, False) and session.could_change(vid, 1)
        right = cont.get(lane - 1, False) and session.could_change(vid, -1)
        return safety.lane_mask(lane, len(place.widths), left, right)

    def observe(
        self, session: SumoSession, vid: str, kin: Kinematics, neighbours: dict, place: RoutePlace
    ) -> tuple[dict[str, np.ndarray], SignalView | None, list[tuple[float, float, float, float]]]:
        """Observation of ``vid``; also returns its signal view and the others' [x, y, angle, length]
        (SUMO's coordinates). ``along`` has just been read for the same state: its lane place is
        not read again."""
        x, y, _, speed, _, _, edge = kin
        place.edge, place.internal = edge, edge.startswith(":")
        if edge and not place.internal:
            if edge != place.road:  # a new edge: its lanes' widths, read once per edge
                n = session.edge_lanes(edge)
                place.widths, place.road = tuple(session.lane_geometry(f"{edge}_{i}")[1] for i in range(n)), edge
            place.lane = kin.lane
        widths, lane = place.widths, place.lane
        lane_id, pos = place.lane_place if place.lane_place is not None else session.lane_place(vid)
        place.lane_place = None
        shape, _ = session.lane_geometry(lane_id)
        cx, cy, dx, dy = lane_frame(shape, pos)
        others = [(*v[VAR_POSITION], v[VAR_ANGLE], v[VAR_LENGTH]) for k, v in neighbours.items() if k != vid]
        rows = to_route_frame(np.array(others, dtype=np.float64).reshape(-1, 4), cx, cy, dx, dy)
        centres = np.cumsum((np.asarray(widths) + np.concatenate(([0.0], widths[:-1]))) / 2)
        lane_y = (centres - centres[min(lane, len(centres) - 1)])[: self._lanes]
        ego_along = (x - cx) * dx + (y - cy) * dy
        grid = _grid(rows, lane_y, self._rows, self._lanes, ego_along - self.cfg.grid_behind, 1.0 / self.cfg.cell_length)
        sig = self.signal(session, vid)
        n_obs = self.cfg.observed_lanes
        if sig is None:
            logic = logic_vector(lane, n_obs, 0.0, speed, NO_V2I, NO_V2I)
        else:
            logic = logic_vector(lane, n_obs, min(sig.distance, self._high[-4]), speed, sig.red,
                                 min(sig.time_to_green, self._high[-1]))
        return {"grid": grid, "logic": logic}, sig, others
