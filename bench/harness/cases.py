"""Fixed test cases: (SUMO seed, ego insertion time) pairs shared by every method.

    ecodrive cases --write|--check [--generalisation]

The list is generated from a documented master seed and stored in ``bench/harness/cases.json`` (a
versioned file in the repo). ``ecodrive cases --write`` regenerates it; ``--check``
verifies the stored file matches the generator. With ``--generalisation`` both act on the
family of held-out corridors (``bench/harness/generalisation.json``, ``bench.harness.generalisation``).
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.args import Parser

MASTER_SEED = 20240501  # documented master seed of the protocol
CASES_PER_SETTING = 100  # section 5.3
SEED_GROUPS = 10  # independent groups for the violin figure
INSERT_RANGE = (150.0, 300.0)  # [s] U(150, 300)
VERSION = 1
CASES_FILE = Path(__file__).with_name("cases.json")


@dataclass(frozen=True)
class Case:
    index: int
    sumo_seed: int
    insert_time: float  # [s], rounded to 0.1 s
    group: int  # seed group in [0, SEED_GROUPS)

    def options(self) -> dict[str, float]:
        return {"sumo_seed": self.sumo_seed, "insert_time": self.insert_time}


def generate(master_seed: int = MASTER_SEED, n: int = CASES_PER_SETTING, groups: int = SEED_GROUPS) -> dict:
    rng = np.random.default_rng(master_seed)
    seeds = rng.choice(2**31 - 1, size=n, replace=False)
    times = np.round(rng.uniform(*INSERT_RANGE, size=n), 1)
    cases = [{"index": i, "sumo_seed": int(seeds[i]), "insert_time": float(times[i]), "group": i % groups}
             for i in range(n)]
    return {"version": VERSION, "master_seed": master_seed, "insert_range_s": list(INSERT_RANGE),
            "groups": groups, "cases": cases}


def load(path: Path = CASES_FILE) -> list[Case]:
    data = json.loads(path.read_text())
    if data.get("version") != VERSION:
        raise ValueError(f"{path}: cases version {data.get('version')!r} is not the supported {VERSION}")
    return [Case(**c) for c in data["cases"]]


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", action="store_true", help="regenerate bench/harness/cases.json")
    g.add_argument("--check", action="store_true", help="check bench/harness/cases.json against the generator")
    ap.add_argument("--generalisation", action="store_true",
                    help="write or check the generalisation family instead (bench/harness/generalisation.json, "
                         "bench.harness.generalisation)")
    args = ap.parse_args(argv)
    if args.generalisation:
        from bench.harness import generalisation

        return generalisation.main(args.write)
    data = generate()
    text = json.dumps(data, indent=1) + "\n"
    if args.write:
        CASES_FILE.write_text(text)
        print(f"wrote {len(data['cases'])} cases to {CASES_FILE}")
        return 0
    ok = CASES_FILE.exists() and CASES_FILE.read_text() == text
    print("cases.json matches the generator" if ok else "cases.json differs from the generator")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
