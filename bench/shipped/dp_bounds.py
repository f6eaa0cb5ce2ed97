"""The shipped bounds' writer and checker (the file and its reader: ``bench.cases.shipped_bounds``).

``write_bounds`` (``ecodrive cases --write --bounds``) runs the baseline over every fixed case and
solves both bounds of each (``solve_entry``), written by ``save`` as ``entry`` rows; ``check`` re-solves a sample of them with the DP
and compares (``ecodrive cases --check``): the floats within ``bench.hosts.DP_RTOL``, the plans'
decisions exactly, so a file written on an AVX-512 host checks on an AVX2 one.
"""
from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.cases.bounds import BoundTask, solve_plans
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.cases.shipped_bounds import (
    ARRAYS,
    COLUMNS,
    FILE,
    FORMAT,
    META_KEY,
    REBUILD,
    SCALARS,
    ShippedError,
    content_sha256,
    grid_key,
    problem_digest,
    read,
    row_mpc_plan,
    row_plan,
)
from ecodrive_bench.bench.hosts import ATOL, DP_RTOL, arrays_close, close
from ecodrive_bench.bench.io import atomic_file
from ecodrive_bench.bench.oracle import dp, mpc
from ecodrive_bench.bench.oracle.energy import energy_wh
from ecodrive_bench.envs.config import SIGNALS, ScenarioConfig

CHECK_PER_SETTING = 2  # [cases] re-solved per signal setting by `ecodrive cases --check` (two DP solves each)
CHECK_SEED = 20240501  # [-] the sample's seed: the same cases on every check


def write_bounds(path: Path, workers: int, progress: bool = True) -> list[str]:
    """Rebuild the shipped bounds: the baseline over every fixed case of each setting, in a
    temporary run folder (the departures, and the travel times that limit the energy bounds,
    exactly as a run measures them), then both bounds of each case with its plan. Returns error
    lines ([]: written); after an error nothing is written."""
    import pandas as pd

    from ecodrive_bench.bench.cases.bounds import tasks_for
    from ecodrive_bench.bench.harness.executors import run_local
    from ecodrive_bench.bench.harness.options import RunOptions
    from ecodrive_bench.bench.harness.run import run
    from ecodrive_bench.bench.progress import bar
    from ecodrive_bench.envs.config import SIGNALS

    with tempfile.TemporaryDirectory(prefix="ecodrive-shipped-bounds-") as tmp:
        opts = RunOptions(profile="paper", methods=["baseline"], signals=list(SIGNALS), workers=workers,
                          run_id="baseline", logs=Path(tmp), argv=["--methods", "baseline"])
        results = run(opts, progress)
    if opts.failures:
        return [f"{path}: not written: {len(opts.failures)} baseline episode(s) failed (above); rerun: {REBUILD}"]
    tasks = tasks_for(results)
    rows = list(bar(run_local(tasks, workers, solve_entry), total=len(tasks), desc="bounds", unit="case",
                    enabled=progress))
    save(pd.DataFrame(rows), path)
    return []


def solve_entry(task: BoundTask) -> dict[str, Any]:
    """Both bounds of one case as a row of the shipped bounds, with the cost plan and mpc's first
    plan (runs in a worker)."""
    cfg, cost, eq, wall = solve_plans(task)
    first = mpc.shippable_first(dp.Corridor.from_config(cfg), cfg, task.depart_time)  # the mpc method's first plan
    return entry(task.signals, task.case, cfg, task.depart_time, task.time_limit, cost, eq, wall, first)


