"""The benchmark harness: every method over the fixed test cases, one MCAP per episode.

    python -m bench.run [--profile smoke|paper|full] [--executor local|ray] [--address ADDR]
                        [--workers N] [--methods ...] [--signals ...] [--run-id ID] [--logs DIR]

Writes ``<logs>/<run-id>/<signals>/<method>/case-XXX.mcap``, ``results.parquet`` and
``manifest.json``. Rerunning the same command skips cases whose MCAP is complete and reruns the
rest, so a killed run loses nothing that finished. Evaluation is greedy.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm import tqdm

from agents.registry import LEARNING, METHODS
from envs.config import SIGNALS

from .cases import load
from .checkpoint import MODELS, CheckpointError, atomic_parquet, policy_dir, sha256
from .executors import EXECUTORS, Task, run_local, run_ray
from .mcaplog import episode_summary
from .provenance import git_sha, package_versions

PROFILES = {  # name: cases per setting (full: `nox -s benchmark` adds lateral, mixed, reward and heatmap)
    "smoke": 3,
    "paper": 100,
    "full": 100,
}
KEEP = ("method", "signals", "case", "seed", "insert_time", "depart_time", "energy", "travel_time", "steps",
        "terminated", "truncated", "return", "stops", "time_stopped", "lane_changes_requested",
        "lane_changes_applied", "clips", "jerk_exceedances", "collisions", "teleports", "battery_consumed",
        "battery_regenerated", "mcap")


class UsageError(Exception):
    """Bad input; printed as one line, nothing touched."""


def _choice(flag: str, value: str, accepted: tuple[str, ...] | list[str]) -> str:
    if value not in accepted:
        raise UsageError(f"{flag} {value!r} is not accepted; choose one of {', '.join(accepted)}")
    return value


def parse(argv: list[str]) -> dict[str, Any]:
    """A small, strict parser: unknown flags and values are one-line errors (no usage dump)."""
    opts: dict[str, Any] = {"profile": "paper", "executor": "local", "address": None, "workers": os.cpu_count() or 1,
                            "methods": None, "signals": list(SIGNALS), "run_id": None, "logs": Path("logs"),
                            "models": MODELS}
    multi = {"--methods": "methods", "--signals": "signals"}
    single = {"--profile": "profile", "--executor": "executor", "--address": "address", "--workers": "workers",
              "--run-id": "run_id", "--logs": "logs", "--models": "models"}
    i = 0
    while i < len(argv):
        flag = argv[i]
        if flag in ("-h", "--help"):
            print(__doc__)
            raise SystemExit(0)
        if flag in multi:
            vals = []
            while i + 1 < len(argv) and not argv[i + 1].startswith("--"):
                vals.append(argv[i + 1])
                i += 1
            if not vals:
                raise UsageError(f"{flag} needs at least one value")
            opts[multi[flag]] = vals
        elif flag in single:
            if i + 1 >= len(argv):
                raise UsageError(f"{flag} needs a value")
            opts[single[flag]] = argv[i + 1]
            i += 1
        else:
            raise UsageError(f"unknown option {flag!r}; accepted: {', '.join([*single, *multi])}")
        i += 1
    _choice("--profile", opts["profile"], tuple(PROFILES))
    _choice("--executor", opts["executor"], EXECUTORS)
    try:
        opts["workers"] = int(opts["workers"])
    except ValueError:
        raise UsageError(f"--workers {opts['workers']!r} must be an integer >= 1") from None
    if opts["workers"] < 1:
        raise UsageError(f"--workers {opts['workers']} must be >= 1")
    for s in opts["signals"]:
        _choice("--signals", s, SIGNALS)
    opts["logs"], opts["models"] = Path(opts["logs"]), Path(opts["models"])
    opts["run_id"] = opts["run_id"] or opts["profile"]
    return opts


def resolve_methods(opts: dict[str, Any]) -> tuple[list[tuple[str, str]], list[str]]:
    """((method, signals) pairs to run, "method/signals" skipped for want of a shipped policy).

    Without ``--methods``, a learning method runs in each setting it has a policy for; named in
    ``--methods``, a missing policy is an error."""
    explicit = opts["methods"] is not None
    pairs, skipped = [], []
    for m in (opts["methods"] if explicit else METHODS):
        if explicit:
            _choice("--methods", m, METHODS)
        for s in opts["signals"]:
            if m in LEARNING and not (policy_dir(m, s, opts["models"]) / "manifest.json").is_file():
                if explicit:
                    raise UsageError(f"no trained policy for {m} / {s} (expected {policy_dir(m, s, opts['models'])}); "
                                     f"train it: python -m bench.train --method {m} --signals {s}")
                skipped.append(f"{m}/{s}")
            else:
                pairs.append((m, s))
    return pairs, skipped


def check_writable(run_dir: Path) -> None:
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        probe = run_dir / f".write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise UsageError(f"log folder {run_dir} is not writable ({e.strerror})") from None


def run(opts: dict[str, Any], progress: bool = True) -> pd.DataFrame:
    pairs, skipped = resolve_methods(opts)
    methods = list(dict.fromkeys(m for m, _ in pairs))
    if skipped:
        print(f"note: no shipped policy for {', '.join(skipped)}; running the rest", file=sys.stderr)
    run_dir = opts["logs"] / opts["run_id"]
    check_writable(run_dir)
    cases = load()[: PROFILES[opts["profile"]]]
    rows, tasks = [], []
    for signals in opts["signals"]:
        for method in [m for m, s in pairs if s == signals]:
            pdir = str(policy_dir(method, signals, opts["models"])) if method in LEARNING else ""
            sha = sha256(Path(pdir) / "policy.pt") if pdir else ""  # a log of another policy is rerun
            for case in cases:
                path = run_dir / signals / method / f"case-{case.index:03d}.mcap"
                done = episode_summary(path, agent_sha256=sha)
                if done is not None:
                    rows.append({**done, "mcap": str(path), "episode_wall_s": float("nan")})
                else:
                    tasks.append(Task(method, signals, case, str(path), pdir))
    t0 = time.perf_counter()
    it = (run_local(tasks, opts["workers"]) if opts["executor"] == "local"
          else run_ray(tasks, opts["address"], opts["workers"]))
    with tqdm(total=len(rows) + len(tasks), initial=len(rows), desc="episodes", unit="ep", disable=not progress) as bar:
        for row in it:
            rows.append(row)
            bar.update(1)
    wall = time.perf_counter() - t0
    df = pd.DataFrame(rows).rename(columns={"return_": "return", "case_index": "case", "sumo_seed": "seed"})
    df = df.sort_values(["signals", "method", "case"], ignore_index=True)
    ran = df["episode_wall_s"].dropna()
    atomic_parquet(df[list(KEEP)], run_dir / "results.parquet")
    shas = {f"{m}-{s}": sha256(policy_dir(m, s, opts["models"]) / "policy.pt")
            for m, s in pairs if m in LEARNING}
    manifest = {
        "command": " ".join(["python", "-m", "bench.run", *opts.get("argv", [])]), "profile": opts["profile"],
        "executor": opts["executor"], "workers": opts["workers"], "methods": methods, "skipped_methods": skipped,
        "signals": opts["signals"], "cases_per_setting": len(cases), "git_sha": git_sha(),
        "packages": package_versions(), "checkpoint_sha256": shas,
        "episodes_run": int(len(ran)), "episodes_reused": int(len(df) - len(ran)),
        "wall_time_s": round(wall, 2), "episode_time_sum_s": round(float(ran.sum()), 2),
        "harness_overhead": round(float(wall * min(opts["workers"], max(len(ran), 1)) / ran.sum() - 1), 4)
        if len(ran) else None,
    }
    from envs.config import ScenarioConfig

    manifest["scenario"] = {s: ScenarioConfig(signals=s).to_dict() for s in opts["signals"]}
    tmp = run_dir / ".manifest.json.tmp"
    tmp.write_text(json.dumps(manifest, indent=1))
    os.replace(tmp, run_dir / "manifest.json")
    return df


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        opts = parse(argv)
        opts["argv"] = argv
        df = run(opts)
    except (UsageError, CheckpointError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: finished episodes are kept; rerun the same command to continue", file=sys.stderr)
        return 130
    summary = df.groupby(["signals", "method"])[["energy", "travel_time", "collisions"]].mean().round(2)
    print(summary.to_string())
    print(f"results: {opts['logs'] / opts['run_id'] / 'results.parquet'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
