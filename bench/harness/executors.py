"""Where episodes run: a local process pool (one SUMO per process) or a Ray cluster.

Both run the same ``run_task`` and yield result rows as episodes finish; the rows do not depend
on the executor (tests compare them). On both, a task whose worker process dies is run again, at
most ``RETRIES`` more times; a task that raises is not retried. A task that cannot be finished
goes to ``on_failure`` (a ``bench.harness.pool.Failure``), or, without it, raises.

The ``--executor``/``--address`` options live here (``add_options``), for every command that
offers Ray. A task whose files must reach the driver returns them as data (``Files``: ``collect``
on the worker, ``land`` on the driver), so no node needs the driver's disk.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.harness.pool import RETRIES, Failure, _die_with_parent, describe, run_pool  # noqa: F401 (initializer of running pools)
from ecodrive_bench.bench.io import atomic_bytes
from ecodrive_bench.bench.methods.errors import install_hint
from ecodrive_bench.bench.methods.planners import PLANNERS, identity

EXECUTORS = ("local", "ray")
# an episode's default wall-clock limit on the local pool (``episode_limit``): a fixed allowance for
# what comes before its first step (a fresh worker imports torch, builds its env and agent, SUMO
# loads; a clairvoyant planner drives the case first, 15-60 s on a loaded machine) plus an
# allowance per step, some 30 times the slowest method's (clairvoyant: about 35 ms a step, its
# prepare included, on a loaded 2-core machine)
EPISODE_FIXED_S = 300.0  # [s]
EPISODE_STEP_S = 1.0  # [s] per step of the scenario (max_episode_time / step_length)
# a Ray head's GCS address (HOST:PORT, HOST a name, an IPv4 or a bracketed IPv6) or a Ray Client one
ADDRESS = re.compile(r"(?:ray://)?(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?):([0-9]{1,5})")
ADDRESSES = "auto, HOST:PORT or ray://HOST:PORT with PORT 1..65535"


def address(value: str) -> str:
    """``--address``: ``auto`` (the cluster this machine has joined), a head's ``HOST:PORT`` or a
    Ray Client ``ray://HOST:PORT``; anything else is an argparse error naming the value."""
    m = ADDRESS.fullmatch(value)
    if value != "auto" and not (m and 1 <= int(m.group(1)) <= 65535):
        raise argparse.ArgumentTypeError(f"{value!r} is not accepted; accepted: {ADDRESSES}")
    return value


def add_options(ap: argparse.ArgumentParser, ray: str = "") -> None:
    """``--executor`` and ``--address``; ``ray`` adds to the help of ``--executor`` what a Ray run
    does differently (e.g. where its checkpoints live). ``check_options`` after parsing."""
    ap.add_argument("--executor", default="local", choices=list(EXECUTORS),
                    help=f"local: processes on this machine; ray: Ray tasks on the nodes of a cluster{ray}")
    ap.add_argument("--address", type=address, default=None,
                    help=f"Ray cluster to join, with --executor ray: {ADDRESSES} (default: start a local Ray)")


