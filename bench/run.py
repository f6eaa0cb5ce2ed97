"""Run methods over the fixed test cases, one MCAP per episode, and a results table.

    python -m bench.run [--methods baseline glosa] [--signals coordinated uncoordinated]
                        [--cases N] [--run-id ID] [--logs logs]

Layout: ``logs/<run-id>/<signals>/<method>/case-XXX.mcap`` and ``logs/<run-id>/results.parquet``.
A rerun skips cases whose MCAP is complete and reruns the rest. This is the sequential
core; the process pool, Ray executor and profiles are the harness issue's work.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from agents import RULE_BASED
from envs.config import SIGNALS

from .cases import load
from .episode import make_env, run_episode
from .mcaplog import is_complete, read_log
from .provenance import git_sha, package_versions


def _row_from_log(path: Path) -> dict:
    ep = read_log(path).episode
    return {f.name: getattr(ep, f.name) for f in ep.DESCRIPTOR.fields}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--methods", nargs="+", default=list(RULE_BASED), help=f"any of {', '.join(RULE_BASED)}")
    ap.add_argument("--signals", nargs="+", default=list(SIGNALS), help=f"any of {', '.join(SIGNALS)}")
    ap.add_argument("--cases", type=int, default=100, help="first N fixed cases per setting (1-100)")
    ap.add_argument("--run-id", default="default", help="folder name under --logs")
    ap.add_argument("--logs", type=Path, default=Path("logs"), help="root folder of the run folders")
    args = ap.parse_args(argv)
    for m in args.methods:
        if m not in RULE_BASED:
            ap.error(f"unknown method {m!r}; accepted: {', '.join(RULE_BASED)}")
    for s in args.signals:
        if s not in SIGNALS:
            ap.error(f"unknown signals {s!r}; accepted: {', '.join(SIGNALS)}")
    cases = load()
    if not 1 <= args.cases <= len(cases):
        ap.error(f"--cases {args.cases} is out of range; accepted: 1..{len(cases)}")
    run_dir = args.logs / args.run_id
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        probe = run_dir / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        ap.error(f"log folder {run_dir} is not writable ({e.strerror})")
    jobs = [(m, s, c) for s in args.signals for m in args.methods for c in cases[: args.cases]]
    rows = []
    envs: dict = {}
    t0 = time.perf_counter()
    for method, signals, case in tqdm(jobs, desc="episodes", unit="ep"):
        path = run_dir / signals / method / f"case-{case.index:03d}.mcap"
        if is_complete(path):
            rows.append({**_row_from_log(path), "mcap": str(path)})
            continue
        agent = RULE_BASED[method]()
        key = (method, signals)
        if key not in envs:
            envs[key] = make_env(agent, signals)
        row = run_episode(envs[key], agent, case, method, log_path=path)
        rows.append({**row, "mcap": str(path)})
    for env in envs.values():
        env.close()
    df = pd.DataFrame(rows).rename(columns={"return_": "return", "case_index": "case", "sumo_seed": "seed"})
    tmp = run_dir / "results.parquet.tmp"
    df.to_parquet(tmp, index=False)
    tmp.replace(run_dir / "results.parquet")
    manifest = {"command": sys.argv, "git_sha": git_sha(), "packages": package_versions(),
                "methods": args.methods, "signals": args.signals, "cases": args.cases,
                "wall_time_s": round(time.perf_counter() - t0, 2)}
    (run_dir / "manifest.json").write_text(json.dumps(manifest, indent=1))
    summary = df.groupby(["signals", "method"])[["energy", "travel_time", "collisions"]].mean().round(2)
    print(summary.to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
