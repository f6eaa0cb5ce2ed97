"""The shipped clairvoyant drives' writer and checker (the file and its reader:
``bench.cases.clairvoyant_drives``): every set whose drives are shipped (``case_sets``), every
drive of a case planned from scratch in a worker (``solve``), a set's price of time and each
case's chosen drive (``choose_set``) written as ``entry`` rows (``write_clairvoyant``:
``ecodrive cases --write --clairvoyant``), and the check that re-plans a sample of the shipped
rows (``sample``, ``check``; ``ecodrive cases --check``). The agent that plans one case and
replays a drive is ``bench.methods.clairvoyant_agent``."""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.cases import clairvoyant_drives as drives
from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.cases.shipped_bounds import problem_digest
from ecodrive_bench.bench.hosts import ENERGY_RTOL, close
from ecodrive_bench.bench.io import atomic_file
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
    return [entry(p, price, k) for p, k in zip(planned, choices(costs, times, price))]


def save(frame: pd.DataFrame, path: Path = drives.FILE) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    frame = frame[list(drives.COLUMNS)].sort_values(["corridor", "signals", "case"], ignore_index=True)
    meta = {"version": drives.VERSION, "sha256": drives.content_sha256(frame), "rows": len(frame)}
    tab = pa.Table.from_pandas(frame, preserve_index=False).replace_schema_metadata({drives.META_KEY: json.dumps(meta).encode()})
    with atomic_file(path) as f:
        pq.write_table(tab, f, compression="zstd", compression_level=19)




def case_sets() -> list[tuple[str, str, dict[str, Any] | None, tuple[Case, ...]]]:
    """Every shipped set: (corridor, signals, scenario overrides or None, cases), the fixed cases'
    per setting, each held-out variant's per setting (``bench.cases.heldout``), then each real
    corridor's once (``bench.cases.real``: a network's own signal programs are the same problem in
    both settings, ``shipped_bounds.problem_digest``; its rows name the first setting)."""
    from ecodrive_bench.bench.cases import case, heldout, real
    from ecodrive_bench.envs.config import SIGNALS

    fixed = tuple(case.load())
    sets = [(drives.PAPER, s, None, fixed) for s in SIGNALS]
    sets += [(v.name, s, v.scenario, v.cases) for v in heldout.load() for s in SIGNALS]
    return sets + [(v.name, SIGNALS[0], v.scenario, v.cases) for v in real.variants()]


def entry(planned: dict[str, Any], price: float, chosen: int) -> dict[str, Any]:
    """A row: drive ``chosen`` of a planned case (``bench.shipped.drives.solve``) at its set's ``price``."""
    c: Case = planned["case"]
    lateral, accel = zip(*planned["actions"][chosen]) if planned["actions"][chosen] else ((), ())
    return {"corridor": planned["corridor"], "signals": planned["signals"], "case": c.index, "sumo_seed": c.sumo_seed,
            "insert_time": float(c.insert_time), "scenario_digest": planned["digest"], "version": drives.VERSION,
            "cost": float(planned["costs"][chosen]), "travel_time": float(planned["times"][chosen]),
            "sumo_driver_time": float(planned["limit"]), "time_price": float(price), "rounds": len(planned["costs"]),
            "lateral": [int(a) for a in lateral], "accel": [float(b) for b in accel]}


def current_sets(frame: Any, sets: list[tuple[str, str, dict[str, Any] | None, tuple]]) -> tuple[list[Any], dict]:
    """Of the shipped ``frame`` (None: none), the rows of each set of ``sets``
    (``case_sets``) that are current (this ``VERSION``, the scenario's digest,
    exactly its cases), and the solve tasks of every other set, by (corridor, signals)."""
    from ecodrive_bench.bench.cases.setting import setting

    kept, todo = [], {}
    for corridor, s, scenario, cases in sets:
        have = None if frame is None else frame[(frame.corridor == corridor) & (frame.signals == s)]
        want = {(c.index, c.sumo_seed, float(c.insert_time)) for c in cases}
        if have is not None and len(have) == len(cases) and set(have.version) == {drives.VERSION} \
                and set(have.scenario_digest) == {problem_digest(setting(s, scenario))} \
                and {(int(r.case), int(r.sumo_seed), float(r.insert_time)) for r in have.itertuples()} == want:
            kept.append(have)
        else:
            todo[(corridor, s)] = [(corridor, s, scenario, c) for c in cases]
    return kept, todo


