"""The clairvoyant reference's mathematics: the case's recorded traffic as moving obstacles of the DP.

A case's traffic is deterministic given its SUMO seed, so a drive of the case records the future
of every other vehicle. ``Recording`` holds it: per step from the ego's departure, every vehicle
on the ego's route (id, front bumper along the route, lane index times a pitch, length, speed;
``envs.env.EcoDriveEnv.traffic``) and where the recorded ego was; ``Tracks`` holds the same by vehicle.

``ahead_future`` gives, over a re-plan's look-ahead, the nearest vehicle ahead of the ego in a lane:
the vehicles in the lane ahead of the ego now, each moved as the recording moved it from now (a
vehicle occupies a lane while its centre is within ``LANE_HALF`` of the lane's). ``gap_caps`` turns
that into what ``bench.oracle.mpc.replan(caps=...)`` masks: at each look-ahead step, the highest
row of each speed, the ego's front bumper ``MIN_GAP + MARGIN`` plus Krauss' safe distance behind
the vehicle's rear,

    gap >= tau v + (v^2 - v_l^2) / (2 b),

which is exactly ``v <= v_safe`` of SUMO's Krauss model (tau = ``HEADWAY``, b = -a_min), so a plan
that keeps it is not clipped by the safety layer. The harness (``bench.methods.clairvoyant_agent``)
records, drives, and records again.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .lattice import GRID_EPS, Lattice
from .mpc import HEADWAY, MIN_GAP

MARGIN = 1.0  # [m] kept beyond SUMO's minGap and Krauss' safe distance: the plan's rows are rounded
LANE_HALF = 2.2  # [m] a vehicle whose y is this close to a lane's centre occupies the lane (lanes are 3.2 m)
NO_CAP = 1 << 40  # [rows] a step without a vehicle ahead


@dataclass(frozen=True)
class Recording:
    """A drive of one case: per step k from the ego's departure (time ``t0 + k dt``), the ego's front
    bumper ``ego_x[k]`` and the other vehicles on the route ``traffic[k]``: their ids and rows of front
    bumper x, y [m], length [m], speed [m/s]."""

    t0: float  # [s] the ego's departure
    ego_x: np.ndarray  # [m] per step
    traffic: tuple[tuple[tuple[str, ...], np.ndarray], ...]  # per step: (ids, (n, 4) rows)


@dataclass(frozen=True)
class Tracks:
    """A recording by vehicle: ``front[vid][k]``, ``y[vid][k]`` and ``speed[vid][k]`` at step k (NaN
    where the vehicle is not on the route)."""

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


def gap_caps(rear: np.ndarray, speed: np.ndarray, decel: float, x0: float) -> Callable[[Lattice, int], np.ndarray]:
    """``caps(lat, m)``: the highest row of each speed at look-ahead step m behind ``rear[m]``
    (``MIN_GAP + MARGIN`` and Krauss' safe distance), for ``mpc.replan``."""
    cache: dict[tuple[int, int], np.ndarray] = {}

    def caps(lat: Lattice, m: int) -> np.ndarray:
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
