"""The clairvoyant reference's mathematics: the DP with the case's recorded traffic as moving obstacles.

A case's traffic is deterministic given its SUMO seed, so a drive of the case records the future
of every other vehicle. ``Recording`` holds it: per step from the ego's departure, every vehicle
heading east (front bumper x, y, length, speed; ``envs.sumo.SumoSession.eastbound``) and where the
recorded ego was. ``lane_obstacles`` turns it into the obstacles of one lane: at each step the
nearest vehicle ahead of the recorded ego that occupies the lane (its centre within
``LANE_HALF`` of the lane's, so a vehicle changing lanes occupies both). ``Obstacles.caps`` gives
the DP (``bench.oracle.dp.solve(obstacles=...)``) each step's highest row per speed: the ego's
front bumper stays ``MIN_GAP + MARGIN`` plus Krauss' safe distance behind that vehicle's rear,

    gap >= tau v + (v^2 - v_l^2) / (2 b),

which is exactly ``v <= v_safe`` of SUMO's Krauss model (tau = ``HEADWAY``, b = -a_min), so a plan
that keeps it is not clipped by the safety layer. A step's cap never lies below the rows full
braking reaches, so a cut-in that leaves no room makes the plan brake, not the problem infeasible.

``plan_lane`` solves the ``"cost"`` objective (E + phi T) for one lane; the harness
(``bench.harness.clairvoyant``) records, plans every lane, replays the cheapest in SUMO and, where
the ego's own presence changed the traffic, records that replay and plans again.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ecodrive_bench.envs.config import ScenarioConfig

from .dp import GRID_EPS, Corridor, Plan, _Lattice, solve
from .mpc import HEADWAY, MIN_GAP

MARGIN = 1.0  # [m] kept beyond SUMO's minGap and Krauss' safe distance: the plan's rows are rounded
LANE_HALF = 2.2  # [m] a vehicle whose y is this close to a lane's centre occupies the lane (lanes are 3.2 m)
NO_CAP = 1 << 40  # [rows] a step without a vehicle ahead
REFERENCE_ROUNDS = 4  # [-] plans per lane at most, each classing the vehicles against the last one


@dataclass(frozen=True)
class Recording:
    """A drive of one case: per step k from the ego's departure (time ``t0 + k dt``), the ego's front
    bumper ``ego_x[k]`` and the other eastbound vehicles ``traffic[k]``: their ids and rows of front
    bumper x, y [m], length [m], speed [m/s]."""

    t0: float  # [s] the ego's departure
    ego_x: np.ndarray  # [m] per step
    traffic: tuple[tuple[tuple[str, ...], np.ndarray], ...]  # per step: (ids, (n, 4) rows)


@dataclass(frozen=True)
class Obstacles:
    """The vehicle ahead in one lane per step: its rear bumper ``rear[k]`` (inf: none) and speed."""

    rear: np.ndarray  # [m]
    speed: np.ndarray  # [m/s]
    decel: float  # [m/s^2] b > 0: the ego's braking in Krauss' safe distance
    x0: float  # [m] the lattice's row 0: the ego's front bumper at its departure

    def caps(self, lat: _Lattice, steps: int) -> np.ndarray:
        """[steps, speeds] the highest row of each speed at each step (``NO_CAP``: none)."""
        out = np.full((steps, lat.nv + 1), NO_CAP, dtype=np.int64)
        n = min(steps, len(self.rear))
        v = np.arange(lat.nv + 1) * lat.dv
        vl = self.speed[:n, None]
        gap = np.maximum(0.0, HEADWAY * v[None, :] + (v[None, :] * v[None, :] - vl * vl) / (2.0 * self.decel))
        limit = self.rear[:n, None] - MIN_GAP - MARGIN - gap
        with np.errstate(invalid="ignore"):
            rows = np.floor((limit - self.x0) / lat.dx + GRID_EPS)
        out[:n] = np.where(np.isfinite(rows), rows, NO_CAP).astype(np.int64)
        lo, j = 0, lat.nv  # never below the rows full braking reaches (windows' first row)
        for k in range(steps):
            np.maximum(out[k], lo, out=out[k])
            j = max(0, j + lat.d_min)
            lo += j
        return out


def lane_obstacles(rec: Recording, lane_y: tuple[float, ...], lanes: list[set[int]], decel: float,
                   x0: float, ref_x: np.ndarray | None = None) -> Obstacles:
    """The obstacles of the lanes ``lanes[k]`` at step k (the last entry for every later step).

    A lane's order does not change, so a vehicle is ahead of the ego or behind it for as long as it
    stays in the lane: it is classed when it enters the lane (or at the departure), ahead if its
    front is then ahead of the ego's ``ref_x`` (default: the recorded ego's; a planner iterates it
    with its own plan's positions, ``plan_lane``). Vehicles inserted behind the ego, and ones the ego
    had passed when they changed in, stay behind it: their recorded paths do not hold the ego up
    (in SUMO they follow it). At each step the obstacle is the nearest vehicle ahead."""
    n = len(rec.traffic)
    rear, speed = np.full(n, np.inf), np.zeros(n)
    ys = np.asarray(lane_y)
    ref = rec.ego_x if ref_x is None else ref_x
    ahead: dict[str, bool] = {}  # vehicles in the lanes now -> classed ahead
    for k, (ids, tr) in enumerate(rec.traffic):
        mine = np.array(sorted(lanes[min(k, len(lanes) - 1)]))
        occupies = (np.abs(tr[:, 1:2] - ys[None, mine]) < LANE_HALF).any(axis=1) if len(tr) else np.zeros(0, bool)
        now: dict[str, bool] = {}
        best = np.inf
        for i in np.flatnonzero(occupies):
            vid = ids[i]
            front = tr[i, 0]
            is_ahead = ahead[vid] if vid in ahead else bool(front > ref[min(k, len(ref) - 1)])
            now[vid] = is_ahead
            if is_ahead and front - tr[i, 2] < best:
                best, rear[k], speed[k] = front - tr[i, 2], front - tr[i, 2], tr[i, 3]
        ahead = now
    return Obstacles(rear, speed, decel, x0)


def merged(obstacles: list[Obstacles]) -> Obstacles:
    """The nearest vehicle ahead at each step over several recordings' obstacles (of one lane)."""
    n = max(len(o.rear) for o in obstacles)
    rear, speed = np.full(n, np.inf), np.zeros(n)
    for o in obstacles:
        m = len(o.rear)
        closer = o.rear < rear[:m]
        rear[:m] = np.where(closer, o.rear, rear[:m])
        speed[:m] = np.where(closer, o.speed, speed[:m])
    return Obstacles(rear, speed, obstacles[0].decel, obstacles[0].x0)


