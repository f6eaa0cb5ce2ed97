"""Regression check of the published numbers and of the project's own reference.

    ecodrive regress [--write-reference]

Runs every method with a shipped policy on the first ``CI_CASES`` fixed cases per setting (the
``smoke`` cases are among them), then checks, and prints side by side:
1. the paper's claims, each an inequality (a claim about a method without a shipped policy is
   reported as NOT CHECKED, never as passed);
2. Table 4's baseline row within the calibration tolerance, and the RL rows' improvements beside
   the published ones within a stated band;
3. the project's own reference results (``bench/regression/reference/ci.csv``, written by
   ``--write-reference`` from the same command) with tight tolerances.
Exits 1 on any failed check. Tolerances and their reasons: ``docs/regression.md``.
"""
from __future__ import annotations

import os
import shutil
import stat
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from ecodrive_bench.bench.args import Parser, UsageError, fail
from ecodrive_bench.bench.claims import single_vehicle
from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import preflight, run
from ecodrive_bench.bench.hosts import ENERGY_RTOL
from ecodrive_bench.bench.io import atomic_csv
from ecodrive_bench.bench.methods.errors import AgentError
from ecodrive_bench.bench.methods.policies import CheckpointError

CI_CASES = 20
REFERENCE = Path(__file__).with_name("reference") / "ci.csv"
# own reference, relative per episode: runs are deterministic for a seed on one machine, but torch
# picks its CPU kernels by instruction set (AVX2, AVX-512), and a continuous action that differs
# in its last bits moves an episode's energy by up to 1e-7 (8.2e-8 measured, AVX-512 against the
# reference's host; every discrete column identical, the rule-based and DQN rows bit-identical).
# So energy is compared to 1e-6, and the counts and times exactly (up to formatting noise).
REF_RTOL = 1e-9
REF_RTOL_BY_COLUMN = {"energy": ENERGY_RTOL}
CLAIMS_RECORD = REFERENCE.with_name("claims.csv")  # the claims' statuses when the reference was written
REF_COLUMNS = ["method", "signals", "train_seed", "case", "energy", "travel_time", "steps", "stops", "lane_changes_applied",
               "clips", "collisions"]


def claims(df: pd.DataFrame) -> list[tuple[str, str, str]]:
    """The paper's inequality claims (``bench.claims``, kind "claim"): (name, PASS/FAIL/NOT CHECKED, detail)."""
    return [(c.name, _status(c.ok), c.detail) for c in single_vehicle(df) if c.kind == "claim"]


def published(df: pd.DataFrame) -> list[tuple[str, str, str]]:
    """Table 4's baseline within the calibration tolerance (PASS/FAIL), and PRL's improvements
    beside the published ones within the band (PASS/OUTSIDE BAND: reported, not failed)."""
    out = []
    for c in single_vehicle(df):
        if c.kind == "published" or (c.kind == "band" and c.ok is not None):
            status = _status(c.ok)
            out.append((c.name, "OUTSIDE BAND" if c.kind == "band" and status == "FAIL" else status, c.detail))
    return out


def _status(ok: bool | None) -> str:
    return "NOT CHECKED" if ok is None else ("PASS" if ok else "FAIL")


def reference(df: pd.DataFrame) -> list[tuple[str, str, str]]:
    if not REFERENCE.is_file():
        return [("own reference", "FAIL", f"{REFERENCE} missing: ecodrive regress --write-reference")]
    ref = pd.read_csv(REFERENCE)
    # a reference written before training seeds existed holds one policy per method: seed 0
    keys = [c for c in ("method", "signals", "train_seed", "case") if c in ref.columns]
    values = [c for c in REF_COLUMNS if c not in ("method", "signals", "train_seed", "case")]
    ours = df[keys + values].sort_values(keys[:-1][::-1] + ["case"], ignore_index=True)
    ref = ref.sort_values(keys[:-1][::-1] + ["case"], ignore_index=True)
    out = []
    for group, r in ref.groupby(keys[:-1]):
        name = "reference " + "/".join(map(str, group))
        o = ours[(ours[keys[:-1]] == pd.Series(group, index=keys[:-1])).all(axis=1)]
        if len(o) != len(r):
            out.append((name, "FAIL", f"{len(o)} episodes, reference has {len(r)}"))
            continue
        bad = [c for c in values if not np.allclose(o[c].to_numpy(float), r[c].to_numpy(float),
                                                    rtol=REF_RTOL_BY_COLUMN.get(c, REF_RTOL), atol=1e-9)]
        out.append((name, "FAIL" if bad else "PASS", f"differs in {', '.join(bad)}" if bad else f"{len(r)} episodes identical"))
    new = sorted(set(map(tuple, ours[keys[:-1]].values)) - set(map(tuple, ref[keys[:-1]].values)))
    for group in new:
        out.append(("reference " + "/".join(map(str, group)), "FAIL", "not in the reference: regenerate it in its own commit"))
    return out


