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
from pathlib import Path

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.args import InputError, Parser, fail, int_in
from ecodrive_bench.bench.cases import case, train_family
from ecodrive_bench.bench.hosts import DP_RTOL
from ecodrive_bench.bench.io import write_or_check


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
    ok = write_or_check(case.CASES_FILE, json.dumps(data, indent=1) + "\n", args.write,
                        f"wrote {len(data['cases'])} cases to {case.CASES_FILE}", "cases.json matches the generator",
                        "cases.json differs from the generator")
    if args.write:
        return 0
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
    lines = (planned.write_clairvoyant(path, workers) if write
             else planned.check(path, seed=drives.CHECK_SEED if seed is None else seed))
    for line in lines:
        fail(prog, line)
    if not lines and not write:
        print(f"{path.name} matches the planner on the sample ({drives.CHECK_PER_SETTING} case per setting and one "
              f"of a set with a price of time on the generated corridors, {drives.CHECK_PER_SETTING} on the real ones)")
    return 2 if lines else 0


def bounds(prog: str, write: bool, workers: int, path: Path | None, seed: int | None = None) -> int:
    """Write or check the shipped bounds: 0, or 2 after one line per problem."""
    from ecodrive_bench.bench.args import UsageError
    from ecodrive_bench.bench.cases import shipped_bounds
    from ecodrive_bench.bench.shipped import dp_bounds as shipped

    path = path or shipped_bounds.FILE
    try:
        lines = (shipped.write_bounds(path, workers) if write
                 else shipped.check(path, seed=shipped.CHECK_SEED if seed is None else seed))
    except (UsageError, InputError, OSError) as e:  # a run folder or case list refused, a write that failed
        lines = [f"{path}: not written ({e})"]
    for line in lines:
        fail(prog, line)
    if not lines:
        n = shipped.CHECK_PER_SETTING
        print(f"wrote {path}" if write else f"{path.name} matches the DP on the sample ({n} cases per setting; floats within a relative {DP_RTOL:g})")
    return 2 if lines else 0


if __name__ == "__main__":
    sys.exit(main())
