"""``ecodrive cases``: write or check the versioned case files against their generators.

    ecodrive cases --write|--check [--generalisation]

The fixed test cases (``bench/harness/cases.json``, ``bench.harness.cases``) and, with
``--generalisation``, the family of held-out corridors (``bench/harness/generalisation.json``,
``bench.harness.generalisation``). This command sits above both modules, so neither imports
the other back.
"""
from __future__ import annotations

import json
import sys

from ecodrive_bench.bench.args import Parser
from ecodrive_bench.bench.harness import cases, generalisation


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
        return generalisation.main(args.write)
    data = cases.generate()
    text = json.dumps(data, indent=1) + "\n"
    if args.write:
        cases.CASES_FILE.write_text(text)
        print(f"wrote {len(data['cases'])} cases to {cases.CASES_FILE}")
        return 0
    ok = cases.CASES_FILE.exists() and cases.CASES_FILE.read_text() == text
    print("cases.json matches the generator" if ok else "cases.json differs from the generator")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
