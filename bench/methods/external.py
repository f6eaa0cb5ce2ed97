"""Your own agent in the benchmark, without editing the package.

Two ways in, both giving a *factory*: a callable ``factory(observation_space, action_space)``
that returns an object satisfying ``agents.base.Agent``:

- ``ecodrive run --agent package.module:factory [--name NAME]`` imports it by path, from the
  installed packages, ``PYTHONPATH`` or the current folder (``agent_folder``: the folder a
  ``python -m`` run would look in, put after the others so it shadows nothing);
- an installed package registers it under the entry-point group ``ecodrive_bench.agents``
  (``[project.entry-points."ecodrive_bench.agents"] theirs = "theirpkg.agent:make"``), and
  ``ecodrive run --methods theirs`` finds it.

The factory's ``action_interface`` attribute (or the agent class's) picks the env's action type
(``parameterized``, ``discrete27``, ``longitudinal``; default ``parameterized``) before the
spaces exist. Every action the agent returns is checked against the env's action space; an
action outside it stops the run with one line naming the value and the space.

The agent's code is hashed (``code_sha256``: the files of the factory's module and of the
agent's class; an ``--sb3`` model's zip) into every step log and the manifest, so a changed agent
does not reuse the logs of the earlier one.
"""
from __future__ import annotations

import hashlib
import importlib
import os
import re
import sys
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

from ecodrive_bench.agents.base import Agent
from ecodrive_bench.bench.args import MAX_NAME, is_name
from ecodrive_bench.bench.methods.errors import AgentError

GROUP = "ecodrive_bench.agents"
INTERFACES = ("parameterized", "discrete27", "longitudinal")
SPEC = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


_WARNED: set[str] = set()  # entry-point names already reported as left out


def registered() -> dict[str, str]:
    """Agent name -> ``module:factory`` of every installed entry point in ``GROUP``. A name is a
    folder name of the run (``<run>/<signals>/<name>/``), so one that is not a plain name
    (``bench.args.is_name``: no path separator, not ``.`` or ``..``, at most ``MAX_NAME``
    characters) is left out, with one line."""
    out = {}
    for ep in metadata.entry_points(group=GROUP):
        if is_name(ep.name):
            out[ep.name] = ep.value
        elif ep.name not in _WARNED:
            _WARNED.add(ep.name)
            print(f"warning: installed agent {ep.name!r} ({ep.value}, entry-point group {GROUP}) is left out: a method "
                  f"name is made of letters, digits, '.', '_' and '-', at most {MAX_NAME} characters", file=sys.stderr)
    return out


def agent_folder() -> str | None:
    """The current folder, absolute, where an ``--agent`` module is looked up after ``sys.path``
    (as ``python -m`` would find it there; the console script's ``sys.path`` lacks it). None
    where the folder is gone. The pool's workers run in the same folder; ``run_ray`` hands it to
    Ray's in ``PYTHONPATH``."""
    try:
        return os.getcwd()
    except OSError:
        return None


def load_factory(spec: str) -> Callable[..., Any]:
    """The factory named by ``package.module:factory`` (or, for ``sb3:ALGO:PATH``, the one that
    loads a Stable-Baselines3 model: ``bench.methods.sb3``); the module is imported from
    ``sys.path``, then from ``agent_folder()``."""
    if spec.startswith("sb3:"):
        from ecodrive_bench.bench.methods import sb3

        return sb3.factory(spec)
    if not SPEC.match(spec):
        raise AgentError(f"--agent {spec!r} is not accepted; expected package.module:factory")
    module, attr = spec.split(":")
    here = agent_folder()
    if here is not None and here not in {os.path.abspath(p or os.curdir) for p in sys.path}:
        sys.path.append(here)
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name is None or not (module == e.name or module.startswith(e.name + ".")):
            raise AgentError(f"--agent {spec!r}: cannot import {module} ({type(e).__name__}: {e})") from None
        top = module.split(".")[0]  # the user's own module (or its package) is not found
        raise AgentError(f"--agent {spec!r}: cannot import {module}: no module {e.name!r} in the current folder "
                         f"({here or 'gone'}) nor on PYTHONPATH; run from the folder that holds {top}.py (or the "
                         f"package {top}/), or add that folder to PYTHONPATH") from None
    except Exception as e:  # the user's module: any error while importing it
        raise AgentError(f"--agent {spec!r}: cannot import {module} ({type(e).__name__}: {e})") from None
    factory = getattr(mod, attr, None)
    if not callable(factory):
        raise AgentError(f"--agent {spec!r}: {module} has no callable {attr!r}")
    return factory


def interface_of(factory: Callable[..., Any]) -> str:
    interface = getattr(factory, "action_interface", "parameterized")
    if interface not in INTERFACES:
        raise AgentError(f"agent factory {getattr(factory, '__name__', factory)!r}: action_interface {interface!r} "
                         f"is not accepted; choose one of {', '.join(INTERFACES)}")
    return interface


