"""Corridor families: the splits an agent trains, selects and is tested on (``family=`` of EcoDrive-v0).

A family is a list of corridors, each a name and a dict of ``ScenarioConfig`` overrides (spacing,
signal plans, offsets, demand, lanes, number of junctions; never the grid, the step or the
perception, so one policy observes them all). Three splits, disjoint by construction and by test:

- ``"train"``: the training family, sampled at each ``reset`` of a training env;
- ``"validation"``: its held-apart corridors, for checkpoint selection and tuning;
- ``"test"``: the held-out family of ``ecodrive run --profile generalisation``, never trained or
  selected on.

The data files live beside this module (``families/train.json`` holds the first two splits,
``families/heldout.json`` the third, with its test cases); the generators that write them, and
the checks that they equal their generator's output, are ``bench.cases.train_family`` and
``bench.cases.heldout`` (``ecodrive cases --family train|test --check|--write``). This
module only reads them, so the env stays below the benchmark's layers.
"""
from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from .config import ConfigError, ScenarioConfig

FAMILY_DIR = Path(__file__).with_name("families")
TRAIN_FILE = FAMILY_DIR / "train.json"  # the "train" and "validation" splits
HELDOUT_FILE = FAMILY_DIR / "heldout.json"  # the "test" split (with its cases)
SPLITS = ("train", "validation", "test")
OBS_LANES = 5  # [-] lanes every family env observes: the most any corridor has, the paper's
MAX_BYTES = 4 << 20  # [bytes] a larger family file is refused before it is parsed


@dataclass(frozen=True)
class Corridor:
    """One corridor of a family: its name and its ``ScenarioConfig`` overrides (no ``signals``)."""

    name: str
    scenario: dict[str, Any]

    def config(self, base: dict[str, Any]) -> ScenarioConfig:
        """``base`` (a config dict with ``signals``) with this corridor's overrides, observing
        ``OBS_LANES`` lanes."""
        return ScenarioConfig.from_dict({**base, **self.scenario, "obs_lanes": OBS_LANES})


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    seen: dict[str, Any] = {}
    for k, v in pairs:
        if k in seen:
            raise ConfigError(f"duplicate key {k!r}")
        seen[k] = v
    return seen


def read(path: Path) -> dict[str, Any]:
    """A family file as JSON: a regular file of at most ``MAX_BYTES``, no duplicate key; a
    ``ConfigError`` of one line naming the file otherwise."""
    if not path.is_file() or path.stat().st_size > MAX_BYTES:
        raise ConfigError(f"{path}: not a regular family file of at most {MAX_BYTES >> 20} MiB")
    try:
        data = json.loads(path.read_text(), object_pairs_hook=_unique_keys)
    except (ValueError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: not a family file ({e})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: not a family file (a JSON object is expected)")
    return data


def _corridors(path: Path, entries: Any, what: str) -> tuple[Corridor, ...]:
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path}: {what} must be a non-empty list of corridors")
    out, names = [], set()
    for k, e in enumerate(entries):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str) or not isinstance(e.get("scenario"), dict):
            raise ConfigError(f"{path}: {what} #{k} must be an object with a 'name' and a 'scenario'")
        if e["name"] in names or "signals" in e["scenario"]:
            raise ConfigError(f"{path}: {what} #{k} ({e['name']!r:.40}) repeats a name or sets the signals")
        names.add(e["name"])
        out.append(Corridor(e["name"], dict(e["scenario"])))
    return tuple(out)


def corridors(split: str) -> tuple[Corridor, ...]:
    """The corridors of ``split`` (one of ``SPLITS``), read once per process; a ``ConfigError`` of
    one line for anything else (a list, a name not in ``SPLITS``)."""
    if not isinstance(split, str) or split not in SPLITS:
        raise ConfigError(f"family={split!r:.60} is not accepted; accepted: {', '.join(SPLITS)}")
    return _split(split)


def set_fields(split: str) -> tuple[str, ...]:
    """The scenario fields the corridors of ``split`` set (and ``obs_lanes``, which every family env
    observes): a family env refuses them from its caller."""
    return tuple(sorted({k for c in corridors(split) for k in c.scenario} | {"obs_lanes"}))


@cache
def _split(split: str) -> tuple[Corridor, ...]:
    if split == "test":
        return _corridors(HELDOUT_FILE, read(HELDOUT_FILE).get("variants"), "'variants'")
    splits = read(TRAIN_FILE).get("splits")
    if not isinstance(splits, dict):
        raise ConfigError(f"{TRAIN_FILE}: 'splits' must be an object of 'train' and 'validation'")
    return _corridors(TRAIN_FILE, splits.get(split), f"split {split!r}")


_WARNED_TEST = False  # the held-out split sampled: said once per process


def check_caller(split: str, base: dict[str, Any]) -> None:
    """Refuse the scenario fields a family sets per corridor where the caller gave another value
    than the default (they would be replaced silently), naming them; warn once per process when an
    env samples the held-out test split (evaluation's, never training's or selection's)."""
    global _WARNED_TEST
    defaults = ScenarioConfig().to_dict()
    clash = sorted(k for k in set_fields(split) if k in base and base[k] != defaults.get(k))
    if clash:
        raise ConfigError(f"family={split!r} sets {', '.join(clash)} per corridor; they are not accepted with it "
                          f"(given: {', '.join(f'{k}={base[k]!r:.40}' for k in clash)})")
    if split == "test" and not _WARNED_TEST:
        _WARNED_TEST = True
        warnings.warn("family='test' samples the held-out corridors: evaluate on them, never train or select on "
                      "them (docs/generalisation.md)", UserWarning, stacklevel=4)
