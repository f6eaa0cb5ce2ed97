"""The training family: corridors to train on (``"train"``) and to select on (``"validation"``).

The protocol of train levels against test levels (Procgen, IntersectionZoo): a policy trained on
the family is tested on the held-out family (``bench.cases.heldout``, ``family="test"``)
that it never saw, and its checkpoints are chosen on the validation split, never on a test case.
Both files are drawn on the same axes (junctions, spacing, cycle and green share, offsets, demand,
lanes: ``bench.cases.heldout.draw_corridor``), each split stratified over every axis, the
training family from its own ``MASTER_SEED``. ``check`` refuses a family that shares a corridor
with the held-out family or that is the paper's corridor, in either signal setting.

    ecodrive cases --family train --check|--write   # envs/families/train.json

Each validation corridor carries ``VALIDATION_CASES`` cases (seed, insertion time), drawn like
the test cases: a trainer scores its checkpoints on all of them (``bench.training.train``).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.args import InputError
from ecodrive_bench.bench.cases import heldout
from ecodrive_bench.bench.cases.case import INSERT_RANGE, Case, CaseError, check_cases
from ecodrive_bench.bench.cases.heldout import CYCLES, FLOW_RANGE, JUNCTIONS, LANES, draw_family
from ecodrive_bench.bench.io import write_or_check
from ecodrive_bench.envs.config import SIGNALS, ConfigError, ScenarioConfig, diff
from ecodrive_bench.envs.family import TRAIN_FILE, Corridor, read

MASTER_SEED = 20261127  # documented master seed of the training family (the held-out family has its own)
VERSION = 1
N_TRAIN = 48  # [corridors] sampled by a training env
N_VALIDATION = 8  # [corridors] scored at every checkpoint
VALIDATION_CASES = 3  # [cases] per validation corridor: 24 greedy episodes per checkpoint


class TrainFamilyError(InputError):
    """A training-family file that is not the generator's, or that overlaps a held-out corridor."""


def generate(master_seed: int = MASTER_SEED) -> dict[str, Any]:
    rng = np.random.default_rng(master_seed)
    return {"version": VERSION, "master_seed": master_seed, "axes": {
                "junctions": list(JUNCTIONS), "lanes": list(LANES), "cycles_s": list(CYCLES),
                "flow_vph": list(FLOW_RANGE), "spacing_m": list(heldout.SPACING_RANGE),
                "green_share": list(heldout.GREEN_SHARE)},
            "validation_cases": VALIDATION_CASES, "insert_range_s": list(INSERT_RANGE),
            "splits": {"train": draw_family(rng, N_TRAIN, 0, lambda k: f"t{k + 1:02d}"),
                       "validation": draw_family(rng, N_VALIDATION, VALIDATION_CASES, lambda k: f"v{k + 1:02d}")}}


def text(data: dict[str, Any] | None = None) -> str:
    """The family file's exact text."""
    return json.dumps(generate() if data is None else data, indent=1) + "\n"


def overlaps(data: dict[str, Any]) -> list[str]:
    """The training-family corridors that equal, in effect and in either signal setting, a
    held-out one or the paper's corridor: one line each ([]: disjoint)."""
    held = [(v["name"], v["scenario"]) for v in heldout.generate()["variants"]] + [("the paper's corridor", {})]
    out = []
    for split, entries in data["splits"].items():
        for c in entries:
            for s in SIGNALS:
                mine = ScenarioConfig.from_dict({**c["scenario"], "signals": s}).to_dict()
                for name, scenario in held:
                    if not diff(mine, ScenarioConfig.from_dict({**scenario, "signals": s}).to_dict()):
                        out.append(f"{split} corridor {c['name']} is {name} ({s})")
    return out


def load(path: Path | None = None) -> dict[str, Any]:
    """The training family, verified: the generator's output of this ``VERSION``, every corridor a
    valid scenario in both settings, the validation cases valid; a ``TrainFamilyError`` otherwise."""
    path = TRAIN_FILE if path is None else path
    try:
        data = read(path)
    except ConfigError as e:
        raise TrainFamilyError(f"{e} (restore it with `ecodrive cases --family train --write`)") from None
    if data.get("version") != VERSION:
        raise TrainFamilyError(f"{path}: family version {data.get('version')!r} is not the supported {VERSION}")
    if path.read_text() != text():
        raise TrainFamilyError(f"{path}: differs from the generator (version {VERSION}, master seed {MASTER_SEED}); "
                               f"restore it with `ecodrive cases --family train --write`")
    return data


def validation_set(path: Path | None = None) -> list[tuple[Corridor, list[Case]]]:
    """The validation corridors with their cases, as checkpoint selection scores them."""
    data = load(path)
    out = []
    for c in data["splits"]["validation"]:
        try:
            cases = check_cases(c["cases"], f"{path or TRAIN_FILE}: corridor {c['name']}", groups=VALIDATION_CASES)
        except CaseError as e:
            raise TrainFamilyError(str(e)) from None
        out.append((Corridor(c["name"], c["scenario"]), cases))
    return out


def main(write: bool, path: Path | None = None) -> int:
    """``ecodrive cases --family train --write|--check``: 0 as generated; 1 it differs from the
    generator or overlaps the held-out family."""
    path = TRAIN_FILE if path is None else path
    data = generate()
    bad = overlaps(data)
    for line in bad:
        print(f"the training family overlaps the held-out family: {line}")
    if bad:
        return 1
    ok = write_or_check(path, text(data), write, f"wrote {N_TRAIN} training and {N_VALIDATION} validation corridors to {path}",
                        f"{path.name} matches the generator and shares no corridor with the held-out family",
                        f"{path.name} differs from the generator")
    return 0 if ok else 1
