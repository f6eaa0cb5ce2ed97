"""Clairvoyant's planning of whole case sets, for the drives shipped with them
(``bench.cases.clairvoyant_drives``): every drive of a case planned from scratch in a worker
(``solve``), a set's price of time and each case's chosen drive (``choose_set``), and the check
that re-plans a sample of the shipped rows (``sample``, ``check``; ``ecodrive cases --check``).
The agent that plans one case and replays a drive is ``bench.methods.clairvoyant_agent``."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.cases import clairvoyant_drives as drives
from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.hosts import ENERGY_RTOL, close
from ecodrive_bench.bench.methods.clairvoyant_agent import ClairvoyantAgent
from ecodrive_bench.bench.oracle.time_price import choices, pick, time_price


def solve(task: tuple[str, str, dict[str, Any] | None, Case]) -> dict[str, Any]:
    """Every drive of one case of a set (corridor, signals, scenario overrides, case), planned from
    scratch in a worker: their costs, times and actions, and SUMO's driver's time (``limit``)."""
    from ecodrive_bench.bench.cases.setting import setting
    from ecodrive_bench.bench.methods.env import make_env

    corridor, signals, scenario, case = task
    cfg = setting(signals, scenario)
    agent = ClairvoyantAgent(cfg, shipped=None)
    env = make_env(agent, signals, scenario)
    try:
        tried = agent.plan(env, case)
    finally:
        env.close()
    return {"corridor": corridor, "signals": signals, "case": case, "digest": shipped_bounds.problem_digest(cfg),
            "limit": agent.rounds[0]["sumo_driver_time"], "costs": np.array([d[0] for d in tried]),
            "times": np.array([d[1] for d in tried]), "actions": [d[2] for d in tried]}


def choose_set(planned: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The shipped rows of one case set's planned cases (``solve``): the set's price of time, at
    which its mean travel time is at most SUMO's driver's (``bench.oracle.time_price``), and each
    case's drive at that price."""
    costs, times = [p["costs"] for p in planned], [p["times"] for p in planned]
    price = time_price(costs, times, float(np.mean([p["limit"] for p in planned])))
    return [drives.entry(p, price, k) for p, k in zip(planned, choices(costs, times, price))]


def sample(frame, per_setting: int = drives.CHECK_PER_SETTING, seed: int = drives.CHECK_SEED) -> list[tuple[str, Any]]:
    """The rows ``check`` re-plans: ``per_setting`` of each signal setting drawn over all its sets
    (``seed``: ``ecodrive cases --check`` draws a new one each run and prints it), and one more of a
    set with a positive price of time where the draw holds none, so that a choice the price moved
    is checked too."""
    rng = np.random.default_rng(seed)
    out = []
    for s in sorted(set(frame.signals)):
        rows = frame[frame.signals == s].sort_values(["corridor", "case"], ignore_index=True)
        drawn = sorted(rng.choice(len(rows), size=min(per_setting, len(rows)), replace=False).tolist())
        priced = rows.index[rows.time_price > 0].tolist()
        if priced and not set(drawn) & set(priced):
            drawn.append(int(rng.choice(priced)))
        out += [(s, r) for r in rows.iloc[drawn].itertuples(index=False)]
    return out


def check(path: Path = drives.FILE, per_setting: int = drives.CHECK_PER_SETTING,
          seed: int = drives.CHECK_SEED) -> list[str]:
    """One line per drift ([]: none) on a sample of the shipped cases (``sample``), planned again
    and chosen at their set's stored price: the lane decisions and the travel times exactly, SUMO's
    driver's time exactly, the accelerations and the cost within the cross-host tolerances. The
    stored price itself is not re-derived (that needs the whole set: ``ecodrive cases --write``)."""
    try:
        frame = drives.read(path)
    except drives.DrivesError as e:
        return [str(e)]
    sets = {(corridor, s): (scenario, {c.index: c for c in cases}) for corridor, s, scenario, cases in drives.case_sets()}
    lines = []
    for s, r in sample(frame, per_setting, seed):
        at = f"{path}: {r.corridor} {s} case {int(r.case)}"
        if (r.corridor, s) not in sets or int(r.case) not in sets[(r.corridor, s)][1]:
            lines.append(f"{at}: no such case in the sets of bench.cases (corridor {r.corridor!r}); rebuild: {drives.REBUILD}")
            continue
        scenario, cases = sets[(r.corridor, s)]
        got = solve((r.corridor, s, scenario, cases[int(r.case)]))
        k = pick(got["costs"], got["times"], float(r.time_price))
        lateral, accel = [a for a, _ in got["actions"][k]], [b for _, b in got["actions"][k]]
        if float(got["limit"]) != float(r.sumo_driver_time):
            lines.append(f"{at}: SUMO's driver's time {float(r.sumo_driver_time)!r} s stored, {float(got['limit'])!r} s "
                         f"driven; rebuild: {drives.REBUILD}")
        elif lateral != [int(a) for a in r.lateral] or float(got["times"][k]) != float(r.travel_time):
            lines.append(f"{at}: the lane decisions or travel time differ from a new plan's; rebuild: {drives.REBUILD}")
        elif not np.allclose(accel, list(r.accel), rtol=drives.ACCEL_RTOL, atol=1e-9):
            lines.append(f"{at}: the accelerations differ beyond a relative {drives.ACCEL_RTOL:g}; rebuild: {drives.REBUILD}")
        elif not close(float(got["costs"][k]), float(r.cost), ENERGY_RTOL):
            lines.append(f"{at}: cost {float(r.cost)!r} stored, {float(got['costs'][k])!r} planned; rebuild: {drives.REBUILD}")
    return lines
