"""Does the paper hold on this run: section 5.3's and Table 4's claims on the run's own episodes
(``reports.claims``), every one NOT CHECKED on a scenario other than the paper's."""
from __future__ import annotations

import pandas as pd

from . import claims, tables
from .inputs import Run

ANCHOR = "claims"
PHASE = "Table 4, statistics, return split, violins and trajectories"


def compute(run: Run, warnings: list[str]) -> pd.DataFrame | None:
    if run.results is None:
        return None
    table = claims.paper_claims(run.results)
    if run.overrides:
        table = claims.off_scenario(table, f"this run's scenario is not the paper's ({run.overrides})")
    return table


def markdown(table: pd.DataFrame) -> str:
    counts = table.status.value_counts()
    summary = ", ".join(f"{s} {int(counts[s])}" for s in claims.STATUSES if counts.get(s, 0))
    return "\n".join(["## Does the paper hold on this run?", "",
                      f"**{len(table)} claims** from the paper: {summary}.", "",
                      "Section 5.3's and Table 4's claims on this run's own episodes, with the published numbers and "
                      "tolerances of `bench/paper.py`; a claim about a method or setting not in the run is NOT CHECKED.",
                      "*paper*: what the paper reports (improvements recomputed from Table 4's means); *ours*: the same "
                      "quantity from this run's mean over its test cases. Energy savings and travel-time changes are "
                      "against the SUMO baseline of the same setting. `ecodrive regress` checks the same claims on "
                      "20 cases against a recorded reference.",
                      "", tables.frame_markdown(table.set_index(["signals", "claim"]))])
