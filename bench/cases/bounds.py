"""The energy-optimal bound of every case of a run (``bench.oracle``), joined to its results.

For each (signal setting, case) the ego's own departure time fixes the problem; two bounds are
solved: ``cost_bound``, the least E + phi T through the signals (phi of the scenario's reward),
and ``energy_bound``, the least energy that arrives no later than SUMO's driver (``baseline``)
did on that case, an equal-time comparison. Solutions are kept in ``<run>/bounds.parquet``,
rewritten as each case finishes (a killed run loses only the cases in flight), and reused by a
rerun (the DP takes a few seconds per case); its progress with an ETA is on stderr (``bench.progress``). On a
network corridor (``envs.route``) the problem also holds the ego's speed at its insertion, which
traffic may slow: each case is reset once to read it, and the bounds start there. A case
whose problem the bounds shipped with the fixed cases answer (``bench.cases.shipped_bounds``:
same scenario, DP version and grid, departure and time limit) is read from there, not solved;
its row says so in ``bound_source`` ("shipped", else "solved") and keeps in ``bound_wall_s`` the
DP's seconds where it was solved (NaN in the other setting's row of a network case, solved once).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.io import atomic_parquet
from ecodrive_bench.bench.progress import bar as progress_bar

NO_LIMIT = -1.0  # no baseline row, or it did not finish: no equal-time bound
KEY = ["signals", "case", "depart_time", "time_limit"]
COLUMNS = KEY + ["cost_bound", "bound_energy", "bound_travel_time", "energy_bound", "energy_bound_travel_time",
                 "bound_wall_s", "bound_source"]
SOLVED, SHIPPED = "solved", "shipped"  # bound_source: solved by this run, or read from the shipped bounds


@dataclass(frozen=True)
class BoundTask:
    signals: str
    case: int
    depart_time: float  # [s] the ego's entry step on this case
    time_limit: float  # [s] the baseline's travel time on this case (NO_LIMIT: no equal-time bound)
    scenario: str = ""  # JSON of the run's scenario overrides (bench.harness.scenarios), "" none
    sumo_seed: int = -1  # the case's SUMO seed and insertion time: a network corridor's bound starts from the
    insert_time: float = float("nan")  # ego's insertion state, which they fix (``start_speed``)


def solve_plans(task: BoundTask) -> tuple[Any, Any, Any, float]:
    """(scenario config, "cost" plan, "energy" plan or None, seconds) of one case."""
    from ecodrive_bench.bench.cases.setting import setting
    from ecodrive_bench.bench.oracle.dp import bound

    cfg = setting(task.signals, json.loads(task.scenario) if task.scenario else None)
    t0 = time.perf_counter()
    if cfg.network is not None:  # a network corridor: from the ego's insertion state, in its route frame
        from ecodrive_bench.bench.oracle.dp import Corridor, Grid
        from ecodrive_bench.bench.oracle.dp import solve as plan

        cor = Corridor.from_config(cfg).starting(start_speed(cfg, task), Grid().spacing(cfg, fine=False)[0])
        cost = plan(cor, cfg, task.depart_time, "cost")
        eq = (plan(cor, cfg, task.depart_time, "energy", time_limit=task.time_limit)
              if task.time_limit != NO_LIMIT else None)
        return cfg, cost, eq, time.perf_counter() - t0
    cost = bound(cfg, task.depart_time, "cost")
    eq = bound(cfg, task.depart_time, "energy", time_limit=task.time_limit) if task.time_limit != NO_LIMIT else None
    return cfg, cost, eq, time.perf_counter() - t0


def start_speed(cfg: Any, task: BoundTask) -> float:
    """[m/s] the ego's speed at its insertion on a network corridor's case, where traffic may slow it
    (every method shares it: the traffic is the same until the ego is in): the case reset once.
    A ValueError where the reset's departure is not the task's."""
    from ecodrive_bench.envs.env import EcoDriveEnv

    env = EcoDriveEnv(config=cfg, action="longitudinal")
    try:
        obs, info = env.reset(options={"sumo_seed": task.sumo_seed, "insert_time": task.insert_time})
        if float(info["time"]) != task.depart_time:
            raise ValueError(f"case {task.case}: its reset departs at {float(info['time']):g} s, the results say "
                             f"{task.depart_time:g} s")
        return float(obs["logic"][cfg.observed_lanes + 1])
    finally:
        env.close()


def solve(task: BoundTask) -> dict[str, Any]:
    """Both bounds of one case (runs in a worker)."""
    _, cost, eq, wall = solve_plans(task)
    return {"signals": task.signals, "case": task.case, "depart_time": task.depart_time, "time_limit": task.time_limit,
            "cost_bound": cost.cost, "bound_energy": cost.energy, "bound_travel_time": cost.travel_time,
            "energy_bound": eq.energy if eq is not None else np.nan,
            "energy_bound_travel_time": eq.travel_time if eq is not None else np.nan,
            "bound_wall_s": wall, "bound_source": SOLVED}


def shipped_row(table: Any, task: BoundTask) -> dict[str, Any] | None:
    """The row ``solve(task)`` would give (its time aside), read from the shipped bounds
    (``bench.cases.shipped_bounds.Table``); None when they do not answer both of its bounds."""
    from ecodrive_bench.bench.cases.setting import setting

    cfg = setting(task.signals, json.loads(task.scenario) if task.scenario else None)
    plan = table.plan(cfg, task.depart_time)
    eq = table.energy(cfg, task.depart_time, task.time_limit) if task.time_limit != NO_LIMIT else (np.nan, np.nan)
    if plan is None or eq is None:
        return None
    return {"signals": task.signals, "case": task.case, "depart_time": task.depart_time, "time_limit": task.time_limit,
            "cost_bound": plan.cost, "bound_energy": plan.energy, "bound_travel_time": plan.travel_time,
            "energy_bound": eq[0], "energy_bound_travel_time": eq[1], "bound_wall_s": plan.grid["wall_s"],
            "bound_source": SHIPPED}


def tasks_for(results: pd.DataFrame, scenario: str = "") -> list[BoundTask]:
    """One task per (signals, case) of ``results``: the departure every method shared on that case
    (they share the traffic until the ego's insertion), the baseline's travel time as the limit."""
    out = []
    for (s, c), g in results.groupby(["signals", "case"]):
        base = g[g.method == "baseline"]
        limit = float(base.travel_time.iloc[0]) if len(base) and bool(base.terminated.iloc[0]) else NO_LIMIT
        seed, insert = ((int(g.seed.iloc[0]), float(g.insert_time.iloc[0])) if {"seed", "insert_time"} <= set(g.columns)
                        else (-1, float("nan")))
        out.append(BoundTask(str(s), int(c), float(g.depart_time.iloc[0]), limit, scenario, seed, insert))
    return out


def attach(run_dir: Path, results: pd.DataFrame, workers: int, runner,
           scenario: dict[str, Any] | None = None, progress: bool = True,
           shipped: Path | None = None) -> pd.DataFrame:
    """``results`` with the bound columns of its case, reading what the shipped bounds answer
    (``shipped``: their file, default ``bench.cases.shipped_bounds.FILE``) and solving (with
    ``runner(tasks, workers, fn)``, an executor of ``bench.harness.executors``) the rest of what
    ``bounds.parquet`` lacks, on the run's ``scenario`` (overrides; one per run folder). On a network
    corridor both signal settings pose one problem (``shipped_bounds.problem_digest``): a case with
    the same departure and baseline time in both is solved once, and its row written for each."""
    from ecodrive_bench.bench.cases import shipped_bounds

    path = run_dir / "bounds.parquet"
    done = pd.read_parquet(path) if path.is_file() else pd.DataFrame(columns=COLUMNS)
    have = set(map(tuple, done[KEY].astype(object).values)) if len(done) else set()
    todo = [t for t in tasks_for(results, json.dumps(scenario, sort_keys=True) if scenario else "") if (t.signals, t.case, t.depart_time, t.time_limit) not in have]
    if todo:
        network = bool(scenario and scenario.get("network") is not None)  # nothing is shipped for those
        table = shipped_bounds.table(shipped or shipped_bounds.FILE) if not network else None
        rows = [r for r in (shipped_row(table, t) for t in todo) if r is not None] if table is not None else []
        read = {(r["signals"], r["case"]) for r in rows}
        todo = [t for t in todo if (t.signals, t.case) not in read]

        def save() -> None:
            new = pd.DataFrame(rows, columns=COLUMNS)
            atomic_parquet(pd.concat([done, new], ignore_index=True) if len(done) else new, path)

        def problem(signals: str, case: int, depart: float, limit: float) -> tuple:
            return (case, depart, limit) if network else (signals, case)  # a network's settings: one problem

        twins: dict[tuple, list[BoundTask]] = {}  # the tasks of each problem, solved once
        for t in todo:
            twins.setdefault(problem(t.signals, t.case, t.depart_time, t.time_limit), []).append(t)
        unique = [ts[0] for ts in twins.values()]
        if rows:
            save()
        with progress_bar(total=len(rows) + len(unique), initial=len(rows), desc="bounds", unit="case",
                          enabled=progress) as bar:
            for row in runner(unique, workers, solve) if unique else ():
                key = problem(row["signals"], row["case"], row["depart_time"], row["time_limit"])
                rows += [{**row, "signals": t.signals, **({"bound_wall_s": float("nan")} if i else {})}
                         for i, t in enumerate(twins[key])]  # a twin's row took no DP time of its own
                save()
                bar.update(1)
        done = pd.read_parquet(path)
    cols = ["signals", "case", "cost_bound", "energy_bound"]
    latest = done.drop_duplicates(["signals", "case"], keep="last")[cols]
    return results.drop(columns=[c for c in cols[2:] if c in results.columns]).merge(latest, on=["signals", "case"],
                                                                                      how="left")