def save(frame: pd.DataFrame, path: Path = FILE) -> None:
    """Write the rows (atomically, ``bench.io``) with their format and content digest."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    frame = frame[list(COLUMNS)].sort_values(["signals", "case"], ignore_index=True)
    types = {str: pa.string(), int: pa.int64(), float: pa.float64()}
    schema = pa.schema([(c, types[t]) for c, t in SCALARS.items()] + [(c, pa.list_(pa.float64())) for c in ARRAYS])
    meta = {"format": FORMAT, "sha256": content_sha256(frame), "rows": len(frame)}
    tab = pa.Table.from_pandas(frame, schema=schema, preserve_index=False).replace_schema_metadata(
        {META_KEY: json.dumps(meta).encode()})
    with atomic_file(path) as f:
        pq.write_table(tab, f, compression="zstd", compression_level=19)


def entry(signals: str, case: int, cfg: ScenarioConfig, depart_time: float, time_limit: float, plan: dp.Plan,
          energy: dp.Plan | None, wall_s: float, first: dp.Plan | None = None) -> dict[str, Any]:
    """A row: the ``"cost"`` plan of a case and its ``"energy"`` bound under ``time_limit`` [s]
    (``energy`` None: the baseline did not finish, no energy bound), solved in ``wall_s`` [s], and
    mpc's first plan ``first`` (None: the periodic table does not serve the departure)."""
    f, none = first, math.nan
    mpc_cols = {"mpc_version": mpc.VERSION, "mpc_energy": f.energy if f else none,
                "mpc_travel_time": f.travel_time if f else none, "mpc_cost": f.cost if f else none,
                "mpc_crossings": f.crossings.tolist() if f else [], "mpc_speed": f.v.tolist() if f else [],
                "mpc_x": f.x.tolist() if f else []}
    return {"signals": signals, "case": case, "scenario_digest": problem_digest(cfg), "dp_version": dp.VERSION,
            "grid": grid_key(), "depart_time": float(depart_time), "time_limit": float(time_limit),
            "cost_bound": plan.cost, "bound_energy": plan.energy, "bound_travel_time": plan.travel_time,
            "energy_bound": energy.energy if energy is not None else math.nan,
            "energy_bound_travel_time": energy.travel_time if energy is not None else math.nan, "wall_s": float(wall_s),
            "crossings": plan.crossings.tolist(), "speed": plan.v.tolist(), "x": plan.x.tolist(), **mpc_cols}


def sample(rows: pd.DataFrame, n: int = CHECK_PER_SETTING, seed: int = CHECK_SEED) -> pd.DataFrame:
    """The rows ``check`` re-solves: ``n`` of ``rows`` (one setting's), drawn with ``seed`` (the same
    rows for the same seed; ``ecodrive cases --check`` draws a new seed each run and prints it)."""
    rows = rows.sort_values("case", ignore_index=True)
    pick = np.random.default_rng(seed).choice(len(rows), size=min(n, len(rows)), replace=False)
    return rows.iloc[np.sort(pick)]


def check(path: Path = FILE, per_setting: int = CHECK_PER_SETTING, signals: tuple[str, ...] = SIGNALS,
          progress: bool = True, seed: int = CHECK_SEED) -> list[str]:
    """One line per drift ([]: none): a file that cannot be read; a setting whose rows are for
    another problem (scenario, DP version, grid) or that lacks fixed cases; and, on ``sample``'s
    rows of each setting, a stored bound or plan that is not exactly what the DP solves now."""
    from ecodrive_bench.bench.cases.case import load
    from ecodrive_bench.bench.progress import bar

    try:
        tab = read(path)
    except ShippedError as e:
        return [str(e)]
    lines, todo, fixed = [], [], {c.index for c in load()}
    for s in signals:
        cfg = setting(s, None)
        now = (problem_digest(cfg), dp.VERSION, grid_key())
        rows = tab.frame[tab.frame.signals == s]
        other = rows[(rows.scenario_digest != now[0]) | (rows.dp_version != now[1]) | (rows.grid != now[2])]
        if len(other):
            r = other.iloc[0]
            lines.append(f"{path}: {len(other)} of the {s} rows are for another problem (scenario {r.scenario_digest}, "
                         f"DP version {int(r.dp_version)}, {r.grid}; now {now[0]}, {now[1]}, {now[2]}); they would miss "
                         f"and be solved; rebuild: {REBUILD}")
            continue
        old = rows[rows.mpc_version != mpc.VERSION]
        if len(old):
            lines.append(f"{path}: {len(old)} of the {s} rows hold mpc first plans of planner version "
                         f"{int(old.mpc_version.iloc[0])}, not {mpc.VERSION}; mpc would solve them; rebuild: {REBUILD}")
        missing = sorted(fixed - set(rows.case))
        if missing:
            lines.append(f"{path}: no {s} rows for {len(missing)} of the {len(fixed)} fixed cases (first: case "
                         f"{missing[0]}); rebuild: {REBUILD}")
        todo += [(s, cfg, r) for r in sample(rows, per_setting, seed).itertuples(index=False)]
    for s, cfg, r in bar(todo, desc="check bounds", unit="case", enabled=progress):
        lines += compare(path, s, cfg, r)
    return lines


