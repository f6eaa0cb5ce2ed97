"""``ecodrive run``'s options: its parser and the typed, checked ``RunOptions`` it gives
(CleanRL's ``Args`` dataclass is the model: every field with a one-line doc)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.args import MAX_NAME, Parser, float_in, int_in, name, name_shown
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.cases.heldout import CASES_PER_VARIANT, FamilyError, Variant
from ecodrive_bench.bench.harness import scenarios
from ecodrive_bench.bench.harness.executors import EPISODE_FIXED_S, EPISODE_STEP_S, add_options, check_options
from ecodrive_bench.bench.methods.errors import AgentError
from ecodrive_bench.bench.methods.external import GROUP, registered
from ecodrive_bench.bench.methods.planners import CLAIRVOYANT, MPC, ORACLE, PLANNERS
from ecodrive_bench.bench.methods.policies import MODELS
from ecodrive_bench.bench.methods.sb3 import ALGOS as SB3_ALGOS
from ecodrive_bench.envs.config import SIGNALS, ConfigError

RUN_DOC = """The benchmark harness: every method over the fixed test cases, one MCAP per episode.

    ecodrive run [--profile smoke|paper|full|generalisation] [--executor local|ray] [--address ADDR]
                        [--workers N] [--episode-limit S] [--methods ...] [--planners] [--signals ...]
                        [--run-id ID] [--logs DIR] [--agent MODULE:FACTORY | --sb3 MODEL.zip --sb3-algo ALGO]
                        [--name NAME] [--scenario FILE.json] [--set FIELD=VALUE ...] [--transfer]
                        [--variants NAME ...]

Writes ``<logs>/<run-id>/<signals>/<method>/case-XXX.mcap``, ``results.parquet`` and
``manifest.json``. Rerunning the same command skips cases whose MCAP is complete and reruns the
rest, so a killed run loses nothing that finished. Evaluation is greedy. ``--scenario`` and
``--set`` evaluate on another corridor (one per run folder and setting); a policy drives a
scenario other than its training one only with ``--transfer`` (``bench.harness.scenarios``).
``--profile generalisation`` runs over the held-out corridors of ``bench.cases.heldout``
instead, one sub-folder per variant (``bench.harness.generalisation_run``).
A worker that dies is replaced and its episode rerun (at most twice more); an episode that still
fails, or whose agent raises, is one line on stderr (its traceback in ``<run>/errors/``) and no
row; so is an episode past its wall-clock limit (``--episode-limit``), whose worker is killed.
Exit codes: 0 done; 2 bad input, or the run folder in use by another command; 3 finished with
failed episodes, an agent that raised or returned an action outside its space among them (rerun
the command to retry them); 130 interrupted (Ctrl-C); 143 terminated (SIGTERM).
"""

METHODS = (*registry.names("rule-based"), *registry.names("learned"))  # the methods a run runs by default
MAX_LIMIT_S = 7 * 86400.0  # [s] the largest --episode-limit

PROFILES = {  # name: cases per setting (full: `nox -s benchmark` adds lateral, mixed, reward and heatmap)
    "smoke": 3,
    "paper": 100,
    "full": 100,
    "generalisation": CASES_PER_VARIANT,  # per variant and setting, over bench.cases.heldout's family
    "real": 30,  # per real corridor and setting (bench.cases.real.CASES_PER_CORRIDOR)
}
FAMILY_PROFILES = registry.FAMILY_PROFILES  # profiles over a family of corridors (the registry's case sets), one sub-run each


@dataclass
class RunOptions:
    """What one ``ecodrive run`` does, checked (``parse``); every field has its one-line doc."""

    profile: str = "paper"  # smoke | paper | full | generalisation | real (PROFILES: cases per setting)
    methods: list[str] | None = None  # the methods asked for; None: every method with a shipped policy
    planners: bool = False  # also the planners (oracle, mpc, clairvoyant), in the same pool as the methods
    signals: list[str] = field(default_factory=lambda: list(SIGNALS))  # signal settings to run
    executor: str = "local"  # local process pool, or ray
    address: str | None = None  # Ray cluster address (executor ray); None: a local Ray
    workers: int = 1  # parallel episodes
    episode_limit: float | None = None  # [s] wall-clock limit of one episode (local pool); None: by its steps
    run_id: str = "paper"  # run folder under logs (a plain name)
    logs: Path = Path("logs")  # log root
    models: Path = MODELS  # shipped policies, <method>-<signals>/s<seed>/
    bounds: bool = False  # add each case's cost-optimal bound (bench.oracle DP)
    train_seeds: list[int] | None = None  # training seeds of the learning methods; None: every shipped one
    factories: dict[str, str] = field(default_factory=dict)  # user method name -> package.module:factory
    agent_sha256: dict[str, str] = field(default_factory=dict)  # user method name -> sha256 of its --sb3 zip
    scenario: dict[str, Any] = field(default_factory=dict)  # scenario overrides (--scenario, --set)
    transfer: bool = False  # a policy may drive a scenario other than its training one
    family: list[Variant] = field(default_factory=list)  # the corridors of a family profile (generalisation, real)
    cases: list[Case] | None = None  # the cases per setting; None: the profile's first fixed cases
    argv: list[str] = field(default_factory=list)  # the command line, for the manifest
    failures: list[Any] = field(default_factory=list)  # episodes that failed (bench.harness.failures), filled in

    @property
    def run_dir(self) -> Path:
        return self.logs / self.run_id

    def variant(self, v: Variant) -> RunOptions:
        """The options of one held-out corridor's sub-run (``--profile generalisation``)."""
        return replace(self, logs=self.run_dir, run_id=v.name, scenario=v.scenario, transfer=True, cases=list(v.cases))


