"""Where episodes run: a local process pool (one SUMO per process) or a Ray cluster.

Both run the same ``run_task`` and yield result rows as episodes finish; the rows do not depend
on the executor (tests compare them).
"""
from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.harness.cases import Case
from bench.harness.oracle import NAME as ORACLE

EXECUTORS = ("local", "ray")


@dataclass(frozen=True)
class Task:
    method: str
    signals: str
    case: Case
    path: str  # MCAP to write
    policy_dir: str  # models/<method>-<signals>/s<seed> for learning methods, "" otherwise
    train_seed: int = -1  # the policy's training seed; -1 for rule-based methods
    factory: str = ""  # a user agent's package.module:factory (bench.harness.external), "" otherwise
    scenario: str = ""  # JSON of the env's scenario overrides (bench.harness.scenarios), "" none
    transfer: bool = False  # the policy may drive a scenario other than its training one
    meta: tuple[tuple[str, str], ...] = ()  # extra step-log metadata (the scenarios)


# per worker process: one env per (method, signals, scenario); one agent per (method, signals,
# policy folder, scenario)
_ENVS: dict[tuple[str, str, str], Any] = {}
_AGENTS: dict[tuple[str, str, str, str], tuple[Any, str]] = {}  # agent, policy sha256


def run_task(task: Task) -> dict[str, Any]:
    """One greedy episode in this worker; envs and policies are loaded once per worker."""
    import torch

    from bench.harness.episode import make_env, run_episode

    torch.set_num_threads(1)
    scenario = json.loads(task.scenario) if task.scenario else None
    env_key = (task.method, task.signals, task.scenario)
    key = (task.method, task.signals, task.policy_dir, task.scenario)
    if task.factory and key not in _AGENTS:
        from bench.harness.external import make

        _ENVS[env_key], agent = make(task.factory, task.signals, scenario)
        _AGENTS[key] = (agent, getattr(agent, "sha256", ""))  # an --sb3 zip's, "" for code
    if task.method == ORACLE and key not in _AGENTS:
        from bench.harness.oracle import OracleAgent

        _ENVS[env_key] = env = make_env(OracleAgent, task.signals, scenario)  # type: ignore[arg-type]
        _AGENTS[key] = (OracleAgent(env.cfg), "")
    if env_key not in _ENVS:
        _ENVS[env_key] = make_env(task.method, task.signals, scenario)
    env = _ENVS[env_key]
    if key not in _AGENTS:
        _AGENTS[key] = task_agent(task, env)
    agent, sha = _AGENTS[key]
    t0 = time.perf_counter()
    row = run_episode(env, agent, task.case, task.method, log_path=Path(task.path), agent_sha256=sha,
                      log_meta=dict(task.meta))
    row["episode_wall_s"] = time.perf_counter() - t0
    row["mcap"] = task.path
    row["train_seed"] = task.train_seed
    return row


def task_agent(task: Task, env: Any) -> tuple[Any, str]:
    """(agent, policy sha256) of a built-in method on ``env``: a rule-based one, or a learning
    one holding its verified policy (``bench.harness.policies``; a policy that cannot be loaded
    is a ``CheckpointError`` naming the file)."""
    from agents.registry import LEARNING, make_agent
    from bench.harness.policies import load_policy, policy_agent, policy_spaces

    if task.method not in LEARNING:
        return make_agent(task.method, env.observation_space, env.action_space), ""
    folder = Path(task.policy_dir)
    state, manifest = load_policy(folder, task.method, env.cfg.to_dict(), task.transfer)
    spaces = (policy_spaces(folder, manifest) if task.transfer  # the spaces it trained with: its shapes and input scaling
              else (env.observation_space, env.action_space))
    return policy_agent(folder, task.method, spaces, manifest, state), manifest["sha256"]


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _die_with_parent(parent: int) -> None:
    """Worker initializer: on Linux, ask for SIGTERM when the process that started the pool dies
    (a killed sweep must not leave orphans computing its cells); elsewhere nothing."""
    import ctypes
    import signal
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # it died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


def run_local(tasks: Iterable[Any], workers: int, fn: Callable[[Any], dict] = run_task) -> Iterator[dict[str, Any]]:
    ctx = mp.get_context("spawn")  # a fresh interpreter per worker: no libsumo state is inherited
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_die_with_parent,
                             initargs=(os.getpid(),)) as pool:
        futures = [pool.submit(fn, t) for t in tasks]
        try:
            for f in as_completed(futures):
                yield f.result()
        except BaseException:
            for f in futures:
                f.cancel()
            raise


def run_ray(tasks: Iterable[Any], address: str | None, workers: int,
            fn: Callable[[Any], dict] = run_task) -> Iterator[dict[str, Any]]:
    try:
        import ray
    except ImportError:
        raise SystemExit("error: --executor ray needs Ray: pip install '.[distributed]'") from None
    root = str(Path(__file__).resolve().parents[2])
    if not ray.is_initialized():
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                  "runtime_env": {"env_vars": {"PYTHONPATH": root}}}
        if address:
            ray.init(address=address, **kwargs)
        else:
            ray.init(num_cpus=workers, **kwargs)
    remote = ray.remote(num_cpus=1)(fn)
    pending = [remote.remote(t) for t in tasks]
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        yield ray.get(done[0])