def write_clairvoyant(path: Path, workers: int, progress: bool = True) -> list[str]:
    """Plan every case of every set (``case_sets``, about 10 s a
    case) and ship the chosen drives; a set whose rows are current (this ``VERSION``, scenario and
    cases) is kept as it is, and rows of sets that ``case_sets`` no longer holds are dropped. The
    file is saved as each set completes, so a stopped write keeps them. A set whose fastest drives
    are still slower than SUMO's driver on average is shipped with them, and named on stderr."""
    import pandas as pd

    from ecodrive_bench.bench.harness.executors import run_local
    from ecodrive_bench.bench.methods.planners import CLAIRVOYANT
    from ecodrive_bench.bench.oracle.time_price import TIME_TOL
    from ecodrive_bench.bench.progress import bar

    try:
        frame = drives.read(path) if path.exists() else None
    except drives.DrivesError:
        frame = None  # damaged or of another layout: every set is planned
    kept, todo = current_sets(frame, case_sets())
    tasks = [t for ts in todo.values() for t in ts]
    done: dict[tuple[str, str], list[dict]] = {key: [] for key in todo}
    for planned in bar(run_local(tasks, workers, solve), total=len(tasks), desc=CLAIRVOYANT, unit="case",
                       enabled=progress and bool(tasks)):
        key = (planned["corridor"], planned["signals"])
        done[key].append(planned)
        if len(done[key]) == len(todo[key]):  # the set is complete: its price, its rows, saved
            rows = pd.DataFrame(choose_set(sorted(done[key], key=lambda p: p["case"].index)))
            if rows.travel_time.mean() > rows.sumo_driver_time.mean() + TIME_TOL:
                print(f"note: {key[0]} {key[1]}: even its fastest drives are slower than SUMO's driver on average "
                      f"({rows.travel_time.mean():.1f} s against {rows.sumo_driver_time.mean():.1f} s); shipped "
                      "with them", file=sys.stderr)
            kept.append(rows)
            save(pd.concat(kept, ignore_index=True), path)
    stale = frame is not None and sum(map(len, kept)) != len(frame) and not todo
    if stale:  # nothing to plan, but rows of sets no longer in case_sets
        save(pd.concat(kept, ignore_index=True), path)
    print(f"wrote {path}" if todo or stale else f"{path.name}: every set is current; nothing to plan")
    return []


def sample(frame, per_setting: int = drives.CHECK_PER_SETTING, seed: int = drives.CHECK_SEED) -> list[tuple[str, Any]]:
    """The rows ``check`` re-plans: ``per_setting`` of each signal setting drawn over its generated
    corridors' sets (``seed``: ``ecodrive cases --check`` draws a new one each run and prints it),
    and one more of a set with a positive price of time where the draw holds none, so that a choice
    the price moved is checked too; then ``per_setting`` drawn over the real corridors' sets (a
    real case costs 2-6 generated ones to plan, so no priced one is added there)."""
    from ecodrive_bench.bench.cases.real import SCENARIOS

    rng = np.random.default_rng(seed)
    out = []
    for is_real in (False, True):
        for s in sorted(set(frame.signals)):
            rows = frame[(frame.signals == s) & (frame.corridor.isin(SCENARIOS) == is_real)]
            if not len(rows):
                continue
            rows = rows.sort_values(["corridor", "case"], ignore_index=True)
            drawn = sorted(rng.choice(len(rows), size=min(per_setting, len(rows)), replace=False).tolist())
            priced = rows.index[rows.time_price > 0].tolist()
            if priced and not is_real and not set(drawn) & set(priced):
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
    sets = {(corridor, s): (scenario, {c.index: c for c in cases}) for corridor, s, scenario, cases in case_sets()}
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