def parser() -> Parser:
    ap = Parser(description=RUN_DOC)
    ap.add_argument("--profile", default="paper", choices=list(PROFILES),
                    help="smoke: 3 cases per setting; paper: the 100 fixed cases; full: paper plus section 5's "
                         "experiments (`nox -s benchmark -- --profile full`; the main job runs paper); generalisation: every method with a policy, "
                         f"{ORACLE}, {MPC} and {CLAIRVOYANT} included, on each held-out corridor of the family (docs/generalisation.md), "
                         "its cases, with --transfer implied, one sub-folder per variant; real: every method with a "
                         "policy, zero-shot, on each real corridor (bench.cases.real, docs/networks.md), one sub-folder "
                         "per corridor")
    ap.add_argument("--variants", nargs="+", default=None, metavar="NAME",
                    help="with --profile generalisation: only these variants of the family, by full or short name "
                         "(g1, g2, ...; default: all); with --profile real: only these corridors")
    users = [*registered(), *registry.names("user")]
    ap.add_argument("--methods", nargs="+", default=None, metavar="METHOD", choices=[*METHODS, *PLANNERS, *users],
                    help=f"among {', '.join([*METHODS, *PLANNERS, *users])} (default: every method with a shipped "
                         f"policy; {ORACLE} (the cost-optimal plan replayed, a DP solve per case), {MPC} (re-plans "
                         f"on the DP in closed loop, a few s per case), {CLAIRVOYANT} (knows the case's future traffic; "
                         "its drives of the fixed and held-out cases are shipped, other cases some 5-30 s each) and installed "
                         f"agents of the entry-point group {GROUP} run when named)")
    ap.add_argument("--planners", action="store_true",
                    help=f"also run the planners, {ORACLE}, {MPC} and {CLAIRVOYANT}, besides the methods (the default ones or "
                         "--methods), in the same pool: one command for the main job (nox -s benchmark)")
    ap.add_argument("--agent", default=None, metavar="MODULE:FACTORY",
                    help="also evaluate your own agent: factory(observation_space, action_space) -> "
                         "ecodrive_bench.agents.base.Agent; MODULE is imported from the installed packages, "
                         "PYTHONPATH or the current folder (as `python -m` finds it there)")
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
    add_options(ap)
    ap.add_argument("--workers", type=int_in(1), default=os.cpu_count() or 1, help="parallel episodes (>= 1; default: this machine's CPUs)")
    ap.add_argument("--episode-limit", type=float_in(0, MAX_LIMIT_S, lo_open=True), default=None, metavar="S",
                    help="wall-clock limit of one episode in seconds, from when a worker takes it (local executor): "
                         "an episode past it is recorded as failed (exit 3) and its worker killed (default: "
                         f"{EPISODE_FIXED_S:g} s plus {EPISODE_STEP_S:g} s per step of the scenario, "
                         f"{EPISODE_FIXED_S + 900 * EPISODE_STEP_S:g} s for the paper's 900 steps)")
    ap.add_argument("--run-id", type=name, default=None,
                    help="run folder under --logs: letters, digits, '.', '_', '-' (default: the profile)")
    ap.add_argument("--logs", type=Path, default=Path("logs"), help="log root (default: logs)")
    ap.add_argument("--models", type=Path, default=MODELS, help="shipped policies (default: models/)")
    ap.add_argument("--bounds", action="store_true",
                    help="add each case's cost-optimal bound (bench.oracle DP; a few s per case, kept in "
                         "<run>/bounds.parquet): columns cost_bound and energy_bound")
    ap.add_argument("--train-seeds", nargs="+", type=int_in(0), default=None, metavar="SEED",
                    help="training seeds of the learning methods to evaluate, each >= 0 (default: every shipped one)")
    scenarios.add_options(ap)
    return ap


