"""The scenario ``ecodrive run`` evaluates on: the paper's corridor of each signal setting, with
the overrides of ``--scenario FILE.json`` (a JSON object, nested like ``ScenarioConfig.to_dict``)
and then of each ``--set FIELD=VALUE`` (dotted for the EV and the reward: ``ev.mass=1500``;
VALUE is read as JSON where it parses, ``spacings=[300,600,440,500]``, else as text).

A learning method's policy drives only the scenario it was trained on (the signals, the GLOSA
device and the reward aside) unless ``--transfer`` is given: then any scenario whose observation
it can take, a road with fewer lanes included (``bench.methods.policies.transfer_overrides``).
Each episode's step log and result row name both scenarios by digest (``ScenarioConfig.digest``):
``eval_scenario_hash``, the command's scenario of the setting (before a method's own overrides,
e.g. GLOSA's device; the log's ``config_json`` has the env's exact config), and
``train_scenario_hash``, the policy's (empty for methods without one); the run's
``manifest.json`` maps them to the configs.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ecodrive_bench.bench.args import (
    MAX_JSON_BYTES,
    MAX_JSON_DEPTH,
    DuplicateKey,
    InputError,
    depth,
    loads,
    one_line,
    read_json,
)
from ecodrive_bench.bench.cases.setting import deep_merge, setting
from ecodrive_bench.envs.config import ConfigError, ScenarioConfig


def add_options(ap) -> None:
    ap.add_argument("--scenario", type=Path, default=None, metavar="FILE.json",
                    help="evaluate on this scenario: a JSON object of ScenarioConfig overrides, in a regular file "
                         f"of at most {MAX_JSON_BYTES / 2**20:g} MiB (docs/environment.md)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", dest="set_scenario",
                    help="override one scenario field, after --scenario (repeatable; e.g. lanes=3, "
                         "spacings=[300,600,440,500], ev.mass=1500)")
    ap.add_argument("--network", default=None, metavar="SPEC.json|NAME",
                    help="evaluate on a route through a SUMO network (docs/networks.md): a JSON file of a network "
                         "spec (net, demand, route, insert; paths relative to the file) or a real corridor's name "
                         "(ingolstadt7, cologne3, cologne8); the same as --set network=...; --transfer for policies")
    ap.add_argument("--transfer", action="store_true",
                    help="let a policy drive a scenario other than the one it was trained on (recorded in "
                         "the logs and results)")


def network_value(spec: str) -> str:
    """``--network``'s value as ``ScenarioConfig.network``: a real corridor's name as it is; a JSON
    file's spec (read with bounds, its paths taken relative to the file) as its JSON text."""
    from ecodrive_bench.envs.network import config_value, real_corridors

    if "/" not in spec and not spec.endswith(".json") and spec in real_corridors():
        return spec
    path = Path(spec)
    data = read_json(path, "--network")
    if not isinstance(data, dict):
        raise InputError(f"--network {path}: a JSON {type(data).__name__}; expected an object with net, demand, "
                         f"route and insert (or one of the real corridors: {', '.join(real_corridors())})")
    here = path.resolve().parent
    for key in ("net", "demand"):
        value = data.get(key)
        if isinstance(value, str):
            data[key] = str(here / value)
        elif isinstance(value, list):
            data[key] = [str(here / v) if isinstance(v, str) else v for v in value]
    try:
        return config_value(data)
    except ConfigError as e:
        raise InputError(f"--network {path}: {e}") from None


def parse_overrides(path: Path | None, items: list[str], signals: list[str], build: bool = True,
                    network: str | None = None) -> dict[str, Any]:
    """The overrides of ``--scenario`` and ``--set``, each validated on the corridor of every
    setting in ``signals``; an ``InputError`` (a ValueError) is one line naming the option, the value
    and the range. The file is read with bounds (``bench.args.read_json``: a regular file of at
    most ``MAX_JSON_BYTES``). With ``build``, a scenario other than the paper's is then built
    (``envs.scenario.build``, cached), so one netconvert cannot make is refused here, in one line."""
    out: dict[str, Any] = {}
    if path is not None:
        out = read_json(path, "--scenario")
        if not isinstance(out, dict):
            raise InputError(f"--scenario {path}: a JSON {type(out).__name__}; expected an object of scenario fields")
        _check(f"--scenario {path}", out, signals)
    for item in items:
        key, sep, raw = item.partition("=")
        shown = one_line(item, 80)
        if not sep or not key or any(not part for part in key.split(".")):
            raise InputError(f"--set {shown!r}: expected FIELD=VALUE, e.g. lanes=3 or ev.mass=1500")
        try:
            value = loads(raw)
        except json.JSONDecodeError:
            value = raw
        except DuplicateKey as e:
            raise InputError(f"--set {shown}: {e}") from None
        except (RecursionError, ValueError) as e:  # nested too deeply; an integer of too many digits
            raise InputError(f"--set {shown}: VALUE is not readable ({type(e).__name__}); accepted: a JSON "
                             f"number, list or object nested at most {MAX_JSON_DEPTH} deep, or text") from None
        if depth(value) > MAX_JSON_DEPTH:
            raise InputError(f"--set {shown}: VALUE nested more than {MAX_JSON_DEPTH} deep; accepted: up to "
                             f"{MAX_JSON_DEPTH}")
        nested: dict[str, Any] = {}
        at = nested
        *subs, name = key.split(".")
        if len(subs) >= MAX_JSON_DEPTH:
            raise InputError(f"--set {shown}: FIELD has {len(subs) + 1} parts; accepted: up to {MAX_JSON_DEPTH}")
        for s in subs:
            at = at.setdefault(s, {})
        at[name] = value
        out = deep_merge(out, nested)
        _check(f"--set {shown}", out, signals)
    if network is not None:
        out = {**out, "network": network_value(network)}
        _check(f"--network {one_line(network, 80)}", out, signals)
    if build and out:
        for s in signals:
            check_buildable(setting(s, out), "--scenario/--set")
    return out