def make(spec: str, signals: str, config: dict[str, Any] | None = None) -> tuple[Any, Agent]:
    """(env, agent) for the user's factory ``spec`` on ``signals``: the env has the factory's
    action type, and the agent's own ``env_overrides`` when it has any."""
    from ecodrive_bench.bench.methods.env import make_env

    factory = load_factory(spec)
    probe = make_env(_Interface(interface_of(factory)), signals, config)
    agent = build(spec, probe.observation_space, probe.action_space)
    if not agent.env_overrides:
        return probe, agent
    probe.close()
    return make_env(agent, signals, config), agent


def code_sha256(spec: str, agent: Any) -> str:
    """The sha256 of the code behind ``agent``, built from ``spec``: for ``--sb3`` its zip's
    (the agent's ``sha256``); else over the files (name and bytes) of the modules of ``spec``, of
    the factory and of the agent's class, each module standing for its whole top-level package:
    every ``.py`` file under the package's folder (at most ``MAX_HASHED`` files), so a change to any
    module of the package, one the agent imports included, changes it. A module outside a package
    (``myagents.py`` in the current folder) stands for its own file; a change to another top-level
    module it imports does not change it. This package's modules are left out (the run's
    ``git_sha`` names them)."""
    if spec.startswith("sb3:"):
        return str(getattr(agent, "sha256", ""))
    factory = load_factory(spec)
    inner = getattr(agent, "agent", agent)  # ``Checked`` holds the user's agent
    names = {spec.split(":")[0], getattr(factory, "__module__", None), type(inner).__module__}
    files = sorted({f for n in names if n and not n.startswith("ecodrive_bench.") for f in _code_files(n)})
    h = hashlib.sha256()
    for f in files:
        h.update(f.encode() + b"\0")
        try:
            h.update(Path(f).read_bytes())
        except OSError:
            h.update(b"(unreadable)")
    return h.hexdigest()


MAX_HASHED = 2000  # [-] .py files of one agent package hashed into its identity


def _code_files(module: str) -> list[str]:
    """The files that stand for ``module`` in ``code_sha256``: the ``.py`` files of its top-level
    package's folders, or its own file outside a package."""
    top = sys.modules.get(module.split(".")[0])
    folders = list(getattr(top, "__path__", []) or [])
    if not folders:
        f = getattr(sys.modules.get(module), "__file__", None)
        return [str(Path(f).resolve())] if f else []
    out: list[str] = []
    for folder in folders:
        for root, dirs, names in os.walk(folder):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__" and not d.startswith("."))
            out += [str((Path(root) / n).resolve()) for n in sorted(names) if n.endswith(".py")]
            if len(out) > MAX_HASHED:
                return out[:MAX_HASHED]
    return out


class _Interface:
    """Just enough of an agent for ``make_env`` before the real one exists."""

    def __init__(self, interface: str) -> None:
        self.action_interface, self.env_overrides = interface, {}


def build(spec: str, observation_space, action_space) -> Agent:
    """The user's agent, checked against the ``Agent`` protocol and wrapped so that every action
    is checked against ``action_space``."""
    factory = load_factory(spec)
    try:
        agent = factory(observation_space, action_space)
    except AgentError:
        raise
    except Exception as e:
        raise AgentError(f"agent factory {spec!r} failed ({type(e).__name__}: {e})") from None
    missing = [a for a in ("name", "action_interface", "env_overrides", "act", "observe", "state_dict",
                           "load_state_dict") if not hasattr(agent, a)]
    if missing:
        raise AgentError(f"agent from {spec!r} does not satisfy agents.base.Agent: missing {', '.join(missing)}")
    if agent.action_interface != interface_of(factory):
        raise AgentError(f"agent from {spec!r}: its action_interface {agent.action_interface!r} differs from the "
                         f"factory's {interface_of(factory)!r}, which picks the env's action type before the agent "
                         f"is built: set the factory's action_interface = {agent.action_interface!r} too, or give "
                         f"the agent's class as the factory")
    return Checked(agent, action_space, spec)


class Checked:
    """An agent whose every action must lie in the action space."""

    def __init__(self, agent: Agent, action_space, spec: str) -> None:
        self.agent, self.space, self.spec = agent, action_space, spec
        self.name, self.action_interface = agent.name, agent.action_interface
        self.env_overrides = dict(agent.env_overrides)
        self.sha256 = getattr(agent, "sha256", "")  # of the file it was loaded from, when it has one

    def act(self, obs, info, explore: bool = False):
        action = self.agent.act(obs, info, explore=explore)
        try:
            ok = self.space.contains(action)
        except Exception:
            ok = False
        if not ok:
            raise AgentError(f"agent from {self.spec!r} returned {action!r}, outside the action space {self.space}")
        return action

    def observe(self, *args, **kw):
        return self.agent.observe(*args, **kw)

    def state_dict(self) -> dict[str, Any]:
        return self.agent.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.agent.load_state_dict(state)
