"""Statistics: per method, setting and metric the mean and IQM with bootstrap CIs, and the chance
of improving on the baseline on the same case (``reports.metrics.statistics``)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv, atomic_text

from . import metrics, stats, tables
from .inputs import Run

ANCHOR = "statistics"
PHASE = "Table 4, statistics, return split, violins and trajectories"


def compute(run: Run, warnings: list[str]) -> pd.DataFrame | None:
    return None if run.results is None else metrics.statistics(run.results)


def write(st: pd.DataFrame, out: Path) -> None:
    atomic_text(tables.stats_markdown(st), out / "statistics.md")
    atomic_csv(st, out / "statistics.csv")


def markdown(st: pd.DataFrame) -> str:
    return "\n".join([
        "## Statistics", "",
        f"Bootstrap (BCa, {stats.BOOTSTRAP_RESAMPLES} resamples) {int(stats.CI_LEVEL * 100)}% CIs; IQM = "
        "25% trimmed mean; P(improve) = chance the method uses less than the baseline on the same case (per case "
        "over its training seeds, averaged over the cases; CI by resampling cases and seeds).",
        "", tables.stats_markdown(st)])
