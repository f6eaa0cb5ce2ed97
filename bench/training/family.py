"""Training over the corridor family: the pieces ``ecodrive train --family train`` adds to a run.

A generalist is trained with ``EcoDrive-v0(family="train")``: each episode's corridor is drawn
from the env's generator after the episode's seed, so a resumed run draws the same corridors. Its
checkpoints are scored on the validation split (``bench.cases.train_family``: 8 corridors x 3 cases,
never a test case and never a training corridor; all 24 unless ``--validation-cases`` asks fewer),
by the same criteria as a specialist's, and the
chosen one ships under the method's own name, ``<method>-family`` (``models/prl-family-<signals>/``).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ecodrive_bench.bench.cases import train_family
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.io import sha256
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.envs.family import OBS_LANES, TRAIN_FILE, Corridor

SUFFIX = "-family"  # a generalist's method name: <method>-family


def method_name(method: str, family: str | None) -> str:
    """The name a run exports under: ``prl`` or, trained on a family, ``prl-family``."""
    return method if family is None else f"{method}{SUFFIX}"


def identity(family: str) -> dict[str, Any]:
    """What a checkpoint and a manifest record of the family: a changed family file is another run."""
    return {"split": family, "file": TRAIN_FILE.name, "version": train_family.VERSION,
            "master_seed": train_family.MASTER_SEED, "sha256": sha256(TRAIN_FILE)}


def cases(n: int | None = None) -> list[tuple[Corridor, list[Case]]]:
    """The first ``n`` validation cases (all for None), taken round-robin over the corridors (case 0
    of every corridor, then case 1, ...), grouped by corridor."""
    todo = train_family.validation_set()
    order = [(i, j) for j in range(train_family.VALIDATION_CASES) for i in range(len(todo))][:n]
    return [(c, [cs[j] for i2, j in order if i2 == i]) for i, (c, cs) in enumerate(todo) if any(i2 == i for i2, _ in order)]


def validate(method: str, signals: str, scenario: dict[str, Any], agent, n: int | None = None,
             progress: bool = False) -> dict[str, float]:
    """Mean greedy energy, travel time and return over ``cases(n)`` (the corridor's overrides on
    ``scenario``, observing ``OBS_LANES`` lanes as in training)."""
    from ecodrive_bench.bench.progress import bar as progress_bar

    rows = []
    todo = cases(n)
    bar = progress_bar(total=sum(len(c) for _, c in todo), desc="validation", unit="ep", leave=False,
                       enabled=progress)
    for corridor, some in todo:
        env = make_env(method, signals, {**scenario, **corridor.scenario, "obs_lanes": OBS_LANES})
        try:
            for case in some:
                rows.append(run_episode(env, agent, case, "validation"))
                bar.update(1)
        finally:
            env.close()
    bar.close()
    return {k: round(float(np.mean([r[col] for r in rows])), 4)
            for k, col in (("energy", "energy"), ("travel_time", "travel_time"), ("return", "return_"))}