def against_record(rows: list[tuple[str, str, str]], record: dict[str, str]) -> list[tuple[str, str, str]]:
    """A claim that failed when the reference was written and still fails is a KNOWN FAIL (a
    documented gap of the reproduction, not a regression); one that now passes fails the check
    until the record is rewritten, like a strict xfail. Everything else is unchanged."""
    out = []
    for name, status, detail in rows:
        was = record.get(name)
        if was == "FAIL" and status == "FAIL":
            status, detail = "KNOWN FAIL", f"{detail} (failed when the reference was written; see docs/results.md)"
        elif was == "FAIL" and status == "PASS":
            status, detail = "FAIL", f"{detail} (now passes: rewrite the reference in its own commit)"
        out.append((name, status, detail))
    return out


def record_rows(now: list[tuple[str, str, str]], earlier: list[tuple[str, str, str]]) -> list[tuple[str, str, str]]:
    """The claims record to write: this run's checked claims, then, where it left some unchecked,
    the earlier record's rows for the claims it did not check (``--no-mixed`` keeps the recorded
    mixed-traffic claims). A run that checked every claim writes its own rows alone, so a claim
    that was renamed or dropped leaves no stale row."""
    checked = [r for r in now if r[1] != "NOT CHECKED"]
    if len(checked) == len(now):
        return checked
    names = {r[0] for r in checked}
    return checked + [r for r in earlier if r[0] not in names and r[1] != "NOT CHECKED"]


def _drop_if_empty(folder: Path) -> None:
    """Remove the fresh temporary log root of a refused command, if nothing was written in it."""
    try:
        folder.rmdir()
    except OSError:
        pass


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("--write-reference", action="store_true", help=f"write bench/regression/reference/{REFERENCE.name} from this run")
    ap.add_argument("--no-mixed", action="store_true", help="skip the mixed-traffic cells (reported NOT CHECKED)")
    ap.add_argument("--logs", type=Path, default=None, help="log root (default: a fresh temporary folder, so no old log is reused)")
    args = ap.parse_args(argv)
    import ecodrive_bench.bench.harness.options as br
    from ecodrive_bench.bench.experiments.mixed import CellMismatch
    from ecodrive_bench.bench.regression import mixed_cells as regression_mixed

    logs = str(args.logs) if args.logs is not None else tempfile.mkdtemp(prefix="ecodrive-regression-")
    made = os.stat(logs) if args.logs is None else None  # the folder this command made: removed after a pass
    br.PROFILES["regression"] = CI_CASES  # for this run only: `ecodrive run` offers no such profile
    try:
        opts = parse(["--profile", "regression", "--logs", logs])
        checks = preflight(opts)  # a refused command prints its one error line only
        if args.logs is None:  # every episode and cell is written there as it finishes: a kill keeps them
            print(f"regression: logs in {logs} (after a kill, --logs {logs} reuses what finished)", file=sys.stderr)
        df = run(opts, checks=checks)  # progress on stderr: bars on a terminal, lines in a log
    except (UsageError, CheckpointError, AgentError) as e:  # a shipped policy that cannot drive included
        if args.logs is None:
            _drop_if_empty(Path(logs))
        return fail(ap.prog, str(e))
    finally:
        del br.PROFILES["regression"]
    if args.write_reference:
        REFERENCE.parent.mkdir(exist_ok=True)
        atomic_csv(df[REF_COLUMNS], REFERENCE, float_format="%.10g")
        print(f"wrote {REFERENCE} ({len(df)} episodes)")
    try:
        mixed = (regression_mixed.claims(None, "--no-mixed given") if args.no_mixed
                 else regression_mixed.claims(regression_mixed.run_cells(logs=opts.run_dir / "mixed")))
    except CellMismatch as e:  # a cell left in --logs by other settings: never silently reused
        return fail(ap.prog, str(e))
    paper = claims(df)
    if args.write_reference:
        earlier = pd.read_csv(CLAIMS_RECORD) if CLAIMS_RECORD.is_file() else None
        rows = record_rows(paper + mixed, [] if earlier is None else [tuple(r) for r in earlier.values])
        pd.DataFrame(rows, columns=["claim", "status", "detail"]).to_csv(CLAIMS_RECORD, index=False)
        print(f"wrote {CLAIMS_RECORD}")
    record = dict(pd.read_csv(CLAIMS_RECORD)[["claim", "status"]].values) if CLAIMS_RECORD.is_file() else {}
    paper, mixed = against_record(paper, record), against_record(mixed, record)
    failed = False
    for title, rows in (("1. the paper's claims", paper), ("2. the published numbers", published(df)),
                        ("3. the project's own reference", reference(df)),
                        ("4. mixed traffic (section 5.5)", mixed)):
        print(f"\n{title}")
        for name, status, detail in rows:
            print(f"  {status:12s} {name:50s} {detail}")
            failed |= status == "FAIL"
    print("\nregression: FAILED" if failed else "\nregression: ok")
    if made is not None:
        if failed:
            print(f"regression: its logs are kept in {logs}", file=sys.stderr)
        else:
            _remove_made(Path(logs), made)
    return 1 if failed else 0


def _remove_made(folder: Path, made: os.stat_result) -> None:
    """Remove ``folder`` with its contents if it is still the folder this command made (the same
    device and inode, not a link); anything else is left as it is."""
    try:
        st = os.lstat(folder)
    except OSError:
        return
    if stat.S_ISDIR(st.st_mode) and (st.st_dev, st.st_ino) == (made.st_dev, made.st_ino):
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
