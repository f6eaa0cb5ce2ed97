"""Train every learning method on both signal settings, two at a time, resumably.

    ecodrive train-all [--episodes 1000] [--seed 0] [--parallel 2] [--methods prl mpdqn dqn ddpg]

Each run is ``ecodrive train`` with its own log next to its run folder; finished runs
(a policy already in models/ from the same seed and episode count, trained under today's
scenario: see ``stale``) are skipped, unfinished ones resume from their last checkpoint.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from agents.registry import LEARNING
from bench.args import Parser
from bench.harness.policies import MODELS, policy_dir
from bench.training.train import RUNS
from envs.config import SIGNALS


def stale(trained: dict, method: str, signals: str) -> list[str]:
    """Scenario fields in which a policy trained under ``trained`` differs from what today's
    ``bench.training.train`` would train it under (``envs.config.diff``)."""
    from agents.registry import ENV_OVERRIDES
    from bench.harness.episode import deep_merge
    from envs.config import ScenarioConfig, diff

    return diff(trained, ScenarioConfig.from_dict(deep_merge({"signals": signals}, ENV_OVERRIDES.get(method, {}))).to_dict())


def _finished(method: str, signals: str, seed: int, episodes: int, models: Path = MODELS) -> bool:
    """A policy in ``models`` from this seed and episode count, trained under today's scenario."""
    man = policy_dir(method, signals, models) / "manifest.json"
    if not man.is_file():
        return False
    m = json.loads(man.read_text())
    return (m.get("seed") == seed and m.get("episodes") == episodes
            and not stale(m.get("scenario", {}), method, signals))


def plan(methods: list[str], seed: int, episodes: int, runs: Path = RUNS, models: Path = MODELS) -> list[tuple[str, str]]:
    """(method, signals) still to train (no policy from this seed and episode count in ``models``);
    runs with a checkpoint (started in an earlier session) come before new ones, otherwise in the
    given method order."""
    todo = [(m, s) for m in methods for s in SIGNALS if not _finished(m, s, seed, episodes, models)]
    return sorted(todo, key=lambda ms: not (runs / f"{ms[0]}-{ms[1]}-s{seed}" / "checkpoint.pt").is_file())


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parallel", type=int, default=2, help="concurrent trainings (one core each)")
    ap.add_argument("--methods", nargs="+", default=list(LEARNING), choices=list(LEARNING))
    args = ap.parse_args(argv)
    todo = plan(args.methods, args.seed, args.episodes)
    for m, s in todo:
        man, diff = policy_dir(m, s) / "manifest.json", []
        if man.is_file():
            diff = stale(json.loads(man.read_text()).get("scenario", {}), m, s)
        if diff:  # a policy from another seed or episode count is not "older"
            print(f"note: {man.parent} was trained under an older scenario (differs in {', '.join(diff)}); "
                  f"retraining. If {RUNS / f'{m}-{s}-s{args.seed}'} holds that finished run, move it away "
                  f"first, or it is exported again", flush=True)
    running: list[tuple[subprocess.Popen, str]] = []
    RUNS.mkdir(parents=True, exist_ok=True)
    failed = []
    while todo or running:
        while todo and len(running) < args.parallel:
            m, s = todo.pop(0)
            log = open(RUNS / f"{m}-{s}-s{args.seed}.log", "a")
            cmd = [sys.executable, "-m", "bench.training.train", "--method", m, "--signals", s, "--episodes",
                   str(args.episodes), "--seed", str(args.seed)]
            running.append((subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT), f"{m}/{s}"))
            print(f"started {m}/{s}", flush=True)
        for p, name in list(running):
            if p.poll() is not None:
                running.remove((p, name))
                print(f"finished {name} (exit {p.returncode})", flush=True)
                if p.returncode:
                    failed.append(name)
        time.sleep(5)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
