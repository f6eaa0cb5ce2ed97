"""Train every learning method on both signal settings for several training seeds, two runs at a
time, resumably; finished seeds are skipped, so seeds accumulate across sessions.

    ecodrive train-all [--seeds 0 1 2 3 4] [--parallel 2] [--methods prl mpdqn dqn ddpg]
    ecodrive train-all --paper --models DIR   # the paper's 1000 episodes and Table 2, for comparison

Each run is ``ecodrive train`` by the (method, setting)'s recipe (``bench.training.recipes``),
with its own log next to its run folder. A (method, setting, seed) is finished when
``models/<method>-<signals>/s<seed>/`` holds a policy from that seed, trained by the recipe (its
episodes and agent config) under today's scenario (see ``stale``); an unfinished one resumes from
its last checkpoint. Started runs go first, then the lowest seeds, so that every method reaches a
seed before any gets the next one.

With ``--executor ray`` every run is a Ray task of one CPU on a node of the cluster at
``--address``: it trains in a temporary folder of that node (its checkpoints and replay buffer
stay there) and sends back its policy, manifest and training metrics as data, which this machine
writes into ``<models>/<method>-<signals>/s<seed>/`` (manifest last) exactly as a local run
writes them. No node needs this machine's disk. A run whose node dies is run again by Ray (at most
twice more) from episode 0, never resumed: its checkpoints were on the lost node. Training is
seeded, so the rerun exports the same policy. A Ray run does not resume a checkpoint that a local
run left under ``$ECODRIVE_RUNS``.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from ecodrive_bench.agents.registry import LEARNING
from ecodrive_bench.bench.args import Parser, fail, int_in
from ecodrive_bench.bench.harness.executors import Files, add_options, check_options, collect, land, run_ray
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError, policy_dir, read_manifest
from ecodrive_bench.bench.training.recipes import RUNS, is_recipe, recipe
from ecodrive_bench.envs.config import SIGNALS


def stale(trained: dict, method: str, signals: str) -> list[str]:
    """Scenario fields in which a policy trained under ``trained`` differs from what today's
    ``bench.training.train`` would train it under (``envs.config.diff``)."""
    from ecodrive_bench.bench import registry
    from ecodrive_bench.bench.cases.setting import deep_merge
    from ecodrive_bench.envs.config import ScenarioConfig, diff

    return diff(trained, ScenarioConfig.from_dict(deep_merge({"signals": signals}, registry.method(method).overrides())).to_dict())


def manifest(folder: Path) -> dict | None:
    """A policy folder's manifest.json, None where there is none; a ``CheckpointError`` naming the
    file where it is not a JSON object or its agent_config or scenario is not an object (it is never
    trained over: that would replace the policy)."""
    if not (folder / "manifest.json").is_file():
        return None
    m = read_manifest(folder)
    for key in ("agent_config", "scenario"):
        if m.get(key) is not None and not isinstance(m[key], dict):
            raise CheckpointError(f"{folder / 'manifest.json'}: {key} is a JSON {type(m[key]).__name__}, "
                                  f"expected an object; restore the file or move the folder away")
    return m


def is_reference_seed(method: str, signals: str, seed: int, episodes: int | None = None, models: Path = MODELS,
                      paper: bool = False) -> bool:
    """A policy in ``models`` from this seed, trained by the recipe (``paper``: the paper's;
    ``episodes`` given: that episode count instead of the recipe's) under today's scenario."""
    m = manifest(policy_dir(method, signals, models, seed))
    if m is None:
        return False
    r = recipe(method, signals, paper)
    return (m.get("seed") == seed and m.get("episodes") == (r.episodes if episodes is None else episodes)
            and is_recipe(method, signals, m.get("agent_config") or {}, paper)
            and not stale(m.get("scenario") or {}, method, signals))


def plan(methods: list[str], seeds: list[int], episodes: int | None = None, runs: Path = RUNS,
         models: Path = MODELS, paper: bool = False) -> list[tuple[str, str, int]]:
    """(method, signals, seed) still to train; runs with a checkpoint (started in an earlier
    session) come first, then by seed, then in the given method order."""
    todo = [(m, s, sd) for sd in seeds for m in methods for s in SIGNALS
            if not is_reference_seed(m, s, sd, episodes, models, paper)]
    return sorted(todo, key=lambda t: not (runs / f"{t[0]}-{t[1]}-s{t[2]}" / "checkpoint.pt").is_file())


@dataclass(frozen=True)
class Run:
    """One (method, setting, seed) training as ``ecodrive train`` runs it for ``train-all``."""

    method: str
    signals: str
    seed: int
    episodes: int
    models: str  # the --models folder as given (the manifest's command names it)
    device: str = "cpu"
    paper: bool = False

    @property
    def name(self) -> str:
        return f"{self.method}/{self.signals}/s{self.seed}"

    def argv(self) -> list[str]:
        """``ecodrive train``'s options for this run: the local subprocess's command line, and
        the command every manifest records, whichever executor ran it."""
        return ["--method", self.method, "--signals", self.signals, "--episodes", str(self.episodes), "--seed",
                str(self.seed), "--models", self.models, "--device", self.device, *(["--paper"] if self.paper else [])]


def remote_run(run: Run) -> Files:
    """On a Ray worker: ``bench.training.train.train`` called as ``ecodrive train`` with
    ``run.argv()`` calls it (the recipe's agent config, the default checkpoints, validation and
    selection), in a temporary folder; the exported policy folder's files returned."""
    from ecodrive_bench.bench.training.train import train

    with tempfile.TemporaryDirectory(prefix=f"ecodrive-{run.method}-{run.signals}-s{run.seed}-") as tmp:
        models = Path(tmp) / "models"
        train(run.method, run.signals, run.episodes, run.seed, Path(tmp) / "run", models=models,
              agent_config=recipe(run.method, run.signals, run.paper).overrides or None,
              command=["ecodrive", "train", *run.argv()], progress=False, device=run.device)
        return Files(run.name, collect(policy_dir(run.method, run.signals, models, run.seed)))


def train_on_ray(runs: list[Run], address: str | None, parallel: int) -> list[str]:
    """Train ``runs`` as Ray tasks, each policy written into ``<models>`` as it arrives; the names
    of the runs that failed."""
    by_name = {r.name: r for r in runs}
    failed: list[str] = []

    def failure(f) -> None:
        failed.append(f.task.name)
        print(f"failed {f.task.name}: {f.reason}", file=sys.stderr, flush=True)

    print(f"submitted {len(runs)} run(s) to Ray: {', '.join(by_name)}", flush=True)
    for done in run_ray(runs, address, parallel, remote_run, on_failure=failure):
        r = by_name[done.value]
        land(done.files, policy_dir(r.method, r.signals, Path(r.models), r.seed), last=("manifest.json",))
        print(f"finished {r.name}", flush=True)
    return failed


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("--episodes", type=int_in(1, 100_000), default=None,
                    help="training episodes per run (1-100000; default: each recipe's)")
    ap.add_argument("--seeds", nargs="+", type=int_in(0), default=[0], help="training seeds, each >= 0 (default: 0)")
    ap.add_argument("--parallel", type=int_in(1), default=2,
                    help="concurrent trainings, one core each (>= 1; with --executor ray and --address, the cluster's CPUs)")
    ap.add_argument("--methods", nargs="+", default=list(LEARNING), choices=list(LEARNING), help="learning methods")
    ap.add_argument("--paper", action="store_true",
                    help="train by the paper's 1000 episodes and Table 2, not the recipes (needs --models DIR where "
                         "a recipe departs from the paper)")
    ap.add_argument("--models", type=Path, default=MODELS,
                    help="folder the policies go to, as <method>-<signals>/s<seed>/ (default: the shipped models/)")
    ap.add_argument("--device", default="cpu",
                    help="where every run's networks train: cpu (default), cuda or cuda:N (--executor ray: cpu)")
    add_options(ap, ray=" (a run killed with its node restarts from episode 0 elsewhere: see above)")
    args = ap.parse_args(argv)
    check_options(ap, args)
    if args.executor == "ray" and args.device != "cpu":  # whatever this machine has: the nodes train
        ap.error(f"--device {args.device} with --executor ray: a Ray run trains on the one CPU its task holds; "
                 f"accepted: --device cpu")
    from ecodrive_bench.agents.device import parse as parse_device  # torch: not for --help

    try:
        parse_device(args.device)
    except ValueError as e:
        ap.error(str(e))
    if args.models.resolve() == MODELS.resolve():
        off = [f"{m}/{s}" for m in args.methods for s in SIGNALS
               if recipe(m, s, args.paper) != recipe(m, s)
               or (args.episodes is not None and args.episodes != recipe(m, s).episodes)]
        if off:
            ap.error(f"{'--paper' if args.paper else f'--episodes {args.episodes}'} trains experiments, not the "
                     f"recipe, for {', '.join(off)}; give --models DIR (they never go to the shipped models/)")
    try:
        todo = plan(args.methods, args.seeds, args.episodes, models=args.models, paper=args.paper)
    except CheckpointError as e:
        return fail(ap.prog, str(e))
    for m, s, sd in todo:
        folder = policy_dir(m, s, args.models, sd)
        found = manifest(folder)  # read without error by plan()
        diff = stale(found.get("scenario") or {}, m, s) if found is not None else []
        if diff:  # a policy from another seed or episode count is not "older"
            print(f"note: {folder} was trained under an older scenario (differs in {', '.join(diff)}); "
                  f"retraining. If {RUNS / f'{m}-{s}-s{sd}'} holds that finished run, move it away "
                  f"first, or it is exported again", flush=True)
    runs = [Run(m, s, sd, recipe(m, s, args.paper).episodes if args.episodes is None else args.episodes,
                str(args.models), args.device, args.paper) for m, s, sd in todo]
    failed = train_on_ray(runs, args.address, args.parallel) if args.executor == "ray" else _train_local(runs, args.parallel)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


def _train_local(runs: list[Run], parallel: int) -> list[str]:
    """Each run an ``ecodrive train`` subprocess, ``parallel`` at a time, its output in
    ``$ECODRIVE_RUNS/<method>-<signals>-s<seed>.log``; the names of the runs that failed."""
    todo = list(runs)
    running: list[tuple[subprocess.Popen, str]] = []
    RUNS.mkdir(parents=True, exist_ok=True)
    failed = []
    while todo or running:
        while todo and len(running) < parallel:
            run = todo.pop(0)
            log = open(RUNS / f"{run.method}-{run.signals}-s{run.seed}.log", "a")
            cmd = [sys.executable, "-m", "ecodrive_bench.bench.training.train_command", *run.argv()]
            running.append((subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT), run.name))
            print(f"started {run.name}", flush=True)
        for p, name in list(running):
            if p.poll() is not None:
                running.remove((p, name))
                print(f"finished {name} (exit {p.returncode})", flush=True)
                if p.returncode:
                    failed.append(name)
        time.sleep(5)
    return failed


if __name__ == "__main__":
    sys.exit(main())
