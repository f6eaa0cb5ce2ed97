"""``ecodrive cases``: write or check the versioned case files against their generators.

    ecodrive cases --write|--check [--family train|test | --bounds] [--workers N]

The fixed test cases (``bench/cases/cases.json``, ``bench.cases.case``); with
``--family test`` (or ``--generalisation``), the family of held-out corridors
(``envs/families/heldout.json``, ``bench.cases.heldout``); with ``--family train``, the
training family and its validation split (``envs/families/train.json``,
``bench.cases.train_family``), which must share no corridor with the held-out one; with ``--bounds``, the DP's bounds, the oracle's plans and
mpc's first plans for the fixed cases (``bench/cases/shipped_bounds.parquet``,
``bench.cases.shipped_bounds``).
``--check`` alone checks cases.json and the shipped bounds: the DP re-solves a fixed sample of
2 cases per setting (under a minute) and each stored value or plan that differs is one line.
``--write --bounds`` runs the baseline over every fixed case, then the DP (about 20 minutes
on 2 busy cores); ``--write`` alone rewrites cases.json only. This command sits above these
modules, so none of them imports it back. Exit codes: 0 as generated; 1 cases.json or the family differs
from its generator; 2 the shipped bounds differ from the DP, cannot be read, or were not written.
"""
from __future__ import annotations

import json
import os
import secrets
import sys
import tempfile
from pathlib import Path
from typing import Any

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.args import InputError, Parser, fail, int_in
from ecodrive_bench.bench.cases import case, train_family
from ecodrive_bench.bench.hosts import DP_RTOL


def main(argv: list[str] | None = None, bounds_file: Path | None = None) -> int:
    """The command; ``bounds_file``: the shipped bounds' file (default
    ``bench.cases.shipped_bounds.FILE``)."""
    ap = Parser(description=__doc__)
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", action="store_true", help="regenerate bench/cases/cases.json")
    g.add_argument("--check", action="store_true",
                   help="check bench/cases/cases.json against the generator and the shipped bounds against the DP")
    which = ap.add_mutually_exclusive_group()
    which.add_argument("--generalisation", action="store_true",
                       help="write or check the held-out family instead (envs/families/heldout.json, "
                            "bench.cases.heldout); the same as --family test")
    which.add_argument("--family", choices=("train", *(c.family for c in registry.CASE_SETS if c.family)), default=None,
                       help="write or check a corridor family instead: train (the training and validation splits, "
                            "envs/families/train.json, bench.cases.train_family), test (the held-out family) or "
                            "real (the real corridors from the installed sumo-rl, envs/families/real.json, "
                            "bench.cases.real)")
    which.add_argument("--clairvoyant", action="store_true",
                       help="write or check the clairvoyant drives of the fixed and held-out cases only "
                            "(bench/cases/clairvoyant_drives.parquet, bench.methods.clairvoyant_agent)")
    which.add_argument("--bounds", action="store_true",
                       help="write or check the shipped bounds only (bench/cases/shipped_bounds.parquet, "
                            "bench.cases.shipped_bounds)")
    ap.add_argument("--sample-seed", type=int_in(0, 2**32 - 1), default=None, metavar="S",
                    help="with --check: the seed of the sample of shipped bounds and drives re-solved (default: a new "
                         "one each run, printed, so that no file can be tuned to a known sample)")
    ap.add_argument("--workers", type=int_in(1), default=os.cpu_count() or 1, metavar="N",
                    help="parallel episodes and DP solves of --write --bounds (>= 1)")
    args = ap.parse_args(argv)
    if args.family == "train":
        return train_family.main(args.write)
    family = "test" if args.generalisation else args.family
    if family is not None:  # a case set of the registry: its generator writes or checks it
        chosen = next(c for c in registry.CASE_SETS if c.family == family)
        return registry.load(chosen.writer)(args.write)
    seed = args.sample_seed if args.sample_seed is not None else secrets.randbelow(2**32)
    if not args.write:
        print(f"sample seed {seed} (--sample-seed {seed} draws the same sample)", flush=True)
    if args.bounds:
        return bounds(ap.prog, args.write, args.workers, bounds_file, seed)
    if args.clairvoyant:
        return clairvoyant(ap.prog, args.write, args.workers, seed)
    data = case.generate()
    text = json.dumps(data, indent=1) + "\n"
    if args.write:
        case.CASES_FILE.write_text(text)
        print(f"wrote {len(data['cases'])} cases to {case.CASES_FILE}")
        return 0
    ok = case.CASES_FILE.exists() and case.CASES_FILE.read_text() == text
    print("cases.json matches the generator" if ok else "cases.json differs from the generator")
    return (bounds(ap.prog, False, args.workers, bounds_file, seed) or clairvoyant(ap.prog, False, 1, seed)
            or (0 if ok else 1))


