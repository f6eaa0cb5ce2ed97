"""Across training seeds: each method's mean over its seeds with a stratified bootstrap CI, the IQM
and the range of the per-seed means (``reports.metrics.across_seeds``)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv

from . import metrics, stats, tables
from .inputs import Run

ANCHOR = "seeds"
PHASE = "Table 4, statistics, return split, violins and trajectories"


def compute(run: Run, warnings: list[str]) -> pd.DataFrame | None:
    return None if run.results is None else metrics.across_seeds(run.results)


def write(seeds: pd.DataFrame, out: Path) -> None:
    atomic_csv(seeds, out / "seeds.csv")


def markdown(seeds: pd.DataFrame) -> str:
    return "\n".join([
        "## Across training seeds", "",
        "Each method's runs on the same cases, a learning method's shipped training seeds: the mean over seeds "
        f"and cases with a {int(stats.CI_LEVEL * 100)}% stratified bootstrap CI over seeds (seeds resampled per "
        "case, as rliable does), the IQM over all runs, and the range of the per-seed means. One seed (a "
        "rule-based method or an agent of your own runs once) has no CI.",
        "", tables.frame_markdown(seeds.set_index(["method", "signals", "metric"]), digits=2)])
