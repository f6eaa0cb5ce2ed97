"""Table 4: each method's mean energy and travel time per setting with the published values beside
them, and the reward's cost E + phi T against the cost the paper's Table 4 implies."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv, atomic_text

from . import headline, metrics, tables
from .inputs import Run

ANCHOR = "table4"
PHASE = "Table 4, statistics, return split, violins and trajectories"


@dataclass(frozen=True)
class Table4:
    table: pd.DataFrame  # metrics.table4, rows in the run's order of methods
    costs: pd.DataFrame  # metrics.paper_costs: one row per method and setting the paper prints


def compute(run: Run, warnings: list[str]) -> Table4 | None:
    if run.results is None:
        return None
    t4 = metrics.table4(run.results)
    t4 = t4.set_index("method").loc[[m for m in run.methods if m in set(t4.method)]].reset_index()
    return Table4(t4, metrics.paper_costs(t4, headline.phis(run.results, run.manifest)))


def write(d: Table4, out: Path) -> None:
    atomic_text(tables.table4_markdown(d.table), out / "table4.md")
    atomic_text(tables.table4_latex(d.table), out / "table4.tex")
    atomic_csv(d.table, out / "table4.csv")


def markdown(d: Table4) -> str:
    lines = ["## Table 4", "",
             "Each method's mean over its episodes: the fixed test cases times its training seeds (the paper: 100 "
             "cases, one policy). *imp.* = (baseline - method) / baseline, as in the paper: + means less energy or "
             "less time than the baseline of the same setting (better), - more (worse). *vs paper* = this run / "
             "published - 1. The *paper* columns are the published Table 4 (the baseline and PRL; the paper's "
             "imp. recomputed from its means).", "", tables.table4_markdown(d.table)]
    if not d.costs.empty:
        lines += ["Table 4 compares energy and travel time apart; the reward's cost, E + phi T (eq. 11, the criterion "
                  "the learning methods' checkpoints are selected by), weighs them together. Ours against the cost "
                  "that the paper's Table 4 implies:", ""]
        lines += [f"- {r.method}, {r.signals}: {r.cost:.1f} against {r.paper_cost:.1f} (phi = {r.phi:g} Wh/s; "
                  f"{100 * r.cost_vs_paper:+.1f}%)" for r in d.costs.itertuples()] + [""]
    return "\n".join(lines)
