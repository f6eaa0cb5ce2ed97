"""The benchmark harness: every method over the fixed test cases, one MCAP per episode.

    ecodrive run [--profile smoke|paper|full|generalisation] [--executor local|ray] [--address ADDR]
                        [--workers N] [--methods ...] [--signals ...] [--run-id ID] [--logs DIR]
                        [--agent MODULE:FACTORY | --sb3 MODEL.zip --sb3-algo ALGO] [--name NAME]
                        [--scenario FILE.json] [--set FIELD=VALUE ...] [--transfer] [--variants NAME ...]

Writes ``<logs>/<run-id>/<signals>/<method>/case-XXX.mcap``, ``results.parquet`` and
``manifest.json``. Rerunning the same command skips cases whose MCAP is complete and reruns the
rest, so a killed run loses nothing that finished. Evaluation is greedy. ``--scenario`` and
``--set`` evaluate on another corridor (one per run folder and setting); a policy drives a
scenario other than its training one only with ``--transfer`` (``bench.harness.scenarios``).
``--profile generalisation`` runs over the held-out corridors of ``bench.harness.generalisation``
instead, one sub-folder per variant (``bench.harness.generalisation_run``).
A worker that dies is replaced and its episode rerun (at most twice more); an episode that still
fails, or whose agent raises, is one line on stderr (its traceback in ``<run>/errors/``) and no
row. Exit codes: 0 done; 2 bad input, or the run folder in use by another command; 3 finished
with failed episodes (rerun the command to retry them); 130 interrupted.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm import tqdm

from agents.registry import LEARNING, METHODS
from bench.args import Parser, fail, int_in, name
from bench.harness import external, failures, runlock, scenarios
from bench.harness.bounds import attach
from bench.harness.cases import load
from bench.harness.executors import EXECUTORS, Task, run_local, run_ray
from bench.harness.external import GROUP, AgentError, registered
from bench.harness.generalisation import CASES_PER_VARIANT, FamilyError
from bench.harness.oracle import NAME as ORACLE
from bench.harness.policies import MODELS, CheckpointError, check_policy, family_dir, policy_dir, shipped_seeds
from bench.harness.provenance import carry_forward, git_sha, package_versions
from bench.harness.sb3 import ALGOS as SB3_ALGOS
from bench.io import Unwritable, atomic_json, atomic_parquet, refuse_links, sha256, writable_dir
from bench.logs.mcaplog import episode_summary, resolve_log
from envs.config import SIGNALS

PROFILES = {  # name: cases per setting (full: `nox -s benchmark` adds lateral, mixed, reward and heatmap)
    "smoke": 3,
    "paper": 100,
    "full": 100,
    "generalisation": CASES_PER_VARIANT,  # per variant and setting, over bench.harness.generalisation's family
}
KEEP = ("method", "signals", "train_seed", "case", "seed", "insert_time", "depart_time", "energy", "travel_time", "steps",
        "terminated", "truncated", "return", "stops", "time_stopped", "lane_changes_requested",
        "lane_changes_applied", "clips", "jerk_exceedances", "collisions", "teleports", "battery_consumed",
        "battery_regenerated", "mcap", "eval_scenario_hash", "train_scenario_hash")
SCENARIO_COLUMNS = ("eval_scenario_hash", "train_scenario_hash")  # not in tables written before them


class UsageError(Exception):
    """Bad input; printed as one line, nothing touched."""


def parser() -> Parser:
    ap = Parser(description=__doc__)
    ap.add_argument("--profile", default="paper", choices=list(PROFILES),
                    help="smoke: 3 cases per setting; paper: the 100 fixed cases; full: paper plus section 5's "
                         "experiments (in `nox -s benchmark`); generalisation: every method with a policy, "
                         f"{ORACLE} included, on each held-out corridor of the family (docs/generalisation.md), "
                         "its cases, with --transfer implied, one sub-folder per variant")
    ap.add_argument("--variants", nargs="+", default=None, metavar="NAME",
                    help="with --profile generalisation: only these variants of the family, by full or short name "
                         "(g1, g2, ...; default: all)")
    users = registered()
    ap.add_argument("--methods", nargs="+", default=None, metavar="METHOD", choices=[*METHODS, ORACLE, *users],
                    help=f"among {', '.join([*METHODS, ORACLE, *users])} (default: every method with a shipped "
                         f"policy; {ORACLE} (the energy-optimal plan replayed, a DP solve per case) and installed "
                         f"agents of the entry-point group {GROUP} run when named)")
    ap.add_argument("--agent", default=None, metavar="MODULE:FACTORY",
                    help="also evaluate your own agent: factory(observation_space, action_space) -> agents.base.Agent")
    ap.add_argument("--sb3", type=Path, default=None, metavar="MODEL.zip",
                    help="also evaluate a Stable-Baselines3 model trained on EcoDrive-v0 (needs the sb3 extra; "
                         "nothing in the zip is unpickled but its spaces and policy class and kwargs, through an "
                         "allow list)")
    ap.add_argument("--sb3-algo", default=None, choices=SB3_ALGOS,
                    help=f"the --sb3 model's algorithm: {', '.join(SB3_ALGOS)}")
    ap.add_argument("--name", type=name, default=None,
                    help="the --agent's or --sb3's method name in results and reports (default: the factory's "
                         "name; sb3-<algo> for --sb3)")
    ap.add_argument("--signals", nargs="+", default=list(SIGNALS), choices=list(SIGNALS), help="signal settings")
    ap.add_argument("--executor", default="local", choices=list(EXECUTORS), help="local process pool, or Ray")
    ap.add_argument("--address", default=None, help="Ray cluster address (with --executor ray; default: a local Ray)")
    ap.add_argument("--workers", type=int_in(1), default=os.cpu_count() or 1, help="parallel episodes (>= 1)")
    ap.add_argument("--run-id", type=name, default=None,
                    help="run folder under --logs: letters, digits, '.', '_', '-' (default: the profile)")
    ap.add_argument("--logs", type=Path, default=Path("logs"), help="log root (default: logs)")
    ap.add_argument("--models", type=Path, default=MODELS, help="shipped policies (default: models/)")
    ap.add_argument("--bounds", action="store_true",
                    help="add each case's energy-optimal bound (bench.oracle DP; a few s per case, kept in "
                         "<run>/bounds.parquet): columns cost_bound and energy_bound")
    ap.add_argument("--train-seeds", nargs="+", type=int_in(0), default=None, metavar="SEED",
                    help="training seeds of the learning methods to evaluate, each >= 0 (default: every shipped one)")
    scenarios.add_options(ap)
    return ap


def parse(argv: list[str]) -> dict[str, Any]:
    """The options as a dict; bad input exits 2 with one line (``bench.args.Parser``)."""
    ap = parser()
    opts = vars(ap.parse_args(argv))
    opts["run_id"] = opts["run_id"] or opts["profile"]
    users = registered()
    opts["factories"] = {m: users[m] for m in opts["methods"] or [] if m in users}
    if opts["sb3"] or opts["sb3_algo"]:
        opts["agent"] = sb3_spec(ap, opts)
    if opts["agent"]:
        label = opts["name"] or (f"sb3-{opts['sb3_algo'].lower()}" if opts["sb3"] else opts["agent"].split(":")[-1])
        if label in (*METHODS, ORACLE) or label in opts["factories"]:
            ap.error(f"--name {label!r} is taken by a built-in or installed method; choose another")
        opts["factories"][label] = opts["agent"]
        opts["agent_sha256"] = {label: opts.pop("sb3_sha256")} if "sb3_sha256" in opts else {}
    elif opts["name"]:
        ap.error("--name names an --agent or --sb3; give --agent package.module:factory or --sb3 MODEL.zip too")
    if opts["profile"] == "generalisation":
        if opts["scenario"] or opts["set_scenario"]:
            ap.error("--profile generalisation evaluates on its family's corridors; --scenario and --set "
                     "are for the other profiles")
        from bench.harness import generalisation

        try:
            opts["family"] = generalisation.select(generalisation.load(), opts["variants"])
        except FamilyError as e:
            ap.error(str(e))
        opts["transfer"] = True
    elif opts["variants"]:
        ap.error("--variants selects corridors of the generalisation family; give --profile generalisation too")
    try:
        opts["scenario"] = scenarios.parse_overrides(opts.pop("scenario"), opts.pop("set_scenario"), opts["signals"])
    except ValueError as e:
        ap.error(str(e))
    return opts


def sb3_spec(ap: Parser, opts: dict[str, Any]) -> str:
    """The factory spec of ``--sb3 --sb3-algo`` (``bench.harness.sb3``), the zip read and checked
    now: bad input is one line before anything runs."""
    if opts["agent"]:
        ap.error("--sb3 and --agent each add one agent; give one of them")
    if not (opts["sb3"] and opts["sb3_algo"]):
        ap.error(f"--sb3 MODEL.zip and --sb3-algo go together; --sb3-algo is one of {', '.join(SB3_ALGOS)}")
    from bench.harness import sb3

    try:
        saved = sb3.inspect(opts["sb3"], opts["sb3_algo"])
    except AgentError as e:
        ap.error(str(e))
    opts["sb3_sha256"] = saved.sha256
    return sb3.spec(opts["sb3_algo"], opts["sb3"])


def resolve_methods(opts: dict[str, Any]) -> tuple[list[tuple[str, str, int]], list[str]]:
    """((method, signals, training seed) to run, "method/signals" skipped for want of a shipped
    policy). Rule-based methods have the training seed -1.

    Without ``--methods``, a learning method runs in each setting it has a policy for, every
    shipped seed (or those of ``--train-seeds``); named in ``--methods``, a missing policy is an
    error."""
    explicit = opts["methods"] is not None
    wanted = opts.get("train_seeds")
    runs, skipped = [], []
    factories = opts.get("factories", {})
    default = [*METHODS, ORACLE] if opts.get("profile") == "generalisation" else METHODS
    named = [m for m in (opts["methods"] if explicit else default) if m not in factories]
    for m in [*named, *factories]:
        for s in opts["signals"]:
            if m not in LEARNING:
                runs.append((m, s, -1))
                continue
            seeds = [sd for sd in shipped_seeds(m, s, opts["models"]) if wanted is None or sd in wanted]
            if not seeds:
                if explicit:
                    raise UsageError(f"no trained policy for {m} / {s}"
                                     f"{'' if wanted is None else ' with training seed ' + ' or '.join(map(str, wanted))}"
                                     f" (expected {family_dir(m, s, opts['models'])}/s<seed>/); "
                                     f"train it: ecodrive train --method {m} --signals {s}")
                skipped.append(f"{m}/{s}")
            runs.extend((m, s, sd) for sd in seeds)
    return runs, skipped


def check_policies(pdirs: dict[tuple[str, str, int], str], checked: set[str] | None = None) -> None:
    """Load every policy of the command into its agent once, here in the parent: a file that
    cannot drive is a ``CheckpointError`` before the run folder is made or any episode starts
    (``bench.harness.policies.check_policy``). Folders in ``checked`` are skipped and added to it."""
    checked = set() if checked is None else checked
    for (method, _, _), pdir in pdirs.items():
        if pdir and pdir not in checked:
            check_policy(Path(pdir), method)
            checked.add(pdir)


def check_writable(run_dir: Path) -> None:
    try:
        refuse_links(run_dir, "run folder")
        writable_dir(run_dir)
    except Unwritable as e:
        raise UsageError(f"log {e}") from None


def preflight(opts: dict[str, Any], checked: set[str] | None = None) -> dict[str, Any]:
    """Every check of a run that writes nothing: methods, factories, policies (``checked``: policy
    folders already loaded by an earlier call), the scenario each may drive, and the run folder's
    scenario. Raises ``UsageError``, ``CheckpointError`` or ``AgentError``; returns what ``run`` needs."""
    runs, skipped = resolve_methods(opts)
    factories = opts.get("factories", {})
    overrides, transfer = opts.get("scenario") or {}, bool(opts.get("transfer"))
    for spec in factories.values():  # a factory that cannot build its agent fails before any episode
        try:
            env, _ = external.make(spec, opts["signals"][0], overrides or None)
            env.close()
        except AgentError as e:
            raise UsageError(str(e)) from None
    run_dir = opts["logs"] / opts["run_id"]
    evals = {s: scenarios.setting(s, overrides) for s in opts["signals"]}
    pdirs = {(m, s, sd): str(policy_dir(m, s, opts["models"], sd)) if sd >= 0 else "" for m, s, sd in runs}
    # a policy that may not (or cannot) drive the scenario is refused before anything is written
    where = {r: scenarios.evaluation(r[0], r[1], pdirs[r], overrides, transfer) for r in runs}
    check_policies(pdirs, checked)
    one_scenario(run_dir, {s: c.digest() for s, c in evals.items()})
    return {"runs": runs, "skipped": skipped, "pdirs": pdirs, "where": where, "evals": evals}


def run(opts: dict[str, Any], progress: bool = True, checks: dict[str, Any] | None = None) -> pd.DataFrame:
    """Run (or reuse) every episode of the command and write ``results.parquet`` and the manifest;
    ``checks``: this command's ``preflight``, when the caller ran it already. The run folder is
    locked meanwhile (``bench.harness.runlock``); failed episodes are appended to
    ``opts["failures"]`` (``bench.harness.failures``)."""
    checks = preflight(opts) if checks is None else checks
    check_writable(opts["logs"] / opts["run_id"])
    with runlock.hold(opts["logs"] / opts["run_id"]):
        return _run(opts, progress, checks)


def _run(opts: dict[str, Any], progress: bool, checks: dict[str, Any]) -> pd.DataFrame:
    runs, skipped, pdirs, where, evals = (checks[k] for k in ("runs", "skipped", "pdirs", "where", "evals"))
    factories = opts.get("factories", {})
    overrides, transfer = opts.get("scenario") or {}, bool(opts.get("transfer"))
    methods = list(dict.fromkeys(m for m, _, _ in runs))
    run_dir = opts["logs"] / opts["run_id"]
    if skipped:  # after the checks: a refused command prints its one error line only
        print(f"note: no shipped policy for {', '.join(skipped)}; running the rest", file=sys.stderr)
    check_writable(run_dir)
    cases = opts.get("cases") or load()[: PROFILES[opts["profile"]]]  # a variant's own (generalisation)
    rows, tasks = [], []
    shas = {}
    trained = {ev.train_hash: ev.train for ev in where.values() if ev.train_hash}
    for signals in opts["signals"]:
        for method, seed in [(m, sd) for m, s, sd in runs if s == signals]:
            pdir, ev = pdirs[(method, signals, seed)], where[(method, signals, seed)]
            sha = (sha256(Path(pdir) / "policy.pt") if pdir  # a log of another policy is rerun
                   else opts.get("agent_sha256", {}).get(method, ""))
            if sha:
                shas[policy_key(method, signals, seed)] = sha
            folder = run_dir / signals / method / (f"s{seed}" if seed >= 0 else "")
            for case in cases:
                path = folder / f"case-{case.index:03d}.mcap"
                done = episode_summary(path, agent_sha256=sha, eval_scenario=ev.eval_hash,
                                       legacy_scenario=scenarios.legacy_hash(signals))
                if done is not None:
                    rows.append({**done, "mcap": str(path), "episode_wall_s": float("nan"), "train_seed": seed})
                else:
                    tasks.append(Task(method, signals, case, str(path), pdir, seed, factories.get(method, ""),
                                      scenario=ev.scenario, transfer=transfer, meta=ev.meta(transfer)))
    failed = failures.Failures(run_dir, tasks, opts.setdefault("failures", []))
    t0 = time.perf_counter()
    it = (run_local(tasks, opts["workers"], on_failure=failed, skip=failed.skip) if opts["executor"] == "local"
          else run_ray(tasks, opts["address"], opts["workers"], on_failure=failed, skip=failed.skip))
    with tqdm(total=len(rows) + len(tasks), initial=len(rows), desc="episodes", unit="ep", disable=not progress) as bar:
        for row in it:
            rows.append(row)
            bar.update(1)
    wall = time.perf_counter() - t0
    df = pd.DataFrame(rows).rename(columns={"return_": "return", "case_index": "case", "sumo_seed": "seed"})
    df = df if len(df) else pd.DataFrame(columns=[*KEEP, "episode_wall_s"])  # every episode failed
    for i, col in enumerate(SCENARIO_COLUMNS):
        df[col] = [(ev.eval_hash, ev.train_hash)[i] for ev in map(where.get, zip(df.method, df.signals, df.train_seed))]
    ran = df["episode_wall_s"].dropna()
    kept = earlier_rows(run_dir, df, shas)
    df = pd.concat([df[list(KEEP)], kept], ignore_index=True) if len(kept) else df[list(KEEP)]
    df = df.sort_values(["signals", "method", "train_seed", "case"], ignore_index=True)
    df["mcap"] = [_relative(run_dir, m) for m in df.mcap]  # the run folder moves as a whole
    if opts.get("bounds"):
        def runner(tasks, workers, fn):
            return (run_local(tasks, workers, fn) if opts["executor"] == "local"
                    else run_ray(tasks, opts["address"], workers, fn))
        df = attach(run_dir, df, opts["workers"], runner, overrides)
    atomic_parquet(df, run_dir / "results.parquet")
    manifest = {
        "command": " ".join(["ecodrive", "run", *opts.get("argv", [])]), "profile": opts["profile"],
        "executor": opts["executor"], "workers": opts["workers"], "methods": methods, "skipped_methods": skipped,
        "signals": opts["signals"], "cases_per_setting": len(cases), "git_sha": git_sha(),
        "packages": package_versions(), "checkpoint_sha256": shas,
        "episodes_run": int(len(ran)), "episodes_reused": int(len(df) - len(ran) - len(kept)),
        "episodes_kept_from_earlier_commands": int(len(kept)),
        "wall_time_s": round(wall, 2), "episode_time_sum_s": round(float(ran.sum()), 2),
        "harness_overhead": round(float(wall * min(opts["workers"], max(len(ran), 1)) / ran.sum() - 1), 4)
        if len(ran) else None,
    }
    manifest["scenario"] = {s: c.to_dict() for s, c in evals.items()}  # eval_scenario_hash: their digests
    manifest.update(scenario_overrides=overrides, transfer=transfer, train_scenarios=trained, **failed.manifest())
    if opts.get("bounds"):  # the DP's per-case time, as measured in this run's workers
        manifest["bound_wall_s_median"] = round(float(pd.read_parquet(run_dir / "bounds.parquet").bound_wall_s.median()), 3)
    kept_keys = {policy_key(m, s, sd) for m, s, sd in zip(kept.method, kept.signals, kept.train_seed)}
    atomic_json(carry_forward(manifest, run_dir / "manifest.json", kept_keys), run_dir / "manifest.json")
    return df


def policy_key(method: str, signals: str, seed: int) -> str:
    """A policy's key in the manifest's ``checkpoint_sha256`` (``prl-coordinated/s0``; no seed for a rule)."""
    return f"{method}-{signals}" + (f"/s{int(seed)}" if seed >= 0 else "")


def earlier_rows(run_dir: Path, df: pd.DataFrame, shas: dict[str, str] | None = None) -> pd.DataFrame:
    """Rows of ``results.parquet`` from earlier commands on this run folder that this command did
    not run (other methods, settings or cases) and whose step log is still complete: a rerun with
    fewer methods keeps them instead of shrinking the table. A row of a policy this command ran
    (``shas``, by ``policy_key``) is kept only if its log was written by the same policy file: rows
    of a replaced policy are dropped, never mixed with the new one's."""
    shas = shas or {}
    path = run_dir / "results.parquet"
    if not path.is_file():
        return pd.DataFrame(columns=list(KEEP))
    try:
        old = pd.read_parquet(path)
    except Exception as e:  # pyarrow's errors for a truncated file have no common base
        raise UsageError(f"{path}: not a readable results table ({type(e).__name__}); move it away to start "
                         f"afresh, or use another --run-id") from None
    if set(SCENARIO_COLUMNS) - set(old.columns) and "signals" in old.columns:  # a table from before them
        old = old.assign(eval_scenario_hash=old.signals.map(scenarios.legacy_hash), train_scenario_hash="")
    if not set(KEEP) <= set(old.columns):
        return pd.DataFrame(columns=list(KEEP))
    now = set(zip(df.signals, df.method, df.train_seed, df.case))
    rows = [r for r in old.itertuples(index=False) if (r.signals, r.method, r.train_seed, r.case) not in now]
    keep = [r._asdict() for r in rows if episode_summary(
        resolve_log(run_dir, r.mcap), agent_sha256=shas.get(policy_key(r.method, r.signals, r.train_seed))) is not None]
    return pd.DataFrame(keep, columns=list(KEEP))


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


def _relative(run_dir: Path, mcap: str) -> str:
    p = resolve_log(run_dir, mcap)
    return str(p.relative_to(run_dir)) if p.is_relative_to(run_dir) else str(p)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    opts = parse(argv)
    opts["argv"], opts["failures"] = argv, []
    try:
        if opts["profile"] == "generalisation":
            from bench.harness.generalisation_run import run_family

            df = run_family(opts)
        else:
            df = run(opts)
    except (UsageError, CheckpointError, AgentError, runlock.InUse) as e:
        return fail(parser().prog, str(e))
    except KeyboardInterrupt:
        print("interrupted: finished episodes are kept; rerun the same command to continue", file=sys.stderr)
        return 130
    by = ["variant", "signals", "method"] if "variant" in df.columns else ["signals", "method"]
    if len(df):
        print(df.groupby(by)[["energy", "travel_time", "collisions"]].mean().round(2).to_string())
    table = "generalisation.parquet" if "variant" in df.columns else "results.parquet"
    print(f"results: {opts['logs'] / opts['run_id'] / table}")
    return failures.exit_code(opts["failures"])  # 0, or 2 / 3 after failed episodes


if __name__ == "__main__":
    sys.exit(main())