def check_buildable(cfg: ScenarioConfig, where: str) -> None:
    """Build ``cfg``'s network (once: the build is cached); an ``InputError`` of one line naming the
    scenario and netconvert's message when it cannot be built."""
    from ecodrive_bench.envs.config import ConfigError
    from ecodrive_bench.envs.network import corridor_files
    from ecodrive_bench.envs.scenario import ScenarioBuildError

    try:
        corridor_files(cfg)
    except (ScenarioBuildError, ConfigError) as e:  # a NetworkError is a ConfigError
        raise InputError(f"{where}: {e}") from None


def check_cached(method: str, signals: str, ev: Evaluation) -> None:
    """Build (or check in the cache, rebuilding a damaged entry) the scenario ``method`` drives
    in ``signals`` under ``ev``, as its worker will (``bench.methods.env.make_env``): an entry
    that cannot be rebuilt is one ``InputError`` line, before any episode."""
    overrides = json.loads(ev.scenario) if ev.scenario else {}
    check_buildable(setting(signals, deep_merge(overrides, _needs(method))), f"{method}/{signals}")


def _needs(method: str) -> dict[str, Any]:
    """The scenario overrides ``method``'s agent needs (the registry's; {} for a user's --agent, whose
    own are read from its agent)."""
    from ecodrive_bench.bench import registry

    entry = registry.method(method)
    return entry.overrides() if entry is not None else {}


def _check(where: str, overrides: dict[str, Any], signals: list[str]) -> None:
    if "signals" in overrides:
        raise InputError(f"{where}: the signal setting is chosen with --signals, not as a scenario field")
    for s in signals:
        try:
            setting(s, overrides)
        except ConfigError as e:
            raise InputError(f"{where}: {e}") from None


def legacy_hash(signals: str) -> str:
    """The scenario of logs and tables written before ``ecodrive run`` had scenario options: the
    paper's corridor of the setting."""
    return ScenarioConfig(signals=signals).digest()


@dataclass(frozen=True)
class Evaluation:
    """Where one method (and policy) of a command is evaluated."""

    scenario: str  # JSON of the env's scenario overrides (obs_lanes for a transfer included); "" none
    eval_hash: str  # digest of the command's scenario of the setting
    train_hash: str = ""  # digest of the policy's training scenario; "" without a policy
    train: dict[str, Any] | None = None  # that scenario

    def meta(self, transfer: bool) -> tuple[tuple[str, str], ...]:
        """Step-log metadata: both scenarios (the command's is in each log's ``config_json``)."""
        return (("eval_scenario_hash", self.eval_hash), ("train_scenario_hash", self.train_hash),
                ("train_scenario_json", json.dumps(self.train, sort_keys=True) if self.train else ""),
                ("transfer", "true" if transfer else "false"))


def evaluation(method: str, signals: str, policy: str, overrides: dict[str, Any], transfer: bool) -> Evaluation:
    """The evaluation of ``method`` (its policy folder ``policy``, "" for none) on the command's
    scenario; a ``CheckpointError`` when the policy may not or cannot drive it."""
    from ecodrive_bench.bench.methods.policies import check_scenario, read_manifest, trained_scenario

    extras, train = {}, None
    if policy:
        folder = Path(policy)
        manifest = read_manifest(folder)
        env_cfg = setting(signals, deep_merge(overrides, _needs(method)))
        extras = check_scenario(folder, manifest, env_cfg.to_dict(), transfer)
        train = trained_scenario(folder, manifest)
    merged = deep_merge(overrides, extras)
    return Evaluation(json.dumps(merged, sort_keys=True) if merged else "", setting(signals, overrides).digest(),
                      train.digest() if train else "", train.to_dict() if train else None)