def plan_lane(cor: Corridor, cfg: ScenarioConfig, recs: list[Recording], lane_y: tuple[float, ...],
              lanes: list[set[int]]) -> Plan:
    """The least-cost plan (E + phi T) behind the vehicles of ``lanes`` in every recording of
    ``recs`` (``lane_obstacles``, ``merged``: a vehicle that cut in front of the ego in one replay
    stays an obstacle), Krauss' stop-for-red cap obeyed. Whether a vehicle that changes into the lane is ahead depends
    on where the ego is then, so the plan is solved again with its own positions as the reference
    until the vehicles ahead stop changing (at most ``REFERENCE_ROUNDS``). A ValueError where no
    plan exists."""
    ref, seen, plan = None, [], None
    for _ in range(REFERENCE_ROUNDS):
        ob = merged([lane_obstacles(rec, lane_y, lanes, -cfg.a_min, cor.x0, ref) for rec in recs])
        if any(np.array_equal(ob.rear, r) for r in seen):
            break
        seen.append(ob.rear)
        plan = solve(cor, cfg, recs[0].t0, "cost", krauss=True, obstacles=ob)
        ref = plan.x
    assert plan is not None
    return plan


@dataclass(frozen=True)
class Tracks:
    """A recording by vehicle: ``front[vid][k]``, ``y[vid][k]`` and ``speed[vid][k]`` at step k (NaN
    where the vehicle is not on the road, or not eastbound)."""

    front: dict[str, np.ndarray]
    y: dict[str, np.ndarray]
    speed: dict[str, np.ndarray]
    length: dict[str, float]

    @classmethod
    def of(cls, rec: Recording) -> Tracks:
        n = len(rec.traffic)
        front: dict[str, np.ndarray] = {}
        y: dict[str, np.ndarray] = {}
        speed: dict[str, np.ndarray] = {}
        length: dict[str, float] = {}
        for k, (ids, tr) in enumerate(rec.traffic):
            for i, vid in enumerate(ids):
                if vid not in front:
                    front[vid], y[vid], speed[vid] = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
                    length[vid] = float(tr[i, 2])
                front[vid][k], y[vid][k], speed[vid][k] = tr[i, 0], tr[i, 1], tr[i, 3]
        return cls(front, y, speed, length)