def compare(path: Path, signals: str, cfg: ScenarioConfig, r: Any) -> list[str]:
    """A row's bounds and mpc's first plan solved again: one line per one that differs from the
    stored one beyond what crosses hosts (``bench.hosts``: floats within ``DP_RTOL``, decisions
    exactly unless their costs tie within it)."""
    at = f"{path}: {signals} case {int(r.case)} (depart {float(r.depart_time):g} s)"
    diffs = _plan_diffs(row_plan(r, cfg, path), dp.bound(cfg, float(r.depart_time), "cost"), cfg)
    out = [f"{at}: the stored cost plan is not the DP's: {'; '.join(diffs)}; rebuild: {REBUILD}"] if diffs else []
    if not math.isnan(r.energy_bound):
        eq = dp.bound(cfg, float(r.depart_time), "energy", time_limit=float(r.time_limit))
        have = (float(r.energy_bound), float(r.energy_bound_travel_time))
        if not close(have[0], eq.energy):  # the travel time is a decision: at a tie of energies either is right
            out.append(f"{at}: the stored energy bound under {float(r.time_limit):g} s is not the DP's: energy, travel time "
                       f"{have[0]!r}, {have[1]!r} stored, {eq.energy!r}, {eq.travel_time!r} solved (relative "
                       f"tolerance {DP_RTOL:g}); rebuild: {REBUILD}")
    first = mpc.shippable_first(dp.Corridor.from_config(cfg), cfg, float(r.depart_time))
    if (first is None) != math.isnan(r.mpc_cost):
        out.append(f"{at}: mpc's first plan is {'stored' if first is None else 'missing'}, but the periodic table "
                   f"{'does not serve' if first is None else 'serves'} this departure; rebuild: {REBUILD}")
    elif first is not None:
        diffs = _plan_diffs(row_mpc_plan(r, cfg, path), first, cfg)
        if diffs:
            out.append(f"{at}: the stored mpc first plan is not the planner's: {'; '.join(diffs)}; rebuild: {REBUILD}")
    return out


def _plan_diffs(stored: dp.Plan, solved: dp.Plan, cfg: ScenarioConfig) -> list[str]:
    """What differs between two plans beyond what crosses hosts: cost and energy beyond ``DP_RTOL``;
    the decisions (speeds, crossings, travel time) and what follows from them exactly, unless the
    two costs tie within ``DP_RTOL`` and the stored speeds do cost what the row says (either plan
    is then optimal); positions and accelerations, derived floats, within ``DP_RTOL``."""
    diffs = [f"{k} {getattr(stored, k)!r} stored, {getattr(solved, k)!r} solved (relative tolerance {DP_RTOL:g})"
             for k in ("cost", "energy") if not close(getattr(stored, k), getattr(solved, k))]
    if not diffs and not _same_decisions(stored, solved):
        own = plan_cost(stored.v, cfg)
        if close(own, stored.cost):
            return diffs  # a tie: another host may pick the other plan
        diffs.append(f"the stored speeds cost {own!r}, not the stored {stored.cost!r}")
    if stored.travel_time != solved.travel_time:
        diffs.append(f"travel_time {stored.travel_time!r} stored, {solved.travel_time!r} solved")
    for k in ("t", "x", "v", "a", "crossings"):
        a, b = getattr(stored, k), getattr(solved, k)
        if a.shape != b.shape:
            diffs.append(f"{k} has {a.size} entries stored, {b.size} solved")
        elif k in DECISIONS and not np.array_equal(a, b):
            diffs.append(f"{k} differs at {int((a != b).sum())} of {a.size} entries")
        elif k not in DECISIONS and not arrays_close(a, b):
            diffs.append(f"{k} differs at {int((~np.isclose(a, b, rtol=DP_RTOL, atol=ATOL)).sum())} of {a.size} "
                         f"entries beyond a relative {DP_RTOL:g}")
    return diffs


DECISIONS = ("t", "v", "crossings")  # a plan's choices (its time grid, speeds, stop-line steps): compared exactly


def plan_cost(v: np.ndarray, cfg: ScenarioConfig) -> float:
    """E + phi T [Wh] of a speed profile [m/s per step], as the DP prices it."""
    dt = cfg.step_length
    return float(energy_wh(v[:-1], v[1:], dt, cfg.ev).sum()) + cfg.reward.phi * (len(v) - 1) * dt


def _same_decisions(a: dp.Plan, b: dp.Plan) -> bool:
    return a.travel_time == b.travel_time and all(
        getattr(a, k).shape == getattr(b, k).shape and np.array_equal(getattr(a, k), getattr(b, k)) for k in DECISIONS)