def clairvoyant(prog: str, write: bool, workers: int, seed: int | None = None) -> int:
    """Write or check the shipped clairvoyant drives: 0, or 2 after one line per problem."""
    from ecodrive_bench.bench.cases import clairvoyant_drives as drives
    from ecodrive_bench.bench.shipped import drives as planned

    path = drives.FILE
    if not write and not path.exists():
        print(f"{path.name}: not shipped; every clairvoyant case is planned in the run")
        return 0
    lines = (write_clairvoyant(path, workers) if write
             else planned.check(path, seed=drives.CHECK_SEED if seed is None else seed))
    for line in lines:
        fail(prog, line)
    if not lines and not write:
        print(f"{path.name} matches the planner on the sample ({drives.CHECK_PER_SETTING} case per setting, "
              "and one of a set with a price of time)")
    return 2 if lines else 0


def current_sets(frame: Any, sets: list[tuple[str, str, dict[str, Any] | None, tuple]]) -> tuple[list[Any], dict]:
    """Of the shipped ``frame`` (None: none), the rows of each set of ``sets``
    (``clairvoyant_drives.case_sets``) that are current (this ``VERSION``, the scenario's digest,
    exactly its cases), and the solve tasks of every other set, by (corridor, signals)."""
    from ecodrive_bench.bench.cases import clairvoyant_drives as drives
    from ecodrive_bench.bench.cases.setting import setting
    from ecodrive_bench.bench.cases.shipped_bounds import problem_digest

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
    """Plan every case of every set (``bench.cases.clairvoyant_drives.case_sets``, about 10 s a
    case) and ship the chosen drives; a set whose rows are current (this ``VERSION``, scenario and
    cases) is kept as it is, and rows of sets that ``case_sets`` no longer holds are dropped. The
    file is saved as each set completes, so a stopped write keeps them. A set whose fastest drives
    are still slower than SUMO's driver on average is shipped with them, and named on stderr."""
    import pandas as pd

    from ecodrive_bench.bench.cases import clairvoyant_drives as drives
    from ecodrive_bench.bench.harness.executors import run_local
    from ecodrive_bench.bench.methods.planners import CLAIRVOYANT
    from ecodrive_bench.bench.oracle.time_price import TIME_TOL
    from ecodrive_bench.bench.progress import bar
    from ecodrive_bench.bench.shipped.drives import choose_set, solve

    try:
        frame = drives.read(path) if path.exists() else None
    except drives.DrivesError:
        frame = None  # damaged or of another layout: every set is planned
    kept, todo = current_sets(frame, drives.case_sets())
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
            drives.save(pd.concat(kept, ignore_index=True), path)
    stale = frame is not None and sum(map(len, kept)) != len(frame) and not todo
    if stale:  # nothing to plan, but rows of sets no longer in case_sets
        drives.save(pd.concat(kept, ignore_index=True), path)
    print(f"wrote {path}" if todo or stale else f"{path.name}: every set is current; nothing to plan")
    return []


def bounds(prog: str, write: bool, workers: int, path: Path | None, seed: int | None = None) -> int:
    """Write or check the shipped bounds: 0, or 2 after one line per problem."""
    from ecodrive_bench.bench.args import UsageError
    from ecodrive_bench.bench.cases import shipped_bounds

    path = path or shipped_bounds.FILE
    try:
        lines = (write_bounds(path, workers) if write
                 else shipped_bounds.check(path, seed=shipped_bounds.CHECK_SEED if seed is None else seed))
    except (UsageError, InputError, OSError) as e:  # a run folder or case list refused, a write that failed
        lines = [f"{path}: not written ({e})"]
    for line in lines:
        fail(prog, line)
    if not lines:
        n = shipped_bounds.CHECK_PER_SETTING
        print(f"wrote {path}" if write else f"{path.name} matches the DP on the sample ({n} cases per setting; floats within a relative {DP_RTOL:g})")
    return 2 if lines else 0


def write_bounds(path: Path, workers: int, progress: bool = True) -> list[str]:
    """Rebuild the shipped bounds: the baseline over every fixed case of each setting, in a
    temporary run folder (the departures, and the travel times that limit the energy bounds,
    exactly as a run measures them), then both bounds of each case with its plan. Returns error
    lines ([]: written); after an error nothing is written."""
    import pandas as pd

    from ecodrive_bench.bench.cases.bounds import solve_entry, tasks_for
    from ecodrive_bench.bench.cases.shipped_bounds import REBUILD, save
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


if __name__ == "__main__":
    sys.exit(main())
