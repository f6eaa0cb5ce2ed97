"""Why PRL CVs stall in mixed traffic: the state and every head's choice during long stalls.

    ecodrive stalls [--signals coordinated] [--mpr 1] [--demand 300] [--duration 900]
                           [--at 20 100 250] [--out stalls.parquet]

Runs one mixed-traffic cell (by default the regression's coordinated MPR-1 cell) with the shipped
PRL policy. Whenever a CV has been stalled (``envs.fleet.stalled``: standing, more than 10 m free
ahead, no red light) for exactly one of the ``--at`` durations, it records the CV's logic vector,
the free length ahead and the nearest vehicle behind in every lane, its lane-change mask, the
greedy head and every head's Q value and acceleration. P-DQN gives each lane decision k its own
acceleration x_k(s), so a stall can come from a head the mask forces on the vehicle.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.args import Parser, fail, float_in, int_in
from ecodrive_bench.bench.experiments.mixed import CI_DEMAND, CI_DURATION, MASTER_SEED, cell_scenario
from ecodrive_bench.bench.io import Unwritable, atomic_parquet, writable_dir
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError, acting_config, load_policy, policy_dir
from ecodrive_bench.envs.action import LATERAL
from ecodrive_bench.envs.config import SIGNALS

HEADS = ("left", "stay", "right")  # LATERAL order: k = -1, 0, +1


def lane_gaps(grid: np.ndarray, front: int, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Per lane: free length ahead of the ego's front bumper and distance to the nearest occupied
    cell behind it [m]; NaN where the grid shows none."""
    rows, lanes = grid.shape
    ahead, behind = np.full(lanes, np.nan), np.full(lanes, np.nan)
    for j in range(lanes):
        occ_ahead = np.flatnonzero(grid[front:, j] < 0.5)
        occ_behind = np.flatnonzero(grid[:front, j][::-1] < 0.5)
        if occ_ahead.size:
            ahead[j] = occ_ahead[0] * cell
        if occ_behind.size:
            behind[j] = (occ_behind[0] + 1) * cell
    return ahead, behind


def trace(signals: str, mpr: float, demand: float, duration: float, at: tuple[int, ...], rep: int = 0,
          models: Path = MODELS) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """(one row per CV reaching a stall length in ``at`` [steps], the cell's fleet summary)."""
    import torch

    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.envs.fleet import Fleet

    torch.set_num_threads(1)
    cfg = cell_scenario(signals, mpr, demand)
    fleet = Fleet(cfg)
    state, manifest = load_policy(policy_dir("prl", signals, models), "prl")  # trained alone, driven in a fleet
    agent = make_agent("prl", fleet.obs_type.space, fleet.action_type.space,
                       **acting_config(manifest.get("agent_config") or {}))
    agent.load_state_dict(state)
    lanes, front = cfg.observed_lanes, int(round(cfg.grid_behind / cfg.cell_length))
    rows: list[dict[str, Any]] = []

    def policy(grids: np.ndarray, logics: np.ndarray, masks: np.ndarray) -> list:
        q, accel = agent.heads(grids, logics)
        k = np.argmax(np.where(np.asarray(masks, dtype=bool), q, -np.inf), axis=1)
        for i, vid in enumerate(fleet.cvs):  # the order Fleet.step built the batch in
            run = fleet.stall_run(vid)
            if run not in at:
                continue
            ahead, behind = lane_gaps(grids[i], front, cfg.cell_length)
            lane = int(logics[i, :lanes].argmax())
            distance, speed, red, ttg = (float(v) for v in logics[i, lanes:])
            row = {"time": fleet.sim_time(), "vehicle": vid, "stalled_s": run * cfg.step_length, "lane": lane,
                   "distance": distance, "speed": speed, "red": red, "time_to_green": ttg,
                   "mask": "".join(str(int(m)) for m in masks[i]), "k": LATERAL[k[i]],
                   "accel": float(accel[i, k[i]])}
            row.update({f"q_{h}": float(q[i, j]) for j, h in enumerate(HEADS)})
            row.update({f"a_{h}": float(accel[i, j]) for j, h in enumerate(HEADS)})
            row.update({f"ahead_{j}": ahead[j] for j in range(lanes)})
            row.update({f"behind_{j}": behind[j] for j in range(lanes)})
            rows.append(row)
        return [(int(ki), a) for ki, a in zip(k, accel)]

    fleet.start(MASTER_SEED + rep)
    try:
        for _ in range(int(duration / cfg.step_length)):
            fleet.step(policy)
    finally:
        fleet.close()
    summary = fleet.summary(route_length=cfg.n_intersections * cfg.spacing)
    summary["stall_steps"], summary["longest_stall_s"] = fleet.stats.stall_steps, fleet.stats.longest_stall_s
    return rows, summary


def describe(df: pd.DataFrame) -> str:
    """What the stalled CVs were told to do, in a few lines."""
    if df.empty:
        return "no CV reached the given stall lengths"
    forced = df["mask"] == "010"
    lines = [f"{len(df)} stall records, {df.vehicle.nunique()} CVs",
             f"greedy acceleration <= 0: {(df.accel <= 0).mean():.0%}; lane changes masked (only 'stay' allowed): "
             f"{forced.mean():.0%}; out of V2I range (red = -1): {(df.red == -1).mean():.0%}",
             "mean acceleration per head [m/s^2]: " + ", ".join(f"{h} {df[f'a_{h}'].mean():+.2f}" for h in HEADS)]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__.split("\n")[0])
    ap.add_argument("--signals", default="coordinated", choices=SIGNALS, help="signal setting (default: coordinated)")
    ap.add_argument("--mpr", type=float_in(0, 1, lo_open=True), default=1.0, help="CV share in (0, 1]")
    ap.add_argument("--demand", type=float_in(0, 1000, lo_open=True), default=CI_DEMAND, help="veh/h/lane in (0, 1000]")
    ap.add_argument("--duration", type=float_in(10, 7200), default=CI_DURATION, help="simulated seconds (10-7200)")
    ap.add_argument("--rep", type=int_in(0), default=0, help="repetition (seed = bench.experiments.mixed.MASTER_SEED + rep), >= 0")
    ap.add_argument("--at", type=int_in(1), nargs="+", default=[20, 100, 250], help="stall lengths [steps] to record, >= 1")
    ap.add_argument("--out", type=Path, default=None, help="write the records as parquet (must not exist)")
    args = ap.parse_args(argv)
    if args.out is not None and args.out.exists():
        ap.error(f"--out {args.out} exists; not overwriting it")
    if args.out is not None:
        try:
            writable_dir(args.out.parent)
        except Unwritable as e:
            return fail(ap.prog, f"--out: {e}")
    try:
        rows, summary = trace(args.signals, args.mpr, args.demand, args.duration, tuple(args.at), args.rep)
    except CheckpointError as e:
        return fail(ap.prog, str(e))
    df = pd.DataFrame(rows)
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        cols = ["time", "vehicle", "stalled_s", "lane", "distance", "red", "mask", "k", "accel",
                "a_left", "a_stay", "a_right"]
        print(df[cols].round(2).to_string(index=False) if len(df) else "")
    print(describe(df))
    print(f"cell: {summary['stall_steps']} stalled CV-steps, longest {summary['longest_stall_s']:.0f} s, "
          f"{summary['all']['unfinished']} vehicles unfinished")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        atomic_parquet(df, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
