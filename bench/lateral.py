"""The paper's synthetic lateral scenarios (section 5.4), scripted through the same environment.

A: the ego follows HDV1 in its lane; HDV1 brakes at -2 m/s^2 for three consecutive steps while
   HDV2 drives in the adjacent (left) lane.
B: the ego follows a platoon of HDVs that queues at the first intersection on red; the lane to
   the left holds a shorter queue and the one to the right none.
Both run on an empty corridor (no random demand) with uncoordinated signals, so every method
sees exactly the same situation. ``run_scenario`` returns the trajectories of the ego and the
scripted vehicles; the lateral behaviour is judged from them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from agents.base import Agent

from .episode import make_env

EMPTY = {"arterial_flow": 0.0, "side_flow": 0.0, "max_episode_time": 300.0}
HDV1_BRAKE = -2.0  # [m/s^2] (paper)
BRAKE_STEPS = 3  # (paper)
BRAKE_AT = 5  # [steps after the ego enters]
INSERT_A = 10.0  # [s] ego insertion, scenario A
INSERT_B = 40.0  # [s] ego insertion, scenario B: J1 is red when the platoon arrives


@dataclass(frozen=True)
class Scripted:
    vid: str
    lane_offset: int  # relative to the ego's lane (+1 = left)
    gap: float  # [m] ahead of the ego at insertion
    speed: float  # [m/s]
    hold: bool  # True: scripted speed (no Krauss); False: Krauss after insertion


SCENARIOS: dict[str, list[Scripted]] = {
    "A": [Scripted("hdv1", 0, 25.0, 13.0, True), Scripted("hdv2", 1, 8.0, 13.0, True)],
    "B": [Scripted(f"platoon{i}", 0, 40.0 + 9.0 * i, 13.0, False) for i in range(5)]
         + [Scripted(f"left{i}", 1, 70.0 + 9.0 * i, 13.0, False) for i in range(2)],
}


def run_scenario(name: str, agent: Agent, method: str) -> pd.DataFrame:
    """Trajectories (time, vehicle, x, lane, speed) of scenario ``name`` driven by ``agent``."""
    env = make_env(agent if not isinstance(agent, str) else method, "uncoordinated", EMPTY)
    obs, info = env.reset(options={"sumo_seed": 1, "insert_time": INSERT_A if name == "A" else INSERT_B})
    s = env.session
    x, _, _, _, _, lane, _ = env.ego.kin
    scripted = SCENARIOS[name]
    for v in scripted:
        target = min(max(lane + v.lane_offset, 0), env.cfg.lanes - 1)
        s.add_scripted(v.vid, lane=target, pos=x + v.gap, speed=v.speed)
        if not v.hold:
            s.release_speed(v.vid)
    rows: list[dict[str, Any]] = []
    step = 0
    while True:
        if name == "A" and BRAKE_AT <= step < BRAKE_AT + BRAKE_STEPS and "hdv1" in s.vehicle_ids():
            v1 = s.kinematics("hdv1")[3]
            s.set_speed("hdv1", max(0.0, v1 + HDV1_BRAKE * env.cfg.step_length))
        obs, r, te, tr, info = env.step(agent.act(obs, info, explore=False))
        t = s.time()
        ego = env.ego.kin
        rows.append({"time": t, "vehicle": "ego", "x": ego[0], "lane": ego[5], "speed": ego[3]})
        present = set(s.vehicle_ids())
        for v in scripted:
            if v.vid in present:
                k = s.kinematics(v.vid)
                rows.append({"time": t, "vehicle": v.vid, "x": k[0], "lane": k[5], "speed": k[3]})
        step += 1
        if te or tr:
            break
    env.close()
    df = pd.DataFrame(rows)
    df["method"] = method
    return df


def left_lane_of(df: pd.DataFrame, vid: str) -> bool:
    """Whether the ego ever drove in a lane other than ``vid``'s while behind it."""
    ego = df[df.vehicle == "ego"].set_index("time")
    other = df[df.vehicle == vid].set_index("time")
    both = ego.join(other, lsuffix="_ego", rsuffix="_o", how="inner")
    behind = both[both.x_ego < both.x_o]
    return bool((behind.lane_ego != behind.lane_o).any())


def queue_lengths(df: pd.DataFrame) -> dict[int, int]:
    """Vehicles stopped (speed < 0.1 m/s) per lane at the moment the longest queue formed."""
    others = df[(df.vehicle != "ego") & (df.speed < 0.1)]
    if others.empty:
        return {}
    t = others.groupby("time").size().idxmax()
    return others[others.time == t].groupby("lane").size().to_dict()


def final_lane(df: pd.DataFrame) -> int:
    return int(df[df.vehicle == "ego"].lane.iloc[-1])


def summary(df: pd.DataFrame, name: str, lanes: int = 5) -> dict[str, Any]:
    ego = df[df.vehicle == "ego"]
    out = {"scenario": name, "method": df.method.iloc[0], "lanes_visited": sorted(set(ego.lane)),
           "lane_changes": int((np.diff(ego.lane.to_numpy()) != 0).sum()), "final_lane": final_lane(df)}
    if name == "A":
        out["left_hdv1_lane"] = left_lane_of(df, "hdv1")
    else:
        q = queue_lengths(df)
        out["queues_by_lane"] = q
        fewest = min(q.get(ln, 0) for ln in range(lanes))
        out["ended_in_shortest_queue_lane"] = q.get(final_lane(df), 0) == fewest if q else None
    return out
