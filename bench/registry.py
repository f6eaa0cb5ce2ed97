"""The methods and case sets the suite knows, as plain data: their one home.

Every list of methods (the run's ``--methods``, its defaults, the workers' agents, training,
the perf tool, the report's names, order, learned and planner groups) reads ``METHODS``; every
case set (the paper's fixed cases, the held-out family, the real corridors) is one ``CaseSet``
of ``CASE_SETS``. Nothing here imports a method's code: ``build`` names it as ``module:attr``,
imported when an episode needs the agent, so reading the registry costs no torch and no SUMO.

Adding a method is one module (its agent) and one entry: a ``Method`` here, or, from an
installed package of your own, a ``Method`` object named by an entry point of the group
``ecodrive_bench.methods`` (``[project.entry-points."ecodrive_bench.methods"] toy =
"toypkg.agent:METHOD"``), which ``methods()`` adds after the built-ins (``kind`` "user").
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

KINDS = ("rule-based", "learned", "planner", "user")
INTERFACES = ("parameterized", "discrete27", "longitudinal", "sumo")
ROLES = ("", "driver", "steady", "top")  # SUMO's driver; steady driving (the edge's reference); the top of the scale
GROUP = "ecodrive_bench.methods"  # entry points naming a Method object


@dataclass(frozen=True)
class Method:
    """One method the harness can drive."""

    name: str  # its id: --methods, results' method column, run folders
    kind: str  # one of KINDS: rule-based (no policy), learned (a trained policy), planner (plans on the signal plans), user
    interface: str  # the env's action type it drives (INTERFACES)
    display: str  # its name in tables, figures and the README
    order: int  # its place in tables and figures (smaller first)
    build: str = ""  # module:attr of its agent: a class (rule-based: no arguments; planner: the env's config) or factory
    what: str = ""  # a few words on what it is, for a table's or legend's first use ("" where the name says it)
    algorithm: str = ""  # learned: the algorithm it trains with (ecodrive train --method; agents.registry.make_agent)
    generalist: bool = False  # learned over the corridor family (bench.cases.train_family), not the paper's corridor
    role: str = ""  # one of ROLES: what the report measures against it
    env_overrides: tuple[tuple[str, Any], ...] = ()  # scenario fields its agent needs, as (field, value) pairs

    def overrides(self) -> dict[str, Any]:
        """``env_overrides`` as the nested dict ``bench.methods.env.make_env`` merges."""
        return {k: dict(v) if isinstance(v, tuple) else v for k, v in self.env_overrides}


BUILT_IN: tuple[Method, ...] = (  # the run's order: the rule-based, the specialists, the generalists, the planners
    Method("baseline", "rule-based", "sumo", "Baseline", 0, "ecodrive_bench.agents.baseline:BaselineAgent",
           "SUMO's Krauss driver and LC2013", role="driver"),
    Method("glosa", "rule-based", "sumo", "GLOSA", 2, "ecodrive_bench.agents.glosa:GlosaAgent",
           "SUMO's GLOSA device", env_overrides=(("glosa", True),)),
    Method("baseline0", "rule-based", "sumo", "Baseline0", 1, "ecodrive_bench.agents.baseline:SteadyBaselineAgent",
           "SUMO's driver, imperfection sigma 0", role="steady", env_overrides=(("ego_sigma", 0.0),)),
    Method("prl", "learned", "parameterized", "PRL", 3, algorithm="prl"),
    Method("mpdqn", "learned", "parameterized", "MP-DQN", 4, algorithm="mpdqn"),
    Method("dqn", "learned", "discrete27", "DQN-27", 8, algorithm="dqn"),
    Method("ddpg", "learned", "longitudinal", "DDPG+LC2013", 7, algorithm="ddpg",
           env_overrides=(("reward", (("lane_change_penalty", 0.0),)),)),
    Method("prl-family", "learned", "parameterized", "PRL-family", 5, what="trained on the corridor family",
           algorithm="prl", generalist=True),
    Method("mpdqn-family", "learned", "parameterized", "MP-DQN-family", 6, what="trained on the corridor family",
           algorithm="mpdqn", generalist=True),
    Method("oracle", "planner", "longitudinal", "Oracle", 9, "ecodrive_bench.bench.methods.oracle_agent:OracleAgent",
           "the cost-optimal plan replayed in traffic"),
    Method("mpc", "planner", "longitudinal", "MPC", 10, "ecodrive_bench.bench.methods.mpc_agent:MPCAgent",
           "re-plans with the signal plans, closed loop"),
    Method("clairvoyant", "planner", "parameterized", "Clairvoyant", 11,
           "ecodrive_bench.bench.methods.clairvoyant_agent:ClairvoyantAgent",
           "knows the signal plans and the case's future traffic", role="top"),
)


@cache
def _installed() -> tuple[Method, ...]:
    """The ``Method`` objects of the installed entry points of ``GROUP`` (each checked)."""
    from importlib import metadata

    out = []
    known = {m.name for m in BUILT_IN}
    for ep in sorted(metadata.entry_points(group=GROUP), key=lambda e: e.name):
        m = ep.load()
        if not isinstance(m, Method) or m.name != ep.name or m.name in known:
            raise ValueError(f"entry point {ep.name!r} of {GROUP} ({ep.value}) is not accepted: it must name a "
                             f"registry Method of the same name, not a built-in one")
        known.add(m.name)
        out.append(m)
    return tuple(out)


def methods(installed: bool = True) -> tuple[Method, ...]:
    """Every method: the built-ins, then (``installed``) those of installed packages."""
    return BUILT_IN + (_installed() if installed else ())


def method(name: str) -> Method | None:
    """The entry of ``name``, or None for a method the registry does not know (a run's --agent)."""
    return next((m for m in methods() if m.name == name), None)


def names(kind: str | None = None, generalist: bool | None = None, installed: bool = True) -> tuple[str, ...]:
    """Method names in the run's order, of one ``kind`` and generalist-ness where given."""
    return tuple(m.name for m in methods(installed) if (kind is None or m.kind == kind)
                 and (generalist is None or m.generalist == generalist))


def display(name: str) -> str:
    """``name``'s display name; a method the registry does not know: its id."""
    m = method(name)
    return m.display if m else name


def table_order() -> tuple[str, ...]:
    """Every method by ``order``: the report's tables and figures."""
    return tuple(m.name for m in sorted(methods(), key=lambda m: (m.order, m.name)))


def with_role(role: str) -> str:
    """The method of ``role`` (driver, steady or top)."""
    return next(m.name for m in BUILT_IN if m.role == role)


def algorithm(name: str) -> str:
    """The algorithm ``agents.registry.make_agent`` builds for ``name``: a learned method's
    ``algorithm`` (``prl-family``: ``prl``), else the name itself (a rule-based method)."""
    m = method(name)
    return m.algorithm if m is not None and m.algorithm else name


def interface(name: str) -> str:
    m = method(name)
    if m is None:
        raise KeyError(name)
    return m.interface


def specialist_of(name: str) -> str:
    """A generalist's specialist: the method trained with its algorithm on the paper's corridor."""
    m = method(name)
    assert m is not None and m.generalist
    return next(s.name for s in BUILT_IN if s.kind == "learned" and not s.generalist and s.algorithm == m.algorithm)


@dataclass(frozen=True)
class CaseSet:
    """One set of fixed cases a run evaluates on."""

    name: str  # its id: the profile that runs it (paper / generalisation / real)
    reader: str  # module:attr that reads it: the fixed cases, or a family's variants (names=None: all)
    writer: str  # module:attr of its generator's ``main(write)``: ecodrive cases --write / --check
    file: str  # the shipped file, relative to the package (what ecodrive cases writes and checks)
    family: str  # ecodrive cases --family value that writes and checks it ("" for the paper's cases)
    what: str  # a few words


CASE_SETS: tuple[CaseSet, ...] = (
    CaseSet("paper", "ecodrive_bench.bench.cases.case:load", "", "bench/cases/cases.json", "",
            "the paper's corridor: 100 fixed cases per signal setting"),
    CaseSet("generalisation", "ecodrive_bench.bench.cases.heldout:variants", "ecodrive_bench.bench.cases.heldout:main",
            "envs/families/heldout.json", "test", "the held-out family of generated corridors, 10 cases per corridor and setting"),
    CaseSet("real", "ecodrive_bench.bench.cases.real:variants", "ecodrive_bench.bench.shipped.real_cases:main",
            "envs/families/real.json", "real", "real city corridors (RESCO's networks in the installed sumo-rl), 30 cases each"),
)
FAMILY_PROFILES = tuple(c.name for c in CASE_SETS if c.family)  # run profiles over a family of corridors


def case_set(name: str) -> CaseSet | None:
    return next((c for c in CASE_SETS if c.name == name), None)


def load(spec: str) -> Any:
    """The object that ``module:attr`` names (a method's ``build``, a case set's ``reader``)."""
    import importlib

    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)