def parse(argv: list[str]) -> RunOptions:
    """The checked options; bad input exits 2 with one line (``bench.args.Parser``)."""
    ap = parser()
    ns = ap.parse_args(argv)
    check_options(ap, ns)
    opts = vars(ns)
    opts["run_id"] = opts["run_id"] or opts["profile"]
    if opts["models"] != MODELS and not opts["models"].is_dir():  # a typo would drop every learning method
        ap.error(f"--models {opts['models']}: {'not a folder' if opts['models'].exists() else 'no such folder'} "
                 "(expected a folder of policies, <method>-<signals>/s<seed>/; default: the shipped models/)")
    users = {**registered(), **{m.name: m.build for m in registry.methods() if m.kind == "user"}}
    opts["factories"] = {m: users[m] for m in opts["methods"] or [] if m in users}
    if opts["sb3"] or opts["sb3_algo"]:
        opts["agent"] = sb3_spec(ap, opts)
    if opts["agent"]:
        label = opts["name"] or (f"sb3-{opts['sb3_algo'].lower()}" if opts["sb3"] else opts["agent"].split(":")[-1])
        if len(label) > MAX_NAME:  # the factory's name is a folder and file name of the run, as --name
            ap.error(f"--agent {opts['agent']!r}: the factory's name {name_shown(label)} is too long for a method "
                     f"name (at most {MAX_NAME} characters); give --name")
        if label in (*METHODS, *PLANNERS, *registry.names("user")) or label in opts["factories"]:
            ap.error(f"--name {label!r} is taken by a built-in or installed method; choose another")
        opts["factories"][label] = opts["agent"]
        opts["agent_sha256"] = {label: opts.pop("sb3_sha256")} if "sb3_sha256" in opts else {}
    elif opts["name"]:
        ap.error("--name names an --agent or --sb3; give --agent package.module:factory or --sb3 MODEL.zip too")
    if opts["profile"] in FAMILY_PROFILES:
        if opts["scenario"] or opts["set_scenario"] or opts["network"]:
            ap.error(f"--profile {opts['profile']} evaluates on its family's corridors; --scenario, --set and "
                     "--network are for the other profiles")
        try:  # the case set's reader (bench.registry): its variants, or those named
            opts["family"] = registry.load(registry.case_set(opts["profile"]).reader)(opts["variants"])
        except (FamilyError, ConfigError) as e:
            ap.error(str(e))
        opts["transfer"] = True
    elif opts["variants"]:
        ap.error("--variants selects corridors of a family; give --profile generalisation or real too")
    try:
        opts["scenario"] = scenarios.parse_overrides(opts.pop("scenario"), opts.pop("set_scenario"), opts["signals"],
                                                     network=opts.pop("network"))
    except ValueError as e:
        ap.error(str(e))
    if opts["scenario"].get("network") is not None:  # a network's own insertion window
        opts["cases"] = network_cases(opts["scenario"]["network"], PROFILES[opts["profile"]])
    for flag in ("variants", "agent", "sb3", "sb3_algo", "name", "sb3_sha256"):  # folded into factories, family, ...
        opts.pop(flag, None)
    return RunOptions(**opts, argv=list(argv))


def network_cases(network: str, n: int) -> list[Case]:
    """The first ``n`` fixed cases moved onto a network's insertion window: the same SUMO seeds, each
    insertion time mapped from the fixed cases' range (``INSERT_RANGE``) onto the spec's [lo, hi]."""
    from ecodrive_bench.bench.cases.case import INSERT_RANGE, load
    from ecodrive_bench.envs.network import as_spec

    lo, hi = as_spec(network).insert
    a, b = INSERT_RANGE
    return [Case(c.index, c.sumo_seed, round(lo + (c.insert_time - a) / (b - a) * (hi - lo), 1), c.group)
            for c in load()[:n]]


def sb3_spec(ap: Parser, opts: dict[str, Any]) -> str:
    """The factory spec of ``--sb3 --sb3-algo`` (``bench.methods.sb3``), the zip read and checked
    now: bad input is one line before anything runs."""
    if opts["agent"]:
        ap.error("--sb3 and --agent each add one agent; give one of them")
    if not (opts["sb3"] and opts["sb3_algo"]):
        ap.error(f"--sb3 MODEL.zip and --sb3-algo go together; --sb3-algo is one of {', '.join(SB3_ALGOS)}")
    from ecodrive_bench.bench.methods import sb3

    try:
        saved = sb3.inspect(opts["sb3"], opts["sb3_algo"])
    except AgentError as e:
        ap.error(str(e))
    opts["sb3_sha256"] = saved.sha256
    return sb3.spec(opts["sb3_algo"], opts["sb3"])


