"""The generalisation family: held-out corridors for zero-shot evaluation.

Beside the 100 fixed cases on the paper's corridor, a small versioned family of corridors that no
shipped policy saw in training, each a named scenario override dict (``ScenarioConfig`` fields)
with its own test cases. It is generated from ``MASTER_SEED`` and ``VERSION`` and stored in
``envs/families/heldout.json``; ``ecodrive cases --family test --write`` regenerates
it and ``--check`` verifies it. ``load`` refuses a file that differs from the generator, so a
run always evaluates the documented family.

Every variant changes all five axes at once, each spread over the family by a shuffled
stratification (so each value range is covered, in a seed-given pairing):

- junctions: ``JUNCTIONS`` (3 to 7 signalized intersections; the paper's corridor has 5);
- spacing: the links between the junctions drawn in ``SPACING_RANGE`` (entry and exit links stay
  440 m);
- signal plans: one cycle per variant from ``CYCLES`` (a green wave stays possible), each
  junction's arterial green a share ``GREEN_SHARE`` of it; offsets either the signal setting's
  (green wave over the uneven links / all in sync) or, in half of the variants, drawn at random
  per junction (``junction_offsets``: the two settings are then one corridor, each setting's
  policies drive it);
- demand: ``arterial_flow`` stratified over ``FLOW_RANGE``;
- lanes: ``LANES`` (a shipped 5-lane policy observes fewer as padded, occupied lanes).

The grid, step and perception settings are the paper's, so every shipped policy can observe every
variant (``bench.methods.policies.transfer_overrides``). The file lives with the env
(``envs/families/heldout.json``), whose ``family="test"`` samples its corridors
(``envs.family``); the training family (``bench.cases.train_family``) draws from the same axes
and shares no corridor with it.
"""
from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.args import InputError, read_json
from ecodrive_bench.bench.cases.case import INSERT_RANGE, SEED_BOUND, Case, CaseError, check_cases
from ecodrive_bench.bench.io import write_or_check
from ecodrive_bench.envs.config import SIGNALS, ConfigError, ScenarioConfig
from ecodrive_bench.envs.family import HELDOUT_FILE

MASTER_SEED = 20240621  # documented master seed of the family
VERSION = 2  # 2: the number of junctions is an axis (JUNCTIONS); 1 had the paper's 5 everywhere
N_VARIANTS = 6
CASES_PER_VARIANT = 10  # per signal setting: 6 x 10 x 2 settings = 120 episodes per method
SPACING_RANGE = (200.0, 800.0)  # [m] each inner link, rounded to 10 m
CYCLES = (60.0, 75.0, 90.0, 105.0, 120.0)  # [s] one per variant
GREEN_SHARE = (0.35, 0.6)  # [-] arterial green / cycle per junction, rounded to 1 s
FLOW_RANGE = (600.0, 1400.0)  # [veh/h] W->E, stratified, rounded to 50 veh/h
LANES = (3, 4, 5)  # [-] each twice
JUNCTIONS = (3, 4, 5, 6, 7)  # [-] signalized intersections, stratified (one value twice over six variants)
FAMILY_FILE = HELDOUT_FILE


class FamilyError(InputError):
    """A family file or variant name that is not accepted; one line (a ValueError)."""


@dataclass(frozen=True)
class Variant:
    name: str
    scenario: dict[str, Any]  # ScenarioConfig overrides (no "signals")
    cases: tuple[Case, ...]

    def config(self, signals: str) -> ScenarioConfig:
        return ScenarioConfig.from_dict({**self.scenario, "signals": signals})


def draw_corridor(rng: np.random.Generator, name: str, lanes: int, flow: float, random_offsets: bool,
                  junctions: int) -> dict[str, Any]:
    """One corridor ``{"name", "scenario"}`` on the family's axes, its links, cycle, greens and
    offsets drawn from ``rng`` (the offsets always, so the stream does not depend on the kind)."""
    n = junctions
    spacings = [float(v) for v in np.round(rng.uniform(*SPACING_RANGE, size=n - 1), -1)]
    cycle = float(rng.choice(CYCLES))
    greens = [float(v) for v in np.round(rng.uniform(*GREEN_SHARE, size=n) * cycle)]
    scenario: dict[str, Any] = {"spacings": spacings, "junction_cycles": [cycle] * n, "junction_greens": greens,
                                "arterial_flow": flow, "lanes": lanes}
    offsets = rng.uniform(0.0, cycle, size=n)  # drawn for every variant: the stream does not depend on the kind
    if random_offsets:
        scenario["junction_offsets"] = [float(np.floor(o)) for o in offsets]
    scenario["n_intersections"] = n
    return {"name": f"{name}-{n}j-{lanes}lane-{int(flow)}vph-c{int(cycle)}-{'randoff' if random_offsets else 'planoff'}",
            "scenario": scenario}


