"""What one run folder may hold, checked before ``ecodrive run`` writes to it (``bench.harness.run``):
one scenario per signal setting, and the same cases for every method of a setting."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.args import UsageError
from ecodrive_bench.bench.harness import scenarios

KEEP = ("method", "signals", "train_seed", "case", "seed", "insert_time", "depart_time", "energy", "travel_time", "steps",
        "terminated", "truncated", "return", "stops", "time_stopped", "lane_changes_requested",
        "lane_changes_applied", "clips", "jerk_exceedances", "collisions", "teleports", "battery_consumed",
        "battery_regenerated", "mcap", "eval_scenario_hash", "train_scenario_hash")
SCENARIO_COLUMNS = ("eval_scenario_hash", "train_scenario_hash")  # not in tables written before them


def one_scenario(run_dir: Path, hashes: dict[str, str]) -> None:
    """A run folder holds one scenario per signal setting: a command on another one is refused
    before it overwrites any step log (the results table says which scenario the folder has)."""
    path = run_dir / "results.parquet"
    try:
        old = pd.read_parquet(path) if path.is_file() else pd.DataFrame(columns=["signals"])
    except Exception:  # earlier_rows reports an unreadable table
        return
    if "signals" not in old.columns:
        return
    have = old.eval_scenario_hash if "eval_scenario_hash" in old.columns else old.signals.map(scenarios.legacy_hash)
    for signals, want in hashes.items():
        other = sorted(set(have[old.signals == signals]) - {want})
        if other:
            raise UsageError(f"{run_dir} holds {signals} episodes of another scenario (eval_scenario_hash "
                             f"{', '.join(other)}, this command's is {want}); use another --run-id")


def one_case_set(run_dir: Path, runs: list[tuple[str, str, int]], cases: set[int]) -> None:
    """A run folder's methods drive the same cases in each setting (the report compares them case
    by case and over the whole set). Against the cases the folder's table has in a setting, a
    command is refused before it writes anything, as ``one_scenario``, if it runs other cases, more
    cases while some method of the folder is not rerun, or fewer cases with a method the folder
    does not have yet; rerunning some cases of methods the folder has is allowed. What a command
    cannot see here (rows dropped later for a replaced policy) is caught by ``case_set_gaps``."""
    path = run_dir / "results.parquet"
    try:
        old = pd.read_parquet(path) if path.is_file() else None
    except Exception:  # earlier_rows reports an unreadable table
        return
    if old is None or not set(KEEP) - set(SCENARIO_COLUMNS) <= set(old.columns):  # one earlier_rows would not keep
        return
    for s in sorted({r[1] for r in runs}):
        rows = old[old.signals == s]
        have = {int(c) for c in rows.case}
        if not have or have == cases:
            continue
        there = set(zip(rows.method, rows.train_seed.astype(int)))
        mine = {(m, sd) for m, ss, sd in runs if ss == s}
        left = sorted(there - mine) if cases > have else sorted(mine - there) if cases < have else []
        if cases > have or cases < have:
            if not left:
                continue
            who = ", ".join(_who(m, sd) for m, sd in left[:4]) + (", ..." if len(left) > 4 else "")
            why = (f"{who} would keep only those" if cases > have else f"{who} would drive only these")
        else:
            why = "neither set holds the other"
        raise UsageError(f"{run_dir} holds {s} episodes on cases {_ranges(have)}; this command runs cases "
                         f"{_ranges(cases)} ({why}): every method of a run folder drives the same cases; "
                         "run them all on one set, or use another --run-id")


def case_set_gaps(df: pd.DataFrame) -> list[str]:
    """One line per setting of ``df`` (a results table) whose methods, each training seed apart,
    drove different cases."""
    out = []
    for s, g in df.groupby("signals"):
        sets = {(m, int(sd)): {int(c) for c in c_} for (m, sd), c_ in g.case.groupby([g.method, g.train_seed])}
        if len({frozenset(v) for v in sets.values()}) > 1:
            parts = [f"{_who(m, sd)} {_ranges(v)}" for (m, sd), v in sorted(sets.items())]
            out.append(f"{s}: the methods drove different cases ({'; '.join(parts[:6])}{'; ...' if len(parts) > 6 else ''})")
    return out


def _who(method: str, seed: int) -> str:
    """A method with its training seed, as the messages name it ("prl s0", "baseline")."""
    return method if seed < 0 else f"{method} s{seed}"


def _ranges(ints: set[int]) -> str:
    """``{0, 1, 2, 5}`` as "0-2, 5"."""
    out, run = [], []
    for i in sorted(ints):
        if run and i != run[-1] + 1:
            out.append(run)
            run = []
        run.append(i)
    out.append(run)
    return ", ".join(f"{r[0]}-{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in out if r)