def check_options(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """An ``--address`` is for ``--executor ray``, and ``--executor ray`` needs Ray installed:
    otherwise one line, exit 2, before anything is written."""
    if args.address is not None and args.executor != "ray":
        ap.error(f"--address {args.address} is for --executor ray (got --executor {args.executor}); "
                 f"add --executor ray or drop --address")
    if args.executor == "ray" and importlib.util.find_spec("ray") is None:
        ap.error(f"--executor ray needs Ray, which is not installed here: {install_hint('distributed')}, "
                 "or use --executor local")


@dataclass(frozen=True)
class Files:
    """A task's result that carries files to the driver: ``value`` (its row) and ``files`` (plain
    file name -> content), which the driver writes with ``land``."""

    value: Any
    files: dict[str, bytes]


def collect(folder: Path) -> dict[str, bytes]:
    """The regular files directly in ``folder`` (not links, not sub-folders), by name."""
    return {p.name: p.read_bytes() for p in sorted(Path(folder).iterdir()) if p.is_file() and not p.is_symlink()}


def land(files: dict[str, bytes], folder: Path, last: tuple[str, ...] = ()) -> None:
    """Write ``files`` into ``folder`` (created), each atomically (``bench.io``), the names in
    ``last`` after all others in that order: the file whose presence marks a finished result
    (a job's ``job.json``, a policy's ``manifest.json``) is never there before the rest. A name
    that is not a plain file name is a ValueError before anything is written."""
    bad = [n for n in files if Path(n).name != n or n in ("", ".", "..")]
    if bad:
        raise ValueError(f"{folder}: refusing to write {bad[0]!r}, not a plain file name")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for name in sorted(files, key=lambda n: last.index(n) + 1 if n in last else 0):
        atomic_bytes(files[name], folder / name)


@dataclass(frozen=True)
class Task:
    method: str
    signals: str
    case: Case
    path: str  # MCAP to write
    policy_dir: str  # models/<method>-<signals>/s<seed> for learning methods, "" otherwise
    train_seed: int = -1  # the policy's training seed; -1 for rule-based methods
    factory: str = ""  # a user agent's package.module:factory (bench.methods.external), "" otherwise
    scenario: str = ""  # JSON of the env's scenario overrides (bench.harness.scenarios), "" none
    transfer: bool = False  # the policy may drive a scenario other than its training one
    meta: tuple[tuple[str, str], ...] = ()  # extra step-log metadata (the scenarios)
    limit_s: float = 0.0  # [s] the episode's wall-clock limit on the local pool (episode_limit); 0: none


def episode_limit(cfg: Any) -> float:
    """[s] the default wall-clock limit of one episode on the scenario ``cfg`` (a
    ``ScenarioConfig``): ``EPISODE_FIXED_S`` plus ``EPISODE_STEP_S`` per step; 1200 s for the
    paper's 900 steps."""
    steps = math.ceil(cfg.max_episode_time / cfg.step_length - 1e-9)
    return EPISODE_FIXED_S + EPISODE_STEP_S * steps


def task_limit(task: Any) -> float | None:
    """``run_pool``'s ``limit``: a ``Task``'s ``limit_s``, None for other tasks or 0."""
    return getattr(task, "limit_s", 0.0) or None


# per worker process: one env per (method, signals, scenario); one agent per (method, signals,
# policy folder, scenario)
_ENVS: dict[tuple[str, str, str], Any] = {}
_AGENTS: dict[tuple[str, str, str, str], tuple[Any, str]] = {}  # agent, policy sha256


def run_task(task: Task) -> dict[str, Any]:
    """One greedy episode in this worker; envs and policies are loaded once per worker."""
    import torch

    from ecodrive_bench.bench.harness.episode import run_episode
    from ecodrive_bench.bench.methods.env import make_env

    torch.set_num_threads(1)
    scenario = json.loads(task.scenario) if task.scenario else None
    env_key = (task.method, task.signals, task.scenario)
    key = (task.method, task.signals, task.policy_dir, task.scenario)
    if task.factory and key not in _AGENTS:
        from ecodrive_bench.bench.methods.external import code_sha256, make

        _ENVS[env_key], agent = make(task.factory, task.signals, scenario)
        _AGENTS[key] = (agent, code_sha256(task.factory, agent))  # its code's, an --sb3 zip's
    if task.method in PLANNERS and key not in _AGENTS:
        planner = registry.load(registry.method(task.method).build)  # its agent class, built from the env's config
        env = make_env(planner, task.signals, scenario)  # type: ignore[arg-type]
        agent = planner(env.cfg)
        if agent.action_interface != env.action_type.name:  # clairvoyant on a network corridor drives longitudinal
            env.close()
            env = make_env(agent, task.signals, scenario)
        _ENVS[env_key], _AGENTS[key] = env, (agent, identity(task.method))
    if env_key not in _ENVS:
        _ENVS[env_key] = make_env(task.method, task.signals, scenario)
    env = _ENVS[env_key]
    if key not in _AGENTS:
        _AGENTS[key] = task_agent(task, env)
    agent, sha = _AGENTS[key]
    t0 = time.perf_counter()
    if hasattr(agent, "prepare"):  # a planner that drives the case first (clairvoyant: its future traffic)
        agent.prepare(env, task.case)
    row = run_episode(env, agent, task.case, task.method, log_path=Path(task.path), agent_sha256=sha,
                      log_meta=dict(task.meta))
    row["episode_wall_s"] = time.perf_counter() - t0
    row["mcap"] = task.path
    row["train_seed"] = task.train_seed
    return row


def task_agent(task: Task, env: Any) -> tuple[Any, str]:
    """(agent, policy sha256) of a built-in method on ``env``: a rule-based one, or a learning
    one holding its verified policy (``bench.methods.policies``; a policy that cannot be loaded
    is a ``CheckpointError`` naming the file)."""
    learned = registry.names("learned")
    from ecodrive_bench.bench.methods.policies import load_policy, policy_agent, policy_spaces

    if task.method not in learned:  # a rule-based method: its agent class, no arguments
        return registry.load(registry.method(task.method).build)(), ""
    folder = Path(task.policy_dir)
    state, manifest = load_policy(folder, task.method, env.cfg.to_dict(), task.transfer)
    spaces = (policy_spaces(folder, manifest) if task.transfer  # the spaces it trained with: its shapes and input scaling
              else (env.observation_space, env.action_space))
    return policy_agent(folder, task.method, spaces, manifest, state), manifest["sha256"]


def run_local(tasks: Iterable[Any], workers: int, fn: Callable[[Any], dict] = run_task,
              on_failure: Callable[[Failure], None] | None = None,
              skip: Callable[[Any], bool] | None = None) -> Iterator[dict[str, Any]]:
    """Rows of ``fn(task)`` on a pool of ``workers`` processes, as they finish; a dead worker is
    replaced and its task rerun up to ``RETRIES`` times, and a ``Task`` past its ``limit_s``
    fails and its worker is killed (``bench.harness.pool``).

    With more than one worker the step's numba kernels are compiled here, so that the workers
    load numba's disk cache rather than all compile at once (and numba's cache is not written
    safely by several processes at a time): the occupancy grid's before the workers start (every
    episode needs it), the greedy act's (seconds on a fresh install) in a thread beside them,
    while the learning methods' episodes are held back and the others run."""
    if workers <= 1:
        return run_pool(tasks, workers, fn, on_failure, skip, limit=task_limit)

    tasks = list(tasks)
    compile_grid()
    compiled = threading.Event()
    if not any(getattr(t, "method", None) in registry.names("learned") for t in tasks):
        compiled.set()  # no act to compile (the bounds, the rule-based methods, the planners)

    def compile_act() -> None:
        try:
            compile_greedy()
        except Exception as e:  # the workers compile for themselves, and report it if it recurs
            print(f"warning: compiling the greedy act's kernels failed here ({type(e).__name__}: {e}); "
                  "each worker compiles them", file=sys.stderr)
        finally:
            compiled.set()

    if not compiled.is_set():
        threading.Thread(target=compile_act, name="compile-greedy-act", daemon=True).start()

    def hold(task: Any) -> bool:
        return not compiled.is_set() and getattr(task, "method", None) in registry.names("learned")

    return run_pool(tasks, workers, fn, on_failure, skip, hold=hold, limit=task_limit)


def compile_grid() -> None:
    """The occupancy grid's numba kernels compiled (or loaded from the disk cache) here."""
    from ecodrive_bench.envs.config import ScenarioConfig
    from ecodrive_bench.envs.observation import occupancy_grid

    occupancy_grid(0.0, [(5.0, -1.6, 90.0, 5.0)], (-4.8, -1.6), ScenarioConfig(lanes=2))


def compile_greedy() -> None:
    """The greedy act's numba kernels compiled (or loaded from the disk cache) here."""
    from ecodrive_bench.agents.inference import compile_kernels as greedy

    greedy()



def run_ray(tasks: Iterable[Any], address: str | None, workers: int, fn: Callable[[Any], dict] = run_task,
            on_failure: Callable[[Failure], None] | None = None,
            skip: Callable[[Any], bool] | None = None) -> Iterator[dict[str, Any]]:
    """As ``run_local``; after a failure, pending tasks for which ``skip(task)`` is true are
    cancelled."""
    try:
        import ray
    except ImportError:
        raise SystemExit(f"error: --executor ray needs Ray: {install_hint('distributed')}") from None
    from ecodrive_bench.bench.methods.external import agent_folder

    root = str(Path(__file__).resolve().parents[2])
    if not ray.is_initialized():
        # a user agent's module too: on PYTHONPATH, or in the current folder (external.load_factory)
        path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", ""), agent_folder()) if p)
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                  "runtime_env": {"env_vars": {"PYTHONPATH": path}}}
        if address:
            ray.init(address=address, **kwargs)
        else:
            # "local": a Ray of its own, even where a cluster started on this machine would be joined
            ray.init(address="local", num_cpus=workers, **kwargs)
    # a task whose worker died is retried by Ray; an exception raised by the task is not
    remote = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=False)(fn)
    pending = {remote.remote(t): t for t in tasks}
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        task = pending.pop(done[0])
        if task is None:  # cancelled by skip
            continue
        try:
            yield ray.get(done[0])
        except ray.exceptions.RayTaskError as e:  # the task raised: e.cause is its exception
            if on_failure is None:
                raise
            cause = e.cause if isinstance(e.cause, BaseException) else RuntimeError(str(e))
            on_failure(describe(cause, str(e), f"{type(cause).__name__}: {cause}", 1, task))  # str: the traceback
        except ray.exceptions.RayError as e:  # its worker (or node) died every time
            if on_failure is None:
                raise
            first = str(e).strip().splitlines()[0] if str(e).strip() else ""
            on_failure(describe(None, str(e), f"its worker died ({type(e).__name__}: {first}), "
                                              f"{1 + RETRIES} times", 1 + RETRIES, task))
        else:
            continue
        for ref, t in pending.items():
            if t is not None and skip is not None and skip(t):
                ray.cancel(ref, force=True)
                pending[ref] = None