def draw_family(rng: np.random.Generator, n: int, cases: int, name: Callable[[int], str]) -> list[dict[str, Any]]:
    """``n`` corridors named ``name(k)``, every axis stratified over them in a shuffled pairing, each
    with ``cases`` test cases (seed, insertion time) drawn after it (none for 0)."""
    lanes = rng.permutation(np.resize(np.array(LANES), n))
    flows = rng.permutation(np.round(np.linspace(*FLOW_RANGE, n) / 50.0) * 50.0)
    kinds = rng.permutation(np.arange(n) % 2 == 1)
    junctions = rng.permutation(np.resize(np.array(JUNCTIONS), n))
    out = []
    for k in range(n):
        v = draw_corridor(rng, name(k), int(lanes[k]), float(flows[k]), bool(kinds[k]), int(junctions[k]))
        if cases:
            seeds = rng.choice(SEED_BOUND, size=cases, replace=False)
            times = np.round(rng.uniform(*INSERT_RANGE, size=cases), 1)
            v["cases"] = [{"index": i, "sumo_seed": int(seeds[i]), "insert_time": float(times[i]), "group": i}
                          for i in range(cases)]
        out.append(v)
    return out


def generate(master_seed: int = MASTER_SEED, n: int = N_VARIANTS, cases: int = CASES_PER_VARIANT) -> dict:
    rng = np.random.default_rng(master_seed)
    variants = draw_family(rng, n, cases, lambda k: f"g{k + 1}")
    return {"version": VERSION, "master_seed": master_seed, "cases_per_variant": cases,
            "insert_range_s": list(INSERT_RANGE), "variants": variants}


def text(data: dict | None = None) -> str:
    """The family file's exact text."""
    return json.dumps(generate() if data is None else data, indent=1) + "\n"


def load(path: Path | None = None) -> list[Variant]:
    """The family, verified: a regular JSON file of at most ``MAX_JSON_BYTES``, every variant's
    cases valid (``bench.cases.case.check_cases``: the value and its range named), the file the
    generator's output of this ``VERSION`` (a tampered or stale file is a ``FamilyError``) and every
    variant a valid scenario."""
    path = FAMILY_FILE if path is None else path
    try:
        data = read_json(path, "family file")
    except InputError as e:
        raise FamilyError(f"{e} (restore it with `ecodrive cases --generalisation --write`)") from None
    if not isinstance(data, dict) or data.get("version") != VERSION:
        got = data.get("version") if isinstance(data, dict) else None
        raise FamilyError(f"{path}: family version {got!r} is not the supported {VERSION}")
    variants = data.get("variants")
    if not isinstance(variants, list) or not all(isinstance(v, dict) for v in variants):
        raise FamilyError(f"{path}: 'variants' must be a list of objects")
    for k, v in enumerate(variants):
        try:  # a bad case is named before the comparison with the generator below
            check_cases(v.get("cases"), f"{path}: variant {v.get('name', f'#{k}')!s:.40}", groups=CASES_PER_VARIANT)
        except CaseError as e:
            raise FamilyError(str(e)) from None
    if path.read_text() != text():
        raise FamilyError(f"{path}: differs from the generator (version {VERSION}, master seed {MASTER_SEED}); "
                          f"restore it with `ecodrive cases --generalisation --write`")
    out = []
    for v in data["variants"]:
        variant = Variant(v["name"], v["scenario"], tuple(check_cases(v["cases"], path, CASES_PER_VARIANT)))
        for s in SIGNALS:
            try:
                variant.config(s)
            except ConfigError as e:
                raise FamilyError(f"{path}: variant {variant.name}: {e}") from None
        out.append(variant)
    return out


def select(family: list[Variant], names: list[str] | None) -> list[Variant]:
    """The variants named, in full or by their short name ``gN`` (all for None), in family order; an
    unknown name is a ``FamilyError``."""
    if names is None:
        return family
    known = [v.name for v in family]
    unknown = [n for n in names if n not in known and n not in [k.split("-")[0] for k in known]]
    if unknown:
        raise FamilyError(f"unknown variant {', '.join(map(repr, unknown))}; accepted: {', '.join(known)} "
                          f"(or their short names g1..g{len(known)})")
    return [v for v in family if v.name in names or v.name.split("-")[0] in names]


def variants(names: list[str] | None = None) -> list[Variant]:
    """The family's variants (``names``: only those, by full or short name; ``select``)."""
    return select(load(), names)


def main(write: bool, path: Path | None = None) -> int:
    """``ecodrive cases --generalisation --write|--check``."""
    path = FAMILY_FILE if path is None else path
    data = generate()
    ok = write_or_check(path, text(data), write,
                        f"wrote {len(data['variants'])} variants x {data['cases_per_variant']} cases to {path}",
                        f"{path.name} matches the generator", f"{path.name} differs from the generator")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main("--write" in sys.argv))