def ahead_future(tracks: Tracks | None, k: int, steps: int, ids: tuple[str, ...], rows: np.ndarray,
                 x: float, lane_y: float) -> tuple[np.ndarray, np.ndarray]:
    """(rear [m], speed [m/s]) of the nearest vehicle ahead in the lane centred at ``lane_y`` at each
    look-ahead step 0..``steps`` from step ``k``: the vehicles in it ahead of the ego's front bumper
    ``x`` now (``ids``, ``rows``: the road now, ``envs.env.EcoDriveEnv.traffic``), each moved as the
    recording moved it from step k (inf: none; a vehicle the recording lacks, or that leaves the
    lane there, is held at its speed now for one step and then dropped)."""
    rear, speed = np.full(steps + 1, np.inf), np.zeros(steps + 1)
    if not len(rows):
        return rear, speed
    mine = (np.abs(rows[:, 1] - lane_y) < LANE_HALF) & (rows[:, 0] > x)
    for i in np.flatnonzero(mine):
        vid, now_rear, now_v = ids[i], rows[i, 0] - rows[i, 2], rows[i, 3]
        f = None if tracks is None else tracks.front.get(vid)
        if f is None or k >= len(f) or np.isnan(f[k]):
            path, vs = np.array([now_rear, now_rear + now_v]), np.array([now_v, now_v])
        else:
            end = min(len(f), k + steps + 1)
            seg, ys = f[k:end], tracks.y[vid][k:end]
            stay = ~np.isnan(seg) & (np.abs(ys - lane_y) < LANE_HALF)
            stay[0] = True
            last = int(np.argmin(stay)) if not stay.all() else len(stay)
            path = now_rear + (seg[:last] - f[k])
            vs = np.nan_to_num(tracks.speed[vid][k:k + last], nan=now_v)
        m = len(path)
        closer = path < rear[:m]
        rear[:m] = np.where(closer, path, rear[:m])
        speed[:m] = np.where(closer, vs, speed[:m])
    return rear, speed


def gap_caps(rear: np.ndarray, speed: np.ndarray, decel: float, x0: float) -> Callable[[_Lattice, int], np.ndarray]:
    """``caps(lat, m)``: the highest row of each speed at look-ahead step m behind ``rear[m]``
    (``MIN_GAP + MARGIN`` and Krauss' safe distance, as ``Obstacles.caps``), for ``mpc.replan``."""
    cache: dict[tuple[int, int], np.ndarray] = {}

    def caps(lat: _Lattice, m: int) -> np.ndarray:
        key = (lat.nv, m)
        if key not in cache:
            v = np.arange(lat.nv + 1) * lat.dv
            r, vl = rear[min(m, len(rear) - 1)], speed[min(m, len(speed) - 1)]
            if not np.isfinite(r):
                cache[key] = np.full(lat.nv + 1, NO_CAP, dtype=np.int64)
            else:
                gap = np.maximum(0.0, HEADWAY * v + (v * v - vl * vl) / (2.0 * decel))
                cache[key] = np.floor((r - MIN_GAP - MARGIN - gap - x0) / lat.dx + GRID_EPS).astype(np.int64)
        return cache[key]
    return caps
