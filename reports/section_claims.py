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
    return "\n".join(["## Does the paper hold on this run?", "",
                      "Section 5.3's and Table 4's claims on this run's own episodes, with the published numbers and "
                      "tolerances of `bench/paper.py`; a claim about a method or setting not in the run is NOT CHECKED.",
                      "", tables.frame_markdown(table.set_index(["signals", "claim"]))])
