"""The scenario ``ecodrive run`` evaluates on: the paper's corridor of each signal setting, with
the overrides of ``--scenario FILE.json`` (a JSON object, nested like ``ScenarioConfig.to_dict``)
and then of each ``--set FIELD=VALUE`` (dotted for the EV and the reward: ``ev.mass=1500``;
VALUE is read as JSON where it parses, ``spacings=[300,600,440,500]``, else as text).

A learning method's policy drives only the scenario it was trained on (the signals, the GLOSA
device and the reward aside) unless ``--transfer`` is given: then any scenario whose observation
it can take, a road with fewer lanes included (``bench.harness.policies.transfer_overrides``).
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

from bench.harness.episode import deep_merge
from envs.config import ConfigError, ScenarioConfig


def add_options(ap) -> None:
    ap.add_argument("--scenario", type=Path, default=None, metavar="FILE.json",
                    help="evaluate on this scenario: a JSON object of ScenarioConfig overrides (docs/environment.md)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", dest="set_scenario",
                    help="override one scenario field, after --scenario (repeatable; e.g. lanes=3, "
                         "spacings=[300,600,440,500], ev.mass=1500)")
    ap.add_argument("--transfer", action="store_true",
                    help="let a policy drive a scenario other than the one it was trained on (recorded in "
                         "the logs and results)")


def setting(signals: str, overrides: dict[str, Any] | None) -> ScenarioConfig:
    """The scenario of one signal setting under the command's overrides."""
    return ScenarioConfig.from_dict(deep_merge({"signals": signals}, overrides or {}))


def parse_overrides(path: Path | None, items: list[str], signals: list[str]) -> dict[str, Any]:
    """The overrides of ``--scenario`` and ``--set``, each validated on the corridor of every
    setting in ``signals``; a ValueError is one line naming the option, the value and the range."""
    out: dict[str, Any] = {}
    if path is not None:
        try:
            out = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ValueError(f"--scenario {path}: not a readable JSON file ({type(e).__name__}: "
                             f"{str(e).splitlines()[0] if str(e) else ''})") from None
        if not isinstance(out, dict):
            raise ValueError(f"--scenario {path}: a JSON {type(out).__name__}; expected an object of scenario fields")
        _check(f"--scenario {path}", out, signals)
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key or any(not part for part in key.split(".")):
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE, e.g. lanes=3 or ev.mass=1500")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        nested: dict[str, Any] = {}
        at = nested
        *subs, name = key.split(".")
        for s in subs:
            at = at.setdefault(s, {})
        at[name] = value
        out = deep_merge(out, nested)
        _check(f"--set {item}", out, signals)
    return out


def _check(where: str, overrides: dict[str, Any], signals: list[str]) -> None:
    if "signals" in overrides:
        raise ValueError(f"{where}: the signal setting is chosen with --signals, not as a scenario field")
    for s in signals:
        try:
            setting(s, overrides)
        except ConfigError as e:
            raise ValueError(f"{where}: {e}") from None


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
    from agents.registry import ENV_OVERRIDES
    from bench.harness.policies import check_scenario, read_manifest, trained_scenario

    extras, train = {}, None
    if policy:
        folder = Path(policy)
        manifest = read_manifest(folder)
        env_cfg = setting(signals, deep_merge(overrides, ENV_OVERRIDES.get(method, {})))
        extras = check_scenario(folder, manifest, env_cfg.to_dict(), transfer)
        train = trained_scenario(folder, manifest)
    merged = deep_merge(overrides, extras)
    return Evaluation(json.dumps(merged, sort_keys=True) if merged else "", setting(signals, overrides).digest(),
                      train.digest() if train else "", train.to_dict() if train else None)
