"""One ``ecodrive run`` on one scenario, in three typed steps (the command: ``bench.harness.run_command``).

- ``preflight``: every check that writes nothing (methods, factories, policies, the scenario each
  may drive, the run folder's scenario) -> ``Preflight``;
- ``plan``: the episodes to run as ``Task``s, and the rows of finished step logs that are reused
  -> ``Plan``;
- ``execute``: the tasks on the local pool or Ray, failed episodes set aside
  (``bench.harness.failures``) -> the new rows;
- ``write``: ``results.parquet`` (with the rows of earlier commands kept, and the bounds) and the
  manifest.

``run`` does the four under the run folder's lock (``bench.runlock``).
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench import registry, runlock
from ecodrive_bench.bench.args import UsageError
from ecodrive_bench.bench.cases.bounds import attach
from ecodrive_bench.bench.cases.case import Case, load
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.harness import failures, scenarios
from ecodrive_bench.bench.harness.executors import Task, episode_limit, run_local, run_ray
from ecodrive_bench.bench.harness.options import METHODS, PROFILES, RunOptions
from ecodrive_bench.bench.harness.pool import PoolBroken
from ecodrive_bench.bench.harness.provenance import carry_forward, git_sha, package_versions, process_age
from ecodrive_bench.bench.harness.run_folder import KEEP, SCENARIO_COLUMNS, case_set_gaps, one_case_set, one_scenario
from ecodrive_bench.bench.harness.scenarios import Evaluation
from ecodrive_bench.bench.harness.steplogs import finished, written_by
from ecodrive_bench.bench.io import Unwritable, atomic_json, atomic_parquet, refuse_links, sha256, writable_dir
from ecodrive_bench.bench.logs.mcaplog import resolve_log
from ecodrive_bench.bench.methods import external
from ecodrive_bench.bench.methods.errors import AgentError
from ecodrive_bench.bench.methods.planners import PLANNERS, identity
from ecodrive_bench.bench.methods.policies import check_policy, family_dir, policy_dir, shipped_seeds
from ecodrive_bench.bench.progress import bar as progress_bar
from ecodrive_bench.envs.config import ScenarioConfig

Run = tuple[str, str, int]  # (method, signals, training seed; -1 for a method without a policy)


@dataclass
class Preflight:
    """What the checks found: the runs, and where each may drive."""

    runs: list[Run]  # every (method, signals, seed) of the command
    skipped: list[str]  # "method/signals" left out for want of a shipped policy
    pdirs: dict[Run, str]  # each run's policy folder ("" without a policy)
    where: dict[Run, Evaluation]  # each run's scenario: evaluated on, trained on
    evals: dict[str, ScenarioConfig]  # the command's scenario of each signal setting
    cases: list[Case]  # the cases of each setting
    codes: dict[str, str] = field(default_factory=dict)  # user agent -> sha256 of its code (or --sb3 zip)


@dataclass
class Plan:
    """The episodes of the command: to run, and reused from finished step logs."""

    tasks: list[Task]
    reused: list[dict[str, Any]]  # result rows read back from complete MCAPs
    shas: dict[str, str] = field(default_factory=dict)  # policy_key -> sha256 of the policy that drives it


def resolve_methods(opts: RunOptions) -> tuple[list[tuple[str, str, int]], list[str]]:
    """((method, signals, training seed) to run, "method/signals" skipped for want of a shipped
    policy). Rule-based methods have the training seed -1.

    Without ``--methods``, a learning method runs in each setting it has a policy for, every
    shipped seed (or those of ``--train-seeds``); named in ``--methods``, a missing policy is an
    error. ``--planners`` adds the planners to either."""
    explicit = opts.methods is not None
    wanted = opts.train_seeds
    runs, skipped = [], []
    factories = opts.factories
    default = [*METHODS, *PLANNERS] if opts.profile in registry.FAMILY_PROFILES else METHODS
    named = [m for m in (opts.methods if explicit else default) if m not in factories]
    if opts.planners:
        named += [p for p in PLANNERS if p not in named]
    for m in [*named, *factories]:
        for s in opts.signals:
            if m not in registry.names("learned"):
                runs.append((m, s, -1))
                continue
            have = shipped_seeds(m, s, opts.models)
            seeds = [sd for sd in have if wanted is None or sd in wanted]
            if not seeds:
                if explicit:
                    raise UsageError(f"no trained policy for {m} / {s}"
                                     f"{'' if wanted is None else ' with training seed ' + ' or '.join(map(str, wanted))}"
                                     f" (expected {family_dir(m, s, opts.models)}/s<seed>/; "
                                     f"{'seeds there: ' + ' '.join(map(str, have)) if have else 'none there'}); "
                                     f"train it: ecodrive train --method {m} --signals {s}")
                skipped.append(f"{m}/{s}")
            runs.extend((m, s, sd) for sd in seeds)
    return runs, skipped


def check_policies(pdirs: dict[tuple[str, str, int], str], checked: set[str] | None = None) -> None:
    """Load every policy of the command into its agent once, here in the parent: a file that
    cannot drive is a ``CheckpointError`` before the run folder is made or any episode starts
    (``bench.methods.policies.check_policy``). Folders in ``checked`` are skipped and added to it."""
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


def preflight(opts: RunOptions, checked: set[str] | None = None) -> Preflight:
    """Every check of a run that writes nothing but the scenario cache: methods, factories, policies
    (``checked``: policy folders already loaded by an earlier call), the scenario each may drive
    (built, or checked in the cache), the run folder's scenario and the case list. Raises
    ``UsageError``, ``CheckpointError``, ``AgentError`` or ``InputError`` (a bad case list, a
    scenario cache entry that cannot be rebuilt)."""
    runs, skipped = resolve_methods(opts)
    if opts.scenario.get("network") is not None:
        if opts.bounds or any(m in PLANNERS for m, _, _ in runs):  # a signal that is not fixed-time: the planners cannot know it
            from ecodrive_bench.bench.oracle.corridor import Corridor, PlanError

            try:
                Corridor.from_config(setting(opts.signals[0], opts.scenario))
            except PlanError as e:
                named = sorted({m for m, _, _ in runs if m in PLANNERS} | ({"--bounds"} if opts.bounds else set()))
                raise UsageError(f"{', '.join(named)}: {e}") from None
    codes = {}
    for label, spec in opts.factories.items():  # a factory that cannot build its agent fails before any episode
        try:
            env, agent = external.make(spec, opts.signals[0], opts.scenario or None)
            env.close()
        except AgentError as e:
            raise UsageError(str(e)) from None
        codes[label] = external.code_sha256(spec, agent)
    evals = {s: setting(s, opts.scenario) for s in opts.signals}
    pdirs = {(m, s, sd): str(policy_dir(m, s, opts.models, sd)) if sd >= 0 else "" for m, s, sd in runs}
    # a policy that may not (or cannot) drive the scenario is refused before anything is written
    where = {r: scenarios.evaluation(r[0], r[1], pdirs[r], opts.scenario, opts.transfer) for r in runs}
    check_policies(pdirs, checked)
    for r in runs:  # a damaged scenario cache entry is rebuilt (or named) before any episode
        scenarios.check_cached(r[0], r[1], where[r])
    one_scenario(opts.run_dir, {s: c.digest() for s, c in evals.items()})
    cases = opts.cases or load()[: PROFILES[opts.profile]]  # a variant's own (generalisation)
    one_case_set(opts.run_dir, runs, {c.index for c in cases})
    return Preflight(runs, skipped, pdirs, where, evals, cases, codes)


def run(opts: RunOptions, progress: bool = True, checks: Preflight | None = None) -> pd.DataFrame:
    """Run (or reuse) every episode of the command and write ``results.parquet`` and the manifest;
    ``checks``: this command's ``preflight``, when the caller ran it already. The run folder is
    locked meanwhile; failed episodes are appended to ``opts.failures``."""
    begin = time.perf_counter() - _startup()
    pre = preflight(opts) if checks is None else checks
    check_writable(opts.run_dir)
    with runlock.hold(opts.run_dir):
        if pre.skipped:  # after the checks: a refused command prints its one error line only
            print(f"note: no shipped policy for {', '.join(pre.skipped)}; running the rest", file=sys.stderr)
        todo = plan(opts, pre)
        t0 = time.perf_counter()
        rows, failed = execute(opts, todo, progress)
        return write(opts, pre, todo, rows, failed, time.perf_counter() - t0, progress, before=t0 - begin, begin=begin)


_STARTED: list[float] = []  # this process's start-up, charged once: to the first run of the process


def _startup() -> float:
    """[s] from this process's start to now on its first call (the interpreter, the imports and
    the command line before the first run), 0 on later calls (a family's next variant)."""
    if _STARTED:
        return 0.0
    _STARTED.append(process_age() or 0.0)
    return _STARTED[0]


def plan(opts: RunOptions, pre: Preflight) -> Plan:
    """The episodes to run, and the rows of the complete step logs of this command's runs (a log
    of another policy or scenario is not reused: its episode runs again)."""
    todo = Plan([], [])
    for signals in opts.signals:
        limit = opts.episode_limit or episode_limit(pre.evals[signals])
        for method, seed in [(m, sd) for m, s, sd in pre.runs if s == signals]:
            pdir, ev = pre.pdirs[(method, signals, seed)], pre.where[(method, signals, seed)]
            sha = (sha256(Path(pdir) / "policy.pt") if pdir
                   else pre.codes.get(method) or opts.agent_sha256.get(method, "") or identity(method))
            if sha:
                todo.shas[policy_key(method, signals, seed)] = sha
            folder = opts.run_dir / signals / method / (f"s{seed}" if seed >= 0 else "")
            changed = 0
            for case in pre.cases:
                path = folder / f"case-{case.index:03d}.mcap"
                done = finished(path, agent_sha256=sha, eval_scenario=ev.eval_hash,
                                legacy_scenario=scenarios.legacy_hash(signals))
                if done is None and method in opts.factories and written_by(path) not in (None, sha):
                    changed += 1
                if done is not None:
                    todo.reused.append({**done, "mcap": str(path), "episode_wall_s": float("nan"), "train_seed": seed})
                else:
                    todo.tasks.append(Task(method, signals, case, str(path), pdir, seed, opts.factories.get(method, ""),
                                           scenario=ev.scenario, transfer=opts.transfer, meta=ev.meta(opts.transfer),
                                           limit_s=limit))
            if changed:
                print(f"note: agent {method!r} ({opts.factories[method]}) is not the one that wrote {changed} of its "
                      f"step logs in {folder} (its code's sha256 differs): those episodes run again, and its earlier "
                      "rows are replaced", file=sys.stderr)
    return todo


def execute(opts: RunOptions, todo: Plan, progress: bool = True) -> tuple[list[dict[str, Any]], failures.Failures]:
    """Run the plan's tasks: the rows of the episodes that finished, and the failed ones (each
    reported in one line and recorded in ``opts.failures``, ``bench.harness.failures``)."""
    failed = failures.Failures(opts.run_dir, todo.tasks, opts.failures)
    it = (run_local(todo.tasks, opts.workers, on_failure=failed, skip=failed.skip) if opts.executor == "local"
          else run_ray(todo.tasks, opts.address, opts.workers, on_failure=failed, skip=failed.skip))
    rows = []
    with progress_bar(total=len(todo.reused) + len(todo.tasks), initial=len(todo.reused), desc="episodes",
                      unit="ep", enabled=progress) as bar:
        try:
            for row in it:
                rows.append(row)
                bar.update(1)
        except PoolBroken as e:  # one line and a record; the finished rows are written
            failed.broken(e)
    return rows, failed


def write(opts: RunOptions, pre: Preflight, todo: Plan, rows: list[dict[str, Any]], failed: failures.Failures,
          wall: float, progress: bool = True, before: float = 0.0, begin: float | None = None) -> pd.DataFrame:
    """``results.parquet`` (this command's rows, the earlier commands' kept rows, the bounds) and
    ``manifest.json``, each replaced atomically; returns the table. ``wall``: the episodes' phase
    [s]; ``before``: what preceded it (start-up, checks, plan); ``begin``: the ``perf_counter``
    reading the command's wall time counts from."""
    run_dir = opts.run_dir
    df = pd.DataFrame(todo.reused + rows).rename(columns={"return_": "return", "case_index": "case", "sumo_seed": "seed"})
    df = df if len(df) else pd.DataFrame(columns=[*KEEP, "episode_wall_s"])  # every episode failed
    for i, col in enumerate(SCENARIO_COLUMNS):
        df[col] = [(ev.eval_hash, ev.train_hash)[i] for ev in map(pre.where.get, zip(df.method, df.signals, df.train_seed))]
    ran = df["episode_wall_s"].dropna()
    if "sumo_s" not in df.columns:  # every row reused from a finished log
        df["sumo_s"] = float("nan")
    sumo_s = float(df["sumo_s"].sum())  # [s] inside SUMO for the episodes run now: the floor
    kept = earlier_rows(run_dir, df, todo.shas)
    cols = [*KEEP, "sumo_s"]  # sumo_s: NaN for rows reused or kept from earlier commands
    df = pd.concat([df[cols], kept], ignore_index=True) if len(kept) else df[cols]
    df = df.sort_values(["signals", "method", "train_seed", "case"], ignore_index=True)
    # a replaced policy's rows dropped on cases this command did not run, say (not its own failed or
    # skipped episodes: those are reported on their own and rerun by the same command)
    planned = pd.DataFrame([(t.signals, t.method, t.train_seed, t.case.index) for t in todo.tasks],
                           columns=["signals", "method", "train_seed", "case"])
    gaps = case_set_gaps(pd.concat([df[["signals", "method", "train_seed", "case"]], planned], ignore_index=True))
    for gap in gaps:
        print(f"warning: {run_dir}: {gap}; the report warns of it too", file=sys.stderr)
    df["mcap"] = [_relative(run_dir, m) for m in df.mcap]  # the run folder moves as a whole
    t_bounds = time.perf_counter()
    if opts.bounds:
        def runner(tasks, workers, fn):
            return (run_local(tasks, workers, fn) if opts.executor == "local"
                    else run_ray(tasks, opts.address, workers, fn))
        df = attach(run_dir, df, opts.workers, runner, opts.scenario, progress)
    bounds_s = time.perf_counter() - t_bounds
    atomic_parquet(df, run_dir / "results.parquet")
    manifest = {
        "command": " ".join(["ecodrive", "run", *opts.argv]), "profile": opts.profile,
        "executor": opts.executor, "workers": opts.workers, "methods": list(dict.fromkeys(m for m, _, _ in pre.runs)),
        "skipped_methods": pre.skipped, "signals": opts.signals, "cases_per_setting": len(pre.cases),
        "git_sha": git_sha(), "packages": package_versions(), "checkpoint_sha256": todo.shas,
        "episodes_run": int(len(ran)), "episodes_reused": int(len(df) - len(ran) - len(kept)),
        "episodes_kept_from_earlier_commands": int(len(kept)),
        "wall_time_s": round(wall + bounds_s, 2), "episode_time_sum_s": round(float(ran.sum()), 2),
        "phases_s": {"before": round(before, 2), "episodes": round(wall, 2), "bounds": round(bounds_s, 2)},
        "sumo_time_s": round(sumo_s, 2),  # the floor: SUMO's own time for the episodes run now
        # wall time x workers over SUMO's time: 1 would be SUMO alone on every worker all along
        "floor_ratio": round((wall + bounds_s) * min(opts.workers, max(len(ran), 1)) / sumo_s, 3) if sumo_s > 0 else None,
        "harness_overhead": round(float(wall * min(opts.workers, max(len(ran), 1)) / ran.sum() - 1), 4)
        if len(ran) else None,
    }
    if gaps:
        manifest["mixed_case_sets"] = gaps
    manifest["scenario"] = {s: c.to_dict() for s, c in pre.evals.items()}  # eval_scenario_hash: their digests
    trained = {ev.train_hash: ev.train for ev in pre.where.values() if ev.train_hash}
    manifest.update(scenario_overrides=opts.scenario, transfer=opts.transfer, train_scenarios=trained,
                    **failed.manifest())
    if opts.bounds:  # the DP's per-case time, as measured in this run's workers
        solved = pd.read_parquet(run_dir / "bounds.parquet")
        solved = solved[solved.bound_source != "shipped"] if "bound_source" in solved else solved
        manifest["bound_wall_s_median"] = round(float(solved.bound_wall_s.median()), 3) if len(solved) else None
    kept_keys = {policy_key(m, s, sd) for m, s, sd in zip(kept.method, kept.signals, kept.train_seed)}
    if begin is not None:  # the whole command: start-up, checks, episodes, bounds, the tables written
        manifest["command_wall_s"] = round(time.perf_counter() - begin, 2)
        manifest["phases_s"]["after"] = round(manifest["command_wall_s"] - before - wall - bounds_s, 2)
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
    old = old.loc[np.array([k not in now for k in zip(old.signals, old.method, old.train_seed, old.case)], dtype=bool)]
    complete = [finished(resolve_log(run_dir, mcap), agent_sha256=shas.get(policy_key(m, s, sd))) is not None
                for mcap, m, s, sd in zip(old.mcap, old.method, old.signals, old.train_seed)]
    return old.loc[np.array(complete, dtype=bool), list(KEEP)].reset_index(drop=True)  # by name: "return" is no identifier


def _relative(run_dir: Path, mcap: str) -> str:
    p = resolve_log(run_dir, mcap)
    return str(p.relative_to(run_dir)) if p.is_relative_to(run_dir) else str(p)
