"""Training sweeps of section 5.2: the reward study and the r_p^s x r_p^j sensitivity heatmap.

    ecodrive sweep reward  [--forms r1 r2 r] [--phi 0.5 1 2] [--seeds 0 1 2]
    ecodrive sweep heatmap [--values 10 20 30 40 50] [--seeds 0]
        common: [--signals uncoordinated] [--episodes N] [--paper] [--cases 100]
                [--executor local|ray] [--address A] [--workers 2] [--run-id paper] [--logs logs]
                [--store results/sweeps]

A job trains PRL with one reward configuration by PRL's recipe for ``--signals``
(``bench.training.recipes``: its episodes and its departures from Table 2, as the shipped PRL seeds
were trained; ``--paper``: the paper's 1000 episodes and Table 2), through ``bench.training.train``
(so it resumes from its own checkpoints under ``$ECODRIVE_RUNS/sweeps/<study>/``); a job that is a
shipped seed's training takes that policy instead (``shipped_training``). A trained job copies its
``/train`` log into ``<logs>/<run-id>/<study>/<name>/train.mcap``; every job then runs the exported
(validation-selected) policy greedily on the first ``--cases`` fixed test cases, one MCAP per case next to it, and writes
``job.json`` there last. A rerun skips what is finished; a finished folder made with other values
(episodes, cases, reward, ...) is refused, never overwritten. ``sweep.parquet`` (one row per
finished job of the study folder, whatever command ran it) and ``episodes.parquet`` (one row per
test episode) collect the results after every job; ``ecodrive report`` draws them.

Every finished job's small results (its summary row, evaluation rows, training metrics and policy
manifest; ``bench.experiments.store``) are also saved under ``--store``, which the repository keeps
in git: a job found there is restored into the run folder instead of trained, so a sweep far longer
than one session accumulates job by job, on any machine.

With ``--executor ray`` every job is a Ray task of one CPU on a node of the cluster at
``--address`` (``bench.experiments.sweep_ray``). It trains and evaluates in a temporary folder of
that node and sends its log folder back as data (``job.json``, ``episodes.parquet``,
``metrics.parquet``, the policy manifest, ``train.mcap``, the case MCAPs); this machine writes them
into ``<logs>`` and ``--store`` as a local job does. No node needs this machine's disk. A job whose
node dies is run again by Ray (at most twice more) from episode 0, in a fresh folder, never
resumed: its checkpoints were on the lost node. Training is seeded, so the rerun gives the same
results. A Ray job does not resume a checkpoint that a local sweep left under ``$ECODRIVE_RUNS``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from ecodrive_bench.bench.args import Parser, fail, float_in, int_in, name, prog_name
from ecodrive_bench.bench.experiments import store
from ecodrive_bench.bench.harness.executors import add_options, check_options, run_local
from ecodrive_bench.bench.io import Unwritable, atomic_json, atomic_parquet, writable_dir
from ecodrive_bench.bench.logs.mcaplog import episode_summary
from ecodrive_bench.bench.methods.policies import CheckpointError
from ecodrive_bench.bench.progress import bar
from ecodrive_bench.bench.training.recipes import VALIDATION_CASES, recipe
from ecodrive_bench.envs.config import REWARDS, SIGNALS, ConfigError, RewardConfig, ScenarioConfig, accepted_range

STUDIES = ("reward", "heatmap")
PHIS = (0.5, 1.0, 2.0)  # section 5.2 varies phi; our set
HEATMAP_VALUES = (10.0, 20.0, 30.0, 40.0, 50.0)  # |r_p^s| and |r_p^j|; r_p^c fixed at 50
HEATMAP_LANE_CHANGE = 50.0


@dataclass(frozen=True)
class Job:
    study: str
    name: str  # configuration label, e.g. "r-phi1" or "s40-j30"
    signals: str
    seed: int
    episodes: int
    cases: int  # first N fixed test cases for the greedy evaluation
    run_dir: str  # training folder (checkpoints, replay)
    log_dir: str  # <logs>/<run-id>/<study>/<name>-s<seed>
    reward: dict[str, Any] = field(default_factory=dict)
    agent_config: dict[str, Any] = field(default_factory=dict)  # PRL config fields departing from Table 2 (the recipe's)
    validation_cases: int = VALIDATION_CASES
    max_episode_time: float | None = None  # [s] episode truncation; None = the scenario default

    @property
    def label(self) -> str:
        return f"{self.name}-s{self.seed}"


def run_job(job: Job, work: Path | None = None) -> dict[str, Any]:
    """Train (or resume), copy the training log, evaluate greedily on the test cases. ``work``
    given, the job writes only there (``work/run``: its run folder; ``work/log``: its log folder)
    while its rows name its own log folder, where the driver lands them (``sweep_ray``)."""
    import torch

    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.cases.case import load
    from ecodrive_bench.bench.harness.episode import run_episode
    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.methods.policies import acting_config, load_policy, policy_dir
    from ecodrive_bench.bench.training.train import train

    torch.set_num_threads(1)
    named = Path(job.log_dir)
    run_dir, log_dir = (Path(job.run_dir), named) if work is None else (work / "run", work / "log")
    scenario: dict[str, Any] = {"reward": job.reward}
    if job.max_episode_time is not None:
        scenario["max_episode_time"] = job.max_episode_time
    env = make_env("prl", job.signals, scenario)
    models = run_dir / "export"
    folder = policy_dir("prl", job.signals, models, job.seed)
    t0 = time.perf_counter()
    # a job that is a shipped reference seed's training takes its policy (not when a training of this
    # job has started here: its run folder is its own)
    shipped = None if (run_dir / "checkpoint.pt").is_file() else shipped_training(job, env.cfg.to_dict())
    if shipped is not None and not (folder / "manifest.json").is_file():
        folder.mkdir(parents=True, exist_ok=True)
        for src, dst in ((shipped / "policy.pt", folder / "policy.pt"),
                         (shipped / "metrics.parquet", folder / "metrics.parquet"),
                         (shipped / "metrics.parquet", run_dir / "metrics.parquet"),
                         (shipped / "manifest.json", folder / "manifest.json")):  # the manifest last: present = copied
            tmp = dst.with_name(f".{dst.name}.part")
            shutil.copyfile(src, tmp)
            os.replace(tmp, dst)
    if shipped is not None:  # the export is the shipped policy only if it has its hash (a resumed job)
        same = json.loads((folder / "manifest.json").read_text()).get("sha256")
        shipped = shipped if same == json.loads((shipped / "manifest.json").read_text()).get("sha256") else None
    if not (folder / "manifest.json").is_file():
        # epsilon decays over the job's own episodes (eq. 12 with N = the training length)
        train("prl", job.signals, job.episodes, job.seed, run_dir, models=models, scenario=scenario, progress=False,
              agent_config={"eps_decay_episodes": job.episodes, **job.agent_config}, validation_cases=job.validation_cases,
              command=["ecodrive", "sweep", job.study, f"# job {job.label}"])
    log_dir.mkdir(parents=True, exist_ok=True)
    for fname in ("train.mcap", "metrics.parquet"):
        if (run_dir / fname).is_file():  # a shipped seed's training log is not kept, its metrics are
            shutil.copyfile(run_dir / fname, log_dir / fname)
    shutil.copyfile(folder / "manifest.json", log_dir / store.POLICY_MANIFEST)
    state, manifest = load_policy(folder, "prl", env.cfg.to_dict())
    agent = make_agent("prl", env.observation_space, env.action_space, **acting_config(manifest.get("agent_config") or {}))
    agent.load_state_dict(state)
    rows = []
    for case in load()[: job.cases]:
        path = log_dir / f"case-{case.index:03d}.mcap"
        row = episode_summary(path, agent_sha256=manifest["sha256"])  # a log of an earlier policy is rerun
        if row is None:
            row = run_episode(env, agent, case, "prl", log_path=path, agent_sha256=manifest["sha256"])
        rows.append({**row, "config": job.name, "seed": job.seed, "case": case.index, "mcap": str(named / path.name)})
    env.close()
    ep = pd.DataFrame(rows)
    atomic_parquet(ep, log_dir / "episodes.parquet")
    row = {"study": job.study, "config": job.name, "seed": job.seed, "signals": job.signals,
           **{f"reward_{k}": v for k, v in job.reward.items()},
           **{f"agent_{k}": v for k, v in job.agent_config.items()}, "episodes": job.episodes,
           "selected_episode": manifest.get("selected_episode"), "cases": len(ep),
           "energy": ep.energy.mean(), "travel_time": ep.travel_time.mean(),
           "finished": float(ep.terminated.mean()),  # share of test trips that reached the corridor's end
           "collisions": int(ep.collisions.sum()), "lane_changes": ep.lane_changes_applied.mean(),
           "policy_from": "" if shipped is None else f"models/{shipped.parent.name}/{shipped.name}",
           "job_wall_s": time.perf_counter() - t0, "log_dir": str(named)}
    atomic_json({"job": _identity(job), "row": row}, log_dir / "job.json", default=float)  # last: present = finished
    return row


def shipped_training(job: Job, scenario: dict[str, Any], models: Path | None = None) -> Path | None:
    """The shipped PRL policy folder that is this job's training, or None: a shipped reference seed
    (``train_all.is_reference_seed``: by the recipe, under today's scenario) of the job's seed and
    episodes, when the job trains by the recipe on that scenario (``scenario``: the job's) with the
    same validation cases (the reward study's r, phi = 1 cell; the heatmap's (40, 30)). Such a
    job takes the shipped policy and its training metrics instead of training it again."""
    from ecodrive_bench.bench.methods.policies import MODELS, policy_dir
    from ecodrive_bench.bench.training.train_all import is_reference_seed
    from ecodrive_bench.envs.config import diff

    models = MODELS if models is None else models
    if (job.agent_config != recipe("prl", job.signals).overrides
            or not is_reference_seed("prl", job.signals, job.seed, job.episodes, models)):
        return None
    folder = policy_dir("prl", job.signals, models, job.seed)
    m = json.loads((folder / "manifest.json").read_text())
    same = (m.get("selection") == "objective" and m.get("validation", {}).get("cases") == job.validation_cases
            and not diff(m.get("scenario", {}), scenario))
    return folder if same and all((folder / f).is_file() for f in ("policy.pt", "metrics.parquet")) else None


def _identity(job: Job) -> dict[str, Any]:
    """What makes a job's results: a finished log folder made with other values is not reused. The
    agent config is listed only where it departs from Table 2 (a ``--paper`` job has none)."""
    identity = {"signals": job.signals, "seed": job.seed, "episodes": job.episodes, "cases": job.cases,
                "reward": job.reward, "validation_cases": job.validation_cases, "max_episode_time": job.max_episode_time}
    if job.agent_config:
        identity["agent_config"] = job.agent_config
    return identity


def finished(root: Path) -> dict[str, dict[str, Any]]:
    """Rows of every finished job under a study folder (whatever command made them), by log folder."""
    rows = {}
    for path in sorted(root.glob("*/job.json")):
        try:
            rows[str(path.parent)] = json.loads(path.read_text())["row"]
        except (OSError, ValueError, KeyError):
            continue
    return rows


def is_finished(job: Job) -> bool:
    """Whether the job's log folder holds this job, finished; ConfigError if it holds a finished
    job made with other values."""
    path = Path(job.log_dir) / "job.json"
    if not path.is_file():
        return False
    try:
        stored = json.loads(path.read_text())["job"]
    except (OSError, ValueError, KeyError):
        return False  # unreadable: the job reruns and rewrites it
    want = json.loads(json.dumps(_identity(job), default=float))
    diff = [f"{k} {stored.get(k)!r} (asked {want.get(k)!r})" for k in sorted(want.keys() | stored.keys())
            if stored.get(k) != want.get(k)]  # both ways: a key only one side has (agent_config) differs too
    if diff:
        raise ConfigError(f"{job.log_dir}: finished with {', '.join(diff)}; use another --run-id, or move the "
                          f"folder away to rerun it")
    return True


def write_tables(root: Path, rows: dict[str, dict[str, Any]]) -> pd.DataFrame:
    """``sweep.parquet`` and ``episodes.parquet`` of the study folder, replaced atomically; a
    ConfigError naming a finished job's ``episodes.parquet`` that cannot be read."""
    episodes = {d: store.read_parquet(Path(d) / "episodes.parquet") for d in rows if (Path(d) / "episodes.parquet").is_file()}
    # a job finished before rows recorded ``finished``: its share of trips that reached the end, from its episodes
    df = pd.DataFrame([{**row, "finished": float(episodes[d].terminated.mean())}
                       if "finished" not in row and d in episodes else row for d, row in rows.items()], index=list(rows))
    if not df.empty:
        df = df.sort_values(["config", "seed"])
    order = list(df.index)  # both tables by configuration and seed, whatever order the jobs finished in
    df = df.reset_index(drop=True)
    atomic_parquet(df, root / "sweep.parquet")
    if episodes:
        atomic_parquet(pd.concat([episodes[d] for d in order if d in episodes], ignore_index=True), root / "episodes.parquet")
    return df



def _store(root: Path, job: Job) -> None:
    try:
        store.save(root, job.study, job.label, _identity(job), Path(job.log_dir))
    except (OSError, ConfigError) as e:  # the results stay in the log folder; the next sweep stores them
        print(f"warning: could not store {job.label} under {root}: {e}", file=sys.stderr)


def coarse_to_fine(values: list[float]) -> list[float]:
    """The distinct values, ends first, then by bisection: 10 20 30 40 50 -> 10 50 30 20 40."""
    vals = sorted(set(values))
    out: list[int] = []
    spans = [(0, len(vals) - 1)]
    while spans:
        lo, hi = spans.pop(0)
        for i in (lo, hi, (lo + hi) // 2):
            if i not in out:
                out.append(i)
        if hi - lo > 1:
            mid = (lo + hi) // 2
            spans += [(lo, mid), (mid, hi)]
    return [vals[i] for i in out]


def coarse_to_fine_cells(values: list[float]) -> list[tuple[float, float]]:
    """The heatmap's (|r_p^s|, |r_p^j|) cells in an order whose every prefix of k^2 cells is a complete
    k x k block over the first k values of ``coarse_to_fine``: a study cut short still has a
    crossed grid over the widest range (what its claims are judged on), not one row of it."""
    seq = coarse_to_fine(values)
    cells = []
    for k, v in enumerate(seq):
        cells += [(v, w) for w in seq[:k]] + [(w, v) for w in seq[:k]] + [(v, v)]
    return cells


def order(todo: list[Job]) -> list[Job]:
    """Started jobs first (their checkpoints resume), the rest as ``jobs`` lists them (seed by seed)."""
    return sorted(todo, key=lambda j: not (Path(j.run_dir) / "checkpoint.pt").is_file())


def jobs(study: str, args: argparse.Namespace) -> list[Job]:
    """The job list of a study; every reward configuration is validated before anything runs."""
    from ecodrive_bench.bench.training.train import RUNS

    rec = recipe("prl", args.signals, paper=args.paper)
    episodes = rec.episodes if args.episodes is None else args.episodes
    agent_config = dict(rec.overrides)
    # what else makes a training differs from the defaults: its own run folder (checkpoints and export differ)
    tag = "".join(f"-{k}{v}" for k, v in sorted(agent_config.items()))
    tag += "" if args.validation_cases == VALIDATION_CASES else f"-val{args.validation_cases}"
    tag += "" if args.max_episode_time is None else f"-t{args.max_episode_time:g}"

    if study == "reward":
        configs = [(f"{form}-phi{phi:g}", {"form": form, "phi": phi}) for form in args.forms for phi in args.phi]
    else:
        configs = [(f"s{s:g}-j{j:g}", {"speed_penalty": s, "jerk_penalty": j, "lane_change_penalty": HEATMAP_LANE_CHANGE})
                   for s, j in coarse_to_fine_cells(args.values)]
    for _, reward in configs:
        RewardConfig(**reward)  # raises ConfigError naming the value and its range
    if args.max_episode_time is not None:
        ScenarioConfig(max_episode_time=args.max_episode_time)
    root = Path(args.logs) / args.run_id / study
    return [Job(study, name, args.signals, seed, episodes, args.cases,
                str(RUNS / "sweeps" / study / f"{args.signals}-{name}-s{seed}-e{episodes}{tag}"),
                str(root / f"{name}-s{seed}"), reward, agent_config, args.validation_cases, args.max_episode_time)
            for seed in args.seeds for name, reward in configs]  # every configuration gets seed 0 before any gets seed 1


def parse(argv: list[str] | None) -> argparse.Namespace:
    ap = Parser(description=__doc__)
    ap.add_argument("study", help=f"one of {', '.join(STUDIES)}")
    ap.add_argument("--signals", default="uncoordinated", help=f"one of {', '.join(SIGNALS)}")
    ap.add_argument("--forms", nargs="+", default=list(REWARDS), help=f"reward study: forms among {', '.join(REWARDS)}")
    ap.add_argument("--phi", nargs="+", type=float_in(*accepted_range(RewardConfig, "phi")), default=list(PHIS),
                    help="reward study: phi values [Wh/s], each in [{}, {}]".format(*accepted_range(RewardConfig, "phi")))
    ap.add_argument("--values", nargs="+", type=float_in(*accepted_range(RewardConfig, "speed_penalty")),
                    default=list(HEATMAP_VALUES),
                    help="heatmap: |r_p^s| = |r_p^j| grid, each in [{}, {}]".format(*accepted_range(RewardConfig, "speed_penalty")))
    ap.add_argument("--seeds", nargs="+", type=int_in(0), default=None, help="training seeds (reward: 0 1 2; heatmap: 0)")
    ap.add_argument("--episodes", type=int_in(1, 100_000), default=None,
                    help="training episodes per job (1-100000; default: PRL's recipe's, or 1000 with --paper)")
    ap.add_argument("--paper", action="store_true",
                    help="train by the paper's Table 2 and 1000 episodes instead of PRL's recipe")
    ap.add_argument("--cases", type=int_in(1, 100), default=100, help="fixed test cases evaluated per job (1-100)")
    ap.add_argument("--validation-cases", type=int_in(1, 100), default=VALIDATION_CASES, help="validation cases per training checkpoint (1-100)")
    ap.add_argument("--max-episode-time", type=float_in(*accepted_range(ScenarioConfig, "max_episode_time")),
                    default=None, help="episode truncation [s] (default: the scenario's)")
    add_options(ap, ray=" (a job killed with its node restarts from episode 0 elsewhere: see above)")
    ap.add_argument("--workers", type=int_in(1), default=2,
                    help="parallel jobs (>= 1; with --executor ray and --address, the cluster's CPUs)")
    ap.add_argument("--run-id", type=name, default="paper", help="run folder under --logs")
    ap.add_argument("--logs", type=Path, default=Path("logs"), help="log root (default: logs)")
    ap.add_argument("--store", type=Path, default=store.STORE,
                    help="finished jobs' small results, kept in git: found ones are restored, not trained; "
                         "new ones are added (default: the repository's results/sweeps)")
    args = ap.parse_args(argv)
    for flag, value, accepted in (("study", args.study, STUDIES), ("--signals", args.signals, SIGNALS)):
        if value not in accepted:
            ap.error(f"{flag} {value!r} is not accepted; choose one of {', '.join(accepted)}")
    check_options(ap, args)
    if args.seeds is None:
        args.seeds = [0, 1, 2] if args.study == "reward" else [0]
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        todo = jobs(args.study, args)
    except ConfigError as e:
        return fail(prog_name(), str(e))
    try:
        writable_dir(args.store)  # before any training: a job's results go there when it finishes
    except Unwritable as e:
        return fail(prog_name(), f"--store: {e}")
    root = Path(args.logs) / args.run_id / args.study
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        return fail(prog_name(), f"cannot write {root}: {e.strerror}")
    try:
        return _sweep(args, todo, root)
    except (ConfigError, CheckpointError) as e:  # a stored job, a finished table or a run's checkpoint
        return fail(prog_name(), str(e))


def _sweep(args: argparse.Namespace, todo: list[Job], root: Path) -> int:
    """Restore, run and tabulate the jobs; a ConfigError or CheckpointError names the bad file."""
    done = [job for job in todo if is_finished(job)]
    todo = [job for job in todo if job not in done]
    restored = [job for job in todo if store.restore(args.store, job.study, job.label, _identity(job),
                                                     Path(job.log_dir))]
    if restored:
        print(f"{len(restored)} finished job(s) restored from {args.store / args.study}, not trained: "
              f"{', '.join(j.label for j in restored)}", flush=True)
        todo = [job for job in todo if job not in restored]
    for job in done:  # finished in the log folder (this session, or a sweep stopped before storing it)
        _store(args.store, job)
    todo = order(todo)
    by_dir = {job.log_dir: job for job in todo}
    rows = finished(root)  # every finished job of the study, not only this command's
    write_tables(root, rows)
    if args.executor == "local":
        it = run_local(todo, args.workers, run_job)
    else:
        from ecodrive_bench.bench.experiments.sweep_ray import run_jobs

        it = run_jobs(todo, args.address, args.workers, run_job)
    for row in bar(it, total=len(todo), desc=f"{args.study} jobs", unit="job"):
        rows.update(finished(root))  # and what a sweep running beside this one finished meanwhile
        rows[row["log_dir"]] = row
        _store(args.store, by_dir[row["log_dir"]])
        write_tables(root, rows)  # a killed sweep leaves the tables of its finished jobs
    rows.update(finished(root))
    df = write_tables(root, rows)
    print(df[["config", "seed", "selected_episode", "energy", "travel_time", "collisions"]].round(2).to_string(index=False))
    print(f"results: {root / 'sweep.parquet'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
